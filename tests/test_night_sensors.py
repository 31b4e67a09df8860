"""Sensors under the moonlit sky (sensor.night, skysim.night.MoonlitSky) and the moonlit-compass
reproduction (experiments.studies.moonlit_compass): photometric conversion against published
numbers, noise against closed forms, zero-noise limits, seeds and bad input."""

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("astropy", reason="the Moon's position needs astropy (extra 'moon')")

from sensor.night import (LUX_PER_V_IRRADIANCE, NightPhotodiode,  # noqa: E402
                          camera_photoelectron_rate, four_photodiode_aop_sd_deg, lux_equivalent,
                          moon_illuminance_lx, photocurrent_sd_A)
from skysim.bands import get_band  # noqa: E402
from skysim.exceptions import InvalidParameterError, SunBelowHorizonError  # noqa: E402
from skysim.moon import moon_position  # noqa: E402
from skysim.night import (MoonBelowHorizonError, MoonlitSky, moon_band_irradiance,  # noqa: E402
                          night_sky)
from skysim.sun import Site  # noqa: E402

PARANAL = Site(-24.6272, -70.4042, 2635.0)


# --------------------------------------------------------------------------- photometry
def test_v_band_lux_factor_matches_allen_zero_magnitude_star():
    # Allen's Astrophysical Quantities (4th ed.): a V = 0 star gives 2.54e-6 lx outside the
    # atmosphere; with the V zero point 3.631e-11 W m-2 nm-1 that is 6.995e4 lx per W m-2 nm-1.
    # K_V comes from the Sun (IES 127.5 klx, Willmer's V magnitude): Vega's and the Sun's
    # spectra weigh the V band and the eye's V(lambda) curve alike within ~1 %; 1.5 % allowed.
    allen = 2.54e-6 / get_band("V").zero_point_W_m2_nm
    assert LUX_PER_V_IRRADIANCE == pytest.approx(allen, rel=0.015)


def test_supermoon_illuminance_matches_kyba_maximum():
    # Kyba, Mohar & Posch (2017, A&G 58:1.31): at most 0.32 lx, for a perigee full Moon at
    # culmination in the tropics. The perigee full Moon of 2016-11-14 13:52 UTC over the site
    # where it stands highest, in clear air (0.11 and 0.20 mag per airmass): ROLO's absolute
    # scale is good to 5-10 % (Kieffer & Stone 2005) and the extinction changes the value by
    # 8 %, so [0.27, 0.37] lx.
    t = pd.Timestamp("2016-11-14T13:52:00Z")
    lat, lon = np.meshgrid(np.arange(-30.0, 30.0, 1.0), np.arange(100.0, 200.0, 2.0))
    m = moon_position([t] * lat.size, lat.ravel(), np.mod(lon.ravel() + 180, 360) - 180, 0.0)
    e, _ = moon_band_irradiance(m, "V")
    for k in (0.11, 0.20):
        best = float(np.max(moon_illuminance_lx(e, m.elevation_deg.to_numpy(), extinction=k)))
        assert 0.27 <= best <= 0.37, (k, best)


def test_full_moon_at_paranal_gives_a_tenth_of_a_lux():
    # Kyba et al. (2017): a full Moon typically gives 0.05-0.1 lx, at most 0.32 lx. The full
    # Moon of 2024-01-25/26 at Paranal, near culmination (~45 deg): between 0.1 and 0.3 lx.
    m = moon_position(["2024-01-26T05:30:00Z"], PARANAL.latitude_deg, PARANAL.longitude_deg,
                      PARANAL.altitude_m)
    e, _ = moon_band_irradiance(m, "V")
    lx = float(moon_illuminance_lx(e, m.elevation_deg.to_numpy())[0])
    assert m.elevation_deg.iloc[0] > 40.0
    assert 0.1 <= lx <= 0.3


def test_moonlit_sky_equals_night_sky_without_sun():
    t = "2021-01-27T05:00:00Z"
    sky, moon = MoonlitSky.at(t, PARANAL)
    el, az = np.array([5.0, 30.0, 60.0, 90.0]), np.array([10.0, 100.0, 250.0, 0.0])
    f = sky.field(el, az, moon.elevation_deg, moon.azimuth_deg)
    g = night_sky(el, az, t, PARANAL, include_sun=False).field
    np.testing.assert_allclose(f.I, g.I, rtol=1e-12)
    np.testing.assert_allclose(f.Q, g.Q, rtol=1e-12, atol=1e-30)
    np.testing.assert_allclose(f.U, g.U, rtol=1e-12, atol=1e-30)


