"""Ground-truth data sets for other implementations: ``skysim generate`` and ``skysim compare``.

``skysim generate CONFIG.toml --out DIR`` writes, per entry of the configuration,

- ``[[sky_map]]``: a sky map (schema "skysim.skymap/1": DoP, AoP and Stokes I, Q, U on an
  elevation-azimuth grid) of any sky model of :func:`skysim.sky.make_sky`;
- ``[[measurement]]``: a three-pair sensor sweep (schema "skysim.measurement/1");
- ``[[photodiodes]]``: a compound-eye instrument's raw readings (schema "skysim.photodiodes/2");

each with its JSON sidecar, and ``manifest.json`` (schema "skysim.groundtruth/1": the whole
configuration, the master seed and the SHA-256 of every file). Entry ``name`` draws its random
numbers from ``SeedSequence(seed, spawn_key=(crc32(name),))``: the same configuration and seed
give byte-identical files, and adding an entry leaves the others unchanged.

``skysim compare THEIRS TRUTH`` compares another implementation's files (a file or a folder
laid out like the generated one) with the truth: per quantity the maximum and RMS error, where
the worst case is, and pass/fail against the tolerances of :data:`TOLERANCES` (overridable
with ``--tol NAME=VALUE``). The contract is ``docs/ground_truth.md``.
"""

from __future__ import annotations

import hashlib
import json
import os
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skysim.exceptions import InvalidParameterError, MissingFileError, SkysimError

from experiments.workflows.options import existing_file, output_dir, output_file

__all__ = ["GROUNDTRUTH_SCHEMA", "TOLERANCES", "GenerateConfigError", "CompareError",
           "dataset_rng", "generate", "compare_tables", "compare_paths", "register"]

GROUNDTRUTH_SCHEMA = "skysim.groundtruth/1"
SKYMAP_SCHEMA = "skysim.skymap/1"
_KINDS = ("sky_map", "measurement", "photodiodes")
_TIMES = {"start", "n", "duration_s"}
ENTRY_KEYS = {
    "sky_map": {"name", "format", "sky", "clouds", "time", "sun_elevation_deg",
                "sun_azimuth_deg", "grid_step_deg"},
    "measurement": {"name", "format", "sky", "clouds", *_TIMES, "errors",
                    "heading_offset_deg", "daq_bits", "daq_range_V"},
    "photodiodes": {"name", "format", "sky", "clouds", *_TIMES, "configuration", "n_units",
                    "elevation_deg", "installation_error_max_deg", "yaw_start_deg",
                    "yaw_end_deg", "pitch_deg", "roll_deg", "attitude_noise_deg",
                    "noise_counts", "sweeps", "sweep_interval_s"},
}
"""The keys each kind of entry takes (``docs/ground_truth.md``); any other key is an error."""
SITE_KEYS = {"latitude_deg", "longitude_deg", "altitude_m", "name"}

TOLERANCES = {
    "dop": 1e-6, "aop_deg": 1e-4, "I": 1e-6, "Q": 1e-6, "U": 1e-6,
    "heading_deg": 1e-6, "yaw_deg": 1e-6, "pitch_deg": 1e-6, "roll_deg": 1e-6,
    "true_sun_elevation_deg": 0.01, "true_phi_deg": 0.01, "true_dop": 1e-4,
    "U1_V": 1e-4, "U2_V": 1e-4, "U3_V": 1e-4, "photodiode_counts": 5.0,
}
"""Default tolerances (absolute, in each quantity's unit).

Sky maps are pure functions of the sun angles in their sidecar: double-precision evaluations
of the same equations agree to ~1e-12, so 1e-6 (DoP, Stokes) and 1e-4 deg (AoP) only leave
room for another summation order. Sensor streams also depend on the implementer's sun
position: the project accepts 0.01 deg against NREL SPA (``tests/test_sun.py``), so sun
elevation and phi get 0.01 deg; the channel outputs change by at most ~7.6e-3 V/deg
(``0.5 * 2/ln 10 * 2 d`` at d = 0.9) and get 1e-4 V; a zenith DoP moves by < 1e-2 per deg
of sun elevation, giving 1e-4; photodiode counts (2e4 counts x (1 + d cos 2 chi)) move by
< 350 counts/deg x 0.01 deg, plus 1 count of rounding: 5 counts. Inputs copied from the
configuration (heading, yaw, pitch, roll) must match to 1e-6 deg."""

