"""Raw photodiode data, schema "skysim.photodiodes/1" (contract: ``docs/photodiodes_schema.md``).

Multi-unit polarization instruments (rings or domes of units) record photodiode readings. One
row per sample; CSV or Parquet by file extension; a JSON sidecar ``<name>.json`` beside it.

Required columns: ``time`` (ISO 8601 with UTC offset; may repeat), ``yaw_deg`` and one column
``u{unit}_p{angle:03d}`` per photodiode (0-based unit index, polarizer angle [deg]). Optional:
``pitch_deg``, ``roll_deg``, ``sweep``, accelerometer ``accel_x_mps2``, ``accel_y_mps2``,
``accel_z_mps2`` (specific force in the body frame [m/s^2]). Any other column is kept as
metadata (:attr:`PhotodiodeData.extra_columns`).

The reader never drops or invents a sample. It flags, per sample and photodiode
(:class:`PhotodiodeFlags`): saturated readings (``>= saturation_value``), exact zeros,
missing readings (NaN/empty), dead photodiodes (a column stuck at one value over the whole
file) and, per sample, repeated timestamps.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.sun import Site

from .measurement import (
    MeasurementFormatError,
    check_numeric_columns,
    check_site_block,
    parse_iso_times,
)
from .tables import read_table_and_sidecar, write_table_and_sidecar

__all__ = ["PHOTODIODES_SCHEMA", "ACCEL_COLUMNS", "PhotodiodeFormatError",
           "SidecarMismatchError", "PhotodiodeFlags", "PhotodiodeData", "photodiode_column",
           "photodiode_columns", "read_photodiodes", "write_photodiodes"]

PHOTODIODES_SCHEMA = "skysim.photodiodes/1"
ACCEL_COLUMNS = ("accel_x_mps2", "accel_y_mps2", "accel_z_mps2")
_PD_RE = re.compile(r"^u(\d+)_p(\d{3})$")
_YAW_REFERENCES = ("north", "relative")
_YAW_SENSES = ("clockwise", "counterclockwise")
_READINGS = ("counts", "volts")
DEAD_MIN_SAMPLES = 10
"""A photodiode is called dead when it reads one constant value over at least this many samples
(with real photodiodes and ADC noise a constant column over 10 samples is a stuck channel)."""


class PhotodiodeFormatError(MeasurementFormatError):
    """A photodiode file or table does not follow "skysim.photodiodes/1" (says what and where)."""


class SidecarMismatchError(PhotodiodeFormatError):
    """The sidecar's ``units`` do not describe the photodiode columns of the table.

    Attributes ``missing`` (columns the sidecar announces but the table lacks) and
    ``unexpected`` (photodiode columns in the table the sidecar does not announce).
    """

    def __init__(self, message: str, missing=(), unexpected=()):
        super().__init__(message)
        self.missing = list(missing)
        self.unexpected = list(unexpected)


def photodiode_column(unit: int, angle_deg) -> str:
    """Column name of one photodiode, e.g. ``photodiode_column(0, 45) == "u0_p045"``.

    Raises
    ------
    PhotodiodeFormatError
        For a polarizer angle that is not a whole number of degrees in [0, 180).
    """
    a = float(angle_deg)
    if a != round(a) or not 0 <= a < 180:
        raise PhotodiodeFormatError(
            f"polarizer angle {angle_deg!r} of unit {unit} must be a whole number of degrees in "
            "[0, 180) to be named u{unit}_p{angle:03d}")
    return f"u{int(unit)}_p{int(round(a)):03d}"


def photodiode_columns(units) -> list[str]:
    """All photodiode columns announced by a sidecar's ``units`` list, in unit order."""
    return [photodiode_column(i, a) for i, u in enumerate(units) for a in u["photodiodes"]]


@dataclass(frozen=True)
class PhotodiodeFlags:
    """Per-sample quality flags; boolean arrays, never a replacement of the data.

    Attributes
    ----------
    columns : tuple of str
        Photodiode columns, the order of the second axis below.
    saturated, zero, missing, dead : ndarray (n, m) bool
        Reading at/above ``saturation_value``; exactly zero; NaN/empty; photodiode stuck
        over the whole file (flagged in every sample).
    repeated_time : ndarray (n,) bool
        The sample's time equals that of an earlier sample (first occurrence not flagged).
    """

    columns: tuple
    saturated: np.ndarray
    zero: np.ndarray
    missing: np.ndarray
    dead: np.ndarray
    repeated_time: np.ndarray

    @classmethod
    def compute(cls, table: pd.DataFrame, columns, saturation_value: float | None):
        values = table[list(columns)].to_numpy(dtype=float)
        missing = ~np.isfinite(values)
        with np.errstate(invalid="ignore"):
            saturated = (values >= saturation_value) if saturation_value is not None \
                else np.zeros(values.shape, bool)
            zero = values == 0.0
        n = values.shape[0]
        if n >= DEAD_MIN_SAMPLES:
            first = values[:1]
            stuck = np.all((values == first) | missing, axis=0) & ~np.all(missing, axis=0)
        else:
            stuck = np.zeros(values.shape[1], bool)
        dead = np.broadcast_to(stuck, values.shape).copy()
        repeated = table["time"].duplicated(keep="first").to_numpy()
        return cls(tuple(columns), saturated, zero, missing, dead, repeated)

    @property
    def bad(self) -> np.ndarray:
        """(n, m) True where a reading should not be used (saturated, zero, missing or dead)."""
        return self.saturated | self.zero | self.missing | self.dead

    def to_frame(self) -> pd.DataFrame:
        """Flags as a table: ``<column>_saturated`` etc. plus ``repeated_time``."""
        parts = {f"{c}_{k}": getattr(self, k)[:, j] for k in ("saturated", "zero", "missing",
                                                              "dead")
                 for j, c in enumerate(self.columns)}
        parts["repeated_time"] = self.repeated_time
        return pd.DataFrame(parts)

    def summary(self) -> dict:
        """Counts of flagged readings per kind, and the dead photodiode columns."""
        return {"saturated": int(self.saturated.sum()), "zero": int(self.zero.sum()),
                "missing": int(self.missing.sum()),
                "dead_photodiodes": [c for j, c in enumerate(self.columns)
                                     if self.dead.shape[0] and self.dead[0, j]],
                "repeated_time": int(self.repeated_time.sum())}


