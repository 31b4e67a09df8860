"""Time series of sky maps written block by block: ``skysim sky-series`` and its writers.

Formats (by the output's suffix):

- ``.nc``: netCDF4 (HDF5) through ``h5netcdf`` (optional extra ``skysim[series]``), dimensions
  ``time`` x ``direction``, one chunked variable per quantity; it opens as an
  ``xarray.Dataset`` (``xarray.open_dataset(path, engine="h5netcdf")``). Metadata in the
  global attributes.
- ``.parquet``: a long table, one row per (time, direction), one row group per block, with a
  JSON sidecar (schema ``skysim.skyseries/1``).

Either way the series is never held in memory: each block of suns (see
:mod:`skysim.series`) is evaluated and written, then dropped. The file appears only when
complete (written to a temporary file and renamed).
"""

from __future__ import annotations

import json
from pathlib import Path

from skysim.exceptions import (
    BroadcastError,
    InvalidParameterError,
    MissingDependencyError,
    SunBelowHorizonError,
)

__all__ = ["SERIES_SCHEMA", "write_sky_series", "register"]

SERIES_SCHEMA = "skysim.skyseries/1"

_UNITS = {"dop": ("1", "degree of linear polarization"),
          "aop_deg": ("degree", "angle of polarization from the local meridian"),
          "I": ("1", "radiance (model units, see the sky attribute)"),
          "Q": ("1", "Stokes Q in the local-meridian basis"),
          "U": ("1", "Stokes U in the local-meridian basis")}
_CHUNK_BYTES = 4 * 2**20  # netCDF chunks of ~4 MiB: whole time steps, cheap to read one


def _metadata(sky, times, n_directions, n_suns) -> dict:
    from skysim import __version__

    from .sky_options import AOP_CONVENTION
    return {"schema": SERIES_SCHEMA, "sky": sky.describe(), "aop_convention": AOP_CONVENTION,
            "n_times": int(n_suns), "n_directions": int(n_directions),
            "times": "given" if times is not None else "none (index of the sun positions)",
            "generator": f"skysim {__version__}"}


def _time_ns(times, n):
    import numpy as np
    import pandas as pd

    from skysim.sun import as_utc_index
    if times is None:
        return None
    idx = as_utc_index(pd.DatetimeIndex(times))
    if len(idx) != n:
        raise BroadcastError(f"times and sun positions differ in length: {len(idx)} vs {n}")
    return idx.as_unit("ns").asi8.astype(np.int64)