AOP_MIN_DOP = 1e-3
"""AoP is compared only where the true DoP is at least this (undefined at neutral points)."""


class GenerateConfigError(InvalidParameterError):
    """A ground-truth configuration is invalid (the message names the entry and key)."""


class CompareError(SkysimError, ValueError):
    """Two files cannot be compared (schema, columns, rows or grid differ)."""


def dataset_rng(seed: int, name: str) -> np.random.Generator:
    """Random generator of entry ``name``: ``SeedSequence(seed, spawn_key=(crc32(name),))``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_key(name),)))


def _key(name: str) -> int:
    return zlib.crc32(name.encode("utf-8"))


# --------------------------------------------------------------------------- generate


def _number(entry: dict, key: str, default: float, where: str, low: float = -np.inf) -> float:
    """``entry[key]`` (or ``default``) as a finite float ``>= low``, else a
    :class:`GenerateConfigError` naming the entry and key."""
    v = entry.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < low:
        bound = f" >= {low:g}" if np.isfinite(low) else ""
        raise GenerateConfigError(f"{where}: {key} must be a number{bound}; got {v!r}")
    return float(v)


def _count(entry: dict, key: str, default: int | None, where: str) -> int:
    """``entry[key]`` (or ``default``) as an integer >= 1."""
    v = entry.get(key, default)
    if v is None:
        raise GenerateConfigError(f"{where}: missing {key!r}")
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise GenerateConfigError(f"{where}: {key} must be an integer >= 1; got {v!r}")
    return v


def _times(entry: dict, where: str):
    import pandas as pd
    if "start" not in entry:
        raise GenerateConfigError(f"{where}: missing 'start'")
    n = _count(entry, "n", None, where)
    try:
        start = pd.Timestamp(entry["start"])
    except (ValueError, TypeError):
        start = None
    if start is None or start is pd.NaT:
        raise GenerateConfigError(f"{where}: start {entry['start']!r} is not an ISO 8601 time; "
                                  "write e.g. 2013-05-22T17:10:00+08:00")
    if start.tzinfo is None:
        raise GenerateConfigError(f"{where}: start {entry['start']!r} has no UTC offset; write "
                                  "e.g. 2013-05-22T17:10:00+08:00")
    from skysim.resources import check_memory

    from .sky_options import SAMPLE_BYTES_PER_SAMPLE
    check_memory(n * SAMPLE_BYTES_PER_SAMPLE * max(1, entry.get("n_units", 1) / 3)
                 if isinstance(entry.get("n_units", 1), int) else 0,
                 f"{n} samples", "lower n")
    offsets = np.linspace(0.0, _number(entry, "duration_s", 600.0, where, low=0.0), n)
    try:
        return pd.DatetimeIndex(start + pd.to_timedelta(offsets, unit="s")).as_unit("ns")
    except (OverflowError, pd.errors.OutOfBoundsDatetime):
        raise GenerateConfigError(f"{where}: start {entry['start']!r} plus duration_s is outside "
                                  "the supported years 1678-2261") from None


def _sky(entry: dict, where: str):
    from skysim.sky import make_sky
    spec = dict(entry.get("sky", {"model": "rayleigh", "dmax": 0.7}))
    model = spec.pop("model", "rayleigh")
    try:
        return make_sky(model, **spec)
    except ImportError as exc:
        from skysim.extras import extra_for_module, missing_extra_message
        name = exc.name or getattr(exc.__cause__, "name", None)
        why = missing_extra_message(name, f"sky model {model!r}") if extra_for_module(name) \
            else f"sky model {model!r} is not available here ({exc})"
        raise GenerateConfigError(f"{where}: {why}") from exc
    except TypeError as exc:
        raise GenerateConfigError(f"{where}: sky parameters {spec} do not fit model "
                                  f"{model!r} ({exc})") from exc


CLOUD_KEYS = ("cover", "tau", "seed", "correlation_deg", "base_m", "thickness",
              "wind_speed_m_s", "wind_from_deg")
"""Keys of an entry's ``clouds`` table (:class:`skysim.cloud_field.CloudField`)."""


