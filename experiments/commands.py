"""Foundation commands: ``skysim sky``, ``skysim sample`` and ``skysim calibrate``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["register", "sky_grid", "view_directions", "AOP_CONVENTION"]

AOP_CONVENTION = (
    "AoP (aop_deg) is the E-vector orientation measured from the local meridian (the "
    "direction towards the zenith along the meridian) positive towards increasing azimuth, "
    "i.e. clockwise as seen by an observer looking along the view direction, wrapped to "
    "[-90, 90). Q = I dop cos(2 aop), U = I dop sin(2 aop) in that basis. Azimuths are "
    "clockwise from geographic north; at the zenith the meridian is that of the row's azimuth.")


def sky_grid(step_deg: float = 2.0):
    """Default full-sky grid: elevations 0..90 and azimuths 0..360-step [deg], flattened."""
    import numpy as np
    el = np.arange(0.0, 90.0 + 1e-9, step_deg)
    az = np.arange(0.0, 360.0, step_deg)
    E, A = np.meshgrid(el, az, indexing="ij")
    return E.ravel(), A.ravel()


def view_directions(directions_csv=None, grid_step_deg: float = 2.0):
    """View directions [deg] from a CSV with columns elevation_deg, azimuth_deg, or else the
    default full-sky grid (:func:`sky_grid`)."""
    if not directions_csv:
        return sky_grid(grid_step_deg)
    import pandas as pd
    d = pd.read_csv(directions_csv)
    missing = {"elevation_deg", "azimuth_deg"} - set(d.columns)
    if missing:
        raise ValueError(f"{directions_csv}: missing column(s) {sorted(missing)}")
    return d.elevation_deg.to_numpy(float), d.azimuth_deg.to_numpy(float)


def _sky(args) -> int:
    # pandas, tqdm and the sun are imported only where needed: a Parquet sky map for given
    # sun angles starts in a fraction of the time
    import numpy as np

    from skysim.io import atomic_write_many, sidecar_path
    from skysim.sky import make_sky

    if args.sun_elevation is not None:
        if args.sun_azimuth is None:
            raise ValueError("--sun-elevation needs --sun-azimuth")
        sun_el, sun_az, sun_info = args.sun_elevation, args.sun_azimuth, {
            "elevation_deg": args.sun_elevation, "azimuth_deg": args.sun_azimuth}
    else:
        if args.lat is None or args.lon is None or args.time is None:
            raise ValueError("give the sun as --lat --lon --time (timezone-aware ISO 8601) "
                             "or as --sun-elevation --sun-azimuth")
        from skysim.sun import Site, sun_position
        site = Site(args.lat, args.lon, args.alt)
        pos = sun_position([args.time], site.latitude_deg, site.longitude_deg, site.altitude_m)
        sun_el, sun_az = float(pos.elevation_deg.iloc[0]), float(pos.azimuth_deg.iloc[0])
        sun_info = {"site": site.to_dict(), "time": args.time, "elevation_deg": sun_el,
                    "azimuth_deg": sun_az}
    el, az = view_directions(args.directions, args.grid_step)
    params = {k: getattr(args, k) for k in ("dmax", "tau", "albedo", "wavelength_nm",
                                              "delta_deg", "pressure_hPa")
              if getattr(args, k, None) is not None}
    sky = make_sky(args.model, **params)
    chunk = 100_000
    starts = range(0, el.size, chunk)
    if el.size > chunk:
        from tqdm import tqdm
        starts = tqdm(starts, desc=f"sky ({args.model})", unit="chunk")
    parts = []
    for s in starts:
        f = sky.field(el[s:s + chunk], az[s:s + chunk], sun_el, sun_az)
        parts.append((f.dop, f.aop_deg, f.I, f.Q, f.U))
    table = {"elevation_deg": el, "azimuth_deg": az} | {
        name: np.concatenate(values) for name, values in zip(("dop", "aop_deg", "I", "Q", "U"),
                                                           zip(*parts))}
    if args.out:
        out = Path(args.out)
        if out.suffix.lower() not in (".csv", ".parquet"):
            raise ValueError(f"--out must end in .csv or .parquet; got {out.name!r}")
        sidecar = {"schema": "skysim.skymap/1", "sky": sky.describe(), "sun": sun_info,
                   "aop_convention": AOP_CONVENTION, "n_directions": int(el.size)}
        writer = (lambda p: _frame(table).to_csv(p, index=False)) \
            if out.suffix.lower() == ".csv" else (lambda p: _write_parquet(p, table))
        atomic_write_many([(out, writer), (sidecar_path(out),
                                           lambda p: p.write_text(json.dumps(sidecar, indent=2)))])
        print(f"wrote {el.size} directions to {out}")
    if args.plot:
        from .polar_maps import plot_polar_maps
        maps = {"DoP": (table["dop"], "viridis", (0, 1)),
                "AoP [deg]": (table["aop_deg"], "twilight", (-90, 90))}
        marks = None
        if args.model == "multiple":  # radiance (flux pi) and the neutral points
            from skysim.neutral_points import neutral_points_from_modes
            maps["I (flux pi)"] = (table["I"], "magma", None)
            marks = neutral_points_from_modes(sky.modes(sun_el), sun_el).marks(sun_az)
        plot_polar_maps(el, az, maps, args.plot, sun=(sun_el, sun_az), marks=marks,
                        title=f"{args.model} sky")
        print(f"wrote {args.plot}")
    if not args.out and not args.plot:
        print(_frame(table).describe().to_string())
    return 0


def _frame(columns: dict):
    import pandas as pd
    return pd.DataFrame(columns)


def _write_parquet(path, columns: dict) -> None:
    """Float numpy columns to Parquet through pyarrow's buffers (zero-copy; ``pa.array`` would
    import pandas, 0.3-0.5 s, only to check for pandas types)."""
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq
    arrays = [pa.Array.from_buffers(pa.from_numpy_dtype(v.dtype), v.size,
                                    [None, pa.py_buffer(np.ascontiguousarray(v))])
              for v in columns.values()]
    pq.write_table(pa.Table.from_arrays(arrays, names=list(columns)), path)


def _sample(args) -> int:
    import numpy as np
    import pandas as pd

    from experiments.yang2014 import ERROR_MODEL
    from sensor.daq import Daq
    from sensor.errors import OpponentErrors
    from sensor.opponent import OpponentSensor, zenith_polarization
    from skysim.sky import make_sky
    from skysim.sun import Site

    rng = np.random.default_rng(args.seed)
    site = Site(args.lat, args.lon, args.alt)
    if args.errors == "none":
        errors = OpponentErrors()
    elif args.errors == "random":
        m = ERROR_MODEL
        errors = OpponentErrors.draw(rng, misalignment_max_deg=m.misalignment_max_deg,
                                     transmittance_sd=m.transmittance_sd,
                                     noise_range_V=m.noise_range_V,
                                     turntable_error_deg=m.turntable_error_deg)
    else:
        errors = OpponentErrors.from_dict(json.loads(Path(args.errors).read_text()))
    start = pd.Timestamp(args.start)
    times = pd.DatetimeIndex(start + pd.to_timedelta(np.linspace(0, args.duration, args.n),
                                                     unit="s"))
    sky = make_sky("rayleigh", dmax=args.dmax)
    _, _, _, sun_az0 = zenith_polarization(sky, site, times[:1], [0.0])
    headings = sun_az0[0] - 90.0 + np.linspace(0.0, 180.0, args.n, endpoint=False)
    sensor = OpponentSensor(errors, daq=Daq(None if args.no_daq else 16, 10.0))
    meas = sensor.sample(sky, site, times, headings, rng, seed=args.seed)
    meas.write(args.out)
    print(f"wrote {args.n} samples to {args.out} (+ sidecar); injected errors: "
          f"{json.dumps(errors.to_dict())}")
    return 0


def _calibrate(args) -> int:
    import pandas as pd

    from calibration.pipeline import calibrate_measurement
    from sensor.measurement import read_measurement
    from skysim.io import write_json_atomic

    meas = read_measurement(args.file)
    result = calibrate_measurement(meas)
    rows = pd.DataFrame(result.summary_rows())
    pd.set_option("display.width", 200)
    print(f"LSM compensation (Yang et al. 2014, eqs. 10-14) of {args.file}: "
          f"{len(meas.table)} samples")
    print(rows.to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    if args.out:
        write_json_atomic(args.out, {"file": str(args.file),
                                     "pairs": [c.to_dict() for c in result.pairs.values()],
                                     "summary": result.summary_rows()})
        print(f"wrote {args.out}")
    return 0


def register(sub) -> None:
    p = sub.add_parser("sky", help="sky polarization as ground truth (DoP, AoP, Stokes)",
                       description="Evaluate a sky model for view directions. " + AOP_CONVENTION,
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--lat", type=float, help="site latitude [deg, north +]")
    p.add_argument("--lon", type=float, help="site longitude [deg, east +]")
    p.add_argument("--alt", type=float, default=0.0, help="site altitude [m]")
    p.add_argument("--time", help="timezone-aware ISO 8601 time, e.g. 2013-05-22T17:10+08:00")
    p.add_argument("--sun-elevation", type=float, help="sun elevation [deg] (instead of site/time)")
    p.add_argument("--sun-azimuth", type=float, help="sun azimuth [deg, clockwise from north]")
    p.add_argument("--directions", help="CSV with columns elevation_deg, azimuth_deg")
    p.add_argument("--grid-step", type=float, default=2.0, help="default grid spacing [deg]")
    p.add_argument("--model", default="rayleigh", help="rayleigh | multiple | berry")
    p.add_argument("--dmax", type=float, help="rayleigh: maximum degree of polarization")
    p.add_argument("--tau", type=float, help="multiple: Rayleigh optical thickness")
    p.add_argument("--albedo", type=float, help="multiple: Lambertian ground albedo")
    p.add_argument("--wavelength-nm", type=float, help="multiple: wavelength (derives tau)")
    p.add_argument("--pressure-hPa", type=float, dest="pressure_hPa",
                   help="multiple: surface pressure with --wavelength-nm (default 1013.25)")
    p.add_argument("--delta-deg", type=float,
                   help="berry: separation of the neutral-point pairs (default 40)")
    p.add_argument("--out", help="output table (.csv or .parquet) with a JSON sidecar")
    p.add_argument("--plot", help="PNG with polar maps of DoP and AoP (multiple: also I and "
                   "the neutral points)")
    p.set_defaults(func=_sky)

    s = sub.add_parser("sample", help="simulate a three-pair sensor sweep (measurement table)",
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    s.add_argument("--out", required=True, help="output .csv or .parquet (sidecar beside it)")
    s.add_argument("--lat", type=float, default=34.1447)
    s.add_argument("--lon", type=float, default=108.5467)
    s.add_argument("--alt", type=float, default=400.0)
    s.add_argument("--start", default="2013-05-22T17:10:00+08:00", help="timezone-aware start")
    s.add_argument("--duration", type=float, default=600.0, help="sweep duration [s]")
    s.add_argument("--n", type=int, default=181, help="number of samples")
    s.add_argument("--dmax", type=float, default=0.7)
    s.add_argument("--errors", default="random",
                   help="'random' (Yang 2014 error model), 'none', or a JSON file of OpponentErrors")
    s.add_argument("--no-daq", action="store_true", help="disable 16-bit quantisation")
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=_sample)

    c = sub.add_parser("calibrate", help="LSM compensation of a measurement table",
                       description="Fit each channel pair's mounting errors, transmittance "
                                   "terms and d_max (Yang et al. 2014, eqs. 10-14).")
    c.add_argument("file", help="measurement table (.csv/.parquet) with its JSON sidecar")
    c.add_argument("--out", help="write the fitted parameters as JSON")
    c.set_defaults(func=_calibrate)
