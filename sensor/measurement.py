"""Measurement tables, schema "skysim.measurement/1" (see ``docs/schemas.md``).

One row per sample; CSV or Parquet by file extension; a JSON sidecar ``<name>.json`` beside
the data file. Required columns: ``time`` (ISO 8601 with UTC offset), ``heading_deg``,
``U1_V``, ``U2_V``, ``U3_V``. Unknown extra columns are kept as metadata.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.exceptions import FileFormatError
from skysim.sun import Site

from .tables import format_iso_times, read_table_and_sidecar, write_table_and_sidecar

__all__ = ["MEASUREMENT_SCHEMA", "REQUIRED_COLUMNS", "CHANNEL_COLUMNS", "Measurement",
           "MeasurementFormatError", "read_measurement", "format_iso_times", "parse_iso_times"]

MEASUREMENT_SCHEMA = "skysim.measurement/1"
CHANNEL_COLUMNS = ("U1_V", "U2_V", "U3_V")
REQUIRED_COLUMNS = ("time", "heading_deg") + CHANNEL_COLUMNS
_OFFSET_RE = r"(?:Z|[+-]\d\d:?\d\d|:\d\d(?:\.\d+)?[+-]\d\d)$"
"""A UTC offset ending an ISO 8601 time: ``Z``, ``+hh:mm``, ``+hhmm``, or ``+hh`` right after
the time of day (so that the day of a bare date, ``2013-05-22``, is not read as an offset)."""


class MeasurementFormatError(FileFormatError):
    """A measurement file or table does not follow its schema (message says what and where)."""


def parse_iso_times(values: pd.Series, where: str) -> pd.Series:
    """Parse ISO 8601 times that must carry an offset; raise naming the first bad row."""
    if pd.api.types.is_datetime64_any_dtype(values):
        if getattr(values.dt, "tz", None) is None:
            raise MeasurementFormatError(f"{where}: column 'time' is timezone-naive")
        return values
    if values.isna().any():
        row = int(np.flatnonzero(values.isna().to_numpy())[0])
        raise MeasurementFormatError(
            f"{where}: time is empty in row {row}; every sample needs its ISO 8601 time with "
            "offset, e.g. 2013-05-22T17:10:00+08:00")
    s = values.astype(str)
    ok = s.str.contains(_OFFSET_RE, regex=True)
    if not ok.all():
        row = int(np.flatnonzero(~ok.to_numpy())[0])
        raise MeasurementFormatError(
            f"{where}: time {s.iloc[row]!r} in row {row} has no UTC offset; "
            "write times as ISO 8601 with offset, e.g. 2013-05-22T17:10:00+08:00")
    try:
        parsed = pd.to_datetime(s, format="ISO8601", utc=True)
    except (ValueError, TypeError, OverflowError):
        parsed = None
    if parsed is not None:
        years = parsed.dt.year.to_numpy()
        out = np.flatnonzero((years < 1678) | (years > 2261))
        if not out.size:
            return parsed.dt.as_unit("ns")
        raise MeasurementFormatError(
            f"{where}: time {s.iloc[out[0]]!r} in row {out[0]} is outside the supported years "
            f"1678-2261 ({out.size} such row(s))")
    # locate the first bad row (vectorised) and say what is wrong with it
    row = int(np.flatnonzero(pd.to_datetime(s, format="ISO8601", utc=True,
                                            errors="coerce").isna().to_numpy())[0])
    text = s.iloc[row]
    try:
        pd.Timestamp(text).as_unit("ns")
        why = "not an ISO 8601 time"
    except (pd.errors.OutOfBoundsDatetime, OverflowError):
        why = "outside the supported years 1678-2261"
    except (ValueError, TypeError):
        why = "not an ISO 8601 time"
    raise MeasurementFormatError(
        f"{where}: time {text!r} in row {row} is {why}; write times as ISO 8601 with offset, "
        "e.g. 2013-05-22T17:10:00+08:00")


def check_site_block(site, where: str) -> None:
    """A sidecar's ``site`` must describe a valid :class:`skysim.sun.Site` (numbers
    ``latitude_deg`` in [-90, 90], ``longitude_deg``, ``altitude_m`` [m] when given)."""
    from skysim.exceptions import InvalidParameterError
    try:
        Site.from_dict(site)
    except InvalidParameterError as exc:
        raise MeasurementFormatError(f"{where}: sidecar site: {exc}") from None


def check_daq_block(daq, where: str) -> None:
    """A sidecar's ``sensor.daq`` block must describe a valid :class:`sensor.daq.Daq`
    (``bits`` a whole number 1..32 or null, ``range_V`` > 0 [V])."""
    from skysim.exceptions import InvalidParameterError

    from .daq import Daq
    if not isinstance(daq, dict) or set(daq) - {"bits", "range_V"}:
        raise MeasurementFormatError(f"{where}: sidecar sensor.daq must be an object with "
                                     f"bits and range_V; got {daq!r}")
    try:
        Daq(daq.get("bits", 16), daq.get("range_V", 10.0))
    except InvalidParameterError as exc:
        raise MeasurementFormatError(f"{where}: sidecar sensor.daq: {exc}") from None


def check_numeric_columns(table: pd.DataFrame, columns, where: str) -> None:
    """Raise :class:`MeasurementFormatError` for missing, non-numeric or NaN columns."""
    missing = [c for c in columns if c not in table.columns]
    if missing:
        raise MeasurementFormatError(
            f"{where}: missing required column(s) {missing}; found {list(table.columns)}")
    for c in columns:
        col = pd.to_numeric(table[c], errors="coerce")
        bad = ~np.isfinite(col.to_numpy(dtype=float))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise MeasurementFormatError(
                f"{where}: column {c!r} has {int(bad.sum())} NaN/non-numeric value(s), "
                f"first in row {row} ({table[c].iloc[row]!r})")


@dataclass
class Measurement:
    """A measurement table and its sidecar.

    Attributes
    ----------
    table : pandas.DataFrame
        Columns per schema v1; ``time`` is timezone-aware.
    sidecar : dict
        ``schema``, ``site``, ``sensor`` and (for generated data) ``generator``.
    """

    table: pd.DataFrame
    sidecar: dict

    def __post_init__(self):
        self.validate("measurement")

    def validate(self, where: str) -> None:
        if self.sidecar.get("schema") != MEASUREMENT_SCHEMA:
            raise MeasurementFormatError(
                f"{where}: sidecar schema is {self.sidecar.get('schema')!r}, "
                f"expected {MEASUREMENT_SCHEMA!r}")
        site = self.sidecar.get("site")
        if not isinstance(site, dict) or not all(
                isinstance(site.get(k), (int, float)) and not isinstance(site.get(k), bool)
                for k in ("latitude_deg", "longitude_deg")):
            raise MeasurementFormatError(
                f"{where}: sidecar has no 'site' with numbers latitude_deg, longitude_deg (and "
                f"altitude_m) [deg, m]; got {site!r}; the sun position cannot be computed "
                "without it")
        check_site_block(site, where)
        sensor = self.sidecar.get("sensor")
        if sensor is not None and not isinstance(sensor, dict):
            raise MeasurementFormatError(f"{where}: sidecar 'sensor' must be an object; got "
                                         f"{sensor!r}")
        if not isinstance(self.sidecar.get("generator", {}), dict):
            raise MeasurementFormatError(f"{where}: sidecar 'generator' must be an object; got "
                                         f"{self.sidecar.get('generator')!r}")
        daq = sensor.get("daq") if isinstance(sensor, dict) else None
        if daq is not None:
            check_daq_block(daq, where)
        if "time" not in self.table.columns:
            raise MeasurementFormatError(f"{where}: missing required column 'time'")
        self.table["time"] = parse_iso_times(self.table["time"], where)
        check_numeric_columns(self.table, REQUIRED_COLUMNS[1:], where)

    @property
    def site(self) -> Site:
        return Site.from_dict(self.sidecar["site"])

    @property
    def channels(self) -> np.ndarray:
        """Channel outputs, shape (n, 3) [V]."""
        return self.table[list(CHANNEL_COLUMNS)].to_numpy(dtype=float)

    def write(self, path) -> Path:
        """Write the table (``.csv`` or ``.parquet``) and its sidecar atomically."""
        return write_table_and_sidecar(self.table, self.sidecar, path)


def read_measurement(path) -> Measurement:
    """Read a measurement table and its sidecar.

    Raises
    ------
    MissingFileError
        If the data file or the sidecar is missing.
    MeasurementFormatError
        For a malformed sidecar, a missing/NaN column or times without offsets.
    """
    table, sidecar = read_table_and_sidecar(path, MEASUREMENT_SCHEMA, MeasurementFormatError)
    m = Measurement.__new__(Measurement)
    m.table, m.sidecar = table, sidecar
    m.validate(str(path))
    return m
