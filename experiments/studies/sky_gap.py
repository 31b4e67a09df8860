"""Sky-level gap on the Natraj et al. (2009) tables: ``skysim sky-gap``.

For each atmosphere of the shared subset (tau in {0.02, 0.1, 0.25, 1.0}, ground albedo in
{0, 0.25}; transmitted field, view cosines >= 0.1 as in ``skysim physical-sky``) the cases are
the seven suns (mu0 = 0.1 ... 1.0). :func:`calibration.diagnosis.sky.diagnose_sky` fits on the suns
mu0 = 0.2 and 0.8 and reports on the five withheld ones: where single scattering with a fitted
d_max misses the tables, which candidate (``multiple_scattering``, ``ground_albedo``) explains
it, and how far the withheld gap shrinks. The tables are exact; the noise floor is the
reproducibility of the tables by the engine (``NOISE_FLOOR``).

Writes to ``results/sky-gap/`` (or ``--out``): ``diagnosis_tau<t>_A<a>.json`` (schema
"skysim.diagnosis/3", ``instrument: sky``) per atmosphere, ``summary.csv``, ``summary.json``,
``report.md``, ``gap_by_slice.png`` (withheld gap per slice before/after) and
``residual_maps.png`` (withheld residual |(dq, du)| over the sky, before/after, mu0 = 0.4).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.io import atomic_write, write_json_atomic
from skysim.natraj import natraj_path, read_natraj

from experiments.plotting.figures import save_png
from experiments.workflows.options import output_dir

__all__ = ["CALIBRATION_MU0", "NOISE_FLOOR", "cases_from_natraj", "register",
           "register_reproduce", "run"]

CALIBRATION_MU0 = (0.2, 0.8)
NOISE_FLOOR = 2e-3
"""[DoLP units] The engine reproduces the tables to 2e-3 in DoLP and I/I at worst
(``skysim physical-sky``, ``docs/physical_sky.md``): a perfect model cannot look better."""
QUICK_CONFIGS = ((0.25, 0.0), (0.25, 0.25))
MAP_MU0 = 0.4


def natraj_table(reference: Path | None = None, min_mu: float = 0.1) -> pd.DataFrame:
    """The Natraj 2009 transmitted rows from ``reference`` (a table file or a folder holding
    one, :func:`skysim.natraj.natraj_path`), by default the rows shipped with skysim
    (:func:`skysim.natraj.read_natraj`)."""
    return read_natraj(natraj_path(reference), min_mu)


def cases_from_natraj(rows: pd.DataFrame):
    """:class:`SkyCases` for one atmosphere, one case per mu0 (case id = index of mu0).

    Conventions (``docs/conventions.md``, the table's README): view elevation ``asin(mu)``,
    view azimuth ``phi`` with the sun at azimuth 0; ``Q_skysim = -Q_table``, ``U = U_table``.
    """
    from calibration.diagnosis.sky import SkyCases
    mu0s = np.sort(rows.mu0.unique())
    case = np.searchsorted(mu0s, rows.mu0.to_numpy())
    el = np.degrees(np.arcsin(rows.mu.to_numpy()))
    sun = np.degrees(np.arcsin(rows.mu0.to_numpy()))
    I = rows.I.to_numpy()
    return SkyCases(case, el, rows.phi.to_numpy(), sun, np.zeros_like(sun),
                    -rows.Q.to_numpy() / I, rows.U.to_numpy() / I,
                    {k: {"mu0": float(m)} for k, m in enumerate(mu0s)}), mu0s


def _residuals(c, effect, params, settings):
    from calibration.diagnosis.sky import predict_qu
    q, u = predict_qu(c, effect, params, settings)
    return np.hypot(q - c.q, u - c.u)


def _words(name: str) -> str:
    """An effect or verdict name as words for a figure (``ground_albedo`` -> ground albedo)."""
    return str(name).replace("_", " ")


def _case_words(key: str) -> str:
    """``tau0.25_A0`` -> ``tau = 0.25, ground albedo 0``."""
    import re
    m = re.fullmatch(r"tau([\d.]+)_A([\d.]+)", key)
    return f"tau = {m[1]}, ground albedo {m[2]}" if m else key


def _figures(out: Path, docs: dict, maps: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dims = ["sun_distance_deg", "view_zenith_deg", "horizon", "neutral_points"]
    n = len(docs)
    fig, axes = plt.subplots(n, 1, figsize=(12, 3.6 * n), squeeze=False,
                             layout="constrained")
    for ax, (key, d) in zip(axes[:, 0], docs.items()):
        names, before, after = [], [], []
        for dim in dims:
            after_of = {s.label: s.rms for s in d.where_after if s.dimension == dim}
            rows = sorted((s for s in d.where if s.dimension == dim),
                          key=lambda s: (s.lo if s.lo is not None else 0.0, s.label))
            for b in rows:
                names.append(f"{b.label} deg from the sun" if dim == "sun_distance_deg" else
                             f"view zenith {b.label} deg" if dim == "view_zenith_deg" else
                             b.label)
                before.append(b.rms)
                after.append(after_of.get(b.label, np.nan))
        x = np.arange(len(names))
        ax.bar(x - 0.2, before, 0.4, label="single scattering, fitted d_max")
        ax.bar(x + 0.2, after, 0.4,
               label=f"after fitting {_words(d.verdict.best_candidate)}")
        ax.axhline(d.noise_floor, color="k", ls="--", lw=0.8,
                   label="noise floor (engine vs tables)")
        ax.set_yscale("log")
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=25, ha="right", fontsize=8)
        ax.set_ylabel("withheld RMS |(dq, du)|", fontsize=9)
        ax.set_title(f"{_case_words(key)}: verdict {_words(d.verdict.effect)}",
                     fontsize=10)
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.005, 1.0))
    save_png(fig, out / "gap_by_slice.png")

    fig, axes = plt.subplots(len(maps), 2, figsize=(8.5, 3.8 * len(maps)), squeeze=False,
                             subplot_kw={"projection": "polar"}, layout="constrained")
    for row, (key, (c, before, after, best)) in zip(axes, maps.items()):
        vmax = float(np.max(before))
        for ax, r, title in [(row[0], before, "single scattering, fitted d_max"),
                             (row[1], after, f"after fitting {_words(best)}")]:
            sc = ax.scatter(np.radians(c.view_azimuth_deg), 90.0 - c.view_elevation_deg, c=r,
                            s=14, cmap="magma", vmin=0, vmax=vmax)
            ax.set_theta_zero_location("N")
            ax.set_theta_direction(-1)
            ax.set_ylim(0, 90)
            ax.set_yticks([30, 60, 90])
            ax.set_yticklabels(["30", "60", "90 deg"], fontsize=7)
            ax.set_rlabel_position(157.5)   # zenith-angle labels where the grid has no data
            ax.tick_params(axis="x", labelsize=7)
            ax.set_title(f"{_case_words(key)}, mu0 = {MAP_MU0}\n{title}", fontsize=8)
        fig.colorbar(sc, ax=row.tolist(), fraction=0.04, pad=0.06,
                     label="withheld residual |(dq, du)|")
    fig.suptitle("Residual of the normalised Stokes vector over the withheld sky (sun at "
                 "azimuth 0; radius: view zenith angle)", fontsize=9)
    save_png(fig, out / "residual_maps.png")


def _report(summary: pd.DataFrame, docs: dict, meta: dict) -> str:
    lines = ["# Sky-level gap on Natraj et al. (2009)", "",
             (f"Fitted on mu0 = {', '.join(f'{m:g}' for m in CALIBRATION_MU0)}; scored on "
              f"the other suns. Noise floor {NOISE_FLOOR:g} (engine vs tables). Engine "
              f"{meta['engine_settings']}. {meta['elapsed_s']:.0f} s."), "",
             "| tau | albedo | verdict | d_max | gap before | gap after | shrink | fitted |",
             "|---|---|---|---|---|---|---|---|"]
    for r in summary.itertuples():
        lines.append(f"| {r.tau:g} | {r.albedo:g} | {r.verdict} | {r.d_max:.3f} | "
                     f"{r.gap_before:.4f} | {r.gap_after:.4f} | {r.shrink:.3f} | {r.fitted} |")
    lines += ["", "## Where (withheld cases, single scattering with fitted d_max)", ""]
    for key, d in docs.items():
        top = d.carrying_gap()[:4]
        lines.append(f"- **{key}**: " + "; ".join(
            f"{s.dimension} {s.label} (rms {s.rms:.4f}, {100 * s.share:.0f} % of the excess "
            f"squared gap)" for s in top) if top else f"- **{key}**: no slice above floor")
    lines += ["", "Figures: `gap_by_slice.png`, `residual_maps.png`."]
    return "\n".join(lines) + "\n"


def run(out: Path, reference: Path | None = None, quick: bool = False) -> dict:
    """Diagnose every atmosphere of the subset (two with ``quick``); write the outputs."""
    from calibration.diagnosis.sky import diagnose_sky
    from skysim.rt_sasktran import EngineSettings

    t0 = time.perf_counter()
    out = Path(out)
    settings = EngineSettings(n_streams=16)  # 16 streams: as accurate as 40 here (tables README)
    table = natraj_table(reference)
    from tqdm import tqdm
    rows, docs, maps = [], {}, {}
    groups = [(k, g) for k, g in table.groupby(["tau", "albedo"])
              if not quick or k in QUICK_CONFIGS]
    for (tau, albedo), g in tqdm(groups, desc="sky-gap", unit="atmosphere"):
        c, mu0s = cases_from_natraj(g)
        cal = [int(k) for k, m in enumerate(mu0s) if np.any(np.isclose(m, CALIBRATION_MU0))]
        d = diagnose_sky(c, cal, noise_floor=NOISE_FLOOR, settings=settings,
                         n_grid=5 if quick else 6, xatol=0.02 if quick else 0.01)
        d.data["source"] = {"reference": "Natraj et al. (2009) subset", "tau": tau,
                            "albedo": albedo, "field": "transmitted", "min_mu": 0.1}
        key = f"tau{tau:g}_A{albedo:g}"
        docs[key] = d
        write_json_atomic(out / f"diagnosis_{key}.json", d.to_dict())
        v = d.verdict
        values = {k: p["value"] for k, p in v.params.items()}
        dm = {k: p["value"] for k, p in d.candidate("d_max").params.items()}
        seconds = d.extra["seconds"]
        rows.append({"tau": tau, "albedo": albedo, "verdict": v.effect, "d_max": dm["d_max"],
                     "gap_before": v.gap_before, "gap_after": v.gap_after,
                     "shrink": v.shrink,
                     "fitted": ", ".join(f"{k} {x:.4g}" for k, x in values.items()),
                     "fit_tau": values.get("tau", np.nan),
                     "fit_albedo": values.get("albedo", np.nan),
                     "seconds": seconds})
        k04 = int(np.argmin(np.abs(mu0s - MAP_MU0)))
        cm = c.subset([k04])
        maps[key] = (cm, _residuals(cm, "d_max", dm, settings),
                     _residuals(cm, v.best_candidate, values, settings), v.best_candidate)
        print(f"  tau {tau:g} albedo {albedo:g}: {v.effect} gap {v.gap_before:.4f} -> "
              f"{v.gap_after:.4f} ({seconds:.0f} s)", flush=True)
    summary = pd.DataFrame(rows)
    meta = {"schema": "skysim.skygap-summary/1", "quick": quick,
            "calibration_mu0": list(CALIBRATION_MU0), "noise_floor": NOISE_FLOOR,
            "engine_settings": settings.to_dict(), "elapsed_s": time.perf_counter() - t0,
            "reference": str(natraj_path(reference)),
            "rows": summary.to_dict(orient="records")}
    _figures(out, docs, maps)
    atomic_write(out / "summary.csv", lambda p: summary.to_csv(p, index=False))
    write_json_atomic(out / "summary.json", meta)
    atomic_write(out / "report.md", lambda p: Path(p).write_text(_report(summary, docs, meta)))
    return {"summary": summary, "docs": docs, "meta": meta}


def _main(args) -> int:
    out = Path(args.out or "results/sky-gap")
    result = run(out, reference=args.reference, quick=args.quick)
    pd.set_option("display.width", 160)
    cols = ["tau", "albedo", "verdict", "d_max", "gap_before", "gap_after", "shrink", "fitted"]
    print(result["summary"][cols].to_string(index=False, float_format=lambda x: f"{x:.4f}"))
    print(f"wrote {out}/ in {result['meta']['elapsed_s']:.0f} s")
    return 0


def _reproduce(a) -> int:
    return _main(argparse.Namespace(
        out=a.out, reference=getattr(a, "reference", None),
        quick=bool(getattr(a, "quick", False)) or (a.trials is not None and a.trials < 10)))


_reproduce.takes_reference = True


def register_reproduce(targets: dict) -> None:
    targets["sky-gap"] = _reproduce


def register(sub) -> None:
    p = sub.add_parser("sky-gap", help="sky-level gap: single scattering vs the Natraj tables, "
                       "which effect explains it, on withheld suns")
    p.add_argument("--reference", default=None,
                   help="another copy of the Natraj et al. (2009) tables: the file, or a folder "
                        "holding it (default: the tables shipped with skysim)")
    p.add_argument("--out", type=output_dir, default=None,
                   help="output folder (default: results/sky-gap)")
    p.add_argument("--quick", action="store_true", help="two atmospheres, coarser tau search")
    p.set_defaults(func=_main)
