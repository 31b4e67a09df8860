"""Attitude from skylight polarization and an IMU: quaternion gradient descent (Jin et al. 2020).

The estimator of Jin, Xie, Chu, Wei & Wei [1]_ fuses a gyro (fast, drifting) with two vector
observations that do not drift: gravity from the accelerometer and the skylight E-vector,
which in a Rayleigh sky is perpendicular to the sun direction. Per update k:

1. **Gyro propagation** (quaternion kinematics ``Q' = 1/2 Q (x) [0, omega_b]``, integrated
   exactly over each IMU interval for a constant rate): ``Q_w = Q_{k-1} (x) prod_j
   exp(omega_j dt / 2)``, composed with :class:`scipy.spatial.transform.Rotation`.
2. **Error vector** ``e(Q) = [R(Q)^T z - a / |a| ; lambda e_i . R(Q)^T s]`` with ``z`` the ENU
   up, ``a`` the accelerometer's specific force, ``s`` the ephemeris sun (ENU) and ``e_i`` the
   measured unit E-vector of polarization unit i in the body frame. Each polarization residual
   is zero exactly when the measured E-vector equals the Rayleigh prediction
   ``v_i x R^T s`` (the E-vector lies in the unit's focal plane, perpendicular to its axis v_i),
   and is insensitive to the E-vector's arbitrary sign.
   *Measured-vs-predicted form* (``sky=`` in :func:`estimate_attitude`): a real sky is not
   Rayleigh, and its E-vectors depart from ``perpendicular to the sun`` by degrees (more
   near the neutral points). Each unit's reference vector is then
   ``c_i = s - (s . E_i) E_i`` with ``E_i`` the E-vector that a given
   :class:`skysim.sky.Sky` predicts along the unit's view direction ``R(Q) v_i``
   (:func:`model_references`), and the residual is ``lambda e_i . R(Q)^T c_i``: zero exactly
   when the measured E-vector equals the predicted one, with the same sensitivity to a
   rotation of ``e_i`` in the focal plane as the Rayleigh form. For the Rayleigh sky
   ``E_i`` is normal to ``s``, so ``c_i = s`` and both forms coincide. ``c_i`` is evaluated
   at the current estimate and held fixed in the Jacobian: the term left out is the change of
   ``s . E_i`` with the view direction, zero for the Rayleigh sky and small where the sky's
   departure from it varies slowly; it changes the step, not the solution (the residuals
   still vanish at the true attitude, tested).
3. **Objective** ``F(Q) = 1/2 ||e(Q)||^2``, gradient ``grad F = J^T e`` with the analytic
   Jacobian ``J = de/dQ`` (4 quaternion components; :func:`rotate_to_body`), projected onto
   the tangent space of the unit sphere (its radial part only rescales ``Q``).
4. **One gradient step** ``Q_k = normalise(Q_w - mu_k g)``:

   (a) *fixed step* (Madgwick's form, [2]_ eqs. 42-43): ``mu g = beta dt g / |g|`` with a
       constant quaternion-rate gain ``beta`` [1/s]; Madgwick's choice ``beta = sqrt(3/4)
       omega_err`` for a gyro error ``omega_err`` [rad/s] ([2]_ eq. 50) is
       :func:`madgwick_beta`;
   (b) *dynamic step* from an exact line search on the local quadratic model of ``F``:
       ``mu_k = argmin_mu 1/2 ||e - mu J g||^2 = |g|^2 / |J g|^2`` (Cauchy step of steepest
       descent; [3]_ sect. 3.3, eq. 3.25), so the step shrinks when the measurements agree
       with the gyro and grows when they do not.

The structure (gyro quaternion update, error vector from E-vector and gravity, F = 1/2 |e|^2,
fixed vs line-search step) is that of [1]_; the
paper's own text was not available here, so its equation numbers are not cited and the
formulas above are written from [2]_ and [3]_.

Roll, pitch and yaw follow :func:`sensor.compound_eye.attitude_angles`.

Quaternions are scalar-last ``(x, y, z, w)`` as in scipy, body-to-ENU (``R(Q) = R_nb``).

References
----------
.. [1] H. Jin, X. Xie, J. Chu, W. Wei, Z. Wei, "Optimization method of navigation attitude
   based on skylight polarization pattern", Aero Weaponry 27(1):39 (2020).
.. [2] S. O. H. Madgwick, "An efficient orientation filter for inertial and inertial/magnetic
   sensor arrays", report, University of Bristol (2010), eqs. 42-43 (filter), 50 (beta);
   published as Madgwick, Harrison & Vaidyanathan, IEEE ICORR (2011),
   doi:10.1109/ICORR.2011.5975346.
.. [3] J. Nocedal, S. J. Wright, *Numerical Optimization*, 2nd ed., Springer (2006),
   sect. 3.3, eq. (3.25) (exact step of steepest descent on a quadratic),
   doi:10.1007/978-0-387-40065-5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from sensor.compound_eye import CompoundEyeSensor, attitude_angles
from sensor.imu import check_rate
from sensor.platform import TrajectoryTooShortError
from skysim.exceptions import InvalidParameterError
from skysim.geometry import elevation_azimuth, wrap_deg
from skysim.sky import Sky
from skysim.validation import check_finite, check_sun_above_horizon

from .installation import (
    UnitPolarization,
    e_vectors_sensor,
    polarization_from_photodiodes,
)

__all__ = ["NonUnitQuaternionError", "STEP_METHODS", "check_unit_quaternion", "rotate_to_body",
           "error_vector", "model_references", "objective", "tangent_gradient", "dynamic_step",
           "gradient_step", "madgwick_beta", "e_vectors_from_readings", "AttitudeEstimate", "estimate_attitude",
           "attitude_error_deg"]

STEP_METHODS = ("dynamic", "fixed", "gyro")
"""``dynamic``: exact line search; ``fixed``: Madgwick's constant step; ``gyro``: no correction."""