def _cloudy(sky, entry: dict, where: str, times=None):
    """``sky`` behind the entry's ``clouds`` (itself without them); ``times``: one per sample,
    the cloud field as drawn at the first."""
    spec = entry.get("clouds")
    if spec is None:
        return sky
    if not isinstance(spec, dict) or "cover" not in spec:
        raise GenerateConfigError(f"{where}: clouds must be a table with at least cover, e.g. "
                                  "{cover = 0.5, tau = 10.0, seed = 1}; got " f"{spec!r}")
    unknown = sorted(set(spec) - set(CLOUD_KEYS))
    if unknown:
        raise GenerateConfigError(f"{where}: unknown clouds key(s) {unknown}; valid: "
                                  f"{', '.join(CLOUD_KEYS)}")
    from skysim.cloud_field import CloudField
    from skysim.partly_cloudy import PartlyCloudySky
    args = dict(spec)
    try:
        field = CloudField(args.pop("cover"), args.pop("tau", 10.0), args.pop("seed", 0),
                           **args)
    except (InvalidParameterError, TypeError) as exc:
        raise GenerateConfigError(f"{where}: clouds: {exc}") from exc
    out = PartlyCloudySky(sky, field)
    return out if times is None else out.at_times(times)


def _write(table, sidecar: dict, path: Path) -> None:
    from sensor.tables import write_table_and_sidecar
    write_table_and_sidecar(table, sidecar, path)


def _sky_map(entry: dict, site, seed: int, path: Path, where: str) -> None:
    import pandas as pd

    from skysim.geometry import sky_grid, sky_grid_size
    from skysim.resources import check_memory
    from skysim.sun import sun_position

    from .sky_options import AOP_CONVENTION, SKY_BYTES_PER_DIRECTION
    sky = _cloudy(_sky(entry, where), entry, where)
    if "time" in entry:
        pos = sun_position([entry["time"]], site.latitude_deg, site.longitude_deg,
                           site.altitude_m)
        sun_el, sun_az = float(pos.elevation_deg.iloc[0]), float(pos.azimuth_deg.iloc[0])
        sun = {"site": site.to_dict(), "time": entry["time"]}
    elif "sun_elevation_deg" in entry and "sun_azimuth_deg" in entry:
        sun_el = _number(entry, "sun_elevation_deg", None, where)
        sun_az = _number(entry, "sun_azimuth_deg", None, where)
        sun = {}
    else:
        raise GenerateConfigError(f"{where}: give the sun as time (with [site]) or as "
                                  "sun_elevation_deg and sun_azimuth_deg")
    step = _number(entry, "grid_step_deg", 5.0, where)
    if not 0 < step <= 90:
        raise GenerateConfigError(f"{where}: grid_step_deg must be in (0, 90] [deg]; got {step}")
    check_memory(sky_grid_size(step) * SKY_BYTES_PER_DIRECTION,
                 f"{sky_grid_size(step)} sky directions", "use a coarser grid_step_deg")
    el, az = sky_grid(step)
    f = sky.field(el, az, sun_el, sun_az)
    table = pd.DataFrame({"elevation_deg": el, "azimuth_deg": az, "dop": f.dop,
                          "aop_deg": f.aop_deg, "I": f.I, "Q": f.Q, "U": f.U})
    sidecar = {"schema": SKYMAP_SCHEMA, "sky": sky.describe(),
               "sun": {**sun, "elevation_deg": sun_el, "azimuth_deg": sun_az},
               "aop_convention": AOP_CONVENTION, "n_directions": int(el.size),
               "generator": _generator(entry, seed)}
    _write(table, sidecar, path)


