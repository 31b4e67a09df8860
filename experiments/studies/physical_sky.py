"""Physically based sky: validation, neutral points, Berry model, zenith DoP.

``skysim reproduce physical-sky`` (or ``skysim physical-sky [--quick]``) writes to
``results/physical-sky/``:

- ``validation.csv``: per shared case of Natraj et al. (2009) (transmitted field, view cosines
  >= 0.1) the max |dI/I|, |dDoLP|, |dQ/I|, |dU/I| of :class:`skysim.multiple.MultipleScatteringSky`
  (Fourier modes + spline, as every user gets it); ``validation_points.csv`` every point;
  ``validation_hist.png`` the distribution;
- ``neutral_points.csv`` and ``neutral_points.png``: Arago, Babinet, Brewster distances vs sun
  elevation (multiple scattering) and the Berry et al. (2004) model with delta fitted to them;
- ``polar_maps.png``: DoP, AoP and I of the multiple-scattering sky with the neutral points
  marked, beside the Berry and Rayleigh AoP;
- ``zenith_dop.csv`` and ``zenith_dop.png``: zenith DoP vs sun elevation for single
  scattering, multiple scattering (black ground and albedo 0.25) and Berry, with the tables'
  numbers (0.72, 0.63, 0.53 at mu0 = 0.4);
- ``aerosol_*.csv`` and ``.png``: aerosol skies beside the molecular one
  (:mod:`experiments.studies.aerosol_sky`: principal-plane DoP, neutral points and maximum DoP vs
  AOD, with Kreuter et al. 2010);
- ``summary.json``.

Nothing is fitted to the tables: the engine set-up is fixed by convergence studies
(``docs/physical_sky.md``); Berry's delta is set from the multiple-scattering neutral points.

The tables ship with skysim (:mod:`skysim.natraj`, ``skysim/data/natraj2009/``: the
transmitted rows of the subset, view cosines >= 0.1, with the script that builds them);
``--reference`` reads another copy of the tables.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.io import atomic_write, write_json_atomic
from skysim.natraj import NATRAJ_FILE, natraj_path, read_natraj

from experiments.plotting.figures import save_png
from experiments.workflows.options import output_dir

__all__ = [
    "neutral_point_curves",
    "register",
    "register_reproduce",
    "run",
    "validate_against_natraj",
    "zenith_dop_curves",
]

MU0_04_ELEVATION_DEG = float(np.degrees(np.arcsin(0.4)))
QUICK_CASES = [(0.02, 0.0, 0.4), (0.25, 0.0, 0.4), (0.25, 0.25, 0.4), (1.0, 0.25, 0.1)]


def validate_against_natraj(table_path=NATRAJ_FILE, cases=None, min_mu: float = 0.1):
    """Compare the multiple-scattering sky with the tables, case by case.

    Returns ``(per_case, points)`` DataFrames. ``Q_table = -Q``, ``U_table = U`` (conventions).
    """
    from skysim.multiple import MultipleScatteringSky

    d = read_natraj(table_path, min_mu)
    rows, points = [], []
    for (tau, albedo, mu0), s in d.groupby(["tau", "albedo", "mu0"]):
        if cases is not None and (tau, albedo, mu0) not in cases:
            continue
        t0 = time.perf_counter()
        f = MultipleScatteringSky(tau=tau, albedo=albedo).field(
            np.degrees(np.arcsin(s.mu.to_numpy())), s.phi.to_numpy(),
            float(np.degrees(np.arcsin(mu0))), 0.0)
        ref_i = s.I.to_numpy()
        p = pd.DataFrame({"tau": tau, "albedo": albedo, "mu0": mu0, "mu": s.mu.to_numpy(),
                          "phi_deg": s.phi.to_numpy(), "dI_rel": f.I / ref_i - 1,
                          "dDoLP": f.dop - np.hypot(s.Q, s.U).to_numpy() / ref_i,
                          "dQ_rel": (f.Q + s.Q.to_numpy()) / ref_i,
                          "dU_rel": (f.U - s.U.to_numpy()) / ref_i})
        points.append(p)
        rows.append({"tau": tau, "albedo": albedo, "mu0": mu0,
                     **{f"max_abs_{c}": float(np.abs(p[c]).max())
                        for c in ("dI_rel", "dDoLP", "dQ_rel", "dU_rel")},
                     "seconds": time.perf_counter() - t0})
    return pd.DataFrame(rows), pd.concat(points, ignore_index=True)


def neutral_point_curves(sun_elevations_deg, configs):
    """Neutral points for each (tau, albedo) in ``configs`` and sun elevation; one row each."""
    from skysim.neutral_points import neutral_points
    rows = []
    for tau, albedo in configs:
        for sun in sun_elevations_deg:
            n = neutral_points(float(sun), tau, albedo)
            rows.append(n.to_dict())
    return pd.DataFrame(rows)


def berry_delta_from(n) -> float:
    """Berry's pair separation from multiple-scattering neutral points: Babinet + Brewster
    distance when both are visible, else twice the mean of the visible Babinet/Arago distance."""
    if np.isfinite(n["brewster_elevation_deg"]):
        return float(n["babinet_distance_deg"] + n["brewster_distance_deg"])
    d = [n["babinet_distance_deg"]] + ([n["arago_distance_deg"]]
                                       if np.isfinite(n["arago_elevation_deg"]) else [])
    return float(2.0 * np.mean(d))


def zenith_dop_curves(sun_elevations_deg, configs, berry_delta_deg: float = 40.0):
    """Zenith DoP vs sun elevation: single scattering, multiple (each config), Berry."""
    from skysim.berry import BerrySky
    from skysim.multiple import MultipleScatteringSky
    from skysim.sky import RayleighSky

    sun = np.asarray(sun_elevations_deg, dtype=float)
    out = {"sun_elevation_deg": sun, "mu0": np.sin(np.radians(sun)),
           "single_scattering": RayleighSky().field(90.0, 0.0, sun, 0.0).dop,
           f"berry_delta{berry_delta_deg:g}": BerrySky(berry_delta_deg).field(90.0, 0.0, sun,
                                                                            0.0).dop}
    for tau, albedo in configs:
        out[f"multiple_tau{tau:g}_A{albedo:g}"] = MultipleScatteringSky(
            tau=tau, albedo=albedo).field(90.0, 0.0, sun, 0.0).dop
    return pd.DataFrame(out)


def _aop_rms_difference(a_deg, b_deg) -> float:
    from skysim.geometry import wrap_axial_deg
    return float(np.sqrt(np.mean(wrap_axial_deg(np.asarray(a_deg) - b_deg) ** 2)))


def _figures(out: Path, per_case, points, npts, zen, maps):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from experiments.plotting.polar_maps import plot_polar_maps

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
    for ax, col, label in [(axes[0], "dI_rel", "I/I_table - 1"),
                           (axes[1], "dDoLP", "DoLP - DoLP_table")]:
        ax.hist(points[col], bins=60, color="C0")
        ax.axvline(-2e-3, color="r", ls="--")
        ax.axvline(2e-3, color="r", ls="--", label="acceptance +-2e-3")
        ax.set_xlabel(label)
        ax.set_ylabel("table points")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Multiple-scattering sky vs Natraj et al. (2009): {len(per_case)} cases, "
                 f"{len(points)} points (mu >= 0.1)", fontsize=9)
    fig.tight_layout()
    save_png(fig, out / "validation_hist.png")

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for (tau, albedo), g in npts.groupby(["tau", "albedo"]):
        for name, m in [("babinet", "o-"), ("brewster", "s--"), ("arago", "^:")]:
            ax.plot(g.sun_elevation_deg, g[f"{name}_distance_deg"], m,
                    label=f"{name.capitalize()}, tau={tau:g}, A={albedo:g}", ms=4)
        ax.plot(g.sun_elevation_deg, g.berry_delta_deg / 2, "k-", lw=0.8, alpha=0.5)
    ax.set_xlabel("sun elevation [deg]")
    ax.set_ylabel("distance from sun / anti-sun [deg]")
    ax.set_title("Neutral points: multiple scattering (markers) vs Berry delta/2 (grey)",
                 fontsize=9)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    save_png(fig, out / "neutral_points.png")

    fig, ax = plt.subplots(figsize=(6, 4))
    for col in zen.columns[2:]:
        ax.plot(zen.sun_elevation_deg, zen[col], "o-", ms=3, label=col)
    for v in (0.72, 0.63, 0.53):
        ax.plot(MU0_04_ELEVATION_DEG, v, "kx", ms=9)
    ax.axvline(MU0_04_ELEVATION_DEG, color="grey", lw=0.5)
    ax.set_xlabel("sun elevation [deg]")
    ax.set_ylabel("DoP at the zenith")
    ax.set_title("Zenith DoP; crosses: 0.72 / 0.63 / 0.53 at mu0 = 0.4 (Natraj et al. 2009)",
                 fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_png(fig, out / "zenith_dop.png")

    el, az, sun, fields, marks = maps
    ms, berry, single = fields
    plot_polar_maps(el, az, {"DoP (multiple)": (ms.dop, "viridis", (0, 1)),
                             "AoP [deg] (multiple)": (ms.aop_deg, "twilight", (-90, 90)),
                             "I (multiple, flux pi)": (ms.I, "magma", None),
                             "AoP [deg] (Berry)": (berry.aop_deg, "twilight", (-90, 90)),
                             "AoP [deg] (single)": (single.aop_deg, "twilight", (-90, 90))},
                    out / "polar_maps.png", sun=sun, marks=marks,
                    title=f"tau 0.25, albedo 0.25; sun elevation {sun[0]:g}°, azimuth "
                          f"{sun[1]:g}°; x: neutral points (multiple scattering)")


def run(out: Path, quick: bool = False, reference=None) -> dict:
    """Run everything; return the tables and a summary dict.

    ``reference``: another copy of the Natraj tables (:func:`natraj_path`); default the
    shipped rows. Progress on stderr, step by step (:data:`experiments.workflows.progress.
    STEP_SECONDS`)."""
    from experiments.workflows.progress import STEP_SECONDS, Steps

    t0 = time.perf_counter()
    out = Path(out)
    table = natraj_path(reference)
    with Steps("skysim reproduce physical-sky",
               STEP_SECONDS["physical-sky" + (" --quick" if quick else "")]) as steps:
        return _run(out, quick, table, steps, t0)


def _run(out: Path, quick: bool, table, steps, t0: float) -> dict:
    from skysim.berry import BerrySky
    from skysim.multiple import MultipleScatteringSky
    from skysim.neutral_points import neutral_points
    from skysim.sky import RayleighSky

    from skysim.geometry import sky_grid

    per_case, points = validate_against_natraj(table, cases=QUICK_CASES if quick else None)
    steps.done("validation against the Natraj tables")
    suns = [5.0, MU0_04_ELEVATION_DEG, 45.0] if quick else \
        [3.0, 6.0, 10.0, 15.0, MU0_04_ELEVATION_DEG, 30.0, 40.0, 50.0, 60.0, 70.0]
    configs = [(0.25, 0.0), (0.25, 0.25)]
    npts = neutral_point_curves(suns, configs)
    npts["berry_delta_deg"] = [berry_delta_from(r) for _, r in npts.iterrows()]
    steps.done("neutral points")
    zen = zenith_dop_curves(suns, configs)
    steps.done("zenith DoP")

    sun = (20.0, 180.0)
    el, az = sky_grid(3.0)
    ms = MultipleScatteringSky(tau=0.25, albedo=0.25).field(el, az, *sun)
    n = neutral_points(sun[0], 0.25, 0.25)
    delta = berry_delta_from(n.to_dict())
    berry = BerrySky(delta).field(el, az, *sun)
    single = RayleighSky().field(el, az, *sun)
    away = ms.dop > 0.05  # AoP is meaningless at the neutral points themselves
    aop_rms = {"berry_vs_multiple_deg": _aop_rms_difference(berry.aop_deg[away],
                                                            ms.aop_deg[away]),
               "single_vs_multiple_deg": _aop_rms_difference(single.aop_deg[away],
                                                             ms.aop_deg[away]),
               "berry_delta_deg": delta, "sun_elevation_deg": sun[0]}
    _figures(out, per_case, points, npts, zen,
             (el, az, sun, (ms, berry, single), n.marks(sun[1])))
    steps.done("sky maps and figures")

    from .aerosol_sky import aerosol_section
    aerosol_summary = aerosol_section(out, quick=quick)
    steps.done("aerosol skies")

    row04 = zen[np.isclose(zen.sun_elevation_deg, MU0_04_ELEVATION_DEG)].iloc[0]
    summary = {
        "cases": len(per_case), "points": len(points), "quick": quick,
        "max_abs_dI_rel": float(np.abs(points.dI_rel).max()),
        "max_abs_dDoLP": float(np.abs(points.dDoLP).max()),
        "p50_abs_dI_rel": float(np.abs(points.dI_rel).median()),
        "p95_abs_dI_rel": float(np.abs(points.dI_rel).quantile(0.95)),
        "p50_abs_dDoLP": float(np.abs(points.dDoLP).median()),
        "p95_abs_dDoLP": float(np.abs(points.dDoLP).quantile(0.95)),
        "max_abs_dQ_rel": float(np.abs(points.dQ_rel).max()),
        "max_abs_dU_rel": float(np.abs(points.dU_rel).max()),
        "acceptance_2e-3": bool(np.abs(points.dI_rel).max() <= 2e-3
                                and np.abs(points.dDoLP).max() <= 2e-3),
        "zenith_dop_mu0_0.4": {"single": float(row04.single_scattering),
                               "tau0.25_A0": float(row04["multiple_tau0.25_A0"]),
                               "tau0.25_A0.25": float(row04["multiple_tau0.25_A0.25"]),
                               "natraj2009": [0.72, 0.63, 0.53]},
        "aop_rms_over_sky": aop_rms,
        "aerosol": aerosol_summary,
        "elapsed_s": time.perf_counter() - t0,
        "step_s": {k: round(v, 2) for k, v in steps.elapsed_s.items()},
        "step_cpu_s": {k: round(v, 2) for k, v in steps.cpu_s.items()},
        "config": {"reference": str(table), "min_mu": 0.1,
                   "cases": "quick subset " + repr(QUICK_CASES) if quick else "all shared",
                   "sun_elevations_deg": suns, "neutral_point_configs": configs,
                   "map_sun": sun, "sky": MultipleScatteringSky(tau=0.25).describe()},
    }

    def csv(df):
        return lambda p: df.to_csv(p, index=False)
    for name, df in [("validation.csv", per_case), ("validation_points.csv", points),
                     ("neutral_points.csv", npts), ("zenith_dop.csv", zen)]:
        atomic_write(out / name, csv(df))
    write_json_atomic(out / "summary.json", summary)
    return {"validation": per_case, "points": points, "neutral_points": npts,
            "zenith_dop": zen, "summary": summary}


def _print(result, out: Path) -> None:
    s = result["summary"]
    pd.set_option("display.width", 160)
    print(f"Multiple-scattering sky vs Natraj et al. (2009), transmitted field, mu >= 0.1: "
          f"{s['cases']} cases, {s['points']} points")
    print(f"  |dI/I|:   max {s['max_abs_dI_rel']:.2e}  median {s['p50_abs_dI_rel']:.1e}  "
          f"95% {s['p95_abs_dI_rel']:.1e}")
    print(f"  |dDoLP|:  max {s['max_abs_dDoLP']:.2e}  median {s['p50_abs_dDoLP']:.1e}  "
          f"95% {s['p95_abs_dDoLP']:.1e}   (acceptance 2e-3: "
          f"{'met' if s['acceptance_2e-3'] else 'NOT met'})")
    z = s["zenith_dop_mu0_0.4"]
    print(f"  zenith DoP at mu0 = 0.4: single {z['single']:.3f}, tau 0.25 black ground "
          f"{z['tau0.25_A0']:.3f}, albedo 0.25 {z['tau0.25_A0.25']:.3f} (tables: "
          "0.72/0.63/0.53)")
    cols = ["tau", "albedo", "sun_elevation_deg", "babinet_distance_deg",
            "brewster_distance_deg", "arago_distance_deg", "berry_delta_deg"]
    print(result["neutral_points"][cols].to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    a = s["aop_rms_over_sky"]
    print(f"  RMS AoP difference from multiple scattering over the sky (DoP > 0.05, sun "
          f"{a['sun_elevation_deg']:g} deg): Berry (delta {a['berry_delta_deg']:.1f}) "
          f"{a['berry_vs_multiple_deg']:.2f} deg, single scattering "
          f"{a['single_vs_multiple_deg']:.2f} deg")
    print("  aerosol skies (continental average, 450 nm, albedo 0.1): neutral-point "
          "distances [deg] and maximum DoP vs AOD at 550 nm")
    npt = pd.DataFrame(s["aerosol"]["neutral_points"]).merge(
        pd.DataFrame(s["aerosol"]["max_dop"]), on=["aod_550", "sun_elevation_deg"])
    print(npt.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    print(f"wrote {out}/ (validation.csv, neutral_points.csv, zenith_dop.csv, summary.json, "
          f"figures) in {s['elapsed_s']:.0f} s")


def _reproduce(args) -> int:
    quick = bool(getattr(args, "quick", False)) or (args.trials is not None and args.trials < 10)
    out = Path(args.out or "results/physical-sky")
    result = run(out, quick=quick, reference=getattr(args, "reference", None))
    _print(result, out)
    return 0


_reproduce.takes_reference = True


def register_reproduce(targets: dict) -> None:
    targets["physical-sky"] = _reproduce


def register(sub) -> None:
    p = sub.add_parser("physical-sky", help="multiple-scattering sky: validation vs the Natraj "
                       "tables, neutral points, Berry model, zenith DoP")
    p.add_argument("--quick", action="store_true", help="4 table cases, 3 sun elevations")
    p.add_argument("--reference", default=None,
                   help="another copy of the Natraj et al. (2009) tables: the file, or a folder "
                        "holding it (default: the tables shipped with skysim)")
    p.add_argument("--out", type=output_dir, default=None,
                   help="output folder (default: results/physical-sky)")
    p.set_defaults(func=lambda a: _reproduce(argparse.Namespace(trials=None, **vars(a))))
