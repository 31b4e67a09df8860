"""Adapter of sky fields: where a single-scattering sky misses a polarization field, and why.

The instrument diagnoses ask their three questions of sensor data; this adapter asks them of
a *sky*: a measured or reference field of the normalised Stokes
parameters ``q = Q/I``, ``u = U/I`` (equivalently DoP and AoP) on view directions, for several
cases (sun positions) under one atmosphere.

The method is the judge's (:mod:`calibration.diagnosis.judge`), as for every instrument:
folds of whole cases (one sun each: the independent blocks), held-out scores, the paired
comparison, the verdict rule and the shrink. This adapter brings the sky's data, base model,
candidates and fits.

1. **Base model and gap.** The single-scattering Rayleigh sky with a free ``d_max``
   (``d = d_max sin^2 g / (1 + cos^2 g)``, AoP perpendicular to the scattering plane; Coulson
   1988 [1]_ ch. 2) is fitted on the calibration cases of each fold; ``q, u`` are linear in
   ``d_max`` so the fit is closed-form least squares. The **gap** is the RMS over the
   *withheld cases* of the Stokes residual ``|(q, u)_model - (q, u)_data|`` (a DoLP-sized
   number: it equals the DoP error where the AoP is right and ``2 d sin(dAoP)`` where the DoP
   is right, and it stays defined at the neutral points where the AoP is not). The folds
   are the user's split (``calibration_cases``: one held-out fold) or whole cases dealt
   round-robin into folds, each withheld in turn (:func:`judge.cross_validate`).
2. **Where.** The withheld residuals by angular distance from the sun, near vs away from the
   horizon, in vs out of the neutral-point zones (scattering angle < 30 deg or > 150 deg: the
   Babinet and Brewster points lie 15-25 deg from the sun, the Arago point as far above the
   anti-sun [2]_), and by view zenith angle (:func:`calibration.diagnosis.core.partition_slices`,
   two degrees of freedom per point: ``dq`` and ``du``).
3. **Which.** Candidates, each fitted on the calibration cases of each fold and scored on the
   withheld ones: ``d_max`` (the base itself), ``multiple_scattering`` (a Rayleigh slab of
   free optical thickness ``tau`` over a black ground, no parameter added to the base's one)
   and ``ground_albedo`` (``tau`` and the Lambertian albedo ``A`` free, one added), both
   solved by sasktran2 through :class:`skysim.multiple.MultipleScatteringSky`. The ground
   albedo nests the multiple-scattering sky (``A = 0``), which is fitted as its null even
   when it is not a candidate: the ground is named only when it beats that null on the
   withheld cases (:data:`NULL_MODELS`). Scored by
   :func:`judge.score` (:func:`calibration.diagnosis.core.held_out_score` [3]_) and judged by
   :func:`judge.verdict`: the effect's name, ``none`` (single scattering with a fitted
   ``d_max`` is within the noise floor), ``group``, ``partly_explained`` or ``unexplained``.
   Every parameter carries a standard error (:func:`dmax_se`, :func:`gauss_newton`).
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
``tests/test_sky_gap.py``). The standard errors cost three engine calls per sun and fit
(:func:`gauss_newton`), 10-20 % of the search's.

References
----------
.. [1] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak (1988).
.. [2] M. V. Berry, M. R. Dennis, R. L. Lee, "Polarization singularities in the clear sky",
   New J. Phys. 6:162 (2004), doi:10.1088/1367-2630/6/1/162.
.. [3] G. Schwarz, "Estimating the dimension of a model", Ann. Stat. 6:461-464 (1978),
   doi:10.1214/aos/1176344136.
.. [4] S. Chandrasekhar, *Radiative Transfer*, Oxford (1950; Dover 1960), ch. X.
.. [5] V. Natraj, K.-F. Li, Y. L. Yung, ApJ 691:1909 (2009), doi:10.1088/0004-637X/691/2/1909.
.. [6] D. M. Bates, D. G. Watts, *Nonlinear Regression Analysis and Its Applications*, Wiley
   (1988), ch. 2.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from itertools import pairwise

import numpy as np

from skysim import rayleigh
from skysim.rt_sasktran import DEFAULT_SETTINGS, EngineSettings

from ..effects import UnknownEffectError
from . import core
from . import judge
from .core import Thresholds
from .errors import DiagnosisError, InsufficientDataError
from .protocol import candidate_names
from .report import Candidate, DiagnosisReport

__all__ = [
    "SKY_CANDIDATES",
    "SkyCandidate",
    "SkyCases",
    "SkyGapInputError",
    "albedo_decomposition",
    "diagnose_sky",
    "dmax_se",
    "fit_albedo",
    "fit_dmax",
    "fit_tau",
    "gauss_newton",
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
DEFAULT_THRESHOLDS = Thresholds(block_name="cases")
NULL_MODELS = {"ground_albedo": "multiple_scattering"}
"""The model each candidate reduces to with its own parameters at their null values (a black
ground), fitted whether or not it is among the candidates: a candidate is named only when it
beats its null on the held-out cases (:func:`.core.decide`), so that a multiple-scattering
sky diagnosed without its candidate is not named ``ground_albedo`` for an albedo the
calibration noise drew."""
NULL_SE = 2.0
"""Standard errors by which a fitted albedo must exceed 0 (a black ground, where the
``ground_albedo`` sky is the ``multiple_scattering`` one) for the ground to be a finding; a
smaller one leaves the candidate indistinguishable from its null and it is not named. This
reads the calibration cases that fitted the albedo; the held-out comparison with the null
(:data:`NULL_MODELS`) reads the withheld ones, whose noise is independent of it: under a
black ground each passes by chance ~2 % of the time, both together far less."""


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
    """Fit ``tau`` (and the albedo for ``ground_albedo``) on calibration cases ``c``, with
    standard errors.

    A log-spaced grid of ``n_grid`` values over :data:`TAU_BOUNDS`, then a bounded Brent
    search in ``ln tau`` between the neighbours of the best node (``xatol`` in ``ln tau``:
    0.01 = 1 % in tau), then one Gauss-Newton step from the Brent optimum
    (:func:`gauss_newton`), kept when it lowers the calibration gap; the standard errors
    come from the same Jacobian.

    Returns
    -------
    dict
        ``params`` (``tau`` [1], ``albedo`` [1]), ``se`` (standard error of each, None where
        the data do not constrain it), ``gap`` (calibration RMS of ``|(dq, du)|``),
        ``engine_evaluations`` (tau values the search and the step evaluated), ``seconds``.
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
    gn = gauss_newton(c, effect, params, settings)
    if gn["gap"] < loss:
        loss, params = gn["gap"], gn["params"]
    return {"params": params, "se": gn["se"], "gap": loss,
            "engine_evaluations": len(memo) + gn["engine_evaluations"],
            "seconds": time.perf_counter() - t0}


