"""Least-squares compensation of a channel pair (Gauss-Newton), Yang et al. (2014).

For a pair ``(i, j)`` the unknowns are ``psi = (dth_i1, dth_i2, dth_j1, dth_j2, f_i, f_j)``
(eq. 10 of [1]_), optionally with a DoP scale ``s`` (the sky's ``d_max`` when ``dop`` is the
Rayleigh shape ``sin^2 g / (1 + cos^2 g)``). Given reference polarization azimuths ``phi_k``
(turntable heading minus sun azimuth) and outputs ``U_ik, U_jk``, minimise
``sum_k (U_ik - F_i(phi_k; psi))^2 + (U_jk - F_j(phi_k; psi))^2`` (eq. 11) by Gauss-Newton
steps ``psi <- psi - (J^T J)^-1 J^T r`` (eqs. 12-14) with the analytic Jacobian of
:mod:`calibration.model`, halving a step that does not lower the cost.

:func:`fit_pairs` runs many independent calibrations at once (leading batch axes: Monte-Carlo
trials, sweeps, sensors), all in numpy; :func:`fit_pair` is the single-calibration form.
The columns of ``J`` are scaled to unit norm before the normal equations are solved (Jacobi
preconditioning: angles in degrees and log-offsets differ in scale by ~1e2).

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424, eqs. (10)-(14).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sensor.opponent import CHANNEL_ANGLES_DEG, GAIN
from skysim.exceptions import BroadcastError, InvalidParameterError
from skysim.validation import as_float_array, check_finite

from .exceptions import ConvergenceError, RankDeficientError, TooFewSamplesError
from .model import channel_jacobian
from .solve import pair_index, solve_pair, solve_pair_compensated

__all__ = ["PairCalibration", "BatchPairCalibration", "fit_pair", "fit_pairs",
           "PARAMETER_NAMES"]

PARAMETER_NAMES = ("dtheta_i1_deg", "dtheta_i2_deg", "dtheta_j1_deg", "dtheta_j2_deg",
                   "f_i", "f_j", "dop_scale")


@dataclass(frozen=True)
class BatchPairCalibration:
    """Result of :func:`fit_pairs`: one calibration per element of the batch shape ``B``.

    Attributes
    ----------
    pair : (int, int)
    misalignment_deg : ndarray (*B, 4)
        ``(dth_i1, dth_i2, dth_j1, dth_j2)`` [deg] (for pair (1, 2): dth1..dth4).
    transmittance : ndarray (*B, 2)
        ``(f_i, f_j)``.
    dop_scale : ndarray (*B,) or None
        Fitted DoP scale (None when the DoP was given).
    covariance : ndarray (*B, p, p)
        ``s^2 (J^T J)^-1`` with ``s^2 = SSR / (2n - p)``.
    residuals_V : ndarray (*B, n, 2)
    iterations : ndarray (*B,) of int
    converged : ndarray (*B,) of bool
    """

    pair: tuple
    misalignment_deg: np.ndarray
    transmittance: np.ndarray
    dop_scale: np.ndarray | None
    covariance: np.ndarray
    residuals_V: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    gain: float = GAIN
    parameter_names: tuple = field(default=PARAMETER_NAMES[:6])

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.diagonal(self.covariance, axis1=-2, axis2=-1))

    @property
    def rms_residual_V(self) -> np.ndarray:
        return np.sqrt(np.mean(self.residuals_V ** 2, axis=(-2, -1)))

    def solve(self, U) -> tuple[np.ndarray, np.ndarray]:
        """Compensated polarization azimuth [deg] and DoP for outputs ``U`` (*B, m, 3)."""
        return solve_pair_compensated(U, self.pair, self.misalignment_deg, self.transmittance,
                                      self.gain)

    def element(self, index) -> "PairCalibration":
        """The calibration of one batch element (``index`` into the batch shape)."""
        def pick(a):
            return None if a is None else np.asarray(a[index])
        scale = pick(self.dop_scale)
        return PairCalibration(
            pair=self.pair, misalignment_deg=pick(self.misalignment_deg),
            transmittance=pick(self.transmittance),
            dop_scale=None if scale is None else float(scale),
            covariance=pick(self.covariance), residuals_V=pick(self.residuals_V),
            iterations=int(self.iterations[index]), converged=bool(self.converged[index]),
            gain=self.gain, parameter_names=self.parameter_names)


@dataclass(frozen=True)
class PairCalibration(BatchPairCalibration):
    """Result of :func:`fit_pair`: a :class:`BatchPairCalibration` with an empty batch shape
    (scalars ``dop_scale``, ``iterations``, ``converged``; ``residuals_V`` of shape (n, 2))."""

    def to_dict(self) -> dict:
        values = np.r_[self.misalignment_deg, self.transmittance,
                       [] if self.dop_scale is None else [self.dop_scale]]
        return {"pair": list(self.pair),
                "parameters": dict(zip(self.parameter_names, values.tolist())),
                "standard_errors": dict(zip(self.parameter_names, self.standard_errors.tolist())),
                "rms_residual_V": float(self.rms_residual_V),
                "iterations": int(self.iterations), "converged": bool(self.converged)}


def _model(params, phi, dop, a, gain, fit_scale):
    """Stacked residual-model values ``(b, 2n)`` and Jacobian ``(b, 2n, p)``.

    Rows are channel-major: the n samples of channel i, then those of channel j.
    """
    s = params[:, 6:7] if fit_scale else 1.0
    d = np.clip(s * dop, 1e-9, 1 - 1e-9)
    val, jac = channel_jacobian(phi[..., None], d[..., None], a, params[:, None, 0:4:2],
                                params[:, None, 1:4:2], params[:, None, 4:6], gain,
                                wrt=("e1", "e2", "dop"))                 # each (b, n, 2)
    b, n = phi.shape
    p = params.shape[1]
    J = np.zeros((b, 2, n, p))
    for c in range(2):  # two channels of the pair (columns: e1_c, e2_c, f_c)
        J[:, c, :, 2 * c] = jac["e1"][..., c]
        J[:, c, :, 2 * c + 1] = jac["e2"][..., c]
        J[:, c, :, 4 + c] = gain
        if fit_scale:
            J[:, c, :, 6] = jac["dop"][..., c] * dop
    return val.transpose(0, 2, 1).reshape(b, 2 * n), J.reshape(b, 2 * n, p)


def _check_inputs(phi_deg, U, dop):
    phi = check_finite("phi_deg", phi_deg)
    U = check_finite("U", U)
    if phi.ndim == 0 or U.shape != phi.shape + (3,):
        raise InvalidParameterError(
            f"U must have shape phi_deg.shape + (3,) = {phi.shape + (3,)}; "
            f"got {U.shape}")
    if dop is None:
        raise InvalidParameterError(
            "dop is required: the DoP per sample, or its shape with fit_dop_scale")
    try:
        dop = np.broadcast_to(check_finite("dop", dop), phi.shape).astype(float)
    except ValueError as exc:
        raise BroadcastError(f"dop of shape {np.shape(dop)} does not broadcast to phi_deg's "
                             f"shape {phi.shape}") from exc
    return phi, U, dop


def _index(flat: int, batch: tuple) -> tuple:
    """Batch index of a flat element, as plain ints (for messages)."""
    return tuple(int(x) for x in np.unravel_index(flat, batch))


def fit_pairs(phi_deg, U, pair=(1, 2), dop=None, *, fit_dop_scale: bool = False,
              gain: float = GAIN, max_iter: int = 50, tol: float = 1e-9,
              rcond: float = 1e-10, on_failure: str = "raise") -> BatchPairCalibration:
    """Gauss-Newton estimates of a pair's mounting errors and transmittance terms, batched.

    Parameters
    ----------
    phi_deg : array (*B, n)
        Reference polarization azimuth of each sample [deg]; ``B`` is any batch shape
        (e.g. Monte-Carlo trials) of independent calibrations.
    U : array (*B, n, 3)
        Channel outputs U1..U3 [V].
    pair : (int, int)
    dop : array broadcastable to (*B, n)
        Degree of polarization of each sample; with ``fit_dop_scale`` only its shape matters
        (a scale is fitted, started from the ideal-model estimate).
    fit_dop_scale : bool
        Fit a DoP scale as 7th parameter.
    max_iter, tol : convergence control (``tol`` on the largest update, in deg or log units).
    rcond : float
        Smallest admissible ratio of singular values of the column-scaled Jacobian.
    on_failure : {"raise", "flag"}
        ``"raise"``: a rank-deficient or non-converged element raises (naming its batch
        index). ``"flag"``: such elements get ``converged = False`` (rank-deficient ones keep
        their starting values) and the others are returned; sweeps use this.

    Returns
    -------
    BatchPairCalibration

    Raises
    ------
    TooFewSamplesError
        If there are fewer samples than parameters (6, or 7 with ``fit_dop_scale``).
    RankDeficientError
        If a Jacobian is rank deficient (names the least observable parameter).
    ConvergenceError
        If an element has not converged within ``max_iter`` (reports the last step size).
    """
    if on_failure not in ("raise", "flag"):
        raise InvalidParameterError(f"on_failure must be 'raise' or 'flag'; got {on_failure!r}")
    phi, U, dop = _check_inputs(phi_deg, U, dop)
    batch, n = phi.shape[:-1], phi.shape[-1]
    i, j = pair_index(pair)
    n_par = 7 if fit_dop_scale else 6
    if n < n_par:
        raise TooFewSamplesError(
            f"{n} samples for {n_par} parameters; the compensation needs at least "
            f"{n_par} samples spread over the polarization azimuth")
    names = PARAMETER_NAMES[:n_par]
    phi, dop, U = phi.reshape(-1, n), dop.reshape(-1, n), U.reshape(-1, n, 3)
    b = phi.shape[0]
    a = CHANNEL_ANGLES_DEG[[i, j]]
    y = U[..., [i, j]].transpose(0, 2, 1).reshape(b, 2 * n)
    params = np.zeros((b, n_par))
    if fit_dop_scale:
        _, d_ideal = solve_pair(U, pair, gain)
        params[:, 6] = np.nanmedian(d_ideal / np.where(dop > 0, dop, np.nan), axis=-1)

    val, J = _model(params, phi, dop, a, gain, fit_dop_scale)
    r = val - y
    cost = np.einsum("bk,bk->b", r, r)
    active = np.ones(b, bool)
    rank_ok = np.ones(b, bool)
    iterations = np.zeros(b, int)
    last_step = np.full(b, np.inf)
    for it in range(1, max_iter + 1):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        norms = np.linalg.norm(J[idx], axis=1)                      # (k, p)
        norms[norms == 0] = 1.0
        Js = J[idx] / norms[:, None, :]
        N = np.matmul(Js.transpose(0, 2, 1), Js)
        ev = np.linalg.eigvalsh(N)                                   # ascending, = sv^2
        bad = ev[:, 0] < (rcond ** 2) * ev[:, -1]
        if bad.any():
            k = idx[np.flatnonzero(bad)[0]]
            if on_failure == "raise":
                _, vecs = np.linalg.eigh(N[np.flatnonzero(bad)[0]])
                worst = names[int(np.argmax(np.abs(vecs[:, 0])))]
                where = "" if not batch else f" (batch element {_index(k, batch)})"
                raise RankDeficientError(
                    f"Jacobian is rank deficient{where}; parameter {worst!r} is not "
                    f"observable from these samples: spread the polarization azimuths over "
                    f"[-90, 90) deg (range here: {phi[k].min():.2f}..{phi[k].max():.2f} deg)")
            rank_ok[idx[bad]] = False
            active[idx[bad]] = False
            keep = ~bad
            idx, N, Js, norms = idx[keep], N[keep], Js[keep], norms[keep]
        g = np.matmul(-r[idx][:, None, :], Js)[:, 0, :]
        delta = np.linalg.solve(N, g[..., None])[..., 0] / norms
        lam = np.ones(idx.size)
        pending = np.ones(idx.size, bool)
        new_params, new_val, new_J = params[idx].copy(), val[idx].copy(), J[idx].copy()
        new_cost = cost[idx].copy()
        for _ in range(30):  # step halving keeps each Gauss-Newton step a descent step
            sel = np.flatnonzero(pending)
            trial = params[idx[sel]] + lam[sel, None] * delta[sel]
            v_t, J_t = _model(trial, phi[idx[sel]], dop[idx[sel]], a, gain, fit_dop_scale)
            r_t = v_t - y[idx[sel]]
            c_t = np.einsum("bk,bk->b", r_t, r_t)
            # accept a descent step, or a change at rounding level (converged elements
            # would otherwise halve ~20 times for nothing)
            ok = (c_t <= cost[idx[sel]] * (1.0 + 1e-10)) | (lam[sel] < 1e-6)
            acc = sel[ok]
            new_params[acc], new_val[acc], new_J[acc], new_cost[acc] = (
                trial[ok], v_t[ok], J_t[ok], c_t[ok])
            pending[acc] = False
            lam[sel[~ok]] *= 0.5
            if not pending.any():
                break
        step = np.max(np.abs(lam[:, None] * delta), axis=1)
        params[idx], val[idx], J[idx], cost[idx] = new_params, new_val, new_J, new_cost
        r[idx] = val[idx] - y[idx]
        iterations[idx] = it
        last_step[idx] = step
        active[idx[step < tol]] = False
    converged = rank_ok & (last_step < tol)
    if on_failure == "raise" and not converged.all():
        k = int(np.flatnonzero(~converged)[0])
        where = "" if not batch else f" (batch element {_index(k, batch)})"
        raise ConvergenceError(
            f"Gauss-Newton did not converge in {max_iter} iterations for pair {pair}{where} "
            f"(last step {last_step[k]:.3g})", last_step=float(last_step[k]),
            iterations=max_iter)
    dof = max(2 * n - n_par, 1)
    s2 = cost / dof
    cov = s2[:, None, None] * np.linalg.pinv(np.matmul(J.transpose(0, 2, 1), J))
    res = r.reshape(b, 2, n).transpose(0, 2, 1)
    return BatchPairCalibration(
        pair=(i + 1, j + 1), misalignment_deg=params[:, :4].reshape(batch + (4,)),
        transmittance=params[:, 4:6].reshape(batch + (2,)),
        dop_scale=params[:, 6].reshape(batch) if fit_dop_scale else None,
        covariance=cov.reshape(batch + (n_par, n_par)), residuals_V=res.reshape(batch + (n, 2)),
        iterations=iterations.reshape(batch), converged=converged.reshape(batch), gain=gain,
        parameter_names=names)


def fit_pair(phi_deg, U, pair=(1, 2), dop=None, *, fit_dop_scale: bool = False,
             gain: float = GAIN, max_iter: int = 50, tol: float = 1e-9,
             rcond: float = 1e-10) -> PairCalibration:
    """Gauss-Newton estimate of one pair's mounting errors and transmittance terms.

    Parameters
    ----------
    phi_deg : array (n,)
        Reference polarization azimuth of each sample [deg].
    U : array (n, 3)
        Channel outputs U1..U3 [V].
    pair, dop, fit_dop_scale, gain, max_iter, tol, rcond
        As in :func:`fit_pairs`.

    Returns
    -------
    PairCalibration

    Raises
    ------
    TooFewSamplesError, RankDeficientError, ConvergenceError
        As :func:`fit_pairs` with ``on_failure="raise"``.
    """
    phi = as_float_array("phi_deg", phi_deg).ravel()
    U = as_float_array("U", U)
    if U.ndim != 2 or U.shape[1] != 3 or U.shape[0] != phi.size:
        raise InvalidParameterError(
            f"U must have shape (n, 3) with n = len(phi_deg) = {phi.size}; "
            f"got {U.shape}")
    if dop is not None and np.ndim(dop):
        dop = np.ravel(dop)[None]
    return fit_pairs(phi[None], U[None], pair, dop, fit_dop_scale=fit_dop_scale, gain=gain,
                     max_iter=max_iter, tol=tol, rcond=rcond, on_failure="raise").element(0)