UNIT_TOL = 1e-6
"""Accepted deviation of a quaternion's norm from 1 (float rounding of a normalised quaternion
is ~1e-16; a 1e-6 deviation is an unnormalised input, not rounding)."""


class NonUnitQuaternionError(InvalidParameterError):
    """A quaternion that should describe a rotation does not have unit norm."""


def check_unit_quaternion(name: str, q) -> np.ndarray:
    """Return ``q`` (..., 4) as float; raise :class:`NonUnitQuaternionError` unless |q| = 1."""
    q = check_finite(name, q)
    if q.shape[-1:] != (4,):
        raise InvalidParameterError(f"{name} must have shape (..., 4) (x, y, z, w); got {q.shape}")
    norm = np.linalg.norm(q, axis=-1)
    bad = np.abs(norm - 1.0) > UNIT_TOL
    if bad.any():
        i = np.flatnonzero(bad.ravel())[0]
        raise NonUnitQuaternionError(
            f"{name} must be unit quaternions; entry {i} has norm {float(norm.ravel()[i])!r} "
            f"({int(bad.sum())} bad). Normalise it (q / |q|) or build it with "
            "scipy.spatial.transform.Rotation")
    return q


def rotate_to_body(q, v_n, jacobian: bool = True):
    """``R(q)^T v`` and its Jacobian with respect to the four components of ``q``.

    For ``q = (u, w)`` (not necessarily unit), ``R(q) = (w^2 - u.u) I + 2 u u^T + 2 w [u]x``
    (equal to the rotation matrix for |q| = 1), so ::

        R^T v = (w^2 - u.u) v + 2 u (u.v) - 2 w (u x v)
        d/du  = 2 (u.v) I + 2 u v^T - 2 v u^T + 2 w [v]x,      d/dw = 2 w v - 2 u x v

    Parameters
    ----------
    q : (..., 4) quaternions (x, y, z, w), body-to-ENU
    v_n : (..., 3) ENU vectors (broadcast against q)

    Returns
    -------
    v_b : (..., 3); jac : (..., 3, 4) (only if ``jacobian``)
    """
    q = np.asarray(q, float)
    v = np.asarray(v_n, float)
    shape = np.broadcast_shapes(q.shape[:-1], v.shape[:-1])
    q = np.broadcast_to(q, shape + (4,))
    v = np.broadcast_to(v, shape + (3,))
    u, w = q[..., :3], q[..., 3:]
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    uxv = np.empty(shape + (3,))                                       # u x v, by components
    uxv[..., 0] = u[..., 1] * z - u[..., 2] * y
    uxv[..., 1] = u[..., 2] * x - u[..., 0] * z
    uxv[..., 2] = u[..., 0] * y - u[..., 1] * x
    uv = np.einsum("...i,...i->...", u, v)[..., None]
    v_b = (w * w - np.einsum("...i,...i->...", u, u)[..., None]) * v + 2.0 * u * uv - 2.0 * w * uxv
    if not jacobian:
        return v_b
    vx = np.zeros(shape + (3, 3))                                      # [v]x
    vx[..., 0, 1], vx[..., 0, 2], vx[..., 1, 2] = -z, y, -x
    vx[..., 1, 0], vx[..., 2, 0], vx[..., 2, 1] = z, -y, x
    d_u = 2.0 * (uv[..., None] * np.eye(3) + u[..., :, None] * v[..., None, :]
                 - v[..., :, None] * u[..., None, :] + w[..., None] * vx)
    d_w = 2.0 * w * v - 2.0 * uxv
    return v_b, np.concatenate([d_u, d_w[..., None]], axis=-1)


