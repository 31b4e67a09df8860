"""Levenberg-Marquardt maximum a-posteriori fit with a Gaussian prior and box bounds.

Every instrument's diagnosis fits its forward model with this one method; an instrument
supplies only its residuals and their Jacobian (analytic, or by grouped forward differences).

The objective is

``S(theta) = sum(r(theta)^2) / sigma^2 + sum(((theta - mu) / sd)^2)``

over the free parameters (an infinite ``sd`` puts no prior on a parameter). Each iteration
solves the damped normal equations ``(A + lam D) delta = -g`` with ``A = J^T J / sigma^2 +
diag(1 / sd^2)`` the Gauss-Newton information, ``g = J^T r / sigma^2 + (theta - mu) / sd^2``
half the gradient and ``D = diag(A)`` (Marquardt's scaling, which makes the step invariant to
the parameters' units [1]_). A trial fails when the system is singular, when the model is
evaluated outside its valid range, or when ``S`` does not strictly decrease; the damping
``lam`` then grows and the trial is repeated, and after an accepted step it shrinks, by the
factors of a :class:`Damping` schedule: Marquardt's ([1]_) or a trust-region one ([2]_).
Bounds are kept by clipping each trial into the box; a parameter at a bound whose gradient
points out of the box is held for that iteration (the active set of the projected Newton
method [3]_), so that the others' step is not computed as if it could move.

References
----------
.. [1] D. W. Marquardt, "An algorithm for least-squares estimation of nonlinear parameters",
   J. SIAM 11(2):431-441 (1963), doi:10.1137/0111030.
.. [2] J. Nocedal, S. J. Wright, *Numerical Optimization*, 2nd ed., Springer (2006),
   Algorithm 4.1 (trust-region radius update) and sect. 10.3 (Levenberg-Marquardt as a
   trust-region method).
.. [3] D. P. Bertsekas, "Projected Newton methods for optimization problems with simple
   constraints", SIAM J. Control Optim. 20(2):221-246 (1982), doi:10.1137/0320018.
.. [4] Y. Pawitan, *In All Likelihood: Statistical Modelling and Inference Using
   Likelihood*, Oxford University Press (2001), sect. 3.4 (profile likelihood; its curvature
   is the inverse of the joint information's block of the parameter of interest).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from skysim.exceptions import InvalidParameterError

from .fit_result import FitResult

__all__ = ["Damping", "MARQUARDT", "TRUST_REGION", "information", "levenberg_marquardt"]

LAMBDA_START = 1e-3
"""Initial damping (Marquardt's ``lambda``, relative to the scaled diagonal)."""
LAMBDA_MIN = 1e-9
"""Floor of the damping (the step stays within round-off of the Gauss-Newton step)."""


@dataclass(frozen=True)
class Damping:
    """How the damping follows the trials: times ``up`` after a failed trial, divided by
    ``down`` after an accepted step, at most ``trials`` trials an iteration (no decrease in
    all of them: no descent left at working precision, converged)."""

    up: float
    down: float
    trials: int


MARQUARDT = Damping(10.0, 10.0, 12)
"""Marquardt's own schedule ([1]_: ``nu = 10`` both ways); twelve trials raise the damping
by ``1e12``."""
TRUST_REGION = Damping(4.0, 3.0, 10)
"""A trust-region schedule: a failed trial shrinks a damping-dominated step to a quarter, the
radius reduction of Nocedal & Wright's Algorithm 4.1 ([2]_) on a poor step; an accepted one
lets it grow by three; ten trials raise the damping by ``4^10 ~ 1e6``."""


def information(J, sigma: float, prior_weight) -> np.ndarray:
    """Gauss-Newton information ``J^T J / sigma^2 + diag(prior_weight)`` (dense).

    Parameters
    ----------
    J : ndarray or scipy.sparse matrix (m, k)
        Jacobian of the data residuals [data unit per parameter unit].
    sigma : float
        Noise level of the residuals [data unit].
    prior_weight : ndarray (k,)
        ``1 / sd^2`` of each column's parameter, 0 where it has no prior.
    """
    JtJ = J.T @ J
    if sp.issparse(JtJ):
        JtJ = JtJ.toarray()
    return JtJ / sigma ** 2 + np.diag(prior_weight)


def _prior_weight(sd) -> np.ndarray:
    return np.where(np.isfinite(sd), 1.0 / np.asarray(sd, float) ** 2, 0.0)


def _vector(values, p: int, name: str, dtype=float) -> np.ndarray:
    """``values`` as a vector of one entry per parameter, or a one-line error naming it."""
    v = np.asarray(values, dtype).ravel()
    if v.size != p:
        raise InvalidParameterError(f"{name} has {v.size} values for {p} parameters")
    return v


def levenberg_marquardt(residual: Callable[[np.ndarray], tuple[np.ndarray, Any]],
                        jacobian: Callable[[np.ndarray, np.ndarray, Any, np.ndarray], Any],
                        theta0, prior_mean, prior_sd, *, lower=None, upper=None, free=None,
                        sigma: float = 1.0, max_iter: int = 100, tol: float = 1e-8,
                        step_tol=None, damping: Damping = MARQUARDT,
                        hold_at_bounds: bool = True, covariance: bool = False,
                        profiled=None) -> FitResult:
    """Maximum a-posteriori fit of ``theta`` by Levenberg-Marquardt (module docstring).

    Parameters
    ----------
    residual : callable
        ``residual(theta) -> (r, state)``: the data residuals ``r`` (1-D, model minus data,
        in the data's unit) and anything the Jacobian reuses (a sampled sky, a geometry).
        It may raise :class:`~skysim.exceptions.InvalidParameterError` where ``theta`` leaves
        the model's valid range; a trial that does is a failed trial.
    jacobian : callable
        ``jacobian(theta, r, state, columns) -> J``: ``d r / d theta[columns]`` (``columns`` a
        boolean mask), an ndarray or scipy.sparse matrix of shape ``(r.size,
        columns.sum())``.
    theta0 : array_like (p,)
        Start, and the value of the parameters not fitted; clipped into the bounds.
    prior_mean, prior_sd : array_like (p,)
        Gaussian prior of each parameter (``sd`` infinite: none) [parameter units].
    lower, upper : array_like (p,), optional
        Bounds (default unbounded).
    free : array_like (p,) bool, optional
        Parameters fitted (default all).
    sigma : float
        Noise level of the residuals [data unit], weighting the data against the prior.
    max_iter : int
        Iteration limit; 0 evaluates the cost at the start.
    tol : float
        Converged when an accepted step lowers the cost by less than ``tol`` of it.
    step_tol : array_like (p,), optional
        Also converged when every parameter moved by less than this in a step.
    damping : Damping
        The damping schedule (:data:`MARQUARDT`, :data:`TRUST_REGION`).
    hold_at_bounds : bool
        Hold a parameter at a bound whose gradient points out of the box for the iteration
        (module docstring); False solves for every free parameter and only clips the trial.
    covariance : bool
        Compute the posterior covariance of the free parameters at the optimum,
        ``A^+ max(1, chi2 / (m - k))`` with ``A`` the information (:func:`information`),
        ``chi2`` the data part of the cost, ``m`` the residuals and ``k`` the free
        parameters: the prior-weighted Gauss-Newton covariance, widened where the residuals
        exceed ``sigma``.
    profiled : array_like (p,) bool, optional
        Parameters held in the fit whose uncertainty the covariance takes in: it is the
        free parameters' block of the inverse of the joint information of the free and the
        profiled ones, the Laplace approximation of profiling them out ([4]_).

    Returns
    -------
    FitResult
        ``theta`` (all parameters), ``cost`` ``S``, ``rms`` of the data residuals, the
        iterations taken, ``converged`` (False when ``max_iter`` was reached),
        ``covariance`` (free parameters, in order; None unless asked) and ``free``.
    """
    theta = np.asarray(theta0, float).ravel().copy()
    p = theta.size
    mu, sd = _vector(prior_mean, p, "prior_mean"), _vector(prior_sd, p, "prior_sd")
    lower = np.full(p, -np.inf) if lower is None else _vector(lower, p, "lower")
    upper = np.full(p, np.inf) if upper is None else _vector(upper, p, "upper")
    free = np.ones(p, bool) if free is None else _vector(free, p, "free", bool).copy()
    if not sigma > 0.0:
        raise InvalidParameterError(f"sigma {sigma} must be positive")
    bad = np.flatnonzero(~(sd > 0.0))
    if bad.size:
        raise InvalidParameterError(f"prior_sd {sd[bad[0]]} of parameter {bad[0]} must be "
                                    "positive")
    bad = np.flatnonzero(~(upper >= lower))
    if bad.size:
        raise InvalidParameterError(f"upper bound {upper[bad[0]]} of parameter {bad[0]} is "
                                    f"below its lower bound {lower[bad[0]]}")
    theta = np.clip(theta, lower, upper)
    fidx = np.flatnonzero(free)
    w_prior = _prior_weight(sd[fidx])

    def cost_of(t, r):
        dp = (t[fidx] - mu[fidx])
        return float(np.sum(r ** 2) / sigma ** 2 + np.sum(w_prior * dp ** 2))

    r, state = residual(theta)
    cost = cost_of(theta, r)
    lam, converged, it = LAMBDA_START, False, 0
    for it in range(1, max_iter + 1):
        J = jacobian(theta, r, state, free)
        A = information(J, sigma, w_prior)
        g = J.T @ r / sigma ** 2 + w_prior * (theta[fidx] - mu[fidx])
        t_f = theta[fidx]
        held = ((t_f <= lower[fidx]) & (g > 0)) | ((t_f >= upper[fidx]) & (g < 0))
        held &= hold_at_bounds
        move = fidx[~held]
        if move.size == 0:
            converged = True          # every free parameter pressed against its bound
            break
        if held.any():
            A, g = A[np.ix_(~held, ~held)], g[~held]
        improved = False
        for _ in range(damping.trials):
            M = A + lam * np.diag(np.maximum(np.diag(A), 1e-12))
            try:
                delta = -np.linalg.solve(M, g)
            except np.linalg.LinAlgError:
                lam *= damping.up
                continue
            t_new = theta.copy()
            t_new[move] += delta
            t_new = np.clip(t_new, lower, upper)
            try:
                r_new, state_new = residual(t_new)
            except InvalidParameterError:
                lam *= damping.up
                continue
            c_new = cost_of(t_new, r_new)
            if c_new < cost:
                rel = (cost - c_new) / max(cost, 1e-300)
                small = step_tol is not None and np.all(np.abs(t_new - theta) < step_tol)
                theta, r, state, cost = t_new, r_new, state_new, c_new
                lam = max(lam / damping.down, LAMBDA_MIN)
                improved = True
                break
            lam *= damping.up
        if not improved or rel < tol or small:
            converged = True          # no decrease at any damping, or too small to matter
            break
    cov = None
    if covariance:
        joint = free.copy()
        if profiled is not None:
            joint |= np.asarray(profiled, bool)
        jidx = np.flatnonzero(joint)
        A = information(jacobian(theta, r, state, joint), sigma, _prior_weight(sd[jidx]))
        dof = max(r.size - fidx.size, 1)
        chi2 = float(np.sum(r ** 2) / sigma ** 2) / dof
        keep = np.flatnonzero(free[jidx])     # the free parameters' rows of the joint one
        cov = (np.linalg.pinv(A) * max(chi2, 1.0))[np.ix_(keep, keep)]
    rms = float(np.sqrt(np.mean(r ** 2))) if r.size else np.nan
    return FitResult(theta, cost, rms, it, converged, cov, free)
