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
.. [3] M. Born, E. Wolf, *Principles of Optics*, 7th ed., Cambridge University Press (1999),
   sec. 1.4.2 (a partial polarizer's efficiency ``eta = (1 - eps) / (1 + eps)``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import ClassVar

import numpy as np

from ..effects import BASE_NAMES, Context, Effect, geometry, jacobians, outputs
from ..solve import solve_pair
from .fit_result import FitResult
from .lm import levenberg_marquardt

__all__ = ["BASE_UNITS", "N_BASE", "RelativeExtinction", "base_parameters",
           "effect_parameters", "fit_form", "fit_model", "predict"]

N_BASE = len(BASE_NAMES)
BASE_UNITS = ("deg",) * 6 + ("1",) * 4
"""Units of :data:`calibration.effects.BASE_NAMES` (mounting errors [deg]; transmittance
terms and DoP scale dimensionless)."""
_BASE_PRIOR_SD = np.r_[np.full(6, 5.0), np.full(3, 0.2), 1.0]
_BASE_STEP_TOL = np.r_[np.full(6, 1e-5), np.full(3, 1e-7), 1e-7]


class RelativeExtinction(Effect):
    """The extinction-ratio candidate in the form the data identify: how the six polarizers
    differ from their mean.

    A polarizer of extinction ratio ``eps`` passes polarized light with the efficiency
    ``eta = (1 - eps) / (1 + eps) = exp(-2 atanh eps)`` ([3]_;
    :mod:`calibration.effects.extinction_ratio`). A factor common to the six ``eta`` is
    exactly a smaller DoP scale ``s`` (``eta d`` is all the outputs see), and the intensity
    factor ``1 + eps`` is exactly a change of the transmittance terms ``f``. What the outputs
    identify is therefore

    ``eps_k_rel = atanh(eps_k) - mean_j atanh(eps_j)``, ``k = 1..6``, summing to zero

    (equal to ``eps_k - mean(eps)`` within 1 % of the larger ``eps`` for ``eps <= 0.1``).
    The fit frees ``eps_1_rel .. eps_5_rel`` (``eps_6_rel`` is minus their sum; all six are
    reported, :meth:`report`), so no parameter meets the physical bound ``eps >= 0`` that a
    fit of the six ``eps`` themselves presses its lowest one against once the prior pins
    their common level. The model's efficiencies are ``eta_k = exp(-2 eps_k_rel) / M``
    (:meth:`efficiencies`), ``M = (sum_j exp(-2 p eps_j_rel))^(1/p)`` a smooth maximum
    (``p`` = :attr:`SMOOTH_MAX_POWER`: ``M`` is between the largest ``exp(-2 eps_j_rel)``
    and 6^(1/p) = 1.036 times it), so that every ``eta`` is at most 1 and the outputs are
    smooth in the parameters where two polarizers are nearly equal; the base's
    ``dop_scale`` reads ``d_max`` times the common factor.
    """

    name = "extinction_ratio"
    parameter_names = tuple(f"eps_{k}_rel" for k in range(1, 6))
    reported_names = tuple(f"eps_{k}_rel" for k in range(1, 7))
    units = ("1",) * 5
    bounds = np.tile([-0.55, 0.55], (5, 1))
    """``atanh(0.5) = 0.549``: ``eps`` in 0..0.5 (the library effect's range) keeps every
    difference from the mean inside +-0.55."""
    prior_mean = np.zeros(5)
    prior_sd = np.full(5, 0.05)
    """The library effect's prior width per polarizer (it fixes nothing the data see)."""
    fd_step = np.full(5, 1e-4)
    null = np.zeros(5)
    SMOOTH_MAX_POWER = 50.0
    generation_range: ClassVar[dict] = {"eps_k_rel": "differences of the library effect's "
                                        "log-uniform [1e-3, 0.1] eps per polarizer"}

    @staticmethod
    def from_eps(eps) -> np.ndarray:
        """The six ``eps_k_rel`` of six extinction ratios ``eps`` (class docstring)."""
        a = np.arctanh(np.asarray(eps, float))
        return a - a.mean()

    def _all(self, p) -> np.ndarray:
        p = np.asarray(p, float)
        return np.r_[p, -p.sum()]

    def draw(self, rng):
        from ..effects import get_effect
        return self.from_eps(get_effect("extinction_ratio").draw(rng))[:5]

    def _weights(self, p):
        """``(eta, w)``: the efficiencies and the softmax weights ``w_j = dlnM/d(-2 r_j)``."""
        x = -2.0 * self._all(p)
        z = self.SMOOTH_MAX_POWER * (x - x.max())
        w = np.exp(z) / np.exp(z).sum()
        ln_m = x.max() + np.log(np.exp(z).sum()) / self.SMOOTH_MAX_POWER
        return np.exp(x - ln_m), w

    def efficiencies(self, p) -> np.ndarray:
        """The six ``eta_k = exp(-2 eps_k_rel) / M`` (class docstring), each at most 1."""
        return self._weights(p)[0]

    def channel_terms(self, ctx, p):
        return {"extinction": (np.ones(6), self.efficiencies(p))}

    def output_jacobian(self, ctx, p, parts):
        # U = G [log10(A) - log10(B) + f], A = 1 + eta_n d cos 2x_n, B = 1 - eta_m d cos 2x_m,
        # eta_k = exp(-2 r_k) / M: at fixed M, h_k = dU/dr_k is -2 G/ln10 eta_n dc1 / A
        # (numerator) or -2 G/ln10 eta_m dc2 / B (denominator); M moves every eta, with
        # dlnM/dr_j = -2 w_j, so the full column is h_j - w_j sum_k h_k; r_6 = -(r_1 + ...
        # + r_5) makes each free column d/dr_j - d/dr_6
        eta, w = self._weights(p)
        kl = parts["G_ln10"]
        h = np.zeros(parts["A"].shape + (6,))
        ch = np.arange(3)
        h[:, ch, 2 * ch] = -2.0 * kl * eta[0::2] * parts["dc1"] / parts["A"]
        h[:, ch, 2 * ch + 1] = -2.0 * kl * eta[1::2] * parts["dc2"] / parts["B"]
        h = h - w * h.sum(axis=-1, keepdims=True)
        return h[..., :5] - h[..., 5:6]

    def report(self, values, covariance=None) -> dict:
        """``name -> {"value", "se", "unit"}`` of all six ``eps_k_rel`` from the five fitted
        ones (``se`` from their covariance, NaN without one)."""
        T = np.vstack([np.eye(5), -np.ones((1, 5))])
        v = T @ np.asarray(values, float)
        se = (np.full(6, np.nan) if covariance is None
              else np.sqrt(np.maximum(np.diag(T @ covariance @ T.T), 0.0)))
        return {n: {"value": float(a), "se": float(b), "unit": "1"}
                for n, a, b in zip(self.reported_names, v, se)}

    def describe(self, p) -> dict:
        return {n: d["value"] for n, d in self.report(p).items()}


FIT_FORMS = {"extinction_ratio": RelativeExtinction()}
"""Candidates fitted in another form than the library effect's parameters: the combination
the three-pair outputs identify."""


def fit_form(effect: Effect) -> Effect:
    """The form in which ``effect`` is fitted (:data:`FIT_FORMS`; itself otherwise)."""
    return FIT_FORMS.get(effect.name, effect)


def base_parameters(fit: FitResult) -> dict:
    """``name -> {"value", "se", "unit"}`` of the base model."""
    return fit.parameters(slice(0, N_BASE), BASE_NAMES, BASE_UNITS)


def effect_parameters(fit: FitResult, effect: Effect | None) -> dict:
    """``name -> {"value", "se", "unit"}`` of the effect (empty for a base fit)."""
    if effect is None:
        return {}
    if hasattr(effect, "report"):
        idx = np.arange(fit.theta.size)[fit.effect]
        cov = None if fit.covariance is None else fit.covariance[np.ix_(idx, idx)]
        return effect.report(fit.params, cov)
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
    """Levenberg-Marquardt [2]_ MAP fit of the base model plus one effect
    (:func:`calibration.diagnosis.lm.levenberg_marquardt`).

    Minimises ``sum(r^2) / sigma_V^2 + sum(((theta - mu) / sd)^2)`` over the valid readings,
    with the weak prior of the base parameters (mounting errors 5 deg, ``f`` 0.2, ``s`` 1) and
    the effect's own prior; effect parameters are kept within their bounds. The Jacobian is
    analytic where the effect provides its columns (:func:`calibration.effects.jacobians`);
    otherwise the effect's columns are forward differences, geometry-stage parameters
    recomputing stage 1 and the others only stage 2 (:mod:`calibration.effects`).

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
    unbounded = np.full(10, np.inf)
    lower = np.r_[-unbounded, [] if effect is None else effect.bounds[:, 0]]
    upper = np.r_[unbounded, [] if effect is None else effect.bounds[:, 1]]
    geo_param = np.r_[np.zeros(10, bool),
                      np.full(k, effect is not None and effect.stage == "geometry")]

    def split(theta):
        return theta[:10], (theta[10:] if k else None)

    def residual(theta, geo=None):
        b, p = split(theta)
        if geo is None:
            geo = geometry(ctx, effect, p)
        return outputs(ctx, geo[0], geo[1], b, effect, p)[valid] - y, geo

    def jacobian(theta, r0, geo, columns):
        b, p = split(theta)
        Jb, Je = jacobians(ctx, geo[0], geo[1], b, effect, p)
        J = np.zeros((r0.size, theta.size))
        J[:, :10] = Jb[valid]
        if Je is not None:
            J[:, 10:] = Je[valid]
        else:
            for j in range(10, theta.size):  # effect columns by forward differences
                t = theta.copy()
                t[j] += steps[j]
                J[:, j] = (residual(t, None if geo_param[j] else geo)[0] - r0) / steps[j]
        return J[:, columns]

    def run(theta, iters, covariance=False):
        return levenberg_marquardt(residual, jacobian, theta, prior_mu, prior_sd, lower=lower,
                                   upper=upper, sigma=sigma_V, max_iter=iters, tol=tol,
                                   step_tol=small, covariance=covariance)

    starts = [np.r_[b0]] if effect is None else [
        np.r_[b0, effect.clip(s)] for s in ([effect0] if effect0 is not None
                                            else effect.starts())]
    if effect is not None and effect0 is None and hasattr(effect, "coarse_starts"):
        # screen a coarse grid (e.g. whole and half hours of a clock offset) at zero
        # iterations and keep the best three as starts
        grid = effect.coarse_starts(ctx, b0)
        costs = [run(g, 0).cost for g in grid]
        starts = starts + [grid[i] for i in np.argsort(costs)[:3]]
    if len(starts) > 1:  # a few iterations from each start, then continue the best
        best = min((run(s, 2) for s in starts), key=lambda f: f.cost).theta
    else:
        best = starts[0]
    return replace(run(best, max_iter, covariance=True), free=None,
                   effect=slice(N_BASE, best.size))
