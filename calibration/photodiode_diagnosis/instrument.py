"""Adapter from photodiode data (``skysim.photodiodes/2``) to the arrays the diagnosis fits.

Any instrument: N units of two or more photodiodes, any unit azimuth/elevation, any polarizer
angles, fixed or rotating analysers, raw, dark-subtracted or normalised readings, absolute or
relative yaw in either sense. The adapter converts the
yaw to the project's heading convention (clockwise from north, unwrapped along each sweep so
that a turn stays one continuous angle), finds the sweeps and whether the platform is turning,
and keeps the reader's per-reading flags. It never drops a sample; rows written out of time
order are put in time order (a stable sort: samples with equal times keep the file's order),
because the turn, the sweeps and the noise floor are read along the sample sequence.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from sensor.compound_eye import CompoundEyeSensor, PhotodiodeModel
from sensor.photodiodes_io import PhotodiodeData, heading_ambiguity_deg
from skysim.sun import Site, as_utc_index

from .errors import InsufficientDataError, InstrumentDataError, YawInRadiansWarning

__all__ = ["Instrument", "ROTATING_RATE_DEG_PER_SAMPLE", "MAX_SPAN_DAYS", "analyser_cycles",
           "held_readings", "instrument_from_photodiodes"]

MAX_SPAN_DAYS = 7.0
"""Samples farther than this from the file's median time are not of the same session [days]:
the fit shares the instrument's gains, offsets and the sky's DoP scale over the whole file,
and such a sample is a clock glitch (an unset or reset real-time clock reads 1970 or 2000),
which would also make the sun's track span decades."""

RADIAN_SPAN = 3.0
"""A yaw column whose values all lie within +-pi (or within [0, 2 pi]) but span more than this
[its own units] is warned about as radians (:class:`YawInRadiansWarning`): a platform that
turns by 3 deg or more yet never leaves +-3.14 deg (or 0-6.28 deg) is rare, a turn recorded
in radians spans up to 2 pi."""

ROTATING_RATE_DEG_PER_SAMPLE = 0.2
"""A sample is *rotating* when the yaw changes by more than this per sample [deg] (median over
a 5-sample window): an IMU at rest drifts by far less, a platform turning once in a few hundred
samples by about 1 deg per sample."""


