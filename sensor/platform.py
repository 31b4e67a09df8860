"""Carrier trajectories (true attitude over time) and the sensors sampled along them.

A :class:`Trajectory` holds the true body-to-ENU attitude ``R_nb`` (scipy ``Rotation``) and
the body angular rate at every IMU sample. Attitude angles follow :func:`sensor.compound_eye.
body_attitude`: ``R_nb = Rz(-yaw) Rx(pitch) Ry(roll)`` (yaw clockwise from north, pitch nose
up, roll right side down). For Euler angles ``(psi = -yaw, theta = pitch, phi = roll)`` in this
z-x-y order the body rate is the sum of the three Euler rates, each carried into the body
frame by the rotations that follow it ([1]_ sect. 2.6)::

    omega_b = Ry(phi)^T Rx(theta)^T (0, 0, psi') + Ry(phi)^T (theta', 0, 0) + (0, phi', 0)

:func:`dynamic_trajectory` gives smooth sinusoidal motion about all three axes with closed-form
Euler rates, so the gyro's true input is exact (no numerical differentiation). The platform
rotates about the IMU, so the accelerometer senses gravity only (no lever arm).

:func:`sample_run` samples the IMU (every sample) and the polarization sensor (every
``polarization_every``-th sample) along a trajectory for many independent trials at once.

References
----------
.. [1] P. D. Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
   Systems*, 2nd ed., Artech House (2013), sect. 2.2.1 and 2.6 (Euler rates).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from skysim.exceptions import InvalidParameterError
from skysim.sky import Sky
from skysim.sun import Site, as_utc_index, sun_vector
from skysim.validation import check_finite

from .compound_eye import CompoundEyeSensor, SkySample, attitude_angles, body_attitude
from .imu import ImuSpec, accel_measurements, check_rate, gyro_measurements

__all__ = ["TrajectoryTooShortError", "Trajectory", "static_trajectory", "dynamic_trajectory",
           "euler_rates_to_body_rate", "RunData", "sample_run"]


class TrajectoryTooShortError(InvalidParameterError):
    """A trajectory holds fewer samples than one estimator update needs."""


@dataclass(frozen=True)
class Trajectory:
    """True carrier motion sampled at the IMU rate.

    Attributes
    ----------
    times : DatetimeIndex (UTC), length n
    attitude : Rotation of length n, body-to-ENU ``R_nb``
    rate_body_deg_s : (n, 3) true instantaneous body angular rate [deg/s] (the gyro reads the
        interval mean, :meth:`mean_rate_deg_s`)
    sample_rate_hz : float
    """

    times: pd.DatetimeIndex
    attitude: Rotation
    rate_body_deg_s: np.ndarray
    sample_rate_hz: float

    @property
    def n(self) -> int:
        return len(self.times)

    @property
    def t_s(self) -> np.ndarray:
        """Seconds since the first sample."""
        return np.arange(self.n) / self.sample_rate_hz

    def angles_deg(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """True ``(yaw, pitch, roll)`` [deg]."""
        return attitude_angles(self.attitude)

    def mean_rate_deg_s(self) -> np.ndarray:
        """Mean body rate over each sample interval [deg/s], (n, 3): ``rotvec(R_j^T R_j+1) / dt``.

        What a strapdown gyro reports (its delta angle over the sample period divided by the
        period); composing these increments reproduces the attitude exactly, without the
        coning error that sampling the instantaneous rate would add. The last sample repeats
        the previous interval.
        """
        if self.n < 2:
            return np.zeros((self.n, 3))
        inc = (self.attitude[:-1].inv() * self.attitude[1:]).as_rotvec(degrees=True)
        return np.vstack([inc, inc[-1:]]) * self.sample_rate_hz

    def up_body(self) -> np.ndarray:
        """ENU up in the body frame, (n, 3)."""
        return self.attitude.inv().apply(np.array([0.0, 0.0, 1.0])).reshape(-1, 3)


def _times(start, duration_s: float, sample_rate_hz: float) -> pd.DatetimeIndex:
    fs = check_rate("sample_rate_hz", sample_rate_hz)
    duration_s = float(check_finite("duration_s", duration_s))
    if duration_s <= 0.0:
        raise TrajectoryTooShortError(f"duration_s must be > 0 s; got {duration_s!r}. Give the "
                                      "run length in seconds")
    n = int(np.floor(duration_s * fs + 1e-9)) + 1
    t0 = as_utc_index([start])[0]
    return t0 + pd.to_timedelta(np.arange(n) / fs, unit="s")


def euler_rates_to_body_rate(yaw_deg, pitch_deg, roll_deg, yaw_rate, pitch_rate,
                             roll_rate) -> np.ndarray:
    """Body angular rate (n, 3) from the angles [deg] and their rates (any unit, e.g. deg/s)
    of :func:`sensor.compound_eye.body_attitude` (module equation, [1]_ sect. 2.6)."""
    zero = np.zeros_like(np.asarray(yaw_rate, float))
    after_x = body_attitude(0.0, pitch_deg, roll_deg)            # Rx(theta) Ry(phi)
    after_y = body_attitude(0.0, 0.0, roll_deg)                  # Ry(phi)
    w = after_x.inv().apply(np.stack([zero, zero, -np.asarray(yaw_rate, float)], axis=-1))
    w += after_y.inv().apply(np.stack([np.asarray(pitch_rate, float), zero, zero], axis=-1))
    w[..., 1] += roll_rate
    return w.reshape(-1, 3)


def static_trajectory(start, duration_s: float, sample_rate_hz: float = 100.0,
                      yaw_deg: float = 0.0, pitch_deg: float = 0.0,
                      roll_deg: float = 0.0) -> Trajectory:
    """A carrier at rest at the given attitude [deg] for ``duration_s`` [s]."""
    times = _times(start, duration_s, sample_rate_hz)
    n = len(times)
    att = body_attitude(np.full(n, float(yaw_deg)), pitch_deg, roll_deg)
    return Trajectory(times, att, np.zeros((n, 3)), float(sample_rate_hz))


def dynamic_trajectory(start, duration_s: float, sample_rate_hz: float = 100.0,
                       yaw0_deg: float = 0.0, yaw_rate_deg_s: float = 0.0,
                       amplitude_deg=(90.0, 15.0, 20.0), period_s=(40.0, 12.0, 9.0),
                       phase_deg=(0.0, 30.0, 60.0)) -> Trajectory:
    """Rotations about all three axes: ``angle_i(t) = A_i sin(2 pi t / P_i + p_i)``.

    Yaw additionally grows at ``yaw_rate_deg_s`` from ``yaw0_deg``. The defaults (yaw +-90 deg
    over 40 s, pitch +-15 deg over 12 s, roll +-20 deg over 9 s) give peak rates of about 14,
    8 and 14 deg/s: a manoeuvring land vehicle or a hand-carried instrument.

    Parameters
    ----------
    amplitude_deg, period_s, phase_deg : 3 floats each, order (yaw, pitch, roll)
        Amplitudes [deg], periods [s] (> 0) and phases [deg].
    """
    times = _times(start, duration_s, sample_rate_hz)
    t = np.arange(len(times)) / float(sample_rate_hz)
    A = np.asarray(check_finite("amplitude_deg", amplitude_deg), float).reshape(3)
    P = np.asarray(check_finite("period_s", period_s), float).reshape(3)
    if np.any(P <= 0.0):
        raise InvalidParameterError(f"period_s must be > 0 s for every axis; got {P.tolist()}")
    if abs(A[1]) >= 90.0:
        raise InvalidParameterError(f"pitch amplitude {A[1]} deg must be < 90 deg "
                                    "(the z-x-y Euler angles are singular at pitch +-90)")
    w = 2.0 * np.pi / P
    arg = w[None, :] * t[:, None] + np.radians(np.asarray(phase_deg, float))[None, :]
    ang = A * np.sin(arg)
    rate = A * w * np.cos(arg)                       # d angle / dt [deg/s]
    yaw = yaw0_deg + yaw_rate_deg_s * t + ang[:, 0]
    att = body_attitude(yaw, ang[:, 1], ang[:, 2])
    omega = euler_rates_to_body_rate(yaw, ang[:, 1], ang[:, 2], yaw_rate_deg_s + rate[:, 0],
                                     rate[:, 1], rate[:, 2])
    return Trajectory(times, att, omega, float(sample_rate_hz))


@dataclass(frozen=True)
class RunData:
    """Everything the sensors recorded along one trajectory, for ``S`` trials.

    Attributes
    ----------
    trajectory : Trajectory (IMU rate, n samples)
    gyro_deg_s : (S, n, 3) gyro readings [deg/s]; gyro_bias_deg_s : (S, n, 3) true bias
    accel_mps2 : (S, n, 3) specific force [m/s^2]
    pol_index : (K,) IMU sample index of each polarization sample
    sun_enu : (K, 3) ephemeris sun at the polarization samples
    readings : (S, K, P) photodiode readings [counts]; photodiode_names : (P,)
    truth : SkySample (K, m) noise-free sky seen by the units
    """

    trajectory: Trajectory
    gyro_deg_s: np.ndarray
    gyro_bias_deg_s: np.ndarray
    accel_mps2: np.ndarray
    pol_index: np.ndarray
    sun_enu: np.ndarray
    readings: np.ndarray
    photodiode_names: list
    truth: SkySample

    @property
    def n_trials(self) -> int:
        return self.gyro_deg_s.shape[0]


def sample_run(trajectory: Trajectory, sensor: CompoundEyeSensor, sky: Sky, site: Site,
               imu: ImuSpec, rng: np.random.Generator, n_trials: int = 1,
               polarization_every: int = 10) -> RunData:
    """Sample the IMU and the polarization sensor along ``trajectory`` for ``n_trials`` trials.

    The sky (and so the noise-free E-vectors) is the same for all trials; the IMU errors and
    the photodiode noise are drawn independently per trial (vectorised).

    Parameters
    ----------
    polarization_every : int
        The polarization sensor samples every k-th IMU sample (100 Hz IMU, k = 10: 10 Hz).

    Raises
    ------
    SunBelowHorizonError
        If the sun is below the horizon at some sample (from the sky model).
    UnitBelowHorizonError
        If a unit looks below the horizon at some attitude.
    """
    if imu.sample_rate_hz != trajectory.sample_rate_hz:
        raise InvalidParameterError(
            f"IMU sample rate {imu.sample_rate_hz} Hz differs from the trajectory's "
            f"{trajectory.sample_rate_hz} Hz; build the trajectory at the IMU rate")
    k = int(polarization_every)
    if k < 1:
        raise InvalidParameterError(f"polarization_every must be an integer >= 1; got {k}")
    if trajectory.n < k + 1:
        raise TrajectoryTooShortError(
            f"the trajectory has {trajectory.n} IMU samples, fewer than one update interval "
            f"needs ({k + 1} at polarization_every={k}); make it longer than "
            f"{k / trajectory.sample_rate_hz} s")
    gyro, bias = gyro_measurements(trajectory.mean_rate_deg_s(), imu, rng, n_trials)
    accel = accel_measurements(trajectory.up_body(), imu, rng, n_trials)
    idx = np.arange(0, trajectory.n, k)
    sun, _ = sun_vector(trajectory.times[idx], site)
    obs = sensor.observe(sky, trajectory.attitude[idx], sun)
    tiled = SkySample(*(np.tile(a, (n_trials,) + (1,) * (a.ndim - 1)) for a in (
        obs.radiance, obs.dop, obs.aop_unit_deg, obs.e_vector_sensor, obs.view_elevation_deg,
        obs.view_azimuth_deg)))
    counts, names = sensor.photodiode_readings(tiled, rng)
    return RunData(trajectory, gyro, bias, accel, idx, sun,
                   counts.reshape(n_trials, len(idx), -1), names, obs)