def error_vector(q, up_meas_b, e_meas_b, sun_n, valid=None,
                 polarization_weight: float = 1.0,
                 reference_n=None) -> tuple[np.ndarray, np.ndarray]:
    """Error vector ``e(Q)`` (..., 3 + m) and its Jacobian (..., 3 + m, 4) (module doc, step 2).

    Parameters
    ----------
    q : (..., 4) attitude quaternions (body-to-ENU)
    up_meas_b : (..., 3) measured specific force (any scale; normalised here)
    e_meas_b : (..., m, 3) measured unit E-vectors in the body frame (NaN where invalid)
    sun_n : (..., 3) ephemeris sun unit vector in ENU
    valid : (..., m) bool, optional; invalid units contribute a zero residual and Jacobian
    polarization_weight : float
        ``lambda``, weight of the polarization residuals against the gravity residuals.
    reference_n : (..., m, 3), optional
        Per-unit ENU vectors each measured E-vector should be normal to
        (:func:`model_references`: the measured-vs-predicted form); default the sun for
        every unit (the Rayleigh form ``E perpendicular to the sun``).
    """
    a, e_m = _prepare_measurements(up_meas_b, e_meas_b, valid, polarization_weight)
    ref = np.asarray(sun_n, float) if reference_n is None else np.asarray(reference_n, float)
    return _residuals(np.asarray(q, float), a, e_m, ref)


def model_references(q, view_axes_b, sky: Sky, sun_n) -> np.ndarray:
    """Reference vectors ``c_i = s - (s . E_i) E_i`` (..., m, 3) of the measured-vs-predicted
    error vector (module doc, step 2).

    Parameters
    ----------
    q : (..., 4) attitude quaternions (body-to-ENU) at which the sky is predicted
    view_axes_b : (m, 3) unit optical axes in the body frame
    sky : skysim.sky.Sky
        The sky model that predicts ``E_i`` along ``R(q) v_i``; view directions below the
        horizon are evaluated at the horizon (such a unit sees no sky and is invalid anyway).
    sun_n : (..., 3) ephemeris sun unit vector in ENU
    """
    q = np.asarray(q, float)
    conj = q * np.array([-1.0, -1.0, -1.0, 1.0])     # R(conj)^T = R(q): body -> ENU
    d = rotate_to_body(conj[..., None, :], np.asarray(view_axes_b, float), jacobian=False)
    el, az = elevation_azimuth(d)
    s = np.asarray(sun_n, float)
    s_el, s_az = elevation_azimuth(s)
    E = sky.field(np.clip(el, 0.0, 90.0), az, s_el[..., None], s_az[..., None]).e_vector
    s = np.broadcast_to(s[..., None, :], E.shape)
    return s - np.sum(s * E, axis=-1, keepdims=True) * E


def _prepare_measurements(up_meas_b, e_meas_b, valid, weight):
    """Unit specific force and the weighted E-vectors with invalid units zeroed."""
    a = np.asarray(up_meas_b, float)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    e_m = np.asarray(e_meas_b, float)
    ok = np.all(np.isfinite(e_m), axis=-1) if valid is None else np.asarray(valid, bool)
    return a, np.where(ok[..., None], np.nan_to_num(e_m), 0.0) * weight


