"""The sky options shared by the commands that evaluate a sky model (``skysim sky``,
``sky-series``, ``generate``): the models and their options, the view directions (a CSV or
the full-sky grid) with their memory and time, and the AoP convention of the outputs."""

from __future__ import annotations

from pathlib import Path

from skysim.exceptions import FileFormatError, InvalidParameterError

from .options import float_in, positive_float

__all__ = ["AEROSOL_PRESETS", "AOP_CONVENTION", "MODEL_OPTIONS", "SAMPLE_BYTES_PER_SAMPLE",
           "SAMPLE_SECONDS_PER_SAMPLE", "SKY_BYTES_PER_DIRECTION", "SKY_SECONDS_PER_DIRECTION",
           "SKY_WRITE_SECONDS_PER_DIRECTION", "add_sky_model_options", "read_directions",
           "model_sky", "sky_params", "sky_seconds", "view_directions"]

MODEL_OPTIONS = {"rayleigh": ("dmax",),
                 "multiple": ("tau", "albedo", "wavelength_nm", "pressure_hPa", "response"),
                 "berry": ("delta_deg", "dmax"),
                 "aerosol": ("preset", "aod_550", "albedo", "wavelength_nm", "pressure_hPa",
                             "response")}
"""The ``skysim sky`` options of each sky model (attribute names of the parsed arguments)."""

SKY_BYTES_PER_DIRECTION = 400
"""Peak memory of ``skysim sky`` per view direction [bytes]: the grid, seven float64 columns
in the chunks and again in the joined table, the writer's copy; tracemalloc peak 170 B (CSV)
and 130 B (Parquet) per direction at 520 k directions, 290 B at 130 k; rounded up."""

SKY_SECONDS_PER_DIRECTION = {"rayleigh": 0.1e-6, "berry": 1.0e-6, "multiple": 0.3e-6,
                             "aerosol": 0.3e-6, "moon": 2.0e-6}
"""Time of ``skysim sky`` per view direction for each model's field [s] (measured in chunks
of 1e5 on a shared 2-core machine: rayleigh 0.03, berry 0.48, multiple 0.15 us; doubled,
aerosol as multiple once its engine runs are done, the moonlit sky as berry)."""

SKY_WRITE_SECONDS_PER_DIRECTION = {".csv": 12.0e-6, ".parquet": 0.4e-6}
"""Time to write one row of ``skysim sky --out`` [s]: pandas CSV of seven floats took
5.6 us per row at 3e5 rows on a 2-core machine with one core free, 29 us with both cores
busy (``skysim sky`` with 1e6 and 3e6 directions: 33 and 85 s then); twice the first here.
Parquet through pyarrow's buffers is about 30x faster."""

SAMPLE_BYTES_PER_SAMPLE = 1000
"""Peak memory of ``skysim sample`` per sample [bytes] (times, sun vectors, Stokes, channels,
the table and its CSV text): tracemalloc peak 343 B per sample at 1e5 samples, 1.1 kB at
2e4 (fixed costs included); about 3x the large-run value."""

AEROSOL_PRESETS = ("continental_clean", "continental_average", "urban", "maritime_clean",
                    "desert")
"""Keys of ``skysim.aerosol_types.PRESETS`` (listed here so that ``--help`` needs no import;
a test checks that they match)."""

SAMPLE_SECONDS_PER_SAMPLE = 40e-6
"""Time of ``skysim sample`` per sample [s]: 20 us measured between 2e3 and 2e5 samples (CSV
out) on a shared 2-core machine; doubled."""

AOP_CONVENTION = (
    "AoP (aop_deg) is the E-vector orientation measured from the local meridian (the "
    "direction towards the zenith along the meridian) positive towards increasing azimuth, "
    "i.e. clockwise as seen by an observer looking along the view direction, wrapped to "
    "[-90, 90). Q = I dop cos(2 aop), U = I dop sin(2 aop) in that basis. Azimuths are "
    "clockwise from geographic north; at the zenith the meridian is that of the row's azimuth.")


