"""Foundation commands: ``skysim sky`` (lit by the Sun or the Moon), ``skysim sample`` and
``skysim calibrate``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from skysim.bands import BANDS
from skysim.exceptions import InvalidParameterError
from experiments.workflows.options import (PANDAS_YEARS, DefaultsHelpFormatter, aware_time,
                                           data_file_and_sidecars, existing_file, float_in,
                                           output_dir, output_file, positive_float,
                                           positive_int,
                                           refuse_replacing_inputs, seed, with_sidecar)
from experiments.workflows.sky_options import (AEROSOL_PRESETS as _AEROSOL_PRESETS,  # noqa: F401
                                               AOP_CONVENTION, MODEL_OPTIONS,
                                               SAMPLE_BYTES_PER_SAMPLE, SAMPLE_SECONDS_PER_SAMPLE,
                                               add_sky_model_options, read_directions,
                                               model_sky, sky_params, sky_seconds,
                                               view_directions)

__all__ = ["register", "read_directions", "view_directions", "AOP_CONVENTION", "MODEL_OPTIONS"]


# --------------------------------------------------------------------------- --source moon
class _MoonlitSkyMap:
    """``skysim sky --source moon``: the night sky of one time as the command's sky."""

    def __init__(self, args, params: dict):
        from skysim.sky import make_sky
        from skysim.sun import Site
        self.site = Site(args.lat, args.lon, args.alt)
        self.time, self.band = args.time, args.band
        if "response" in params:
            raise InvalidParameterError(
                f"--response {params['response']} weights a sunlit sky over wavelength; the "
                "night sky's band is --band (B, V, R or I)")
        if args.model == "multiple" and "tau" not in params and "wavelength_nm" not in params:
            from skysim.bands import get_band
            params = {**params, "wavelength_nm": get_band(args.band).wavelength_nm}
        self.pattern = make_sky(args.model, **params)

    def field(self, view_elevation_deg, view_azimuth_deg, *_source):
        from skysim.night import night_sky
        return night_sky(view_elevation_deg, view_azimuth_deg, self.time, self.site,
                         self.band, self.pattern).field

    def describe(self) -> dict:
        return {"model": "night", "source": "moon", "band": self.band,
                "pattern": self.pattern.describe(), "radiance_unit": "W m-2 nm-1 sr-1",
                "radiance": "Krisciunas & Schaefer (1991) moonlit sky with ROLO lunar "
                            "irradiance, the Sun's light added when up, night-sky background "
                            "of the band (skysim.night)"}

    def title(self, moon_elevation_deg: float, moon_azimuth_deg: float) -> str:
        return (f"night sky ({self.pattern.name} pattern), {self.band} band; moon elevation "
                f"{moon_elevation_deg:.1f}°, azimuth {moon_azimuth_deg:.1f}°")


def moon_sky(args, params: dict):
    """For ``skysim sky --source moon``: ``(sky, moon elevation, moon azimuth, info)``."""
    if args.lat is None or args.lon is None or args.time is None:
        raise InvalidParameterError("--source moon needs --lat --lon --time (timezone-aware ISO 8601)")
    if args.sun_elevation is not None or args.sun_azimuth is not None:
        raise InvalidParameterError("--sun-elevation/--sun-azimuth give the Sun; with --source moon the "
                         "Moon's position follows from --lat --lon --time")
    from skysim.moon import moon_position
    sky = _MoonlitSkyMap(args, params)
    pos = moon_position([args.time], sky.site.latitude_deg, sky.site.longitude_deg,
                        sky.site.altitude_m).iloc[0]
    if not pos.elevation_deg > 0.0:
        raise InvalidParameterError(f"--source moon: the Moon is at {pos.elevation_deg:.1f} deg elevation "
                         f"at --time {args.time.isoformat()} and --lat {args.lat:g} --lon "
                         f"{args.lon:g}, below the horizon; choose a time when the Moon is up")
    info = {"site": sky.site.to_dict(), "time": args.time.isoformat(), "source": "moon",
            "elevation_deg": float(pos.elevation_deg), "azimuth_deg": float(pos.azimuth_deg),
            "phase_angle_deg": float(pos.phase_angle_deg),
            "illuminated_fraction": float(pos.illuminated_fraction)}
    return sky, float(pos.elevation_deg), float(pos.azimuth_deg), info


