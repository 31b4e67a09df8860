"""The moonlit sky against FORS2 polarimetry at Paranal (``skysim reproduce moonlit-sky``).

``skysim reproduce moonlit-sky [--data DIR]`` reads the FORS2 sky-background polarization
table (default ``../shared/reference/moonskypol`` beside the checkout: the rows of
``SN-CRISP/Moon-Skypol``'s ``data.csv``), and for every row, whatever its band and
condition:

- turns the field's J2000 RA/Dec into topocentric elevation and azimuth at the row's
  ``MED OBS`` (UTC) at Paranal (astropy, no refraction);
- turns the measured normalised Stokes ``Q``, ``U`` into DoP and AoP. **Frame of the
  measured Q, U**: the equatorial frame of the sky, Q > 0 for an E-vector along the hour
  circle (towards the north celestial pole) and the angle counted from north through east
  (IAU convention), ``AoP_eq = 0.5 atan2(U, Q)``. The source's analysis code
  (``Stokes_func.py``, ``field_functions.py``) computes ``0.5 arctan(U/Q)`` without stating
  a frame; this one is checked on the ``ok`` rows, where the measured E-vector then lies
  within a few degrees of the perpendicular to the scattering plane through the Moon, and
  the mirrored sense (north through west) does not (``tests/test_moon_fors2.py``). The
  E-vector is carried into the local-meridian frame of skysim (``docs/conventions.md``) by
  astropy: a point one arcminute from the field in position angle ``AoP_eq`` is transformed
  to alt/az with the field, and the AoP of that tangent direction is taken in the field's
  local basis;
- evaluates the night-sky model of :mod:`skysim.night` there (Moon from :mod:`skysim.moon`,
  the row's band with its Paranal extinction, dark sky and aerosol-to-molecular scattering
  weight; the Sun is left out because the ``sun`` rows are in twilight, which the model does
  not cover) with the single-scattering Rayleigh pattern and, when the ``rt`` extra is
  installed, the multiple-scattering one over the desert's ground albedo in the band
  (:attr:`skysim.bands.Band.ground_albedo`);
- writes ``moonlit_sky.csv`` (one row per measurement), ``moonlit_sky.png`` (DoP and AoP
  residuals against the scattering angle from the Moon) and ``summary.json`` (residual
  statistics per band, model and condition, for every band in the table, and the band
  parameters used).

Nothing is fitted to the measurements.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.exceptions import InvalidParameterError, MissingFileError
from skysim.io import atomic_write, write_json_atomic

from experiments.plotting.figures import pyplot, save_png

__all__ = ["DEFAULT_DATA", "REQUIRED_COLUMNS", "band_parameters", "band_ratios", "compare",
           "measured_polarization", "paranal", "read_fors2", "register_reproduce", "run"]

DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "reference" / "moonskypol"
"""The FORS2 moonlit-sky rows beside the checkout (``../shared/reference/moonskypol``)."""

REQUIRED_COLUMNS = ("FIELD", "RA", "DEC", "MED OBS", "Q", "error Q", "U", "error U", "BAND",
                    "CONDITION")
"""Columns the check reads (the source's names; spaces around names are ignored)."""

PARANAL_LATITUDE_DEG, PARANAL_LONGITUDE_DEG, PARANAL_ALTITUDE_M = -24.6272, -70.4042, 2635.0
PARANAL_PRESSURE_HPA = 743.0
"""Typical surface pressure at Paranal (2635 m) [hPa], for the Rayleigh optical thickness of
the multiple-scattering sky (the standard atmosphere gives 740 hPa at that height)."""
OFFSET_ARCMIN = 1.0


def paranal():
    """The site of the FORS2 moonlit-sky observations, ESO Paranal (:class:`skysim.sun.Site`)."""
    from skysim.sun import Site
    return Site(PARANAL_LATITUDE_DEG, PARANAL_LONGITUDE_DEG, PARANAL_ALTITUDE_M, "Paranal")



def data_file(folder) -> Path:
    """The table in ``folder`` (the only ``*.csv`` there), or ``folder`` itself if a file.

    Raises
    ------
    FileNotFoundError
        If there is no such folder or file, or no CSV in the folder.
    """
    p = Path(folder)
    if p.is_file():
        return p
    files = sorted(p.glob("*.csv")) if p.is_dir() else []
    if not files:
        raise MissingFileError(f"--data {p}: no FORS2 moonlit-sky table (*.csv) there; give "
                                "the folder of the table or the file itself")
    if len(files) > 1:
        raise InvalidParameterError(f"--data {p}: several CSV files ({', '.join(f.name for f in files)});"
                         " give the file")
    return files[0]


def read_fors2(path) -> pd.DataFrame:
    """Read the FORS2 table by its schema (``;``-separated, any bands, any rows).

    Returns a frame with ``field``, ``ra_deg``, ``dec_deg``, ``time`` (UTC), ``Q``,
    ``Q_err``, ``U``, ``U_err``, ``band``, ``condition``.

    Raises
    ------
    ValueError
        For a missing column (naming it), a value that is not a number or a time (naming the
        row), or no rows.
    """
    path = Path(path)
    d = pd.read_csv(path, sep=";", dtype=str)
    d.columns = [c.strip() for c in d.columns]
    missing = [c for c in REQUIRED_COLUMNS if c not in d.columns]
    if missing:
        raise InvalidParameterError(f"{path}: missing column(s) {missing}; found {list(d.columns)}")
    if d.empty:
        raise InvalidParameterError(f"{path} has a header but no rows")
    out = pd.DataFrame({"field": d["FIELD"].str.strip(), "band": d["BAND"].str.strip(),
                        "condition": d["CONDITION"].str.strip()})
    for src, dst in (("RA", "ra_deg"), ("DEC", "dec_deg"), ("Q", "Q"), ("error Q", "Q_err"),
                     ("U", "U"), ("error U", "U_err")):
        x = pd.to_numeric(d[src], errors="coerce")
        bad = np.flatnonzero(~np.isfinite(x.to_numpy(float)))
        if bad.size:
            raise InvalidParameterError(f"{path}: {src} in data row {bad[0] + 1} is {d[src].iloc[bad[0]]!r},"
                             " not a number")
        out[dst] = x.to_numpy(float)
    t = pd.to_datetime(d["MED OBS"].str.strip(), errors="coerce", utc=True)  # the source: UTC
    bad = np.flatnonzero(t.isna())
    if bad.size:
        raise InvalidParameterError(f"{path}: MED OBS in data row {bad[0] + 1} is "
                         f"{d['MED OBS'].iloc[bad[0]]!r}, not a time")
    out["time"] = t
    return out


def measured_polarization(table: pd.DataFrame) -> pd.DataFrame:
    """Direction, DoP and AoP of each measured row (see the module docstring for the frame).

    Returns ``elevation_deg``, ``azimuth_deg`` [deg], ``dop``, ``dop_err``, ``aop_eq_deg``
    (from celestial north through east) and ``aop_deg`` (skysim's local-meridian AoP) with
    ``aop_err_deg`` [deg] (first-order error propagation of ``Q_err``, ``U_err``).
    """
    import astropy.units as u
    from astropy.coordinates import AltAz, EarthLocation, SkyCoord
    from astropy.time import Time

    from skysim.geometry import aop_from_e_vector, direction_vector
    from skysim.moon import _offline_astropy

    q, uu = table.Q.to_numpy(), table.U.to_numpy()
    dop = np.hypot(q, uu)
    with np.errstate(divide="ignore", invalid="ignore"):
        dop_err = np.hypot(q * table.Q_err, uu * table.U_err) / dop
        aop_err = np.degrees(0.5 * np.hypot(q * table.U_err, uu * table.Q_err) / dop ** 2)
    aop_eq = 0.5 * np.degrees(np.arctan2(uu, q))
    site = paranal()
    loc = EarthLocation.from_geodetic(site.longitude_deg * u.deg, site.latitude_deg * u.deg,
                                      site.altitude_m * u.m)
    t = Time(table.time.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy(), scale="utc")
    frame = AltAz(obstime=t, location=loc)
    target = SkyCoord(ra=table.ra_deg.to_numpy() * u.deg, dec=table.dec_deg.to_numpy() * u.deg,
                      frame="icrs")
    ahead = target.directional_offset_by(aop_eq * u.deg, OFFSET_ARCMIN * u.arcmin)
    with _offline_astropy():
        a0, a1 = target.transform_to(frame), ahead.transform_to(frame)
    el, az = a0.alt.deg, np.mod(a0.az.deg, 360.0)
    tangent = direction_vector(a1.alt.deg, a1.az.deg) - direction_vector(el, az)
    return pd.DataFrame({"elevation_deg": el, "azimuth_deg": az, "dop": dop,
                         "dop_err": dop_err, "aop_eq_deg": aop_eq,
                         "aop_deg": aop_from_e_vector(el, az, tangent), "aop_err_deg": aop_err},
                        index=table.index)


def pattern_skies(bands, with_multiple: bool = True, ground_albedo: float | None = None) -> dict:
    """The polarization patterns compared: ``{"rayleigh": {band: Sky}, "multiple": ...}``;
    the multiple-scattering one (Rayleigh optical thickness at the band's wavelength and
    Paranal's pressure, over a Lambertian ground of the band's desert albedo,
    :attr:`skysim.bands.Band.ground_albedo`, or ``ground_albedo`` in every band; 0 is a
    black ground) only when ``with_multiple`` and the ``rt`` extra is installed."""
    from skysim.bands import get_band
    from skysim.sky import RayleighSky
    out = {"rayleigh": {b: RayleighSky() for b in bands}}
    if with_multiple:
        try:
            import sasktran2  # noqa: F401
        except ImportError:
            return out
        from skysim.multiple import MultipleScatteringSky
        out["multiple"] = {b: MultipleScatteringSky(
            wavelength_nm=get_band(b).wavelength_nm, pressure_hPa=PARANAL_PRESSURE_HPA,
            albedo=get_band(b).ground_albedo if ground_albedo is None else ground_albedo,
            latitude_deg=PARANAL_LATITUDE_DEG, altitude_m=PARANAL_ALTITUDE_M, sun_step_deg=2.0)
            for b in bands}
    return out


def compare(table: pd.DataFrame, with_multiple: bool = True,
            aerosol_scale: float | None = None,
            ground_albedo: float | None = None) -> pd.DataFrame:
    """Measured and modelled DoP and AoP for every row of :func:`read_fors2`'s table.

    ``aerosol_scale``: the weight of the aerosol term in every band; default each band's
    own (:func:`skysim.night.aerosol_weight`); 1 holds K&S's V-band split in every band.
    ``ground_albedo``: the ground albedo of the multiple-scattering pattern in every band;
    default each band's desert albedo (:attr:`skysim.bands.Band.ground_albedo`); 0 is a
    black ground.

    Adds, per model M: ``dop_M``, ``aop_M_deg``, ``dop_resid_M`` (measured - model) and
    ``aop_resid_M_deg`` (measured - model, wrapped to [-90, 90)); and the geometry:
    ``moon_elevation_deg``, ``moon_azimuth_deg``, ``moon_phase_angle_deg``,
    ``sun_elevation_deg``, ``scattering_angle_deg`` (from the Moon) [deg],
    ``background_fraction`` (share of the night-sky background in I) and ``aerosol_scale``
    (the band's weight of the aerosol term, :func:`skysim.night.aerosol_weight`).

    Raises
    ------
    InvalidParameterError
        For a band that skysim does not know (naming it and the valid ones).
    """
    from skysim.geometry import wrap_axial_deg
    from skysim.night import night_sky

    site = paranal()
    meas = measured_polarization(table)
    out = pd.concat([table, meas], axis=1)
    for model, skies in pattern_skies(sorted(table.band.unique()), with_multiple,
                                             ground_albedo).items():
        for band, sky in skies.items():
            rows = np.flatnonzero(table.band.to_numpy() == band)
            ns = night_sky(meas.elevation_deg.to_numpy()[rows], meas.azimuth_deg.to_numpy()[rows],
                           table.time.iloc[rows], site, band, sky, include_sun=False,
                           aerosol_scale=aerosol_scale)
            out.loc[out.index[rows], f"dop_{model}"] = ns.field.dop
            # no moonlight (the Moon below the horizon): no modelled angle
            out.loc[out.index[rows], f"aop_{model}_deg"] = np.where(ns.field.dop > 0.0,
                                                                     ns.field.aop_deg, np.nan)
            if model == "rayleigh":
                moon = ns.sources["moon"]
                geometry = {"moon_elevation_deg": moon.elevation_deg.to_numpy(),
                            "moon_azimuth_deg": moon.azimuth_deg.to_numpy(),
                            "moon_phase_angle_deg": moon.phase_angle_deg.to_numpy(),
                            "sun_elevation_deg": ns.sources["sun_elevation_deg"],
                            "scattering_angle_deg": ns.components["moon_scattering_angle_deg"],
                            "background_fraction": ns.components["background_I"] / ns.field.I,
                            "aerosol_scale": ns.sources["aerosol_scale"]}
                for k, v in geometry.items():
                    out.loc[out.index[rows], k] = v
        out[f"dop_resid_{model}"] = out.dop - out[f"dop_{model}"]
        out[f"aop_resid_{model}_deg"] = wrap_axial_deg(out.aop_deg - out[f"aop_{model}_deg"])
    return out


def band_parameters(bands) -> dict:
    """The model's parameters of each band: effective wavelength [nm], extinction and its
    molecular and aerosol parts [mag per airmass] (:func:`skysim.night.extinction_components`),
    the aerosol term's weight [1], the dark-sky zenith brightness [mag arcsec^-2] and the
    ground albedo of the multiple-scattering pattern [1]."""
    from skysim.bands import get_band
    from skysim.night import aerosol_weight, extinction_components
    out = {}
    for band in bands:
        c = extinction_components(band)
        out[band] = {"wavelength_nm": c["wavelength_nm"],
                     "extinction_mag_per_airmass": c["total"],
                     "molecular_mag_per_airmass": round(c["rayleigh"], 5),
                     "aerosol_mag_per_airmass": round(c["aerosol"], 5),
                     "aerosol_scale": round(aerosol_weight(band), 4),
                     "dark_sky_mag_arcsec2": get_band(band).dark_sky_mag_arcsec2,
                     "ground_albedo": round(get_band(band).ground_albedo, 4)}
    return out


def summarize(result: pd.DataFrame) -> dict:
    """Residual statistics per model, band and condition (RMS and median; AoP over rows
    with measured DoP >= 0.05, where the angle is defined to a few degrees)."""
    models = [c[len("dop_resid_"):] for c in result.columns if c.startswith("dop_resid_")]
    stats = {}
    for model in models:
        for (band, cond), g in result.groupby(["band", "condition"]):
            a = g.loc[g.dop >= 0.05, f"aop_resid_{model}_deg"].dropna()
            d = g[f"dop_resid_{model}"]
            lit = g[f"dop_{model}"] > 0.0
            stats.setdefault(model, {}).setdefault(band, {})[cond] = {
                "n": int(len(g)),
                "dop_resid_rms": float(np.sqrt(np.mean(d ** 2))),
                "dop_resid_median": float(np.median(d)),
                "n_moon_below_horizon": int((~lit).sum()),
                "dop_ratio_median": (float(np.median(g.dop[lit] / g[f"dop_{model}"][lit]))
                                     if lit.any() else None),
                "n_aop": int(len(a)),
                "aop_resid_rms_deg": float(np.sqrt(np.mean(a ** 2))) if len(a) else None,
                "aop_resid_max_abs_deg": float(np.max(np.abs(a))) if len(a) else None}
    return stats


PAIR_WINDOW = pd.Timedelta("1h")
"""Rows of one field in two bands taken within this time of each other are compared."""
PAIR_MIN_DOP = 0.04
"""Reference-band DoP below which a band ratio is not formed (the ratio of two small,
noisy numbers)."""


def band_ratios(result: pd.DataFrame, reference: str = "V") -> dict:
    """DoP of each band relative to ``reference`` on the same fields, measured and modelled.

    Clear (``ok``) rows of one field in a band and in ``reference`` taken within
    :data:`PAIR_WINDOW` are paired (the nearest in time); per model and band: ``n``,
    ``measured_median``, ``model_median`` (of the DoP ratios band / reference) and
    ``diff_rms`` (RMS of measured minus modelled ratio). The band dependence of the model,
    apart from what it shares with the reference band. Empty without the reference band.
    """
    models = [c[len("dop_resid_"):] for c in result.columns if c.startswith("dop_resid_")]
    ok = result[result.condition == "ok"]
    ref = ok[(ok.band == reference) & (ok.dop >= PAIR_MIN_DOP)]
    stats = {}
    for band in sorted(set(ok.band) - {reference}):
        rows = ok[ok.band == band].assign(row_id=np.arange((ok.band == band).sum()))
        pairs = rows.merge(ref, on="field", suffixes=("", "_ref"))
        gap = (pairs.time - pairs.time_ref).abs()
        pairs, gap = pairs[gap <= PAIR_WINDOW], gap[gap <= PAIR_WINDOW]
        pairs = pairs.loc[gap.groupby(pairs.row_id).idxmin()]
        if pairs.empty:
            continue
        measured = pairs.dop / pairs.dop_ref
        for model in models:
            modelled = pairs[f"dop_{model}"] / pairs[f"dop_{model}_ref"]
            stats.setdefault(model, {})[band] = {
                "reference": reference, "n": int(len(pairs)),
                "measured_median": float(np.median(measured)),
                "model_median": float(np.median(modelled)),
                "diff_rms": float(np.sqrt(np.mean((measured - modelled) ** 2)))}
    return stats


def plot(result: pd.DataFrame, path) -> Path:
    """DoP (measured and modelled) and AoP residual against the scattering angle."""
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.4), constrained_layout=True)
    markers = {"ok": "o", "clouds": "s", "sun": "^"}
    colors = {"B": "tab:blue", "V": "tab:green", "R": "tab:red", "I": "tab:brown"}
    models = [c[len("dop_resid_"):] for c in result.columns if c.startswith("dop_resid_")]
    for (band, cond), g in result.groupby(["band", "condition"]):
        c, m = colors.get(band, "k"), markers.get(cond, "x")
        ax1.errorbar(g.scattering_angle_deg, g.dop, yerr=g.dop_err, fmt=m, color=c, ms=5,
                     label=f"{band} measured, {cond}")
        for model, fill in zip(models, ("none", c)):
            ax1.plot(g.scattering_angle_deg, g[f"dop_{model}"], m, mfc=fill, mec=c, ms=8,
                     alpha=0.6, label=f"{band} {model} model, {cond}")
        ax2.errorbar(g.scattering_angle_deg, g[f"aop_resid_{models[0]}_deg"],
                     yerr=g.aop_err_deg, fmt=m, color=c, ms=5, label=f"{band}, {cond}")
    ax1.set_xlabel("scattering angle from the Moon [deg]")
    ax1.set_ylabel("degree of linear polarization")
    ax1.set_title("DoP: measured (small) and model (large)")
    ax1.legend(fontsize=6, ncol=2, loc="upper left")
    ax1.set_ylim(0, 1.05)
    ax2.axhline(0, color="0.5", lw=0.8)
    ax2.set_xlabel("scattering angle from the Moon [deg]")
    ax2.set_ylabel(f"AoP measured - {models[0]} model [deg]")
    ax2.set_title("AoP residual (local-meridian frame)")
    ax2.set_ylim(-45, 45)
    ax2.legend(fontsize=7, loc="lower right")
    return save_png(fig, path)