def _generator(entry: dict, seed: int) -> dict:
    from skysim import __version__
    return {"package": "skysim", "version": __version__, "command": "skysim generate",
            "entry": entry, "master_seed": seed, "spawn_key": [_key(entry["name"])]}


def _measurement(entry: dict, site, seed: int, path: Path, where: str) -> None:
    from sensor.daq import Daq
    from sensor.errors import OpponentErrors
    from sensor.opponent import OpponentSensor, zenith_polarization
    from sensor.yang2014 import ERROR_MODEL
    rng = dataset_rng(seed, entry["name"])
    errors = entry.get("errors", "random")
    if errors == "random":
        errors = ERROR_MODEL.draw_errors(rng)
    elif errors == "none":
        errors = OpponentErrors()
    elif isinstance(errors, dict):
        errors = OpponentErrors.from_dict(errors, where=f"{where}: errors")
    else:
        raise GenerateConfigError(f"{where}: errors must be 'random', 'none' or a table of "
                                  f"OpponentErrors fields; got {errors!r}")
    clear = _sky(entry, where)
    times = _times(entry, where)
    _, _, _, sun_az0 = zenith_polarization(clear, site, times[:1], [0.0])
    sky = _cloudy(clear, entry, where, times)
    headings = (sun_az0[0] + _number(entry, "heading_offset_deg", -90.0, where)
                + np.linspace(0.0, 180.0, len(times), endpoint=False))
    bits = entry.get("daq_bits", 16)
    sensor = OpponentSensor(errors, daq=Daq(None if bits in (0, "none") else bits,
                                            entry.get("daq_range_V", 10.0)))
    meas = sensor.sample(sky, site, times, headings, rng, seed=seed)
    meas.sidecar["generator"].update(_generator(entry, seed))
    _write(meas.table, meas.sidecar, path)


def _photodiodes(entry: dict, site, seed: int, path: Path, where: str) -> None:
    from sensor.compound_eye import (PhotodiodeModel, patent_configuration,
                                     ring_configuration, with_random_installation_errors)
    rng = dataset_rng(seed, entry["name"])
    pm = PhotodiodeModel(noise_counts=_number(entry, "noise_counts", 3.0, where, low=0.0))
    layout = entry.get("configuration", "ring")
    if layout == "ring":
        sensor = ring_configuration(_count(entry, "n_units", 8, where),
                                    _number(entry, "elevation_deg", 45.0, where), photodiode=pm)
    elif layout == "patent":
        sensor = patent_configuration(_number(entry, "elevation_deg", 60.0, where),
                                      photodiode=pm)
    else:
        raise GenerateConfigError(f"{where}: configuration {layout!r} unknown; valid: ring, "
                                  "patent")
    max_err = _number(entry, "installation_error_max_deg", 0.0, where, low=0.0)
    if max_err > 0:
        sensor = with_random_installation_errors(
            sensor, max_err, rng, zenith_unit=0 if layout == "patent" else None)
    import pandas as pd
    one = _times(entry, where)
    yaw1 = np.linspace(_number(entry, "yaw_start_deg", 0.0, where),
                       _number(entry, "yaw_end_deg", 360.0, where), len(one), endpoint=False)
    # several sweeps (one turn each, a sweep column) for a held-out diagnosis
    n_sweeps = _count(entry, "sweeps", 1, where)
    span = float((one[-1] - one[0]).total_seconds()) if len(one) > 1 else 0.0
    every = _number(entry, "sweep_interval_s", span + 60.0, where, low=span)
    times = pd.DatetimeIndex(np.concatenate([one + pd.Timedelta(seconds=k * every)
                                             for k in range(n_sweeps)]))
    yaw = np.tile(yaw1, n_sweeps)
    data = sensor.sample(_cloudy(_sky(entry, where), entry, where, times), site, times, yaw,
                         _number(entry, "pitch_deg", 0.0, where),
                         _number(entry, "roll_deg", 0.0, where), rng,
                         attitude_noise_deg=_number(entry, "attitude_noise_deg", 0.0, where,
                                                    low=0.0),
                         seed=seed, sweep=np.repeat(np.arange(n_sweeps), len(one))
                         if n_sweeps > 1 else None)
    data.sidecar["generator"].update(_generator(entry, seed))
    _write(data.table, data.sidecar, path)