@dataclass
class Instrument:
    """The photodiode instrument and its readings, ready for the forward model.

    Attributes
    ----------
    sensor : CompoundEyeSensor
        Nominal geometry from the sidecar (unit views and polarizer angles).
    site : Site
    t_s : ndarray (n,)
        Recorded sample times [s since 1970-01-01 UTC], in time order (the other per-sample
        arrays follow the same order).
    yaw_deg : ndarray (n,)
        Recorded yaw converted to clockwise [deg], unwrapped within each sweep.
    sweep : ndarray (n,) of int
        Sweep index 0..S-1 (the ``sweep`` column, else runs separated by time gaps).
    rotating : ndarray (n,) bool
    pitch_deg, roll_deg : ndarray (n,)
        Recorded body attitude [deg] (zeros where the file has none).
    readings : ndarray (n, P)
        Photodiode readings in the file's unit.
    pd_unit : ndarray (P,) of int ; pd_angle_deg : ndarray (P,)
    columns : list of str
        Photodiode column names (P,).
    flagged : ndarray (n, P) bool
        Readings the reader flagged (saturated, zero, missing, dead) and the readings a unit
        holds from its previous conversion (:func:`held_readings`).
    absolute_yaw : bool
        True when the yaw is a heading from north (``yaw_reference == "north"``).
    source : dict
    held : ndarray (n, P) bool, optional
        The held readings among ``flagged`` (:func:`held_readings`): excluded from fits, but
        part of what the instrument outputs at a sample, so heading decoding uses them.
    pointing_deg : ndarray (2 U,), optional
        Calibrated pointing of the units [deg]: elevation offsets from nominal, then azimuth
        offsets, from other diagnoses of the same instrument
        (:func:`calibration.photodiode_diagnosis.calibrated_pointing`). Every fit then holds
        the pointing there (NaN: a unit not calibrated, fitted); ``None`` (default) fits all.
    light : {"sun", "moon"}
        The body whose light the sky scatters: ``"moon"`` for a session under the moonlit
        night sky (the Moon takes the Sun's place in every model, as in
        :class:`skysim.night.MoonlitSky`).
    time_uncertainty_s : float
        Standard uncertainty [s] of the recorded times themselves (0: a logged clock). A
        logger without a clock whose times were reconstructed afterwards (a session's start
        from a photograph, then a nominal cadence) has one; the clock candidate adds it in
        quadrature to its own uncertainty, since a clock fitted to within its statistics
        is no better than the times it corrects. Read from the sidecar.
    pd_angle_row_deg : ndarray (n, P), optional
        Polarizer angle of every photodiode at every sample [deg] when an analyser turns
        (:attr:`sensor.photodiodes_io.PhotodiodeData.polarizer_angles_deg`); None: every
        analyser is fixed and ``pd_angle_deg`` holds for every sample.
    readings_kind : {"raw", "dark-subtracted", "normalised"}
        What the readings are (:data:`sensor.photodiodes_io.READINGS_KINDS`).
    unrecoverable : list of dict
        What the data cannot tell, ``{"quantity", "reason"}``
        (:attr:`sensor.photodiodes_io.PhotodiodeData.unrecoverable`), for the report.
    analyser_cycle : ndarray (n,) of int, optional
        Half-turn of the (first) rotating analyser each sample belongs to, counted within
        its sweep (:func:`analyser_cycles`); None without a rotating analyser.
    """

    sensor: CompoundEyeSensor
    site: Site
    t_s: np.ndarray
    yaw_deg: np.ndarray
    sweep: np.ndarray
    rotating: np.ndarray
    pitch_deg: np.ndarray
    roll_deg: np.ndarray
    readings: np.ndarray
    pd_unit: np.ndarray
    pd_angle_deg: np.ndarray
    columns: list
    flagged: np.ndarray
    absolute_yaw: bool
    source: dict = field(default_factory=dict)
    held: np.ndarray | None = None
    pointing_deg: np.ndarray | None = None
    light: str = "sun"
    time_uncertainty_s: float = 0.0
    pd_angle_row_deg: np.ndarray | None = None
    readings_kind: str = "raw"
    unrecoverable: list = field(default_factory=list)
    analyser_cycle: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.t_s.size

    @property
    def heading_ambiguity_deg(self) -> float:
        """180 when every unit looks within a few degrees of the zenith (its heading is known
        modulo 180 deg, :func:`sensor.photodiodes_io.heading_ambiguity_deg`), else 360."""
        return heading_ambiguity_deg([u.elevation_deg for u in self.sensor.units])

    @property
    def n_units(self) -> int:
        return self.sensor.n_units

    @property
    def n_sweeps(self) -> int:
        return int(self.sweep.max()) + 1

    def subset(self, rows) -> "Instrument":
        """The same instrument on a subset of samples (sweeps renumbered 0..S'-1)."""
        rows = np.asarray(rows)
        _, sweep = np.unique(self.sweep[rows], return_inverse=True)
        return replace(self, t_s=self.t_s[rows], yaw_deg=self.yaw_deg[rows], sweep=sweep,
                       rotating=self.rotating[rows], pitch_deg=self.pitch_deg[rows],
                       roll_deg=self.roll_deg[rows], readings=self.readings[rows],
                       flagged=self.flagged[rows],
                       held=None if self.held is None else self.held[rows],
                       pd_angle_row_deg=None if self.pd_angle_row_deg is None
                       else self.pd_angle_row_deg[rows],
                       analyser_cycle=None if self.analyser_cycle is None
                       else self.analyser_cycle[rows])

    def with_readings(self, readings) -> "Instrument":
        """The same instrument and samples with other readings (same shape)."""
        readings = np.asarray(readings, float)
        if readings.shape != self.readings.shape:
            raise ValueError(f"readings must have shape {self.readings.shape}; "
                             f"got {readings.shape}")
        return replace(self, readings=readings)


def _sweeps(table, t_s: np.ndarray, rows: np.ndarray, where: str) -> np.ndarray:
    """Sweep index of every sample; ``rows`` (the file row of each sample) for messages."""
    if "sweep" in table.columns:
        raw = table["sweep"].to_numpy()
        if table["sweep"].isna().any():
            row = int(rows[np.flatnonzero(table["sweep"].isna().to_numpy())[0]])
            raise InstrumentDataError(f"{where}: column 'sweep' is empty in row {row}; give "
                                      "every sample its sweep or drop the column")
        # sweeps in order of first appearance
        _, first, inv = np.unique(raw, return_index=True, return_inverse=True)
        order = np.argsort(np.argsort(first))
        return order[inv.ravel()]
    # no sweep column: new sweep where the clock jumps by more than 60 s
    jump = np.r_[False, np.diff(t_s) > 60.0]
    return np.cumsum(jump)