FD_STEP = 0.02
"""Step in ``ln tau`` of the central differences of :func:`gauss_newton` (2 % in tau: the
field's second derivative in ``ln tau`` changes the difference by ~1e-4 of it, and the
engine's round-off, ~1e-12 of I, by less still)."""


def _engine_residual(c: SkyCases, tau: float, albedo: float, settings) -> np.ndarray:
    """``(q_model - q, u_model - u)`` stacked, from one engine call per sun."""
    q, u = _qu(_engine_stokes(c, tau, albedo, settings))
    return np.concatenate([q - c.q, u - c.u])


def gauss_newton(c: SkyCases, effect: str, params: dict,
                 settings: EngineSettings = DEFAULT_SETTINGS, step: float = FD_STEP) -> dict:
    """One Gauss-Newton step from ``params`` and the standard errors of the fit.

    The residual vector ``r`` stacks ``q_model - q`` and ``u_model - u`` over the points of
    ``c``; its Jacobian ``J`` in ``theta = (ln tau[, A])`` has the ``ln tau`` column from
    central differences of the engine (``step`` in ``ln tau``, two calls per sun) and the
    albedo column in closed form (``dF/dA = V / (1 - A s)^2``, :func:`albedo_decomposition`,
    whose calls the search has made). The step is ``-(J^T J)^-1 J^T r``, kept inside the
    parameters' ranges (an albedo pressed below 0 or above 1 stays at its bound and the step
    is taken in ``ln tau`` alone), and checked with one more engine call per sun. The
    covariance is ``s^2 (J^T J)^-1`` with ``s^2 = |r|^2 / (m - p)`` (``m`` residual values,
    ``p`` parameters; Bates & Watts 1988 [6]_ ch. 2): the residual scatter the fit leaves,
    so a sky the candidate does not fit widens it. A parameter pinned at a bound, or one the
    points do not constrain (``J^T J`` singular), has no standard error (None); the others'
    are profiled over it by the inverse of the full ``J^T J``. ``tau``'s is
    ``tau * se(ln tau)``.

    Returns
    -------
    dict
        ``params`` after the step, ``gap`` (their calibration RMS of ``|(dq, du)|``), ``se``,
        ``engine_evaluations`` (tau values evaluated).
    """
    tau = float(params["tau"])
    albedo = float(params.get("albedo", 0.0))
    x = np.log(tau)
    hi_t, lo_t = tau * np.exp(step), tau * np.exp(-step)
    J = [(_engine_residual(c, hi_t, albedo, settings)
          - _engine_residual(c, lo_t, albedo, settings)) / (2.0 * step)]
    r = _engine_residual(c, tau, albedo, settings)
    names = ["tau"]
    if effect == "ground_albedo":
        F0, V, s = albedo_decomposition(c, tau, settings)
        F = F0 + albedo / (1.0 - albedo * s) * V
        dF = V / (1.0 - albedo * s) ** 2
        J.append(np.concatenate([(dF[1] - F[1] / F[0] * dF[0]) / F[0],
                                 (dF[2] - F[2] / F[0] * dF[0]) / F[0]]))
        names.append("albedo")
    J = np.stack(J, axis=1)
    free = np.ones(len(names), bool)
    delta = np.linalg.lstsq(J, -r, rcond=None)[0]
    if effect == "ground_albedo" and not 0.0 <= albedo + delta[1] <= 1.0:
        free[1] = False                  # the albedo stays at its bound: ln tau alone
        delta = np.r_[np.linalg.lstsq(J[:, :1], -r, rcond=None)[0], 0.0]
    lnb = np.log(TAU_BOUNDS)
    new = {"tau": float(np.exp(np.clip(x + delta[0], *lnb)))}
    if effect == "ground_albedo":
        new["albedo"] = float(np.clip(albedo + delta[1], 0.0, 1.0))
    r_new = _engine_residual(c, new["tau"], new.get("albedo", 0.0), settings)
    half = r.size // 2
    gap_new = _rms_gap(r_new[:half], r_new[half:])
    r_fit = r_new if gap_new < _rms_gap(r[:half], r[half:]) else r
    m, p = r.size, int(free.sum())
    s2 = float(r_fit @ r_fit) / max(m - p, 1)
    se = dict.fromkeys(names)
    Jf = J[:, free]
    JTJ = Jf.T @ Jf
    if np.all(np.isfinite(JTJ)) and np.linalg.cond(JTJ) < 1e12:
        sd = np.sqrt(s2 * np.diag(np.linalg.inv(JTJ)))
        for name, v in zip(np.asarray(names)[free], sd):
            se[str(name)] = float(v)
    if se["tau"] is not None:
        tau_fit = new["tau"] if r_fit is r_new else tau
        se["tau"] = tau_fit * se["tau"]
    return {"params": new, "gap": gap_new, "se": se, "engine_evaluations": 3}