_WRITERS = {"sky_map": _sky_map, "measurement": _measurement, "photodiodes": _photodiodes}


def load_generate_config(path) -> dict:
    """Read and check a ground-truth configuration (TOML)."""
    from .sweep_config import read_toml
    raw = read_toml(path, GenerateConfigError)
    unknown = set(raw) - {"seed", "name", "site", *_KINDS}
    if unknown:
        raise GenerateConfigError(f"{path}: unknown key(s) {sorted(unknown)}; valid: seed, "
                                  f"name, site, {', '.join(_KINDS)}")
    if not isinstance(raw.get("seed"), int):
        raise GenerateConfigError(f"{path}: 'seed' (an integer) is required so that the data "
                                  "can be regenerated")
    for kind in _KINDS:
        entries = raw.get(kind, [])
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            raise GenerateConfigError(f"{path}: {kind} must be a list of tables, written "
                                      f"[[{kind}]]; got {entries!r}")
        for e in entries:
            unknown = sorted(set(e) - ENTRY_KEYS[kind])
            if unknown:
                raise GenerateConfigError(
                    f"{path}: [[{kind}]] {e.get('name')!r}: unknown key(s) {unknown}; valid: "
                    f"{', '.join(sorted(ENTRY_KEYS[kind]))}")
            if not isinstance(e.get("sky", {}), dict):
                raise GenerateConfigError(f"{path}: [[{kind}]] {e.get('name')!r}: sky must be a "
                                          f"table like {{model = \"rayleigh\", dmax = 0.7}}")
    if "site" in raw:
        site = raw["site"]
        if not isinstance(site, dict) or not {"latitude_deg", "longitude_deg"} <= set(site) \
                or set(site) - SITE_KEYS:
            raise GenerateConfigError(f"{path}: [site] needs latitude_deg and longitude_deg "
                                      f"(and optionally altitude_m, name); got {site!r}")
    names = [e.get("name") for k in _KINDS for e in raw.get(k, [])]
    if not names:
        raise GenerateConfigError(f"{path}: nothing to generate; add [[sky_map]], "
                                  "[[measurement]] or [[photodiodes]] entries")
    bad = [n for n in names if not isinstance(n, str) or not n.replace("_", "").replace(
        "-", "").isalnum()]
    dup = sorted({n for n in names if names.count(n) > 1})
    if bad or dup:
        raise GenerateConfigError(f"{path}: every entry needs a unique name of letters, digits, "
                                  f"'-' and '_' (bad: {bad}, repeated: {dup})")
    return raw


def generate(config: dict, out) -> dict:
    """Write every entry of ``config`` into ``out`` and a manifest; return the manifest.

    All files are first written into a staging folder inside ``out`` and moved into place
    only when every entry succeeded, ``manifest.json`` last: a failed run leaves ``out`` as it
    was (no data without a manifest, no earlier data set half replaced).

    Raises
    ------
    GenerateConfigError
        For an invalid entry (the message names it); the sky layer's errors for invalid
        physical inputs are re-raised as this, with the entry named.
    OutputPathError
        If ``out`` is a file or not writable.
    """
    import shutil
    import tempfile

    from skysim.io import check_output_dir, sidecar_path, write_json_atomic
    from skysim.sun import Site
    out = check_output_dir(out)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    site = Site.from_dict(config["site"]) if "site" in config else None
    files = {}
    staging = Path(tempfile.mkdtemp(prefix=".generate-", dir=out))
    try:
        for kind in _KINDS:
            for entry in config.get(kind, []):
                where = f"[[{kind}]] {entry['name']!r}"
                if site is None and (kind != "sky_map" or "time" in entry):
                    raise GenerateConfigError(f"{where}: needs [site] (latitude_deg, "
                                              "longitude_deg, altitude_m)")
                fmt = entry.get("format", "csv")
                if fmt not in ("csv", "parquet"):
                    raise GenerateConfigError(f"{where}: format must be csv or parquet; "
                                              f"got {fmt!r}")
                path = staging / f"{entry['name']}.{fmt}"
                try:
                    _WRITERS[kind](entry, site, config["seed"], path, where)
                except GenerateConfigError:
                    raise
                except InvalidParameterError as exc:
                    raise GenerateConfigError(f"{where}: {exc}") from exc
                files[path.name] = {"kind": kind, "sha256": _sha256(path),
                                    "sidecar": sidecar_path(path).name,
                                    "sidecar_sha256": _sha256(sidecar_path(path))}
        manifest = {"schema": GROUNDTRUTH_SCHEMA, "config": config, "seed": config["seed"],
                    "files": files}
        write_json_atomic(staging / "manifest.json", manifest)
        for name, info in files.items():
            for f in (name, info["sidecar"]):
                os.replace(staging / f, out / f)
        os.replace(staging / "manifest.json", out / "manifest.json")
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        if created and not any(out.iterdir()):
            out.rmdir()            # leave no empty folder behind a failed first run
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return manifest


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# --------------------------------------------------------------------------- compare


