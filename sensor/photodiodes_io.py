"""Raw photodiode data of any polarization compass, schema "skysim.photodiodes/2"
(contract: ``docs/photodiodes_schema.md``).

A photodiode compass is one or more *units*, each a group of at least two photodiodes behind
linear polarizers looking along one optical axis (a ring of four-polarizer units, a zenith
pair of crossed polarizers, ...). A unit's analyser is fixed, or turns (a polarizer wheel
driven by a motor): its angle is then a per-row column or a rate and a phase. One row per
sample; CSV or Parquet by file extension; a JSON sidecar ``<name>.json`` beside it.

Required columns: ``time`` (ISO 8601 with UTC offset; may repeat), ``yaw_deg`` and one column
per photodiode (named by the sidecar, by default ``u{unit}_p{angle}``, e.g. ``u0_p045`` or
``u0_p022.5``). Optional: ``pitch_deg``, ``roll_deg``, ``sweep``, accelerometer
``accel_x_mps2``, ``accel_y_mps2``, ``accel_z_mps2`` (specific force in the body frame
[m/s^2]) and the analyser angle columns the sidecar names. Any other column is kept as
metadata (:attr:`PhotodiodeData.extra_columns`).

Files of the first version, "skysim.photodiodes/1", are still read: their sidecar is
converted on load (:func:`migrate_sidecar`), and a writer writes the second version.

The reader never drops or invents a sample. It flags, per sample and photodiode
(:class:`PhotodiodeFlags`): saturated readings (``>= saturation_value``), exact zeros (raw
readings only: a dark-subtracted or normalised reading may be 0), missing readings
(NaN/empty), dead photodiodes (a column stuck at one value over the whole file) and, per
sample, repeated timestamps.
"""

from __future__ import annotations

import copy
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.bands import BANDS
from skysim.exceptions import InvalidParameterError, UnsupportedOperationError
from skysim.sun import Site

from .measurement import (
    MeasurementFormatError,
    check_numeric_columns,
    check_site_block,
    parse_iso_times,
)
from .tables import read_table_and_sidecar, write_table_and_sidecar

__all__ = ["PHOTODIODES_SCHEMA", "PHOTODIODES_SCHEMA_V1", "PHOTODIODES_SCHEMAS",
           "ACCEL_COLUMNS", "READINGS_KINDS", "READING_UNITS", "ZENITH_TOLERANCE_DEG",
           "PhotodiodeFormatError", "SidecarMismatchError", "PhotodiodeFlags", "PhotodiodeData",
           "photodiode_column", "photodiode_columns", "migrate_sidecar", "heading_ambiguity_deg",
           "heading_error_deg", "read_photodiodes", "write_photodiodes"]

PHOTODIODES_SCHEMA = "skysim.photodiodes/2"
PHOTODIODES_SCHEMA_V1 = "skysim.photodiodes/1"
PHOTODIODES_SCHEMAS = (PHOTODIODES_SCHEMA, PHOTODIODES_SCHEMA_V1)
"""Every schema name this reader accepts (the first is the one it writes)."""
ACCEL_COLUMNS = ("accel_x_mps2", "accel_y_mps2", "accel_z_mps2")
_PD_RE = re.compile(r"^u(\d+)_p(\d{3}(?:\.\d+)?)$")
_YAW_REFERENCES = ("north", "relative")
_YAW_SENSES = ("clockwise", "counterclockwise")
_V1_READINGS = ("counts", "volts")
READINGS_KINDS = ("raw", "dark-subtracted", "normalised")
"""What the readings are: ``raw`` (converter output, dark offset included),
``dark-subtracted`` (the dark reading removed before writing) or ``normalised`` (scaled by
their authors, e.g. per analyser revolution: no absolute level, no dark offset, no degree of
polarization scale survives)."""
READING_UNITS = ("counts", "volts", "amperes", "relative")
_ANALYSER_KINDS = ("fixed", "rotating")
_SCHEMA_COLUMNS = ("time", "yaw_deg", "pitch_deg", "roll_deg", "sweep", *ACCEL_COLUMNS)
ZENITH_TOLERANCE_DEG = 5.0
"""A unit whose axis is within this of the zenith [deg] counts as zenith-looking. The angle
of polarization at the zenith is perpendicular to the sun's azimuth, which it fixes only
modulo 180 deg; at 5 deg from the zenith the other half of the sky differs from it by less
than a hand-built unit's pointing uncertainty, so such a unit does not resolve the ambiguity."""
DEAD_MIN_SAMPLES = 10
"""A photodiode is called dead when it reads one constant value over at least this many samples
(with real photodiodes and ADC noise a constant column over 10 samples is a stuck channel)."""
BAND_WAVELENGTH_RANGE_NM = (200.0, 2500.0)
"""Wavelengths a band may name [nm]: from the UV-C edge of the sky's spectrum (ozone absorbs
below about 290 nm; 200 leaves room for a response table's tail) to the short-wave infrared."""