def dmax_se(c: SkyCases, d_max: float) -> float | None:
    """Standard error of the closed-form ``d_max`` (:func:`fit_dmax`): ``s / |(q1, u1)|``
    with ``s^2`` the residual variance per Stokes component (linear least squares, exact)."""
    q1, u1 = _rayleigh_qu(c)
    r = np.concatenate([d_max * q1 - c.q, d_max * u1 - c.u])
    norm = float(np.sum(q1 * q1 + u1 * u1))
    if not norm > 0 or r.size < 2:
        return None
    return float(np.sqrt(float(r @ r) / (r.size - 1) / norm))


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

def _sky_folds(cases: SkyCases, calibration_cases, folds: int):
    """Fold of every point (whole cases) and the folds held out in turn.

    With ``calibration_cases`` the split is the user's: the calibration cases are fold 0,
    only ever fitted on, and the others fold 1, withheld. Without, the cases are dealt
    round-robin into ``folds`` folds (:func:`.core.assign_folds`), each held out in turn.
    """
    ids = cases.case_ids
    if calibration_cases is None:
        if folds < 2 or ids.size < 2:
            raise InsufficientDataError(
                f"cases {ids.tolist()} in folds={folds!r}: cross-validation needs at least "
                "two cases and two folds (or give calibration_cases)")
        fold = core.assign_folds(cases.case, min(int(folds), ids.size))
        return fold, np.unique(fold), None
    cal = np.intersect1d(ids, np.asarray(list(calibration_cases), dtype=int))
    if cal.size == 0 or cal.size == ids.size:
        raise InsufficientDataError(
            f"cases {ids.tolist()} with calibration cases {list(calibration_cases)}: need at "
            "least one case to fit on and one withheld case to score")
    return np.where(np.isin(cases.case, cal), 0, 1), np.array([1]), cal.tolist()


