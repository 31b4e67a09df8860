"""The pointing of a photodiode instrument's units, calibrated on other sessions.

A hand-built ring's units sit a few degrees off their nominal elevation and azimuth, and one
session cannot tell a common shift of the unit elevations from a shift of the sun's: raising
every unit by ``d`` changes the angle of polarization the units see almost as lowering the
sun by ``d`` does (on a real ring, a clock 1 h off and a common elevation offset of about
8 deg fitted the same session equally well). The per-sweep headings take up the sun's
azimuth, so nothing else pins the sun. The mounting does not change between sessions of one
instrument: fitted on sessions whose clocks are right, it pins the sun in the others, and a
clock error becomes measurable (profiled on the reference ring's 09:08 session with its
clock set 2 h wrong: the fitted clock moved 1 h per 8 deg of common elevation offset, and the
day's other sessions put that offset at -3 to -5.5 deg).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .errors import PointingCalibrationError

__all__ = ["calibrated_pointing"]


def _report(item, i: int) -> tuple[dict, str]:
    if isinstance(item, dict):
        return item, f"report {i}"
    path = Path(item)
    try:
        return json.loads(path.read_text()), str(path)
    except (OSError, json.JSONDecodeError) as exc:
        raise PointingCalibrationError(f"{path}: cannot read a diagnosis report ({exc})") from exc


def calibrated_pointing(reports, n_units: int | None = None) -> np.ndarray:
    """Unit pointing offsets [deg] from earlier diagnoses of the same instrument.

    Parameters
    ----------
    reports : sequence of dict or path
        Diagnosis reports (``diagnosis.json`` written by ``skysim diagnose`` or the dicts
        :func:`calibration.photodiode_diagnosis.diagnose_photodiodes` returns) of sessions of
        this instrument whose times are right.
    n_units : int, optional
        Units of the instrument to be diagnosed; checked against the reports.

    Returns
    -------
    ndarray (2 U,)
        Elevation offsets of units 0..U-1, then azimuth offsets [deg]: per unit, the median
        over the reports that fitted it; NaN for a unit the screen excluded in every report
        (its pointing is then fitted).

    Raises
    ------
    PointingCalibrationError
        No report given, a file that is not JSON, a report without the base fit's pointing
        (not a photodiode-instrument diagnosis, or one its screen stopped), or reports of
        instruments with different units.
    """
    reports = list(reports) if not isinstance(reports, (str, Path, dict)) else [reports]
    if not reports:
        raise PointingCalibrationError("no diagnosis report given to calibrate the pointing")
    el, az = [], []
    for i, item in enumerate(reports):
        doc, name = _report(item, i)
        base = doc.get("base_fit") if isinstance(doc, dict) else None
        if not isinstance(base, dict) or not isinstance(base.get("elevation_offset_deg"), dict) \
                or not isinstance(base.get("azimuth_offset_deg"), dict):
            raise PointingCalibrationError(
                f"{name}: no fitted unit pointing (base_fit.elevation_offset_deg and "
                "azimuth_offset_deg): give diagnosis reports of this photodiode instrument")
        if base.get("pointing_held"):
            raise PointingCalibrationError(
                f"{name}: its pointing was itself held at a calibration, not fitted: give "
                "the reports the calibration came from")
        keys = sorted(base["elevation_offset_deg"], key=lambda k: int(str(k).lstrip("u")))
        row_el = [base["elevation_offset_deg"][k] for k in keys]
        row_az = [base["azimuth_offset_deg"].get(k) for k in keys]
        if el and len(row_el) != len(el[0]):
            raise PointingCalibrationError(
                f"{name}: {len(row_el)} units, the first report has {len(el[0])}: give "
                "reports of one instrument")
        el.append([np.nan if v is None else float(v) for v in row_el])
        az.append([np.nan if v is None else float(v) for v in row_az])
    U = len(el[0])
    if n_units is not None and n_units != U:
        raise PointingCalibrationError(
            f"the reports describe {U} units, the instrument to be diagnosed has {n_units}")
    E, A = np.array(el), np.array(az)
    seen = np.isfinite(E).any(axis=0)
    out = np.full(2 * U, np.nan)
    out[:U][seen] = np.nanmedian(E[:, seen], axis=0)
    out[U:][seen] = np.nanmedian(A[:, seen], axis=0)
    return out
