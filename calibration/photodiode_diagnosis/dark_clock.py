"""A session whose recorded times put the sun below the twilight limit, yet whose units read a
lit, polarized sky: the clock is searched before anything else.

A logger whose clock is hours off (a timezone or daylight-saving slip) can stamp an evening
session with a time after dusk, or in deep twilight. The base model cannot be evaluated
after dusk (no single-scattering sky below the twilight limit,
:data:`skysim.validation.TWILIGHT_LIMIT_DEG`), and in deep twilight a clock fit from the
recorded times walks below the limit, so the usual
order — base fit, then candidates, the clock among them — never starts. Here the clock comes
first (for a session in deep twilight, with the sun within a few degrees of the limit, the
recorded times compete in step 1 and, when they win, the session is diagnosed as it is):

1. **Coarse search.** At every whole and half hour within +-14 h
   (:data:`.effects.ClockOffset.COARSE_S`) that keeps the sun above the limit by
   :data:`CLOCK_START_MARGIN_DEG` over the whole session, the nominal instrument (unit
   gains, no offsets, a typical DoP scale) is oriented (:func:`.fit.orient`: polarizer sense
   and offset, per-sweep headings from a 30-deg grid, then fitted) and scored by its sum of
   squared relative residuals. The best half hour of each of the three best branches
   (offsets an hour or more apart) is refined on a 5-min grid within a quarter hour, and the
   refined branches within :data:`CLOCK_TIE` of the best go to the smallest offset: a
   sky symmetric about the solar meridian reads the same at the mirror time about noon
   (relative yaw absorbs the sun's azimuth), and a clock a few hours off is likelier than
   one many hours off.
2. **The diagnosis at the corrected times**, once (:func:`.run.diagnose_instrument` shifts
   the times by the offset found here and diagnoses the session with every candidate, the
   clock's own fine fit and refinement among them).
3. **The report** (:func:`clock_found`): the clock candidate's offset is the coarse offset
   plus its fine fit; the verdict is ``clock_offset`` — the data cannot be compared with the
   model at the recorded times at all — with the verdict at the corrected times kept beside
   it. When the units read no usable sky (the fault screen, which does not depend on the
   times, leaves fewer than two units; or the diagnosis at the corrected times finds none),
   the twilight error stands.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from skysim.geometry import elevation_azimuth
from skysim.validation import TWILIGHT_LIMIT_DEG

from ..diagnosis.report import DiagnosisReport, Verdict
from .effects import ClockOffset
from .errors import SunTooLowError
from .faults import screen
from .fit import fit_headings, orient, thin
from .forward import Forward, SunTrack
from .instrument import Instrument

__all__ = ["BRANCH_S", "CLOCK_START_MARGIN_DEG", "CLOCK_TIE", "ClockSearch", "N_BRANCHES",
           "NOMINAL_DOP_SCALE", "REFINE_STEP_S", "clock_found", "coarse_clock_search",
           "search_clock"]

CLOCK_TIE = 0.005
"""Clock-offset fits whose costs differ by less than this fraction are ties, resolved towards
the smaller offset: with every sample stamped at one time, the per-sweep headings absorb the
sun's azimuth, and a sky symmetric about the solar meridian looks the same with the sun at
the same elevation before and after noon (the mirror time), so the data cannot tell them
apart; a clock that is minutes off is likelier than one many hours off."""

NOMINAL_DOP_SCALE = 0.6
"""DoP scale of the nominal instrument that scores coarse clock starts (a clear sky's maximum
DoP is 0.6-0.8 in the visible; the refinement fits the scale)."""

CLOCK_START_MARGIN_DEG = 3.0
"""A coarse clock start keeps the sun this far [deg] above the lowest elevation the sky model
holds for at the session's mean time: a session spans 12-13 minutes, over which the sun's
elevation changes by up to 2.5 deg."""


BRANCH_S = 3600.0
"""Coarse offsets within this many seconds of each other belong to one branch of the clock
search (its mirror about noon is hours away)."""
N_BRANCHES = 3
"""Branches of the coarse search refined (:func:`coarse_clock_search`)."""
REFINE_STEP_S = 300.0
"""Step [s] of the refinement around a branch's best half hour (the sun moves up to ~1 deg in
5 min at dusk; the diagnosis at the corrected times fits the rest)."""


def _offset_score(thin: Instrument, sun: SunTrack, dt: float, lowest: float) -> float | None:
    """Cost of the nominal instrument with its headings fitted at clock offset ``dt`` [s], or
    None where the sun is not above ``lowest`` [deg] at every sample."""
    el, _ = elevation_azimuth(sun(thin.t_s + dt))
    if el.min() <= lowest:
        return None
    fwd = Forward(replace(thin, t_s=thin.t_s + dt), sun=sun)
    theta = np.zeros(fwd.layout.size)
    theta[fwd.layout.scale] = NOMINAL_DOP_SCALE
    _, theta = orient(fwd, theta)
    # headings refined from orient's 30-deg grid, which alone leaves residuals of a heading up
    # to 15 deg off that swamp the clock's (the score then follows how well the grid happens
    # to match the sun's azimuth at each offset)
    return float(fit_headings(fwd, theta, coarse=False).cost)


def coarse_clock_search(inst: Instrument, sun: SunTrack) -> tuple[float, list]:
    """Best clock offset [s] (true minus recorded time) for a session whose recorded times are
    too dark or in deep twilight, and the scored offsets ``[(offset_s, score)]``.

    Whole and half hours are scored first; the best offset of each of the
    :data:`N_BRANCHES` best branches (offsets more than :data:`BRANCH_S` apart) is then
    refined on a :data:`REFINE_STEP_S` grid within a quarter hour, because at dusk the sun
    moves ~5 deg in half an hour and the half hour nearest the truth can score worse than one
    on the mirror branch that happens to meet the sun's elevation. Refined branches within
    :data:`CLOCK_TIE` of the best go to the smallest offset (a sky symmetric about the
    solar meridian reads the same at the mirror time).

    Raises
    ------
    SunTooLowError
        When no offset within +-14 h keeps the sun above the twilight limit (a polar night).
    """
    thinned = thin(inst)
    lowest = TWILIGHT_LIMIT_DEG + CLOCK_START_MARGIN_DEG

    def limit(dt):      # the recorded times need only hold for the model
        return TWILIGHT_LIMIT_DEG if dt == 0.0 else lowest
    scored = [(float(dt), c) for dt in ClockOffset.COARSE_S
              if (c := _offset_score(thinned, sun, float(dt), limit(dt))) is not None]
    if not scored:
        raise SunTooLowError(f"{inst.source.get('path', 'photodiode data')}: no clock offset "
                             "within +-14 h puts the sun above the twilight limit")
    branches = []
    for dt, c in sorted(scored, key=lambda x: x[1]):
        if all(abs(dt - b) > BRANCH_S for b, _ in branches):
            branches.append((dt, c))
        if len(branches) == N_BRANCHES:
            break
    refined = []
    for dt0, c0 in branches:
        best = (dt0, c0)
        for k in range(-3, 4):
            dt = dt0 + k * REFINE_STEP_S
            if k == 0 or (dt == 0.0 and dt0 != 0.0):
                continue
            c = _offset_score(thinned, sun, dt, limit(dt))
            if c is not None:
                scored.append((dt, c))
                if c < best[1]:
                    best = (dt, c)
        refined.append(best)
    top = min(c for _, c in refined)
    close = [(dt, c) for dt, c in refined if c <= top * (1.0 + CLOCK_TIE)]
    return min(close, key=lambda x: abs(x[0]))[0], scored


@dataclass(frozen=True)
class ClockSearch:
    """A clock offset found before the diagnosis (:func:`search_clock`).

    Attributes
    ----------
    offset_s : float
        True minus recorded time [s].
    scored : list of (float, float)
        Every offset tried [s] and its score.
    too_low : SunTooLowError or None
        The error of the recorded times (None in deep twilight, where they were scored too).
    """

    offset_s: float
    scored: list
    too_low: SunTooLowError | None


def search_clock(inst: Instrument, too_low: SunTooLowError | None) -> ClockSearch | None:
    """The clock offset of a session whose recorded times are too dark (``too_low`` its
    error), or, with ``too_low`` None, of a session in deep twilight (the sun within
    :data:`CLOCK_START_MARGIN_DEG` of the twilight limit at a recorded time), where the
    recorded times compete: None when they win, or when no unit reads a usable sky.

    Raises
    ------
    SunTooLowError
        ``too_low`` again when no unit reads a usable sky at any clock.
    """
    if screen(inst).unit_ok.sum() < 2:      # dark or dead at any clock: nothing to search
        if too_low is None:
            return None
        raise too_low
    sun = SunTrack(inst.site, inst.t_s.min(), inst.t_s.max(), margin_s=15 * 3600.0)
    dt, scored = coarse_clock_search(inst, sun)
    return None if dt == 0.0 else ClockSearch(dt, scored, too_low)


def clock_found(report: DiagnosisReport, search: ClockSearch,
                sun_elevation_deg) -> DiagnosisReport:
    """The report of the diagnosis at the corrected times (module doc, step 3), its clock
    candidate's offset counted from the recorded times; ``sun_elevation_deg`` the sun's
    elevations [deg] at the recorded times."""
    dt = search.offset_s
    at_corrected = asdict(report.verdict)
    if at_corrected["effect"] == "clock_offset":
        at_corrected["params"] = {}
    clock = report.candidate("clock_offset")
    fine = 0.0
    if clock is not None and "clock_offset_s" in clock.params:
        fine = float(clock.params["clock_offset_s"]["value"])
        clock.params["clock_offset_s"]["value"] = dt + fine
        clock.details["coarse_offset_s"] = dt
    param = dict((clock.params if clock is not None else {}).get("clock_offset_s", {}),
                 value=dt + fine, unit="s")
    low = float(np.min(sun_elevation_deg))
    report.verdict = Verdict(
        "clock_offset",
        f"at the recorded times the sun is as low as {low:.1f} deg, "
        + (f"below the twilight limit {TWILIGHT_LIMIT_DEG:g} deg, yet the units read a lit, "
           "polarized sky" if search.too_low is not None else
           "in deep twilight, and the units read the sky of another time far better")
        + f"; the clock search puts the true time {(dt + fine) / 3600.0:+.2f} h from the "
        "recorded one",
        best_candidate="clock_offset", gap_after=at_corrected["gap_before"],
        params={"clock_offset_s": param})
    report.extra["dark_clock"] = {
        "recorded_sun_elevation_min_deg": low, "coarse_offset_s": dt, "fine_offset_s": fine,
        "coarse_scores": [{"offset_s": o, "score": s} for o, s in search.scored],
        "method": "coarse clock search on the nominal instrument, then the diagnosis at the "
                  "corrected times",
        "at_corrected_times": at_corrected}
    return report
