"""Installation-error calibration (the patent's three steps): round trips, uncertainty,
observability."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.exceptions import CalibrationError, TooFewSamplesError
from calibration.installation import (SaturatedUnitError, UnobservableError,
                                      attitude_from_data, attitude_from_sun_gravity,
                                      calibrate_installation, estimate_body_installation,
                                      estimate_unit_installation, sun_vector_sensor)
from sensor.photodiodes_io import PhotodiodeData
from sensor.compound_eye import (attitude_angles, body_attitude, patent_configuration,
                                 with_random_installation_errors)
from skysim.geometry import angle_between_deg
from skysim.sky import RayleighSky
from skysim.sun import Site, sun_vector

SITE = Site(39.98, 116.35, 50.0)
SKY = RayleighSky(0.7)
UP = np.array([0.0, 0.0, 1.0])


def _geometry(n, rng, tilt_deg=10.0, same_attitude=False):
    times = pd.date_range("2020-06-15T13:00+08:00", "2020-06-15T17:00+08:00", periods=n)
    if same_attitude:
        times = pd.DatetimeIndex([times[-1]] * n)   # 17:00: the zenith is well polarized
        yaw, pitch, roll = np.full(n, 37.0), np.full(n, 3.0), np.full(n, -2.0)
    else:
        yaw = rng.uniform(0, 360, n)
        pitch, roll = rng.uniform(-tilt_deg, tilt_deg, (2, n))
    return times, yaw, pitch, roll


def _exact_inputs(sensor, n, rng, **kw):
    times, yaw, pitch, roll = _geometry(n, rng, **kw)
    sun = sun_vector(times, SITE)[0]
    att = body_attitude(yaw, pitch, roll)
    obs = sensor.observe(SKY, att, sun)
    return sun, att, obs


def _noisy(sensor, n, rng, **kw):
    times, yaw, pitch, roll = _geometry(n, rng, **kw)
    return sensor.sample(SKY, SITE, times, yaw, pitch, roll, rng, attitude_noise_deg=0.1,
                         accel_noise_mps2=0.01)


@pytest.fixture
def sensor(rng):
    return with_random_installation_errors(patent_configuration(), 1.0, rng)


def test_step1_recovers_body_error_exactly(sensor, rng):
    sun, att, obs = _exact_inputs(sensor, 60, rng)
    est = estimate_body_installation(obs.e_vector_sensor[:, 0], att, sun)
    # exact data: only the Gauss-Newton stopping rule (1e-9 deg) limits the agreement
    np.testing.assert_allclose(est.rotvec_deg, sensor.installation_error_deg, atol=1e-7)
    assert est.residual_rms < 1e-10


def test_step2_sun_in_sensor_frame(sensor, rng):
    sun, att, obs = _exact_inputs(sensor, 40, rng)
    truth = (att * sensor.body_installation()).inv().apply(sun)
    est, quality = sun_vector_sensor(obs.e_vector_sensor, obs.dop)
    assert angle_between_deg(est, truth).max() < 1e-6     # exact E-vectors: only round-off
    assert quality.max() < 1e-12


def test_step3_recovers_unit_errors_exactly(sensor, rng):
    sun, att, obs = _exact_inputs(sensor, 80, rng)
    up_s = (att * sensor.body_installation()).inv().apply(UP)
    chi = np.radians(obs.aop_unit_deg[:, 1:])
    e_unit = np.stack([np.cos(chi), np.sin(chi), np.zeros_like(chi)], axis=-1)
    ests = estimate_unit_installation(obs.e_vector_sensor[:, 0], e_unit,
                                      sensor.unit_matrices(False)[1:], up_s,
                                      np.degrees(np.arcsin(sun[:, 2])))
    got = np.array([e.rotvec_deg for e in ests])
    want = np.array([u.installation_error_deg for u in sensor.units[1:]])
    # the numerical Jacobian only changes the path, not the fixed point: exact to ~1e-7 deg
    np.testing.assert_allclose(got, want, atol=1e-6)


@settings(max_examples=30, deadline=None)
@given(st.floats(0, 359), st.floats(-30, 30), st.floats(-30, 30), st.floats(5, 80),
       st.floats(0, 359))
def test_triad_returns_the_attitude(yaw, pitch, roll, sun_el, sun_az):
    att = body_attitude(yaw, pitch, roll)
    sun_enu = np.array([[np.cos(np.radians(sun_el)) * np.sin(np.radians(sun_az)),
                         np.cos(np.radians(sun_el)) * np.cos(np.radians(sun_az)),
                         np.sin(np.radians(sun_el))]])
    est = attitude_from_sun_gravity(att.inv().apply(sun_enu), att.inv().apply(UP)[None],
                                    sun_enu)
    assert np.degrees((est * att.inv()).magnitude()[0]) < 1e-6


def test_noisy_calibration_meets_goal_and_uncertainty_is_honest(rng):
    """0.1 deg reference, accelerometer 0.01 m/s^2, 16-bit photodiodes, 300 attitudes.

    Goal of the issue: <= 0.05 deg RMS per axis. Honesty of the reported 1-sigma: over 6
    sensors x 9 fitted rotations x 3 axes (162 numbers) the normalised errors must have an RMS
    in [0.7, 1.4] (sqrt(chi^2/162) lies within 0.89-1.11 at 95 % for independent numbers; the
    27 numbers of one sensor share its attitudes and its phi_1 error, which widens the spread:
    over seeds 0-4 we measured 0.84-1.10)."""
    z, err = [], []
    for _ in range(6):
        sensor = with_random_installation_errors(patent_configuration(), 1.0, rng)
        cal = calibrate_installation(_noisy(sensor, 300, rng))
        truth = [sensor.installation_error_deg] + [u.installation_error_deg
                                                   for u in sensor.units[1:]]
        for est, want in zip([cal.body] + cal.units, truth):
            err.append(est.rotvec_deg - want)
            z.append((est.rotvec_deg - want) / est.std_deg)
    err, z = np.array(err), np.array(z)
    assert np.sqrt(np.mean(err ** 2, axis=0)).max() <= 0.05
    assert 0.7 <= np.sqrt(np.mean(z ** 2)) <= 1.4
    assert np.abs(z).max() < 4.5        # 162 normal draws: P(max |z| > 4.5) ~ 1e-3


def test_compensation_improves_heading(sensor, rng):
    cal = calibrate_installation(_noisy(sensor, 300, rng))
    test = _noisy(sensor, 200, rng)
    true_yaw = test.table["true_yaw_deg"].to_numpy()

    def heading_rms(s):
        yaw = attitude_angles(attitude_from_data(test, s)[0])[0]
        return np.sqrt(np.mean((np.mod(yaw - true_yaw + 180, 360) - 180) ** 2))

    unc, comp, ideal = heading_rms(sensor.nominal()), heading_rms(cal.sensor), heading_rms(sensor)
    assert unc > 0.3                 # up to 1 deg per axis of installation error is visible
    assert comp < 0.2 and comp < 1.2 * ideal + 0.01   # near the noise floor of the instrument


def test_one_attitude_leaves_axes_unobservable(sensor, rng):
    sun, att, obs = _exact_inputs(sensor, 30, rng, same_attitude=True)
    e = obs.e_vector_sensor[:, 0] + 1e-4 * rng.standard_normal((30, 3))  # noise: not exact rank
    with pytest.raises(UnobservableError, match="phi_1 is not observable") as exc:
        estimate_body_installation(e, att, sun)
    assert exc.value.axes.shape[0] == 2          # null space: rotations about the sun and E
    assert "the sun direction" in exc.value.named and "the E-vector" in exc.value.named


def test_two_yaws_leave_one_axis_unobservable(sensor, rng):
    """With two attitudes the rows e x s span a plane; the unobservable axis is its normal."""
    sun, att, obs = _exact_inputs(sensor, 2, rng)
    e = np.repeat(obs.e_vector_sensor[:, 0], 5, axis=0)
    sun, att = np.repeat(sun, 5, axis=0), att[np.repeat([0, 1], 5)]
    with pytest.raises(UnobservableError) as exc:
        estimate_body_installation(e, att, sun)
    s_b = att.inv().apply(sun)
    normal = np.cross(np.cross(e[0], s_b[0]), np.cross(e[5], s_b[5]))
    assert exc.value.axes.shape[0] == 1
    assert abs(np.dot(exc.value.axes[0], normal / np.linalg.norm(normal))) > 1 - 1e-9


def test_too_few_attitudes_and_unit_unobservable(sensor, rng):
    sun, att, obs = _exact_inputs(sensor, 2, rng)
    with pytest.raises(TooFewSamplesError, match="2 usable sample"):
        estimate_body_installation(obs.e_vector_sensor[:, 0], att, sun)
    data = _noisy(sensor, 40, rng, same_attitude=True)
    with pytest.raises(UnobservableError, match="not observable"):
        calibrate_installation(data)


def test_saturated_unit_and_flagged_samples(sensor, rng):
    data = _noisy(sensor, 200, rng)
    sat = data.sidecar["saturation_value"]
    table = data.table.copy()
    table.loc[:9, [c for c in data.columns if c.startswith("u5_")]] = sat   # 10 flagged samples
    partial = calibrate_installation(PhotodiodeData(table.copy(), data.sidecar))
    assert partial.valid_fraction[5] <= 190 / 200          # flagged samples are not used
    assert np.all(np.abs(partial.units[4].rotvec_deg
                         - sensor.units[5].installation_error_deg) < 5 * partial.units[4].std_deg)
    table[[c for c in data.columns if c.startswith("u3_")]] = sat
    with pytest.raises(SaturatedUnitError, match="unit 3 are saturated"):
        calibrate_installation(PhotodiodeData(table, data.sidecar))


def test_relative_yaw_cannot_give_step1(rng):
    ring_data = patent_configuration().sample(
        SKY, SITE, pd.date_range("2020-06-15T14:00+08:00", periods=10, freq="1min"),
        np.arange(10) * 36.0, 0.0, 0.0, rng, yaw_reference="relative", yaw_offset_deg=12.0)
    with pytest.raises(CalibrationError, match="yaw_reference='relative'"):
        calibrate_installation(ring_data)


def test_opponent_and_stokes_extraction_agree(sensor, rng):
    data = _noisy(sensor, 300, rng)
    truth = [sensor.installation_error_deg] + [u.installation_error_deg for u in sensor.units[1:]]
    for method in ("stokes", "opponent"):   # opponent: pairs U1, U2 only (4 of 6 photodiodes)
        cal = calibrate_installation(data, method=method)
        for est, want in zip([cal.body] + cal.units, truth):
            assert np.all(np.abs(est.rotvec_deg - want) < 4 * est.std_deg)


def test_ring_with_relative_yaw_gets_its_north_offset(rng):
    """45-deg ring, four photodiodes per unit, relative yaw, level platform without an
    accelerometer: the sky alone gives the north offset of the yaw readings. Tolerance: the
    sun direction from 8 units at ~3 counts noise on ~2e4 is good to a few 0.01 deg per sample;
    0.05 deg covers 5 sigma of the mean over 60 samples with a comfortable margin."""
    from sensor.compound_eye import ring_configuration
    from calibration.installation import yaw_offset_from_sky
    ring = ring_configuration(8, 45.0)
    times = pd.date_range("2020-06-15T15:00+08:00", periods=60, freq="5s")
    data = ring.sample(SKY, SITE, times, np.linspace(0, 354, 60), 0.0, 0.0, rng,
                       yaw_reference="relative", yaw_offset_deg=123.4)
    from sensor.photodiodes_io import ACCEL_COLUMNS
    data = PhotodiodeData(data.table.drop(columns=list(ACCEL_COLUMNS)), data.sidecar)
    offset, se = yaw_offset_from_sky(data)
    assert abs(offset - 123.4) < 0.05
    assert se < 0.02


def test_step3_one_attitude_names_the_unit(sensor, rng):
    """One attitude gives one scalar per unit: two of its three axes cannot be seen."""
    sun, att, obs = _exact_inputs(sensor, 20, rng, same_attitude=True)
    chi = np.radians(obs.aop_unit_deg[:, 1:3] + 1e-3 * rng.standard_normal((20, 2)))
    e_unit = np.stack([np.cos(chi), np.sin(chi), np.zeros_like(chi)], axis=-1)
    up_s = (att * sensor.body_installation()).inv().apply(UP)
    with pytest.raises(UnobservableError, match="installation error of unit 1 is not") as exc:
        estimate_unit_installation(obs.e_vector_sensor[:, 0], e_unit,
                                   sensor.unit_matrices(False)[1:3], up_s,
                                   np.degrees(np.arcsin(sun[:, 2])),
                                   unit_labels=["unit 1", "unit 2"])
    assert exc.value.axes.shape[0] == 2 and exc.value.frame == "unit 1"
