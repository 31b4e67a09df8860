"""Polar (fish-eye) maps of a sky field: DoP, AoP and radiance."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from skysim.io import atomic_write

__all__ = ["plot_polar_maps"]


def plot_polar_maps(elevation_deg, azimuth_deg, quantities: dict, path, *, sun=None,
                    marks=None, title: str = "") -> Path:
    """Scatter-plot quantities over the sky in polar axes (zenith at the centre).

    Parameters
    ----------
    elevation_deg, azimuth_deg : arrays (n,)
        Directions [deg]; azimuth clockwise from north, north up.
    quantities : dict name -> (values (n,), colormap, (vmin, vmax) or None)
    path : output PNG path (written atomically)
    sun : (elevation_deg, azimuth_deg), optional, marked with a star
    marks : dict label -> (elevation_deg, azimuth_deg) of extra points (e.g. neutral points)
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = 90.0 - np.asarray(elevation_deg, dtype=float)
    th = np.radians(np.asarray(azimuth_deg, dtype=float))
    n = len(quantities)
    fig, axes = plt.subplots(1, n, subplot_kw={"projection": "polar"}, figsize=(4.2 * n, 4.4))
    for ax, (name, (values, cmap, lim)) in zip(np.atleast_1d(axes), quantities.items()):
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(-1)  # clockwise azimuth
        vmin, vmax = lim if lim is not None else (np.nanmin(values), np.nanmax(values))
        sc = ax.scatter(th, r, c=values, s=4, cmap=cmap, vmin=vmin, vmax=vmax, linewidths=0)
        ax.set_ylim(0, 90)
        ax.set_yticks([30, 60, 90], ["60°", "30°", "0°"], fontsize=7)
        if sun is not None:
            ax.plot(np.radians(sun[1]), 90 - sun[0], "*", color="gold", mec="k", ms=14)
        for label, (el, az) in (marks or {}).items():
            ax.plot(np.radians(az), 90 - el, "x", color="k", ms=8)
            ax.annotate(label, (np.radians(az), 90 - el), fontsize=7)
        ax.set_title(name, fontsize=10)
        fig.colorbar(sc, ax=ax, shrink=0.7, pad=0.1)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    return path