class PhotodiodeFormatError(MeasurementFormatError):
    """A photodiode file or table does not follow "skysim.photodiodes/2" (says what and where)."""


class SidecarMismatchError(PhotodiodeFormatError):
    """The sidecar's ``units`` do not describe the photodiode columns of the table.

    Attributes ``missing`` (columns the sidecar announces but the table lacks) and
    ``unexpected`` (photodiode columns in the table the sidecar does not announce).
    """

    def __init__(self, message: str, missing=(), unexpected=()):
        super().__init__(message)
        self.missing = list(missing)
        self.unexpected = list(unexpected)


def _angle_text(a: float) -> str:
    """``45 -> "045"``, ``22.5 -> "022.5"``, ``0.125 -> "000.125"`` (at most 6 decimals)."""
    whole, _, frac = f"{a:.6f}".partition(".")
    frac = frac.rstrip("0")
    return f"{int(whole):03d}" + (f".{frac}" if frac else "")


def photodiode_column(unit: int, angle_deg) -> str:
    """Default column name of one photodiode: ``photodiode_column(0, 45) == "u0_p045"``,
    ``photodiode_column(1, 22.5) == "u1_p022.5"``.

    Raises
    ------
    PhotodiodeFormatError
        For a polarizer angle that is not a finite number in [0, 180) [deg].
    """
    try:
        a = float(angle_deg)
    except (TypeError, ValueError):
        a = float("nan")
    if not np.isfinite(a) or not 0 <= a < 180:
        raise PhotodiodeFormatError(
            f"polarizer angle {angle_deg!r} of unit {unit} must be a number of degrees in "
            "[0, 180) to be named u{unit}_p{angle}")
    return f"u{int(unit)}_p{_angle_text(a)}"


def photodiode_columns(units) -> list[str]:
    """All photodiode columns of a sidecar's ``units`` list, in unit order (a unit's
    ``columns`` if it names them, else the default names of :func:`photodiode_column`)."""
    out = []
    for i, u in enumerate(units):
        cols = u.get("columns")
        out.extend(cols if cols is not None else
                   [photodiode_column(i, a) for a in u["photodiodes"]])
    return out


def heading_ambiguity_deg(elevations_deg) -> float:
    """The period [deg] within which a compass of units at these elevations knows its heading:
    180 when every unit looks within :data:`ZENITH_TOLERANCE_DEG` of the zenith (the zenith's
    angle of polarization fixes the sun's azimuth only modulo 180 deg), else 360."""
    el = np.asarray(elevations_deg, float)
    return 180.0 if el.size and np.all(el >= 90.0 - ZENITH_TOLERANCE_DEG) else 360.0


def heading_error_deg(est, true, ambiguity_deg=360.0) -> np.ndarray:
    """Heading error ``est - true`` [deg] wrapped into ``[-ambiguity/2, ambiguity/2)``.

    A zenith-only compass knows its heading modulo 180 deg: an estimate 180 deg off is then
    right, and its error is that modulo 180 (``ambiguity_deg=180``).

    Parameters
    ----------
    est, true : array-like
        Estimated and true headings [deg]; broadcast together. NaN stays NaN.
    ambiguity_deg : {360, 180}

    Raises
    ------
    InvalidParameterError
        For another ambiguity, or headings that do not broadcast together.
    """
    if isinstance(ambiguity_deg, bool) or not isinstance(ambiguity_deg, (int, float, np.number)) \
            or float(ambiguity_deg) not in (180.0, 360.0):
        raise InvalidParameterError(f"ambiguity_deg must be 360 or 180 [deg]; got "
                                    f"{ambiguity_deg!r}")
    try:
        e, t = np.broadcast_arrays(np.asarray(est, float), np.asarray(true, float))
    except ValueError:
        raise InvalidParameterError(
            f"est (shape {np.shape(est)}) and true (shape {np.shape(true)}) headings do not "
            "broadcast together") from None
    p = float(ambiguity_deg)
    return np.mod(e - t + 0.5 * p, p) - 0.5 * p


