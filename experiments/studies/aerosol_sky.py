"""Aerosol skies beside the molecular one: principal-plane DoP, neutral points, max DoP vs AOD.

Part of ``skysim reproduce physical-sky`` (:mod:`experiments.studies.physical_sky`); writes to its
output folder:

- ``aerosol_principal_plane.csv`` / ``.png``: signed DoP ``-Q/I`` along the solar vertical
  (positive: E-vector perpendicular to the scattering plane) against the scattering angle,
  for several AODs at 450 nm (AOD 0 is the molecular sky), sun at 10 and 40 deg;
- ``aerosol_neutral_points.csv``: Arago, Babinet and Brewster distances [deg] from the
  anti-sun / sun against AOD (zeros of Q on the solar vertical);
- ``aerosol_max_dop.csv`` / ``.png``: the sky's maximum DoP against AOD beside the range
  measured by Kreuter, Emde & Blumthaler (2010, Atmos. Res. 98:363,
  doi:10.1016/j.atmosres.2010.07.011): about 0.7 at AOD 0.05 falling to 0.4 at 0.5
  (450 nm; the two quoted end points are plotted, not their full data).

Cost: one engine call per sun elevation for all AODs together (:func:`skysim.aerosol.
prefetch_tables`), after the Mie optics of the preset (seconds, cached).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from experiments.plotting.figures import save_png

__all__ = ["AODS", "KREUTER2010", "aerosol_section", "principal_plane", "vertical_zeros"]

AODS = (0.0, 0.05, 0.1, 0.2, 0.5, 1.0)
"""Aerosol optical depths at 550 nm of the reproduction (0: the molecular sky)."""
SUNS_DEG = (10.0, 40.0)
PRESET, WAVELENGTH_NM, ALBEDO = "continental_average", 450.0, 0.1
KREUTER2010 = {"aod": (0.05, 0.5), "max_dop": (0.7, 0.4)}
"""Kreuter et al. (2010): the measured maximum DoP at 450 nm at the two ends of their AOD
range, as quoted in their abstract (about 0.7 and 0.4)."""


def principal_plane(sky, sun_elevation_deg: float, step_deg: float = 0.05) -> pd.DataFrame:
    """Stokes along the solar vertical: towards the sun (``phi = 0``) and away from it
    (``phi = 180``), elevations 0-90 deg in ``step_deg`` steps; with the angle from the sun
    along the vertical ``from_sun_deg`` (negative below the sun), the scattering angle [deg]
    and the signed DoP ``-Q/I`` (U vanishes there by symmetry)."""
    el = np.arange(0.0, 90.0 + step_deg / 2, step_deg)
    parts = []
    for phi in (0.0, 180.0):
        f = sky.field(el, phi, sun_elevation_deg, 0.0)
        along = el - sun_elevation_deg if phi == 0.0 else 180.0 - el - sun_elevation_deg
        parts.append(pd.DataFrame({"phi_deg": phi, "elevation_deg": el,
                                   "from_sun_deg": along,
                                   "scattering_angle_deg": np.abs(along), "I": f.I, "Q": f.Q,
                                   "signed_dop": -f.Q / f.I, "dop": f.dop}))
    return pd.concat(parts, ignore_index=True)


def vertical_zeros(pp: pd.DataFrame, sun_elevation_deg: float) -> dict:
    """Babinet (above the sun), Brewster (below it) and Arago (above the anti-sun) distances
    [deg] from the sun / anti-sun: the zeros of Q nearest to them on the solar vertical,
    located by linear interpolation between samples; nan where not visible."""
    out = {}
    for name, phi, side in (("babinet", 0.0, 1), ("brewster", 0.0, -1), ("arago", 180.0, 0)):
        s = pp[pp.phi_deg == phi]
        el, q = s.elevation_deg.to_numpy(), s.Q.to_numpy()
        # a sign change between samples, or a zero on a sample (not counted twice)
        i = np.flatnonzero(((q[:-1] == 0.0) | (np.sign(q[:-1]) * np.sign(q[1:]) < 0))
                           & (q[1:] != q[:-1]))
        z = el[i] - q[i] * (el[i + 1] - el[i]) / (q[i + 1] - q[i])
        if side == 1:
            z = z[z > sun_elevation_deg]
            d = z.min() - sun_elevation_deg if z.size else np.nan
        elif side == -1:
            z = z[z < sun_elevation_deg]
            d = sun_elevation_deg - z.max() if z.size else np.nan
        else:
            d = z.min() + sun_elevation_deg if z.size else np.nan
        out[f"{name}_distance_deg"] = float(d)
    return out


def aerosol_section(out: Path, quick: bool = False) -> dict:
    """Compute, write and plot the aerosol part of the reproduction; return its summary."""
    from skysim.aerosol import AerosolSky, prefetch_tables

    aods = AODS[::2] if quick else AODS   # quick: 0, 0.1, 0.5
    skies = {a: AerosolSky(PRESET, a, ALBEDO, WAVELENGTH_NM) for a in aods}
    for sun in SUNS_DEG:
        prefetch_tables(aods, [sun], sky=skies[aods[0]])
    planes, points, maxima = [], [], []
    el, az = np.meshgrid(np.arange(0.0, 90.1, 1.0), np.arange(0.0, 360.0, 2.0))
    for sun in SUNS_DEG:
        for a, sky in skies.items():
            pp = principal_plane(sky, sun)
            planes.append(pp.assign(aod_550=a, sun_elevation_deg=sun))
            points.append({"aod_550": a, "sun_elevation_deg": sun,
                           **vertical_zeros(pp, sun)})
            maxima.append({"aod_550": a, "sun_elevation_deg": sun,
                           "max_dop": float(sky.field(el, az, sun, 0.0).dop.max())})
    planes, points, maxima = pd.DataFrame(pd.concat(planes)), pd.DataFrame(points), \
        pd.DataFrame(maxima)
    from skysim.io import atomic_write
    for name, df in (("aerosol_principal_plane.csv", planes),
                     ("aerosol_neutral_points.csv", points), ("aerosol_max_dop.csv", maxima)):
        atomic_write(out / name, lambda p, df=df: df.to_csv(p, index=False))
    _figures(out, planes, maxima)
    return {"preset": PRESET, "wavelength_nm": WAVELENGTH_NM, "albedo": ALBEDO,
            "neutral_points": points.to_dict("records"), "max_dop": maxima.to_dict("records")}


def _figures(out: Path, planes: pd.DataFrame, maxima: pd.DataFrame) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(SUNS_DEG), figsize=(11, 6.5), sharex="col",
                             gridspec_kw={"height_ratios": [2, 1]})
    for col, sun in enumerate(SUNS_DEG):
        for k, (a, g) in enumerate(planes[planes.sun_elevation_deg == sun].groupby("aod_550")):
            s = g.sort_values("from_sun_deg")
            for ax in axes[:, col]:
                ax.plot(s.from_sun_deg, s.signed_dop, color=f"C{k}", lw=1,
                        label=f"AOD {a:g}" + (" (molecular)" if a == 0 else ""))
        for ax in axes[:, col]:
            ax.axhline(0.0, color="k", lw=0.5)
            ax.axvline(0.0, color="orange", lw=0.8, ls=":")
            ax.axvline(90.0 - sun, color="grey", lw=0.8, ls=":")
        axes[1, col].set_ylim(-0.06, 0.06)
        axes[1, col].set_xlabel("angle from the sun along the solar vertical [deg] "
                                "(negative: below it)")
        axes[0, col].set_title(f"sun at {sun:g} deg (dotted: the sun and the zenith)",
                               fontsize=8)
    axes[0, 0].set_ylabel("signed DoP  -Q/I")
    axes[1, 0].set_ylabel("zoom: zeros = neutral points")
    axes[0, -1].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"{PRESET}, {WAVELENGTH_NM:g} nm, albedo {ALBEDO:g}: DoP on the solar vertical",
                 fontsize=9)
    fig.tight_layout()
    save_png(fig, out / "aerosol_principal_plane.png")

    fig, ax = plt.subplots(figsize=(5.5, 4))
    for k, (sun, g) in enumerate(maxima.groupby("sun_elevation_deg")):
        ax.plot(g.aod_550, g.max_dop, "o-", color=f"C{k}", ms=4,
                label=f"model, sun at {sun:g} deg")
    ax.plot(KREUTER2010["aod"], KREUTER2010["max_dop"], "ks", ms=7,
            label="Kreuter et al. 2010 (quoted range)")
    ax.set_xlabel("aerosol optical depth at 550 nm")
    ax.set_ylabel("maximum DoP of the sky")
    ax.set_ylim(0.0, 1.0)
    ax.set_title(f"{PRESET}, {WAVELENGTH_NM:g} nm, albedo {ALBEDO:g}", fontsize=9)
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    save_png(fig, out / "aerosol_max_dop.png")
