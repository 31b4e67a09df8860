"""`skysim diagnose` and `skysim gap-benchmark`: sim-to-real gap diagnosis, checked blind.

``skysim diagnose DATA`` parses its arguments, runs :func:`calibration.diagnose` on the file (a
measurement table "skysim.measurement/1" or raw photodiode data "skysim.photodiodes/1" with
its sidecar) and writes the report: ``diagnosis.json`` (schema "skysim.diagnosis/3"),
``report.md`` and figures.

``skysim gap-benchmark`` generates data sets with one hidden effect (or none) at a magnitude
drawn from the effect's documented range, diagnoses each without the label, and scores the
verdicts. The generator (this module's :func:`simulate_session`) and the diagnoser share only
:mod:`calibration.effects`; the label and the true parameters go to a separate truth record
the diagnoser never reads.

Benchmark session (a documented choice; the issue leaves it open): the Xi'an rooftop of Yang
et al. (2014) on 2013-05-22, six turntable sweeps of 121 stops over 180 deg, 600 s each,
starting every 30 min from 15:30 to 18:00 local time (sun elevation ~51 -> ~18 deg, so the
illuminance falls ~2.5x and the sensor cools by a few kelvin: the slow effects have something
to act on; the last sweep ends early enough that a one-hour clock error keeps the recorded
sun above the horizon). Sensor errors, noise, DAQ and ``d_max`` follow
:data:`sensor.yang2014.ERROR_MODEL`.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from calibration.diagnosis import (
    DEFAULT_CANDIDATES,
    DiagnosisData,
    DiagnosisReport,
    Thresholds,
    data_from_table,
    diagnose,
)
from calibration.diagnosis.three_pair import DEFAULT_THRESHOLDS as THREE_PAIR_THRESHOLDS
from calibration.effects import EFFECT_NAMES, Context, base_vector, forward, get_effect
from calibration.effects.dark_current import clear_sky_illuminance_lx
from sensor.daq import Daq
from sensor.measurement import MEASUREMENT_SCHEMA, Measurement
from sensor.opponent import OpponentSensor
from sensor.yang2014 import ERROR_MODEL, SITE
from skysim import __version__
from skysim.io import atomic_write, write_json_atomic

from experiments.workflows.options import (
    DefaultsHelpFormatter,
    data_file_and_sidecars,
    existing_file,
    int_at_least,
    name_list,
    nonnegative_float,
    output_dir,
    positive_int,
    refuse_replacing_inputs,
    seed,
)

__all__ = [
    "SESSION",
    "Session",
    "register",
    "run_benchmark",
    "score_benchmark",
    "simulate_session",
]


@dataclass(frozen=True)
class Session:
    """Acquisition plan of a benchmark data set (see module docstring)."""

    date: str = "2013-05-22"
    utc_offset: str = "+08:00"
    first_start: str = "15:30"
    sweep_spacing_min: float = 30.0
    n_sweeps: int = 6
    n_stops: int = 121
    sweep_duration_s: float = 600.0
    temperature_start_C: tuple = (28.0, 36.0)
    cooling_K_per_h: tuple = (1.0, 4.0)
    illuminance_factor: tuple = (0.8, 1.1)

    def starts(self) -> pd.DatetimeIndex:
        t0 = pd.Timestamp(f"{self.date}T{self.first_start}:00{self.utc_offset}")
        return pd.DatetimeIndex([t0 + pd.Timedelta(minutes=self.sweep_spacing_min * k)
                                 for k in range(self.n_sweeps)])


SESSION = Session()


def _to_times(t_s, tz_offset: str) -> pd.Series:
    idx = pd.to_datetime(np.round(np.asarray(t_s) * 1e9).astype(np.int64), unit="ns", utc=True)
    return pd.Series(idx).dt.tz_convert(pd.Timestamp(f"2000-01-01T00:00{tz_offset}").tz)


def simulate_session(effect: str | None, rng: np.random.Generator, *, params=None,
                     session: Session = SESSION, model=ERROR_MODEL, seed=None) -> dict:
    """One data set with a hidden effect (or none) and its effect-free twin.

    Returns a dict with ``measurement`` (the recorded table, as a real instrument would
    write it), ``clean`` (the same noise and sensor regenerated without the effect, and with
    correct timestamps), ``truth`` (label and parameters, never given to the diagnoser) and
    ``data``/``clean_data`` (:class:`DiagnosisData` built from the tables alone).
    """
    errors = model.draw_errors(rng)
    dmax = rng.uniform(*model.dmax_range)
    eff = None if effect is None else get_effect(effect)
    p = None if eff is None else (eff.draw(rng) if params is None else np.asarray(params, float))
    starts = session.starts()
    n = session.n_sweeps * session.n_stops
    sweep = np.repeat(np.arange(session.n_sweeps), session.n_stops)
    frac = np.tile(np.linspace(0.0, 1.0, session.n_stops), session.n_sweeps)
    t0 = starts.tz_convert("UTC").as_unit("ns").asi8 / 1e9
    duration = float(p[0]) if effect == "sun_motion" else session.sweep_duration_s
    t_true = t0[sweep] + frac * duration
    track = Context.from_arrays(SITE, _to_times(t_true, session.utc_offset), np.zeros(n)).sun
    _, sun_az0 = track.elevation_azimuth(t0)
    heading = (sun_az0[sweep] - 90.0 + frac * 179.9) % 360.0
    sun_el, _ = track.elevation_azimuth(t_true)
    temp = (rng.uniform(*session.temperature_start_C)
            - rng.uniform(*session.cooling_K_per_h) * (t_true - t_true[0]) / 3600.0)
    lux = rng.uniform(*session.illuminance_factor) * clear_sky_illuminance_lx(sun_el)
    t_rec = t_true.copy()
    if effect == "sun_motion":
        t_rec = t0[sweep]
    elif effect == "clock_offset":
        t_rec = t_true - float(p[0])
    base = base_vector(errors.misalignment_deg, errors.transmittance, dmax)
    heading_true = heading + model.turntable_error_deg * rng.standard_normal(n)
    noise = rng.standard_normal((n, 3)) * np.asarray(errors.noise_V)
    daq = Daq(model.daq_bits, model.daq_range_V)

    def make_ctx(t, h):
        return Context(SITE, t, h, sweep, frac, lux, temp, track, float(t_true[0]))

    U = daq.acquire(forward(make_ctx(t_rec, heading_true), base, eff, p) + noise)[0]
    U_clean = daq.acquire(forward(make_ctx(t_true, heading_true), base) + noise)[0]
    sensor = OpponentSensor(errors, daq=daq)

    def table(t, u):
        return Measurement(pd.DataFrame({
            "time": _to_times(t, session.utc_offset), "heading_deg": heading,
            "U1_V": u[:, 0], "U2_V": u[:, 1], "U3_V": u[:, 2], "sweep": sweep,
            "illuminance_lx": lux, "temperature_C": temp}),
            {"schema": MEASUREMENT_SCHEMA, "site": SITE.to_dict(), "sensor": sensor.describe(),
             "generator": {"package": "skysim", "version": __version__,
                           "command": "skysim gap-benchmark", "seed": seed,
                           "session": session.__dict__, "truth": "withheld (truth.json)"}})

    meas, clean = table(t_rec, U), table(t_true, U_clean)
    truth = {"effect": effect or "none", "params": None if eff is None else eff.describe(p),
             "dmax": dmax, "errors": errors.to_dict(), "seed": seed}
    return {"measurement": meas, "clean": clean, "truth": truth,
            "data": measurement_data(meas), "clean_data": measurement_data(clean)}


def measurement_data(m: Measurement) -> DiagnosisData:
    """:class:`DiagnosisData` from a measurement table: its columns and sidecar only."""
    return data_from_table(m.table, m.sidecar, "generated")


# --------------------------------------------------------------------------- blind benchmark
BENCHMARK_LABELS = ("none",) + EFFECT_NAMES


def _one_case(i: int, label: str, seed_seq, effects, thresholds, n_folds) -> dict:
    rng = np.random.default_rng(seed_seq)
    # recorded seed: the benchmark seed and this case's spawn key (SeedSequence.spawn)
    ds = simulate_session(None if label == "none" else label, rng,
                          seed={"entropy": seed_seq.entropy,
                                "spawn_key": list(seed_seq.spawn_key)})
    doc = diagnose(ds["data"], effects, folds=n_folds, seed=i, thresholds=thresholds)
    clean = diagnose(ds["clean_data"], [], folds=n_folds, seed=i, thresholds=thresholds)
    v = doc.verdict
    # the true effect withheld: a second diagnosis, since the paired comparison is against
    # the best candidate that remains
    loo = (v.effect if label == "none" else
           diagnose(ds["data"], [e for e in effects if e != label], folds=n_folds, seed=i,
                    thresholds=thresholds).verdict.effect)
    shrink_true = 1.0 - clean.verdict.gap_before / v.gap_before
    best = doc.candidate(v.best_candidate) if v.best_candidate else None
    shrink_best = best.shrink if best else 0.0
    return {"case": i, "truth": label, "verdict": v.effect, "group": json.dumps(v.group),
            "loo_verdict": loo,
            "gap_before_mV": v.gap_before, "gap_after_mV": v.gap_after,
            "noise_floor_mV": doc.noise_floor, "gap_clean_mV": clean.verdict.gap_before,
            "gap_ratio": v.gap_before / doc.noise_floor,
            "shrink_est": v.shrink, "shrink_best_candidate": shrink_best,
            "shrink_true": shrink_true, "shrink_se": v.shrink_se,
            "truth_params": json.dumps(ds["truth"]["params"]),
            "fitted_params": json.dumps({k: p["value"] for k, p in v.params.items()})}


def run_benchmark(n: int = 200, seed: int = 7, effects=DEFAULT_CANDIDATES, n_folds: int = 3,
                  thresholds: Thresholds | None = None, progress: bool = True) -> pd.DataFrame:
    """Generate ``n`` data sets (labels cycling through none + the effects, magnitudes from the
    documented ranges), diagnose each blind, and return one row per case."""
    from tqdm import tqdm
    labels = [lab for lab in BENCHMARK_LABELS if lab == "none" or lab in effects]
    available = [lab for lab in labels if lab == "none" or _available(lab)]
    thresholds = thresholds or THREE_PAIR_THRESHOLDS
    seeds = np.random.SeedSequence(seed).spawn(n)
    rows = [_one_case(i, available[i % len(available)], seeds[i], effects, thresholds, n_folds)
            for i in tqdm(range(n), desc="gap-benchmark", disable=not progress, unit="set")]
    return pd.DataFrame(rows)


def _available(name: str) -> bool:
    """False when an effect's optional physics (e.g. the multiple-scattering sky) is missing."""
    return get_effect(name).available() is None


