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
   :data:`.run.CLOCK_START_MARGIN_DEG` over the whole session, the nominal instrument (unit
   gains, no offsets, a typical DoP scale) is oriented (:func:`.run.orient`: polarizer sense
   and offset, per-sweep headings from a 30-deg grid, then fitted) and scored by its sum of
   squared relative residuals. The best half hour of each of the three best branches
   (offsets an hour or more apart) is refined on a 5-min grid within a quarter hour, and the
   refined branches within :data:`.run.CLOCK_TIE` of the best go to the smallest offset: a
   sky symmetric about the solar meridian reads the same at the mirror time about noon
   (relative yaw absorbs the sun's azimuth), and a clock a few hours off is likelier than
   one many hours off.
2. **The diagnosis at the corrected times** (:func:`.run.diagnose_instrument`, every
   candidate, the clock's own fine fit and refinement among them).
3. **The report**: the clock candidate's offset is the coarse offset plus its fine fit; the
   verdict is ``clock_offset`` — the data cannot be compared with the model at the recorded
   times at all — with the verdict at the corrected times kept beside it. When the units read
   no usable sky (the fault screen, which does not depend on the times, leaves fewer than two
   units; or the diagnosis at the corrected times finds none), the twilight error stands.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from skysim.geometry import elevation_azimuth
from skysim.validation import TWILIGHT_LIMIT_DEG

from .effects import ClockOffset
from .errors import SunTooLowError
from .faults import screen
from .fit import fit_headings
from .forward import Forward, SunTrack
from .instrument import Instrument

__all__ = ["BRANCH_S", "N_BRANCHES", "REFINE_STEP_S", "coarse_clock_search",
           "diagnose_dark_clock"]

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
    from .run import NOMINAL_DOP_SCALE, orient
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
    :data:`.run.CLOCK_TIE` of the best go to the smallest offset (a sky symmetric about the
    solar meridian reads the same at the mirror time).

    Raises
    ------
    SunTooLowError
        When no offset within +-14 h keeps the sun above the twilight limit (a polar night).
    """
    from .run import CLOCK_START_MARGIN_DEG, CLOCK_TIE, _thin
    thin = _thin(inst)
    lowest = TWILIGHT_LIMIT_DEG + CLOCK_START_MARGIN_DEG

    def limit(dt):      # the recorded times need only hold for the model
        return TWILIGHT_LIMIT_DEG if dt == 0.0 else lowest
    scored = [(float(dt), c) for dt in ClockOffset.COARSE_S
              if (c := _offset_score(thin, sun, float(dt), limit(dt))) is not None]
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
            c = _offset_score(thin, sun, dt, limit(dt))
            if c is not None:
                scored.append((dt, c))
                if c < best[1]:
                    best = (dt, c)
        refined.append(best)
    top = min(c for _, c in refined)
    close = [(dt, c) for dt, c in refined if c <= top * (1.0 + CLOCK_TIE)]
    return min(close, key=lambda x: abs(x[0]))[0], scored


def diagnose_dark_clock(inst: Instrument, effects, too_low: SunTooLowError | None, *,
                        n_folds: int, seed: int, max_iter: int) -> dict | None:
    """The diagnosis of a session whose recorded times are too dark (module doc), or, with
    ``too_low`` None, of a session in deep twilight (the sun within
    :data:`.run.CLOCK_START_MARGIN_DEG` of the twilight limit at a recorded time): there the
    recorded times compete in the coarse search, and None is returned when they win (the
    caller diagnoses the session as it is).

    Raises
    ------
    SunTooLowError
        ``too_low`` again when the units read no usable sky at the corrected times either.
    """
    from .run import diagnose_instrument
    if screen(inst).unit_ok.sum() < 2:      # dark or dead at any clock: nothing to search
        if too_low is None:
            return None
        raise too_low
    sun = SunTrack(inst.site, inst.t_s.min(), inst.t_s.max(), margin_s=15 * 3600.0)
    dt, scored = coarse_clock_search(inst, sun)
    if dt == 0.0:
        return None
    doc = diagnose_instrument(replace(inst, t_s=inst.t_s + dt), effects, n_folds=n_folds,
                              seed=seed, max_iter=max_iter, pointing=None)
    at_corrected = doc["verdict"]
    if at_corrected.get("gap_before") is None:      # no usable sky: a dark session
        if too_low is None:
            return None
        raise too_low
    clock = next((c for c in doc["candidates"] if c["effect"] == "clock_offset"), None)
    fine = 0.0
    if clock is not None and "clock_offset_s" in clock.get("params", {}):
        fine = float(clock["params"]["clock_offset_s"]["value"])
        clock["params"]["clock_offset_s"]["value"] = dt + fine
        clock["coarse_offset_s"] = dt
    if at_corrected.get("effect") == "clock_offset":
        at_corrected = dict(at_corrected, params={})
    param = dict((clock or {}).get("params", {}).get("clock_offset_s", {}),
                 value=dt + fine, unit="s")
    sun_el, _ = elevation_azimuth(sun(inst.t_s))
    doc["verdict"] = {
        "effect": "clock_offset",
        "reason": (f"at the recorded times the sun is as low as {float(sun_el.min()):.1f} deg, "
                   + (f"below the twilight limit {TWILIGHT_LIMIT_DEG:g} deg, yet the units "
                      "read a lit, polarized sky" if too_low is not None else
                      "in deep twilight, and the units read the sky of another time far "
                      "better")
                   + f"; the clock search puts the true time {(dt + fine) / 3600.0:+.2f} h "
                   "from the recorded one"),
        "gap_before": None, "gap_after": at_corrected.get("gap_before"), "shrink": None,
        "metric": at_corrected.get("metric"), "noise_floor": at_corrected.get("noise_floor"),
        "best_candidate": "clock_offset", "params": {"clock_offset_s": param},
        "at_corrected_times": at_corrected}
    doc["dark_clock"] = {"recorded_sun_elevation_min_deg": float(sun_el.min()),
                         "coarse_offset_s": dt, "fine_offset_s": fine,
                         "coarse_scores": [{"offset_s": o, "score": s} for o, s in scored],
                         "method": "coarse clock search on the nominal instrument, then the "
                                   "diagnosis at the corrected times"}
    return doc
