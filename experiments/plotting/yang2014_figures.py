"""Figures of the Yang et al. (2014) reproduction, analogous to the paper's Figs. 3-5."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration.solve import PAIRS, heading_error_deg
from sensor.opponent import channel_outputs

from .figures import pyplot, save_png

__all__ = ["plot_error_vs_phi", "plot_table1_bands"]


def plot_error_vs_phi(result: dict, out: Path) -> None:
    """Fig. 3: channel outputs vs phi; Fig. 4: ideal-model error; Fig. 5: compensated error."""
    plt = pyplot()
    ex = result["examples"]
    groups = sorted({g for g, _ in ex})
    # Fig. 3 analogue: measured outputs and the ideal model, group a
    phi_ref, _, cal, U, _ = ex[(groups[0], PAIRS[0])]
    order = np.argsort(phi_ref)
    fig, ax = plt.subplots(figsize=(6.4, 4))
    dop_shape = result["geometry"][groups[0]][3]
    ideal = channel_outputs(phi_ref[order], cal.dop_scale * dop_shape[order])
    for c, name in enumerate(("U1 (60°)", "U2 (0°)", "U3 (120°)")):
        ax.plot(phi_ref[order], U[order, c], ".", ms=3, label=f"{name} simulated")
        ax.plot(phi_ref[order], ideal[:, c], "-", lw=0.8, color="k")
    ax.set(xlabel="polarization azimuth φ [deg]", ylabel="channel output [V]",
           title=f"Fig. 3 analogue: outputs vs φ, group {groups[0]} (lines: ideal model)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_png(fig, out / "fig3_outputs_vs_phi.png", dpi=120)

    for fig_no, kind in ((4, "ideal model (uncompensated)"), (5, "after LSM compensation")):
        fig, axes = plt.subplots(len(groups), 1, figsize=(6.4, 2.4 * len(groups)), sharex=True)
        for ax, g in zip(np.atleast_1d(axes), groups):
            for pair in PAIRS:
                phi_ref, raw_err, cal, U, fit_idx = ex[(g, pair)]
                if fig_no == 4:
                    x, y = phi_ref, raw_err
                else:
                    x = phi_ref[~fit_idx]
                    y = heading_error_deg(cal.solve(U[~fit_idx])[0], x)
                o = np.argsort(x)
                ax.plot(x[o], y[o], ".-", ms=2, lw=0.6, label=f"pair {pair[0]}-{pair[1]}")
            ax.set_ylabel(f"group {g}\nerror [deg]")
            ax.grid(alpha=0.3)
        fig.suptitle(f"Fig. {fig_no} analogue: heading error, {kind}, trial 0", fontsize=10)
        np.atleast_1d(axes)[0].legend(fontsize=7, ncol=3)
        np.atleast_1d(axes)[-1].set_xlabel("polarization azimuth φ [deg]")
        fig.tight_layout()
        save_png(fig, out / f"fig{fig_no}_error_{'raw' if fig_no == 4 else 'compensated'}.png",
                 dpi=120)


def plot_table1_bands(table1, path: Path) -> None:
    """Monte-Carlo 5-95 % bands of compensated 3 sigma with the paper's values."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.6))
    x = np.arange(len(table1))
    med = table1.compensated_3sigma_median_deg.to_numpy()
    lo = med - table1.compensated_3sigma_p05_deg.to_numpy()
    hi = table1.compensated_3sigma_p95_deg.to_numpy() - med
    ax.errorbar(x, med, yerr=[lo, hi], fmt="o", capsize=4, label="simulated median, 5-95 %")
    ax.plot(x, table1.paper_3sigma_deg, "r*", ms=10, label="Yang et al. 2014, Table 1")
    ax.set_xticks(x, [f"{g}\n{p}" for g, p in zip(table1.group, table1.pair)])
    ax.set(ylabel="3σ heading error [deg]", title="Compensated heading error by group and pair")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, path, dpi=120)