def score_benchmark(cases: pd.DataFrame, ratio_min: float = 2.0,
                    shrink_tol: float = 0.20) -> dict:
    """Acceptance figures of the issue from the per-case table.

    - accuracy where the effect's gap is >= ``ratio_min`` x the noise floor, the effect named
      (``accuracy_strong``) or named or in the named group (``found_strong``);
    - leave-one-out: fraction ``unexplained`` with the true effect withheld (same strata),
      and the fraction naming a wrong effect (``loo_not_named_strong``: the fraction naming
      none); also over every effect case whose gap the
      diagnosis detected (verdict other than ``none``);
    - ``none`` on effect-free data;
    - false attributions: verdicts naming an effect other than the truth, over all cases;
    - shrink error ``shrink_est - shrink_true`` on correctly attributed strong cases, where
      ``shrink_true = 1 - G_clean / G_before`` (G_clean: the same data regenerated without the
      effect); within +-``shrink_tol`` counts as accurate.
    """
    if "group" not in cases:            # a table recorded before groups were reported
        cases = cases.assign(group="[]")
    in_group = np.array([v == t or (v == "group" and t in json.loads(g))
                         for v, t, g in zip(cases.verdict, cases.truth, cases.group)], bool)
    cases = cases.assign(found=in_group)
    eff = cases[cases.truth != "none"]
    strong = eff[eff.gap_ratio >= ratio_min]
    none = cases[cases.truth == "none"]
    named = cases.verdict.isin(EFFECT_NAMES)
    false_attr = named & (cases.verdict != cases.truth)
    loo_wrong = strong.loo_verdict.isin(EFFECT_NAMES)
    detected = eff[eff.verdict != "none"]  # effect data whose gap exceeds the floor
    ok = strong[strong.verdict == strong.truth]
    err = ok.shrink_est - ok.shrink_true
    labels = list(dict.fromkeys(list(BENCHMARK_LABELS)
                                + ["group", "partly_explained", "unexplained"]))
    confusion = pd.crosstab(cases.truth, cases.verdict).reindex(
        index=[x for x in labels if x in set(cases.truth)], columns=labels, fill_value=0)

    def frac(x):
        return float(np.mean(x)) if len(x) else float("nan")

    summary = {
        "cases": len(cases), "effect_cases": len(eff),
        "strong_effect_cases": len(strong), "none_cases": len(none),
        "accuracy_strong": frac(strong.verdict == strong.truth),
        "found_strong": frac(strong.found),
        "accuracy_all": frac(cases.verdict == cases.truth),
        "loo_unexplained_strong": frac(strong.loo_verdict == "unexplained"),
        "loo_wrong_effect_strong": frac(loo_wrong),
        "loo_not_named_strong": frac(~loo_wrong),
        "loo_unexplained_detected": frac(detected.loo_verdict == "unexplained"),
        "detected_effect_cases": int(len(detected)),
        "none_on_effect_free": frac(none.verdict == "none"),
        "false_attribution_rate": frac(false_attr),
        "shrink_within_tol": frac(np.abs(err) <= shrink_tol),
        "shrink_error_median_abs": float(np.median(np.abs(err))) if len(err) else float("nan"),
        "shrink_error_p90_abs": float(np.quantile(np.abs(err), 0.9)) if len(err) else float("nan"),
        "ratio_min": ratio_min, "shrink_tol": shrink_tol,
        "per_effect_accuracy_strong": {lab: frac(g.verdict == lab) for lab, g in
                                       strong.groupby("truth")},
    }
    summary["acceptance"] = {
        "found_strong>=0.90": summary["found_strong"] >= 0.90,
        "loo_not_named>=0.90": summary["loo_not_named_strong"] >= 0.90,
        "none_on_effect_free>=0.90": summary["none_on_effect_free"] >= 0.90,
        "shrink_within_20pct>=0.90": summary["shrink_within_tol"] >= 0.90}
    return {"summary": summary, "confusion": confusion}


