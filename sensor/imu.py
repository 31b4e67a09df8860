"""Strapdown IMU error model: gyroscope (bias, bias instability, white noise) and accelerometer.

Gyroscope, per axis [1]_ [2]_::

    omega_meas = omega_true + b0 + b_GM(t) + n_w

- ``b0`` constant turn-on bias [deg/s] (fixed per run; drawn per trial or given).
- ``b_GM`` bias instability, a first-order Gauss-Markov process with correlation time ``tau``
  and stationary standard deviation ``sigma_b``: ``b_{k+1} = a b_k + sigma_b sqrt(1 - a^2) w_k``,
  ``a = exp(-dt / tau)`` (exact discretisation, [2]_ eq. 4.29). It starts from its stationary
  distribution.
- ``n_w`` white rate noise from the angle random walk ``ARW`` [deg/sqrt(h)]: per-sample standard
  deviation ``ARW / 60 * sqrt(f_s)`` [deg/s] ([1]_ sect. 5: the Allan deviation of white rate
  noise is ``ARW / sqrt(tau)``).

Accelerometer: specific force in the body frame ``f_b = R_nb^T (a_n + g z_up) + b_a + n_a``
(ENU navigation frame, z up; at rest it reads +g along body "up"), with a constant bias
``b_a`` and white noise of standard deviation ``sigma_a`` [m/s^2] per sample.

Body frame as in :mod:`sensor.compound_eye` (x right, y forward, z up); rates are body-frame
angular velocities of the body relative to ENU (Earth rotation, 0.004 deg/s, is below the
modelled biases and is not added).

References
----------
.. [1] IEEE Std 952-1997, "IEEE Standard Specification Format Guide and Test Procedure for
   Single-Axis Interferometric Fiber Optic Gyros", Annex C (Allan variance),
   doi:10.1109/IEEESTD.1998.86153.
.. [2] R. G. Brown, P. Y. C. Hwang, *Introduction to Random Signals and Applied Kalman
   Filtering*, 4th ed., Wiley (2012), sect. 2.9 and 4.3 (Gauss-Markov processes).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from skysim.exceptions import InvalidParameterError
from skysim.validation import check_finite

from .compound_eye import GRAVITY_MPS2

__all__ = ["InvalidRateError", "GyroSpec", "AccelSpec", "ImuSpec", "check_rate",
           "gauss_markov", "gyro_measurements", "accel_measurements", "allan_deviation"]


class InvalidRateError(InvalidParameterError):
    """A sample or update rate is zero, negative or not finite. Give a rate in Hz > 0."""


def check_rate(name: str, rate_hz) -> float:
    """Return ``rate_hz`` as float; raise :class:`InvalidRateError` unless finite and > 0."""
    r = float(np.asarray(rate_hz, dtype=float))
    if not np.isfinite(r) or r <= 0.0:
        raise InvalidRateError(f"{name} must be a finite rate > 0 Hz; got {rate_hz!r}. "
                               "Give the sample rate in Hz, e.g. 100.0")
    return r


def _check_nonnegative(name: str, value) -> float:
    v = float(check_finite(name, value))
    if v < 0.0:
        raise InvalidParameterError(f"{name} must be >= 0; got {value!r}")
    return v


@dataclass(frozen=True)
class GyroSpec:
    """Gyroscope error parameters (defaults: a tactical-grade MEMS gyro).

    Parameters
    ----------
    bias_deg_s : float
        1-sigma of the constant turn-on bias per axis [deg/s] (drawn per trial), 0.01 deg/s =
        36 deg/h.
    bias_instability_deg_s : float
        Stationary 1-sigma of the Gauss-Markov bias [deg/s] (0.002 deg/s = 7 deg/h).
    bias_correlation_s : float
        Correlation time of the Gauss-Markov bias [s].
    arw_deg_rt_h : float
        Angle random walk [deg/sqrt(h)] (white rate noise).
    """

    bias_deg_s: float = 0.01
    bias_instability_deg_s: float = 0.002
    bias_correlation_s: float = 100.0
    arw_deg_rt_h: float = 0.15

    def __post_init__(self):
        for k, v in asdict(self).items():
            _check_nonnegative(k, v)
        if self.bias_correlation_s <= 0.0:
            raise InvalidParameterError(
                f"bias_correlation_s must be > 0 s; got {self.bias_correlation_s!r}")

    def white_noise_deg_s(self, sample_rate_hz: float) -> float:
        """Per-sample standard deviation of the white rate noise [deg/s]: ARW/60 sqrt(f_s)."""
        return self.arw_deg_rt_h / 60.0 * np.sqrt(check_rate("sample_rate_hz", sample_rate_hz))


@dataclass(frozen=True)
class AccelSpec:
    """Accelerometer error parameters.

    Parameters
    ----------
    bias_mps2 : float
        1-sigma of the constant bias per axis [m/s^2] (drawn per trial); 0.005 m/s^2 ~ 0.5 mg.
    noise_mps2 : float
        Per-sample white noise 1-sigma [m/s^2].
    """

    bias_mps2: float = 0.005
    noise_mps2: float = 0.02

    def __post_init__(self):
        for k, v in asdict(self).items():
            _check_nonnegative(k, v)


@dataclass(frozen=True)
class ImuSpec:
    """A gyro triad, an accelerometer triad and their common sample rate [Hz]."""

    gyro: GyroSpec = GyroSpec()
    accel: AccelSpec = AccelSpec()
    sample_rate_hz: float = 100.0

    def __post_init__(self):
        check_rate("sample_rate_hz", self.sample_rate_hz)

    def to_dict(self) -> dict:
        return {"gyro": asdict(self.gyro), "accel": asdict(self.accel),
                "sample_rate_hz": self.sample_rate_hz}


def gauss_markov(shape, n_samples: int, sigma: float, tau_s: float, dt_s: float,
                 rng: np.random.Generator) -> np.ndarray:
    """First-order Gauss-Markov sequences, shape ``shape[:-1] + (n_samples, shape[-1])``.

    ``x_{k+1} = a x_k + sigma sqrt(1 - a^2) w_k`` with ``a = exp(-dt/tau)``, ``x_0 ~ N(0, sigma^2)``
    ([2]_ eq. 4.29), vectorised with an IIR filter along time.
    """
    lead, axes = tuple(shape[:-1]), int(shape[-1])
    a = np.exp(-dt_s / tau_s)
    w = rng.standard_normal(lead + (n_samples, axes)) * sigma * np.sqrt(1.0 - a * a)
    x0 = rng.standard_normal(lead + (1, axes)) * sigma
    w[..., 0:1, :] = x0                           # x_0 drawn from the stationary law
    from scipy.signal import lfilter  # scipy.signal costs ~0.5 s to import: only when needed

    return lfilter([1.0], [1.0, -a], w, axis=-2)


def gyro_measurements(rate_true_deg_s, spec: ImuSpec, rng: np.random.Generator,
                      n_trials: int | None = None,
                      bias_deg_s=None) -> tuple[np.ndarray, np.ndarray]:
    """Gyro readings [deg/s] for true body rates (n, 3), for ``n_trials`` independent gyros.

    Parameters
    ----------
    rate_true_deg_s : array (n, 3)
        True body angular rate at the IMU samples [deg/s].
    spec : ImuSpec
    rng : numpy.random.Generator
    n_trials : int, optional
        Independent draws (bias, bias instability, noise); output gets a leading axis.
    bias_deg_s : array (3,) or (n_trials, 3), optional
        Use this turn-on bias instead of drawing one.

    Returns
    -------
    readings : (n, 3) or (n_trials, n, 3) [deg/s]
    bias_total : same shape, the true total bias b0 + b_GM [deg/s] (for diagnostics).
    """
    w = check_finite("rate_true_deg_s", rate_true_deg_s)
    if w.ndim != 2 or w.shape[1] != 3:
        raise InvalidParameterError(f"rate_true_deg_s must have shape (n, 3); got {w.shape}")
    g, dt = spec.gyro, 1.0 / spec.sample_rate_hz
    lead = () if n_trials is None else (int(n_trials),)
    n = w.shape[0]
    b0 = (rng.standard_normal(lead + (1, 3)) * g.bias_deg_s if bias_deg_s is None
          else np.asarray(bias_deg_s, float).reshape(lead + (1, 3)))
    b_gm = gauss_markov(lead + (3,), n, g.bias_instability_deg_s, g.bias_correlation_s, dt, rng)
    bias = b0 + b_gm
    noise = rng.standard_normal(lead + (n, 3)) * g.white_noise_deg_s(spec.sample_rate_hz)
    return w + bias + noise, np.broadcast_to(bias, lead + (n, 3)).copy()


def accel_measurements(up_body, spec: ImuSpec, rng: np.random.Generator,
                       n_trials: int | None = None, accel_nav_mps2=None) -> np.ndarray:
    """Accelerometer specific force [m/s^2] in the body frame.

    Parameters
    ----------
    up_body : (n, 3)
        ENU "up" in the body frame, ``R_nb^T z`` (from the true attitude).
    accel_nav_mps2 : (n, 3) in body frame, optional
        Kinematic acceleration of the IMU already rotated into the body frame (0 for a platform
        rotating about the IMU).

    Returns
    -------
    (n, 3) or (n_trials, n, 3) [m/s^2]
    """
    up = check_finite("up_body", up_body)
    lead = () if n_trials is None else (int(n_trials),)
    f = GRAVITY_MPS2 * up
    if accel_nav_mps2 is not None:
        f = f + check_finite("accel_nav_mps2", accel_nav_mps2)
    a = spec.accel
    bias = rng.standard_normal(lead + (1, 3)) * a.bias_mps2
    return f + bias + rng.standard_normal(lead + up.shape) * a.noise_mps2


def allan_deviation(rate, dt_s: float, taus_s) -> np.ndarray:
    """Overlapping Allan deviation of a rate signal along axis -2 ([1]_ eq. C.8).

    Parameters
    ----------
    rate : (..., n, k) samples [any rate unit]
    dt_s : sample interval [s]
    taus_s : cluster times [s] (rounded to whole samples)

    Returns
    -------
    (len(taus), ..., k) Allan deviation [rate unit].
    """
    r = np.asarray(rate, float)
    theta = np.concatenate([np.zeros(r.shape[:-2] + (1, r.shape[-1])),
                            np.cumsum(r, axis=-2) * dt_s], axis=-2)
    out = []
    for tau in np.atleast_1d(taus_s):          # a handful of cluster times
        m = int(round(tau / dt_s))
        d = theta[..., 2 * m:, :] - 2 * theta[..., m:-m, :] + theta[..., :-2 * m, :]
        out.append(np.sqrt(np.mean(d ** 2, axis=-2) / (2.0 * (m * dt_s) ** 2)))
    return np.stack(out)