def _fold_params(eff: SkyCandidate, fits: list) -> dict:
    """A candidate's parameters over its fold fits.

    One fold (a given split): its fit's values and standard errors. ``k`` folds (each case
    held out once): the mean over folds, with the larger of the SE of a fit on every case and
    the folds' jackknife SE (:func:`.judge.fold_mean_se`), which a candidate whose form is
    wrong for these data widens beyond the first: it disagrees between suns.
    """
    P = np.array([f.params for f in fits], float)
    k = len(fits)
    out = {}
    for j, (name, unit) in enumerate(zip(eff.parameter_names, eff.units)):
        sds = [f.sd[j] if f.sd is not None else None for f in fits]
        se = judge.fold_mean_se(P[:, j], sds)[0] if None not in sds else None
        out[name] = {"value": float(P[:, j].mean()), "unit": unit, "se": se}
        if k > 1:
            out[name]["fold_values"] = P[:, j].tolist()
    return out


def diagnose_sky(cases: SkyCases, calibration_cases=None, *, candidates=SKY_CANDIDATES,
                 noise_floor: float, folds: int = 2,
                 settings: EngineSettings = DEFAULT_SETTINGS,
                 thresholds: Thresholds = DEFAULT_THRESHOLDS, n_grid: int = TAU_GRID_NODES,
                 xatol: float = 0.01, seed: int = 0) -> DiagnosisReport:
    """Sky-level gap diagnosis (module docstring) through the judge
    (:mod:`calibration.diagnosis.judge`); gaps in DoLP units.

    Parameters
    ----------
    cases : SkyCases
        The field, every case.
    calibration_cases : sequence of int, optional
        Case ids to fit on, all others withheld and scored (one split). Without it the
        cases are cross-validated in ``folds`` folds of whole cases.
    candidates : sequence of str
        Subset of :data:`SKY_CANDIDATES` (``d_max``, the base, is always fitted).
    noise_floor : float
        Expected RMS Stokes residual [DoLP units] of a perfect model on these data (measurement
        noise, or the reproducibility of the reference), > 0.
    folds : int
        Folds of whole cases without ``calibration_cases`` (each held out in turn; every
        candidate is fitted once per fold, so the engine cost grows with it).
    settings : EngineSettings
        sasktran2 set-up for the multiple-scattering candidates.
    thresholds : Thresholds
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
    fold, held_folds, cal_given = _sky_folds(cases, calibration_cases, folds)
    names = ["d_max"] + [e for e in SKY_CANDIDATES[1:] if e in candidates]
    # the candidates and the nested nulls of those that have one (fitted, not reported)
    models = names + sorted({NULL_MODELS[n] for n in names if n in NULL_MODELS} - set(names))
    unavailable = {n: why for n in models if (why := SKY_EFFECTS[n].available())}
    stokes = {n: np.full((cases.q.size, 2), np.nan) for n in ("base", *models)}

    def by_rows(rows):
        return cases.subset(np.unique(cases.case[rows]))

    def fit_fold(train, held, skip):
        c_cal, c_held = by_rows(train), by_rows(held)
        base = fit_dmax(c_cal)
        q, u = predict_qu(c_held, "d_max", base)
        stokes["base"][held] = np.c_[q - c_held.q, u - c_held.u]
        cal_gap = _rms_gap(*[a - b for a, b in zip(predict_qu(c_cal, "d_max", base),
                                                   (c_cal.q, c_cal.u))])
        fit0 = judge.FoldFit(np.hypot(q - c_held.q, u - c_held.u),
                             np.array([base["d_max"]]),
                             sd=[dmax_se(c_cal, base["d_max"])],
                             state={"calibration_gap": cal_gap, "engine_evaluations": 0,
                                    "fit_seconds": 0.0})
        fits = {"base": fit0, "d_max": fit0}
        stokes["d_max"][held] = stokes["base"][held]
        for name in models[1:]:
            if name in skip:
                continue
            out, why = core.run_candidate(_fit_and_predict, c_cal, c_held, name, settings,
                                          n_grid, xatol)
            if why is not None:
                fits[name] = why
                continue
            f, (q, u) = out
            eff = SKY_EFFECTS[name]
            stokes[name][held] = np.c_[q - c_held.q, u - c_held.u]
            fits[name] = judge.FoldFit(
                np.hypot(q - c_held.q, u - c_held.u),
                np.array([f["params"][n] for n in eff.parameter_names]),
                sd=[f["se"][n] for n in eff.parameter_names],
                state={"calibration_gap": f["gap"], "engine_evaluations":
                       f["engine_evaluations"], "fit_seconds": f["seconds"]})
        return np.ones(held.size, bool), fits

    # |(dq, du)| per point: its mean square is the gap's, paired per withheld case
    held = judge.cross_validate(fold, models, cases.q.shape, fit_fold, unavailable,
                                held_folds=held_folds)
    used = np.flatnonzero(held.usable)
    block = cases.case[used]
    n_cal = int(round(np.mean([np.sum(fold != f) for f in held_folds])))
    rows = []
    for name in names:
        eff = SKY_EFFECTS[name]
        if name in held.unavailable:
            rows.append(Candidate.unavailable(name, held.unavailable[name]))
            continue
        fits = held.fits[name]
        row = judge.score(held, name, eff.k, cases.case, noise_floor, n_cal)
        row["params"] = _fold_params(eff, fits)
        P = np.array([f.params for f in fits])
        row["at_bound"] = core.at_bound(P, *zip(*[PARAMETER_BOUNDS[n]
                                                  for n in eff.parameter_names]),
                                        eff.parameter_names)
        if name == "ground_albedo":
            a = row["params"]["albedo"]
            row["null_excluded"] = bool(a["se"] is not None
                                        and a["value"] > NULL_SE * a["se"])
        if name in NULL_MODELS:
            row["null_model"] = NULL_MODELS[name]
        # the calibration gap of the folds' fits on average, their cost in total
        row["calibration_gap"] = float(np.mean([f.state["calibration_gap"] for f in fits]))
        row["engine_evaluations"] = int(sum(f.state["engine_evaluations"] for f in fits))
        row["fit_seconds"] = float(sum(f.state["fit_seconds"] for f in fits))
        rows.append(Candidate.from_dict(row))
    avail = ["base"] + held.available(models)
    ranked, verdict = judge.verdict(rows, {k: held.residual[k][used] for k in avail}, block,
                                    noise_floor, thresholds, np.random.default_rng(seed))
    if verdict.effect == "none":          # the base model's d_max is the answer
        verdict = replace(verdict, params=next(c.params for c in ranked
                                               if c.effect == "d_max"))
    after = verdict.best_candidate if verdict.effect != "none" and \
        verdict.best_candidate is not None else "base"
    withheld = np.unique(block)
    c_held = cases.subset(withheld)
    margin = thresholds.none_margin
    split = ({"method": "given calibration cases; the others withheld"}
             if cal_given else
             {"method": "whole cases, round-robin into folds, each fold withheld in turn",
              "folds": [np.unique(cases.case[fold == f]).tolist() for f in held_folds]})
    return DiagnosisReport(
        instrument="sky", metric=METRIC, unit="DoLP", verdict=verdict, candidates=ranked,
        where=slice_residuals(c_held, *stokes["base"][used].T, noise_floor, margin),
        where_after=slice_residuals(c_held, *stokes[after][used].T, noise_floor, margin),
        noise_floor=noise_floor,
        noise_floor_method="given: the RMS Stokes residual a perfect model leaves on these data",
        data={"cases": cases.case_ids.tolist(),
              "calibration_cases": cal_given or cases.case_ids.tolist(),
              "withheld_cases": withheld.tolist(),
              "labels": {str(k): v for k, v in cases.labels.items()},
              "split": {**split, "held_out_values": int(used.size),
                        "calibration_values": n_cal}},
        thresholds=thresholds.to_dict(), seed=seed,
        extra={"engine_settings": settings.to_dict(), "seconds": time.perf_counter() - t0})


class SkyAdapter:
    """Sky fields (:class:`SkyCases`) as an instrument of :func:`calibration.diagnosis.diagnose`
    (:class:`.protocol.InstrumentAdapter`).

    Without ``calibration_cases`` the cases are cross-validated: whole cases round-robin
    into ``folds`` folds (at most one per case), each withheld in turn.
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
        return diagnose_sky(data, calibration_cases, candidates=self.candidates(candidates),
                            noise_floor=noise_floor, folds=min(folds, data.case_ids.size),
                            seed=seed, **options)