# --------------------------------------------------------------------------- noise
def test_photocurrent_noise_is_poisson_of_the_window():
    # 50 pA for 10 s: 3.12e9 electrons, sd sqrt(N) electrons -> sqrt(q I / T) amperes
    n_e = 50e-12 * 10.0 / 1.602176634e-19
    assert photocurrent_sd_A(50e-12, 10.0) == pytest.approx(np.sqrt(n_e) * 1.602176634e-19
                                                            / 10.0, rel=1e-12)
    # Johnson noise of 1 GOhm at 293.15 K over 10 s: sqrt(2 k T / (R T))
    j = np.sqrt(2 * 1.380649e-23 * 293.15 / (1e9 * 10.0))
    assert photocurrent_sd_A(0.0, 10.0, 1e9) == pytest.approx(j, rel=1e-12)


@pytest.mark.parametrize("dark_A, feedback", [(0.0, np.inf), (50e-12, 1e9)])
def test_four_photodiode_aop_sd_matches_closed_form(dark_A, feedback):
    # Monte Carlo of the 0/45/90/135 unit with dark subtraction against the first-order
    # closed form; 20000 draws give the sd to 0.5 % (1 sigma); 3 % allowed
    from calibration.installation import polarization_from_photodiodes
    pdiode = NightPhotodiode(dark_A=dark_A, feedback_ohm=feedback)
    angles = np.array([0.0, 45.0, 90.0, 135.0])
    lux, dop, chi, window = 0.01, 0.4, 20.0, 10.0
    rng = np.random.default_rng(7)
    n = 20_000
    cur = pdiode.read_A(np.full((n, 1), lux), chi, dop, angles, window, rng)
    est, _ = polarization_from_photodiodes(cur - pdiode.dark_level_A(window, rng, cur.shape),
                                           angles)
    err = (est - chi + 90.0) % 180.0 - 90.0
    i0 = pdiode.responsivity_A_per_lx * lux
    johnson = pdiode.sd_A(0.0, window) ** 2
    extra = 2 * johnson + 1.602176634e-19 * dark_A / window   # Johnson twice, dark estimate
    expected = four_photodiode_aop_sd_deg(i0, dark_A, dop, window, extra)
    assert np.std(err) == pytest.approx(expected, rel=0.03)


def test_aop_sd_scales_as_shot_and_dark_limits():
    # shot-noise limit: sd ~ 1/sqrt(I0); dark-current limit: sd ~ 1/I0 (closed form)
    sd = four_photodiode_aop_sd_deg
    assert sd(4e-12, 0.0, 0.5, 1.0) / sd(16e-12, 0.0, 0.5, 1.0) == pytest.approx(2.0, rel=1e-12)
    ratio = sd(1e-14, 50e-12, 0.5, 1.0) / sd(4e-14, 50e-12, 0.5, 1.0)
    assert ratio == pytest.approx(4.0, rel=1e-3)


def test_three_pair_heading_sd_is_inverse_in_illuminance_when_dark_limited():
    # log-ratio channels far below the dark level: U_k - U_k(0) ~ Ka/ln10 * I (...)/delta is
    # linear in I, the output noise is fixed, so the heading sd halves when I doubles (first
    # order). 4000 samples per level give each sd to 1.1 %; the ratio to 2 within 6 %.
    from calibration.dark_current import ChannelModel, solve_combined
    from sensor.photodiode import PhotodiodeChannels
    p = PhotodiodeChannels(dark_A=(20e-12, 60e-12, 30e-12, 80e-12, 25e-12, 70e-12))
    model = ChannelModel.from_photodiodes(p)
    rng = np.random.default_rng(11)
    phi = rng.uniform(-90.0, 90.0, 4000)
    sds = []
    for lux in (0.005, 0.01):
        U = p.outputs(lux, phi, 0.5) + 2e-5 * rng.standard_normal((phi.size, 3))
        est = solve_combined(U, model, 2e-5).phi_deg
        sds.append(np.std((est - phi + 90.0) % 180.0 - 90.0))
    assert sds[0] / sds[1] == pytest.approx(2.0, rel=0.06)


# --------------------------------------------------------------------------- reproduction
@pytest.fixture(scope="module")
def conditions():
    from experiments.studies.moonlit_compass import QUICK, night_conditions
    return night_conditions(QUICK)