def _unwrap_per_sweep(yaw: np.ndarray, sweep: np.ndarray) -> np.ndarray:
    out = np.empty_like(yaw)
    for s in np.unique(sweep):
        m = sweep == s
        out[m] = np.degrees(np.unwrap(np.radians(yaw[m])))
    return out


def analyser_cycles(angle_deg: np.ndarray, sweep: np.ndarray) -> np.ndarray:
    """Index (n,) of the half-turn of a rotating analyser each sample falls in, distinct per
    sweep: its angle [deg] unwrapped along each sweep (successive samples less than 180 deg
    apart), counted in steps of 180 deg from the sweep's first sample. Within a half-turn the
    analyser passes every polarizer angle once."""
    au = _unwrap_per_sweep(np.asarray(angle_deg, float), sweep)
    first = np.zeros_like(au)
    for s in np.unique(sweep):
        m = sweep == s
        first[m] = au[m][0]
    half = np.floor((au - first) / 180.0).astype(int)
    return np.unique(np.c_[sweep, half], axis=0, return_inverse=True)[1].ravel()


def _rotating(yaw: np.ndarray, sweep: np.ndarray) -> np.ndarray:
    rate = np.abs(np.gradient(yaw)) if yaw.size > 1 else np.zeros_like(yaw)
    edge = np.r_[True, sweep[1:] != sweep[:-1]] | np.r_[sweep[1:] != sweep[:-1], True]
    rate[edge] = 0.0
    k = 5
    pad = np.pad(rate, k // 2, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(pad, k)
    return np.median(windows, axis=1) > ROTATING_RATE_DEG_PER_SAMPLE


def held_readings(readings: np.ndarray, pd_unit: np.ndarray) -> np.ndarray:
    """Readings (n, P) that repeat their unit's previous conversion (sample and hold).

    A unit's reading at a sample is *held* when every photodiode of that unit reads exactly
    what it read at the previous sample (missing values count as equal; a unit with no finite
    reading is not marked). A multiplexed logger converts one or two units per sample and
    holds the others: on the reference ring 78-82 % of every unit's daylight readings are
    held, a unit converting its four photodiodes together about every 4.8 samples.
    A held reading is no new measurement, and while the platform turns (about 1 deg per
    sample there) it belongs to the heading of its conversion up to a few samples earlier,
    not to the sample's; kept, it also adds zero second differences that bias the noise
    floor low. With 4 noisy photodiodes at tens of counts or more, an equal conversion by
    chance is rare; at a few counts (a dark twilight sky) it is common, but such units carry
    no polarization signal and the fault screen excludes them as zero or dead.
    """
    r = np.asarray(readings, float)
    n, P = r.shape
    out = np.zeros((n, P), bool)
    if n < 2:
        return out
    a, b = r[1:], r[:-1]
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    finite = np.isfinite(a)
    for u in np.unique(pd_unit):
        cols = np.flatnonzero(pd_unit == u)
        held = same[:, cols].all(axis=1) & finite[:, cols].any(axis=1)
        out[1:, cols] = held[:, None]
    return out


def instrument_from_photodiodes(data: PhotodiodeData, where: str = "photodiode data") -> Instrument:
    """Build the :class:`Instrument` of a photodiode file.

    Raises
    ------
    InstrumentDataError
        For a yaw that is not a finite number, a time more than :data:`MAX_SPAN_DAYS` from
        the session's median time, an empty sweep label, or a unit without columns.
    InsufficientDataError
        With fewer than two sweeps (a held-out split needs whole sweeps).

    Readings a unit holds from its previous conversion are excluded (:func:`held_readings`)
    and counted in ``source["held_readings"]``.

    Warns
    -----
    YawInRadiansWarning
        When every yaw lies within +-pi or [0, 2 pi] but spans more than :data:`RADIAN_SPAN`.
    """
    table = data.table
    yaw = table["yaw_deg"].to_numpy(dtype=float)
    if not np.isfinite(yaw).all():
        row = int(np.flatnonzero(~np.isfinite(yaw))[0])
        raise InstrumentDataError(f"{where}: yaw_deg is not a finite number in row {row} "
                                  f"({table['yaw_deg'].iloc[row]!r}); the heading of every "
                                  "sample is needed")
    radian_range = (np.all(np.abs(yaw) <= np.pi + 1e-9)
                    or np.all((yaw >= 0.0) & (yaw <= 2 * np.pi + 1e-9))) if yaw.size else False
    if radian_range and np.ptp(yaw) > RADIAN_SPAN:
        warnings.warn(YawInRadiansWarning(
            f"{where}: every yaw_deg lies within +-pi or [0, 2 pi] ({yaw.min():.3f} to "
            f"{yaw.max():.3f}) "
            f"while it spans {np.ptp(yaw):.3f}: if the column is in radians, convert it to "
            "degrees (a full turn would read as 6.3 deg and no sweep would turn)"), stacklevel=2)
    t_s = as_utc_index(table["time"]).as_unit("ns").asi8 / 1e9
    if t_s.size:
        far = np.abs(t_s - np.median(t_s)) / 86400.0
        if far.max() > MAX_SPAN_DAYS:
            row = int(np.argmax(far))
            raise InstrumentDataError(
                f"{where}: time {table['time'].iloc[row]} in row {row} is {far[row]:.1f} days "
                f"from the session's median time; samples more than {MAX_SPAN_DAYS:g} days "
                "apart are not one session (a clock glitch?): fix or drop that row")
    readings, flagged = data.readings, data.flags.bad.copy()
    row_angles = data.polarizer_angles_deg if data.rotating_units else None
    analyser = data.analyser_angles_deg()[:, data.rotating_units[0]] if data.rotating_units \
        else None
    rows = np.arange(len(table))
    if np.any(np.diff(t_s) < 0):   # rows written out of time order: samples in time order
        rows = np.argsort(t_s, kind="stable")
        table, yaw, t_s = table.iloc[rows].reset_index(drop=True), yaw[rows], t_s[rows]
        readings, flagged = readings[rows], flagged[rows]
        row_angles = None if row_angles is None else row_angles[rows]
        analyser = None if analyser is None else analyser[rows]
    if data.sidecar["yaw_sense"] == "counterclockwise":
        yaw = -yaw
    sweep = _sweeps(table, t_s, rows, where)
    if np.unique(sweep).size < 2:
        found = "no samples" if len(table) == 0 else f"only one sweep in {len(table)} samples"
        raise InsufficientDataError(
            f"{where}: {found}; the diagnosis fits on some sweeps and scores on held-out ones: "
            "record at least two (column 'sweep')")
    yaw = _unwrap_per_sweep(yaw, sweep)
    att = {}
    for c in ("pitch_deg", "roll_deg"):
        v = table[c].to_numpy(dtype=float) if c in table.columns else np.zeros(len(table))
        att[c] = np.where(np.isfinite(v), v, 0.0)
    counts = PhotodiodeModel(counts_per_radiance=1.0, noise_counts=0.0)
    sensor = CompoundEyeSensor.from_sidecar(data.sidecar, counts)
    pd_unit = data.pd_unit
    held = held_readings(readings, pd_unit)
    flagged = flagged | held
    pd_angle = data.nominal_angles_deg
    for i in range(sensor.n_units):
        if not np.any(pd_unit == i):
            raise InstrumentDataError(f"{where}: unit {i} lists no photodiode columns")
    return Instrument(
        sensor=sensor, site=data.site, t_s=t_s, yaw_deg=yaw, sweep=sweep,
        rotating=_rotating(yaw, sweep), pitch_deg=att["pitch_deg"], roll_deg=att["roll_deg"],
        readings=readings, pd_unit=pd_unit, pd_angle_deg=pd_angle,
        columns=list(data.columns), flagged=flagged, held=held,
        absolute_yaw=data.sidecar["yaw_reference"] == "north",
        time_uncertainty_s=data.time_uncertainty_s, pd_angle_row_deg=row_angles,
        readings_kind=data.readings_kind, unrecoverable=data.unrecoverable,
        analyser_cycle=None if analyser is None else analyser_cycles(analyser, sweep),
        source={"path": where, "schema": data.sidecar["schema"],
                "readings": data.reading_unit, "readings_kind": data.readings_kind,
                "heading_ambiguity_deg": data.heading_ambiguity_deg,
                "band_wavelength_nm": data.band_wavelength_nm,
                "samples": int(len(table)),
                "photodiodes": len(data.columns), "units": sensor.n_units,
                "sweeps": int(np.unique(sweep).size),
                "yaw_reference": data.sidecar["yaw_reference"],
                "yaw_sense": data.sidecar["yaw_sense"],
                "saturation_value": None if data.sidecar.get("saturation_value") is None
                else float(data.sidecar["saturation_value"]),
                "held_readings": int(held.sum())})
