"""Data of the three-pair sensor's diagnosis: a measurement table ("skysim.measurement/1") or
raw photodiode data of the three orthogonal pairs ("skysim.photodiodes/1"), read tolerantly
(bad readings flagged and counted, never silently dropped) into :class:`DiagnosisData`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from sensor.measurement import (
    CHANNEL_COLUMNS,
    MEASUREMENT_SCHEMA,
    MeasurementFormatError,
    parse_iso_times,
)
from sensor.opponent import CHANNEL_ANGLES_DEG, GAIN
from sensor.photodiodes_io import PHOTODIODES_SCHEMA, PHOTODIODES_SCHEMAS, PhotodiodeData
from sensor.tables import read_table_and_sidecar

from ..effects import Context
from .errors import AllNaNChannelError, MissingSiteError, UnsupportedInstrumentError

__all__ = ["MIN_SUN_ELEVATION_DEG", "DiagnosisData", "data_from_photodiodes",
           "data_from_table", "load_diagnosis_data", "read_sidecar"]

_MIN_BLOCK_ROWS = 10
MIN_SUN_ELEVATION_DEG = 1.0
"""Samples whose recorded time puts the sun lower than this [deg] are excluded and counted
(plane-parallel sky models do not hold at the horizon; a clock error can cause it)."""


@dataclass
class DiagnosisData:
    """Measured outputs with their context and the data cleaning applied.

    Attributes
    ----------
    ctx : Context
    U : ndarray (n, 3)
        Channel outputs [V] (NaN where missing).
    valid : ndarray (n, 3) bool
        Readings used (finite, not saturated, channel not dead).
    cleaning : dict
        What was flagged or excluded, with counts.
    source : dict
        Path, schema and other provenance.
    """

    ctx: Context
    U: np.ndarray
    valid: np.ndarray
    cleaning: dict = field(default_factory=dict)
    source: dict = field(default_factory=dict)

    def __post_init__(self):
        self.U = np.asarray(self.U, dtype=float)
        if self.U.shape != (self.ctx.n, 3):
            raise ValueError(f"U must have shape ({self.ctx.n}, 3); got {self.U.shape}")
        self.valid = np.asarray(self.valid, bool) & np.isfinite(self.U)
        for c in range(3):
            if not np.isfinite(self.U[:, c]).any():
                raise AllNaNChannelError(
                    f"channel U{c + 1}_V has no finite value in {self.ctx.n} rows; check the "
                    "column mapping or drop the sensor from the data set")

    @classmethod
    def from_arrays(cls, ctx: Context, U, saturation_V=None, source=None):
        """Flag non-finite, saturated (``|U| >= saturation_V``, or outside ``(lo, hi)`` for a
        pair) and dead (constant) readings, and samples with the sun below
        :data:`MIN_SUN_ELEVATION_DEG` at the recorded time."""
        U = np.asarray(U, dtype=float)
        finite = np.isfinite(U)
        sat = np.zeros(U.shape, bool)
        if saturation_V is not None:
            lo, hi = (saturation_V if isinstance(saturation_V, tuple)
                      else (-saturation_V, saturation_V))
            with np.errstate(invalid="ignore"):
                sat = (U <= lo) | (U >= hi)
        dead = np.zeros(3, bool)
        if U.shape[0] >= _MIN_BLOCK_ROWS:
            dead = np.array([np.nanmax(U[:, c]) == np.nanmin(U[:, c])
                             if finite[:, c].any() else False for c in range(3)])
        sun_el, _ = ctx.sun.elevation_azimuth(ctx.t_s)
        night = sun_el <= MIN_SUN_ELEVATION_DEG
        valid = finite & ~sat & ~dead[None, :] & ~night[:, None]
        t = ctx.t_s
        cleaning = {"rows": int(U.shape[0]), "missing_readings": int((~finite).sum()),
                    "saturated_readings": int(sat.sum()),
                    "dead_channels": [f"U{c + 1}_V" for c in range(3) if dead[c]],
                    "sun_below_horizon_samples": int(night.sum()),
                    "excluded_readings": int((~valid).sum()),
                    "repeated_timestamps": int(U.shape[0] - np.unique(t).size)}
        data = cls.__new__(cls)
        data.ctx, data.U, data.valid = ctx, U, valid
        data.cleaning, data.source = cleaning, dict(source or {})
        data.__post_init__()
        return data


def _site_of(sidecar: dict, where: str):
    from skysim.sun import Site
    if not isinstance(sidecar.get("site"), dict):
        raise MissingSiteError(
            f"{where}: sidecar has no 'site' (latitude_deg, longitude_deg, altitude_m); the sun "
            "position, hence the sky model, cannot be computed: add the site to the sidecar")
    return Site.from_dict(sidecar["site"])


def _daq_saturation_V(sidecar: dict, where: str):
    """Rails ``(lo, hi)`` [V] from the sidecar's ``sensor.daq`` (``bits``, ``range_V`` as a
    symmetric full scale ``R`` or ``[lo, hi]``), one LSB inside each rail; None without a DAQ.

    Raises
    ------
    MeasurementFormatError
        For a ``daq`` block whose ``bits`` is not a whole number in 1..32 or whose
        ``range_V`` is neither a positive number nor ``[lo, hi]`` with ``lo < hi``.
    """
    sensor = sidecar.get("sensor") or {}
    daq = sensor.get("daq") if isinstance(sensor, dict) else None
    if not daq:
        return None
    if not isinstance(daq, dict):
        raise MeasurementFormatError(f"{where}: sidecar sensor.daq must be an object with "
                                     f"'bits' and 'range_V'; got {daq!r}")
    bits = daq.get("bits")
    if bits is None:
        return None
    if isinstance(bits, bool) or not isinstance(bits, (int, float)) or bits != int(bits) \
            or not 1 <= bits <= 32:
        raise MeasurementFormatError(f"{where}: sidecar sensor.daq.bits must be a whole number "
                                     f"in 1..32; got {bits!r}")
    rng_v = daq.get("range_V", 10.0)
    if isinstance(rng_v, (list, tuple)) and len(rng_v) == 2 and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in rng_v) \
            and rng_v[0] < rng_v[1]:
        lo, hi = float(rng_v[0]), float(rng_v[1])
    elif isinstance(rng_v, (int, float)) and not isinstance(rng_v, bool) and rng_v > 0:
        lo, hi = -float(rng_v), float(rng_v)
    else:
        raise MeasurementFormatError(
            f"{where}: sidecar sensor.daq.range_V must be a positive full scale [V] or "
            f"[lo, hi] with lo < hi; got {rng_v!r}")
    lsb = (hi - lo) / 2 ** int(bits)
    return lo + lsb, hi - lsb


def data_from_table(table, sidecar: dict, where: str = "measurement") -> DiagnosisData:
    """:class:`DiagnosisData` from a "skysim.measurement/1" table, tolerating bad readings.

    Unlike :func:`sensor.measurement.read_measurement`, NaN channel values are kept (masked and
    counted), readings at the DAQ rails (sidecar ``sensor.daq``) are flagged as saturated, a
    channel stuck at one value is flagged dead. Blocks are the ``sweep`` column, else runs of
    samples separated by gaps longer than 10 x the median sample spacing.

    Raises
    ------
    MissingSiteError, MeasurementFormatError, AllNaNChannelError
    """
    site = _site_of(sidecar, where)
    for c in ("time", "heading_deg") + CHANNEL_COLUMNS:
        if c not in table.columns:
            raise MeasurementFormatError(
                f"{where}: missing required column {c!r}; found {list(table.columns)}")
    times = parse_iso_times(table["time"], where)
    heading = pd.to_numeric(table["heading_deg"], errors="coerce").to_numpy(float)
    if not np.isfinite(heading).all():
        row = int(np.flatnonzero(~np.isfinite(heading))[0])
        raise MeasurementFormatError(f"{where}: heading_deg is not a number in row {row}")
    if "sweep" in table.columns:
        block = table["sweep"].to_numpy()
    else:
        t = times.dt.tz_convert("UTC").astype("int64").to_numpy() / 1e9
        dt = np.diff(t)
        pos = dt[dt > 0]
        gap = 10.0 * (np.median(pos) if pos.size else 1.0)
        block = np.r_[0, np.cumsum(dt > gap)]
    opt = {c: pd.to_numeric(table[c], errors="coerce").to_numpy(float)
           for c in ("illuminance_lx", "temperature_C") if c in table.columns}
    ctx = Context.from_arrays(site, times, heading, block, opt.get("illuminance_lx"),
                              opt.get("temperature_C"))
    sat = _daq_saturation_V(sidecar, where)
    U = np.stack([pd.to_numeric(table[c], errors="coerce").to_numpy(float)
                  for c in CHANNEL_COLUMNS], axis=1)
    return DiagnosisData.from_arrays(ctx, U, saturation_V=sat,
                                     source={"schema": MEASUREMENT_SCHEMA, "path": where})


def data_from_photodiodes(pd_data: PhotodiodeData, where: str = "photodiodes") -> DiagnosisData:
    """Three-pair channels ``U_i = g log10(S(a_i) / S(a_i + 90))`` from raw photodiode data.

    Uses the first unit holding the six polarizer angles 60/150, 0/90, 120/30 deg (numerator
    and denominator of U1, U2, U3, :mod:`sensor.photodiode`); readings flagged by the reader
    (saturated, zero, missing, dead) are excluded and counted. ``yaw_deg`` is the heading
    (sign flipped for ``yaw_sense = counterclockwise``); a relative yaw only adds a constant
    offset, which the mounting errors absorb.

    Raises
    ------
    UnsupportedInstrumentError
        When no unit has the six angles.
    """
    site = _site_of(pd_data.sidecar, where)
    need = [(a, (a + 90) % 180) for a in CHANNEL_ANGLES_DEG.astype(int)]
    unit = next((i for i, u in enumerate(pd_data.units)
                 if {round(a) for a in u["photodiodes"]} >= {x for p in need for x in p}),
                None)
    if unit is None:
        raise UnsupportedInstrumentError(
            f"{where}: no unit has polarizers at 60/150, 0/90 and 120/30 deg (the three "
            "orthogonal pairs of the three-pair sensor); the diagnosis models that sensor only")
    mine = np.flatnonzero(pd_data.pd_unit == unit)
    column_at = {round(float(pd_data.nominal_angles_deg[j])): int(j) for j in mine}
    bad = pd_data.flags.bad
    R = pd_data.readings
    U = np.empty((R.shape[0], 3))
    for c, (a, b) in enumerate(need):
        ia, ib = column_at[a], column_at[b]     # the unit's own columns, whatever their names
        with np.errstate(divide="ignore", invalid="ignore"):
            U[:, c] = GAIN * np.log10(R[:, ia] / R[:, ib])
        U[bad[:, ia] | bad[:, ib], c] = np.nan
    t = pd_data.table
    yaw = t["yaw_deg"].to_numpy(float)
    if pd_data.sidecar.get("yaw_sense") == "counterclockwise":
        yaw = -yaw
    table = pd.DataFrame({"time": t["time"], "heading_deg": yaw, "U1_V": U[:, 0],
                          "U2_V": U[:, 1], "U3_V": U[:, 2]})
    if "sweep" in t.columns:
        table["sweep"] = t["sweep"].to_numpy()
    data = data_from_table(table, {"site": site.to_dict()}, where)
    data.cleaning["photodiode_flags"] = pd_data.flags.summary()
    data.cleaning["unit"] = unit
    data.cleaning["yaw_reference"] = pd_data.sidecar.get("yaw_reference")
    data.source = {"schema": PHOTODIODES_SCHEMA, "path": where}
    return data


def read_sidecar(path) -> dict:
    """The JSON sidecar beside a data file, as a dict.

    Raises
    ------
    FileNotFoundError
        Without a sidecar.
    MeasurementFormatError
        For a sidecar that is not a JSON object.
    """
    import json

    from skysim.io import find_sidecar, sidecar_path
    side = find_sidecar(path)
    if side is None:
        raise FileNotFoundError(f"no sidecar {sidecar_path(path)} beside {path}")
    try:
        sidecar = json.loads(side.read_text())
    except ValueError as exc:
        raise MeasurementFormatError(f"{side}: not valid JSON ({exc})") from None
    if not isinstance(sidecar, dict):
        raise MeasurementFormatError(f"{side}: a sidecar must be a JSON object; got "
                                     f"{type(sidecar).__name__}")
    return sidecar


def load_diagnosis_data(path) -> DiagnosisData:
    """Read a measurement table or photodiode data of the three-pair sensor (schema from the
    sidecar).

    Raises
    ------
    FileNotFoundError, MeasurementFormatError
        Without a readable sidecar, or for another schema.
    """
    from skysim.io import find_sidecar
    sidecar = read_sidecar(path)
    schema = sidecar.get("schema")
    if schema in PHOTODIODES_SCHEMAS:
        from sensor.photodiodes_io import read_photodiodes
        return data_from_photodiodes(read_photodiodes(path), str(path))
    if schema != MEASUREMENT_SCHEMA:
        raise MeasurementFormatError(
            f"{find_sidecar(path)}: schema {schema!r} is neither {MEASUREMENT_SCHEMA!r} nor "
            f"{PHOTODIODES_SCHEMA!r}")
    table, sidecar = read_table_and_sidecar(path, MEASUREMENT_SCHEMA, MeasurementFormatError)
    return data_from_table(table, sidecar, str(path))