class PhotodiodeData:
    """A photodiode table, its sidecar and the per-sample flags.

    Parameters
    ----------
    table : pandas.DataFrame
        Columns per schema; ``time`` is converted to timezone-aware timestamps.
    sidecar : dict
        ``schema``, ``site``, ``yaw_reference``, ``yaw_sense``, ``units``, ``readings``,
        ``adc_full_scale``, ``saturation_value`` (and ``generator`` for simulated data).
    flags : PhotodiodeFlags, optional
        Computed from the table when omitted.

    Raises
    ------
    PhotodiodeFormatError
        For a malformed sidecar or table; :class:`SidecarMismatchError` when the sidecar's
        units do not match the photodiode columns.
    """

    def __init__(self, table: pd.DataFrame, sidecar: dict, flags: PhotodiodeFlags | None = None,
                 *, where: str = "photodiode data"):
        self.table = table
        self.sidecar = sidecar
        _validate_sidecar(sidecar, where)
        self.columns = photodiode_columns(sidecar["units"])
        _validate_table(table, self.columns, where)
        self.flags = flags if flags is not None else PhotodiodeFlags.compute(
            table, self.columns, sidecar.get("saturation_value"))

    @property
    def site(self) -> Site:
        return Site.from_dict(self.sidecar["site"])

    @property
    def units(self) -> list[dict]:
        return self.sidecar["units"]

    @property
    def readings(self) -> np.ndarray:
        """Photodiode readings (n, m) in the sidecar's unit (NaN where missing)."""
        return self.table[self.columns].to_numpy(dtype=float)

    def unit_readings(self, unit: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(readings (n, k), polarizer angles (k,) [deg], bad (n, k))`` of one unit."""
        angles = np.asarray(self.units[unit]["photodiodes"], dtype=float)
        idx = [self.columns.index(photodiode_column(unit, a)) for a in angles]
        return self.readings[:, idx], angles, self.flags.bad[:, idx]

    @property
    def extra_columns(self) -> list[str]:
        """Columns the schema does not define, kept as metadata."""
        known = {"time", "yaw_deg", "pitch_deg", "roll_deg", "sweep", *ACCEL_COLUMNS,
                 *self.columns}
        return [c for c in self.table.columns if c not in known]

    @property
    def has_accelerometer(self) -> bool:
        return all(c in self.table.columns for c in ACCEL_COLUMNS)

    def write(self, path) -> Path:
        """Same as :func:`write_photodiodes`."""
        return write_photodiodes(self, path)


def _require(cond: bool, where: str, message: str):
    if not cond:
        raise PhotodiodeFormatError(f"{where}: {message}")


def _is_number(value) -> bool:
    """True for a finite number, or text that reads as one (``"45"``); not a bool."""
    if isinstance(value, bool):
        return False
    try:
        return bool(np.isfinite(float(value)))
    except (TypeError, ValueError, OverflowError):
        return False


def _validate_sidecar(sidecar: dict, where: str) -> None:
    _require(isinstance(sidecar, dict), where, "sidecar must be a JSON object")
    _require(sidecar.get("schema") == PHOTODIODES_SCHEMA, where,
             f"sidecar schema is {sidecar.get('schema')!r}, expected {PHOTODIODES_SCHEMA!r}")
    _require("site" in sidecar, where, "sidecar has no 'site' (latitude_deg, longitude_deg, "
             "altitude_m); the sun position cannot be computed without it")
    site = sidecar["site"]
    _require(isinstance(site, dict) and all(_is_number(site.get(k)) for k in
                                            ("latitude_deg", "longitude_deg"))
             and _is_number(site.get("altitude_m", 0.0)), where,
             f"sidecar 'site' must give the numbers latitude_deg, longitude_deg (and "
             f"altitude_m) [deg, m]; got {site!r}")
    try:
        check_site_block(site, where)
    except PhotodiodeFormatError:
        raise
    except MeasurementFormatError as exc:   # this schema's error for the same check
        raise PhotodiodeFormatError(str(exc)) from None
    for key, valid in (("yaw_reference", _YAW_REFERENCES), ("yaw_sense", _YAW_SENSES),
                       ("readings", _READINGS)):
        _require(sidecar.get(key) in valid, where,
                 f"sidecar {key!r} is {sidecar.get(key)!r}; valid: {', '.join(valid)}")
    for key in ("adc_full_scale", "saturation_value"):
        v = sidecar.get(key)
        _require(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
                 and v > 0, where, f"sidecar {key!r} must be a positive number; got {v!r}")
    _require(isinstance(sidecar.get("generator", {}), dict), where,
             f"sidecar 'generator' must be an object; got {sidecar.get('generator')!r}")
    units = sidecar.get("units")
    _require(isinstance(units, list) and len(units) > 0, where,
             "sidecar 'units' must be a non-empty list of {azimuth_deg, elevation_deg, "
             "photodiodes}")
    for i, u in enumerate(units):
        _require(isinstance(u, dict) and {"azimuth_deg", "elevation_deg", "photodiodes"} <= set(u),
                 where, f"unit {i} must give azimuth_deg, elevation_deg and photodiodes; got {u!r}")
        for key in ("azimuth_deg", "elevation_deg"):
            _require(_is_number(u[key]), where,
                     f"unit {i} {key} must be a finite number [deg]; got {u[key]!r}")
        _require(0.0 <= float(u["elevation_deg"]) <= 90.0, where,
                 f"unit {i} elevation_deg {u['elevation_deg']!r} is outside [0, 90]: a sky "
                 "polarization unit looks at or above the body's x-y plane")
        _require(isinstance(u["photodiodes"], list)
                 and all(_is_number(a) for a in u["photodiodes"]), where,
                 f"unit {i} photodiodes must be a list of polarizer angles [deg]; "
                 f"got {u['photodiodes']!r}")
        pds = list(u["photodiodes"])
        _require(len(pds) >= 3 and len({float(a) % 180 for a in pds}) >= 3, where,
                 f"unit {i} needs at least 3 photodiodes at distinct polarizer angles (mod 180) "
                 f"to determine a linear polarization; got {pds!r}")
        for a in pds:
            _require(float(a) == round(float(a)) and 0 <= float(a) < 180, where,
                     f"unit {i} photodiodes: polarizer angle {a!r} must be a whole number of "
                     f"degrees in [0, 180) (its column is u{i}_p{{angle:03d}})")


def _validate_table(table: pd.DataFrame, columns: list[str], where: str) -> None:
    present = [c for c in table.columns if _PD_RE.match(str(c))]
    missing = [c for c in columns if c not in table.columns]
    unexpected = [c for c in present if c not in columns]
    if missing or unexpected:
        raise SidecarMismatchError(
            f"{where}: the sidecar's units do not match the photodiode columns: "
            f"missing from the table {missing}, not announced by the sidecar {unexpected}. "
            "Each unit i with polarizer angles a needs a column u{i}_p{a:03d}",
            missing, unexpected)
    _require("time" in table.columns, where, "missing required column 'time'")
    optional = [c for c in ("pitch_deg", "roll_deg", *ACCEL_COLUMNS) if c in table.columns]
    try:   # the measurement schema's checks, re-raised as this schema's error
        table["time"] = parse_iso_times(table["time"], where)
        check_numeric_columns(table, ["yaw_deg", *optional], where)
    except PhotodiodeFormatError:
        raise
    except MeasurementFormatError as exc:
        raise PhotodiodeFormatError(str(exc)) from exc
    for c in columns:  # readings may be NaN (flagged as missing) but never text
        coerced = pd.to_numeric(table[c], errors="coerce")
        bad = coerced.isna() & table[c].notna()
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise PhotodiodeFormatError(
                f"{where}: photodiode column {c!r} has a non-numeric value {table[c].iloc[row]!r} "
                f"in row {row}")
        table[c] = coerced.astype(float)


def write_photodiodes(data: PhotodiodeData, path) -> Path:
    """Write the table (``.csv`` or ``.parquet``) and its sidecar atomically (both or neither).

    The flags are not written: they are recomputed by the reader from the readings.
    """
    return write_table_and_sidecar(data.table, data.sidecar, path)


def read_photodiodes(path) -> PhotodiodeData:
    """Read a photodiode table and its sidecar, flagging suspicious readings per sample.

    Raises
    ------
    MissingFileError
        If the data file or its sidecar is missing.
    PhotodiodeFormatError
        For invalid JSON, a malformed sidecar, a missing/non-numeric required column or times
        without offsets; :class:`SidecarMismatchError` when the sidecar's units do not match
        the photodiode columns.
    """
    table, sidecar = read_table_and_sidecar(path, PHOTODIODES_SCHEMA, PhotodiodeFormatError,
                                            dtype={"time": str})
    return PhotodiodeData(table, sidecar, where=str(path))