def run(data, out, with_multiple: bool = True) -> dict:
    """The check of the module docstring; returns the summary written to ``summary.json``."""
    t0 = time.perf_counter()
    path = data_file(data)
    result = compare(read_fors2(path), with_multiple)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    table = result.assign(time=result.time.dt.strftime("%Y-%m-%dT%H:%M:%SZ"))
    atomic_write(out / "moonlit_sky.csv", lambda p: table.to_csv(p, index=False,
                                                                 float_format="%.6g"))
    plot(result, out / "moonlit_sky.png")
    bands = sorted(result.band.unique())
    summary = {"data": str(path), "rows": int(len(result)), "bands": bands,
               "band_parameters": band_parameters(bands),
               "aop_frame_of_measurement": "equatorial, from celestial north through east",
               "models": sorted(c[len("dop_resid_"):] for c in result.columns
                                if c.startswith("dop_resid_")),
               "residuals": summarize(result), "band_ratio_to_V": band_ratios(result),
               "elapsed_s": time.perf_counter() - t0}
    write_json_atomic(out / "summary.json", summary)
    return summary


# --------------------------------------------------------------------------- command line
def _reproduce(args) -> int:
    folder = Path(args.data) if args.data else DEFAULT_DATA
    if not folder.exists():
        raise MissingFileError(f"--data {folder}: no such folder; give the folder of the "
                                "FORS2 moonlit-sky table")
    out = Path(args.out or "results/moonlit-sky")
    summary = run(folder, out, with_multiple=not args.quick)
    for band, b in summary["band_parameters"].items():
        print(f"band {band}: {b['wavelength_nm']:g} nm, extinction "
              f"{b['extinction_mag_per_airmass']:.2f} mag/airmass (molecules "
              f"{b['molecular_mag_per_airmass']:.3f}, aerosol {b['aerosol_mag_per_airmass']:.3f}), "
              f"aerosol term x{b['aerosol_scale']:.2f}, dark sky {b['dark_sky_mag_arcsec2']:g} "
              f"mag/arcsec2, ground albedo {b['ground_albedo']:.2f}")
    for model, bands in summary["residuals"].items():
        for band, conds in bands.items():
            for cond, s in conds.items():
                aop = "-" if s["aop_resid_rms_deg"] is None else f"{s['aop_resid_rms_deg']:.1f}"
                ratio = "-" if s["dop_ratio_median"] is None else f"{s['dop_ratio_median']:.2f}"
                print(f"{model:9s} {band} {cond:7s} n={s['n']:2d}  DoP resid RMS "
                      f"{s['dop_resid_rms']:.3f} (measured/model median {ratio})  "
                      f"AoP resid RMS {aop} deg")
    for model, bands in summary["band_ratio_to_V"].items():
        for band, r in bands.items():
            print(f"{model:9s} {band}/V DoP on {r['n']} clear field(s): measured median "
                  f"{r['measured_median']:.2f}, model {r['model_median']:.2f}, RMS difference "
                  f"{r['diff_rms']:.3f}")
    print(f"wrote {out}/moonlit_sky.csv, moonlit_sky.png and summary.json")
    return 0


_reproduce.takes_data = True


def register_reproduce(targets: dict) -> None:
    targets["moonlit-sky"] = _reproduce