# --------------------------------------------------------------------------- reports, figures
def _fmt(x, nd=3):
    return "—" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.{nd}g}"


def plot_diagnosis(report: DiagnosisReport, out: Path) -> list[Path]:
    """Held-out residual RMS by slice (one panel per dimension, the noise floor and each
    slice's limit marked) and the gap before/after per candidate (PNG, matplotlib Agg)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from experiments.plotting.figures import quantity_label
    u = report.unit
    dims = list(dict.fromkeys(s.dimension for s in report.where))
    fig, axes = plt.subplots(1, max(len(dims), 1), figsize=(3.4 * max(len(dims), 1), 3.6),
                             constrained_layout=True, squeeze=False)
    for ax, dim in zip(axes[0], dims):
        tab = [s for s in report.where if s.dimension == dim]
        tab.sort(key=lambda s: (s.lo if s.lo is not None else 0.0, s.label))
        x = np.arange(len(tab))
        ax.bar(x, [s.rms for s in tab],
               color=["tab:red" if s.carries_gap else "tab:blue" for s in tab])
        ax.plot(x, [s.limit for s in tab], "k_", ms=12, label="slice limit")
        if report.noise_floor is not None:
            ax.axhline(report.noise_floor, color="k", ls="--", lw=1, label="noise floor")
        ax.set_xticks(x, [s.label for s in tab], rotation=45, ha="right", fontsize=7)
        ax.set_title(f"by {quantity_label(dim)}", fontsize=9)
        ax.set_ylabel(f"held-out RMS [{u}]")
    axes[0][0].legend(fontsize=7)
    p1 = out / "residuals_by_slice.png"
    atomic_write(p1, lambda q: fig.savefig(q, dpi=110, format="png"))
    plt.close(fig)
    v = report.verdict
    rows = [c for c in report.candidates if c.available]
    fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
    names = ["base"] + [c.effect for c in rows]
    gaps = [v.gap_before] + [c.gap_after for c in rows]
    if v.gap_before is not None:
        colors = ["tab:gray"] + ["tab:green" if c.effect == v.effect else "tab:blue"
                                 for c in rows]
        ax.bar(range(len(names)), gaps, color=colors)
        ax.set_xticks(range(len(names)), names, rotation=35, ha="right", fontsize=8)
    if report.noise_floor is not None:
        ax.axhline(report.noise_floor, color="k", ls="--", lw=1, label="noise floor")
        ax.legend(fontsize=8)
    ax.set_ylabel(f"held-out gap [{u}]")
    ax.set_title(f"gap before/after — verdict: {v.effect}")
    p2 = out / "gap_before_after.png"
    atomic_write(p2, lambda q: fig.savefig(q, dpi=110, format="png"))
    plt.close(fig)
    return [p1, p2]


def benchmark_markdown(result: dict, n: int, seed: int, elapsed: float) -> str:
    s = result["summary"]
    conf = result["confusion"]
    acc = s["acceptance"]
    lines = [f"# Blind gap benchmark — {n} data sets, seed {seed}", "",
             ("Each data set hides one effect (or none) at a magnitude drawn from the effect's "
              "documented range; the diagnosis sees only the table. Strong cases: held-out gap "
              f">= {s['ratio_min']} x noise floor."), "",
             "| figure | value | acceptance |", "|---|---|---|",
             (f"| effect named or in the named group, strong effect cases "
              f"({s['strong_effect_cases']}) | {100 * s['found_strong']:.1f} % (named alone "
              f"{100 * s['accuracy_strong']:.1f} %) | >= 90 %: "
              f"{'pass' if acc['found_strong>=0.90'] else 'FAIL'} |"),
             (f"| leave-one-out: no single effect named, strong cases | "
              f"{100 * s['loo_not_named_strong']:.1f} % (`unexplained` "
              f"{100 * s['loo_unexplained_strong']:.1f} %) | >= 90 %: "
              f"{'pass' if acc['loo_not_named>=0.90'] else 'FAIL'} |"),
             (f"| leave-one-out `unexplained`, all detected effect cases "
              f"({s['detected_effect_cases']}) | {100 * s['loo_unexplained_detected']:.1f} % | — |"),
             (f"| `none` on effect-free data ({s['none_cases']}) | "
              f"{100 * s['none_on_effect_free']:.1f} % | >= 90 %: "
              f"{'pass' if acc['none_on_effect_free>=0.90'] else 'FAIL'} |"),
             (f"| shrink within ±{s['shrink_tol']:.2f} of truth (correct strong cases) | "
              f"{100 * s['shrink_within_tol']:.1f} % (median abs error "
              f"{s['shrink_error_median_abs']:.4f}, 90th pct {s['shrink_error_p90_abs']:.4f}) "
              f"| >= 90 %: {'pass' if acc['shrink_within_20pct>=0.90'] else 'FAIL'} |"),
             (f"| false-attribution rate (all cases) | {100 * s['false_attribution_rate']:.1f} % "
              "| — |"),
             f"| accuracy, all cases | {100 * s['accuracy_all']:.1f} % | — |", "",
             "## Confusion matrix (rows: truth, columns: verdict)", "",
             "| truth \\ verdict | " + " | ".join(conf.columns) + " |",
             "|---" * (len(conf.columns) + 1) + "|"]
    for lab, row in conf.iterrows():
        lines.append(f"| {lab} | " + " | ".join(str(int(x)) for x in row) + " |")
    lines += ["", f"Elapsed: {elapsed:.0f} s.", ""]
    return "\n".join(lines)


def plot_benchmark(cases: pd.DataFrame, confusion: pd.DataFrame, out: Path) -> list[Path]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 5.5), constrained_layout=True)
    m = confusion.to_numpy()
    ax.imshow(m, cmap="Blues")
    for (i, j), x in np.ndenumerate(m):
        if x:
            ax.text(j, i, str(int(x)), ha="center", va="center", fontsize=8)
    ax.set_xticks(range(m.shape[1]), confusion.columns, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(m.shape[0]), confusion.index, fontsize=8)
    ax.set_xlabel("verdict")
    ax.set_ylabel("hidden effect")
    p1 = out / "confusion.png"
    fig.savefig(p1, dpi=110)
    plt.close(fig)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    ok = cases[(cases.verdict == cases.truth) & (cases.truth != "none")]
    axes[0].plot([0, 1], [0, 1], "k--", lw=1)
    for lab, g in ok.groupby("truth"):
        axes[0].plot(g.shrink_true, g.shrink_est, "o", ms=4, label=lab)
    axes[0].set_xlabel("true shrink (data regenerated without the effect)")
    axes[0].set_ylabel("estimated shrink")
    axes[0].legend(fontsize=7)
    for lab, g in cases.groupby("truth"):
        axes[1].plot(g.gap_ratio, (g.verdict == g.truth).astype(float)
                     + 0.04 * np.random.default_rng(0).standard_normal(len(g)), "o", ms=3,
                     label=lab)
    axes[1].axvline(2.0, color="k", ls="--", lw=1)
    axes[1].set_xscale("log")
    axes[1].set_xlabel("held-out gap / noise floor")
    axes[1].set_ylabel("verdict correct (1) or not (0)")
    p2 = out / "shrink_and_detection.png"
    fig.savefig(p2, dpi=110)
    plt.close(fig)
    return [p1, p2]


# --------------------------------------------------------------------------- command line
def _effects_arg(names: tuple[str, ...] | None):
    """Benchmark effects: all by default, else the names given (validated)."""
    if not names:
        return DEFAULT_CANDIDATES
    for name in names:
        get_effect(name)  # UnknownEffectError lists the valid names
    return names


def write_diagnosis(report: DiagnosisReport, out: Path) -> list[Path]:
    """Write ``diagnosis.json``, ``report.md`` and the figures into ``out`` (each atomically)."""
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "diagnosis.json", report.to_dict())
    md = report.to_markdown()
    atomic_write(out / "report.md", lambda p: p.write_text(md))
    return [out / "diagnosis.json", out / "report.md", *plot_diagnosis(report, out)]


DEFAULT_CANDIDATE_COUNT = 10
"""Candidates a diagnosis tries when none are named (the ring's defaults; the three-pair
sensor's are fewer), for the expected duration."""


def _expected_seconds(data, names) -> float:
    """Expected wall time of ``skysim diagnose`` [s] (:data:`.progress.COMMAND_SECONDS`): a
    camera frame as the README's 512 x 512 image; a table 0.75 times the README's
    two-candidate ring session per candidate, between that session (6 s, estimated 9 s) and
    a real ring session of 5,000 samples with the ten default candidates (about 65 s on a
    shared 2-core machine, estimated 45 s): within 2x of both."""
    from .progress import COMMAND_SECONDS
    if Path(data).suffix.lower() in (".tif", ".tiff", ".png"):
        return COMMAND_SECONDS["diagnose camera image 512x512"]
    n = len(names) if names else DEFAULT_CANDIDATE_COUNT
    return 0.75 * COMMAND_SECONDS["diagnose ring, two effects"] * max(n, 1)


def _diagnose_cmd(args) -> int:
    from calibration import diagnose as run_diagnosis
    names = args.effects or None
    options = {}
    if getattr(args, "pointing_from", None):
        options["pointing_from"] = list(args.pointing_from)
    if getattr(args, "light", "sun") != "sun":
        options["light"] = args.light
    if getattr(args, "time_uncertainty", None):
        options["time_uncertainty_s"] = args.time_uncertainty
    out = Path(args.out or Path("results") / "diagnose" / Path(args.data).stem)
    refuse_replacing_inputs(
        [("--out", out / "diagnosis.json"), ("--out", out / "report.md")],
        [("data", p) for p in data_file_and_sidecars(args.data)]
        + [("--pointing-from", p) for p in options.get("pointing_from", ())])
    from .progress import working
    with working("skysim diagnose", _expected_seconds(args.data, names)):
        report = run_diagnosis(args.data, names, folds=args.folds, seed=args.seed, **options)
    written = write_diagnosis(report, out)
    v = report.verdict
    # a dimensionless gap (a fraction of the mean reading or signal) is printed bare
    u, su = ("relative", "") if report.unit == "1" else (report.unit, f" {report.unit}")
    print(f"verdict: {v.effect} ({v.reason})")
    if v.gap_before is not None:
        se = "" if v.shrink_se is None else f" +- {100 * v.shrink_se:.1f}"
        floor = ("unknown" if report.noise_floor is None
                 else f"{report.noise_floor:.4g}{su}")
        print(f"gap {v.gap_before:.4g} -> {v.gap_after:.4g}{su} (noise floor "
              f"{floor}), shrink {100 * v.shrink:.1f}{se} %")
    print(f"| effect | held-out gap [{u}] | score | explains |")
    for c in report.candidates:
        if c.available:
            print(f"| {c.effect} | {c.gap_after:.4g} | {c.score:.1f} | "
                  f"{'yes' if c.explained else 'no'} |")
        else:
            print(f"| {c.effect} | unavailable | | |")
    for line in _instrument_summary(report):
        print(line)
    print(f"wrote {out}/" + ", ".join(p.name for p in written))
    return 0


def _instrument_summary(report: DiagnosisReport) -> list[str]:
    """What a photodiode report says beside its verdict, one line each: the heading error
    (and the heading ambiguity of a zenith-only compass), the base fit's parameters at a
    bound of the fit, what the data cannot recover, and why a candidate was not applicable."""
    extra = report.extra or {}
    lines = []
    for c in report.candidates:
        if not c.available and c.not_applicable:
            lines.append(f"{c.effect}: {c.not_applicable}")
    he = extra.get("heading_error")
    if he and he.get("base_deg") is not None:
        best = "" if he.get("best_deg") is None else f", {he['best_deg']:.3g} deg with the " \
                                                       "named effect"
        amb = he.get("ambiguity_deg", 360.0)
        mod = f" (modulo {amb:g} deg: {he['ambiguity']})" if amb != 360.0 else ""
        lines.append(f"heading error {he['base_deg']:.3g} deg RMS{best}{mod}")
    base = extra.get("base_fit") or {}
    if base.get("at_bound"):
        lines.append("base fit at a bound (taking up a misfit, not a measurement): "
                     + ", ".join(base["at_bound"]))
    for u in base.get("not_recoverable", []):
        lines.append(f"not recoverable: {u['quantity']} ({u['reason']})")
    return lines


def _real_benchmark_cmd(args) -> int:
    from calibration.photodiode_diagnosis import RING_EFFECT_NAMES

    from .progress import check_duration
    from .real_benchmark import run_real_benchmark, session_files
    from .real_injection import INJECTABLE
    inject = INJECTABLE
    cands = RING_EFFECT_NAMES
    if args.effects:
        inject = args.effects
    n = 1 if args.quick else (args.n if args.n != 200 else 3)
    if args.quick:
        cands = ("clock_offset", "yaw_scale", "occlusion")
    out = Path(args.out or "results/gap_benchmark_real")
    n = min(n, len(session_files(args.real, "--real")))   # a missing folder named first
    check_duration(n * len(inject) * REAL_SECONDS_PER_CASE_AND_CANDIDATE * len(cands),
                   f"skysim gap-benchmark --real: {n} session(s) x {len(inject)} effect(s)",
                   "a smaller --n, fewer --effects or --quick make it shorter")
    table = run_real_benchmark(args.real, inject, cands, out, n, args.seed, args.folds)
    print(table.to_string(index=False))
    print(f"wrote {out}/real_cases.csv, real_summary.json")
    return 0


REAL_SECONDS_PER_CASE_AND_CANDIDATE = 50.0
"""Time of ``skysim gap-benchmark --real`` per injected case and candidate effect [s]: the
``--quick`` run (one session, four injected effects, three candidates) took 610 s on a shared
2-core machine, 51 s per case and candidate; other candidate lists scaled in proportion."""

BENCHMARK_BYTES_PER_SET = 20_000
"""Memory one data set of the blind benchmark keeps until the end [bytes]: its seed, its
row of the case table (about 30 values and two JSON strings) and its share of the final
frame and CSV text; rounded up from about 5 kB."""

BENCHMARK_SECONDS_PER_SET = 1.5
"""Time to generate and diagnose one data set twice (with and without its effect) [s]:
1.4-2.2 s measured on a shared 2-core machine."""


def _benchmark_cmd(args) -> int:
    from skysim.resources import check_memory

    from .progress import check_duration
    if getattr(args, "real", None):
        return _real_benchmark_cmd(args)
    n = 27 if args.quick else args.n
    check_memory(n * BENCHMARK_BYTES_PER_SET, f"{n} data sets of gap-benchmark", "use a "
                 "smaller --n")
    effects = _effects_arg(args.effects)
    check_duration(n * BENCHMARK_SECONDS_PER_SET, f"skysim gap-benchmark: {n} data sets",
                   "a smaller --n or --quick makes it shorter")
    out = Path(args.out or "results/gap_benchmark")
    t0 = time.perf_counter()
    cases = run_benchmark(n, args.seed, effects, n_folds=args.folds)
    result = score_benchmark(cases)
    elapsed = time.perf_counter() - t0
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "cases.csv", lambda p: cases.to_csv(p, index=False))
    atomic_write(out / "confusion.csv", lambda p: result["confusion"].to_csv(p))
    summary = dict(result["summary"], n=n, seed=args.seed, elapsed_s=elapsed,
                   session=SESSION.__dict__,
                   generation_ranges={e: get_effect(e).generation_range for e in effects})
    write_json_atomic(out / "summary.json", summary)
    md = benchmark_markdown(result, n, args.seed, elapsed)
    atomic_write(out / "report.md", lambda p: p.write_text(md))
    plot_benchmark(cases, result["confusion"], out)
    print(md)
    print(f"wrote {out}/cases.csv, confusion.csv, summary.json, report.md, confusion.png, "
          "shrink_and_detection.png")
    return 0