def _refuse_two_suns(args) -> None:
    """The sun's position is given once: by --sun-elevation --sun-azimuth, or by --lat --lon
    --time (a site and time given with the angles would be ignored)."""
    if args.sun_azimuth is not None and args.sun_elevation is None:
        raise InvalidParameterError(f"--sun-azimuth {args.sun_azimuth:g} needs --sun-elevation")
    if args.sun_elevation is None or args.source != "sun":
        return
    for flag, value in (("--time", args.time and args.time.isoformat()),
                        ("--lat", args.lat is not None and f"{args.lat:g}"),
                        ("--lon", args.lon is not None and f"{args.lon:g}")):
        if value:
            raise InvalidParameterError(f"{flag} {value} and --sun-elevation {args.sun_elevation:g} both "
                             "place the sun: give --sun-elevation --sun-azimuth, or --lat --lon "
                             "--time")


def _sky(args) -> int:
    # pandas, tqdm and the sun are imported only where needed: a Parquet sky map for given
    # sun angles starts in a fraction of the time
    import numpy as np

    from skysim.io import atomic_write_many, sidecar_path
    from skysim.sky import make_sky

    from experiments.workflows.cloud_options import with_clouds
    params = sky_params(args)
    refuse_replacing_inputs(with_sidecar("--out", args.out) + [("--plot", args.plot)],
                            [("--directions", args.directions)])
    _refuse_two_suns(args)
    sky = None
    if args.source == "moon":  # the night sky: the Moon as the source (skysim.night)
        sky, sun_el, sun_az, sun_info = moon_sky(args, params)
    elif args.sun_elevation is not None:
        if args.sun_azimuth is None:
            raise InvalidParameterError("--sun-elevation needs --sun-azimuth")
        sun_el, sun_az, sun_info = args.sun_elevation, args.sun_azimuth, {
            "elevation_deg": args.sun_elevation, "azimuth_deg": args.sun_azimuth}
    else:
        if args.lat is None or args.lon is None or args.time is None:
            raise InvalidParameterError("give the sun as --lat --lon --time (timezone-aware ISO 8601) "
                             "or as --sun-elevation --sun-azimuth")
        from skysim.sun import Site, sun_position
        site = Site(args.lat, args.lon, args.alt)
        pos = sun_position([args.time], site.latitude_deg, site.longitude_deg, site.altitude_m)
        sun_el, sun_az = float(pos.elevation_deg.iloc[0]), float(pos.azimuth_deg.iloc[0])
        sun_info = {"site": site.to_dict(), "time": args.time.isoformat(),
                    "elevation_deg": sun_el, "azimuth_deg": sun_az}
    if sky is not None and args.clouds is not None:
        raise InvalidParameterError("--clouds needs the sunlit sky (--source sun): the clouds are lit by "
                         "the Sun")
    sky = with_clouds(model_sky(args.model, params), args) if sky is None else sky
    el, az = view_directions(args.directions, args.grid_step)
    from experiments.workflows.progress import check_duration
    check_duration(sky_seconds(el.size, "moon" if args.source == "moon" else args.model,
                               args.out), f"skysim sky: {el.size} directions",
                   "give fewer directions or a coarser --grid-step, or write .parquet")
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
        sidecar = {"schema": "skysim.skymap/1", "sky": sky.describe(), "sun": sun_info,
                   "aop_convention": AOP_CONVENTION, "n_directions": int(el.size)}
        writer = (lambda p: _frame(table).to_csv(p, index=False)) \
            if out.suffix.lower() == ".csv" else (lambda p: _write_parquet(p, table))
        atomic_write_many([(out, writer), (sidecar_path(out),
                                           lambda p: p.write_text(json.dumps(sidecar, indent=2)))])
        print(f"wrote {el.size} directions to {out}")
    if args.plot:
        from experiments.plotting.polar_maps import plot_polar_maps, sky_title
        maps = {"DoP": (table["dop"], "viridis", (0, 1)),
                "AoP [deg]": (table["aop_deg"], "twilight", (-90, 90))}
        marks = None
        if args.model == "multiple":  # radiance (flux pi)
            maps["I (flux pi)"] = (table["I"], "magma", None)
        if args.model == "aerosol" or args.clouds:  # log scale: bright aureole and clouds
            unit = "relative" if args.model in ("rayleigh", "berry") else "flux pi"
            maps[f"log10 I ({unit})"] = (np.log10(table["I"]), "magma", None)
        if args.model == "multiple" and args.source == "sun" and not args.clouds:
            # and the neutral points of the clear sky
            from skysim.neutral_points import neutral_points_from_modes
            marks = neutral_points_from_modes(sky.modes(sun_el), sun_el).marks(sun_az)
        plot_polar_maps(el, az, maps, args.plot, sun=(sun_el, sun_az), marks=marks,
                        title=sky_title(sky.describe(), sun_el, sun_az) if args.source == "sun"
                        else sky.title(sun_el, sun_az))
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

    from sensor.daq import Daq
    from sensor.opponent import OpponentSensor, zenith_polarization
    from skysim.sky import make_sky
    from skysim.sun import Site

    from skysim.resources import check_memory

    from experiments.workflows.cloud_options import with_clouds
    interval = args.duration + 60.0 if args.sweep_interval is None else args.sweep_interval
    if args.sweeps > 1 and interval < args.duration:
        raise InvalidParameterError(f"--sweep-interval {interval:g} s is shorter than --duration "
                         f"{args.duration:g} s: one sensor cannot do overlapping sweeps")
    refuse_replacing_inputs(with_sidecar("--out", args.out),
                            [("--errors", args.errors if args.errors not in ("random", "none")
                              else None)])
    total = args.n * args.sweeps
    check_memory(total * SAMPLE_BYTES_PER_SAMPLE, f"{total} samples (--n {args.n} x "
                 f"--sweeps {args.sweeps})", "use fewer samples or sweeps")
    from experiments.workflows.progress import check_duration
    check_duration(total * SAMPLE_SECONDS_PER_SAMPLE, f"skysim sample: {total} samples",
                   "fewer --n or --sweeps make it shorter")
    rng = np.random.default_rng(args.seed)
    site = Site(args.lat, args.lon, args.alt)
    errors = _sensor_errors(args.errors, rng)
    # sweep k starts k * interval after --start; each sweeps the heading over 180 deg from
    # 90 deg counter-clockwise of the sun at its own start (as the paper's groups a, b, c)
    offsets_s = (np.arange(args.sweeps)[:, None] * interval
                 + np.linspace(0.0, args.duration, args.n)[None, :])
    try:
        end = args.start + pd.Timedelta(seconds=float(offsets_s.max()))  # pandas' range
    except (OverflowError, ValueError):    # beyond what a pandas time difference holds
        end = pd.Timestamp.max.tz_localize("UTC")
    if end.year > PANDAS_YEARS[1]:
        raise InvalidParameterError(f"the last sample ({end}) is beyond the supported years "
                         f"{PANDAS_YEARS[0]}-{PANDAS_YEARS[1]}; shorten --duration, "
                         "--sweeps or --sweep-interval")
    times = pd.DatetimeIndex(args.start + pd.to_timedelta(offsets_s.ravel(), unit="s"))
    clear = make_sky("rayleigh", dmax=args.dmax)
    _, _, _, sun_az0 = zenith_polarization(clear, site, times[::args.n], np.zeros(args.sweeps))
    sky = with_clouds(clear, args, times)
    headings = (sun_az0[:, None] - 90.0
                + np.linspace(0.0, 180.0, args.n, endpoint=False)[None, :]).ravel()
    sweep = np.repeat(np.arange(args.sweeps), args.n)
    sensor = OpponentSensor(errors, daq=Daq(None if args.no_daq else 16, 10.0))
    meas = sensor.sample(sky, site, times, headings, rng, seed=args.seed,
                         sweep=sweep if args.sweeps > 1 else None)
    meas.write(args.out)
    print(f"wrote {total} samples ({args.sweeps} sweep(s) of {args.n}) to {args.out} "
          f"(+ sidecar); injected errors: {json.dumps(errors.to_dict())}")
    return 0