def _residuals(q, a, e_m, ref, jacobian: bool = True):
    """e(Q) (and J) for prepared measurements; ``ref`` is the sun (..., 3) or per-unit
    reference vectors (..., m, 3); up and references rotated in one call."""
    up = np.array([0.0, 0.0, 1.0])
    per_unit = ref.ndim == e_m.ndim
    if per_unit:
        lead = np.broadcast_shapes(ref.shape[:-2], q.shape[:-1])
        refs = np.concatenate([np.broadcast_to(up, lead + (1, 3)),
                               np.broadcast_to(ref, lead + ref.shape[-2:])], axis=-2)
    else:
        refs = np.stack(np.broadcast_arrays(up, ref), axis=-2)          # (..., 2, 3)
    out = rotate_to_body(q[..., None, :], refs, jacobian)
    v_b = out[0] if jacobian else out
    pol = v_b[..., 1:, :] if per_unit else v_b[..., 1:2, :]
    r = np.concatenate([v_b[..., 0, :] - a, np.einsum("...mi,...mi->...m", e_m, pol)], axis=-1)
    if not jacobian:
        return r
    J = out[1]
    J_ref = J[..., 1:, :, :] if per_unit else J[..., 1:2, :, :]
    J_pol = np.einsum("...mi,...mij->...mj", e_m, J_ref)
    return r, np.concatenate([J[..., 0, :, :], J_pol], axis=-2)


def objective(e) -> np.ndarray:
    """``F = 1/2 ||e||^2`` over the last axis."""
    return 0.5 * np.sum(np.asarray(e, float) ** 2, axis=-1)


def tangent_gradient(q, e, J) -> np.ndarray:
    """``grad F = J^T e`` projected onto the tangent space of the unit sphere at ``q``."""
    g = np.einsum("...ki,...k->...i", J, e)
    return g - np.sum(g * q, axis=-1, keepdims=True) * q


def dynamic_step(g, J) -> np.ndarray:
    """Exact line-search step ``mu = |g|^2 / |J g|^2`` (0 where g = 0) ([3]_ eq. 3.25)."""
    Jg = np.einsum("...ki,...i->...k", J, g)
    num = np.sum(g * g, axis=-1)
    den = np.sum(Jg * Jg, axis=-1)
    return np.divide(num, den, out=np.zeros_like(num), where=den > 1e-300)