@dataclass(frozen=True)
class QuantityResult:
    """Deviation of one quantity: errors in the quantity's unit, worst case located."""

    quantity: str
    n: int
    max_abs_error: float
    rms_error: float
    tolerance: float
    worst_row: int
    worst_at: str
    theirs: float
    truth: float

    @property
    def passed(self) -> bool:
        return bool(self.max_abs_error <= self.tolerance)

    def to_dict(self) -> dict:
        return {**self.__dict__, "passed": self.passed}


_ANGLE_PERIODS = {"aop_deg": 180.0, "true_phi_deg": 180.0, "heading_deg": 360.0,
                  "yaw_deg": 360.0}


def _read(path: Path):
    from sensor.tables import read_table_and_sidecar
    return read_table_and_sidecar(path, "any skysim schema", CompareError)


def _quantities(schema: str, truth) -> dict:
    """Quantity name -> list of columns compared, per schema."""
    if schema == SKYMAP_SCHEMA:
        return {q: [q] for q in ("dop", "aop_deg", "I", "Q", "U")}
    if schema == "skysim.measurement/1":
        q = {c: [c] for c in ("heading_deg", "U1_V", "U2_V", "U3_V")}
        q.update({c: [c] for c in ("true_phi_deg", "true_dop", "true_sun_elevation_deg")
                  if c in truth})
        return q
    if schema in ("skysim.photodiodes/1", "skysim.photodiodes/2"):
        from sensor.photodiodes_io import _PD_RE
        q = {c: [c] for c in ("yaw_deg", "pitch_deg", "roll_deg") if c in truth}
        q["photodiode_counts"] = [c for c in truth.columns if _PD_RE.match(str(c))]
        return q
    raise CompareError(f"truth schema {schema!r} is not one skysim generates; expected "
                       f"{SKYMAP_SCHEMA}, skysim.measurement/1 or skysim.photodiodes/2")


def _row_labels(schema: str, truth, where: str, theirs) -> list[str] | None:
    """Check the rows are the same samples/directions; return labels of the truth rows."""
    if len(theirs) != len(truth):
        raise CompareError(f"{where}: {len(theirs)} rows, the truth has {len(truth)}")
    if schema == SKYMAP_SCHEMA:
        keys = ["elevation_deg", "azimuth_deg"]
        a, b = theirs[keys].to_numpy(float), truth[keys].to_numpy(float)
        bad = np.flatnonzero(np.any(np.abs(a - b) > 1e-9, axis=1))
        if bad.size:
            raise CompareError(f"{where}: direction of row {bad[0]} is {a[bad[0]].tolist()}, "
                               f"truth {b[bad[0]].tolist()}: write the truth's grid in its order")
        return None
    import pandas as pd
    ta = pd.to_datetime(theirs["time"], format="ISO8601", utc=True)
    tb = pd.to_datetime(truth["time"], format="ISO8601", utc=True)
    bad = np.flatnonzero((ta != tb).to_numpy())
    if bad.size:
        raise CompareError(f"{where}: time of row {bad[0]} is {ta.iloc[bad[0]]}, truth "
                           f"{tb.iloc[bad[0]]}")
    return None


