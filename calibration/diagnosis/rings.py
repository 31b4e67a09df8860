"""Adapter of multi-unit photodiode instruments (rings, domes): runs
:func:`calibration.photodiode_diagnosis.diagnose_instrument`, which returns the shared
:class:`.report.DiagnosisReport`.

The ring diagnosis keeps its own physics (forward model, fits, fault screen, clock
refinement, pointing) and runs the method of every instrument (:mod:`.judge`): the
one verdict rule with the ring's thresholds
(:data:`calibration.photodiode_diagnosis.run.RING_THRESHOLDS`: the paired rule of every
instrument, with the named effect also lowering the gap in most held-out sweeps). This
adapter adds the notes on what pins a clock offset.
"""

from __future__ import annotations

import numpy as np

from .report import DiagnosisReport

__all__ = ["RingAdapter", "clock_notes", "diagnose_rings", "pointing_from_reports",
           "ring_candidates"]


def ring_candidates(names=None) -> tuple:
    """Validated candidate names of the ring diagnosis (default: its default set).

    Raises
    ------
    UnknownEffectError
        For a name the ring diagnosis does not know (the message lists the valid ones), or
        two names of one candidate (``side_glare`` and ``side_glare(scale_deg=94)``: a
        report names each candidate once).
    """
    from ..effects import UnknownEffectError
    from ..photodiode_diagnosis import RING_EFFECT_NAMES, get_ring_effect
    if names is None:
        return RING_EFFECT_NAMES
    names = tuple(names)
    seen: dict = {}
    for n in names:
        base = get_ring_effect(n).name
        if base in seen:
            raise UnknownEffectError(f"{seen[base]!r} and {n!r} are the same candidate, "
                                     f"{base}: ask for it once")
        seen[base] = n
    return names


def clock_notes(report: DiagnosisReport) -> list[str]:
    """What pins the clock-offset candidate's fit, in words (empty without one)."""
    c = report.candidate("clock_offset")
    sens = None if c is None else c.details.get("sensitivity")
    if sens is None:
        return []
    per_deg = sens["s_per_deg_of_sun_elevation"]
    notes = [f"The clock offset is read from {sens['read_from']}; the sun's elevation changes "
             f"{sens['sun_elevation_rate_deg_per_h']:+.2f} deg/h here, so "
             + (f"each degree of misfit between the sky model and the sky in the sun's "
                f"apparent elevation moves the fitted clock by {per_deg / 60:.1f} min."
                if per_deg is not None else "the data cannot pin the clock.")]
    shift = sens.get("sun_elevation_shift_deg")
    if shift is not None and np.isfinite(shift) and not sens.get("absolute_yaw", False):
        notes.append(f"The fitted clock offset moves the sun's elevation by {shift:+.2f} deg: "
                     "a clock error, or a sky whose sun appears that much "
                     f"{'higher' if shift >= 0 else 'lower'} than the ephemeris's, which "
                     "these data cannot tell apart.")
    return notes


def pointing_from_reports(reports, n_units: int | None = None):
    """Unit pointing [deg] calibrated on earlier diagnoses of the same instrument
    (:func:`calibration.photodiode_diagnosis.calibrated_pointing`) from reports of either
    schema: :class:`.report.DiagnosisReport` objects, their dicts, or ``diagnosis.json``
    paths (a path that is not a readable report is handed on as it is, so that the error
    names it).

    Raises
    ------
    PointingCalibrationError
        As :func:`calibration.photodiode_diagnosis.calibrated_pointing`.
    """
    import json
    from pathlib import Path

    from ..photodiode_diagnosis import calibrated_pointing
    from .report import DIAGNOSIS_SCHEMA, PREVIOUS_SCHEMA

    def base_fit_of(item):
        if isinstance(item, DiagnosisReport):
            return {"base_fit": item.extra.get("base_fit")}
        doc = item
        if isinstance(item, (str, Path)):
            try:
                doc = json.loads(Path(item).read_text())
            except (OSError, ValueError):
                return item
        if isinstance(doc, dict) and doc.get("schema") in (DIAGNOSIS_SCHEMA, PREVIOUS_SCHEMA) \
                and "unit" in doc:
            return {"base_fit": (doc.get("extra") or {}).get("base_fit")}
        return doc

    items = [reports] if isinstance(reports, (str, Path, dict, DiagnosisReport)) else reports
    return calibrated_pointing([base_fit_of(r) for r in items], n_units=n_units)


