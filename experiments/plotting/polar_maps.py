"""Polar (fish-eye) maps of a sky field: DoP, AoP and radiance."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .figures import pyplot, save_png

__all__ = ["plot_polar_maps", "sky_title"]

TITLE_PARAMETERS = ("dmax", "tau", "aod_550", "albedo", "wavelength_nm", "pressure_hPa",
                    "delta_deg")
"""The physical parameters of a sky model shown in a map's title (numerical settings are in
the sidecar)."""


def sky_title(describe: dict, sun_elevation_deg: float, sun_azimuth_deg: float) -> str:
    """Figure title: the sky model with its scalar parameters and the sun, e.g.
    ``rayleigh sky, dmax 0.7; sun elevation 30°, azimuth 275°``."""
    clouds = ""
    if "clouds" in describe and "clear" in describe:   # a partly cloudy sky
        c = describe["clouds"]
        seed = f", seed {c['seed']}" if isinstance(c.get("seed"), int) else ""
        clouds = f"; clouds cover {c['cover']:g}, tau {c['tau']:g}{seed}"
        describe = describe["clear"]
    params = ", ".join(f"{k} {describe[k]:.4g}" for k in TITLE_PARAMETERS
                       if isinstance(describe.get(k), (int, float)))
    return (f"{describe.get('model', '')} sky{', ' + params if params else ''}{clouds}; sun "
            f"elevation {sun_elevation_deg:.1f}°, azimuth {sun_azimuth_deg:.1f}°")


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
    marks : dict label -> (elevation_deg, azimuth_deg) of extra points (e.g. neutral points),
        labelled beside their marker
    title : figure title (e.g. :func:`sky_title`)

    The radial axis is the zenith angle: rings are labelled with their elevation.
    """
    plt = pyplot()
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
        ax.set_yticks([30, 60, 90], ["el 60°", "el 30°", "el 0°"], fontsize=7)
        for t in ax.get_yticklabels():
            t.set_bbox({"boxstyle": "round,pad=0.1", "fc": "white", "alpha": 0.7, "lw": 0})
        # ring labels perpendicular to the solar meridian, away from the sun and the neutral
        # points (which lie on that meridian)
        ax.set_rlabel_position(((sun[1] if sun is not None else 0.0) + 90.0) % 360.0)
        ax.tick_params(axis="x", labelsize=7)
        if sun is not None:
            ax.plot(np.radians(sun[1]), 90 - sun[0], "*", color="gold", mec="k", ms=14)
        for label, (el, az) in (marks or {}).items():
            ax.plot(np.radians(az), 90 - el, "x", color="k", ms=8)
            ax.annotate(label, (np.radians(az), 90 - el), xytext=(6, 6),
                        textcoords="offset points", fontsize=7,
                        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "alpha": 0.7,
                              "lw": 0})
        ax.set_title(name, fontsize=10)
        fig.colorbar(sc, ax=ax, shrink=0.7, pad=0.1)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_png(fig, path)
