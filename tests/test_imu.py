"""IMU error model and platform trajectories (issue 6, part 1).

References: white rate noise has the Allan deviation ARW / sqrt(tau) (IEEE Std 952-1997,
Annex C); a first-order Gauss-Markov process has variance sigma^2 and autocorrelation
exp(-lag / tau) (Brown & Hwang, sect. 2.9); Euler-rate kinematics are checked against the
rotation increments of the attitude itself (an independent finite difference).
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sensor.compound_eye import GRAVITY_MPS2, PhotodiodeModel, patent_configuration
from sensor.imu import (
    AccelSpec,
    GyroSpec,
    ImuSpec,
    InvalidRateError,
    accel_measurements,
    allan_deviation,
    check_rate,
    gauss_markov,
    gyro_measurements,
)
from sensor.platform import (
    TrajectoryTooShortError,
    dynamic_trajectory,
    sample_run,
    static_trajectory,
)
from skysim.exceptions import InvalidParameterError, SunBelowHorizonError
from skysim.sky import RayleighSky
from skysim.sun import Site

SITE = Site(38.88, 121.53, name="Dalian")
START = "2018-05-25T17:10:46+08:00"


def test_white_noise_allan_deviation_matches_arw():
    """ADEV of white rate noise = ARW/60/sqrt(tau) [deg/s] (IEEE 952 Annex C). 1 h at 100 Hz,
    3 axes x 2 trials: ~21,600 s of data, so the relative 1-sigma of the overlapping ADEV at
    tau <= 10 s is below 1.5 %; tolerance 6 % (4 sigma)."""
    gyro = GyroSpec(bias_deg_s=0.0, bias_instability_deg_s=0.0, arw_deg_rt_h=0.3)
    spec = ImuSpec(gyro, AccelSpec(), 100.0)
    g, bias = gyro_measurements(np.zeros((360_000, 3)), spec, np.random.default_rng(1), 2)
    assert np.all(bias == 0.0)
    taus = np.array([0.1, 1.0, 10.0])
    adev = allan_deviation(g, 0.01, taus)
    expected = 0.3 / 60.0 / np.sqrt(taus)
    np.testing.assert_allclose(adev, np.broadcast_to(expected[:, None, None], adev.shape),
                               rtol=0.06)


def test_gauss_markov_variance_and_correlation():
    """Stationary variance sigma^2 and correlation exp(-lag/tau) (Brown & Hwang 2.9): 4000
    independent sequences; the sample variance has relative 1-sigma sqrt(2/4000) = 2.2 %
    (tolerance 9 %), the correlation 1-sigma ~ 0.014 (tolerance 0.05)."""
    x = gauss_markov((4000, 1), 201, 0.5, 1.0, 0.01, np.random.default_rng(2))[..., 0]
    assert x.shape == (4000, 201)
    np.testing.assert_allclose(x[:, [0, 100, 200]].var(axis=0), 0.25, rtol=0.09)
    rho = np.corrcoef(x[:, 0], x[:, 100])[0, 1]
    assert abs(rho - np.exp(-1.0)) < 0.05


def test_turn_on_bias_is_recovered_by_averaging():
    """A given turn-on bias appears in the readings: the time mean of (reading - truth) over
    100 s equals the bias within the white + Gauss-Markov noise of the mean (< 3e-4 deg/s:
    GM sigma 0.002 deg/s with tau = 100 s averages only partly, so use 5 sigma of it)."""
    spec = ImuSpec()
    rate = np.tile([1.0, -2.0, 3.0], (10_001, 1))
    b0 = np.array([0.02, -0.01, 0.005])
    g, bias = gyro_measurements(rate, spec, np.random.default_rng(3), bias_deg_s=b0)
    assert g.shape == (10_001, 3)
    assert np.all(np.abs((g - rate).mean(axis=0) - b0) < 5 * spec.gyro.bias_instability_deg_s)
    np.testing.assert_allclose(bias.mean(axis=0), (g - rate).mean(axis=0), atol=1e-3)


def test_accelerometer_at_rest_reads_gravity_up():
    """Specific force at rest = +g along body up; mean over 10^4 samples within 5 sigma of the
    noise of the mean plus the drawn bias (1-sigma 0.005 m/s^2, so 0.03 m/s^2 is > 5 sigma)."""
    traj = static_trajectory(START, 100.0, 100.0, yaw_deg=30.0, pitch_deg=10.0, roll_deg=-5.0)
    f = accel_measurements(traj.up_body(), ImuSpec(), np.random.default_rng(4))
    expected = GRAVITY_MPS2 * Rotation.from_euler("ZXY", [-30, 10, -5], degrees=True).inv().apply(
        [0.0, 0.0, 1.0])
    np.testing.assert_allclose(f.mean(axis=0), expected, atol=0.03)


@pytest.mark.parametrize("rate", [0.0, -100.0, float("nan"), float("inf")])
def test_bad_rates_are_rejected(rate):
    with pytest.raises(InvalidRateError, match="rate > 0 Hz"):
        check_rate("sample_rate_hz", rate)
    with pytest.raises(InvalidRateError, match="nan" if np.isnan(rate) else repr(rate)):
        ImuSpec(sample_rate_hz=rate)
    with pytest.raises(InvalidRateError):
        static_trajectory(START, 10.0, rate)


@given(st.floats(-1e6, 0.0))
@settings(max_examples=25, deadline=None)
def test_nonpositive_rates_always_rejected(rate):
    with pytest.raises(InvalidRateError):
        GyroSpec().white_noise_deg_s(rate)


def test_negative_noise_parameters_are_rejected():
    with pytest.raises(InvalidParameterError, match="arw_deg_rt_h"):
        GyroSpec(arw_deg_rt_h=-0.1)
    with pytest.raises(InvalidParameterError, match="bias_correlation_s"):
        GyroSpec(bias_correlation_s=0.0)
    with pytest.raises(InvalidParameterError, match="noise_mps2"):
        AccelSpec(noise_mps2=-1.0)


def test_dynamic_trajectory_body_rate_matches_rotation_increments():
    """Closed-form Euler-rate kinematics vs the attitude's own increments: the central
    difference rotvec(R_k^T R_k+1)/dt approximates the mean of the end-point rates to
    O(dt^2 |omega''|) ~ 1e-4 deg/s for these motions; tolerance 1e-3 deg/s (peak rates ~14 deg/s,
    so a sign or axis error would show as > 1 deg/s)."""
    traj = dynamic_trajectory(START, 30.0, 100.0, yaw0_deg=10.0, yaw_rate_deg_s=2.0)
    fd = traj.mean_rate_deg_s()[:-1]
    mid = 0.5 * (traj.rate_body_deg_s[:-1] + traj.rate_body_deg_s[1:])
    np.testing.assert_allclose(fd, mid, atol=1e-3)
    assert np.abs(traj.rate_body_deg_s).max() > 5.0          # moves about all axes
    assert np.all(np.abs(traj.rate_body_deg_s).max(axis=0) > 3.0)


def test_dynamic_trajectory_angles_round_trip():
    """The attitude reproduces the commanded sinusoids (exact up to rounding)."""
    traj = dynamic_trajectory(START, 20.0, 50.0, yaw0_deg=30.0, amplitude_deg=(40, 10, 15),
                              period_s=(20, 8, 6), phase_deg=(0, 0, 0))
    yaw, pitch, roll = traj.angles_deg()
    t = traj.t_s
    np.testing.assert_allclose(np.mod(yaw - (30 + 40 * np.sin(2 * np.pi * t / 20)) + 180, 360)
                               - 180, 0.0, atol=1e-9)
    np.testing.assert_allclose(pitch, 10 * np.sin(2 * np.pi * t / 8), atol=1e-9)
    np.testing.assert_allclose(roll, 15 * np.sin(2 * np.pi * t / 6), atol=1e-9)


def test_static_trajectory_is_at_rest():
    traj = static_trajectory(START, 5.0, 100.0, 45.0, 3.0, -2.0)
    assert traj.n == 501
    assert np.all(traj.rate_body_deg_s == 0.0)
    np.testing.assert_allclose(traj.mean_rate_deg_s(), 0.0, atol=1e-12)
    yaw, pitch, roll = traj.angles_deg()
    np.testing.assert_allclose([yaw[-1], pitch[-1], roll[-1]], [45.0, 3.0, -2.0], atol=1e-9)


def test_trajectory_too_short_is_rejected():
    with pytest.raises(TrajectoryTooShortError, match="duration_s"):
        static_trajectory(START, 0.0)
    traj = static_trajectory(START, 0.05, 100.0)          # 6 samples < one 10-sample update
    with pytest.raises(TrajectoryTooShortError, match="fewer than one update"):
        sample_run(traj, patent_configuration(), RayleighSky(0.7), SITE, ImuSpec(),
                   np.random.default_rng(0), 1, polarization_every=10)


def test_sample_run_shapes_and_rayleigh_geometry():
    """Sampled along a dynamic trajectory: the noise-free unit E-vectors are perpendicular to
    the sun in the body frame (Rayleigh single scattering, exact up to rounding), and the
    trials differ only by noise."""
    traj = dynamic_trajectory(START, 3.0, 100.0)
    sensor = patent_configuration(photodiode=PhotodiodeModel(noise_counts=50.0))
    run = sample_run(traj, sensor, RayleighSky(0.7), SITE, ImuSpec(), np.random.default_rng(5),
                     n_trials=4, polarization_every=10)
    K = len(run.pol_index)
    assert K == 31 and run.readings.shape == (4, K, 54) and run.gyro_deg_s.shape == (4, 301, 3)
    sun_b = traj.attitude[run.pol_index].inv().apply(run.sun_enu)
    dots = np.einsum("kmi,ki->km", run.truth.e_vector_sensor, sun_b)
    assert np.abs(dots).max() < 1e-12
    assert not np.allclose(run.readings[0], run.readings[1])


def test_sample_run_sun_below_horizon():
    traj = static_trajectory("2018-05-25T22:00:00+08:00", 1.0, 100.0)
    with pytest.raises(SunBelowHorizonError, match="twilight limit"):   # sun at -25 deg
        sample_run(traj, patent_configuration(), RayleighSky(0.7), SITE, ImuSpec(),
                   np.random.default_rng(0))
