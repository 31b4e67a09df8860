"""Levenberg-Marquardt fit of the three-pair sensor's base model plus one effect.

The base model is eqs. (2)-(3) of Yang et al. (2014) [1]_ with the LSM's six mounting
errors, three transmittance terms and the DoP scale ``d_max`` (all three channels jointly);
an effect of :mod:`calibration.effects` adds its own parameters (its forward hooks).

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424, eqs. (2)-(3), (10)-(14).
.. [2] D. W. Marquardt, "An algorithm for least-squares estimation of nonlinear
   parameters", J. Soc. Ind. Appl. Math. 11(2):431-441 (1963), doi:10.1137/0111030.
"""

from __future__ import annotations

import numpy as np

from ..effects import BASE_NAMES, Context, Effect, geometry, jacobians, outputs
from ..solve import solve_pair
from .fit_result import FitResult

__all__ = ["BASE_UNITS", "N_BASE", "base_parameters", "effect_parameters", "fit_model",
           "predict"]

N_BASE = len(BASE_NAMES)
BASE_UNITS = ("deg",) * 6 + ("1",) * 4
"""Units of :data:`calibration.effects.BASE_NAMES` (mounting errors [deg]; transmittance
terms and DoP scale dimensionless)."""
_BASE_PRIOR_SD = np.r_[np.full(6, 5.0), np.full(3, 0.2), 1.0]
_BASE_STEP_TOL = np.r_[np.full(6, 1e-5), np.full(3, 1e-7), 1e-7]


def base_parameters(fit: FitResult) -> dict:
    """``name -> {"value", "se", "unit"}`` of the base model."""
    return fit.parameters(slice(0, N_BASE), BASE_NAMES, BASE_UNITS)


def effect_parameters(fit: FitResult, effect: Effect | None) -> dict:
    """``name -> {"value", "se", "unit"}`` of the effect (empty for a base fit)."""
    if effect is None:
        return {}
    return fit.parameters(fit.effect, effect.parameter_names, effect.units)


def predict(ctx: Context, fit: FitResult, effect: Effect | None) -> np.ndarray:
    """Channel outputs (n, 3) [V] of a fitted model at the samples of ``ctx``."""
    p = fit.params if effect is not None else None
    phi, shape = geometry(ctx, effect, p)
    return outputs(ctx, phi, shape, fit.base, effect, p)


def _initial_base(U, valid, shape) -> np.ndarray:
    """Start of the base fit: zero mounting errors and ``f``; ``s`` from the ideal solve."""
    ok = valid[:, 0] & valid[:, 1]
    s = 0.7
    if ok.sum() >= 3:
        _, d = solve_pair(np.where(valid, U, 0.0)[ok], (1, 2))
        ratio = d / np.maximum(shape[ok], 1e-3)
        s = float(np.clip(np.median(ratio), 0.05, 0.99))
    return np.r_[np.zeros(9), s]