def _sensor_errors(spec: str, rng):
    """``--errors``: 'random' (the Yang 2014 error model), 'none' or a JSON file."""
    from sensor.errors import OpponentErrors
    from sensor.yang2014 import ERROR_MODEL
    if spec == "none":
        return OpponentErrors()
    if spec == "random":
        return ERROR_MODEL.draw_errors(rng)
    path = existing_file_or_error(spec, "--errors")
    try:
        d = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InvalidParameterError(f"--errors {path}: not valid JSON ({exc})") from None
    return OpponentErrors.from_dict(d, where=f"--errors {path}")


def existing_file_or_error(text: str, flag: str) -> Path:
    """``text`` as the path of an existing file, or a ``ValueError`` naming ``flag``."""
    try:
        return existing_file(text)
    except argparse.ArgumentTypeError as exc:
        raise InvalidParameterError(f"{flag}: {exc} (or give 'random' or 'none')") from None


def _calibrate(args) -> int:
    import pandas as pd

    from calibration.pipeline import calibrate_measurement
    from sensor.measurement import read_measurement
    from skysim.io import write_json_atomic

    refuse_replacing_inputs([("--out", args.out)],
                            [("file", p) for p in data_file_and_sidecars(args.file)])
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
    from experiments.workflows.cloud_options import add_cloud_options
    fmt = DefaultsHelpFormatter
    p = sub.add_parser("sky", help="sky polarization as ground truth (DoP, AoP, Stokes)",
                       description="Evaluate a sky model for view directions. " + AOP_CONVENTION,
                       formatter_class=fmt)
    p.add_argument("--lat", type=float_in(-90, 90, unit="deg"),
                   help="site latitude [deg, north +]")
    p.add_argument("--lon", type=float_in(-180, 360, unit="deg"),
                   help="site longitude [deg, east +]")
    p.add_argument("--alt", type=float_in(-500, 9000, unit="m"), default=0.0,
                   help="site altitude [m]")
    p.add_argument("--time", type=aware_time,
                   help="timezone-aware ISO 8601 time, e.g. 2013-05-22T17:10+08:00")
    p.add_argument("--sun-elevation", type=float_in(-90, 90, unit="deg"),
                   help="sun elevation [deg] (instead of site and time); rayleigh and berry "
                        "hold in twilight down to -10 deg, multiple and aerosol need the sun "
                        "above the horizon")
    p.add_argument("--sun-azimuth", type=float_in(unit="deg"),
                   help="sun azimuth [deg, clockwise from north]")
    p.add_argument("--source", default="sun", choices=("sun", "moon"),
                   help="light source: the Sun, or the Moon (night sky: moonlit Stokes "
                        "radiance [W m-2 nm-1 sr-1] over the night-sky background, the Sun "
                        "added when up; needs --lat --lon --time)")
    p.add_argument("--band", default="V", choices=tuple(BANDS),
                   help="--source moon: photometric band of the radiances")
    p.add_argument("--directions", type=existing_file,
                   help="CSV with columns elevation_deg, azimuth_deg [deg] (instead of a grid)")
    p.add_argument("--grid-step", type=float_in(0, 90, low_open=True, unit="deg"), default=2.0,
                   help="spacing of the elevation-azimuth grid [deg]")
    add_sky_model_options(p)
    add_cloud_options(p)
    p.add_argument("--out", type=output_file(".csv", ".parquet"),
                   help="output table (.csv or .parquet); its JSON sidecar is <out>.json")
    p.add_argument("--plot", type=output_file(".png"),
                   help="PNG with polar maps of DoP and AoP (multiple: also I and the neutral "
                        "points; aerosol and --clouds: also log10 I)")
    p.set_defaults(func=_sky)

    s = sub.add_parser("sample", help="simulate a three-pair sensor sweep (measurement table)",
                       description="Simulate the three-pair sensor of Yang et al. (2014) on a "
                                   "turntable under a single-scattering sky: each sweep turns "
                                   "the heading through 180 deg; several sweeps follow each "
                                   "other (column 'sweep').",
                       formatter_class=fmt)
    s.add_argument("--out", required=True, type=output_file(".csv", ".parquet"),
                   help="output table (.csv or .parquet); its JSON sidecar is <out>.json")
    s.add_argument("--lat", type=float_in(-90, 90, unit="deg"), default=34.1447,
                   help="site latitude [deg, north +]")
    s.add_argument("--lon", type=float_in(-180, 360, unit="deg"), default=108.5467,
                   help="site longitude [deg, east +]")
    s.add_argument("--alt", type=float_in(-500, 9000, unit="m"), default=400.0,
                   help="site altitude [m]")
    s.add_argument("--start", type=aware_time, default="2013-05-22T17:10:00+08:00",
                   help="timezone-aware ISO 8601 start of the first sweep")
    s.add_argument("--duration", type=positive_float, default=600.0,
                   help="duration of one sweep [s], > 0 (the turntable takes time to turn)")
    s.add_argument("--n", type=positive_int, default=181, help="samples per sweep")
    s.add_argument("--sweeps", type=positive_int, default=1,
                   help="number of sweeps (e.g. 3 for a diagnosis with held-out sweeps)")
    s.add_argument("--sweep-interval", type=positive_float, default=None,
                   help="time from one sweep's start to the next [s] (default: --duration "
                        "+ 60)")
    s.add_argument("--dmax", type=float_in(0, 1, low_open=True, high_open=True), default=0.7,
                   help="maximum degree of polarization of the sky (skysim sky: 1)")
    s.add_argument("--errors", default="random",
                   help="sensor errors: 'random' (Yang 2014 error model), 'none', or a JSON "
                        "file with misalignment_deg (6 values) [deg], transmittance (3) "
                        "[log10], noise_V (3) [V], turntable_error_deg [deg]")
    s.add_argument("--no-daq", action="store_true",
                   help="no 16-bit quantisation of the outputs (+/-10 V range)")
    add_cloud_options(s, wind=True)
    s.add_argument("--seed", type=seed, default=0, help="random seed, >= 0")
    s.set_defaults(func=_sample)

    c = sub.add_parser("calibrate", help="LSM compensation of a measurement table",
                       description="Fit each channel pair's mounting errors, transmittance "
                                   "terms and d_max (Yang et al. 2014, eqs. 10-14).")
    c.add_argument("file", type=existing_file,
                   help="measurement table (.csv/.parquet) with its JSON sidecar")
    c.add_argument("--out", type=output_file(".json"),
                   help="write the fitted parameters as JSON (.json; not the table's sidecar)")
    c.set_defaults(func=_calibrate)

    m = sub.add_parser("identifiability", help="can the gap diagnosis tell its effects apart?",
                       description="Simulate each default candidate effect of an instrument "
                                   "at two strengths, and clean data; diagnose each with all "
                                   "candidates and with the true effect withheld; write the "
                                   "verdict table and the parameter z-scores.",
                       formatter_class=fmt)
    m.add_argument("--instrument", required=True,
                   choices=("three-pair", "ring", "camera", "sky"),
                   help="instrument whose default candidates are simulated and diagnosed")
    m.add_argument("--quick", action="store_true",
                   help="one noise seed and the strong strength only")
    m.add_argument("--z-draws", type=int, default=0, metavar="N",
                   help="also diagnose each candidate alone over N noise draws of its own "
                        "and write the RMS of its parameters' z-scores with a bootstrap "
                        "interval (z_over_draws.csv): one seed's few z-scores cannot tell a "
                        "calibrated uncertainty from one off by a factor of two")
    m.add_argument("--out", type=output_dir, default=Path("results/identifiability"),
                   help="output folder")
    m.set_defaults(func=_identifiability)


def _identifiability(args) -> int:
    from calibration.diagnosis.identifiability import write_matrix
    s = write_matrix(args.instrument, args.out, quick=args.quick, z_draws=args.z_draws)
    print(f"named or in group {s['found_rate']:.0%}, clean none {s['clean_none_rate']:.0%}, "
          f"withheld never a single effect {s['withheld_ok_rate']:.0%}; wrote "
          f"{args.out / 'identifiability.md'}")
    for e, r in s.get("z_over_draws", {}).items():
        print(f"  {e}: z RMS {r['rms']:.2f} ({r['rms_low']:.2f}-{r['rms_high']:.2f}) over "
              f"{r['draws']} draws")
    return 0
