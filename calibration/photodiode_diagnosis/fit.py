"""Least-squares fit of the forward model: Levenberg-Marquardt with a grouped sparse Jacobian.

The Jacobian is formed by forward differences, several columns per model evaluation where the
columns touch disjoint readings (Curtis, Powell & Reid 1974 [1]_): the gains and offsets of the
k-th photodiode of every unit in one evaluation, all polarizer offsets in one, all per-sweep
heading offsets in one. Output-stage columns reuse the sky sampled at the current point; only
heading and effect columns sample the sky again. The fit is the Levenberg-Marquardt (Marquardt
1963 [2]_) maximum a-posteriori fit of :func:`calibration.diagnosis.lm.levenberg_marquardt`,
objective ``sum(r^2) / sigma^2 + sum(((theta - mu) / sd)^2)``, the weak prior fixing
directions the data leave free (a unit's common gain, which the profiled radiance absorbs);
parameters are kept within their bounds.

References
----------
.. [1] A. R. Curtis, M. J. D. Powell, J. K. Reid, "On the estimation of sparse Jacobian
   matrices", IMA J. Appl. Math. 13(1):117-119 (1974), doi:10.1093/imamat/13.1.117.
.. [2] D. W. Marquardt, "An algorithm for least-squares estimation of nonlinear parameters",
   J. SIAM 11(2):431-441 (1963), doi:10.1137/0111030.
.. [3] Y. Pawitan, *In All Likelihood: Statistical Modelling and Inference Using
   Likelihood*, Oxford University Press (2001), sect. 3.4 (profile likelihood; its curvature
   is the inverse of the joint information's block of the parameter of interest).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from ..diagnosis.fit_result import FitResult
from ..diagnosis.lm import TRUST_REGION, levenberg_marquardt
from .forward import Forward
from .instrument import Instrument

__all__ = ["FitResult", "Priors", "fit", "fit_pinned", "geometry_mask", "fit_headings",
           "coarse_headings", "ANGLE_SD_DEG", "OFFSET_SD",
           "FIT_SAMPLES", "orient", "thin"]

OFFSET_SD = 0.02
"""Prior SD of each photodiode's dark offset, in units of the session's median reading. A
silicon photodiode's dark current (pA to nA) is far below its photocurrent under a daylight
sky (uA), so the offset is the converter's own zero and small. Left free (SD 0.5), the
offsets take up part of the depth of the polarization modulation at the unit's brightest
samples and distort the fitted DoP: on the reference ring the DoP scale ran to 0.7-1.0 (a
sky polarized up to 100 %), against 0.50 with the offsets held near zero, where the measured
DoP follows the single-scattering shape ``sin^2 g / (1 + cos^2 g)`` within 10 % from 35 to
115 deg from the sun."""

ANGLE_SD_DEG = 5.0
"""Prior SD [deg] of each photodiode's polarizer-angle deviation from nominal (the common part
of a unit is its polarizer offset ``delta_u``, prior SD 20 deg): polarizer film cut and placed
by hand sits within a few degrees of its nominal angle; the prior only resolves the common
mode with ``delta_u``, the data fix the rest."""


@dataclass
class Priors:
    """Prior mean, prior SD, bounds and difference step of every parameter."""

    mu: np.ndarray
    sd: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    step: np.ndarray

    @classmethod
    def for_model(cls, fwd: Forward, theta0) -> "Priors":
        L, e = fwd.layout, fwd.effect
        n = L.size
        mu, sd = np.asarray(theta0, float).copy(), np.full(n, np.inf)
        lo, hi, step = np.full(n, -np.inf), np.full(n, np.inf), np.ones(n)
        mu[L.lam], sd[L.lam], step[L.lam] = 0.0, 0.5, 1e-4
        mu[L.off], sd[L.off], step[L.off] = 0.0, OFFSET_SD, 1e-4
        mu[L.angle], sd[L.angle], step[L.angle] = 0.0, ANGLE_SD_DEG, 1e-3
        lo[L.angle], hi[L.angle] = -20.0, 20.0
        lo[L.off] = -0.5
        mu[L.delta], sd[L.delta], step[L.delta] = 0.0, 20.0, 1e-3
        mu[L.scale], sd[L.scale], step[L.scale] = 0.6, 1.0, 1e-4
        lo[L.scale], hi[L.scale] = 0.0, 1.0
        mu[L.pointing], sd[L.pointing], step[L.pointing] = 0.0, 5.0, 1e-3
        lo[L.pointing], hi[L.pointing] = -20.0, 20.0
        sd[L.heading], step[L.heading] = np.inf, 1e-3
        if e is not None:
            mu[L.effect], sd[L.effect] = e.prior_mean, e.prior_sd
            lo[L.effect], hi[L.effect] = e.lower, e.upper
            step[L.effect] = e.fd_step
        return cls(mu, sd, lo, hi, step)


def _groups(fwd: Forward, free: np.ndarray):
    """Column groups: (param indices, stage, support (n, P) masks per index)."""
    L, inst = fwd.layout, fwd.inst
    n, P = fwd.y.shape
    cols_of_unit = fwd.member.astype(bool)              # (U, P)
    rank = np.zeros(P, int)
    for u in range(inst.n_units):
        rank[cols_of_unit[u]] = np.arange(cols_of_unit[u].sum())
    groups = []
    for sl in (L.lam, L.off, L.angle):
        for j in range(rank.max() + 1):
            idx = [sl.start + p for p in np.flatnonzero(rank == j)]
            groups.append((idx, "output", [("cols", cols_of_unit[inst.pd_unit[i - sl.start]])
                                           for i in idx]))
    groups.append((list(range(L.delta.start, L.delta.stop)), "output",
                   [("cols", cols_of_unit[u]) for u in range(inst.n_units)]))
    e = fwd.effect
    scale_stage = "geometry" if e is not None and e.dop_scale_in_sky else "output"
    groups.append(([L.scale], scale_stage, [("all", None)]))
    for half in range(2):   # elevation offsets of all units, then azimuth offsets
        start = L.pointing.start + half * inst.n_units
        groups.append((list(range(start, start + inst.n_units)), "geometry",
                       [("cols", cols_of_unit[u]) for u in range(inst.n_units)]))
    h = list(range(L.heading.start, L.heading.stop))
    if inst.absolute_yaw:
        groups.append((h, "geometry", [("all", None)]))
    else:
        groups.append((h, "geometry", [("rows", inst.sweep == k) for k in range(len(h))]))
    n_pd_eff = 0 if e is None else e.per_photodiode
    P = inst.pd_unit.size
    for s0 in range(L.effect.start, L.effect.start + n_pd_eff, P):  # blocks of P, one each
        for j in range(rank.max() + 1):
            idx = [s0 + p for p in np.flatnonzero(rank == j)]
            groups.append((idx, "output", [("cols", cols_of_unit[inst.pd_unit[i - s0]])
                                           for i in idx]))
    stage = "output" if e is not None and e.output_only else "geometry"
    for i in range(L.effect.start + n_pd_eff, L.effect.stop):
        groups.append(([i], stage, [("all", None)]))
    out = []
    for idx, stage, supports in groups:
        keep = [(i, s) for i, s in zip(idx, supports) if free[i]]
        if keep:
            out.append(([i for i, _ in keep], stage, [s for _, s in keep]))
    return out


def _jacobian_plan(fwd: Forward, free, usable_idx):
    """The column groups of :func:`_groups` with, for every parameter, its position among
    the free ones and the positions of its support among the usable residuals: fixed for a
    forward model and a set of free parameters, so remembered on ``fwd`` (a fit's dozens of
    Jacobians share one)."""
    key = (np.asarray(free, bool).tobytes(), usable_idx.tobytes())
    cache = fwd.__dict__.setdefault("_jacobian_plans", {})
    if key in cache:
        return cache[key]
    P = fwd.y.shape[1]
    col_of = {int(i): c for c, i in enumerate(np.flatnonzero(free))}
    u_row, u_col = np.divmod(usable_idx, P)
    plan = []
    for idx, stage, supports in _groups(fwd, free):
        cols = []
        for i, (kind, mask) in zip(idx, supports):
            if kind == "cols":
                at = np.flatnonzero(mask[u_col])
            elif kind == "rows":
                at = np.flatnonzero(mask[u_row])
            else:
                at = np.arange(usable_idx.size)
            cols.append((i, col_of[int(i)], at, usable_idx[at]))
        plan.append((np.array(idx), stage, cols))
    cache[key] = plan
    return plan


def _jacobian(fwd: Forward, theta, r0, obs0, free, step, usable_idx, upper=None):
    """Forward-difference Jacobian (sparse, usable residuals x free parameters) by column
    groups (:func:`_jacobian_plan`); a step that would cross ``upper`` (a parameter at its
    bound: an acceptance at its widest) is taken backwards, where the model is defined."""
    fidx = np.flatnonzero(free)
    rows, cols, vals = [], [], []
    for idx, stage, group in _jacobian_plan(fwd, free, usable_idx):
        t = theta.copy()
        h = step[idx]
        if upper is not None:
            h = np.where(t[idx] + h > upper[idx], -h, h)
        t[idx] += h
        r = fwd.residual(t, obs0 if stage == "output" else None)
        d = (r - r0).ravel()
        for (i, c, at, flat), hi in zip(group, h):
            v = d[flat] / hi
            nz = v != 0.0
            rows.append(at[nz])
            cols.append(np.full(nz.sum(), c))
            vals.append(v[nz])
    rows = np.concatenate(rows) if rows else np.zeros(0, int)
    return sp.csc_matrix((np.concatenate(vals) if vals else np.zeros(0),
                          (rows, np.concatenate(cols) if cols else np.zeros(0, int))),
                         shape=(usable_idx.size, fidx.size))


def _not_calibrated(fwd: Forward) -> np.ndarray:
    """False for the pointing parameters calibrated on other sessions
    (:attr:`Instrument.pointing_deg`, finite entries), True elsewhere."""
    L = fwd.layout
    m = np.ones(L.size, bool)
    if fwd.inst.pointing_deg is not None:
        m[np.arange(L.size)[L.pointing][np.isfinite(fwd.inst.pointing_deg)]] = False
    return m


def fit(fwd: Forward, theta0, free=None, *, priors: Priors | None = None, sigma: float = 0.01,
        max_iter: int = 40, tol: float = 1e-6, covariance: bool = False,
        profiled=None) -> FitResult:
    """Levenberg-Marquardt MAP fit of the parameters marked ``free`` (default: all).

    Parameters
    ----------
    fwd : Forward
    theta0 : ndarray
        Start (and value of the fixed parameters). The pointing is held whatever ``free``
        says when the instrument's pointing is calibrated (:attr:`Instrument.pointing_deg`),
        and so is every parameter the readings leave without effect
        (:meth:`Forward.held_by_readings`) or that the profiled radiance absorbs
        (:meth:`Forward.absorbed_by_profile`).
    sigma : float
        Noise level of the relative residuals, weighting the data against the prior.
    covariance : bool
        Compute the posterior covariance of the free parameters at the solution.
    profiled : ndarray (p,) bool, optional
        Parameters held in the fit whose uncertainty the covariance takes in: it is the
        marginal covariance of the free parameters from the joint information of the free and
        the profiled ones (data and prior) at the solution, the Laplace approximation of
        profiling them out (Pawitan 2001, sect. 3.4 [3]_).
        A held parameter that trades with a free one (the units' elevations and a clock)
        then widens its uncertainty by what the data leave of the trade. Calibrated pointing
        (:attr:`Instrument.pointing_deg`) is not profiled.

    Returns
    -------
    FitResult
        ``converged`` is False when ``max_iter`` was reached (reported by the caller).
    """
    L = fwd.layout
    free = np.ones(L.size, bool) if free is None else np.asarray(free, bool).copy()
    free &= _not_calibrated(fwd)             # calibrated pointing: held
    # what the readings cannot inform (the dark offsets of dark-subtracted or normalised
    # readings, the DoP scale of normalised ones) is held: free, it would follow its prior
    # or wander to a bound, and be reported as a finding
    free &= ~(fwd.held_by_readings() | fwd.absorbed_by_profile())
    pri = priors or Priors.for_model(fwd, np.asarray(theta0, float))
    usable_idx = np.flatnonzero(fwd.usable.ravel())

    def residual(t):
        # a trial outside the model's valid range (a clock that puts the sun below the
        # horizon, a unit that looks below it) raises InvalidParameterError: damped, retried
        obs = fwd.observe(t)
        r = fwd.residual(t, obs)
        return r.ravel()[usable_idx], (r, obs)

    def jacobian(t, _, state, columns):
        return _jacobian(fwd, t, state[0], state[1], columns, pri.step, usable_idx, pri.upper)

    if profiled is not None:
        profiled = (np.asarray(profiled, bool) & _not_calibrated(fwd)
                    & ~fwd.held_by_readings() & ~fwd.absorbed_by_profile())
    # the schedule and the bound handling with which the ring's diagnoses and identifiability
    # matrix are measured: a trust-region schedule, trials clipped into the bounds (held at
    # them where the effect asks, RingEffect.hold_at_bounds)
    hold = bool(getattr(fwd.effect, "hold_at_bounds", False))
    return levenberg_marquardt(residual, jacobian, theta0, pri.mu, pri.sd, lower=pri.lower,
                               upper=pri.upper, free=free, sigma=sigma, max_iter=max_iter,
                               tol=tol, damping=TRUST_REGION, hold_at_bounds=hold,
                               covariance=covariance, profiled=profiled)


def geometry_mask(fwd: Forward) -> np.ndarray:
    """Parameters the angle of polarization pins: every unit's pointing, and the parameters
    of a geometric effect (``RingEffect.geometric``: clock, tilt, yaw scale)."""
    L = fwd.layout
    m = np.zeros(L.size, bool)
    m[L.pointing] = True
    if fwd.effect is not None and fwd.effect.geometric:
        m[L.effect] = True
    return m


def fit_pinned(fwd: Forward, theta0, *, sigma: float, max_iter: int, geometry: bool = True,
               covariance: bool = False, full: bool = True, give_up_above: float = np.inf
               ) -> tuple[FitResult | None, FitResult | None]:
    """Fit in two stages so that a DoP profile the sky model lacks cannot move the geometry.

    1. (``geometry``) The angle of polarization alone: :attr:`Forward.dop_free` profiles the
       polarized radiance out, and the pointing (base model) or a geometric effect's
       parameters (with the pointing held at ``theta0``'s: the two are nearly degenerate in
       the AoP), the polarizer angles, gains, offsets and headings are fitted; the DoP scale
       and a non-geometric effect's parameters (which act on the DoP) are held.
    2. The full model with the geometry (:func:`geometry_mask`) held at stage 1's values, or
       at ``theta0``'s without stage 1.

    A geometric effect started away from its null (a clock hours off, found by a coarse
    search) first has the pointing re-read from the AoP with the effect held at its start.

    A sky effect whose sky has its own angle of polarization (``aop_from_own_sky``: the
    neutral-point and multiple-scattering skies) always runs stage 1, whatever ``geometry``
    says, with its parameters free beside the pointing, from ``theta0`` and from each of
    the effect's starts (the best AoP cost kept): the pointing the base model read under
    single scattering is off under such a sky (8.4 deg low under neutral points 40 deg
    apart), and held there the effect's fit cannot reach its own sky. Stage 2 is then
    reported not converged when stage 1 was not, so that a caller continues both.

    A free unit elevation or clock in one fit of the full model takes up the difference
    between the model's and the real sky's DoP profile (on a real ring the unit elevations
    followed the sun from +7 to -13 deg); the angle of polarization carries the geometry
    without that bias, because an aerosol or multiple-scattering sky changes the DoP profile
    far more than the AoP pattern.

    ``give_up_above`` ends the fit after stage 1 when stage 1's cost exceeds it (a start
    that has already lost the comparison the caller makes on that stage, see
    :func:`.run._fit_effect`).

    Returns
    -------
    (FitResult or None, FitResult or None)
        Stage 2 (None with ``full=False`` or when stage 1 gave up), and stage 1 (with its
        covariance when asked) or None. A geometric effect's covariance has the held
        pointing profiled out (:func:`fit`, ``profiled``): its uncertainty is that of the
        effect with the units' pointing unknown within its prior and what the AoP says of
        it.
    """
    L = fwd.layout
    theta = np.asarray(theta0, float)
    first = None
    e = fwd.effect
    own_sky_aop = e is not None and not e.geometric and getattr(e, "aop_from_own_sky", False)
    geometry = geometry or own_sky_aop
    if geometry and e is not None and e.geometric and np.any(theta[L.effect] != e.null):
        # a start away from the effect's null (a clock hours off): the pointing is re-read
        # from the AoP there first, since the base's pointing was fitted without it
        free = np.zeros(L.size, bool)
        free[:L.n_base] = True
        free[L.scale] = False
        free[L.heading] = True
        fwd.dop_free = True
        try:
            theta = fit(fwd, theta, free, sigma=sigma, max_iter=max_iter).theta
        finally:
            fwd.dop_free = False
    if geometry:
        free = np.ones(L.size, bool)
        free[L.scale] = False
        if fwd.effect is not None and not fwd.effect.geometric and not own_sky_aop:
            free[L.effect] = False
        profiled = None
        if fwd.effect is not None and fwd.effect.geometric:
            # the pointing stays where the base model's AoP fit put it: a common shift of
            # the units' elevations and a shift of the sun's (a clock) are nearly the same
            # to the AoP, and freed together they trade one for the other; the effect's
            # uncertainty takes in what the data leave of that trade
            free[L.pointing] = False
            profiled = np.zeros(L.size, bool)
            profiled[L.pointing] = True
        starts = [theta]
        if own_sky_aop:
            # the sky's angle of polarization has local minima in its parameters (on two
            # simulated sweeps, a neutral-point separation of 11 deg against the true 20,
            # whose AoP cost is 1.6 % higher): its own starts are fitted too, the best kept
            for p in e.starts(None):
                if not np.allclose(p, theta[L.effect]):
                    t = theta.copy()
                    t[L.effect] = p
                    starts.append(t)
        fwd.dop_free = True
        try:
            first = min((fit(fwd, t, free, sigma=sigma, max_iter=max_iter,
                             covariance=covariance, profiled=profiled) for t in starts),
                        key=lambda f: f.cost)
        finally:
            fwd.dop_free = False
        theta = first.theta
    if not full or (first is not None and first.cost > give_up_above):
        return None, first  # the AoP stage is all the caller reads, or all it needs
    second = fit(fwd, theta, ~geometry_mask(fwd), sigma=sigma, max_iter=max_iter)
    if own_sky_aop and not first.converged:
        # the sky's parameters were still moving the pointing: not converged, so that the
        # caller continues both stages from here
        second = replace(second, converged=False)
    return second, first


def coarse_headings(fwd: Forward, theta, step_deg: float = 15.0) -> np.ndarray:
    """Per-sweep heading offsets [deg] from a grid search (other parameters fixed)."""
    L, inst = fwd.layout, fwd.inst
    grid = np.arange(0.0, 360.0, step_deg)
    n_h = L.n_heading
    score = np.empty((grid.size, n_h))
    key = np.zeros(inst.n, int) if inst.absolute_yaw else inst.sweep
    for g, off in enumerate(grid):
        t = np.array(theta, float)
        t[L.heading] = off
        r2 = np.sum(fwd.residual(t) ** 2, axis=1)
        score[g] = np.bincount(key, weights=r2, minlength=n_h)
    best = grid[np.argmin(score, axis=0)]
    return best


def fit_headings(fwd: Forward, theta, *, sigma: float = 0.01, coarse: bool = True) -> FitResult:
    """Fit only the heading offsets (the shared parameters held fixed), from a grid start."""
    L = fwd.layout
    t = np.array(theta, float)
    if coarse:
        t[L.heading] = coarse_headings(fwd, t)
    free = np.zeros(L.size, bool)
    free[L.heading] = True
    return fit(fwd, t, free, sigma=sigma)


FIT_SAMPLES = 1500
"""Fits use every k-th sample of a sweep so that about this many samples remain: a platform
turning once in ~400 samples moves ~1 deg per sample, far finer than the sky's polarization
pattern varies, so thinning loses only noise averaging; held-out gaps use every sample."""


def thin(inst: Instrument, target: int = FIT_SAMPLES) -> Instrument:
    """Every k-th sample (about ``target`` remain), and the first sample of any sweep shorter
    than k that this skips: each sweep keeps its heading offset, so the thinned fit has the
    same parameters as the full model."""
    k = max(1, int(np.ceil(inst.n / target)))
    if k == 1:
        return inst
    rows = np.arange(0, inst.n, k)
    ids, first = np.unique(inst.sweep, return_index=True)
    missed = first[~np.isin(ids, inst.sweep[rows])]
    return inst.subset(np.union1d(rows, missed) if missed.size else rows)


def orient(fwd: Forward, theta) -> tuple[float, np.ndarray]:
    """Polarizer-angle sense (+1/-1) and a common polarizer offset (0/45/90/135 deg) that fit
    the readings best, with per-sweep headings from a 30-deg grid; returns ``(sign, theta)``.

    The sky is sampled once per heading of the grid: sense and offset act on the output
    stage only.
    """
    L = fwd.layout
    grid = np.arange(0.0, 360.0, 30.0)
    key = np.zeros(fwd.inst.n, int) if fwd.inst.absolute_yaw else fwd.inst.sweep
    obs = []
    for off in grid:
        t = np.array(theta, float)
        t[L.heading] = off
        obs.append((t, fwd.observe(t)))
    best = (np.inf, 1.0, None)
    for sign in (1.0, -1.0):
        fwd.polarizer_sign = sign
        for d0 in (0.0, 45.0, 90.0, 135.0):
            score = np.empty((grid.size, L.n_heading))
            for g, (t, o) in enumerate(obs):
                t = t.copy()
                t[L.delta] = d0
                r2 = np.sum(fwd.residual(t, o) ** 2, axis=1)
                score[g] = np.bincount(key, weights=r2, minlength=L.n_heading)
            total = float(score.min(axis=0).sum())
            if total < best[0]:
                t = np.array(theta, float)
                t[L.delta] = d0
                t[L.heading] = grid[np.argmin(score, axis=0)]
                best = (total, sign, t)
    fwd.polarizer_sign = best[1]
    return best[1], best[2]