@dataclass(frozen=True)
class PhotodiodeFlags:
    """Per-sample quality flags; boolean arrays, never a replacement of the data.

    Attributes
    ----------
    columns : tuple of str
        Photodiode columns, the order of the second axis below.
    saturated, zero, missing, dead : ndarray (n, m) bool
        Reading at/above ``saturation_value``; exactly zero (raw readings only); NaN/empty;
        photodiode stuck over the whole file (flagged in every sample).
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
    def compute(cls, table: pd.DataFrame, columns, saturation_value: float | None,
                flag_zero: bool = True):
        values = table[list(columns)].to_numpy(dtype=float)
        missing = ~np.isfinite(values)
        with np.errstate(invalid="ignore"):
            saturated = (values >= saturation_value) if saturation_value is not None \
                else np.zeros(values.shape, bool)
            zero = (values == 0.0) if flag_zero else np.zeros(values.shape, bool)
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
    """A photodiode table, its sidecar (always of the current version) and per-sample flags.

    Parameters
    ----------
    table : pandas.DataFrame
        Columns per schema; ``time`` is converted to timezone-aware timestamps.
    sidecar : dict
        A "skysim.photodiodes/2" sidecar, or a "/1" one (converted, :func:`migrate_sidecar`).
        Not modified: :attr:`sidecar` is a checked copy with every default written out.
    flags : PhotodiodeFlags, optional
        Computed from the table when omitted.

    Attributes
    ----------
    migrated_from : str or None
        The schema of the given sidecar when it was converted, else None.

    Raises
    ------
    PhotodiodeFormatError
        For a malformed sidecar or table, naming the field and its value;
        :class:`SidecarMismatchError` when the sidecar's units do not match the photodiode
        columns.
    """

    def __init__(self, table: pd.DataFrame, sidecar: dict, flags: PhotodiodeFlags | None = None,
                 *, where: str = "photodiode data"):
        _require(isinstance(sidecar, dict), where, "sidecar must be a JSON object")
        self.migrated_from = sidecar.get("schema") if sidecar.get("schema") != \
            PHOTODIODES_SCHEMA else None
        side = migrate_sidecar(sidecar, where)
        _validate_sidecar(side, where)
        self.table = table
        self.columns = photodiode_columns(side["units"])
        _validate_table(table, self.columns, side, where)
        for u in side["units"]:   # a rate's epoch defaults to the first sample's time
            a = u["analyser"]
            if a["kind"] == "rotating" and "rate_deg_per_s" in a and a.get("epoch") is None:
                _require(len(table) > 0, where, "a rotating analyser given by its rate needs "
                         "an 'epoch' (ISO 8601 time of its phase) when the table is empty")
                a["epoch"] = pd.Timestamp(table["time"].iloc[0]).isoformat()
        self.sidecar = side
        self.flags = flags if flags is not None else PhotodiodeFlags.compute(
            table, self.columns, side.get("saturation_value"),
            flag_zero=side["readings"] == "raw")

    # ---------------------------------------------------------------- the sidecar
    @property
    def site(self) -> Site:
        return Site.from_dict(self.sidecar["site"])

    @property
    def units(self) -> list[dict]:
        return self.sidecar["units"]

    @property
    def readings_kind(self) -> str:
        """``"raw"``, ``"dark-subtracted"`` or ``"normalised"`` (:data:`READINGS_KINDS`)."""
        return self.sidecar["readings"]

    @property
    def reading_unit(self) -> str:
        return self.sidecar["reading_unit"]

    @property
    def time_uncertainty_s(self) -> float:
        """Standard uncertainty of the recorded times [s] (0: a logged clock)."""
        return float(self.sidecar["time_uncertainty_s"])

    @property
    def band(self):
        """The spectral band: a name of :data:`skysim.bands.BANDS`, ``"unknown"``, or a dict
        (``{"wavelength_nm", "fwhm_nm"}`` or ``{"response": [[nm, relative], ...]}``)."""
        return self.sidecar["band"]

    @property
    def band_wavelength_nm(self) -> float | None:
        """Effective wavelength of the band [nm]: the named band's, the given centre, or the
        response-weighted mean wavelength of a response table (trapezoidal); None when
        unknown."""
        b = self.band
        if isinstance(b, str):
            return None if b == "unknown" else float(BANDS[b].wavelength_nm)
        if "response" in b:
            w, r = np.asarray(b["response"], float).T
            return float(np.trapezoid(w * r, w) / np.trapezoid(r, w))
        return float(b["wavelength_nm"])

    # ---------------------------------------------------------------- geometry
    @property
    def pd_unit(self) -> np.ndarray:
        """Unit index of every photodiode column (P,)."""
        return np.array([i for i, u in enumerate(self.units) for _ in u["photodiodes"]], int)

    @property
    def nominal_angles_deg(self) -> np.ndarray:
        """Polarizer angle of every photodiode relative to its analyser's zero (P,) [deg]."""
        return np.array([float(a) for u in self.units for a in u["photodiodes"]], float)

    @property
    def rotating_units(self) -> list[int]:
        """Units whose analyser turns."""
        return [i for i, u in enumerate(self.units) if u["analyser"]["kind"] == "rotating"]

    def analyser_angles_deg(self) -> np.ndarray:
        """Angle of every unit's analyser at every sample (n, U) [deg] (0 for a fixed one):
        the angle column, or ``phase + rate * (t - epoch)``."""
        n = len(self.table)
        out = np.zeros((n, len(self.units)))
        for i, u in enumerate(self.units):
            a = u["analyser"]
            if a["kind"] != "rotating":
                continue
            if "angle_column" in a:
                out[:, i] = self.table[a["angle_column"]].to_numpy(float)
            else:
                t = (self.table["time"] - pd.Timestamp(a["epoch"])).dt.total_seconds()
                out[:, i] = float(a.get("phase_deg", 0.0)) + float(a["rate_deg_per_s"]) * \
                    t.to_numpy(float)
        return out

    @property
    def polarizer_angles_deg(self) -> np.ndarray:
        """Polarizer angle of every photodiode at every sample (n, P) [deg, in [0, 180)]:
        its nominal angle plus its unit's analyser angle."""
        ana = self.analyser_angles_deg()
        return np.mod(self.nominal_angles_deg[None, :] + ana[:, self.pd_unit], 180.0)

    @property
    def heading_ambiguity_deg(self) -> float:
        """180 when every unit looks at the zenith (:func:`heading_ambiguity_deg`), else 360."""
        return heading_ambiguity_deg([float(u["elevation_deg"]) for u in self.units])

    @property
    def unrecoverable(self) -> list[dict]:
        """What these data cannot tell, each ``{"quantity", "reason"}``, for a report."""
        out = []
        kind = self.readings_kind
        if kind == "normalised":
            why = ("the readings were normalised by their authors: their modulation depth is "
                   "not the sky's degree of polarization times an instrument scale")
            out += [{"quantity": "dop_scale", "reason": why},
                    {"quantity": "dark_offset", "reason": "normalised readings keep no dark "
                     "level"},
                    {"quantity": "radiance", "reason": "normalised readings keep no absolute "
                     "level"}]
        elif kind == "dark-subtracted":
            out.append({"quantity": "dark_offset", "reason": "the dark reading was removed "
                        "before the file was written (held at 0)"})
        if self.band == "unknown":
            out.append({"quantity": "molecular_optical_thickness",
                        "reason": "the spectral band is unknown: give 'band' as a name, a "
                        "centre wavelength or a response table"})
        if self.heading_ambiguity_deg == 180.0:
            out.append({"quantity": "heading_beyond_180_deg",
                        "reason": "every unit looks at the zenith: the heading is known "
                        "modulo 180 deg"})
        return out

    # ---------------------------------------------------------------- readings
    @property
    def readings(self) -> np.ndarray:
        """Photodiode readings (n, m) in the sidecar's unit (NaN where missing)."""
        return self.table[self.columns].to_numpy(dtype=float)

    def unit_readings(self, unit: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(readings (n, k), polarizer angles (k,) [deg], bad (n, k))`` of one unit with a
        fixed analyser.

        Raises
        ------
        UnsupportedOperationError
            For a unit whose analyser turns (its angles change per sample: use
            :attr:`polarizer_angles_deg`).
        """
        if self.units[unit]["analyser"]["kind"] != "fixed":
            raise UnsupportedOperationError(
                f"unit {unit} has a rotating analyser: its polarizer angles change per "
                "sample; use PhotodiodeData.polarizer_angles_deg")
        idx = np.flatnonzero(self.pd_unit == unit)
        angles = self.nominal_angles_deg[idx]
        return self.readings[:, idx], angles, self.flags.bad[:, idx]

    @property
    def extra_columns(self) -> list[str]:
        """Columns the schema does not define, kept as metadata."""
        known = {*_SCHEMA_COLUMNS, *self.columns, *_analyser_columns(self.units)}
        return [c for c in self.table.columns if c not in known]

    @property
    def has_accelerometer(self) -> bool:
        return all(c in self.table.columns for c in ACCEL_COLUMNS)

    def write(self, path) -> Path:
        """Same as :func:`write_photodiodes`."""
        return write_photodiodes(self, path)


def _analyser_columns(units) -> list[str]:
    return [u["analyser"]["angle_column"] for u in units
            if isinstance(u.get("analyser"), dict) and "angle_column" in u["analyser"]]


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


def _is_strict_number(value) -> bool:
    """True for a finite JSON number (not text, not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and bool(np.isfinite(value))


def _check_common(sidecar: dict, where: str) -> None:
    """Checks shared by both versions: site, yaw reference and sense, generator."""
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
    for key, valid in (("yaw_reference", _YAW_REFERENCES), ("yaw_sense", _YAW_SENSES)):
        _require(sidecar.get(key) in valid, where,
                 f"sidecar {key!r} is {sidecar.get(key)!r}; valid: {', '.join(valid)}")
    _require(isinstance(sidecar.get("generator", {}), dict), where,
             f"sidecar 'generator' must be an object; got {sidecar.get('generator')!r}")


def _check_unit_pointing(i: int, u, where: str) -> None:
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


def _validate_v1(sidecar: dict, where: str) -> None:
    """The checks of "skysim.photodiodes/1" (whole-degree angles, at least 3 per unit)."""
    _check_common(sidecar, where)
    _require(sidecar.get("readings") in _V1_READINGS, where,
             f"sidecar 'readings' is {sidecar.get('readings')!r}; valid: "
             f"{', '.join(_V1_READINGS)}")
    for key in ("adc_full_scale", "saturation_value"):
        v = sidecar.get(key)
        _require(_is_strict_number(v) and v > 0, where,
                 f"sidecar {key!r} must be a positive number; got {v!r}")
    units = sidecar.get("units")
    _require(isinstance(units, list) and len(units) > 0, where,
             "sidecar 'units' must be a non-empty list of {azimuth_deg, elevation_deg, "
             "photodiodes}")
    for i, u in enumerate(units):
        _check_unit_pointing(i, u, where)
        pds = list(u["photodiodes"])
        _require(len(pds) >= 3 and len({float(a) % 180 for a in pds}) >= 3, where,
                 f"unit {i} needs at least 3 photodiodes at distinct polarizer angles (mod 180) "
                 f"to determine a linear polarization; got {pds!r}")
        for a in pds:
            _require(float(a) == round(float(a)) and 0 <= float(a) < 180, where,
                     f"unit {i} photodiodes: polarizer angle {a!r} must be a whole number of "
                     f"degrees in [0, 180) (its column is u{i}_p{{angle:03d}})")


def migrate_sidecar(sidecar: dict, where: str = "photodiode data") -> dict:
    """A sidecar of the current version: a "/2" one copied, a "/1" one checked and converted.

    The conversion keeps every key and the column names, and sets ``readings`` to ``"raw"``
    with the first version's ``readings`` (``counts`` or ``volts``) as ``reading_unit``,
    ``time_uncertainty_s`` to 0, ``band`` to ``"unknown"`` and every unit's analyser to
    ``fixed``. Defaults of the current version are written out (see
    ``docs/photodiodes_schema.md``); the given dict is not modified.

    Raises
    ------
    PhotodiodeFormatError
        For another schema, or a "/1" sidecar that breaks its own contract.
    """
    _require(isinstance(sidecar, dict), where, "sidecar must be a JSON object")
    schema = sidecar.get("schema")
    _require(schema in PHOTODIODES_SCHEMAS, where,
             f"sidecar schema is {schema!r}, expected {PHOTODIODES_SCHEMA!r} (or "
             f"{PHOTODIODES_SCHEMA_V1!r}, converted on load)")
    side = copy.deepcopy(sidecar)
    if schema == PHOTODIODES_SCHEMA_V1:
        _validate_v1(side, where)
        side["schema"] = PHOTODIODES_SCHEMA
        side["reading_unit"] = side["readings"]
        side["readings"] = "raw"
        side["time_uncertainty_s"] = 0.0
        side["band"] = "unknown"
        side["units"] = [{"azimuth_deg": float(u["azimuth_deg"]),
                          "elevation_deg": float(u["elevation_deg"]),
                          "photodiodes": [float(a) for a in u["photodiodes"]],
                          "columns": [photodiode_column(i, a) for a in u["photodiodes"]],
                          "analyser": {"kind": "fixed"},
                          **{k: v for k, v in u.items() if k not in
                             ("azimuth_deg", "elevation_deg", "photodiodes")}}
                         for i, u in enumerate(side["units"])]
        return side
    side.setdefault("time_uncertainty_s", 0.0)
    side.setdefault("band", "unknown")
    units = side.get("units")
    if isinstance(units, list):
        for i, u in enumerate(units):
            if isinstance(u, dict):
                u.setdefault("analyser", {"kind": "fixed"})
                if "columns" not in u and isinstance(u.get("photodiodes"), list) \
                        and all(_is_number(a) for a in u["photodiodes"]):
                    try:
                        u["columns"] = [photodiode_column(i, a) for a in u["photodiodes"]]
                    except PhotodiodeFormatError:
                        pass        # the angle check below names the unit and the angle
    return side


def _check_band(band, where: str) -> None:
    valid = f"a band name ({', '.join(BANDS)}), 'unknown', {{'wavelength_nm': x, " \
            "'fwhm_nm': y}} or {'response': [[wavelength_nm, relative_response], ...]}"
    lo, hi = BAND_WAVELENGTH_RANGE_NM
    if isinstance(band, str):
        _require(band in BANDS or band == "unknown", where,
                 f"sidecar 'band' is {band!r}; valid: {valid}")
        return
    _require(isinstance(band, dict) and band and (set(band) <= {"wavelength_nm", "fwhm_nm"}
                                                  or set(band) == {"response"}),
             where, f"sidecar 'band' is {band!r}; valid: {valid}")
    if "response" in band:
        tab = band["response"]
        ok = isinstance(tab, list) and len(tab) >= 2 and all(
            isinstance(r, list) and len(r) == 2 and all(_is_strict_number(x) for x in r)
            for r in tab)
        _require(ok, where, f"sidecar band 'response' must be a list of at least 2 "
                 f"[wavelength_nm, relative_response] pairs; got {tab!r}")
        w, r = np.asarray(tab, float).T
        _require(bool(np.all(np.diff(w) > 0)), where,
                 f"sidecar band 'response' wavelengths must increase strictly; got {w.tolist()}")
        _require(bool(w[0] >= lo and w[-1] <= hi), where,
                 f"sidecar band 'response' wavelengths {w[0]:g}-{w[-1]:g} nm leave "
                 f"[{lo:g}, {hi:g}] nm")
        _require(bool(np.all(r >= 0) and np.trapezoid(r, w) > 0), where,
                 f"sidecar band 'response' must be >= 0 and not all 0; got {r.tolist()}")
        return
    _require("wavelength_nm" in band, where,
             f"sidecar 'band' {band!r} gives no 'wavelength_nm' (the centre of the "
             "photodiodes' response [nm]); without one write \"band\": \"unknown\"")
    w = band["wavelength_nm"]
    _require(_is_strict_number(w) and lo <= w <= hi, where,
             f"sidecar band 'wavelength_nm' must be a number in [{lo:g}, {hi:g}] nm; got {w!r}")
    if "fwhm_nm" in band:
        f = band["fwhm_nm"]
        _require(_is_strict_number(f) and f > 0, where,
                 f"sidecar band 'fwhm_nm' must be a positive number [nm]; got {f!r}")


def _check_analyser(i: int, a, where: str) -> None:
    _require(isinstance(a, dict) and a.get("kind") in _ANALYSER_KINDS, where,
             f"unit {i} analyser must be {{'kind': 'fixed'}} or {{'kind': 'rotating', ...}}; "
             f"got {a!r}")
    if a["kind"] == "fixed":
        _require(set(a) == {"kind"}, where, f"unit {i} analyser is fixed but gives "
                 f"{sorted(set(a) - {'kind'})}; a fixed analyser has no angle column or rate")
        return
    keys = set(a) - {"kind"}
    by_column, by_rate = "angle_column" in keys, "rate_deg_per_s" in keys
    _require(by_column != by_rate, where,
             f"unit {i} rotating analyser needs either 'angle_column' (a per-row angle [deg]) "
             f"or 'rate_deg_per_s' (with 'phase_deg' and 'epoch'), not "
             f"{'both' if by_column else 'neither'}; got {a!r}")
    allowed = {"angle_column"} if by_column else {"rate_deg_per_s", "phase_deg", "epoch"}
    _require(keys <= allowed, where, f"unit {i} analyser: unknown key(s) "
             f"{sorted(keys - allowed)}; valid with {'angle_column' if by_column else 'a rate'}: "
             f"{', '.join(sorted(allowed))}")
    if by_column:
        c = a["angle_column"]
        _require(isinstance(c, str) and c.strip() != "" and c not in _SCHEMA_COLUMNS, where,
                 f"unit {i} analyser 'angle_column' must name a column of the table other "
                 f"than {', '.join(_SCHEMA_COLUMNS)}; got {c!r}")
        return
    r = a["rate_deg_per_s"]
    _require(_is_strict_number(r) and r != 0, where,
             f"unit {i} analyser 'rate_deg_per_s' must be a non-zero number [deg/s] (negative: "
             f"turning towards decreasing polarizer angle); got {r!r}")
    p = a.get("phase_deg", 0.0)
    _require(_is_strict_number(p), where,
             f"unit {i} analyser 'phase_deg' must be a finite number [deg]; got {p!r}")
    e = a.get("epoch")
    if e is not None:
        ok = isinstance(e, str)
        if ok:
            try:
                ts = pd.Timestamp(e)
                ok = ts.tzinfo is not None
            except (ValueError, TypeError):
                ok = False
        _require(ok, where, f"unit {i} analyser 'epoch' must be an ISO 8601 time with a UTC "
                 f"offset (when the analyser was at 'phase_deg'); got {e!r}")


def _validate_sidecar(sidecar: dict, where: str) -> None:
    """Every field of a "skysim.photodiodes/2" sidecar (after :func:`migrate_sidecar`)."""
    _check_common(sidecar, where)
    kind = sidecar.get("readings")
    _require(kind in READINGS_KINDS, where,
             f"sidecar 'readings' is {kind!r}; valid: {', '.join(READINGS_KINDS)}"
             + (f" (the unit, {kind!r}, is 'reading_unit' in {PHOTODIODES_SCHEMA})"
                if kind in _V1_READINGS else ""))
    _require(sidecar.get("reading_unit") in READING_UNITS, where,
             f"sidecar 'reading_unit' is {sidecar.get('reading_unit')!r}; valid: "
             f"{', '.join(READING_UNITS)}")
    for key in ("adc_full_scale", "saturation_value"):
        v = sidecar.get(key)
        if kind == "normalised" and v is None:
            continue
        _require(_is_strict_number(v) and v > 0, where,
                 f"sidecar {key!r} must be a positive number"
                 f"{' (or null for normalised readings)' if kind == 'normalised' else ''}; "
                 f"got {v!r}")
    tu = sidecar.get("time_uncertainty_s")
    _require(_is_strict_number(tu) and tu >= 0, where,
             f"sidecar 'time_uncertainty_s' must be a number >= 0 [s]; got {tu!r}")
    _check_band(sidecar.get("band"), where)
    units = sidecar.get("units")
    _require(isinstance(units, list) and len(units) > 0, where,
             "sidecar 'units' must be a non-empty list of {azimuth_deg, elevation_deg, "
             "photodiodes}")
    seen: dict[str, str] = {}
    for i, u in enumerate(units):
        _check_unit_pointing(i, u, where)
        pds = [float(a) for a in u["photodiodes"]]
        for a in pds:
            _require(0 <= a < 180, where, f"unit {i} photodiodes: polarizer angle {a!r} must be "
                     "in [0, 180) [deg]")
        _require(len(pds) >= 2 and len({a % 180 for a in pds}) == len(pds), where,
                 f"unit {i} needs at least 2 photodiodes at distinct polarizer angles (mod 180);"
                 f" got {u['photodiodes']!r}")
        _check_analyser(i, u.get("analyser"), where)
        cols = u.get("columns")
        _require(isinstance(cols, list) and len(cols) == len(pds)
                 and all(isinstance(c, str) and c.strip() for c in cols), where,
                 f"unit {i} columns must be a list of {len(pds)} column names, one per "
                 f"photodiode; got {cols!r}")
        ana = u["analyser"].get("angle_column")
        named = [(c, "photodiode") for c in cols] + ([(ana, "analyser")] if ana else [])
        for c, role in named:
            _require(c not in _SCHEMA_COLUMNS, where,
                     f"unit {i} column {c!r} is a column the schema reserves")
            owner = f"unit {i} {role}"
            # one angle column may drive several units' analysers (one wheel)
            _require(c not in seen or (role == "analyser" and seen[c].endswith("analyser")),
                     where, f"column {c!r} is named by both {seen.get(c)} and {owner}")
            seen.setdefault(c, owner)


def _validate_table(table: pd.DataFrame, columns: list[str], side: dict, where: str) -> None:
    present = [c for c in table.columns if _PD_RE.match(str(c))]
    missing = [c for c in columns if c not in table.columns]
    unexpected = [c for c in present if c not in columns]
    if missing or unexpected:
        raise SidecarMismatchError(
            f"{where}: the sidecar's units do not match the photodiode columns: "
            f"missing from the table {missing}, not announced by the sidecar {unexpected}. "
            "Each photodiode needs the column its unit's 'columns' name (by default "
            "u{unit}_p{angle}, e.g. u0_p045)",
            missing, unexpected)
    _require("time" in table.columns, where, "missing required column 'time'")
    optional = [c for c in ("pitch_deg", "roll_deg", *ACCEL_COLUMNS) if c in table.columns]
    analyser = sorted(set(_analyser_columns(side["units"])))
    for c in analyser:
        _require(c in table.columns, where, f"the table has no column {c!r}, which the "
                 "sidecar names as a rotating analyser's angle [deg]")
    try:   # the measurement schema's checks, re-raised as this schema's error
        table["time"] = parse_iso_times(table["time"], where)
        check_numeric_columns(table, ["yaw_deg", *optional, *analyser], where)
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
    """Write the table (``.csv`` or ``.parquet``) and its "skysim.photodiodes/2" sidecar
    atomically (both or neither).

    The flags are not written: they are recomputed by the reader from the readings.
    """
    return write_table_and_sidecar(data.table, data.sidecar, path)


def read_photodiodes(path) -> PhotodiodeData:
    """Read a photodiode table and its sidecar ("/2", or "/1" converted on load), flagging
    suspicious readings per sample.

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