def gradient_step(q, e, J, method: str, fixed_step: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One normalised gradient-descent update of ``q``; returns ``(q_new, step_rad)``.

    ``step_rad`` is the rotation applied by the correction [rad] (twice the quaternion step).
    ``fixed_step`` is the quaternion step length per update (``beta * dt``) for ``"fixed"``.
    """
    g = tangent_gradient(q, e, J)
    gn = np.linalg.norm(g, axis=-1)
    if method == "dynamic":
        mu = dynamic_step(g, J)
        dq = mu[..., None] * g
    elif method == "fixed":
        dq = fixed_step * np.divide(g, gn[..., None], out=np.zeros_like(g),
                                    where=gn[..., None] > 0)
    else:
        raise InvalidParameterError(f"unknown step method {method!r}; valid: 'dynamic', 'fixed'")
    q_new = q - dq
    q_new /= np.linalg.norm(q_new, axis=-1, keepdims=True)
    return q_new, 2.0 * np.linalg.norm(dq, axis=-1)


def madgwick_beta(gyro_error_deg_s: float) -> float:
    """Madgwick's gain ``beta = sqrt(3/4) omega_err`` [1/s] for a per-axis gyro error
    ``omega_err`` [deg/s] ([2]_ eq. 50)."""
    return float(np.sqrt(0.75) * np.radians(gyro_error_deg_s))


def e_vectors_from_readings(readings, sensor: CompoundEyeSensor,
                            min_dop: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Unit E-vectors in the sensor frame from photodiode readings (Malus/Stokes fit per unit).

    Parameters
    ----------
    readings : (..., P) photodiode readings, columns ordered unit by unit as in
        :meth:`sensor.compound_eye.CompoundEyeSensor.photodiode_readings`
    sensor : the sensor as the user knows it (its installation errors are applied)
    min_dop : units with a measured DoP below this are invalid (near the sun the E-vector is
        dominated by noise)

    Returns
    -------
    e : (..., m, 3), NaN where invalid; valid : (..., m) bool
    """
    P = np.asarray(readings, float)
    lead = P.shape[:-1]
    aop, dop = [], []
    start = 0
    for u in sensor.units:                      # a handful of units
        k = len(u.photodiodes_deg)
        a_, d_ = polarization_from_photodiodes(P[..., start:start + k], u.photodiodes_deg)
        aop.append(a_)
        dop.append(d_)
        start += k
    if start != P.shape[-1]:
        raise InvalidParameterError(f"readings have {P.shape[-1]} columns but the sensor has "
                                    f"{start} photodiodes")
    aop, dop = np.stack(aop, axis=-1), np.stack(dop, axis=-1)
    valid = np.isfinite(aop) & (dop >= min_dop)
    pol = UnitPolarization(np.where(valid, aop, np.nan).reshape(-1, sensor.n_units),
                           dop.reshape(-1, sensor.n_units), valid.reshape(-1, sensor.n_units))
    e = e_vectors_sensor(pol, sensor, compensated=True).reshape(lead + (sensor.n_units, 3))
    return e, valid


@dataclass(frozen=True)
class AttitudeEstimate:
    """Estimated attitude at the update samples, for S trials.

    Attributes
    ----------
    quat : (S, K, 4) body-to-ENU quaternions (x, y, z, w)
    t_s : (K,) update times since the start [s]
    objective : (S, K) ``F`` after the update (measured-vs-predicted form: with the reference
        vectors of the update)
    step_rad : (S, K) rotation applied by the correction [rad]
    method : str
    """

    quat: np.ndarray
    t_s: np.ndarray
    objective: np.ndarray
    step_rad: np.ndarray
    method: str

    def rotation(self) -> Rotation:
        return Rotation.from_quat(self.quat.reshape(-1, 4))

    def angles_deg(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(yaw in [0, 360), pitch, roll)`` [deg], each (S, K)."""
        return tuple(a.reshape(self.quat.shape[:2]) for a in attitude_angles(self.rotation()))


def _interval_increments(gyro_deg_s, dt, every: int, n_updates: int) -> Rotation:
    """Gyro rotation over each update interval, shape (S * (K - 1)): exact for a rate
    constant over each IMU sample (zero-order hold), composed in time order."""
    S = gyro_deg_s.shape[0]
    w = np.radians(gyro_deg_s[:, : (n_updates - 1) * every]).reshape(S, n_updates - 1, every, 3)
    inc = Rotation.from_rotvec((w * dt).reshape(-1, 3)).as_quat().reshape(
        S * (n_updates - 1), every, 4)
    total = Rotation.from_quat(inc[:, 0])
    for j in range(1, every):                   # samples per interval: a handful
        total = total * Rotation.from_quat(inc[:, j])
    return total


def estimate_attitude(gyro_deg_s, accel_mps2, e_meas_b, sun_enu, q0, sample_rate_hz: float,
                      polarization_every: int, method: str = "dynamic",
                      beta: float | None = None, valid=None,
                      polarization_weight: float = 1.0, sky: Sky | None = None,
                      view_axes_b=None) -> AttitudeEstimate:
    """Run the estimator over S trials at once (module doc, steps 1-4).

    Parameters
    ----------
    gyro_deg_s, accel_mps2 : (S, n, 3) IMU readings at ``sample_rate_hz`` [deg/s], [m/s^2]
    e_meas_b : (S, K, m, 3) measured E-vectors (body frame) at IMU samples 0, k, 2k, ...
        with ``k = polarization_every``; NaN where invalid
    sun_enu : (K, 3) ephemeris sun at those samples
    q0 : (S, 4) or (4,) unit quaternion: the initial attitude (e.g. a coarse alignment)
    method : {"dynamic", "fixed", "gyro"}
    beta : float, optional
        Fixed-step gain [1/s] (required for ``"fixed"``; see :func:`madgwick_beta`).
    sky : skysim.sky.Sky, optional
        Use the measured-vs-predicted error vector with this sky's E-vectors
        (:func:`model_references`); None (default): the Rayleigh form, E normal to the sun.
    view_axes_b : (m, 3), optional
        Unit optical axes in the body frame (required with ``sky``; e.g.
        ``CompoundEyeSensor.view_directions_sensor()``).

    Raises
    ------
    NonUnitQuaternionError, InvalidRateError, SunBelowHorizonError, TrajectoryTooShortError
    InvalidParameterError
        If ``sky`` is given without ``view_axes_b`` (or with the wrong number of axes).
    """
    if method not in STEP_METHODS:
        raise InvalidParameterError(f"unknown method {method!r}; valid: {', '.join(STEP_METHODS)}")
    fs = check_rate("sample_rate_hz", sample_rate_hz)
    every = int(polarization_every)
    if every < 1:
        raise InvalidParameterError(f"polarization_every must be >= 1; got {polarization_every}")
    gyro = check_finite("gyro_deg_s", gyro_deg_s)
    accel = np.asarray(accel_mps2, float)
    S, n = gyro.shape[:2]
    e_meas = np.asarray(e_meas_b, float)
    K = e_meas.shape[1]
    if K < 2 or n < (K - 1) * every + 1:
        raise TrajectoryTooShortError(
            f"{n} IMU samples and {K} polarization samples cover less than one update "
            f"interval ({every} IMU samples at {fs} Hz); record at least {every + 1} IMU "
            "samples and two polarization samples")
    sun = np.asarray(sun_enu, float).reshape(K, 3)
    check_sun_above_horizon(np.degrees(np.arcsin(np.clip(sun[:, 2], -1, 1))))
    q = np.broadcast_to(check_unit_quaternion("q0", q0), (S, 4)).copy()
    if method == "fixed" and (beta is None or not np.isfinite(beta) or beta < 0):
        raise InvalidParameterError(f"method 'fixed' needs a gain beta >= 0 [1/s]; got "
                                    f"{beta!r} (see madgwick_beta)")
    step_len = (beta or 0.0) * every / fs
    if sky is not None:
        axes = None if view_axes_b is None else np.asarray(view_axes_b, float)
        if axes is None or axes.shape != (e_meas.shape[2], 3):
            raise InvalidParameterError(
                f"the measured-vs-predicted error vector (sky=...) needs view_axes_b of shape "
                f"({e_meas.shape[2]}, 3), one optical axis per unit in the body frame; got "
                f"{None if axes is None else axes.shape}")
    up, e_m = _prepare_measurements(accel[:, ::every][:, :K], e_meas, valid, polarization_weight)
    incr = _interval_increments(gyro, 1.0 / fs, every, K)
    incr = incr.as_quat().reshape(S, K - 1, 4)
    quat = np.empty((S, K, 4))
    F = np.empty((S, K))
    steps = np.zeros((S, K))
    for k in range(K):                          # the filter recursion (sequential in time)
        if k:
            q = (Rotation.from_quat(q) * Rotation.from_quat(incr[:, k - 1])).as_quat()
        ref = sun[k] if sky is None else model_references(q, axes, sky, sun[k])
        if method != "gyro":
            e, J = _residuals(q, up[:, k], e_m[:, k], ref)
            q, steps[:, k] = gradient_step(q, e, J, method, step_len)
        # F after the update, with the update's reference vectors (one sky evaluation per
        # update; the same as at the new attitude for the Rayleigh sky)
        F[:, k] = objective(_residuals(q, up[:, k], e_m[:, k], ref, jacobian=False))
        quat[:, k] = q
    return AttitudeEstimate(quat, np.arange(K) * every / fs, F, steps, method)


def attitude_error_deg(estimate: AttitudeEstimate, truth: Rotation) -> dict:
    """Attitude errors of an estimate against the true attitude at the update samples.

    Returns a dict of (S, K) arrays [deg]: ``total`` (angle of ``R_true^T R_est``), and the
    differences ``yaw`` (wrapped to [-180, 180)), ``pitch``, ``roll``.
    """
    S, K = estimate.quat.shape[:2]
    R_true = Rotation.from_quat(np.tile(truth.as_quat().reshape(K, 4), (S, 1)))
    total = np.degrees((R_true.inv() * estimate.rotation()).magnitude()).reshape(S, K)
    yaw, pitch, roll = estimate.angles_deg()
    ty, tp, tr = attitude_angles(truth)
    return {"total": total, "yaw": wrap_deg(yaw - ty),
            "pitch": pitch - tp, "roll": roll - tr}