def test_conditions_are_moonlit_nights(conditions):
    assert len(conditions) >= 3
    assert np.all(conditions.moon_elevation_deg > 0.0)
    m = moon_position(conditions.time, PARANAL.latitude_deg, PARANAL.longitude_deg,
                      PARANAL.altitude_m)
    np.testing.assert_allclose(m.phase_angle_deg, conditions.phase_angle_deg, atol=1e-9)
    from skysim.sun import sun_position
    s = sun_position(conditions.time, PARANAL.latitude_deg, PARANAL.longitude_deg,
                     PARANAL.altitude_m)
    assert np.all(s.elevation_deg < -18.0)
    # fuller Moon, brighter zenith at the same elevation
    near = conditions[np.abs(conditions.moon_elevation_deg - 20.0) < 5.0]
    order = np.argsort(near.phase_angle_deg.to_numpy())
    assert np.all(np.diff(near.zenith_lux_eq.to_numpy()[order]) < 0)


def test_zero_noise_limits_give_the_heading(conditions):
    from experiments.studies.moonlit_compass import (QUICK, camera_errors, night_camera,
                                                     ring_errors, three_pair_errors)
    cfg = replace(QUICK, three_pair_trials=1, ring_trials=4, camera_trials=1, camera_px=128)
    rng = np.random.default_rng(5)
    tp = three_pair_errors(conditions, cfg, rng, noise_free=True)
    assert np.max(np.abs(tp["three-pair true-parameters"])) < 1e-6
    assert np.max(np.abs(ring_errors(conditions, cfg, rng, window_s=np.inf))) < 1e-6
    # the camera without shot and read noise keeps its ADC quantisation: with 16 bits
    # (0.16 e- per DN, against the 12-bit default's 2.6 e- at signals of a few to tens of DN)
    # what is left is the demosaicing's field-of-view error, 0.011 deg at 128 px
    # (docs/camera.md) on a Rayleigh sky; 0.05 deg allowed for the saturated Moon's disk
    cam = night_camera(cfg, adc_bits=16)
    err, expo = camera_errors(conditions, cfg, rng, cam, noise_free=True)
    assert np.max(np.abs(err)) < 0.05
    assert np.all(expo <= cfg.window_s)


def test_run_is_reproducible_and_writes_outputs(tmp_path):
    from experiments.studies.moonlit_compass import QUICK, run
    cfg = replace(QUICK, night_step_days=8, elevations_deg=(30.0,), three_pair_trials=1,
                  ring_trials=3, camera_trials=1, camera_px=64, headings=6)
    a = run(cfg=cfg, seed=3, out=tmp_path / "a")
    b = run(cfg=cfg, seed=3)
    c = run(cfg=cfg, seed=4)
    cols = ["rms_error_deg", "mean_error_deg"]
    pd.testing.assert_frame_equal(a["table"][cols], b["table"][cols])
    assert not a["table"][cols].equals(c["table"][cols])
    for name in ("table.csv", "table.md", "conditions.csv", "summary.json",
                 "heading_vs_phase.png", "heading_vs_illuminance.png"):
        assert (tmp_path / "a" / name).stat().st_size > 0


# --------------------------------------------------------------------------- bad input
def test_moon_below_horizon_is_a_clear_error():
    sky = MoonlitSky(1e-6)
    with pytest.raises(MoonBelowHorizonError, match="-3"):
        sky.field(45.0, 0.0, -3.0, 100.0)
    assert issubclass(MoonBelowHorizonError, SunBelowHorizonError)
    with pytest.raises(MoonBelowHorizonError, match="below the horizon"):
        MoonlitSky.at("2024-06-06T05:00:00Z", PARANAL)   # new Moon: down at night
    with pytest.raises(MoonBelowHorizonError):
        moon_illuminance_lx(1e-6, -1.0)


def test_bad_inputs_name_the_value():
    with pytest.raises(ValueError, match="band 'V'"):
        lux_equivalent(1e-8, band="B")
    with pytest.raises(InvalidParameterError, match="radiance"):
        lux_equivalent(-1e-8)
    with pytest.raises(InvalidParameterError, match="moon_irradiance"):
        MoonlitSky(0.0)
    with pytest.raises(InvalidParameterError, match="f_number"):
        camera_photoelectron_rate(f_number=0.0)
    with pytest.raises(InvalidParameterError, match="window_s"):
        photocurrent_sd_A(1e-12, 0.0)
    with pytest.raises(InvalidParameterError, match="dark_A"):
        NightPhotodiode(dark_A=-1e-12)
    from experiments.studies.moonlit_compass import QUICK, night_conditions
    with pytest.raises(ValueError, match="no time"):
        night_conditions(replace(QUICK, start="2024-06-06T12:00:00Z",
                                 end="2024-06-07T12:00:00Z"))
