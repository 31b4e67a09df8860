"""Compound-eye installation-error calibration (Guo, Liu, Yang & Wang, BUAA patent, 2020).

``skysim reproduce compound-eye``: per Monte-Carlo trial, a patent-layout sensor (zenith unit
plus eight units at 60 deg elevation, three opponent pairs = six photodiodes each) gets random
installation errors, U(-1, 1) deg per axis, for the sensor-to-body rotation phi_1 and for each
tilted unit phi_i. A carrier is moved through random attitudes (yaw U(0, 360), pitch and roll
U(-10, 10) deg) over a clear-sky afternoon in Beijing; a navigation module records the attitude
with 0.1 deg noise, an accelerometer the specific force with 0.01 m/s^2 noise (~0.06 deg of
tilt). The three calibration steps recover phi_1 and phi_i; on held-out attitudes of the same
afternoon the carrier attitude is then computed from the sky and gravity alone with the
nominal (uncompensated), the calibrated and the true installation.

Outputs in ``results/compound-eye/``: ``installation_errors.csv`` (every injected and
recovered angle with its 1-sigma), ``attitude_errors.csv``, ``table.md``, ``summary.json``,
one example data set ``calibration_data.parquet`` (+ sidecar, schema skysim.photodiodes/1),
and figures.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.geometry import wrap_deg
from skysim.io import atomic_write, write_json_atomic

from experiments.plotting.figures import pyplot, save_png
from skysim.sun import Site

__all__ = ["SITE", "SCENARIO", "Scenario", "run", "format_table", "register_reproduce"]

SITE = Site(39.98, 116.35, 50.0, name="Beihang University, Beijing")
MEMORY_PER_TRIAL_BYTES = 60_000
"""Peak memory per trial [bytes]: 28 kB measured with tracemalloc (5 vs 25 trials; the
per-trial result rows), doubled; ``skysim reproduce`` refuses --trials that would not fit."""
"""The patent's institution (the patent gives no site; the method does not depend on it)."""


@dataclass(frozen=True)
class Scenario:
    """Experiment parameters (none tuned to the result).

    max_error_deg : injected installation errors, U(-max, max) per axis ("up to ~1 deg").
    start, end : the afternoon (UTC+8); the sun is 60 -> 10 deg high, so the zenith unit is
        polarized enough (DoP > 0.05 needs the sun below ~70 deg).
    n_calibration, n_test : carrier attitudes for the calibration and for the held-out check.
    tilt_deg : pitch and roll U(-tilt, tilt) deg (a vehicle or hand-held carrier).
    attitude_noise_deg : reference attitude and heading accuracy, 0.1 deg (the patent's).
    accel_noise_mps2 : accelerometer noise per axis (a navigation-grade MEMS at rest).
    dmax : maximum DoP of the clear sky (real clear skies: 0.6-0.8).
    """

    max_error_deg: float = 1.0
    start: str = "2020-06-15T14:30:00+08:00"
    end: str = "2020-06-15T18:30:00+08:00"
    n_calibration: int = 300
    n_test: int = 300
    tilt_deg: float = 10.0
    attitude_noise_deg: float = 0.1
    accel_noise_mps2: float = 0.01
    dmax: float = 0.7


SCENARIO = Scenario()


def _carrier(n, rng, sc: Scenario):
    times = pd.date_range(sc.start, sc.end, periods=n)
    yaw = rng.uniform(0.0, 360.0, n)
    pitch, roll = rng.uniform(-sc.tilt_deg, sc.tilt_deg, (2, n))
    return times, yaw, pitch, roll


def _attitude_errors(data, sensors: dict) -> dict:
    """RMS heading, pitch, roll and total attitude error [deg] per sensor model."""
    from calibration.installation import attitude_from_data
    from sensor.compound_eye import attitude_angles, body_attitude

    t = data.table
    truth = body_attitude(t["true_yaw_deg"], t["true_pitch_deg"], t["true_roll_deg"])
    out = {}
    for name, sensor in sensors.items():
        att, _ = attitude_from_data(data, sensor)
        yaw, pitch, roll = attitude_angles(att)
        rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
        out[name] = {"heading_rms_deg": rms(wrap_deg(yaw - t["true_yaw_deg"])),
                     "pitch_rms_deg": rms(pitch - t["true_pitch_deg"]),
                     "roll_rms_deg": rms(roll - t["true_roll_deg"]),
                     "attitude_rms_deg": rms(np.degrees((att * truth.inv()).magnitude()))}
    return out