def fit_model(ctx: Context, U, valid, effect: Effect | None = None, *, base0=None,
              effect0=None, sigma_V: float = 5e-4, max_iter: int = 100,
              tol: float = 1e-8) -> FitResult:
    """Levenberg-Marquardt [2]_ MAP fit of the base model plus one effect.

    Minimises ``sum(r^2) / sigma_V^2 + sum(((theta - mu) / sd)^2)`` over the valid readings,
    with the weak prior of the base parameters (mounting errors 5 deg, ``f`` 0.2, ``s`` 1) and
    the effect's own prior; effect parameters are clipped into their bounds after each step.
    Geometry-stage parameters recompute stage 1 for their Jacobian columns, the others only
    stage 2 (:mod:`calibration.effects`).

    Parameters
    ----------
    ctx : Context
    U : ndarray (n, 3)
        Measured outputs [V].
    valid : ndarray (n, 3) bool
    effect : Effect, optional
    base0, effect0 : starting vectors (default: ideal-solve start, the effect's starts)
    sigma_V : float
        Noise level [V] weighting the data against the prior.

    Returns
    -------
    FitResult
        ``converged`` is False when ``max_iter`` was reached (the caller reports it).
    """
    k = 0 if effect is None else effect.k
    y = U[valid]
    geo0 = geometry(ctx) if base0 is None else None
    b0 = _initial_base(U, valid, geo0[1]) if base0 is None else np.asarray(base0, float)
    prior_mu = np.r_[np.zeros(9), b0[9], [] if effect is None else effect.prior_mean]
    prior_sd = np.r_[_BASE_PRIOR_SD, [] if effect is None else effect.prior_sd]
    steps = np.r_[np.ones(10), [] if effect is None else effect.fd_step]
    small = np.r_[_BASE_STEP_TOL, [] if effect is None else 1e-3 * effect.fd_step]
    geo_param = np.r_[np.zeros(10, bool),
                      np.full(k, effect is not None and effect.stage == "geometry")]

    def split(theta):
        return theta[:10], (theta[10:] if k else None)

    def evaluate(theta, geo=None):
        b, p = split(theta)
        if geo is None:
            geo = geometry(ctx, effect, p)
        r = (outputs(ctx, geo[0], geo[1], b, effect, p)[valid] - y) / sigma_V
        return np.r_[r, (theta - prior_mu) / prior_sd], geo

    def jacobian(theta, geo, r0):
        J = np.zeros((r0.size, theta.size))
        b, p = split(theta)
        m = int(valid.sum())
        Jb, Je = jacobians(ctx, geo[0], geo[1], b, effect, p)
        J[:m, :10] = Jb[valid] / sigma_V
        J[m:, :] = np.diag(1.0 / prior_sd)
        if Je is not None:
            J[:m, 10:] = Je[valid] / sigma_V
            return J
        for j in range(10, theta.size):  # effect columns by forward differences
            t = theta.copy()
            t[j] += steps[j]
            rj, _ = evaluate(t, None if geo_param[j] else geo)
            J[:, j] = (rj - r0) / steps[j]
        return J

    def run(theta, iters):
        r, geo = evaluate(theta)
        cost = r @ r
        lam = 1e-3
        it, converged = 0, False
        for it in range(1, iters + 1):
            J = jacobian(theta, geo, r)
            JtJ = J.T @ J
            g = J.T @ r
            # active set: effect parameters held at a bound the descent direction points out of
            free = np.ones(theta.size, bool)
            if k:
                lo, hi = effect.bounds[:, 0], effect.bounds[:, 1]
                pe = theta[10:]
                free[10:] = ~(((pe <= lo) & (g[10:] > 0)) | ((pe >= hi) & (g[10:] < 0)))
            Jf = JtJ[np.ix_(free, free)]
            improved = False
            for _ in range(12):
                delta = np.zeros(theta.size)
                A = Jf + lam * np.diag(np.diag(Jf) + 1e-12)
                delta[free] = -np.linalg.solve(A, g[free])
                trial = theta + delta
                if k:
                    trial[10:] = effect.clip(trial[10:])
                r_t, geo_t = evaluate(trial)
                cost_t = r_t @ r_t
                if cost_t <= cost:
                    improved = True
                    break
                lam *= 10.0
            if not improved:
                converged = True  # no descent direction left at this damping: a minimum
                break
            rel = (cost - cost_t) / max(cost, 1e-300)
            theta, r, geo, cost = trial, r_t, geo_t, cost_t
            lam = max(lam / 10.0, 1e-9)
            if rel < tol or np.all(np.abs(delta) < small):
                converged = True
                break
        return theta, cost, it, converged, r, geo

    starts = [np.r_[b0]] if effect is None else [
        np.r_[b0, effect.clip(s)] for s in ([effect0] if effect0 is not None
                                            else effect.starts())]
    if effect is not None and effect0 is None and hasattr(effect, "coarse_starts"):
        # screen a coarse grid (e.g. whole and half hours of a clock offset) at zero
        # iterations and keep the best three as starts
        grid = effect.coarse_starts(ctx, b0)
        costs = [run(g, 0)[1] for g in grid]
        starts = starts + [grid[i] for i in np.argsort(costs)[:3]]
    if len(starts) > 1:  # a few iterations from each start, then continue the best
        trials = [run(s, 2) for s in starts]
        best = min(trials, key=lambda t: t[1])[0]
    else:
        best = starts[0]
    theta, cost, it, converged, r, geo = run(best, max_iter)
    J = jacobian(theta, geo, r)
    m = int(valid.sum())
    dof = max(m - theta.size, 1)
    chi2 = float(np.sum(r[:m] ** 2))
    cov = np.linalg.pinv(J.T @ J) * max(1.0, chi2 / dof)
    return FitResult(theta.copy(), float(cost), float(np.sqrt(chi2 / max(m, 1)) * sigma_V), it,
                     converged, cov, None, slice(N_BASE, theta.size))

