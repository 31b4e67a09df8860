"""Installation-error calibration of a compound-eye polarization sensor (patent [1]_).

Three steps, each a batch Gauss-Newton least-squares fit over many carrier attitudes that
returns the estimate with its covariance (:class:`InstallationEstimate`):

1. :func:`estimate_body_installation` -- sensor-to-body error ``phi_1`` from the zenith unit:
   with the reference attitude ``R_nb`` of a navigation module and the ephemeris sun ``s_n``,
   the E-vector is perpendicular to the sun (single scattering) and to the viewing direction
   (it is measured in the unit's focal plane), so ``(R_nb^T s_n) . (R_bs(phi_1) e_s) = 0``.
   One scalar per attitude; rotations about the sun and about the E-vector leave it unchanged,
   so the carrier attitudes must vary (at least three different yaws) for all three axes.
2. :func:`sun_vector_sensor` -- the sun in the sensor frame is the direction perpendicular to
   all units' E-vectors (smallest eigenvector of ``sum w e e^T``); sign: above the horizon.
3. :func:`estimate_unit_installation` -- each unit's error ``phi_i`` (i = 2..9 in the patent)
   from the invariance of the sun-gravity angle: the sun direction from the zenith unit and
   unit i, ``c = e_1 x R_i(phi_i) e_i``, must make the ephemeris angle ``90 deg - h`` with the
   up direction measured by the accelerometer: residual ``|c . u_s| - sin(h) |c|`` (the
   unnormalised form down-weights near-parallel E-vectors, where the sun is ill-defined).

Then :func:`attitude_from_sun_gravity` turns the sun (sensor) and gravity (accelerometer) into
the carrier attitude by TRIAD [2]_, with or without the calibrated errors.

Frames and conventions as in :mod:`sensor.compound_eye`. Rotation vectors are reported in
degrees: ``phi_1`` in the sensor/body frame, ``phi_i`` in unit i's own frame.

References
----------
.. [1] G. Guo, X. Liu, J. Yang, Y. Wang (Beihang University), "A method of multi-direction
   calibration for polarization sensor imitating compound eye", Chinese patent (2020).
.. [2] M. D. Shuster, S. D. Oh, "Three-axis attitude determination from vector observations",
   J. Guidance and Control 4(1):70-77 (1981), doi:10.2514/3.19717 (TRIAD, eqs. 1-7).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from sensor.compound_eye import CompoundEyeSensor, attitude_angles, body_attitude
from sensor.opponent import GAIN
from sensor.photodiodes_io import ACCEL_COLUMNS, PhotodiodeData
from skysim.exceptions import InvalidParameterError
from skysim.geometry import wrap_axial_deg
from skysim.sun import sun_vector

from .exceptions import (
    CalibrationError,
    ConvergenceError,
    RankDeficientError,
    TooFewSamplesError,
)
from .solve import solve_pair

__all__ = ["UnobservableError", "SaturatedUnitError", "InstallationEstimate",
           "InstallationCalibration", "UnitPolarization", "polarization_from_photodiodes",
           "unit_polarization", "e_vectors_sensor", "estimate_body_installation",
           "sun_vector_sensor", "estimate_unit_installation", "attitude_from_sun_gravity",
           "calibrate_installation", "attitude_from_data", "yaw_offset_from_sky", "RCOND"]

RCOND = 1e-4
"""Smallest eigenvalue ratio of the normal matrix accepted as observable: below it the weakest
axis would be known >= 100x worse than the best one, i.e. it is fixed by noise, not geometry."""


class UnobservableError(RankDeficientError):
    """Some rotation axis of an installation error is not observable from these attitudes.

    Attributes ``axes`` (k, 3): unobservable rotation axes (frame ``frame``); ``named``: the
    physical directions they lie along (e.g. "the sun direction"), where recognisable.
    """

    def __init__(self, message: str, axes, frame: str, named=()):
        super().__init__(message)
        self.axes = np.asarray(axes)
        self.frame = frame
        self.named = list(named)


class SaturatedUnitError(CalibrationError, ValueError):
    """Every photodiode of a unit is saturated in every sample: the unit carries no
    polarization. Reduce the exposure/gain or shade the unit from the direct sun."""


@dataclass(frozen=True)
class InstallationEstimate:
    """A fitted small rotation with its uncertainty.

    Attributes
    ----------
    rotvec_deg : (3,) rotation vector [deg]; std_deg : (3,) its 1-sigma uncertainty [deg];
    covariance_deg2 : (3, 3) [deg^2]; frame : where the axes are ("sensor" or "unit i");
    n_samples, iterations, residual_rms : fit diagnostics; condition : eigenvalue ratio
    ``lambda_min / lambda_max`` of the normal matrix (1 = isotropic, < RCOND = unobservable).
    """

    rotvec_deg: np.ndarray
    std_deg: np.ndarray
    covariance_deg2: np.ndarray
    frame: str
    n_samples: int
    iterations: int
    residual_rms: float
    condition: float

    def to_dict(self) -> dict:
        return {"rotvec_deg": self.rotvec_deg.tolist(), "std_deg": self.std_deg.tolist(),
                "frame": self.frame, "n_samples": self.n_samples,
                "iterations": self.iterations, "residual_rms": self.residual_rms,
                "condition": self.condition}


@dataclass(frozen=True)
class UnitPolarization:
    """Per-sample, per-unit polarization measured by the photodiodes.

    ``aop_deg`` (n, m): E-vector angle in the unit frame [deg]; ``dop`` (n, m); ``valid``
    (n, m): False where a photodiode was flagged or the DoP is below the threshold (those
    entries are NaN, and are skipped by every estimator).
    """

    aop_deg: np.ndarray
    dop: np.ndarray
    valid: np.ndarray

    @property
    def e_unit(self) -> np.ndarray:
        """E-vectors in the unit frames, (n, m, 3)."""
        chi = np.radians(self.aop_deg)
        return np.stack([np.cos(chi), np.sin(chi), np.zeros_like(chi)], axis=-1)


def _is_three_pair(angles) -> bool:
    a = np.mod(np.asarray(angles, float), 180.0)
    return len(a) == 6 and set(np.round(a, 9)) == {0.0, 30.0, 60.0, 90.0, 120.0, 150.0}


def polarization_from_photodiodes(readings, angles_deg, method: str = "stokes"):
    """E-vector angle [deg, unit frame, in [-90, 90)] and DoP from photodiode readings.

    Parameters
    ----------
    readings : array (..., k)
        Readings behind polarizers at ``angles_deg`` (any linear unit; dark-subtracted).
    angles_deg : (k,) polarizer angles [deg], at least 3 distinct mod 180.
    method : {"stokes", "opponent"}
        "stokes": linear least squares of ``P_k = s0 + s1 cos 2a_k + s2 sin 2a_k`` (Malus);
        for 0/45/90/135 this is exactly ``s1 = (P0 - P90)/2, s2 = (P45 - P135)/2``.
        "opponent" (three-pair units only): log ratios of the orthogonal pairs,
        ``U = g log10(P_a / P_a+90)``, solved by :func:`calibration.solve.solve_pair`
        (channels U1, U2) as the analog sensor of Yang et al. (2014) does.
    """
    P = np.asarray(readings, float)
    a = np.radians(np.asarray(angles_deg, float))
    if method == "opponent":
        if not _is_three_pair(angles_deg):
            raise InvalidParameterError(
                f"method 'opponent' needs the three-pair angles 0/30/.../150 deg; "
                f"got {list(angles_deg)}")
        col = {int(round(x)) % 180: j for j, x in enumerate(np.asarray(angles_deg, float))}
        with np.errstate(divide="ignore", invalid="ignore"):
            U = np.stack([GAIN * np.log10(P[..., col[c]] / P[..., col[(c + 90) % 180]])
                          for c in (60, 0, 120)], axis=-1)
        # solve_pair's model is cos 2(phi + a); Malus's pair ratio is cos 2(chi - a): chi = -phi
        phi, dop = solve_pair(U, (1, 2), GAIN)
        return wrap_axial_deg(-phi), dop
    if method != "stokes":
        raise InvalidParameterError(f"unknown method {method!r}; valid: 'stokes', 'opponent'")
    A = np.stack([np.ones_like(a), np.cos(2 * a), np.sin(2 * a)], axis=1)
    s = P @ np.linalg.pinv(A).T
    with np.errstate(divide="ignore", invalid="ignore"):
        dop = np.hypot(s[..., 1], s[..., 2]) / s[..., 0]
    aop = 0.5 * np.degrees(np.arctan2(s[..., 2], s[..., 1]))
    return wrap_axial_deg(aop), dop


def unit_polarization(data: PhotodiodeData, min_dop: float = 0.05,
                      method: str = "stokes") -> UnitPolarization:
    """Polarization of every unit and sample of a photodiode data set.

    A sample of a unit is invalid when any of its photodiodes is flagged (saturated, zero,
    missing, dead) or its DoP is below ``min_dop`` (the E-vector of weakly polarized light,
    near the sun, is dominated by noise). Vectorised over all units sharing a photodiode set.

    Raises
    ------
    SaturatedUnitError
        If every photodiode of some unit is saturated in every sample.
    """
    n, m = len(data.table), len(data.units)
    aop, dop = np.full((n, m), np.nan), np.full((n, m), np.nan)
    sat_all = np.all(data.flags.saturated, axis=0)
    groups: dict = {}
    for i, u in enumerate(data.units):
        groups.setdefault(tuple(float(a) for a in u["photodiodes"]), []).append(i)
    bad = data.flags.bad
    for angles, idx in groups.items():     # one vectorised solve per photodiode layout
        cols = [[data.columns.index(f"u{i}_p{int(round(a)):03d}") for a in angles] for i in idx]
        cols = np.array(cols)                                    # (g, k)
        if len(idx) and np.any(sat_all[cols].all(axis=1)):
            unit = idx[int(np.flatnonzero(sat_all[cols].all(axis=1))[0])]
            raise SaturatedUnitError(
                f"all photodiodes of unit {unit} are saturated in every sample "
                f"(saturation_value {data.sidecar['saturation_value']}); reduce the exposure "
                "or shade the unit from the direct sun")
        a_, d_ = polarization_from_photodiodes(data.readings[:, cols], angles, method)
        ok = ~bad[:, cols].any(axis=-1)
        aop[:, idx] = np.where(ok, a_, np.nan)
        dop[:, idx] = np.where(ok, d_, np.nan)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(aop) & (dop >= min_dop)
    return UnitPolarization(np.where(valid, aop, np.nan), np.where(valid, dop, np.nan), valid)


def e_vectors_sensor(pol: UnitPolarization, sensor: CompoundEyeSensor,
                     compensated: bool = True) -> np.ndarray:
    """E-vectors in the sensor frame (n, m, 3), using the sensor's unit installation errors
    when ``compensated`` (else the nominal unit orientations). NaN where invalid."""
    return np.einsum("mij,nmj->nmi", sensor.unit_matrices(compensated), pol.e_unit)


def _rotate(rotvec, v):
    """Rodrigues rotation of vectors ``v`` (..., 3) by rotation vectors [rad] (..., 3)."""
    th = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    k = np.divide(rotvec, th, out=np.zeros_like(rotvec), where=th > 0)
    return (v * np.cos(th) + np.cross(k, v) * np.sin(th)
            + k * np.sum(k * v, axis=-1, keepdims=True) * (1 - np.cos(th)))


def _check_observable(J, what: str, frame: str, directions):
    """Raise for too few samples or an unobservable axis of the (weighted) Jacobian J (N, 3).

    ``directions()`` returns named physical directions (same frame) used to describe the
    unobservable axes, e.g. {"the sun direction": ...}."""
    if J.shape[0] < 3:
        raise TooFewSamplesError(
            f"{what}: {J.shape[0]} usable sample(s) for 3 unknown rotation angles; record at "
            "least 3 (better dozens of) carrier attitudes with different yaw")
    lam, vec = np.linalg.eigh(J.T @ J)
    ratio = lam / lam[-1] if lam[-1] > 0 else np.zeros(3)
    weak = ratio < RCOND
    if weak.any():
        Q = vec[:, weak]
        named = [name for name, d in directions().items()
                 if np.linalg.norm(Q.T @ (d / np.linalg.norm(d))) > 0.95]
        axes = "; ".join(np.array2string(q, precision=3, suppress_small=True) for q in Q.T)
        along = f" (along {' and '.join(named)})" if named else ""
        raise UnobservableError(
            f"{what} is not observable from these {J.shape[0]} samples: rotation about the "
            f"axis {axes} ({frame} frame){along} cannot be seen (eigenvalue ratio "
            f"{ratio[weak].max():.1e} < {RCOND:g}). Move the carrier through more attitudes: "
            "different yaws (at least 3) and some pitch/roll", Q.T, frame, named)
    return float(ratio[0])


def _finish(params, J, r, w, frame, iterations) -> InstallationEstimate:
    # Sandwich (heteroscedasticity-consistent, HC1) covariance: the residual noise varies with
    # the geometry and DoP in ways the weights only approximate, so the plain s^2 (J^T W J)^-1
    # would understate it. White (1980), doi:10.2307/1912934, eq. (2.4); MacKinnon & White's
    # n/(n-k) small-sample factor.
    n = r.size
    dof = max(n - 3, 1)
    s2 = float(np.sum((w * r) ** 2) / dof)
    Jw, rw = J * w[:, None], w * r
    bread = np.linalg.inv(Jw.T @ Jw)
    meat = (Jw * rw[:, None] ** 2).T @ Jw
    cov = n / dof * bread @ meat @ bread
    cov_deg2 = cov * np.degrees(1.0) ** 2
    lam = np.linalg.eigvalsh(J.T @ J)
    return InstallationEstimate(np.degrees(params), np.sqrt(np.diag(cov_deg2)), cov_deg2, frame,
                                int(n), iterations, float(np.sqrt(s2)), float(lam[0] / lam[-1]))


def estimate_body_installation(e_zenith_sensor, reference_attitude: Rotation, sun_enu,
                               max_iter: int = 20, tol_deg: float = 1e-9) -> InstallationEstimate:
    """Step 1: sensor-to-body installation error ``phi_1`` [deg] from the zenith unit.

    Parameters
    ----------
    e_zenith_sensor : (n, 3)
        E-vectors of the zenith unit in the sensor frame (NaN rows are skipped).
    reference_attitude : Rotation of length n
        Body-to-ENU attitude from the navigation module (noisy reference).
    sun_enu : (n, 3)
        Ephemeris sun unit vectors in ENU.

    Returns
    -------
    InstallationEstimate in the sensor frame (``R_bs = Rotation.from_rotvec(rotvec_deg)``).

    Raises
    ------
    TooFewSamplesError, UnobservableError (names the unobservable axis), ConvergenceError
    """
    e = np.asarray(e_zenith_sensor, float)
    ok = np.all(np.isfinite(e), axis=1)
    s_b = reference_attitude.inv().apply(np.asarray(sun_enu, float).reshape(-1, 3))
    e, s_b = e[ok], s_b[ok]
    R = Rotation.identity()
    J = np.cross(e, s_b)
    _check_observable(J, "sensor-to-body installation error phi_1", "sensor", lambda:
                      {"the sun direction": s_b.mean(0), "the E-vector": _axial_mean(e),
                       "the zenith-unit axis (sensor z)": np.array([0.0, 0.0, 1.0])})
    for it in range(1, max_iter + 1):
        e_b = R.apply(e)
        r = np.sum(s_b * e_b, axis=1)
        J = np.cross(e_b, s_b)     # d r / d(delta) for the left perturbation R <- exp(delta) R
        delta = np.linalg.lstsq(J, -r, rcond=None)[0]
        R = Rotation.from_rotvec(delta) * R
        if np.degrees(np.linalg.norm(delta)) < tol_deg:
            break
    else:
        raise ConvergenceError(f"phi_1 fit did not converge in {max_iter} iterations",
                               np.degrees(np.linalg.norm(delta)), max_iter)
    e_b = R.apply(e)
    return _finish(R.as_rotvec(), np.cross(e_b, s_b), np.sum(s_b * e_b, axis=1),
                   np.ones(len(e)), "sensor", it)


def _axial_mean(e):
    """Principal axis of a set of axial vectors (sign-free mean direction)."""
    e = e[np.all(np.isfinite(e), axis=-1)]
    return np.linalg.eigh(e.T @ e)[1][:, -1] if len(e) else np.array([1.0, 0, 0])


def sun_vector_sensor(e_sensor, weights=None, up_sensor=None):
    """Step 2: sun unit vectors in the sensor frame from the units' E-vectors.

    Parameters
    ----------
    e_sensor : (n, m, 3)
        E-vectors in the sensor frame (NaN = not usable).
    weights : (n, m), optional
        Per-unit weights (e.g. DoP); default 1.
    up_sensor : (n, 3), optional
        Up direction in the sensor frame; the sun is chosen above it (default: sensor z).

    Returns
    -------
    sun : (n, 3); quality : (n,) ratio of the smallest to the middle eigenvalue of
    ``sum w e e^T`` (0 = all E-vectors exactly perpendicular to one direction).
    """
    e = np.asarray(e_sensor, float)
    w = np.ones(e.shape[:2]) if weights is None else np.asarray(weights, float)
    ok = np.all(np.isfinite(e), axis=-1) & np.isfinite(w)
    e = np.where(ok[..., None], e, 0.0)
    w = np.where(ok, w, 0.0)
    M = np.einsum("nm,nmi,nmj->nij", w, e, e)
    lam, vec = np.linalg.eigh(M)
    sun = vec[:, :, 0]
    up = np.array([0.0, 0.0, 1.0]) if up_sensor is None else np.asarray(up_sensor, float)
    sun = sun * np.where(np.sum(sun * up, axis=-1) < 0, -1.0, 1.0)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        quality = lam[:, 0] / lam[:, 1]
    return sun, quality


def _step3_residual(params, e1, e_unit, nominal, up, sin_h):
    """Residual |c.u| - sin(h)|c| with c = e1 x R_nom R(phi) e_unit; params (m, 3) rad."""
    e_i = np.einsum("mij,nmj->nmi", nominal, _rotate(params[None], e_unit))
    c = np.cross(e1[:, None, :], e_i)
    return np.abs(np.sum(c * up[:, None, :], axis=-1)) - sin_h[:, None] * np.linalg.norm(c, axis=-1)


def estimate_unit_installation(e_zenith_sensor, e_unit, unit_matrices_nominal, up_sensor,
                               sun_elevation_deg, weights=None, unit_labels=None,
                               up_rotation_covariance_deg2=None, max_iter: int = 30,
                               tol_deg: float = 1e-9):
    """Step 3: installation errors ``phi_i`` [deg, unit frame] of units from the sun-gravity angle.

    All units are fitted together (batched Gauss-Newton, numerical Jacobian, 3 parameters
    per unit, independent blocks).

    Parameters
    ----------
    e_zenith_sensor : (n, 3)
        Zenith-unit E-vectors in the sensor frame (defines the frame).
    e_unit : (n, m, 3)
        The units' E-vectors in their own frames (NaN = not usable).
    unit_matrices_nominal : (m, 3, 3)
        Nominal unit-to-sensor rotations.
    up_sensor : (n, 3)
        Up (accelerometer specific force, normalised) in the sensor frame, i.e. after removing
        ``phi_1`` from step 1.
    sun_elevation_deg : (n,)
        Ephemeris sun elevation [deg].
    weights : (n, m), optional
        Residual weights (e.g. the unit's DoP, to which the E-vector noise is inversely
        proportional); default 1.
    up_rotation_covariance_deg2 : (3, 3), optional
        Covariance [deg^2] of a common rotation error of ``up_sensor`` -- the uncertainty of
        ``phi_1`` from step 1, through which ``up_sensor`` was computed. It is the same for
        every sample, so it does not average out: it is propagated linearly into each unit's
        covariance (``G C G^T``, G the sensitivity of ``phi_i`` to that rotation).

    Returns
    -------
    list of InstallationEstimate, one per unit.

    Raises
    ------
    TooFewSamplesError, UnobservableError (names the axis), ConvergenceError
    """
    e1 = np.asarray(e_zenith_sensor, float)
    eu = np.asarray(e_unit, float)
    n, m, _ = eu.shape
    labels = unit_labels or [f"unit {i}" for i in range(m)]
    w = np.ones((n, m)) if weights is None else np.asarray(weights, float)
    ok = np.all(np.isfinite(eu), axis=-1) & np.all(np.isfinite(e1), axis=-1)[:, None] & (w > 0)
    w = np.where(ok, w, 0.0)
    eu = np.where(ok[..., None], eu, np.array([1.0, 0.0, 0.0]))
    e1 = np.where(np.isfinite(e1), e1, 0.0)
    up = np.asarray(up_sensor, float)
    up = up / np.linalg.norm(up, axis=-1, keepdims=True)
    sin_h = np.sin(np.radians(np.asarray(sun_elevation_deg, float)))
    args = (e1, eu, np.asarray(unit_matrices_nominal, float), up, sin_h)
    params = np.zeros((m, 3))
    h = 1e-6

    def jacobian(p):
        cols = []
        for k in range(3):          # 3 parameter axes, each evaluated for all units at once
            dp = np.zeros(3)
            dp[k] = h
            cols.append((_step3_residual(p + dp, *args) - _step3_residual(p - dp, *args)) / (2 * h))
        return np.stack(cols, axis=-1)                  # (n, m, 3)

    J = jacobian(params)
    for i in range(m):
        use = ok[:, i]
        _check_observable(J[use, i] * w[use, i, None], f"installation error of {labels[i]}",
                          labels[i], lambda: {"the unit's E-vector": _axial_mean(eu[use, i]),
                                      "the unit's optical axis (z)": np.array([0.0, 0, 1])})
    for it in range(1, max_iter + 1):
        r = _step3_residual(params, *args) * w
        J = jacobian(params) * w[..., None]
        A = np.einsum("nmi,nmj->mij", J, J)
        b = np.einsum("nmi,nm->mi", J, r)
        delta = -np.linalg.solve(A, b[..., None])[..., 0]
        params = params + delta
        step = np.degrees(np.abs(delta).max())
        if step < tol_deg:
            break
    else:
        raise ConvergenceError(f"unit installation fit did not converge in {max_iter} "
                               f"iterations (last step {step:.3g} deg)", step, max_iter)
    r = _step3_residual(params, *args)
    J = jacobian(params)
    out = [_finish(params[i], J[ok[:, i], i], r[ok[:, i], i], w[ok[:, i], i], labels[i], it)
           for i in range(m)]
    if up_rotation_covariance_deg2 is None:
        return out
    # sensitivity of the fixed point to a common rotation of `up` (one Gauss-Newton step)
    Jw = J * w[..., None]
    A_inv = np.linalg.inv(np.einsum("nmi,nmj->mij", Jw, Jw))
    G = np.empty((m, 3, 3))
    for k in range(3):
        rot = np.zeros(3)
        rot[k] = h
        dr = (_step3_residual(params, e1, eu, args[2], _rotate(rot, up), sin_h) - r) / h
        G[:, :, k] = -np.einsum("mij,nmj,nm->mi", A_inv, Jw, dr * w)
    extra = G @ np.asarray(up_rotation_covariance_deg2, float) @ np.swapaxes(G, 1, 2)
    return [replace(e, covariance_deg2=e.covariance_deg2 + extra[i],
                    std_deg=np.sqrt(np.diag(e.covariance_deg2 + extra[i])))
            for i, e in enumerate(out)]


def attitude_from_sun_gravity(sun_body, up_body, sun_enu) -> Rotation:
    """Body-to-ENU attitude from the sun and up directions in the body frame (TRIAD [2]_).

    Gravity (up) is the primary vector: an accelerometer gives it better than the sky gives
    the sun; the sun fixes the heading. Shapes (n, 3).
    """
    def triad(a, b):
        t1 = a / np.linalg.norm(a, axis=-1, keepdims=True)
        t2 = np.cross(t1, b)
        t2 /= np.linalg.norm(t2, axis=-1, keepdims=True)
        return np.stack([t1, t2, np.cross(t1, t2)], axis=-1)       # columns t1, t2, t3
    up_enu = np.broadcast_to([0.0, 0.0, 1.0], np.shape(sun_enu))
    M = triad(up_enu, np.asarray(sun_enu, float)) @ np.swapaxes(
        triad(np.asarray(up_body, float), np.asarray(sun_body, float)), -1, -2)
    return Rotation.from_matrix(M)


def _reference_attitude(data: PhotodiodeData) -> Rotation:
    t = data.table
    if data.sidecar["yaw_reference"] != "north":
        raise CalibrationError(
            "step 1 needs the absolute reference heading of a navigation module, but this file "
            "has yaw_reference='relative'; record yaw clockwise from north")
    sense = 1.0 if data.sidecar["yaw_sense"] == "clockwise" else -1.0
    pitch = t["pitch_deg"] if "pitch_deg" in t else 0.0
    roll = t["roll_deg"] if "roll_deg" in t else 0.0
    return body_attitude(sense * t["yaw_deg"].to_numpy(float), pitch, roll)


def _up_body(data: PhotodiodeData) -> np.ndarray:
    """Up in the body frame: accelerometer specific force if recorded, else from the recorded
    pitch and roll (yaw does not matter, so relative yaw is fine)."""
    t = data.table
    if data.has_accelerometer:
        f = t[list(ACCEL_COLUMNS)].to_numpy(float)
        return f / np.linalg.norm(f, axis=1, keepdims=True)
    if "pitch_deg" not in t or "roll_deg" not in t:
        raise CalibrationError("no accelerometer columns (accel_x/y/z_mps2) and no pitch_deg/"
                               "roll_deg: the up direction in the body frame is unknown")
    tilt = body_attitude(0.0, t["pitch_deg"].to_numpy(float), t["roll_deg"].to_numpy(float))
    return tilt.inv().apply(np.array([0.0, 0.0, 1.0])).reshape(-1, 3)


@dataclass(frozen=True)
class InstallationCalibration:
    """Result of the three-step calibration: ``body`` (phi_1), ``units`` (phi_i, unit 0 is the
    zenith unit and is not fitted) and the compensated ``sensor``."""

    body: InstallationEstimate
    units: list
    sensor: CompoundEyeSensor
    n_samples: int
    valid_fraction: np.ndarray = field(repr=False)

    def to_dict(self) -> dict:
        return {"body": self.body.to_dict(), "units": [u.to_dict() for u in self.units],
                "n_samples": self.n_samples, "valid_fraction": self.valid_fraction.tolist()}


def calibrate_installation(data: PhotodiodeData, sensor: CompoundEyeSensor | None = None,
                           min_dop: float = 0.05,
                           method: str = "stokes") -> InstallationCalibration:
    """The patent's three steps on a photodiode data set with reference attitude and gravity.

    Parameters
    ----------
    data : PhotodiodeData
        Needs absolute ``yaw_deg`` (and ``pitch_deg``, ``roll_deg``) from a navigation module;
        accelerometer columns for step 3 (else the reference tilt is used as up).
    sensor : CompoundEyeSensor, optional
        Nominal geometry (default: from the sidecar). Unit 0 must be the zenith unit.
    """
    sensor = (sensor or CompoundEyeSensor.from_sidecar(data.sidecar)).nominal()
    if sensor.units[0].elevation_deg != 90.0:
        raise CalibrationError(f"unit 0 must be the zenith unit (elevation 90 deg); it is at "
                               f"{sensor.units[0].elevation_deg} deg")
    pol = unit_polarization(data, min_dop, method)
    ref = _reference_attitude(data)
    sun_enu, _ = sun_vector(data.table["time"], data.site)
    e_s = e_vectors_sensor(pol, sensor, compensated=False)
    body = estimate_body_installation(e_s[:, 0], ref, sun_enu)
    R_bs = Rotation.from_rotvec(body.rotvec_deg, degrees=True)
    up_s = R_bs.inv().apply(_up_body(data))
    nominal = sensor.unit_matrices(False)
    units = estimate_unit_installation(
        e_s[:, 0], pol.e_unit[:, 1:], nominal[1:], up_s, np.degrees(np.arcsin(sun_enu[:, 2])),
        weights=pol.dop[:, 1:], unit_labels=[f"unit {i}" for i in range(1, sensor.n_units)],
        up_rotation_covariance_deg2=body.covariance_deg2)
    compensated = sensor.with_installation(
        body.rotvec_deg, np.vstack([np.zeros(3)] + [u.rotvec_deg for u in units]))
    return InstallationCalibration(body, units, compensated, len(data.table),
                                   pol.valid.mean(axis=0))


def attitude_from_data(data: PhotodiodeData, sensor: CompoundEyeSensor, min_dop: float = 0.05,
                       method: str = "stokes") -> tuple[Rotation, np.ndarray]:
    """Carrier attitude per sample from the compound eye and the accelerometer.

    Uses the installation errors stored in ``sensor`` (pass ``sensor.nominal()`` for the
    uncompensated instrument). Returns the attitude and the step-2 quality per sample.
    """
    pol = unit_polarization(data, min_dop, method)
    R_bs = sensor.body_installation()
    up_b = _up_body(data)
    up_s = R_bs.inv().apply(up_b)
    sun_s, quality = sun_vector_sensor(e_vectors_sensor(pol, sensor, True), pol.dop, up_s)
    sun_enu, _ = sun_vector(data.table["time"], data.site)
    return attitude_from_sun_gravity(R_bs.apply(sun_s), up_b, sun_enu), quality


def yaw_offset_from_sky(data: PhotodiodeData, sensor: CompoundEyeSensor | None = None,
                        min_dop: float = 0.05, method: str = "stokes") -> tuple[float, float]:
    """North reference of relative yaw: ``yaw_north = yaw_recorded + offset`` [deg].

    For instruments that only record yaw relative to their start (e.g. a 45-deg ring with
    four photodiodes per unit): the sky (sun from the E-vectors) and gravity give the absolute
    heading per sample; the offset is their circular mean difference to the recorded yaw.

    Returns
    -------
    offset_deg in [0, 360), standard error [deg] (circular spread / sqrt(n)).
    """
    sensor = sensor or CompoundEyeSensor.from_sidecar(data.sidecar)
    att, _ = attitude_from_data(data, sensor, min_dop, method)
    heading = attitude_angles(att)[0]
    sense = 1.0 if data.sidecar["yaw_sense"] == "clockwise" else -1.0
    d = np.radians(heading - sense * data.table["yaw_deg"].to_numpy(float))
    d = d[np.isfinite(d)]
    if d.size == 0:
        raise CalibrationError("no sample with a usable sky heading (all units flagged or "
                               "weakly polarized)")
    mean = np.arctan2(np.sin(d).mean(), np.cos(d).mean())
    spread = np.sqrt(np.mean(np.angle(np.exp(1j * (d - mean))) ** 2))
    return float(np.mod(np.degrees(mean), 360.0)), float(np.degrees(spread) / np.sqrt(d.size))