def run(trials: int = 50, seed: int = 2020, out=None, scenario: Scenario = SCENARIO,
        figures: bool = True, progress: bool = True) -> dict:
    """Monte-Carlo calibration trials; returns tables and a summary, writes them to ``out``."""
    from tqdm import tqdm

    from calibration.installation import calibrate_installation
    from sensor.compound_eye import (
        patent_configuration,
        with_random_installation_errors,
    )
    from skysim.sky import RayleighSky

    t0 = time.perf_counter()
    sky = RayleighSky(scenario.dmax)
    rows, att_rows, example = [], [], None
    kw = dict(attitude_noise_deg=scenario.attitude_noise_deg,
              accel_noise_mps2=scenario.accel_noise_mps2)
    for k, child in enumerate(tqdm(np.random.SeedSequence(seed).spawn(trials), disable=not progress,
                                   desc="compound-eye trials", unit="trial")):
        rng = np.random.default_rng(child)
        sensor = with_random_installation_errors(patent_configuration(), scenario.max_error_deg,
                                                 rng)
        cal_data = sensor.sample(sky, SITE, *_carrier(scenario.n_calibration, rng, scenario), rng,
                                 seed=seed, **kw)
        cal = calibrate_installation(cal_data)
        truth = [sensor.installation_error_deg] + [u.installation_error_deg
                                                   for u in sensor.units[1:]]
        for est, inj in zip([cal.body] + cal.units, truth):
            for a, axis in enumerate("xyz"):
                rows.append({"trial": k, "rotation": "phi_1 (sensor-body)" if est.frame == "sensor"
                             else f"phi_{int(est.frame.split()[1]) + 1} ({est.frame})",
                             "kind": "body" if est.frame == "sensor" else "unit", "axis": axis,
                             "injected_deg": float(inj[a]), "estimated_deg": est.rotvec_deg[a],
                             "std_deg": est.std_deg[a],
                             "error_deg": est.rotvec_deg[a] - float(inj[a])})
        test = sensor.sample(sky, SITE, *_carrier(scenario.n_test, rng, scenario), rng, **kw)
        errs = _attitude_errors(test, {"uncompensated": sensor.nominal(),
                                       "compensated": cal.sensor, "true installation": sensor})
        att_rows += [{"trial": k, "sensor": name, **v} for name, v in errs.items()]
        if k == 0:
            example = {"cal_data": cal_data, "test": test, "sensor": sensor, "cal": cal}
    est = pd.DataFrame(rows)
    att = pd.DataFrame(att_rows)
    table = _table(est, att)
    summary = _summary(est, att, trials, seed, scenario, time.perf_counter() - t0)
    result = {"installation": est, "attitude": att, "table": table, "summary": summary,
              "example": example}
    if out is not None:
        _write(Path(out), result, figures)
    return result


def _table(est: pd.DataFrame, att: pd.DataFrame) -> pd.DataFrame:
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    rows = []
    for kind, label in (("body", "phi_1 sensor-to-body"), ("unit", "phi_2..9 units")):
        sub = est[est.kind == kind]
        for axis in "xyz":
            s = sub[sub.axis == axis]
            rows.append({"quantity": f"{label}, axis {axis}", "goal_deg": 0.05,
                         "rms_error_deg": rms(s.error_deg), "mean_reported_std_deg":
                         float(s.std_deg.mean()), "rms_injected_deg": rms(s.injected_deg)})
    for name in ("uncompensated", "compensated", "true installation"):
        s = att[att.sensor == name]
        for q in ("heading", "attitude"):
            rows.append({"quantity": f"{q} error, {name}", "goal_deg": np.nan,
                         "rms_error_deg": rms(s[f"{q}_rms_deg"]), "mean_reported_std_deg": np.nan,
                         "rms_injected_deg": np.nan})
    return pd.DataFrame(rows)


def _summary(est, att, trials, seed, scenario, elapsed) -> dict:
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    per_axis = {f"{kind}_{axis}": rms(est[(est.kind == kind) & (est.axis == axis)].error_deg)
                for kind in ("body", "unit") for axis in "xyz"}
    z = est.error_deg / est.std_deg
    heading = {n: rms(att[att.sensor == n].heading_rms_deg) for n in att.sensor.unique()}
    return {"source": "Guo, Liu, Yang & Wang (BUAA), patent 'A method of multi-direction "
                      "calibration for polarization sensor imitating compound eye' (2020)",
            "trials": trials, "seed": seed, "scenario": asdict(scenario), "site": SITE.to_dict(),
            "rms_error_per_axis_deg": per_axis, "goal_deg": 0.05,
            "goal_met": bool(max(per_axis.values()) <= 0.05),
            "normalised_error_rms": rms(z), "heading_rms_deg": heading,
            "elapsed_s": elapsed}


