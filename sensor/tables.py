"""Shared file layer of the sensor data schemas: a table (CSV or Parquet) plus a JSON sidecar.

Both "skysim.measurement/1" and "skysim.photodiodes/1" store one row per sample in
``<name>.csv`` or ``<name>.parquet`` with the sidecar ``<name>.csv.json`` (or
``<name>.parquet.json``) beside it; readers also accept the older ``<name>.json``
(``docs/schemas.md``).
These two functions hold the rules common to both: extensions, ISO 8601 times with offsets in
CSV, atomic commit of both files (both or neither), and the errors for missing, non-JSON or
unreadable files. Schema checks stay with each schema's reader.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from skysim.exceptions import InvalidParameterError, MissingFileError
from skysim.io import (
    _json_default,
    atomic_write_many,
    check_csv_header,
    find_sidecar,
    sidecar_path,
)

__all__ = ["TABLE_SUFFIXES", "write_table_and_sidecar", "read_table_and_sidecar",
           "format_iso_times"]

TABLE_SUFFIXES = (".csv", ".parquet")


def format_iso_times(times: pd.Series) -> pd.Series:
    """ISO 8601 strings with a ``+hh:mm`` offset (vectorised)."""
    s = pd.Series(times).dt.strftime("%Y-%m-%dT%H:%M:%S.%f%z")
    return s.str.replace(r"([+-]\d\d)(\d\d)$", r"\1:\2", regex=True)


def write_table_and_sidecar(table: pd.DataFrame, sidecar: dict, path) -> Path:
    """Write ``table`` (``.csv`` or ``.parquet`` by extension) and its JSON sidecar atomically.

    In CSV the ``time`` column (timezone-aware) is written as ISO 8601 with ``+hh:mm``.
    Both files appear together or not at all; a failure leaves no partial file behind.

    Raises
    ------
    InvalidParameterError
        For an extension other than ``.csv``/``.parquet``, or a table that names a column
        twice (its reader would refuse the file).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in TABLE_SUFFIXES:
        raise InvalidParameterError(f"unsupported extension {path.suffix!r}; use .csv or .parquet")
    repeated = table.columns[table.columns.duplicated()]
    if len(repeated):
        raise InvalidParameterError(f"the table names column {repeated[0]!r} twice; name each "
                                    f"column once (writing {path})")

    def write_table(tmp: Path):
        if suffix == ".csv":
            out = table.copy()
            if "time" in out.columns and pd.api.types.is_datetime64_any_dtype(out["time"]):
                out["time"] = format_iso_times(out["time"])
            out.to_csv(tmp, index=False)
        else:
            table.to_parquet(tmp, index=False)

    def write_sidecar(tmp: Path):
        tmp.write_text(json.dumps(sidecar, indent=2, default=_json_default) + "\n")

    atomic_write_many([(path, write_table), (sidecar_path(path), write_sidecar)])
    return path


def read_table_and_sidecar(path, schema: str, error_cls: type[Exception],
                           **read_csv_kwargs) -> tuple[pd.DataFrame, dict]:
    """Read a data file and its sidecar, without schema checks.

    Parameters
    ----------
    path : path-like
        ``.csv`` or ``.parquet`` data file; the sidecar is ``<name>.json`` beside it
        (``data.csv.json``), or the older ``<stem>.json`` (``data.json``).
    schema : str
        Schema name, for messages.
    error_cls : exception class
        Raised (with the path and cause) for a sidecar that is not a JSON object, an
        extension other than ``.csv``/``.parquet`` or an unreadable table.
    **read_csv_kwargs
        Passed to :func:`pandas.read_csv`.

    Raises
    ------
    MissingFileError
        If the data file or the sidecar is missing (a ``FileNotFoundError``).
    error_cls
        For a CSV header that names a column twice (pandas would rename the second).
    """
    path = Path(path)
    if path.is_dir():
        raise error_cls(f"{path} is a folder; give a data file (.csv or .parquet)")
    if not path.exists():
        raise MissingFileError(f"no data file {path} (schema {schema})")
    if path.suffix.lower() not in TABLE_SUFFIXES:
        raise error_cls(f"{path}: unsupported extension {path.suffix!r}; use .csv or .parquet")
    side = find_sidecar(path)
    if side is None:
        if sidecar_path(path).is_dir():
            raise error_cls(f"sidecar {sidecar_path(path)} is a folder, not a JSON file")
        raise MissingFileError(f"no sidecar {sidecar_path(path)} beside {path} "
                               f"(schema {schema})")
    try:
        sidecar = json.loads(side.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise error_cls(f"{side}: not valid JSON ({exc})") from exc
    if not isinstance(sidecar, dict):
        raise error_cls(f"{side}: the sidecar must be a JSON object {{...}}; got a "
                        f"{type(sidecar).__name__}")
    if path.suffix.lower() == ".csv":
        check_csv_header(path, error_cls)
    try:
        table = pd.read_parquet(path) if path.suffix.lower() == ".parquet" else \
            pd.read_csv(path, **read_csv_kwargs)
    except Exception as exc:  # pandas/pyarrow raise many types for corrupt files
        raise error_cls(f"{path}: cannot read table ({exc})") from exc
    if table.empty:
        raise error_cls(f"{path} has no rows (a header at most); a {schema} table needs one "
                        "row per sample")
    return table, sidecar