def _write_netcdf(tmp: Path, blocks, el, az, sel, saz, t_ns, dtype, chunk_rows, meta):
    try:
        import h5netcdf
    except ImportError as exc:  # pragma: no cover - depends on the environment
        from skysim.extras import missing_extra_message
        raise MissingDependencyError(
            missing_extra_message("h5netcdf", "writing a sky series as .nc (or write .parquet)"),
            name="h5netcdf") from exc
    with h5netcdf.File(tmp, "w") as f:
        f.dimensions = {"time": sel.size, "direction": el.size}
        for name, values, dim, units in (("elevation_deg", el, "direction", "degree"),
                                         ("azimuth_deg", az, "direction", "degree"),
                                         ("sun_elevation_deg", sel, "time", "degree"),
                                         ("sun_azimuth_deg", saz, "time", "degree")):
            v = f.create_variable(name, (dim,), "f8", data=values)
            v.attrs["units"] = units
        if t_ns is not None:
            v = f.create_variable("time", ("time",), "i8", data=t_ns // 1000)
            v.attrs["units"] = "microseconds since 1970-01-01T00:00:00+00:00"
            v.attrs["calendar"] = "proleptic_gregorian"
        out = {}
        for name in _UNITS:
            out[name] = f.create_variable(name, ("time", "direction"), dtype,
                                          chunks=(chunk_rows, el.size))
            out[name].attrs["units"], out[name].attrs["long_name"] = _UNITS[name]
        for key, value in meta.items():
            f.attrs[key] = value if isinstance(value, (str, int)) else json.dumps(value)
        for suns, field in blocks:
            for name, var in out.items():
                var[suns, :] = getattr(field, name)


def _write_parquet(tmp: Path, blocks, el, az, sel, saz, t_ns, dtype):
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrow_float = pa.from_numpy_dtype(np.dtype(dtype))
    columns = ([("time", pa.timestamp("ns", tz="UTC"))] if t_ns is not None else []) + [
        ("sun_elevation_deg", pa.float64()), ("sun_azimuth_deg", pa.float64()),
        ("elevation_deg", pa.float64()), ("azimuth_deg", pa.float64())] + [
        (name, arrow_float) for name in _UNITS]
    schema = pa.schema(columns)
    with pq.ParquetWriter(tmp, schema) as writer:
        for suns, field in blocks:
            k = suns.stop - suns.start
            data = {"sun_elevation_deg": np.repeat(sel[suns], el.size),
                    "sun_azimuth_deg": np.repeat(saz[suns], el.size),
                    "elevation_deg": np.tile(el, k), "azimuth_deg": np.tile(az, k)}
            if t_ns is not None:
                data["time"] = pa.array(np.repeat(t_ns[suns], el.size), schema.field("time").type)
            for name in _UNITS:
                data[name] = np.ascontiguousarray(getattr(field, name)).reshape(-1)
            writer.write_table(pa.table(data, schema=schema))


def write_sky_series(path, sky, view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                     sun_azimuth_deg, times=None, max_block_bytes=None,
                     progress: bool = False) -> dict:
    """Evaluate ``sky`` for every sun and direction and write it block by block.

    Parameters
    ----------
    path : str or Path
        ``.nc`` (netCDF4 via h5netcdf) or ``.parquet`` (long table + JSON sidecar).
    sky : skysim.sky.Sky
        The sky model (``RayleighSky(dmax, dtype="float32")`` stores float32 quantities).
    view_elevation_deg, view_azimuth_deg : array (N,)
        View directions [deg].
    sun_elevation_deg, sun_azimuth_deg : array (T,)
        Sun positions [deg], one per time step.
    times : DatetimeIndex-like (T,), optional
        Timezone-aware times of the sun positions (stored as UTC).
    max_block_bytes : int, optional
        Memory budget of one block [bytes] (default
        :data:`skysim.series.DEFAULT_MAX_BLOCK_BYTES`).
    progress : bool
        Show a progress bar of the blocks on stderr (when there are several).

    Returns
    -------
    dict with ``path``, ``n_times``, ``n_directions``, ``block_suns`` and ``n_blocks``.

    Raises
    ------
    InvalidParameterError
        For an unsupported suffix, mismatched inputs, naive times or a sun below the horizon
        (nothing is written then).
    skysim.io.WriteError
        If the file system has no room for the series (checked before writing), or a write
        fails part-way (the temporary file is removed).
    """
    import numpy as np

    from skysim.io import atomic_write_many, check_free_space, sidecar_path
    from skysim.series import DEFAULT_MAX_BLOCK_BYTES, iter_sky_series, suns_per_block

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".nc", ".parquet"):
        raise InvalidParameterError(
            f"a sky series is written to .nc or .parquet; got {path.name!r}")
    budget = DEFAULT_MAX_BLOCK_BYTES if max_block_bytes is None else int(max_block_bytes)
    el, az, sel, saz = (np.asarray(a, dtype=float).reshape(-1) for a in (
        view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg))
    dtype = np.dtype(getattr(sky, "dtype", np.float64))
    block = min(suns_per_block(el.size, budget, dtype.itemsize), max(sel.size, 1))
    chunk_rows = max(1, min(block, _CHUNK_BYTES // (dtype.itemsize * max(el.size, 1))))
    block -= block % chunk_rows  # whole chunks per block: no chunk is written twice
    t_ns = _time_ns(times, sel.size)
    check_free_space(path, sel.size * el.size * series_bytes_per_value(
        suffix, dtype.itemsize, t_ns is not None), f"{sel.size} time steps x {el.size} directions")
    meta = _metadata(sky, times, el.size, sel.size)
    blocks = iter_sky_series(sky, el, az, sel, saz, budget, block_suns=block)
    n_blocks = -(-sel.size // block)
    if progress and n_blocks > 1:
        from tqdm import tqdm
        blocks = tqdm(blocks, total=n_blocks, desc="sky-series", unit="block")
    if suffix == ".nc":
        items = [(path, lambda tmp: _write_netcdf(tmp, blocks, el, az, sel, saz, t_ns, dtype,
                                                  chunk_rows, meta))]
    else:
        items = [(path, lambda tmp: _write_parquet(tmp, blocks, el, az, sel, saz, t_ns, dtype)),
                 (sidecar_path(path), lambda tmp: tmp.write_text(json.dumps(meta, indent=2)))]
    atomic_write_many(items)
    return {"path": str(path), "n_times": int(sel.size), "n_directions": int(el.size),
            "block_suns": int(block), "n_blocks": n_blocks}


SERIES_BYTES_PER_TIME = 200
"""Peak memory per time step before the blocks [bytes]: the times, the sun positions and
their frame (tracemalloc peak 115 B per time step at 2e5 steps), rounded up."""

SECONDS_PER_VALUE = {".nc": 0.6e-6, ".parquet": 2.0e-6}
"""Time to evaluate and write one (time, direction) point of a single-scattering sky
[s]: measured 0.55 us (.nc) and 1.8 us (.parquet) per point in float64 over 8280 directions,
0.3 us (.nc) over 130,320 directions, on a shared 2-core machine; rounded up."""

ENGINE_CALL_S = 6.0
"""Time of ``--model multiple`` per time step [s]: one radiative-transfer solution per
distinct sun elevation (16 s measured for 3 hourly suns over 360 directions)."""


def series_bytes_per_value(suffix: str, itemsize: int, with_times: bool = True) -> int:
    """Bytes on disk per (time, direction) point, uncompressed: the five quantities, and for
    Parquet the four angle columns and the time of every row [bytes]."""
    per = len(_UNITS) * itemsize
    if suffix == ".parquet":
        per += 4 * 8 + (8 if with_times else 0)
    return per


def _count_times(args) -> int:
    """Number of time steps the options ask for, computed without building them."""
    import pandas as pd

    from .options import PANDAS_YEARS
    if args.periods is None and args.end is None:
        raise InvalidParameterError("give the times as --start with --end or --periods")
    if args.periods is not None and args.end is not None:
        raise InvalidParameterError("give --end or --periods, not both")
    step = (args.start + args.freq) - args.start
    if args.end is not None:
        if args.end < args.start:
            raise InvalidParameterError(f"--end {args.end.isoformat()} is before --start "
                                        f"{args.start.isoformat()}")
        return int((args.end - args.start) // step) + 1
    last_ns = args.start.value + (args.periods - 1) * step.value
    if not last_ns < pd.Timestamp(f"{PANDAS_YEARS[1] + 1}-01-01", tz="UTC").value:
        freq = args.freq.freqstr if args.freq.freqstr[0].isdigit() else f"1{args.freq.freqstr}"
        raise InvalidParameterError(
            f"--periods {args.periods} of --freq {freq} from --start "
            f"{args.start.isoformat()} run beyond the supported years "
            f"{PANDAS_YEARS[0]}-{PANDAS_YEARS[1]}; use fewer --periods or a "
            "shorter --freq")
    return args.periods


def _check_size(args, n_times: int, n_directions: int, itemsize: int) -> None:
    """Refuse a series that does not fit the memory or the disk, and say how long it takes."""
    from skysim.io import check_free_space
    from skysim.resources import check_memory, format_count
    from skysim.series import VALUES_PER_POINT

    from .progress import check_duration
    from .sky_options import SKY_BYTES_PER_DIRECTION
    directions = f"{format_count(n_directions)} directions"
    what = f"{format_count(n_times)} time steps x {directions}"
    n_directions = float(min(n_directions, 10**300))
    budget = args.max_memory_mb * 2**20
    check_memory(n_times * SERIES_BYTES_PER_TIME + n_directions * SKY_BYTES_PER_DIRECTION
                 + budget, what, "use fewer time steps (--periods, or an earlier --end or a "
                 "longer --freq), a coarser --grid-step or a smaller --max-memory-mb")
    one_step = VALUES_PER_POINT * itemsize * n_directions
    if budget < one_step:
        raise InvalidParameterError(
            f"--max-memory-mb {args.max_memory_mb:g} is below the arrays of one "
            f"time step ({one_step / 2**20:.3g} MiB for {directions}); raise it "
            "or use fewer directions")
    suffix = Path(args.out).suffix.lower()
    check_free_space(args.out, n_times * n_directions * series_bytes_per_value(suffix, itemsize),
                     what)
    seconds = n_times * n_directions * SECONDS_PER_VALUE[suffix] * itemsize / 8
    if args.model == "multiple":
        seconds += n_times * ENGINE_CALL_S
    check_duration(seconds, f"skysim sky-series: {what}",
                      "fewer --periods, a coarser --grid-step or --float32 make it shorter")


def _sky_series(args) -> int:
    import numpy as np
    import pandas as pd

    from skysim.geometry import sky_grid_size
    from skysim.sky import make_sky
    from skysim.sun import Site, sun_position

    from .options import refuse_replacing_inputs, with_sidecar
    from .sky_options import model_sky, sky_params, view_directions
    refuse_replacing_inputs(with_sidecar("--out", args.out),
                            [("--directions", args.directions)])
    site = Site(args.lat, args.lon, args.alt)
    params = sky_params(args)
    if args.float32:
        if args.model != "rayleigh":
            raise InvalidParameterError(
                f"--float32 is available for --model rayleigh; got --model "
                f"{args.model}")
        params["dtype"] = "float32"
    itemsize = 4 if args.float32 else 8
    n_times = _count_times(args)
    n_dir = None if args.directions else sky_grid_size(args.grid_step)
    _check_size(args, n_times, n_dir or 1, itemsize)   # before the times are built
    sky = model_sky(args.model, params)
    times = pd.date_range(start=args.start, end=args.end, periods=args.periods,
                          freq=args.freq)
    pos = sun_position(times, site.latitude_deg, site.longitude_deg, site.altitude_m)
    sel, saz = pos.elevation_deg.to_numpy(float), pos.azimuth_deg.to_numpy(float)
    if args.daylight_only:
        day = sel > 0.0
        print(f"{int((~day).sum())} of {len(times)} times have the sun down; left out")
        times, sel, saz = times[day], sel[day], saz[day]
        if not day.any():
            raise SunBelowHorizonError(
                f"the sun is below the horizon at all {day.size} time steps "
                f"from {args.start.isoformat()}; choose daytime at this site "
                "(check the UTC offset)")
    el, az = view_directions(args.directions, args.grid_step)
    if n_dir is None:
        _check_size(args, len(times), el.size, itemsize)
    info = write_sky_series(args.out, sky, el, az, sel, saz, times=times,
                            max_block_bytes=int(args.max_memory_mb * 2**20), progress=True)
    print(f"wrote {info['n_times']} times x {info['n_directions']} directions to {args.out} "
          f"in {info['n_blocks']} block(s) of up to {info['block_suns']} times "
          f"(budget {args.max_memory_mb:g} MiB)")
    return 0


def register(sub) -> None:
    from .options import (DefaultsHelpFormatter, aware_time, existing_file, float_in,
                          output_file, positive_float, positive_int, time_step)
    from .sky_options import add_sky_model_options
    p = sub.add_parser("sky-series", help="time series of sky maps (many suns x many "
                       "directions), streamed to netCDF or Parquet",
                       description="Evaluate a sky model for every time step and view "
                                   "direction, block by block within a memory budget. The "
                                   "size (memory, disk) is checked before any work; runs "
                                   "longer than about 10 s state their expected duration.",
                       formatter_class=DefaultsHelpFormatter)
    p.add_argument("--lat", type=float_in(-90, 90, unit="deg"), required=True,
                   help="site latitude [deg, north +]")
    p.add_argument("--lon", type=float_in(-180, 360, unit="deg"), required=True,
                   help="site longitude [deg, east +]")
    p.add_argument("--alt", type=float_in(-500, 9000, unit="m"), default=0.0,
                   help="site altitude [m]")
    p.add_argument("--start", type=aware_time, required=True,
                   help="timezone-aware ISO 8601 start time, e.g. 2013-05-22T06:00+08:00")
    p.add_argument("--end", type=aware_time,
                   help="timezone-aware ISO 8601 end time, inclusive (or give --periods)")
    p.add_argument("--periods", type=positive_int,
                   help="number of time steps, >= 1 (or give --end)")
    p.add_argument("--freq", type=time_step, default="1min",
                   help="time step, a positive pandas offset: 1s, 10min, 1h, 1D")
    p.add_argument("--daylight-only", action="store_true",
                   help="leave out the times with the sun at or below the horizon")
    p.add_argument("--directions", type=existing_file,
                   help="CSV with columns elevation_deg, azimuth_deg [deg] (instead of a grid)")
    p.add_argument("--grid-step", type=float_in(0, 90, low_open=True, unit="deg"), default=2.0,
                   help="spacing of the elevation-azimuth grid [deg]")
    add_sky_model_options(p.add_argument_group("sky model"))
    p.add_argument("--float32", action="store_true",
                   help="rayleigh: float32 arithmetic and storage (AoP within 1e-3 deg beyond "
                        "2 deg from the sun, DoP within 1e-5)")
    p.add_argument("--max-memory-mb", type=positive_float, default=256.0,
                   help="memory budget of one block of times [MiB]")
    p.add_argument("--out", type=output_file(".nc", ".parquet"), required=True,
                   help="output .nc (netCDF4, needs the series extra) or .parquet (with a "
                        "JSON sidecar <out>.json)")
    p.set_defaults(func=_sky_series)
