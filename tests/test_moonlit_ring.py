"""The ring diagnosis under the moonlit night sky: the Moon takes the Sun's place
(``light="moon"``), checked blind on ring sessions the sensor simulator draws under
:class:`skysim.night.MoonlitSky`."""

import numpy as np
import pandas as pd
import pytest
from ring_sessions import SITE

from calibration import diagnose
from calibration.diagnosis import UnsupportedInstrumentError
from calibration.photodiode_diagnosis import (
    InstrumentDataError,
    SunTooLowError,
    diagnose_photodiodes,
)
from sensor.compound_eye import PhotodiodeModel, ring_configuration
from sensor.photodiodes_io import PhotodiodeData

pytest.importorskip("astropy", reason="the Moon's ephemeris needs astropy (extra skysim[moon])")

from skysim.moon import MoonTrack, moon_position, moon_vector
from skysim.night import MoonlitSky

NIGHT = "2022-05-15T00:30:00+02:00"
"""Moon 98 % lit at 37 deg, Sun at -31 deg (the Gkanias et al. 2023 site, two nights before
full Moon)."""


def moonlit_session(start=NIGHT, seed=4, n_sweeps=3, per_sweep=90):
    """A relative-yaw ring session under the moonlit sky, its ADC gain set for moonlight (the
    sky's radiance is ~1e-6 W m-2 nm-1 sr-1; a night-time transimpedance gain)."""
    t0 = pd.Timestamp(start)
    sky, _ = MoonlitSky.at(t0, SITE)
    level = float(np.mean(sky.field(45.0, np.arange(0.0, 360.0, 45.0), 37.0, 184.0).I))
    sensor = ring_configuration(8, 45.0, photodiode=PhotodiodeModel(
        counts_per_radiance=20_000.0 / level))
    times = pd.DatetimeIndex([t0 + pd.Timedelta(seconds=60 * s + 0.1 * k)
                              for s in range(n_sweeps) for k in range(per_sweep)])
    yaw = np.tile(np.linspace(0.0, 360.0, per_sweep, endpoint=False), n_sweeps) + 20.0
    data = sensor.sample(sky, SITE, times, yaw, 0.0, 0.0, np.random.default_rng(seed),
                         yaw_reference="relative", yaw_offset_deg=35.0, include_truth=False,
                         sweep=np.repeat(np.arange(n_sweeps), per_sweep), source="moon")
    t = data.table.drop(columns=["pitch_deg", "roll_deg"])
    t["yaw_deg"] = -(((t["yaw_deg"] + 180.0) % 360.0) - 180.0)
    return PhotodiodeData(t, dict(data.sidecar, yaw_sense="counterclockwise"))


def test_moon_track_matches_the_ephemeris_between_knots():
    """Linear interpolation between 60-s knots renormalised: the Moon moves < 0.25 deg/min,
    so the sagitta error is < 1e-4 deg (as the Sun's track)."""
    t0 = pd.Timestamp(NIGHT)
    track = MoonTrack(SITE, t0.timestamp(), t0.timestamp() + 600.0, margin_s=0.0)
    times = t0 + pd.to_timedelta([17.3, 211.9, 433.1], unit="s")
    exact, _ = moon_vector(times, SITE)
    got = track(np.array([t.timestamp() for t in times]))
    ang = np.degrees(np.arccos(np.clip(np.sum(exact * got, axis=1), -1, 1)))
    assert np.all(ang < 1e-4)
    el = moon_position(times, SITE.latitude_deg, SITE.longitude_deg).elevation_deg
    np.testing.assert_allclose(track.elevation_azimuth(
        np.array([t.timestamp() for t in times]))[0], el, atol=1e-4)


def test_moonlit_session_diagnosed_with_the_moon_as_the_light():
    """The moonlit sky (Krisciunas & Schaefer 1991) is moonlight scattered by molecules,
    polarized in the Rayleigh pattern about the Moon, plus aerosol forward scattering,
    unpolarized and bright within a few tens of degrees of the Moon, over the night sky's own
    light. With the Moon in the Sun's place the base model reads the AoP right (heading
    error of the base a few hundredths of a degree) and the gap lies in the DoP near the
    Moon, where the aerosol light lowers it: 30-60 deg from the Moon carries a larger
    residual than 60-120 deg."""
    rep = diagnose(moonlit_session(), ("fov",), light="moon")
    assert rep.extra["heading_error"]["base_deg"] < 0.1
    # against the second-difference RMS: the glow near the Moon leaves residuals that are
    # not white reading to reading, so the report's floor may be unknown
    assert rep.verdict.gap_before > 2 * rep.extra["noise_floor_parts"]["white_noise_rms"]
    rms = {w.label: w.rms for w in rep.where if w.dimension == "sun_distance_deg"}
    assert rms["30-60"] > max(rms["60-90"], rms["90-120"])


def test_the_sun_in_place_of_the_moon_is_refused():
    """Diagnosed as sunlit, the night session is refused: the Sun is at -31 deg."""
    with pytest.raises(SunTooLowError, match="twilight limit"):
        diagnose_photodiodes(moonlit_session(), ("fov",))


def test_moonlit_needs_the_moon_up_and_the_sun_down():
    day = moonlit_session().table.copy()
    day["time"] = day["time"] + pd.Timedelta(hours=12)     # Moon set, Sun up
    side = moonlit_session().sidecar
    with pytest.raises(SunTooLowError, match="Moon is at"):
        diagnose_photodiodes(PhotodiodeData(day, side), ("fov",), light="moon")
    dusk = moonlit_session().table.copy()
    dusk["time"] = dusk["time"] - pd.Timedelta(hours=3.5)   # Moon up, Sun in twilight
    with pytest.raises(InstrumentDataError, match="twilight, not moonlight"):
        diagnose_photodiodes(PhotodiodeData(dusk, side), ("fov",), light="moon")
    with pytest.raises(InstrumentDataError, match="light must be one of"):
        diagnose_photodiodes(moonlit_session(), ("fov",), light="stars")


def test_moon_light_is_for_ring_instruments_only():
    from experiments.workflows.diagnose import simulate_session
    ds = simulate_session(None, np.random.default_rng(1))
    with pytest.raises(UnsupportedInstrumentError, match="light='moon'"):
        diagnose(ds["data"], ("tilt",), light="moon")
