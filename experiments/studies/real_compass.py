"""Real ring-compass sessions: the photodiode-instrument diagnosis on every session of a folder
(``skysim reproduce real-sky-compass``), its report and figures (the blind check on real
sessions with injected effects, ``skysim gap-benchmark --real DIR``, is
:mod:`experiments.workflows.real_benchmark`).

Default data: the Gkanias et al. (2023) ring-compass recordings (Sardinia, May 2022) in
``../shared/reference/gkanias2023`` beside the checkout, when present.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.io import atomic_write, write_json_atomic

from experiments.workflows.real_benchmark import session_files

__all__ = ["DEFAULT_DATA", "DEFAULT_SEED", "session_files", "session_row", "run_sessions",
           "day_parameters", "day_held_values", "day_held_check", "DAY_HELD_COLUMNS"]

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "reference" / "gkanias2023"
DEFAULT_SEED = 2023
QUICK_EFFECTS = ("yaw_scale", "occlusion")


def session_row(name: str, report) -> dict:
    """One row of the per-session table from a :class:`calibration.DiagnosisReport`."""
    v = report.verdict
    he = report.extra.get("heading_error") or {}
    best = report.candidate(v.best_candidate) if v.best_candidate else None
    sun = report.data.get("sun_elevation_deg", [np.nan, np.nan])
    clock = report.candidate("clock_offset")
    clock_p = (clock.params.get("clock_offset_s", {}) if clock is not None and clock.available
               else {})
    base_fit = report.extra.get("base_fit") or {}
    elev = [x for x in (base_fit.get("elevation_offset_deg") or {}).values() if x is not None]
    return {"session": name, "sun_elevation_deg": float(np.mean(sun)),
            "faults": len(report.faults),
            "faulty": ", ".join(f"{f['channel']}:{f['kind']}" for f in report.faults),
            "gap_base": v.gap_before, "verdict": v.effect,
            "best": v.best_candidate, "gap_best": best.gap_after if best else None,
            "shrink": best.shrink if best else None,
            "share_of_excess": v.explained_share, "share_of_excess_se": v.explained_share_se,
            "group": "+".join(v.group or []),
            "params": _params_text(best.params if best else {}),
            "heading_rms_base_deg": he.get("base_deg"), "heading_rms_best_deg": he.get("best_deg"),
            "unit_elevation_offset_deg": base_fit.get("elevation_offset_mean_deg"),
            "unit_elevation_offset_min_deg": min(elev) if elev else None,
            "unit_elevation_offset_max_deg": max(elev) if elev else None,
            "clock_offset_s": clock_p.get("value"),
            "clock_uncertainty_s": clock_p.get("uncertainty"),
            "top_where": "; ".join(f"{w.dimension}={w.label} ({100 * w.share:.0f}%)"
                                   for w in report.where[:3])}


_PER_PHOTODIODE = re.compile(r"^(\w+?)_(u\d+_p\d+)$")
"""A per-photodiode parameter: its kind (``S``, ``L``, ``R``) and photodiode (``u0_p045``)."""


def _params_text(params: dict) -> str:
    """Fitted parameters for a table cell; per-photodiode ones, per kind, as their largest
    value and the photodiode that has it."""
    kinds: dict = {}
    rest = []
    for k, p in params.items():
        m = _PER_PHOTODIODE.match(k)
        if m:
            kinds.setdefault(m.group(1), []).append((p["value"], m.group(2)))
        else:
            rest.append(f"{k}={p['value']:.4g}")
    tops = [f"max {kind}={max(v)[0]:.3g} ({max(v)[1]})" for kind, v in kinds.items()]
    return "; ".join(tops + rest)


ESTIMATED_TIMES_UNCERTAINTY_S = 120.0
"""Uncertainty [s] of per-sample times that were estimated, not logged: the Gkanias et al.
(2023) recordings carry no clock, and where no log survives their times are reconstructed
from the session's photograph and a nominal cadence, "good to about +-2 minutes at
mid-session" (the data set's README)."""