def diagnose_rings(data, effects=None, *, folds: int = 3, seed: int = 0,
                   where: str = "photodiode data", pointing=None,
                   pointing_from=None, light: str = "sun",
                   time_uncertainty_s: float | None = None) -> DiagnosisReport:
    """Diagnose a photodiode instrument.

    Parameters
    ----------
    data : PhotodiodeData or Instrument
        A ``skysim.photodiodes/1`` file's data, or the ring diagnosis's instrument.
    effects : sequence of str, optional
        Candidates (default :data:`calibration.photodiode_diagnosis.RING_EFFECT_NAMES`).
    folds, seed : int
    where : str
        Name of the data in messages and in ``data.path``.
    pointing : ndarray (2 U,), optional
        Unit elevation then azimuth offsets [deg] to hold (calibrated on other sessions).
    pointing_from : sequence, optional
        Reports (objects, dicts or paths) of other sessions of this instrument to calibrate
        ``pointing`` from (:func:`pointing_from_reports`).
    light : {"sun", "moon"}
        The body that lights the session's sky: ``"moon"`` for a session under the moonlit
        night sky (the Moon takes the Sun's place in every model).
    time_uncertainty_s : float, optional
        Standard uncertainty [s] of the recorded times (>= 0; default: the sidecar's
        ``time_uncertainty_s``, else 0 for a logged clock): times reconstructed after the
        fact (a start from a photograph and a nominal cadence) are uncertain by that much,
        and the clock candidate's uncertainty includes it
        (:attr:`calibration.photodiode_diagnosis.instrument.Instrument.time_uncertainty_s`).

    Returns
    -------
    DiagnosisReport
        Gaps as fractions of each unit's mean reading; heading error [deg] in
        ``extra["heading_error"]``.

    Raises
    ------
    SunTooLowError, InstrumentDataError, InsufficientDataError, UnknownEffectError
        As :func:`calibration.photodiode_diagnosis.diagnose_instrument`.
    """
    from dataclasses import replace

    from ..photodiode_diagnosis import diagnose_instrument, instrument_from_photodiodes
    from ..photodiode_diagnosis.errors import InstrumentDataError
    from ..photodiode_diagnosis.instrument import Instrument
    from ..photodiode_diagnosis.run import LIGHTS
    if light not in LIGHTS:
        raise InstrumentDataError(f"{where}: light must be one of {', '.join(LIGHTS)}; "
                                  f"got {light!r}")
    inst = data if isinstance(data, Instrument) else instrument_from_photodiodes(data, where)
    tu = float(inst.time_uncertainty_s if time_uncertainty_s is None else time_uncertainty_s)
    if not (np.isfinite(tu) and tu >= 0.0):
        raise InstrumentDataError(f"{where}: time_uncertainty_s must be a finite number of "
                                  f"seconds >= 0; got {time_uncertainty_s!r}")
    inst = replace(inst, light=light, time_uncertainty_s=tu)
    if pointing_from is not None:
        pointing = pointing_from_reports(pointing_from, n_units=inst.n_units)
    report = diagnose_instrument(inst, ring_candidates(effects), n_folds=folds, seed=seed,
                                 pointing=pointing)
    report.data.setdefault("path", where)
    report.notes += clock_notes(report)
    return report


class RingAdapter:
    """Multi-unit photodiode instruments as an instrument of
    :func:`calibration.diagnosis.diagnose` (:class:`.protocol.InstrumentAdapter`):
    "skysim.photodiodes" data (either version) that are not the one-unit three-pair sensor."""

    name = "photodiodes"

    def accepts(self, data, sidecar: dict | None = None) -> bool:
        from sensor.photodiodes_io import PHOTODIODES_SCHEMAS, PhotodiodeData

        from ..photodiode_diagnosis import is_three_pair_sensor
        from ..photodiode_diagnosis.instrument import Instrument
        if isinstance(data, Instrument):
            return True
        side = data.sidecar if isinstance(data, PhotodiodeData) else (sidecar or {})
        return side.get("schema") in PHOTODIODES_SCHEMAS and not is_three_pair_sensor(side)

    def load(self, path):
        from sensor.photodiodes_io import read_photodiodes
        return read_photodiodes(path)

    def candidates(self, names=None) -> tuple:
        return ring_candidates(names)

    def diagnose(self, data, candidates, *, folds: int = 3, seed: int = 0,
                 where: str = "photodiode data", pointing=None,
                 pointing_from=None, light: str = "sun",
                 time_uncertainty_s: float | None = None) -> DiagnosisReport:
        return diagnose_rings(data, candidates, folds=folds, seed=seed, where=where,
                              pointing=pointing, pointing_from=pointing_from, light=light,
                              time_uncertainty_s=time_uncertainty_s)
