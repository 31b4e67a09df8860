"""Adapter of sky fields: where a single-scattering sky misses a polarization field, and why.

The instrument diagnoses ask their three questions of sensor data; this adapter asks them of
a *sky*: a measured or reference field of the normalised Stokes
parameters ``q = Q/I``, ``u = U/I`` (equivalently DoP and AoP) on view directions, for several
cases (sun positions) under one atmosphere.

1. **Base model and gap.** The single-scattering Rayleigh sky with a free ``d_max``
   (``d = d_max sin^2 g / (1 + cos^2 g)``, AoP perpendicular to the scattering plane; Coulson
   1988 [1]_ ch. 2) is fitted on the *calibration cases*; ``q, u`` are linear in ``d_max`` so
   the fit is closed-form least squares. The **gap** is the RMS over the *withheld cases* of the
   Stokes residual ``|(q, u)_model - (q, u)_data|`` (a DoLP-sized number: it equals the DoP
   error where the AoP is right and ``2 d sin(dAoP)`` where the DoP is right, and it stays
   defined at the neutral points where the AoP is not).
2. **Where.** The withheld residuals by angular distance from the sun, near vs away from the
   horizon, in vs out of the neutral-point zones (scattering angle < 30 deg or > 150 deg: the
   Babinet and Brewster points lie 15-25 deg from the sun, the Arago point as far above the
   anti-sun [2]_), and by view zenith angle (:func:`calibration.diagnosis.core.partition_slices`,
   two degrees of freedom per point: ``dq`` and ``du``).
3. **Which.** Candidates, each fitted on the calibration cases only and scored on the withheld
   ones: ``d_max`` (the base itself), ``multiple_scattering`` (a Rayleigh slab of free optical
   thickness ``tau`` over a black ground, no parameter added to the base's one) and
   ``ground_albedo`` (``tau`` and the Lambertian albedo ``A`` free, one added), both solved
   by sasktran2 through :class:`skysim.multiple.MultipleScatteringSky`; scored by
   :func:`calibration.diagnosis.core.held_out_score` and judged by
   :func:`calibration.diagnosis.core.decide`: the effect's name, ``none`` (single scattering
   with a fitted ``d_max`` is within the noise floor) or ``unexplained``.
4. **How far.** Held-out gap before and after, the shrink ``1 - G_after / G_before`` (with
   bootstrap standard errors over the withheld cases when there are two or more) and the
   fitted parameters.

Engine economy
--------------
One engine call costs 0.1-3 s. ``tau`` is searched on a coarse log grid followed by a bounded
Brent refinement in ``ln tau``; every (tau, albedo, sun) call is cached by
:mod:`skysim.multiple`. The albedo costs no search at all: over a Lambertian ground the
transmitted Stokes vector is exactly ``F(A) = F(0) + A / (1 - A s) V`` with ``s`` the spherical
albedo of the slab lit from below and ``V`` independent of ``A`` (Chandrasekhar 1950 [4]_
ch. X, sect. 72, the "planetary problem"; the ground depolarizes, so the series of ground-sky
reflections is scalar). Three calls per (tau, sun), at ``A = 0, 1/2, 1``, give ``s`` and ``V``;
any albedo is then a formula (tested against a direct engine call in
``tests/test_sky_gap.py``).

References
----------
.. [1] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak (1988).
.. [2] M. V. Berry, M. R. Dennis, R. L. Lee, "Polarization singularities in the clear sky",
   New J. Phys. 6:162 (2004), doi:10.1088/1367-2630/6/1/162.
.. [3] G. Schwarz, "Estimating the dimension of a model", Ann. Stat. 6:461-464 (1978),
   doi:10.1214/aos/1176344136.
.. [4] S. Chandrasekhar, *Radiative Transfer*, Oxford (1950; Dover 1960), ch. X.
.. [5] V. Natraj, K.-F. Li, Y. L. Yung, ApJ 691:1909 (2009), doi:10.1088/0004-637X/691/2/1909.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np

from skysim import rayleigh
from skysim.rt_sasktran import DEFAULT_SETTINGS, EngineSettings

from ..effects import UnknownEffectError
from . import core
from .core import Thresholds
from .errors import DiagnosisError, InsufficientDataError
from .protocol import candidate_names
from .report import Candidate, DiagnosisReport, Verdict

__all__ = [
    "SKY_CANDIDATES",
    "SkyCandidate",
    "SkyCases",
    "SkyGapInputError",
    "albedo_decomposition",
    "diagnose_sky",
    "fit_albedo",
    "fit_dmax",
    "fit_tau",
    "predict_qu",
    "slice_residuals",
]

SKY_CANDIDATES = ("d_max", "multiple_scattering", "ground_albedo")
"""Candidate sky models, in order of complexity (1, 1 and 2 free parameters)."""
METRIC = "held-out RMS of |(Q/I, U/I) model - data|"
TAU_BOUNDS = (0.005, 3.0)
"""Search range of the Rayleigh optical thickness [1] (0.36 at 400 nm, 0.097 at 550 nm)."""
TAU_GRID_NODES = 6
NEUTRAL_ZONE_DEG = 30.0
HORIZON_ELEVATION_DEG = 15.0
_ALBEDO_NODES = (0.0, 0.5, 1.0)
PARAMETER_BOUNDS = {"d_max": (0.0, 1.0), "tau": TAU_BOUNDS, "albedo": (0.0, 1.0)}
"""Range searched for each sky parameter (a fit at a bound: the candidate's form is wrong
for these data or the range too narrow)."""
DEFAULT_THRESHOLDS = Thresholds()


class SkyGapInputError(DiagnosisError, ValueError):
    """Unusable sky field: shapes, non-finite values, sun below the horizon, no split."""


@dataclass(frozen=True)
class SkyCandidate:
    """A candidate sky model as an effect (:class:`calibration.diagnosis.protocol.Effect`).

    ``k`` counts the parameters it adds to the base model (``d_max``): the multiple-scattering
    sky trades ``d_max`` for ``tau``, the ground albedo adds ``A``.
    """

    name: str
    parameter_names: tuple
    units: tuple
    k: int

    def available(self) -> str | None:
        if self.name == "d_max":
            return None
        import importlib.util
        if importlib.util.find_spec("sasktran2") is None:
            return "needs sasktran2 (extra skysim[rt])"
        return None


SKY_EFFECTS = {"d_max": SkyCandidate("d_max", ("d_max",), ("1",), 0),
               "multiple_scattering": SkyCandidate("multiple_scattering", ("tau",), ("1",), 0),
               "ground_albedo": SkyCandidate("ground_albedo", ("tau", "albedo"), ("1", "1"), 1)}


@dataclass(frozen=True)
class SkyCases:
    """A polarization field on view directions for several cases (one atmosphere).

    Attributes
    ----------
    case : ndarray of int (n,)
        Case id of each point (one sun position each).
    view_elevation_deg, view_azimuth_deg : ndarray (n,)
        View directions [deg], azimuth clockwise from north.
    sun_elevation_deg, sun_azimuth_deg : ndarray (n,)
        Sun position of the point's case [deg]; must be above the horizon.
    q, u : ndarray (n,)
        Normalised Stokes ``Q/I``, ``U/I`` in the skysim local-meridian basis
        (``docs/conventions.md``); DoP = hypot(q, u).
    labels : dict
        Optional description per case id (e.g. ``{"mu0": 0.4}``).
    """

    case: np.ndarray
    view_elevation_deg: np.ndarray
    view_azimuth_deg: np.ndarray
    sun_elevation_deg: np.ndarray
    sun_azimuth_deg: np.ndarray
    q: np.ndarray
    u: np.ndarray
    labels: dict = field(default_factory=dict)

    def __post_init__(self):
        names = ("case", "view_elevation_deg", "view_azimuth_deg", "sun_elevation_deg",
                 "sun_azimuth_deg", "q", "u")
        arrs = [np.asarray(getattr(self, n), dtype=int if n == "case" else float).ravel()
                for n in names]
        n = arrs[0].size
        for name, a in zip(names, arrs):
            if a.size != n:
                raise SkyGapInputError(f"{name} has {a.size} values but case has {n}: give one "
                                       "value per view direction")
            if not np.all(np.isfinite(a)):
                raise SkyGapInputError(f"{name} holds {int((~np.isfinite(a)).sum())} non-finite "
                                       "values: drop those view directions first")
            object.__setattr__(self, name, a)
        if np.any(self.sun_elevation_deg <= 0):
            raise SkyGapInputError(
                f"sun elevation {self.sun_elevation_deg.min():g} deg is not above the horizon: "
                "the sky models need a sun above the horizon")
        if np.any(np.hypot(self.q, self.u) > 1 + 1e-9):
            raise SkyGapInputError("hypot(q, u) exceeds 1: q and u must be Q/I and U/I")

    @property
    def case_ids(self) -> np.ndarray:
        return np.unique(self.case)

    def subset(self, ids) -> SkyCases:
        m = np.isin(self.case, np.asarray(ids))
        return SkyCases(self.case[m], self.view_elevation_deg[m], self.view_azimuth_deg[m],
                        self.sun_elevation_deg[m], self.sun_azimuth_deg[m], self.q[m],
                        self.u[m], {k: v for k, v in self.labels.items() if k in set(ids)})


# ------------------------------------------------------------------------------ the models

def _rayleigh_qu(c: SkyCases):
    """Single-scattering ``(q, u)`` at ``d_max = 1`` ([1]_ ch. 2)."""
    I, Q, U = rayleigh.stokes(c.view_elevation_deg, c.view_azimuth_deg, c.sun_elevation_deg,
                              c.sun_azimuth_deg, 1.0)
    return Q / I, U / I


def _engine_stokes(c: SkyCases, tau: float, albedo: float, settings: EngineSettings):
    """``(I, Q, U)`` of :class:`MultipleScatteringSky` at the points of ``c`` (cached modes)."""
    from skysim.multiple import MultipleScatteringSky
    f = MultipleScatteringSky(tau=tau, albedo=albedo, settings=settings).field(
        c.view_elevation_deg, c.view_azimuth_deg, c.sun_elevation_deg, c.sun_azimuth_deg)
    return np.stack([f.I, f.Q, f.U])


def albedo_decomposition(c: SkyCases, tau: float, settings: EngineSettings = DEFAULT_SETTINGS):
    """``(F0, V, s)`` with ``F(A) = F0 + A / (1 - A s) V`` ([4]_ ch. X sect. 72).

    Three engine calls per sun (``A = 0, 1/2, 1``): with ``D_a = F(a) - F0 = g(a) V`` and
    ``1/g(a) = 1/a - s``, the ratio ``r = g(1) / g(1/2) = (2 - s) / (1 - s)`` gives
    ``s = (r - 2) / (r - 1)`` (least squares over every point and Stokes component), and
    ``V = (1 - s) D_1``.

    Returns
    -------
    F0, V : ndarray (3, n)
        Black-ground Stokes ``(I, Q, U)`` and the ground term per unit ``g``.
    s : float
        Spherical albedo of the slab lit from below [1].
    """
    F0, Fh, F1 = (_engine_stokes(c, tau, a, settings) for a in _ALBEDO_NODES)
    Dh, D1 = Fh - F0, F1 - F0
    r = float(np.sum(D1 * Dh) / np.sum(Dh * Dh))
    s = (r - 2.0) / (r - 1.0)
    return F0, (1.0 - s) * D1, s


def _qu(F):
    return F[1] / F[0], F[2] / F[0]


def predict_qu(c: SkyCases, effect: str, params: dict,
               settings: EngineSettings = DEFAULT_SETTINGS):
    """Model ``(q, u)`` at the points of ``c`` for a candidate and its parameters."""
    if effect == "d_max":
        q1, u1 = _rayleigh_qu(c)
        return params["d_max"] * q1, params["d_max"] * u1
    if effect == "multiple_scattering":
        return _qu(_engine_stokes(c, params["tau"], 0.0, settings))
    if effect == "ground_albedo":
        return _qu(_engine_stokes(c, params["tau"], params["albedo"], settings))
    raise UnknownEffectError(f"unknown sky candidate {effect!r}; choose from {SKY_CANDIDATES}")


def _rms_gap(dq, du) -> float:
    return float(np.sqrt(np.mean(dq * dq + du * du)))


# ------------------------------------------------------------------------------ the fits

def fit_dmax(c: SkyCases) -> dict:
    """Closed-form least squares of ``d_max`` (``q, u`` are linear in it), clipped to (0, 1]."""
    q1, u1 = _rayleigh_qu(c)
    d = float(np.sum(q1 * c.q + u1 * c.u) / np.sum(q1 * q1 + u1 * u1))
    return {"d_max": float(np.clip(d, 1e-6, 1.0))}


def _albedo_loss(c, F0, V, s, albedo):
    g = albedo / (1.0 - albedo * s)
    q, u = _qu(F0 + g * V)
    return _rms_gap(q - c.q, u - c.u)


def fit_albedo(c: SkyCases, F0, V, s) -> tuple[float, float]:
    """Best albedo in [0, 1] and its gap for a fixed tau (no engine call: closed-form field)."""
    from scipy.optimize import minimize_scalar
    grid = np.linspace(0.0, 1.0, 21)
    losses = [_albedo_loss(c, F0, V, s, a) for a in grid]
    k = int(np.argmin(losses))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    r = minimize_scalar(lambda a: _albedo_loss(c, F0, V, s, a), bounds=(lo, hi),
                        method="bounded", options={"xatol": 1e-4})
    return (float(r.x), float(r.fun)) if r.fun < losses[k] else (float(grid[k]), losses[k])


def _tau_loss(c, effect, tau, settings, memo):
    key = (effect, tau)
    if key not in memo:
        if effect == "multiple_scattering":
            q, u = _qu(_engine_stokes(c, tau, 0.0, settings))
            memo[key] = (_rms_gap(q - c.q, u - c.u), {"tau": tau})
        else:
            a, loss = fit_albedo(c, *albedo_decomposition(c, tau, settings))
            memo[key] = (loss, {"tau": tau, "albedo": a})
    return memo[key]


def _fit_and_predict(c_cal: SkyCases, c_held: SkyCases, effect: str, settings, n_grid,
                     xatol):
    """:func:`fit_tau` on the calibration cases and the fitted sky's ``(q, u)`` on the
    withheld ones."""
    f = fit_tau(c_cal, effect, settings, n_grid, xatol)
    return f, predict_qu(c_held, effect, f["params"], settings)


def fit_tau(c: SkyCases, effect: str, settings: EngineSettings = DEFAULT_SETTINGS,
            n_grid: int = TAU_GRID_NODES, xatol: float = 0.01) -> dict:
    """Fit ``tau`` (and the albedo for ``ground_albedo``) on calibration cases ``c``.

    A log-spaced grid of ``n_grid`` values over :data:`TAU_BOUNDS`, then a bounded Brent
    search in ``ln tau`` between the neighbours of the best node (``xatol`` in ``ln tau``:
    0.01 = 1 % in tau). Returns ``{"params", "gap", "engine_evaluations", "seconds"}``.
    """
    from scipy.optimize import minimize_scalar
    if effect not in ("multiple_scattering", "ground_albedo"):
        raise UnknownEffectError(f"fit_tau fits 'multiple_scattering' or 'ground_albedo'; "
                                 f"got {effect!r}")
    t0 = time.perf_counter()
    memo: dict = {}
    grid = np.geomspace(*TAU_BOUNDS, n_grid)
    losses = [_tau_loss(c, effect, float(t), settings, memo)[0] for t in grid]
    k = int(np.argmin(losses))
    lo, hi = np.log(grid[max(k - 1, 0)]), np.log(grid[min(k + 1, n_grid - 1)])
    minimize_scalar(lambda x: _tau_loss(c, effect, float(np.exp(x)), settings, memo)[0],
                    bounds=(lo, hi), method="bounded", options={"xatol": xatol})
    loss, params = min(memo.values(), key=lambda v: v[0])
    return {"params": params, "gap": loss, "engine_evaluations": len(memo),
            "seconds": time.perf_counter() - t0}


# ------------------------------------------------------------------------------ where

def slice_residuals(c: SkyCases, dq, du, noise_floor: float, margin: float = 0.10) -> list:
    """Residuals by sun distance, horizon, neutral-point zone and view zenith (module doc):
    a list of :class:`calibration.diagnosis.report.Slice`, largest share first."""
    r2 = dq * dq + du * du
    gamma = rayleigh.scattering_angle_deg(c.view_elevation_deg, c.view_azimuth_deg,
                                          c.sun_elevation_deg, c.sun_azimuth_deg)
    zen = 90.0 - c.view_elevation_deg
    out = []

    def add(dim, masks, labels, bounds=None):
        out.extend(core.partition_slices(dim, masks, labels, r2, noise_floor, margin,
                                         dof_per_value=2, bounds=bounds,
                                         bound_unit=None if bounds is None else "deg"))

    for dim, x, edges in (("sun_distance_deg", gamma, (0.0, 30.0, 60.0, 90.0, 120.0, 150.0,
                                                        180.01)),
                          ("view_zenith_deg", zen, (0.0, 30.0, 60.0, 75.0, 90.01))):
        top = edges[-1] - 0.01
        bounds = [(a, min(b, top)) for a, b in pairwise(edges)]
        add(dim, [(x >= a) & (x < b) for a, b in pairwise(edges)],
            [f"{a:g}-{b:g}" for a, b in bounds], bounds)
    low = c.view_elevation_deg < HORIZON_ELEVATION_DEG
    add("horizon", [~low, low], [f"elevation >= {HORIZON_ELEVATION_DEG:g} deg",
                                 f"elevation < {HORIZON_ELEVATION_DEG:g} deg"])
    neu = (gamma < NEUTRAL_ZONE_DEG) | (gamma > 180.0 - NEUTRAL_ZONE_DEG)
    add("neutral_points", [~neu, neu], [
        "away from neutral-point zones",
        f"neutral-point zones (< {NEUTRAL_ZONE_DEG:g} deg from sun or anti-sun)"])
    return core.sort_slices(out)


# ------------------------------------------------------------------------------ diagnosis

def diagnose_sky(cases: SkyCases, calibration_cases, *, candidates=SKY_CANDIDATES,
                 noise_floor: float, settings: EngineSettings = DEFAULT_SETTINGS,
                 thresholds: Thresholds = DEFAULT_THRESHOLDS, n_grid: int = TAU_GRID_NODES,
                 xatol: float = 0.01, seed: int = 0) -> DiagnosisReport:
    """Sky-level gap diagnosis (module docstring); gaps in DoLP units.

    Parameters
    ----------
    cases : SkyCases
        The field, every case.
    calibration_cases : sequence of int
        Case ids to fit on; all others are withheld and scored.
    candidates : sequence of str
        Subset of :data:`SKY_CANDIDATES` (``d_max``, the base, is always fitted).
    noise_floor : float
        Expected RMS Stokes residual [DoLP units] of a perfect model on these data (measurement
        noise, or the reproducibility of the reference), > 0.
    settings : EngineSettings
        sasktran2 set-up for the multiple-scattering candidates.
    n_grid, xatol : int, float
        Coarse tau grid size and Brent tolerance in ``ln tau`` (:func:`fit_tau`).
    seed : int
        Seed of the bootstrap over withheld cases.

    Raises
    ------
    InsufficientDataError
        When no case is withheld or none is left for calibration.
    UnknownEffectError
        For a candidate name outside :data:`SKY_CANDIDATES`.
    """
    t0 = time.perf_counter()
    candidate_names(candidates, SKY_CANDIDATES, SKY_CANDIDATES, "sky")
    if not noise_floor > 0:
        raise SkyGapInputError(f"noise_floor must be > 0; got {noise_floor!r} (the RMS Stokes "
                               "residual a perfect model would leave, e.g. 2e-3)")
    noise_floor = float(noise_floor)
    ids = cases.case_ids
    cal = np.intersect1d(ids, np.asarray(list(calibration_cases), dtype=int))
    held = np.setdiff1d(ids, cal)
    if cal.size == 0 or held.size == 0:
        raise InsufficientDataError(
            f"cases {ids.tolist()} with calibration cases {list(calibration_cases)}: need at "
            "least one case to fit on and one withheld case to score")
    c_cal, c_held = cases.subset(cal), cases.subset(held)

    base = fit_dmax(c_cal)
    q0, u0 = predict_qu(c_held, "d_max", base, settings)
    dq0, du0 = q0 - c_held.q, u0 - c_held.u
    G0 = _rms_gap(dq0, du0)
    N, n_cal = int(c_held.q.size), int(c_cal.q.size)
    rows, residuals = [], {"d_max": (dq0, du0)}
    for name in ("d_max",) + tuple(e for e in SKY_CANDIDATES[1:] if e in candidates):
        eff = SKY_EFFECTS[name]
        why = eff.available()
        if why:
            rows.append(Candidate.unavailable(name, why))
            continue
        if name == "d_max":
            params, fit_gap, evals, secs = base, _rms_gap(*[a - b for a, b in zip(
                predict_qu(c_cal, "d_max", base), (c_cal.q, c_cal.u))]), 0, 0.0
        else:
            out, why = core.run_candidate(_fit_and_predict, c_cal, c_held, name, settings,
                                          n_grid, xatol)
            if why is None:
                f, (q, u) = out
                why = core.non_finite_reason(np.hypot(q - c_held.q, u - c_held.u),
                                             np.hypot(dq0, du0))
            if why is not None:
                rows.append(Candidate.unavailable(name, why))
                continue
            params, fit_gap, evals, secs = f["params"], f["gap"], f["engine_evaluations"], \
                f["seconds"]
            residuals[name] = (q - c_held.q, u - c_held.u)
        Gc = _rms_gap(*residuals[name])
        rows.append(Candidate(
            name, k=eff.k, gap_after=Gc, shrink=1 - Gc / G0,
            score=core.held_out_score(Gc, G0, noise_floor, N, eff.k, n_cal),
            params={n: {"value": float(params[n]), "unit": u}
                    for n, u in zip(eff.parameter_names, eff.units)},
            at_bound=core.at_bound([params[n] for n in eff.parameter_names],
                                   *zip(*[PARAMETER_BOUNDS[n] for n in eff.parameter_names]),
                                   eff.parameter_names),
            details={"calibration_gap": fit_gap, "engine_evaluations": evals,
                     "fit_seconds": secs}))
    # |(dq, du)| per point: its mean square is the gap's, paired per withheld case
    held_res = {k: np.hypot(*v) for k, v in residuals.items()}
    judged, dec = core.judge([r for r in rows if r.effect != "d_max"], held_res, c_held.case,
                             noise_floor, thresholds, base="d_max")
    rows = core.rank([r for r in rows if r.effect == "d_max"] + judged)
    effect = dec.effect
    best = rows[0].effect if effect != "none" else "d_max"
    G1 = _rms_gap(*residuals[best])
    se = core.shrink_uncertainty(held_res["d_max"], held_res[best], c_held.case,
                                 np.random.default_rng(seed)) or {}
    named = effect == best and effect != "d_max"
    verdict = Verdict(effect, dec.reason, best, G0, G1, 1 - G1 / G0, se.get("gap_before_se"),
                      se.get("gap_after_se") if named else se.get("gap_before_se"),
                      (se.get("shrink_se") if named else 0.0) if se else None,
                      next(r.params for r in rows if r.effect == best),
                      dec.group, dec.share, dec.share_se, dec.separated_by)
    margin = thresholds.none_margin
    return DiagnosisReport(
        instrument="sky", metric=METRIC, unit="DoLP", verdict=verdict, candidates=rows,
        where=slice_residuals(c_held, dq0, du0, noise_floor, margin),
        where_after=slice_residuals(c_held, *residuals[best], noise_floor, margin),
        noise_floor=noise_floor,
        noise_floor_method="given: the RMS Stokes residual a perfect model leaves on these data",
        data={"cases": ids.tolist(), "calibration_cases": cal.tolist(),
              "withheld_cases": held.tolist(),
              "labels": {str(k): v for k, v in cases.labels.items()},
              "split": {"method": "given calibration cases; the others withheld",
                        "held_out_values": N, "calibration_values": n_cal}},
        thresholds=thresholds.to_dict(), seed=seed,
        extra={"engine_settings": settings.to_dict(), "seconds": time.perf_counter() - t0})


class SkyAdapter:
    """Sky fields (:class:`SkyCases`) as an instrument of :func:`calibration.diagnosis.diagnose`
    (:class:`.protocol.InstrumentAdapter`).

    Without ``calibration_cases`` the split is one fold of :func:`.core.assign_folds` over
    the cases: the last fold is withheld, the others calibrate (each engine fit costs seconds
    to minutes, so a sky is scored on one split rather than cross-validated).
    """

    name = "sky"

    def accepts(self, data, sidecar: dict | None = None) -> bool:
        return isinstance(data, SkyCases)

    def load(self, path):
        from .errors import UnsupportedInstrumentError
        raise UnsupportedInstrumentError(
            f"{path}: sky fields are diagnosed from a SkyCases object (view directions, suns, "
            "Q/I and U/I per case), not from a file")

    def candidates(self, names=None) -> tuple:
        return candidate_names(names, SKY_CANDIDATES, SKY_CANDIDATES, "sky")

    def diagnose(self, data: SkyCases, candidates, *, folds: int = 2, seed: int = 0,
                 noise_floor: float | None = None, calibration_cases=None,
                 **options) -> DiagnosisReport:
        if noise_floor is None:
            raise SkyGapInputError("noise_floor is required for a sky field: the RMS Stokes "
                                   "residual [DoLP units] a perfect model would leave on these "
                                   "data (measurement noise), e.g. 2e-3")
        if calibration_cases is None:
            fold = core.assign_folds(data.case_ids, min(folds, data.case_ids.size))
            calibration_cases = data.case_ids[fold != fold.max()].tolist()
        return diagnose_sky(data, calibration_cases, candidates=self.candidates(candidates),
                            noise_floor=noise_floor, seed=seed, **options)