def times_uncertainty(files) -> dict:
    """Uncertainty [s] of each session's recorded times, from a ``sessions.csv`` beside the
    sessions (columns ``file`` and ``sample_times``: ``logged`` or ``estimated``):
    :data:`ESTIMATED_TIMES_UNCERTAINTY_S` for estimated times, 0 for logged ones and for
    sessions it does not list (as for a folder without one)."""
    out = {}
    for folder in {Path(f).parent for f in files}:
        index = folder / "sessions.csv"
        if not index.exists():
            continue
        table = pd.read_csv(index)
        if not {"file", "sample_times"} <= set(table.columns):
            continue
        for name, kind in zip(table["file"], table["sample_times"]):
            out[str(folder / str(name))] = (ESTIMATED_TIMES_UNCERTAINTY_S
                                            if str(kind).strip() == "estimated" else 0.0)
    return {Path(f): out.get(str(f), 0.0) for f in files}


def run_sessions(files, effects, out: Path, folds: int = 3, seed: int = DEFAULT_SEED):
    """Diagnose every session; write per-session reports, the table and the figures. The
    clock's uncertainty includes that of the recorded times (:func:`times_uncertainty`)."""
    from tqdm import tqdm

    from calibration import diagnose
    from calibration.diagnosis import DiagnosisError
    from sensor.photodiodes_io import read_photodiodes
    rows, reports = [], {}
    uncertain = times_uncertainty(files)
    for f in tqdm(files, desc="sessions", unit="session"):
        sub = out / Path(f).stem
        t0 = time.perf_counter()
        try:
            report = diagnose(read_photodiodes(f), effects, folds=folds, seed=seed,
                              time_uncertainty_s=uncertain[Path(f)], where=str(f))
        except DiagnosisError as exc:
            rows.append({"session": Path(f).name, "verdict": "error", "faulty": str(exc)})
            continue
        reports[f] = report
        sub.mkdir(parents=True, exist_ok=True)
        write_json_atomic(sub / "diagnosis.json", report.to_dict())
        rows.append(dict(session_row(Path(f).name, report), wall_s=time.perf_counter() - t0))
        if "canopy" in Path(f).name or len(files) == 1:
            plot_residual_over_azimuth(report, sub / "residual_by_sky_azimuth.png")
    table = pd.DataFrame(rows)
    atomic_write(out / "sessions.csv", lambda p: table.to_csv(p, index=False))
    atomic_write(out / "sessions.md", lambda p: p.write_text(_table_md(table)))
    plot_day(table, out / "gap_and_heading_over_day.png")
    return table, reports


CLOCK_CHECK_ERRORS_S = (7200.0, -7200.0)
"""Clock errors injected into the day's earliest and latest open-sky session [s, recorded
minus true time]: a logger 2 h fast or slow (a timezone or daylight-saving slip)."""

CLOCK_CHECK_TOLERANCE_S = 600.0
"""A clock error counts as found when the fitted offset is within 10 min of it (the sun's
azimuth moves about 2.5 deg in 10 min, the heading error a wrong clock leaves)."""


def clock_check(files, reports: dict, out: Path, effects, folds: int = 3,
                seed: int = DEFAULT_SEED) -> pd.DataFrame:
    """Inject clock errors (:data:`CLOCK_CHECK_ERRORS_S`) into the earliest and the latest
    open-sky session and diagnose them with the unit pointing calibrated on the day's other
    sessions (:func:`calibration.photodiode_diagnosis.calibrated_pointing`, leave one out).

    ``reports`` maps each session file to its diagnosis (sessions without one, or whose
    screen stopped the fit, are skipped).
    Writes ``clock_check.csv`` and returns the table: per case the verdict, the fitted clock
    offset and its uncertainty, the error against the injected one and whether it was found.
    """
    from calibration import diagnose
    from calibration.diagnosis import DiagnosisError
    from calibration.diagnosis.rings import pointing_from_reports
    from calibration.photodiode_diagnosis import PointingCalibrationError
    from sensor.photodiodes_io import PhotodiodeData, read_photodiodes

    def fitted(report) -> bool:     # a session the screen stopped (a dark sky) fitted nothing
        try:
            pointing_from_reports([report])
        except PointingCalibrationError:
            return False
        return True
    open_sky = [f for f in files if "canopy" not in Path(f).name and f in reports
                and fitted(reports[f])]
    if len(open_sky) < 3:
        return pd.DataFrame()
    rows, uncertain = [], times_uncertainty(files)
    for f in (open_sky[0], open_sky[-1]):
        pointing = pointing_from_reports([reports[g] for g in open_sky if g != f])
        data = read_photodiodes(f)
        for err in CLOCK_CHECK_ERRORS_S:
            t = data.table.copy()
            t["time"] = pd.to_datetime(t["time"]) + pd.to_timedelta(err, unit="s")
            t0 = time.perf_counter()
            row = {"session": Path(f).name, "clock_error_s": err}
            try:
                report = diagnose(PhotodiodeData(t, dict(data.sidecar)), effects, folds=folds,
                                  seed=seed, pointing=pointing,
                                  time_uncertainty_s=uncertain[Path(f)],
                                  where=f"{Path(f).name} with its clock {err:+.0f} s")
            except DiagnosisError as exc:
                rows.append(dict(row, verdict="error", note=str(exc)))
                continue
            c = report.candidate("clock_offset")
            ok = c is not None and c.available
            value = c.params.get("clock_offset_s", {}).get("value") if ok else None
            found = value is not None and abs(value + err) <= CLOCK_CHECK_TOLERANCE_S
            rows.append(dict(row, verdict=report.verdict.effect, fitted_offset_s=value,
                             uncertainty_s=c.details.get("uncertainty_s") if ok else None,
                             error_s=None if value is None else value + err,
                             named=report.verdict.effect == "clock_offset",
                             within_10_min=bool(found),
                             wall_s=time.perf_counter() - t0))
    table = pd.DataFrame(rows)
    atomic_write(out / "clock_check.csv", lambda p: table.to_csv(p, index=False))
    return table