def compare_tables(theirs_path, truth_path, tolerances: dict | None = None):
    """Compare another implementation's file with a generated truth file.

    Returns
    -------
    list of QuantityResult

    Raises
    ------
    CompareError
        For an unknown schema, a missing column, other rows or another grid.
    """
    theirs_path, truth_path = Path(theirs_path), Path(truth_path)
    tol = {**TOLERANCES, **(tolerances or {})}
    truth, sidecar = _read(truth_path)
    theirs, _ = _read(theirs_path)
    schema = sidecar.get("schema")
    where = f"{theirs_path} against the truth {truth_path}"
    _row_labels(schema, truth, where, theirs)
    results = []
    for quantity, cols in _quantities(schema, truth).items():
        missing = [c for c in cols if c not in theirs]
        if missing:
            raise CompareError(f"{where}: missing column(s) {missing} (schema {schema})")
        a = theirs[cols].to_numpy(float)
        b = truth[cols].to_numpy(float)
        err = a - b
        if quantity in _ANGLE_PERIODS:
            p = _ANGLE_PERIODS[quantity]
            err = (err + p / 2) % p - p / 2
        if quantity == "aop_deg":
            err = np.where(truth[["dop"]].to_numpy(float) >= AOP_MIN_DOP, err, 0.0)
        abs_err = np.where(np.isfinite(err), np.abs(err), np.inf)
        k = int(np.argmax(abs_err))
        row, col = np.unravel_index(k, abs_err.shape)
        at = (f"elevation {truth.elevation_deg.iloc[row]:g} deg, azimuth "
              f"{truth.azimuth_deg.iloc[row]:g} deg" if schema == SKYMAP_SCHEMA
              else f"time {truth.time.iloc[row]}")
        if len(cols) > 1:
            at += f", column {cols[col]}"
        results.append(QuantityResult(
            quantity, int(err.size), float(abs_err.max()),
            float(np.sqrt(np.mean(np.square(np.where(np.isfinite(err), err, np.inf))))),
            float(tol[quantity]), int(row), at, float(a[row, col]), float(b[row, col])))
    return results


def compare_paths(theirs, truth, tolerances: dict | None = None) -> dict:
    """Compare a file or a generated folder (its manifest's files) with the truth.

    Returns ``{"passed": bool, "files": {name: [QuantityResult.to_dict(), ...]}}``.
    """
    theirs, truth = Path(theirs), Path(truth)
    if truth.is_dir():
        manifest = truth / "manifest.json"
        if not manifest.is_file():
            raise MissingFileError(f"{truth} has no manifest.json (not a skysim generate folder)")
        try:
            names = list(json.loads(manifest.read_text())["files"])
        except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as exc:
            raise CompareError(f"{manifest}: not a skysim manifest ({type(exc).__name__}: "
                               f"{exc})") from None
        pairs = [(theirs / n if theirs.is_dir() else theirs, truth / n) for n in names]
    else:
        pairs = [(theirs, truth)]
    files = {p[1].name: [r.to_dict() for r in compare_tables(*p, tolerances)] for p in pairs}
    return {"passed": all(r["passed"] for rs in files.values() for r in rs), "files": files}


# --------------------------------------------------------------------------- CLI


def _generate_command(args) -> int:
    from skysim.io import sidecar_path

    from experiments.workflows.options import refuse_replacing_inputs
    config = load_generate_config(args.config)
    written = [Path(args.out) / "manifest.json"] + [
        f for kind in _KINDS for e in config.get(kind, [])
        for f in (Path(args.out) / f"{e['name']}.{e.get('format', 'csv')}",
                  sidecar_path(Path(args.out) / f"{e['name']}.{e.get('format', 'csv')}"))]
    refuse_replacing_inputs([("--out", f) for f in written], [("config", args.config)])
    manifest = generate(config, args.out)
    for name, info in manifest["files"].items():
        print(f"{info['kind']:<12s} {name:<40s} sha256 {info['sha256'][:16]}")
    print(f"wrote {len(manifest['files'])} data sets (+ sidecars) and manifest.json to {args.out}")
    return 0


