"""Identifiability matrix: can the diagnosis tell its candidate effects apart, and are the
uncertainties it reports calibrated?

For one instrument, each candidate effect of its default set is simulated at two strengths
(a moderate and a strong magnitude inside the effect's documented range), and clean data
(no effect) are simulated too, over a few noise seeds. Every data set is diagnosed

1. with all default candidates: the verdict must name the true effect or list it in the named
   ``group`` (``found``), and be ``none`` on clean data;
2. with the true effect withheld: the verdict must never be a single (necessarily wrong)
   effect (``withheld_ok``; ``group``, ``partly_explained``, ``unexplained`` or ``none`` are
   honest answers).

Where the true effect is the best-ranked candidate and its parameters come with standard
errors, each parameter's z-score ``(fitted - true) / SE`` is recorded; their RMS per
candidate should be near 1 when the uncertainties are calibrated (a parameter at a bound of
its range, or with a zero SE, is left out: its SE does not describe a Gaussian error).

The generators are the instruments' simulators (the three-pair benchmark's
:func:`experiments.workflows.diagnose.simulate_session`, the sky engines, the camera and ring
simulators of :mod:`sensor`): they share only the physics library with the diagnoses, which
are never told the truth.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .errors import DiagnosisError

__all__ = ["INSTRUMENTS", "IdentifiabilityInputError", "InstrumentMatrix", "matrix_markdown",
           "matrix_spec", "ring_session", "run_matrix", "score_matrix", "write_matrix",
           "z_draws_markdown", "z_draws_summary", "z_over_draws", "z_rms_interval"]

INSTRUMENTS = ("three-pair", "sky", "camera", "ring")
"""Instruments with an identifiability matrix."""
_HONEST = ("none", "group", "partly_explained", "unexplained")
"""Verdicts that attribute the gap to no single effect."""


class IdentifiabilityInputError(DiagnosisError, ValueError):
    """Unknown instrument, empty seed list or another unusable option of the matrix."""


@dataclass(frozen=True)
class InstrumentMatrix:
    """What the matrix needs of one instrument.

    Attributes
    ----------
    name : str
    candidates : tuple of str
        The default candidate set the diagnoses run with.
    strengths : dict
        ``effect -> {"moderate": truth, "strong": truth}``, each truth a dict
        ``parameter name -> true value`` in the units of the diagnosis's parameters.
    simulate : callable
        ``simulate(effect or None, truth or None, seed) -> data`` for
        :func:`calibration.diagnosis.diagnose`.
    options : dict
        Further keyword arguments of :func:`calibration.diagnosis.diagnose`.
    seeds : tuple of int
        Noise seeds of the full matrix (the quick one uses the first).
    """

    name: str
    candidates: tuple
    strengths: dict
    simulate: Callable
    options: dict = field(default_factory=dict)
    seeds: tuple = (1, 2, 3)


def _verdict_row(rep) -> dict:
    v = rep.verdict
    return {"verdict": v.effect, "group": list(v.group), "best": v.best_candidate,
            "gap_ratio": (v.gap_before / rep.noise_floor
                          if v.gap_before is not None and rep.noise_floor else float("nan"))}


def _z_scores(rep, effect: str, truth: dict) -> dict:
    """``parameter -> (fitted - true) / SE`` of the true effect's candidate row, when it is the
    best-ranked one; parameters at a bound or without a positive finite SE (``se``, or
    ``uncertainty`` in the photodiode instruments' rows) are left out. A truth ``X`` stands
    for every parameter ``X_...`` (one strength for all photodiodes); azimuths
    (``center_deg``) are compared modulo 360 deg."""
    c = rep.candidate(effect)
    if c is None or not c.available or rep.verdict.best_candidate != effect:
        return {}
    z = {}
    for name, p in (c.params or {}).items():
        key = name if name in truth else next((t for t in truth if name.startswith(f"{t}_")),
                                              None)
        if key is None or name in (c.at_bound or []) or not isinstance(p, dict):
            continue
        se = p.get("se", p.get("uncertainty"))
        if se is None or not np.isfinite(se) or se <= 0:
            continue
        d = float(p["value"]) - float(truth[key])
        if name == "center_deg":
            d = (d + 180.0) % 360.0 - 180.0
        z[name] = d / float(se)
    return z


def z_over_draws(spec: InstrumentMatrix, effect: str, seeds, *,
                 progress: Callable | None = None) -> pd.DataFrame:
    """z-scores ``(fitted - true) / SE`` of ``effect``'s own candidate over independent noise
    draws: each seed's data at each strength of the effect, diagnosed with that candidate
    alone (its fit and its reported SE are those of a diagnosis with every candidate: the
    candidates are fitted independently on the same folds).

    The matrix's own z-scores are too few to calibrate an SE: one seed gives one or two per
    parameter, and the parameters of one fit err together (a ring's 32 stray-light
    strengths share one noise draw), so an RMS near 1 needs tens of draws (a calibrated SE
    gives an RMS of ``n`` independent z-scores with a relative spread of ``1 / sqrt(2 n)``).

    Parameters
    ----------
    spec : InstrumentMatrix
    effect : str
        One of ``spec.strengths``.
    seeds : sequence of int
        Noise seeds, one draw each.
    progress : callable, optional
        Called with each finished data set's rows (list of dict).

    Returns
    -------
    DataFrame
        One row per parameter per data set: ``seed, strength, parameter, z, verdict,
        seconds`` (a data set whose best candidate is not the effect's, or whose SE is not
        finite, gives no z-score: its ``parameter`` is None).

    Raises
    ------
    IdentifiabilityInputError
        For an effect the matrix does not simulate, or no seeds.
    """
    from .api import diagnose
    seeds = tuple(seeds)
    if effect not in spec.strengths:
        raise IdentifiabilityInputError(
            f"effect {effect!r} is not simulated by the {spec.name} matrix; choose one of "
            f"{', '.join(spec.strengths)}")
    if not seeds:
        raise IdentifiabilityInputError("seeds is empty: give at least one noise seed")
    rows = []
    for seed in seeds:
        for strength, truth in spec.strengths[effect].items():
            data = spec.simulate(effect, truth, seed)
            t0 = time.perf_counter()
            rep = diagnose(data, (effect,), seed=0, **spec.options)
            base = {"seed": seed, "strength": strength, "verdict": rep.verdict.effect,
                    "seconds": time.perf_counter() - t0}
            z = _z_scores(rep, effect, truth)
            found = [dict(base, parameter=n, z=v) for n, v in z.items()] or [
                dict(base, parameter=None, z=float("nan"))]
            rows += found
            if progress is not None:
                progress(found)
    return pd.DataFrame(rows, columns=["seed", "strength", "parameter", "z", "verdict",
                                       "seconds"])


def run_matrix(spec: InstrumentMatrix, seeds=None, *, progress: Callable | None = None
               ) -> pd.DataFrame:
    """Simulate and diagnose every case of ``spec``; one row per data set.

    Parameters
    ----------
    spec : InstrumentMatrix
    seeds : sequence of int, optional
        Noise seeds (default ``spec.seeds``).
    progress : callable, optional
        Called with each finished row (dict).

    Returns
    -------
    DataFrame
        Columns ``instrument, truth, strength, seed, verdict, group, best, gap_ratio,
        found, withheld_verdict, withheld_group, withheld_ok, z, seconds,
        withheld_seconds`` (``z`` a JSON dict ``parameter -> z-score``).
    """
    from .api import diagnose
    seeds = tuple(spec.seeds if seeds is None else seeds)
    if not seeds:
        raise IdentifiabilityInputError("seeds is empty: give at least one noise seed")
    cases = [(None, None, None)] + [(e, s, truth) for e, by in spec.strengths.items()
                                    for s, truth in by.items()]
    rows = []
    for seed in seeds:
        for effect, strength, truth in cases:
            data = spec.simulate(effect, truth, seed)
            t0 = time.perf_counter()
            rep = diagnose(data, spec.candidates, seed=0, **spec.options)
            t1 = time.perf_counter()
            row = {"instrument": spec.name, "truth": effect or "none",
                   "strength": strength or "-", "seed": seed, **_verdict_row(rep)}
            row["found"] = (row["verdict"] == row["truth"]
                            or (row["verdict"] == "group" and row["truth"] in row["group"]))
            row["z"] = _z_scores(rep, effect, truth) if effect else {}
            row["seconds"] = t1 - t0
            if effect is None:
                row.update(withheld_verdict=None, withheld_group=[], withheld_ok=True,
                           withheld_seconds=0.0)
            else:
                others = tuple(c for c in spec.candidates if c != effect)
                w = diagnose(data, others, seed=0, **spec.options).verdict
                row.update(withheld_verdict=w.effect, withheld_group=list(w.group),
                           withheld_ok=w.effect in _HONEST,
                           withheld_seconds=time.perf_counter() - t1)
            rows.append(row)
            if progress is not None:
                progress(row)
    return pd.DataFrame(rows)


def score_matrix(rows: pd.DataFrame) -> dict:
    """Goals of the matrix from :func:`run_matrix`'s rows.

    Returns
    -------
    dict
        ``found_rate`` (effect cases named or in the named group), ``found_rate_by_effect``,
        ``clean_none_rate``, ``withheld_ok_rate``, ``z_rms`` (``effect -> RMS of its
        parameters' z-scores`` with ``z_count``), ``cells`` (one line per effect and
        strength: the verdicts over seeds), ``seconds`` (total, and mean per diagnosis).
    """
    eff = rows[rows.truth != "none"]
    clean = rows[rows.truth == "none"]
    z_rms, z_n = {}, {}
    for effect, g in eff.groupby("truth"):
        z = np.array([v for d in g.z for v in d.values()], float)
        if z.size:
            z_rms[effect] = float(np.sqrt(np.mean(z ** 2)))
            z_n[effect] = int(z.size)
    cells = []
    for (effect, strength), g in rows.groupby(["truth", "strength"], sort=False):
        cells.append({"effect": effect, "strength": strength,
                      "verdicts": [_label(v, gr) for v, gr in zip(g.verdict, g.group)],
                      "found": int(g.found.sum()), "n": len(g),
                      "withheld": [_label(v, gr) for v, gr in
                                   zip(g.withheld_verdict, g.withheld_group)
                                   if isinstance(v, str)],
                      "gap_ratio": float(np.nanmedian(g.gap_ratio))})
    n_diag = len(rows) + int(rows.withheld_verdict.notna().sum())
    total = float(rows.seconds.sum() + rows.withheld_seconds.sum())
    return {"found_rate": float(eff.found.mean()) if len(eff) else float("nan"),
            "found_rate_by_effect": {e: float(g.found.mean()) for e, g in eff.groupby("truth")},
            "clean_none_rate": float((clean.verdict == "none").mean()) if len(clean)
            else float("nan"),
            "withheld_ok_rate": float(eff.withheld_ok.mean()) if len(eff) else float("nan"),
            "z_rms": z_rms, "z_count": z_n, "cells": cells,
            "seconds": {"total": total, "per_diagnosis": total / max(n_diag, 1)}}


def _label(verdict, group) -> str:
    return f"group({'+'.join(group)})" if verdict == "group" else str(verdict)


def matrix_markdown(score: dict, instrument: str) -> str:
    """The matrix as a Markdown table (effect x strength -> verdicts over seeds), the rates
    and the z-score RMS per candidate."""
    lines = [f"### {instrument}", "",
             "| effect | strength | gap / floor | verdicts (all candidates) | named or in group "
             "| verdicts (true effect withheld) |", "|---|---|---|---|---|---|"]
    for c in score["cells"]:
        lines.append(f"| {c['effect']} | {c['strength']} | {c['gap_ratio']:.3g} | "
                     f"{', '.join(c['verdicts'])} | {c['found']}/{c['n']} | "
                     f"{', '.join(c['withheld']) or '-'} |")
    lines += ["", f"- named or in the named group: {score['found_rate']:.0%}; clean data "
              f"`none`: {score['clean_none_rate']:.0%}; true effect withheld, no single "
              f"effect named: {score['withheld_ok_rate']:.0%}",
              f"- run time {score['seconds']['total']:.0f} s "
              f"({score['seconds']['per_diagnosis']:.1f} s per diagnosis)", "",
              "| candidate | z-scores | RMS of (fitted - true) / SE |", "|---|---|---|"]
    for e, r in score["z_rms"].items():
        lines.append(f"| {e} | {score['z_count'][e]} | {r:.2f} |")
    if not score["z_rms"]:
        lines.append("| (no candidate reported a parameter with a standard error) | 0 | - |")
    return "\n".join(lines) + "\n"


Z_DRAW_SEED0 = 100
"""First noise seed of :func:`z_over_draws` in :func:`write_matrix` (apart from the
matrices' own seeds)."""


def z_rms_interval(z_by_draw, rng=None, n_boot: int = 2000) -> tuple:
    """RMS of z-scores and its 95 % interval from a bootstrap over independent draws.

    Parameters
    ----------
    z_by_draw : sequence of array_like
        The z-scores of each noise draw (any number per draw). A draw's z-scores are
        resampled together: the parameters of one fit err together.
    rng : numpy.random.Generator, optional
        Resampling generator (default ``numpy.random.default_rng(0)``).
    n_boot : int
        Bootstrap resamples.

    Returns
    -------
    rms, (low, high) : float, tuple of float
    """
    rng = np.random.default_rng(0) if rng is None else rng
    z = [np.atleast_1d(np.asarray(d, float)) for d in z_by_draw]
    if not z:
        raise IdentifiabilityInputError("no draws: z_by_draw is empty")

    def rms(draws):
        return float(np.sqrt(np.mean(np.concatenate(draws) ** 2)))

    boot = [rms([z[i] for i in rng.integers(0, len(z), len(z))]) for _ in range(n_boot)]
    return rms(z), tuple(float(b) for b in np.percentile(boot, [2.5, 97.5]))


def z_draws_summary(rows: pd.DataFrame) -> dict:
    """Per effect, from :func:`z_over_draws` rows (an ``effect`` column beside them): z-score
    count, draws, RMS and its bootstrap interval (:func:`z_rms_interval`), data sets without
    a z-score, and the diagnoses' time range [s]."""
    out = {}
    for effect, g in rows.groupby("effect", sort=False):
        have = g[g.parameter.notna()]
        by_draw = [d.z.to_numpy(float) for _, d in have.groupby("seed")]
        rms, (lo, hi) = z_rms_interval(by_draw) if by_draw else (float("nan"), (np.nan, np.nan))
        sets = g.drop_duplicates(["seed", "strength"])
        out[effect] = {"z_count": int(len(have)), "draws": len(by_draw), "rms": rms,
                       "rms_low": lo, "rms_high": hi,
                       "without_z": int(sets.parameter.isna().sum()),
                       "seconds_min": float(sets.seconds.min()),
                       "seconds_max": float(sets.seconds.max())}
    return out


def z_draws_markdown(summary: dict, instrument: str) -> str:
    """:func:`z_draws_summary` as a Markdown table."""
    lines = [f"### {instrument}: standard errors over noise draws", "",
             "| candidate | draws | z-scores | RMS of (fitted - true) / SE | 95 % interval "
             "| data sets without a z-score | diagnosis [s] |", "|---|---|---|---|---|---|---|"]
    for e, r in summary.items():
        lines.append(f"| {e} | {r['draws']} | {r['z_count']} | {r['rms']:.2f} | "
                     f"{r['rms_low']:.2f}-{r['rms_high']:.2f} | {r['without_z']} | "
                     f"{r['seconds_min']:.0f}-{r['seconds_max']:.0f} |")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------- the instruments
def _three_pair() -> InstrumentMatrix:
    from calibration.effects import get_effect
    from experiments.workflows.diagnose import simulate_session

    from .three_pair import DEFAULT_CANDIDATES
    from .three_pair_fit import fit_form
    pattern = np.array([1.2, 0.7, 1.0, 1.4, 0.6, 1.1])   # spread of the six photodiodes

    def tilt(beta, gamma_deg):
        g = np.radians(gamma_deg)
        return [beta * np.cos(g), beta * np.sin(g)]

    def periodic(a1, a2):
        return [a1 * np.cos(0.7), a1 * np.sin(0.7), a2 * np.cos(2.1), a2 * np.sin(2.1)]

    # both strengths inside the documented ranges; the dark current's and the extinction
    # ratio's in the upper half (below it their gaps stay within the noise floor on this
    # session, where no diagnosis can see them)
    values = {
        "dark_current": (3e-2 * pattern, 5e-2 * pattern),
        "sun_motion": ([500.0], [1100.0]),
        "clock_offset": ([600.0], [3600.0]),
        "tilt": (tilt(0.8, 30.0), tilt(2.5, 200.0)),
        "turntable_periodic": (periodic(0.2, 0.15), periodic(0.3, 0.25)),
        "extinction_ratio": (2e-2 * pattern, 6e-2 * pattern),
        "thermal_drift": ([2e-3, 0.05, -0.1, 0.08], [-3.3e-3, 0.15, -0.15, 0.1]),
        "multiple_scattering": ([0.12, 0.1], [0.35, 0.3]),
        "overcast": ([0.6], [2.5]),
    }
    strengths, injected = {}, {}
    for name in DEFAULT_CANDIDATES:
        e = get_effect(name)
        if e.available() is not None:
            continue
        strengths[name] = {}
        for s, v in zip(("moderate", "strong"), values[name]):
            v = np.asarray(v, float)
            # the truth in the parameters the diagnosis reports (the extinction ratios as
            # the six polarizers' differences from their mean, what the outputs identify)
            form = fit_form(e)
            names, shown = ((form.reported_names, form.from_eps(v)) if form is not e
                            else (e.parameter_names, v))
            strengths[name][s] = dict(zip(names, map(float, shown)))
            injected[name, s] = v

    def simulate(effect, truth, seed):
        if truth is None:
            return simulate_session(None, np.random.default_rng(seed))["data"]
        strength = next(s for s, t in strengths[effect].items() if t == truth)
        # a noise draw of its own per effect and strength (the seed with the case's
        # index), so that no two cases share their noise and each z-score is a draw
        case = list(injected).index((effect, strength)) + 1
        return simulate_session(effect, np.random.default_rng([seed, case]),
                                params=injected[effect, strength])["data"]

    return InstrumentMatrix("three-pair", tuple(DEFAULT_CANDIDATES), strengths, simulate,
                            seeds=(11, 12, 13, 14, 15, 16))


SKY_NOISE = 1e-3
"""Gaussian noise per Stokes component (q, u) of the simulated sky fields: a good
polarimeter's repeatability."""
SKY_SUNS_DEG = (25.0, 50.0)
"""Sun elevations of the sky fields' two cases: the first calibrates, the second is withheld."""


def _sky() -> InstrumentMatrix:
    from skysim.multiple import MultipleScatteringSky
    from skysim.rt_sasktran import EngineSettings
    from skysim.sky import RayleighSky

    from .sky import SKY_CANDIDATES, SkyCases
    # 8 streams: data and fits share the engine set-up, so the stream count changes the cost
    # (0.1-0.3 s per call instead of ~1 s at 32), not the closed loop's consistency
    settings = EngineSettings(n_streams=8)
    el, az = np.meshgrid(np.arange(8.0, 90.0, 9.0), np.arange(0.0, 360.0, 30.0), indexing="ij")
    el, az = el.ravel(), az.ravel()
    m = len(SKY_SUNS_DEG)
    E, A = np.tile(el, m), np.tile(az, m)
    S = np.repeat(np.asarray(SKY_SUNS_DEG, float), el.size)
    case = np.repeat(np.arange(m), el.size)

    def simulate(effect, truth, seed):
        if effect is None:
            sky, case_id = RayleighSky(dmax=0.7), 0
        else:
            sky = MultipleScatteringSky(tau=truth["tau"], albedo=truth.get("albedo", 0.0),
                                        settings=settings)
            case_id = 1 + [(e, t) for e, by in strengths.items()
                           for t in by.values()].index((effect, truth))
        f = sky.field(E, A, S, 0.0)
        # a noise draw of its own per case (the seed with the case's index), so that no two
        # cases share their noise and each z-score is an independent draw
        rng = np.random.default_rng([seed, case_id])
        q = f.Q / f.I + rng.normal(0.0, SKY_NOISE, S.size)
        u = f.U / f.I + rng.normal(0.0, SKY_NOISE, S.size)
        return SkyCases(case, E, A, S, np.zeros_like(S), q, u)

    strengths = {"multiple_scattering": {"moderate": {"tau": 0.1}, "strong": {"tau": 0.35}},
                 "ground_albedo": {"moderate": {"tau": 0.1, "albedo": 0.15},
                                   "strong": {"tau": 0.3, "albedo": 0.4}}}
    # the noise floor of |(dq, du)| for that noise: what a perfect model leaves; eight seeds:
    # 16 z-scores of tau (multiple scattering) and 32 of tau and the albedo, so that the RMS
    # of a calibrated SE lies within 0.7-1.5 with high probability (its relative spread is
    # ~1/sqrt(2 n): 0.18 at n = 16; four seeds, 0.25 at n = 8, left a calibrated SE at 0.66)
    return InstrumentMatrix("sky", SKY_CANDIDATES, strengths, simulate,
                            {"noise_floor": SKY_NOISE * np.sqrt(2), "calibration_cases": [0],
                             "settings": settings, "n_grid": 5}, seeds=tuple(range(21, 29)))


CAMERA_SIZE = 128
"""Frame side [px] of the simulated camera (a 64 x 64 super-pixel fisheye sky)."""
CAMERA_DMAX = 0.7
CAMERA_SITE = {"latitude_deg": 34.25, "longitude_deg": 108.9, "altitude_m": 400.0}
CAMERA_TIME = "2024-05-22T02:30:00+00:00"
"""UTC time of the simulated frames (the sun 58 deg high at the camera site)."""


def camera_frame(seed: int, *, lens_shift=(0.0, 0.0, 1.0), angle_offsets=None,
                 extinction_ratio=np.inf, sky=None, yaw_deg: float = 30.0, time=None):
    """A raw frame of the camera simulator (:class:`sensor.camera.PolarizationCamera`) with
    the given injected errors, and the sidecar of the *nominal* camera, as a user's would be.

    Parameters
    ----------
    seed : int
        Shot-noise seed.
    lens_shift : (dcx [px], dcy [px], focal scale)
        The true lens against the nominal one.
    angle_offsets : 4 values [deg], optional
        Angle errors of the 2 x 2 polarizer layout, row by row.
    extinction_ratio : float
        Of every polarizer (inf: ideal).
    sky : Sky, optional
        Default: the Rayleigh sky of :data:`CAMERA_DMAX`.
    yaw_deg : float
    time : datetime, optional
        Timezone-aware time of the frame (default :data:`CAMERA_TIME`).
    """
    import datetime as dt

    from sensor.camera import MosaicSensor, PolarizationCamera, camera_attitude
    from sensor.camera.lens import FisheyeLens
    from skysim.sky import make_sky
    from skysim.sun import sun_position

    from .camera import CameraFrame
    n = CAMERA_SIZE
    time = dt.datetime.fromisoformat(CAMERA_TIME) if time is None else time
    nominal = PolarizationCamera.fisheye(n, n)
    lens = FisheyeLens(nominal.lens.focal_px * lens_shift[2], nominal.lens.cx + lens_shift[0],
                       nominal.lens.cy + lens_shift[1], nominal.lens.fov_deg)
    kw = {"extinction_ratio": extinction_ratio}
    if angle_offsets is not None:
        kw["angle_error_deg"] = np.tile(np.reshape(angle_offsets, (2, 2)), (n // 2, n // 2))
    true = PolarizationCamera(lens, MosaicSensor(n, n, **kw))
    sun = sun_position([time], CAMERA_SITE["latitude_deg"], CAMERA_SITE["longitude_deg"],
                       CAMERA_SITE["altitude_m"]).iloc[0]
    sky = sky or make_sky("rayleigh", dmax=CAMERA_DMAX)
    scene = true.scene(sky, camera_attitude(yaw_deg), float(sun["elevation_deg"]),
                       float(sun["azimuth_deg"]))
    exposure = true.auto_exposure_s(scene)
    raw = true.capture(scene, exposure, np.random.default_rng(seed))
    doc = {"schema": "skysim.dofp/1", "site": CAMERA_SITE, "time": time.isoformat(),
           "attitude": {"yaw_deg": yaw_deg, "pitch_deg": 0.0, "roll_deg": 0.0,
                        "yaw_known": True},
           **nominal.describe(), "exposure": {"exposure_s": exposure},
           "generator": {"sky": sky.describe(), "seed": seed}}
    return CameraFrame(raw, doc, name=f"seed {seed}")


def _camera() -> InstrumentMatrix:
    from skysim.cloud_field import CloudField
    from skysim.partly_cloudy import PartlyCloudySky
    from skysim.sky import make_sky

    from .camera import DEFAULT_CAMERA_CANDIDATES
    offsets = ("offset_a00_deg", "offset_a01_deg", "offset_a10_deg", "offset_a11_deg")

    def simulate(effect, truth, seed):
        if effect is None:
            return camera_frame(seed)
        # a shot-noise draw of its own per effect and strength (the seed with the case's
        # index), so that no two cases share their noise and each z-score is a draw
        case = next(i for i, (e, s) in enumerate(
            (e, s) for e, by in strengths.items() for s in by) if e == effect
            and strengths[e][s] == truth) + 1
        seed = int(np.random.SeedSequence([seed, case]).generate_state(1)[0])
        if effect == "lens":
            return camera_frame(seed, lens_shift=(truth["dcx_px"], truth["dcy_px"],
                                                  truth["focal_scale"]))
        if effect == "polarizer_angles":
            return camera_frame(seed, angle_offsets=[truth[k] for k in offsets])
        if effect == "extinction_ratio":
            return camera_frame(seed, extinction_ratio=1.0 / truth["inverse_extinction_ratio"])
        if effect == "sky_dop":
            return camera_frame(seed, sky=make_sky("berry", delta_deg=truth["delta_deg"],
                                                   dmax=truth["d_max"]))
        return camera_frame(seed, sky=PartlyCloudySky(
            make_sky("rayleigh", dmax=truth["d_max"]),
            CloudField(cover=1.0, tau=truth["cloud_tau"], thickness="uniform")))

    d = CAMERA_DMAX
    strengths = {
        "lens": {"moderate": {"dcx_px": 1.5, "dcy_px": -1.0, "focal_scale": 1.0},
                 "strong": {"dcx_px": 3.0, "dcy_px": -2.0, "focal_scale": 1.04}},
        "polarizer_angles": {"moderate": dict(zip(offsets, (1.0, -0.8, 0.0, 0.5))),
                             "strong": dict(zip(offsets, (2.0, -1.5, 0.0, 1.0)))},
        "extinction_ratio": {"moderate": {"inverse_extinction_ratio": 1 / 50.0},
                             "strong": {"inverse_extinction_ratio": 1 / 20.0}},
        "sky_dop": {"moderate": {"delta_deg": 25.0, "d_max": d},
                    "strong": {"delta_deg": 40.0, "d_max": d}},
        "overcast": {"moderate": {"cloud_tau": 0.5, "d_max": d},
                     "strong": {"cloud_tau": 2.0, "d_max": d}}}
    return InstrumentMatrix("camera", tuple(DEFAULT_CAMERA_CANDIDATES),
                            {e: strengths[e] for e in DEFAULT_CAMERA_CANDIDATES}, simulate,
                            seeds=(50, 51, 52, 53, 54))


RING_SITE = (39.258648, 8.440184, 0.0)
"""Latitude, longitude [deg] and altitude [m] of the simulated ring sessions (a Sardinian
field site)."""
RING_START = "2022-05-12T16:01:00+02:00"
"""Start of the simulated ring sessions (afternoon sun, about 40 deg high)."""
RING_DMAX = 0.6
RING_CAP = (48, 24)
"""Rings x directions per ring over which a unit's acceptance is sampled in the simulated
field-of-view sessions (:func:`_cone_readings`: that many rings on the part of the
acceptance above the horizon and as many on the band the horizon cuts; the candidate's fit
uses Gauss-Legendre rules of 6 nodes: the generator is not the fitter's quadrature)."""


def _modified_sky(base, kind: str, truth: dict):
    """``base`` with its light changed in a known way: ``occlusion`` (a sector of world
    azimuth where the polarized part falls by ``k`` and the radiance by ``k / 2``, with
    logistic edges) or ``aureole`` (unpolarized light ``A exp(-psi / psi_0)`` times the sky's
    radiance added at angular distance ``psi`` from the sun)."""
    from skysim.sky import Sky

    class _Wrapped(Sky):
        name = f"{base.name}+{kind}"

        def _stokes(self, vel, vaz, sel, saz):
            I, Q, U = base._stokes(vel, vaz, sel, saz)
            if kind == "occlusion":
                d = np.abs((np.asarray(vaz) - truth["center_deg"] + 180.0) % 360.0 - 180.0)
                w = 1.0 / (1.0 + np.exp((d - 0.5 * truth["width_deg"])
                                        / truth["edge_deg"]))
                k = truth["depolarization"] * w
                return I * (1.0 - 0.5 * k), Q * (1.0 - k) * (1.0 - 0.5 * k), \
                    U * (1.0 - k) * (1.0 - 0.5 * k)
            from skysim.geometry import direction_vector
            cos_psi = np.sum(direction_vector(vel, vaz) * direction_vector(sel, saz),
                             axis=-1)
            psi = np.degrees(np.arccos(np.clip(cos_psi, -1.0, 1.0)))
            return I * (1.0 + truth["amplitude"] * np.exp(-psi / truth["scale_deg"])), Q, U

        def describe(self):
            return {"model": self.name, **truth}
    return _Wrapped()


RING_SWEEPS = 12
"""Sweeps of a simulated ring session: a real session holds 11-12 one-turn recordings
(``reference/gkanias2023/sessions.csv``)."""
RING_SWEEP_SPACING_S = 62.0
"""Time between the starts of successive sweeps [s]: a real session's recordings follow each
other every 52-107 s (62 s where the times are estimated), so 12 sweeps span about 12 min."""
RING_PER_SWEEP = 60
"""Samples of one turn (6 deg of turn apart: 30 a period of the polarizers' ``cos 2 chi``).
A real turn holds about 410 samples (10 Hz over 41 s), and a fit thins a session to
:data:`calibration.photodiode_diagnosis.fit.FIT_SAMPLES` (1500), about 125 a sweep over 12
sweeps; half that keeps a ring diagnosis of the matrix near a minute (the fits' and
held-out residuals' cost grows with the samples), and the z-scores measure each SE against
the scatter of the estimates on this same design."""
RING_TURN_S = 41.0
"""Duration of one turn [s] (a real recording: about 410 samples at 10 Hz)."""


def ring_session(effect=None, truth=None, seed: int = 1, *, n_sweeps: int = RING_SWEEPS,
                 per_sweep: int = RING_PER_SWEEP, start: str = RING_START,
                 sweep_spacing_s: float = RING_SWEEP_SPACING_S, turn_s: float = RING_TURN_S):
    """A simulated relative-yaw, counter-clockwise ring session (eight units at 45 deg
    elevation, one full turn per sweep; by default 12 sweeps 62 s apart, as a real session)
    with ``effect`` injected.

    The generator is the sensor simulator (:class:`sensor.compound_eye.CompoundEyeSensor`)
    with the effect made physically: a multiple-scattering or neutral-point sky, the units'
    measured acceptance sampled over :data:`RING_CAP` directions, an occluded sector or a
    solar aureole in the sky, sunlight scattered inside the instrument added to the
    readings, a tilted platform, a clock or gyro error in the recorded times or yaw.

    Parameters
    ----------
    effect : str, optional
        A ring candidate's name, or None for clean data.
    truth : dict
        The effect's parameters, by the candidate's parameter names (``stray_light``:
        ``S`` (one strength for every photodiode, in units of the session's median reading
        with the stray light in it, as the candidate's) and ``scale_deg``; ``side_glare``:
        ``L`` and ``R``, the strengths for the sun square to each unit's left and right, and
        ``scale_deg``).
    seed : int
        Noise seed.
    n_sweeps, per_sweep : int
        Sweeps, and samples of each (evenly spread over one turn).
    start : str
        ISO time of the first sample.
    sweep_spacing_s : float
        Time between the starts of successive sweeps [s].
    turn_s : float
        Duration of one turn [s]; must not exceed ``sweep_spacing_s``.

    Returns
    -------
    PhotodiodeData

    Raises
    ------
    IdentifiabilityInputError
        For a ``turn_s`` that is not positive or exceeds ``sweep_spacing_s``.
    """
    import pandas as pd

    from sensor.compound_eye import (PhotodiodeModel, body_attitude, ring_configuration)
    from sensor.photodiodes_io import PhotodiodeData
    from skysim.sky import RayleighSky
    from skysim.sun import Site, sun_vector
    if not (0.0 < turn_s <= sweep_spacing_s):
        raise IdentifiabilityInputError(
            f"turn_s = {turn_s!r} s: a turn must last more than 0 s and no longer than "
            f"the sweep spacing ({sweep_spacing_s!r} s)")
    truth = truth or {}
    site = Site(*RING_SITE)
    rng = np.random.default_rng(seed)
    sensor = ring_configuration(8, 45.0, photodiode=PhotodiodeModel())
    t0 = pd.Timestamp(start)
    dt = turn_s / per_sweep
    times = pd.DatetimeIndex([t0 + pd.Timedelta(seconds=sweep_spacing_s * s + dt * k)
                              for s in range(n_sweeps) for k in range(per_sweep)])
    yaw = np.tile(np.linspace(0.0, 360.0, per_sweep, endpoint=False), n_sweeps) + 20.0
    sweep = np.repeat(np.arange(n_sweeps), per_sweep)
    sky = RayleighSky(RING_DMAX)
    if effect == "multiple_scattering":
        from skysim.multiple import MultipleScatteringSky
        # 1-deg sun nodes (the engine's stated interpolation error is far below the noise):
        # one engine run per node instead of one per sample
        sky = MultipleScatteringSky(tau=truth["tau"], albedo=truth["albedo"],
                                    sun_step_deg=1.0)
    elif effect == "neutral_points":
        from skysim.berry import BerrySky
        sky = BerrySky(delta_deg=truth["separation_deg"], dmax=RING_DMAX)
    elif effect in ("occlusion", "aureole"):
        sky = _modified_sky(sky, effect, truth)
    pitch, roll = ((truth["pitch_deg"], truth["roll_deg"]) if effect == "tilt" else (0.0, 0.0))
    data = sensor.sample(sky, site, times, yaw, pitch, roll, rng, yaw_reference="relative",
                         yaw_offset_deg=35.0, include_truth=False, sweep=sweep)
    t = data.table.drop(columns=["pitch_deg", "roll_deg"])
    cols = list(data.columns)
    if effect in ("fov", "stray_light", "side_glare"):
        att = body_attitude(yaw, np.full(yaw.size, pitch), np.full(yaw.size, roll))
        sun, _ = sun_vector(times, site)
        pm = sensor.photodiode
        R = t[cols].to_numpy(float)
        if effect == "fov":
            R = (pm.counts_per_radiance * _cone_readings(sensor, sky, att, sun,
                                                         truth["hwhm_deg"])
                 + pm.noise_counts * rng.standard_normal(R.shape))
        else:   # sunlight inside the instrument, on readings that carry their noise already
            pd_unit = np.repeat(np.arange(sensor.n_units),
                                [len(u.photodiodes_deg) for u in sensor.units])
            views = _unit_views(sensor.observe(sky, att, sun))
            cos_psi = np.clip(np.einsum("nuk,nk->nu", views, sun), -1.0, 1.0)
            psi = np.degrees(np.arccos(cos_psi))[:, pd_unit]
            if effect == "stray_light":
                strength = truth["S"]
            else:   # light of its own strength for the sun on either side of each unit
                side = _sun_side(views, cos_psi, sun)[:, pd_unit]
                strength = (truth["L"] * (1.0 + side) + truth["R"] * (1.0 - side)) / 2.0
            added = strength * np.exp(-psi / truth["scale_deg"])
            R = R + _stray_level(R, added, np.max(strength)) * added
        t[cols] = np.clip(np.round(R), 0.0, pm.saturation_value)
    t["yaw_deg"] = -(((t["yaw_deg"] + 180.0) % 360.0) - 180.0)      # ccw, wrapped
    if effect == "yaw_scale":   # the recorded change within each sweep, times the factor
        y = t["yaw_deg"].to_numpy(float)
        out = np.empty_like(y)
        for s_ in np.unique(sweep):
            m = sweep == s_
            u = np.degrees(np.unwrap(np.radians(y[m])))
            out[m] = u[0] + truth["factor"] * (u - u[0])
        t["yaw_deg"] = ((out + 180.0) % 360.0) - 180.0
    if effect == "clock_offset":
        t["time"] = pd.to_datetime(t["time"]) - pd.to_timedelta(truth["clock_offset_s"],
                                                                 unit="s")
    side = dict(data.sidecar, yaw_sense="counterclockwise")
    return PhotodiodeData(t, side)


def _stray_level(R, shape, S, tol: float = 1e-9, max_iter: int = 100) -> float:
    """The median ``m`` of the readings ``R + m shape`` (counts): the session's median reading
    with the stray light in it, the unit the ``stray_light`` candidate's strengths are in
    (its fit divides the recorded readings by their median); a truth stated in the median
    of ``R`` alone, 1.3 % lower at ``S = 0.2``, is that much above every strength the
    candidate can fit (0.003, twice the strengths' SE on a simulated ring). Fixed-point
    iteration from ``median(R)``: the map's slope is ``shape`` at the median reading,
    below ``S``.

    Raises
    ------
    IdentifiabilityInputError
        When the iteration does not settle (``S`` of 1 or more).
    """
    m = float(np.median(R))
    for _ in range(max_iter):
        new = float(np.median(R + m * shape))
        if abs(new - m) <= tol * abs(new):
            return new
        m = new
    raise IdentifiabilityInputError(
        f"stray light S = {S!r}: the session's median reading with the stray light in it "
        "does not settle; give S below 1")


def _sun_side(views, cos_psi, sun) -> np.ndarray:
    """Sine of the sun's bearing about each view (n, U): the sun's component along the
    horizontal direction to the view's left (``z x view``, normalised), over the sine of its
    distance from the view; 0 with the sun on the axis."""
    left = np.cross(np.array([0.0, 0.0, 1.0]), views)
    left /= np.linalg.norm(left, axis=-1, keepdims=True)
    sin_psi = np.sqrt(1.0 - cos_psi ** 2)
    along = np.einsum("nuk,nk->nu", left, sun)
    return np.where(sin_psi > 1e-9, along / np.maximum(sin_psi, 1e-9), 0.0)


def _unit_views(obs) -> np.ndarray:
    from skysim.geometry import direction_vector
    return direction_vector(obs.view_elevation_deg, obs.view_azimuth_deg)


def _cone_readings(sensor, sky, att, sun, hwhm_deg: float) -> np.ndarray:
    """Noise-free mean readings [radiance units] (n, P) of photodiodes whose units weigh the
    sky by the measured acceptance of half-width ``hwhm_deg``
    (:func:`calibration.photodiode_diagnosis.acceptance.acceptance`), the ground dark.

    Each photodiode's Malus reading is averaged over :data:`RING_CAP` equal-area directions
    (equal steps in the cosine of the off-axis angle out to where the acceptance falls to
    1e-8; on each ring, equal steps in azimuth over the part of it above the horizon, found
    from the unit's elevation), each weighted by the acceptance and the visible part of its
    ring, and normalised by the whole acceptance (a photodiode sees the dark ground as no
    light): a rule of its own, not the candidate's Gauss-Legendre one, with 27-32 times as
    many directions (the geometry of the visible arc is shared,
    :func:`~calibration.photodiode_diagnosis.acceptance.visible_half_arc`)."""
    from calibration.photodiode_diagnosis.acceptance import (acceptance, arc_azimuth_deg,
                                                             observe_directions,
                                                             theta_max_deg,
                                                             unit_up_vectors,
                                                             visible_half_arc)
    K, M = RING_CAP
    t_max = theta_max_deg(hwhm_deg, cut=1e-8)
    mid_k, mid_m = (np.arange(K) + 0.5) / K, (np.arange(M) + 0.5) / M

    def rings(t0):
        """Ring angles [deg] and solid-angle weights [sr / rad of azimuth] on [0, t_max]:
        K equal-area rings over [0, t0], where every direction is above the horizon,
        and K rings at t0 + (t_max - t0) s^2, equal steps in s, over the cut band, where
        the visible arc shrinks as sqrt(theta - t0) (smooth in s)."""
        t0 = min(t0, t_max)
        c0 = np.cos(np.radians(t0))
        cap = np.degrees(np.arccos(1.0 - mid_k * (1.0 - c0)))
        w_cap = np.full(K, (1.0 - c0) / K)
        if t0 >= t_max:
            return cap, w_cap
        band = t0 + (t_max - t0) * mid_k ** 2
        w_band = np.sin(np.radians(band)) * 2.0 * np.radians(t_max - t0) * mid_k / K
        return np.concatenate([cap, band]), np.concatenate([w_cap, w_band])

    sets = ([], [], [])
    for up in unit_up_vectors(sensor, att):
        theta, dw = rings(90.0 - np.degrees(np.arcsin(up[2])))
        a = acceptance(theta, hwhm_deg) * dw
        half = visible_half_arc(theta, up)                            # (rings,) [rad]
        beta = np.degrees(half[:, None] * (2.0 * mid_m[None, :] - 1.0))
        b = arc_azimuth_deg(beta, up)
        sets[0].append(np.repeat(theta, M))
        sets[1].append(b.ravel())
        # normalised by the whole acceptance (the ground dark)
        sets[2].append(np.repeat(a * 2.0 * half / M / (2.0 * np.pi * a.sum()), M))
    obs, unit, w, _ = observe_directions(sensor, sky, att, sun, *sets)
    out = []
    for i, u in enumerate(sensor.units):
        cols = unit == i
        for ang in u.photodiodes_deg:
            chi = np.radians(obs.aop_unit_deg[:, cols] - ang)
            out.append((obs.radiance[:, cols] * (1.0 + obs.dop[:, cols] * np.cos(2 * chi)))
                       @ w[cols])
    return np.stack(out, axis=1)


def _ring() -> InstrumentMatrix:
    from calibration.photodiode_diagnosis.effects import RING_EFFECT_NAMES
    occl = {"width_deg": 90.0, "edge_deg": 5.0}
    strengths = {
        "multiple_scattering": {"moderate": {"tau": 0.1, "albedo": 0.1},
                                "strong": {"tau": 0.25, "albedo": 0.1}},
        "neutral_points": {"moderate": {"separation_deg": 20.0},
                           "strong": {"separation_deg": 40.0}},
        # a bare photodiode's cosine response has a HWHM of 60 deg, the ring's collared
        # units measure 22.7 deg: on this session a HWHM of 30 deg leaves a held-out gap of
        # 1.06 times the floor after the base fit (its pointing and DoP scale take it up), 40
        # and 45 deg 1.59 and 2.61 times; from 50 deg the readings' flattened tops are
        # flagged as saturated
        "fov": {"moderate": {"hwhm_deg": 40.0}, "strong": {"hwhm_deg": 45.0}},
        "occlusion": {"moderate": {"center_deg": 100.0, **occl, "depolarization": 0.4},
                      "strong": {"center_deg": 250.0, **occl, "depolarization": 0.8}},
        "yaw_scale": {"moderate": {"factor": 1.02}, "strong": {"factor": 0.95}},
        # the strong clock off the whole and half hours of the coarse search: a truth on
        # them is where the fit starts, and its error then says nothing of its SE
        "clock_offset": {"moderate": {"clock_offset_s": 900.0},
                         "strong": {"clock_offset_s": -3300.0}},
        "tilt": {"moderate": {"pitch_deg": 1.0, "roll_deg": -0.5},
                 "strong": {"pitch_deg": -2.5, "roll_deg": 2.0}},
        "aureole": {"moderate": {"amplitude": 0.5, "scale_deg": 15.0},
                    "strong": {"amplitude": 2.0, "scale_deg": 15.0}},
        # sunlight scattered inside an unbaffled unit, a few % of the sky's light near the
        # sun: S = 0.1 and 0.2 (times the session's median reading) add at most 6.5 and 13 %
        # to a unit's reading, where it looks nearest the sun (1.34 times the median); 0.02
        # left a held-out gap of 1.06 times the floor after the base fit, 0.1 and 0.2 leave
        # 1.55 and 2.46 times
        "stray_light": {"moderate": {"S": 0.1, "scale_deg": 20.0},
                        "strong": {"S": 0.2, "scale_deg": 20.0}}}
    return InstrumentMatrix("ring", tuple(RING_EFFECT_NAMES),
                            {e: strengths[e] for e in RING_EFFECT_NAMES}, ring_session,
                            seeds=(31,))


_BUILDERS = {"three-pair": _three_pair, "sky": _sky, "camera": _camera,
             "ring": _ring}


def matrix_spec(instrument: str) -> InstrumentMatrix:
    """The :class:`InstrumentMatrix` of ``instrument`` (one of :data:`INSTRUMENTS`).

    Raises
    ------
    IdentifiabilityInputError
        For another name.
    """
    if instrument not in _BUILDERS:
        raise IdentifiabilityInputError(
            f"no identifiability matrix for instrument {instrument!r}; choose one of "
            f"{', '.join(_BUILDERS)}")
    return _BUILDERS[instrument]()


def rows_to_json(rows: pd.DataFrame) -> list:
    """The rows as plain JSON-ready dicts."""
    return json.loads(rows.to_json(orient="records"))


def write_matrix(instrument: str, out, *, quick: bool = False, z_draws: int = 0) -> dict:
    """Run the matrix of ``instrument`` and write ``identifiability.json`` (the score and
    every case) and ``identifiability.md`` (the tables) into the folder ``out``, each
    atomically; with ``z_draws``, also each candidate's z-scores over that many noise draws
    (:func:`z_over_draws`, seeds from :data:`Z_DRAW_SEED0`) into ``z_over_draws.csv``, their
    summary into the JSON (``z_over_draws``) and its table into the Markdown.

    Parameters
    ----------
    instrument : str
        One of :data:`INSTRUMENTS`.
    out : path
        Output folder (created).
    quick : bool
        The first noise seed and the strong strength only (the z draws too).
    z_draws : int
        Noise draws of the SE calibration (0: none), at both strengths.

    Returns
    -------
    dict
        :func:`score_matrix` of the run (with ``z_over_draws``, the summary, when asked).

    Raises
    ------
    IdentifiabilityInputError
        For a negative ``z_draws``.
    """
    from dataclasses import replace
    from pathlib import Path

    from skysim.io import atomic_write, write_json_atomic
    spec = matrix_spec(instrument)
    if quick:
        spec = replace(spec, seeds=spec.seeds[:1],
                       strengths={e: {"strong": v["strong"]} for e, v in spec.strengths.items()})
    if int(z_draws) != z_draws or z_draws < 0:
        raise IdentifiabilityInputError(
            f"z_draws = {z_draws!r}: give a whole number of noise draws, 0 or more")
    rows = run_matrix(spec)
    score = score_matrix(rows)
    text = matrix_markdown(score, instrument)
    draws = None
    if z_draws:
        seeds = range(Z_DRAW_SEED0, Z_DRAW_SEED0 + int(z_draws))
        draws = pd.concat([z_over_draws(spec, e, seeds).assign(effect=e)
                           for e in spec.strengths], ignore_index=True)
        score["z_over_draws"] = z_draws_summary(draws)
        text += "\n" + z_draws_markdown(score["z_over_draws"], instrument)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if draws is not None:
        atomic_write(out / "z_over_draws.csv", lambda p: draws.to_csv(p, index=False))
    write_json_atomic(out / "identifiability.json",
                      {"instrument": instrument, "seeds": list(spec.seeds), "quick": quick,
                       "score": score, "cases": rows_to_json(rows)})
    atomic_write(out / "identifiability.md", lambda p: p.write_text(text))
    return score