def format_table(table: pd.DataFrame) -> str:
    """Plain-text table for the terminal and ``table.md``."""
    lines = ["| quantity | RMS error [deg] | mean reported 1σ [deg] | RMS injected [deg] | goal |",
             "|---|---|---|---|---|"]
    f = lambda v: "" if not np.isfinite(v) else f"{v:.4f}"  # noqa: E731
    for r in table.itertuples():
        goal = "" if not np.isfinite(r.goal_deg) else f"≤ {r.goal_deg:g}"
        lines.append(f"| {r.quantity} | {f(r.rms_error_deg)} | {f(r.mean_reported_std_deg)} | "
                     f"{f(r.rms_injected_deg)} | {goal} |")
    return "\n".join(lines)


def _write(out: Path, result: dict, figures: bool) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for name, df in (("installation_errors.csv", result["installation"]),
                     ("attitude_errors.csv", result["attitude"])):
        atomic_write(out / name, lambda tmp, df=df: df.to_csv(tmp, index=False))
    text = format_table(result["table"]) + "\n"
    atomic_write(out / "table.md", lambda tmp: tmp.write_text(text))
    write_json_atomic(out / "summary.json", result["summary"])
    ex = result["example"]
    if ex is not None:
        ex["cal_data"].write(out / "calibration_data.parquet")
        write_json_atomic(out / "example_calibration.json", ex["cal"].to_dict())
    if figures:
        plot_recovery(result["installation"], out / "fig_recovered_vs_injected.png")
        if ex is not None:
            plot_heading_errors(ex, out / "fig_heading_error_vs_yaw.png")


def plot_recovery(est: pd.DataFrame, path: Path) -> None:
    """Recovery error vs injected angle, per axis, with the 0.05 deg goal band."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.6), sharey=True)
    for ax, axis in zip(axes, "xyz"):
        for kind, marker, label in (("unit", ".", "units φ2..φ9"),
                                    ("body", "o", "φ1 sensor-body")):
            s = est[(est.axis == axis) & (est.kind == kind)]
            ax.errorbar(s.injected_deg, s.error_deg, yerr=s.std_deg, fmt=marker, ms=3, lw=0.5,
                        alpha=0.7, label=label)
        ax.axhspan(-0.05, 0.05, color="0.9", zorder=0, label="goal ±0.05°")
        ax.set(xlabel=f"injected, axis {axis} [deg]", title=f"axis {axis}")
    axes[0].set_ylabel("recovered − injected [deg] (bars: 1σ)")
    axes[0].legend(fontsize=7)
    fig.suptitle("Compound-eye installation errors: recovery from a 0.1° reference")
    fig.tight_layout()
    save_png(fig, path, dpi=120)


def plot_heading_errors(ex: dict, path: Path) -> None:
    """Heading error vs true yaw of the held-out attitudes (first trial)."""
    from calibration.installation import attitude_from_data
    from sensor.compound_eye import attitude_angles

    plt = pyplot()
    t = ex["test"].table
    fig, ax = plt.subplots(figsize=(6.4, 4))
    for name, sensor in (("uncompensated", ex["sensor"].nominal()),
                         ("compensated", ex["cal"].sensor)):
        yaw = attitude_angles(attitude_from_data(ex["test"], sensor)[0])[0]
        err = wrap_deg(yaw - t["true_yaw_deg"])
        ax.plot(t["true_yaw_deg"], err, ".", ms=3,
                label=f"{name} (RMS {np.sqrt(np.mean(err ** 2)):.3f}°)")
    ax.axhline(0, color="k", lw=0.5)
    ax.set(xlabel="true heading [deg]", ylabel="heading error [deg]",
           title="Heading from sky + gravity, held-out attitudes (trial 0)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_png(fig, path, dpi=120)


def _reproduce(args) -> int:
    trials = args.trials or (10 if getattr(args, "quick", False) else 50)
    out = Path(args.out or "results/compound-eye")
    result = run(trials=trials, seed=args.seed, out=out)
    s = result["summary"]
    print(f"Compound-eye installation calibration — {trials} trials, seed {args.seed}, "
          f"{SCENARIO.n_calibration} attitudes, reference {SCENARIO.attitude_noise_deg} deg")
    print(format_table(result["table"]))
    worst = max(s["rms_error_per_axis_deg"].values())
    verdict = "met" if s["goal_met"] else "NOT met"
    print(f"worst per-axis RMS {worst:.4f} deg (goal ≤ 0.05: {verdict});"
          f" normalised error RMS {s['normalised_error_rms']:.2f} (1 = honest 1σ); "
          f"{s['elapsed_s']:.1f} s")
    print(f"wrote {out}/table.md, installation_errors.csv, attitude_errors.csv, summary.json, "
          "calibration_data.parquet, figures")
    return 0


def register_reproduce(targets: dict) -> None:
    targets["compound-eye"] = _reproduce