DAY_HELD = ("side_glare", "scale_deg")
"""The instrument parameter a day's sessions are asked to share: the side glare's fall-off
(:func:`day_held_check`)."""


def day_held_values(reports: dict, effect: str = DAY_HELD[0], parameter: str = DAY_HELD[1],
                    min_share: float | None = None) -> dict:
    """For each session where ``effect`` removes at least ``min_share`` of the excess (the
    ring's ``min_share`` by default), the median of ``parameter`` over the *other* such
    sessions: the value the rest of the day predicts for it (none with fewer than three
    such sessions).

    Parameters
    ----------
    reports : dict
        Session key -> :class:`calibration.DiagnosisReport`.
    effect, parameter : str
        The candidate and its parameter (default :data:`DAY_HELD`).
    min_share : float, optional
        Least share of the excess the candidate removes in a session that counts (default:
        the ring's ``min_share``, 0.5).

    Returns
    -------
    dict
        Session key -> ``(own value, predicted value)``, in the parameter's unit.
    """
    from calibration.photodiode_diagnosis.run import RING_THRESHOLDS
    min_share = RING_THRESHOLDS.min_share if min_share is None else min_share
    own = {}
    for key, report in reports.items():
        c = report.candidate(effect)
        if (c is None or not c.available or c.not_applicable or c.explained_share is None
                or c.explained_share < min_share or parameter not in c.params):
            continue
        own[key] = float(c.params[parameter]["value"])
    if len(own) < 3:
        return {}
    return {k: (v, float(np.median([w for j, w in own.items() if j != k])))
            for k, v in own.items()}


DAY_HELD_COLUMNS = ("session", "own", "own_se", "held", "share_own", "share_own_se",
                    "share_alone", "share_alone_se", "share_held", "share_held_se",
                    "converged_held", "at_bound_held", "wall_s", "error")
"""Columns of ``day_fall_off.csv`` (:func:`day_held_check`)."""