def _parse_tolerances(items) -> dict:
    tol = {}
    for item in items or []:
        name, _, value = item.partition("=")
        if name not in TOLERANCES or not value:
            raise InvalidParameterError(f"--tol {item!r}: use NAME=VALUE with NAME one of "
                                        f"{', '.join(TOLERANCES)}")
        try:
            x = float(value)
        except ValueError:
            x = float("nan")
        if not (np.isfinite(x) and x >= 0):
            raise InvalidParameterError(
                f"--tol {item!r}: the tolerance must be a number >= 0 (an absolute "
                f"error in the unit of {name})")
        tol[name] = x
    return tol


def _compared_files(what: str, path) -> list[tuple[str, Path]]:
    """The files ``compare`` reads from ``path`` (a data file and its sidecars, or a generated
    folder's manifest and the files it lists), each with the argument that names it."""
    from experiments.workflows.options import data_file_and_sidecars
    path = Path(path)
    if not path.is_dir():
        return [(what, p) for p in data_file_and_sidecars(path)]
    manifest = path / "manifest.json"
    try:
        names = list(json.loads(manifest.read_text())["files"])
    except (OSError, ValueError, KeyError, TypeError):
        names = []
    return [(what, manifest)] + [(what, p) for n in names
                                 for p in data_file_and_sidecars(path / n)]


def _compare_command(args) -> int:
    from skysim.io import write_json_atomic

    from experiments.workflows.options import refuse_replacing_inputs
    refuse_replacing_inputs([("--report", args.report)], _compared_files("theirs", args.theirs)
                            + _compared_files("truth", args.truth))
    tolerances = _parse_tolerances(args.tol)
    report = compare_paths(args.theirs, args.truth, tolerances)
    for name, rows in report["files"].items():
        print(f"\n{name}")
        print(f"  {'quantity':<24s} {'n':>8s} {'max |err|':>11s} {'RMS':>11s} {'tolerance':>10s}"
              f"  result  worst at")
        for r in rows:
            print(f"  {r['quantity']:<24s} {r['n']:>8d} {r['max_abs_error']:>11.3g} "
                  f"{r['rms_error']:>11.3g} {r['tolerance']:>10.3g}  "
                  f"{'pass' if r['passed'] else 'FAIL':<6s}  {r['worst_at']} "
                  f"(theirs {r['theirs']:.6g}, truth {r['truth']:.6g})")
    print(f"\noverall: {'PASS' if report['passed'] else 'FAIL'}")
    if args.report:
        write_json_atomic(args.report, report)
    return 0 if report["passed"] else 1


def register(sub) -> None:
    g = sub.add_parser("generate", help="ground-truth sky maps and sensor streams from a TOML "
                                        "configuration (byte-identical for the same seed)")
    g.add_argument("config", type=existing_file,
                   help="configuration (.toml), see docs/ground_truth.md")
    g.add_argument("--out", required=True, type=output_dir,
                   help="output folder: one data file and sidecar per entry, and "
                        "manifest.json (a failed run leaves it as it was)")
    g.set_defaults(func=_generate_command)
    c = sub.add_parser("compare", help="compare another implementation's output with "
                                       "generated ground truth (exit 1 on failure)")
    c.add_argument("theirs", help="their file, or a folder with the truth's file names")
    c.add_argument("truth", help="a generated file, or a `skysim generate` folder")
    c.add_argument("--tol", action="append", metavar="NAME=VALUE",
                   help="override a tolerance, e.g. --tol aop_deg=1e-3 (repeatable)")
    c.add_argument("--report", type=output_file(".json"),
                   help="write the comparison as JSON (.json; never one of the compared "
                        "files)")
    c.set_defaults(func=_compare_command)
