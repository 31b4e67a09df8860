"""Least-squares compensation of a channel pair (Gauss-Newton), Yang et al. (2014).

For a pair ``(i, j)`` the unknowns are ``psi = (dth_i1, dth_i2, dth_j1, dth_j2, f_i, f_j)``
(eq. 10 of [1]_), optionally with a DoP scale ``s`` (the sky's ``d_max`` when ``dop`` is the
Rayleigh shape ``sin^2 g / (1 + cos^2 g)``). Given reference polarization azimuths ``phi_k``
(turntable heading minus sun azimuth) and outputs ``U_ik, U_jk``, minimise
``sum_k (U_ik - F_i(phi_k; psi))^2 + (U_jk - F_j(phi_k; psi))^2`` (eq. 11) by Gauss-Newton
steps ``psi <- psi - (J^T J)^-1 J^T r`` (eqs. 12-14) with the analytic Jacobian of
:mod:`calibration.model`, halving a step that does not lower the cost.

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424, eqs. (10)-(14).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sensor.opponent import CHANNEL_ANGLES_DEG, GAIN
from skysim.validation import check_finite

from .exceptions import ConvergenceError, RankDeficientError, TooFewSamplesError
from .model import channel_jacobian
from .solve import pair_index, solve_pair_compensated

__all__ = ["PairCalibration", "fit_pair", "PARAMETER_NAMES"]

PARAMETER_NAMES = ("dtheta_i1_deg", "dtheta_i2_deg", "dtheta_j1_deg", "dtheta_j2_deg",
                   "f_i", "f_j", "dop_scale")


@dataclass(frozen=True)
class PairCalibration:
    """Result of :func:`fit_pair`.

    Attributes
    ----------
    pair : (int, int)
    misalignment_deg : ndarray (4,)
        ``(dth_i1, dth_i2, dth_j1, dth_j2)`` [deg] (for pair (1, 2): dth1..dth4).
    transmittance : ndarray (2,)
        ``(f_i, f_j)``.
    dop_scale : float or None
        Fitted DoP scale (None when the DoP was given).
    covariance : ndarray (p, p)
        ``s^2 (J^T J)^-1`` with ``s^2 = SSR / (2n - p)``.
    residuals_V : ndarray (n, 2)
    iterations : int
    converged : bool
    """

    pair: tuple
    misalignment_deg: np.ndarray
    transmittance: np.ndarray
    dop_scale: float | None
    covariance: np.ndarray
    residuals_V: np.ndarray
    iterations: int
    converged: bool = True
    gain: float = GAIN
    parameter_names: tuple = field(default=PARAMETER_NAMES[:6])

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))

    @property
    def rms_residual_V(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_V ** 2)))

    def solve(self, U) -> tuple[np.ndarray, np.ndarray]:
        """Compensated polarization azimuth [deg] and DoP for outputs ``U`` (..., 3)."""
        return solve_pair_compensated(U, self.pair, self.misalignment_deg, self.transmittance,
                                      self.gain)

    def to_dict(self) -> dict:
        return {"pair": list(self.pair),
                "parameters": dict(zip(self.parameter_names,
                                       np.r_[self.misalignment_deg, self.transmittance,
                                             [] if self.dop_scale is None else [self.dop_scale]
                                             ].tolist())),
                "standard_errors": dict(zip(self.parameter_names, self.standard_errors.tolist())),
                "rms_residual_V": self.rms_residual_V, "iterations": self.iterations,
                "converged": self.converged}


def _model(params, phi, dop, a, gain, fit_scale):
    e = params[:4]
    f = params[4:6]
    s = params[6] if fit_scale else 1.0
    d = np.clip(s * dop, 1e-9, 1 - 1e-9)
    val, jac = channel_jacobian(phi[:, None], d[:, None], a, e[0::2], e[1::2], f, gain,
                                wrt=("e1", "e2", "dop"))
    n = phi.size
    p = params.size
    J = np.zeros((2, n, p))
    for c in range(2):  # two channels of the pair (columns: e1_c, e2_c, f_c)
        J[c, :, 2 * c] = jac["e1"][:, c]
        J[c, :, 2 * c + 1] = jac["e2"][:, c]
        J[c, :, 4 + c] = gain
        if fit_scale:
            J[c, :, 6] = jac["dop"][:, c] * dop
    return val.T.reshape(-1), J.reshape(2 * n, p)


def fit_pair(phi_deg, U, pair=(1, 2), dop=None, *, fit_dop_scale: bool = False,
             gain: float = GAIN, max_iter: int = 50, tol: float = 1e-9,
             rcond: float = 1e-10) -> PairCalibration:
    """Gauss-Newton estimate of a pair's mounting errors and transmittance terms.

    Parameters
    ----------
    phi_deg : array (n,)
        Reference polarization azimuth of each sample [deg].
    U : array (n, 3)
        Channel outputs U1..U3 [V].
    pair : (int, int)
    dop : array (n,) or float
        Degree of polarization of each sample; with ``fit_dop_scale`` only its shape matters
        (a scale is fitted, started from the ideal-model estimate).
    fit_dop_scale : bool
        Fit a DoP scale as 7th parameter.
    max_iter, tol : convergence control (``tol`` on the largest update, in deg or log units).
    rcond : float
        Smallest admissible ratio of singular values of the column-scaled Jacobian.

    Returns
    -------
    PairCalibration

    Raises
    ------
    TooFewSamplesError
        If there are fewer samples than parameters (6, or 7 with ``fit_dop_scale``).
    RankDeficientError
        If the Jacobian is rank deficient (names the least observable parameter).
    ConvergenceError
        If no convergence within ``max_iter`` (reports the last step size).
    """
    phi = check_finite("phi_deg", phi_deg).ravel()
    U = check_finite("U", U)
    if U.ndim != 2 or U.shape[1] != 3 or U.shape[0] != phi.size:
        raise ValueError(f"U must have shape (n, 3) with n = len(phi_deg) = {phi.size}; "
                         f"got {U.shape}")
    if dop is None:
        raise ValueError("dop is required: the DoP per sample, or its shape with fit_dop_scale")
    dop = np.broadcast_to(check_finite("dop", dop), phi.shape).astype(float)
    i, j = pair_index(pair)
    n_par = 7 if fit_dop_scale else 6
    if phi.size < n_par:
        raise TooFewSamplesError(
            f"{phi.size} samples for {n_par} parameters; the compensation needs at least "
            f"{n_par} samples spread over the polarization azimuth")
    a = CHANNEL_ANGLES_DEG[[i, j]]
    y = U[:, [i, j]].T.reshape(-1)
    params = np.zeros(n_par)
    if fit_dop_scale:
        from .solve import solve_pair
        _, d_ideal = solve_pair(U, pair, gain)
        params[6] = float(np.median(d_ideal / np.where(dop > 0, dop, np.nan)))
    names = PARAMETER_NAMES[:n_par]

    val, J = _model(params, phi, dop, a, gain, fit_dop_scale)
    r = val - y
    cost = r @ r
    step = np.inf
    for it in range(1, max_iter + 1):
        norms = np.linalg.norm(J, axis=0)
        norms[norms == 0] = 1.0
        Js = J / norms
        sv = np.linalg.svd(Js, compute_uv=False)
        if sv[-1] < rcond * sv[0]:
            _, _, vt = np.linalg.svd(Js)
            worst = names[int(np.argmax(np.abs(vt[-1])))]
            raise RankDeficientError(
                f"Jacobian is rank deficient (singular value ratio {sv[-1] / sv[0]:.2e}); "
                f"parameter {worst!r} is not observable from these samples: spread the "
                f"polarization azimuths over [-90, 90) deg (range here: "
                f"{phi.min():.2f}..{phi.max():.2f} deg)")
        delta = np.linalg.lstsq(Js, -r, rcond=None)[0] / norms
        lam = 1.0
        for _ in range(30):  # step halving keeps each Gauss-Newton step a descent step
            trial = params + lam * delta
            val_t, J_t = _model(trial, phi, dop, a, gain, fit_dop_scale)
            r_t = val_t - y
            cost_t = r_t @ r_t
            if cost_t <= cost or lam < 1e-6:
                break
            lam *= 0.5
        step = float(np.max(np.abs(lam * delta)))
        params, J, r, cost = trial, J_t, r_t, cost_t
        if step < tol:
            break
    else:
        raise ConvergenceError(
            f"Gauss-Newton did not converge in {max_iter} iterations for pair {pair} "
            f"(last step {step:.3g})", last_step=step, iterations=max_iter)
    dof = max(y.size - n_par, 1)
    s2 = cost / dof
    cov = s2 * np.linalg.pinv(J.T @ J)
    return PairCalibration(pair=(i + 1, j + 1), misalignment_deg=params[:4].copy(),
                           transmittance=params[4:6].copy(),
                           dop_scale=float(params[6]) if fit_dop_scale else None,
                           covariance=cov, residuals_V=r.reshape(2, -1).T.copy(),
                           iterations=it, gain=gain, parameter_names=names)