def register(sub) -> None:
    d = sub.add_parser("diagnose", help="sim-to-real gap: where, which effect, how far",
                       description="Fit the base model on calibration sweeps, measure the "
                                   "held-out gap, locate it, refit with each candidate effect "
                                   "and give a verdict (schema skysim.diagnosis/3).",
                       formatter_class=DefaultsHelpFormatter)
    d.add_argument("data", type=existing_file,
                   help="measurement table or photodiode data (.csv/.parquet + sidecar), or "
                        "a raw polarization-camera frame (.tif/.tiff/.png + sidecar)")
    d.add_argument("--effects", type=name_list, help="comma-separated candidates (default: all): "
                   + ",".join(EFFECT_NAMES) + "; for multi-unit photodiode instruments: "
                   "neutral_points,fov,occlusion,yaw_scale,clock_offset,aureole,stray_light "
                   "(default); asked for by name: aerosol (its engine runs take minutes), "
                   "multiple_scattering (the base fit takes its sky up on one session), "
                   "tilt (with --pointing-from only: it turns with the units), overcast (a "
                   "cloud layer over the whole sky), side_glare (glare stronger on the side "
                   "of a unit the sun is on) and read_lag (readings lagging the yaw record); "
                   "'side_glare(scale_deg=94)' or 'stray_light(scale_deg=94)' (quoted for "
                   "the shell) holds the glare's fall-off at a value [deg] (a day's, from "
                   "other sessions); "
                   "for camera frames: lens,polarizer_angles,"
                   "extinction_ratio,sky_dop,overcast (default) and crosstalk")
    d.add_argument("--out", type=output_dir,
                   help="output folder (default: results/diagnose/<name>)")
    d.add_argument("--seed", type=seed, default=0, help="seed of the bootstrap, >= 0")
    d.add_argument("--folds", type=int_at_least(2), default=3,
                   help="held-out folds (whole sweeps), 2 .. number of sweeps")
    d.add_argument("--pointing-from", metavar="REPORTS", type=name_list,
                   help="photodiode instruments: comma-separated diagnosis.json files of other "
                        "sessions of the same instrument whose clocks are right; their fitted "
                        "unit pointing (median per unit) is held, so that a clock error is "
                        "not taken up by a common tilt of the units")
    d.add_argument("--light", choices=("sun", "moon"), default="sun",
                   help="photodiode instruments: the body whose light the session's sky "
                        "scatters; moon for a night session under the moonlit sky (the Moon "
                        "up, the Sun below -18 deg)")
    d.add_argument("--time-uncertainty", type=nonnegative_float, metavar="SECONDS",
                   help="photodiode instruments: standard uncertainty of the recorded times "
                        "[s] (default 0: a logged clock), e.g. for times reconstructed from a "
                        "start and a nominal cadence; the fitted clock's uncertainty includes "
                        "it")
    d.set_defaults(func=_diagnose_cmd)
    b = sub.add_parser("gap-benchmark", help="blind benchmark of the gap diagnosis",
                       formatter_class=DefaultsHelpFormatter)
    b.add_argument("--n", type=positive_int, default=200,
                   help="number of data sets, >= 1 (default 200; with --real: number of "
                        "sessions, default 3); about 1.5 s each")
    b.add_argument("--quick", action="store_true", help="27 data sets (3 per label)")
    b.add_argument("--seed", type=seed, default=7, help="master seed, >= 0")
    b.add_argument("--out", type=output_dir,
                   help="output folder (default: results/gap_benchmark)")
    b.add_argument("--effects", type=name_list, help="comma-separated effects to hide and to try "
                   "(default: all)")
    b.add_argument("--folds", type=int_at_least(2), default=3,
                   help="held-out folds (whole sweeps)")
    b.add_argument("--real", metavar="DIR", help="inject clock offset, yaw scale, occlusion and "
                   "a stuck photodiode into the real photodiode sessions of DIR (--n: how "
                   "many sessions, default 3) and score the diagnosis")
    b.set_defaults(func=_benchmark_cmd)