def read_directions(path):
    """View directions from a CSV with columns ``elevation_deg`` [deg, 0-90] and
    ``azimuth_deg`` [deg].

    Raises
    ------
    ValueError
        For a folder, an empty file, missing or doubled columns, no rows, a value that is not
        a number or an elevation outside [0, 90] deg (naming the row and the value).
    """
    import numpy as np
    import pandas as pd
    path = Path(path)
    if path.is_dir():
        raise FileFormatError(f"--directions {path} is a folder; give a CSV file")
    try:
        d = pd.read_csv(path)
    except pd.errors.EmptyDataError:
        raise FileFormatError(f"--directions {path} is empty; write a CSV with the header "
                         "elevation_deg,azimuth_deg and one direction per row") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"--directions {path} is not a readable CSV ({exc})") from None
    doubled = [c for c in ("elevation_deg", "azimuth_deg") if f"{c}.1" in d.columns]
    if doubled:
        raise FileFormatError(f"--directions {path}: the column {doubled[0]} appears more than "
                         "once; keep one")
    missing = {"elevation_deg", "azimuth_deg"} - set(d.columns)
    if missing:
        raise FileFormatError(f"--directions {path}: missing column(s) {sorted(missing)}; found "
                         f"{list(d.columns)}")
    if d.empty:
        raise FileFormatError(f"--directions {path} has a header but no directions")
    cols = []
    for c in ("elevation_deg", "azimuth_deg"):
        x = pd.to_numeric(d[c], errors="coerce").to_numpy(float)
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            v = d[c].iloc[bad[0]]
            shown = repr(v) if isinstance(v, str) else v
            raise FileFormatError(f"--directions {path}: {c} in data row {bad[0] + 1} is {shown}, "
                             f"not a number ({bad.size} such value(s))")
        cols.append(x)
    low = np.flatnonzero((cols[0] < 0.0) | (cols[0] > 90.0))
    if low.size:
        raise FileFormatError(f"--directions {path}: elevation_deg in data row {low[0] + 1} is "
                         f"{cols[0][low[0]]:g}, outside [0, 90] deg (a sky seen from the "
                         f"ground; {low.size} such value(s))")
    return cols[0], cols[1]


def sky_params(args) -> dict:
    """The sky-model options given, checked against ``--model`` (another model's option is
    an error, not silently ignored)."""
    given = {k for opts in MODEL_OPTIONS.values() for k in opts
             if getattr(args, k, None) is not None}
    foreign = sorted(given - set(MODEL_OPTIONS[args.model]))
    if foreign:
        flag = _flag(foreign[0])
        owners = " or ".join(m for m, o in MODEL_OPTIONS.items() if foreign[0] in o)
        takes = ", ".join(_flag(k) for k in MODEL_OPTIONS[args.model])
        raise InvalidParameterError(f"{flag} is an option of --model {owners}; --model {args.model} "
                         f"takes {takes}")
    if args.model == "multiple" and not given & {"tau", "wavelength_nm", "response"}:
        raise InvalidParameterError("--model multiple needs --tau (Rayleigh optical thickness, "
                                    "about 0.097 at 550 nm), --wavelength-nm or --response")
    if "response" in given:
        other = sorted(given & {"tau", "wavelength_nm"})
        if other:
            raise InvalidParameterError(f"--response {args.response} and {_flag(other[0])} "
                                        "both set the wavelength; give one")
    return {k: getattr(args, k) for k in MODEL_OPTIONS[args.model] if k in given}


BAND_NODES = 8
"""Wavelengths at which a ``--response`` sky is computed (:func:`skysim.spectral.band_sky`)."""


def model_sky(model: str, params: dict):
    """The sky of ``model`` with the options of :func:`sky_params`; with ``response`` among
    them, the band-integrated sky (:func:`skysim.spectral.band_sky`, :data:`BAND_NODES` wavelengths,
    docs/spectral.md)."""
    from skysim.sky import make_sky
    params = dict(params)
    band = params.pop("response", None)
    if band is None:
        return make_sky(model, **params)
    from skysim.spectral import band_sky
    return band_sky(lambda lam: make_sky(model, wavelength_nm=lam, **params), band,
                    n_nodes=BAND_NODES)