def day_held_check(files, reports: dict, out: Path, folds: int = 3,
                   seed: int = DEFAULT_SEED) -> pd.DataFrame:
    """Whether the day's sessions can share the side glare's fall-off (an instrument
    parameter): each session where the side glare removes at least the ring's ``min_share``
    of the excess is diagnosed again with the side glare alone, once with its own fall-off
    fitted and once with it held at the median of the other such sessions
    (:func:`day_held_values`); the two shares of the excess are compared like for like (the
    same candidate set, hence the same noise floor rule).

    Parameters
    ----------
    files : list of path
        The day's session files.
    reports : dict
        Session file -> its diagnosis with every candidate (the side glare among them).
    out : Path
        Folder of ``day_fall_off.csv`` (written, with its header only when no session
        qualifies).
    folds, seed : int
        As in :func:`run_sessions`.

    Returns
    -------
    pandas.DataFrame
        Columns :data:`DAY_HELD_COLUMNS`: the fall-off [deg] fitted in the full diagnosis
        (``own``, ``own_se``) and held (``held``); the side glare's share of the excess in
        the full diagnosis (``share_own``), alone with its fall-off fitted
        (``share_alone``) and alone with it held (``share_held``), each with its SE.
    """
    from calibration import diagnose
    from calibration.diagnosis import DiagnosisError
    from sensor.photodiodes_io import read_photodiodes
    effect, parameter = DAY_HELD
    predicted = day_held_values(reports)
    uncertain = times_uncertainty(files)
    rows = []
    for f in files:
        if f not in predicted:
            continue
        mine, held = predicted[f]
        full = reports[f].candidate(effect)
        row = {"session": Path(f).name, "own": mine,
               "own_se": full.params[parameter].get("uncertainty"), "held": held,
               "share_own": full.explained_share, "share_own_se": full.explained_share_se}
        t0 = time.perf_counter()
        data = read_photodiodes(f)
        try:
            for tag, name in (("alone", effect), ("held", f"{effect}({parameter}={held:.6g})")):
                c = diagnose(data, (name,), folds=folds, seed=seed,
                             time_uncertainty_s=uncertain[Path(f)],
                             where=f"{Path(f).name}, {name} alone").candidate(effect)
                row.update({f"share_{tag}": c.explained_share,
                            f"share_{tag}_se": c.explained_share_se})
        except DiagnosisError as exc:
            rows.append(dict(row, error=str(exc)))
            continue
        rows.append(dict(row, converged_held=c.converged, at_bound_held=",".join(c.at_bound or []),
                         wall_s=time.perf_counter() - t0))
    table = pd.DataFrame(rows, columns=list(DAY_HELD_COLUMNS))
    atomic_write(out / "day_fall_off.csv", lambda p: table.to_csv(p, index=False))
    return table


SESSION_COLUMNS = ("session", "sun_elevation_deg", "faults", "gap_base", "verdict", "group",
                   "best", "gap_best", "shrink", "share_of_excess", "share_of_excess_se",
                   "params", "heading_rms_base_deg",
                   "heading_rms_best_deg", "unit_elevation_offset_deg")


def day_parameters(reports: dict) -> pd.DataFrame:
    """The day's shared parameters (:func:`calibration.diagnosis.shared_parameters.shared_parameters`)
    twice: over every session that fitted a candidate (``sessions_used = "all"``) and over
    those where it removes at least the share of the excess a named effect must
    (``"explaining"``, the ring's ``min_share``), where its parameters describe the effect
    the data hold."""
    from calibration.diagnosis.shared_parameters import shared_parameters
    from calibration.photodiode_diagnosis.run import RING_THRESHOLDS
    parts = [shared_parameters(reports).assign(sessions_used="all"),
             shared_parameters(reports, min_share=RING_THRESHOLDS.min_share
                               ).assign(sessions_used="explaining")]
    columns = ["sessions_used"] + list(shared_parameters({}).columns)
    parts = [t for t in parts if len(t)]
    if not parts:
        return pd.DataFrame(columns=columns)
    return pd.concat(parts, ignore_index=True)[columns]


def _table_md(table: pd.DataFrame, columns=SESSION_COLUMNS) -> str:
    cols = [c for c in columns if c in table.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, r in table.iterrows():
        cells = []
        for c in cols:
            x = r.get(c)
            cells.append(f"{x:.4g}" if isinstance(x, float) and np.isfinite(x) else
                         ("" if x is None or (isinstance(x, float) and not np.isfinite(x))
                          else str(x)))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_day(table: pd.DataFrame, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    t = table.dropna(subset=["gap_base"]) if "gap_base" in table else table.iloc[:0]
    fig, ax = plt.subplots(1, 3, figsize=(14, 4), constrained_layout=True)
    if len(t):
        x = t["sun_elevation_deg"]
        ax[0].plot(x, 100 * t["gap_base"], "o", label="base model")
        ax[0].plot(x, 100 * t["gap_best"].astype(float), "s", label="best candidate")
        ax[1].plot(x, t["heading_rms_base_deg"].astype(float), "o", label="base model")
        ax[1].plot(x, t["heading_rms_best_deg"].astype(float), "s", label="best candidate")
        if "unit_elevation_offset_deg" in t:
            ax[2].plot(x, t["unit_elevation_offset_deg"].astype(float), "o",
                       label="base model, mean over units")
    ax[0].set_xlabel("sun elevation [deg]")
    ax[0].set_ylabel("held-out gap [% of unit mean reading]")
    ax[1].set_xlabel("sun elevation [deg]")
    ax[1].set_ylabel("heading error, RMS [deg]")
    ax[2].axhline(0.0, color="0.5", lw=0.8)
    ax[2].set_xlabel("sun elevation [deg]")
    ax[2].set_ylabel("fitted unit elevation offset [deg]")
    ax[2].set_title("a mounting error would not follow the sun", fontsize=9)
    for a in ax:
        a.legend()
        a.grid(alpha=0.3)
    fig.suptitle("Ring compass over the day: held-out gap, heading error and fitted pointing")
    atomic_write(path, lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)


def plot_residual_over_azimuth(report, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = sorted((w for w in report.where if w.dimension == "sky_azimuth_deg"),
                  key=lambda w: w.lo)
    fig, ax = plt.subplots(figsize=(6, 3.5), constrained_layout=True)
    if rows:
        ax.bar([0.5 * (w.lo + w.hi) for w in rows], [100 * w.rms for w in rows],
               width=28)
    ax.set_xlabel("sky azimuth of the unit's view [deg, clockwise from north]")
    ax.set_ylabel("held-out residual RMS [%]")
    ax.set_title("Base-model residual over sky azimuth")
    atomic_write(path, lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)


# --------------------------------------------------------------------------- command line
def _reproduce(args) -> int:
    from calibration.diagnosis.shared_parameters import AGREEMENT_P
    from calibration.photodiode_diagnosis import RING_EFFECT_NAMES
    from calibration.photodiode_diagnosis.effects import OPTIONAL_EFFECT_NAMES
    folder = Path(getattr(args, "data", None) or DEFAULT_DATA)
    files = session_files(folder)
    # the day is where the aerosol sky is weighed against the real DoP profile
    effects = RING_EFFECT_NAMES + OPTIONAL_EFFECT_NAMES
    if args.quick:
        files, effects = files[:1], QUICK_EFFECTS
    out = Path(args.out or "results/real_sky_compass")
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    table, reports = run_sessions(files, effects, out, seed=args.seed)
    elapsed = time.perf_counter() - t0
    shared = day_parameters({Path(f).name: r for f, r in reports.items()})
    atomic_write(out / "shared_parameters.csv", lambda p: shared.to_csv(p, index=False))
    clocks = clock_check(files, reports, out, RING_EFFECT_NAMES, seed=args.seed)
    t1 = time.perf_counter()
    day = day_held_check(files, reports, out, seed=args.seed) if not args.quick else pd.DataFrame()
    write_json_atomic(out / "summary.json", {
        "sessions": len(table), "effects": list(effects), "data": str(folder),
        "seed": args.seed, "elapsed_s": elapsed, "rows": table.to_dict(orient="records"),
        "clock_check": clocks.to_dict(orient="records"),
        "shared_parameters": shared.to_dict(orient="records"),
        "clock_check_s": t1 - t0 - elapsed, "day_fall_off": day.to_dict(orient="records"),
        "day_fall_off_s": time.perf_counter() - t1})
    print(_table_md(table))
    print(f"wall time {elapsed:.0f} s for {len(table)} sessions")
    if len(shared):
        print("parameters fitted on two or more sessions, combined over the day (weighted "
              "mean, its SE, the between-session SD beyond the sessions' own SEs, "
              f"whether the sessions agree: Cochran's Q, p >= {AGREEMENT_P}, and whether "
              "they drift with the sun's elevation: Spearman's rho, p < "
              f"{AGREEMENT_P}), over every session that fitted the candidate and over "
              "those where it removes half the excess or more:")
        print(_table_md(shared, tuple(shared.columns)))
    if len(clocks):
        print("clock errors injected into the first and last open-sky session, unit pointing "
              "held at the other sessions' (median):")
        print(_table_md(clocks, tuple(clocks.columns)))
        print(f"wall time of the clock check {t1 - t0 - elapsed:.0f} s")
    if len(day):
        print("the side glare's fall-off [deg] of each session where it removes half the "
              "excess or more, held at the median of the other such sessions: its share of "
              "the excess in the full diagnosis, alone with its own fall-off and alone with "
              "the held one")
        print(_table_md(day, tuple(day.columns)))
    print(f"wrote {out}/sessions.csv, sessions.md, summary.json, shared_parameters.csv, "
          f"gap_and_heading_over_day.png"
          f"{', clock_check.csv' if len(clocks) else ''}"
          f"{', day_fall_off.csv' if not args.quick else ''} and one diagnosis.json per "
          "session")
    return 0


_reproduce.takes_data = True


def register_reproduce(targets: dict) -> None:
    targets["real-sky-compass"] = _reproduce