def _flag(option: str) -> str:
    """The command-line flag of a parsed sky option (``aod_550`` -> ``--aod``)."""
    return {"preset": "--aerosol", "aod_550": "--aod"}.get(
        option, "--" + option.replace("_", "-").replace("-hpa", "-hPa"))


def view_directions(directions_csv=None, grid_step_deg: float = 2.0):
    """View directions [deg] from a CSV (:func:`read_directions`), or else the default
    full-sky grid (:func:`skysim.geometry.sky_grid`), after checking their memory."""
    from skysim.geometry import sky_grid, sky_grid_size
    from skysim.resources import check_memory, format_count
    if directions_csv:
        el, az = read_directions(directions_csv)
        check_memory(el.size * SKY_BYTES_PER_DIRECTION, f"{format_count(el.size)} sky "
                     f"directions (--directions {directions_csv})", "give fewer directions")
        return el, az
    check_memory(sky_grid_size(grid_step_deg) * SKY_BYTES_PER_DIRECTION,
                 f"{format_count(sky_grid_size(grid_step_deg))} sky directions (--grid-step "
                 f"{grid_step_deg:g})", "use a coarser --grid-step")
    return sky_grid(grid_step_deg)


def sky_seconds(n_directions: int, model: str, out=None) -> float:
    """Expected wall time of ``skysim sky`` for ``n_directions`` [s]: the field of ``model``
    (or ``"moon"``) and the writing of ``out`` (:data:`SKY_SECONDS_PER_DIRECTION`,
    :data:`SKY_WRITE_SECONDS_PER_DIRECTION`)."""
    write = SKY_WRITE_SECONDS_PER_DIRECTION.get(Path(out).suffix.lower(), 0.0) if out else 0.0
    return n_directions * (SKY_SECONDS_PER_DIRECTION[model] + write)


def add_sky_model_options(p) -> None:
    """Add ``--model`` and the options of each model (:data:`MODEL_OPTIONS`) to the parser
    ``p`` (``skysim sky``, ``sky-series``)."""
    p.add_argument("--model", default="rayleigh", choices=sorted(MODEL_OPTIONS),
                   help="sky model; berry: Berry-Dennis-Lee singularity sky, DoP "
                        "dmax |w|/(2 - |w|) (Rayleigh for delta 0), without horizon "
                        "depolarization (too high near the horizon)")
    p.add_argument("--dmax", type=float_in(0, 1, low_open=True),
                   help="rayleigh, berry: maximum degree of polarization, in (0, 1] (model "
                        "default 1)")
    p.add_argument("--tau", type=positive_float,
                   help="multiple: Rayleigh optical thickness (or give --wavelength-nm)")
    p.add_argument("--albedo", type=float_in(0, 1),
                   help="multiple, aerosol: Lambertian ground albedo [1] (model default 0)")
    p.add_argument("--wavelength-nm", type=positive_float,
                   help="multiple: wavelength [nm], sets tau instead of --tau; aerosol: "
                        "wavelength [nm] (model default 550)")
    p.add_argument("--response",
                   help="multiple, aerosol: the sky through a sensor's spectral response "
                        "instead of one wavelength: U, B, V, R or I (Johnson-Cousins, as "
                        "Gaussians of "
                        "Bessell's effective wavelength and FWHM) or a CSV of wavelength_nm, "
                        f"response; {BAND_NODES} wavelengths, each an engine run "
                        "(docs/spectral.md)")
    p.add_argument("--pressure-hPa", type=positive_float, dest="pressure_hPa",
                   help="multiple (with --wavelength-nm), aerosol: surface pressure [hPa] "
                        "(model default 1013.25)")
    p.add_argument("--aerosol", dest="preset", choices=sorted(AEROSOL_PRESETS),
                   help="aerosol: aerosol type, OPAC mixture (model default "
                        "continental_average)")
    p.add_argument("--aod", dest="aod_550", type=float_in(0, 2),
                   help="aerosol: aerosol optical depth at 550 nm [1] (model default 0.1)")
    p.add_argument("--delta-deg", type=float_in(0, 90, low_open=True, high_open=True,
                                                unit="deg"),
                   help="berry: separation of the neutral-point pairs [deg] (model default 40)")
