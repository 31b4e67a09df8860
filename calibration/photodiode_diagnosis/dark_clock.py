"""A session whose recorded times put the sun below the twilight limit, yet whose units read a
lit, polarized sky: the clock is searched before anything else.

A logger whose clock is hours off (a timezone or daylight-saving slip) can stamp an evening
session with a time after dusk. The base model cannot be evaluated there (no single-scattering
sky below the twilight limit, :data:`skysim.validation.TWILIGHT_LIMIT_DEG`), so the usual
order — base fit, then candidates, the clock among them — never starts. Here the clock comes
first:

1. **Coarse search.** At every whole and half hour within +-14 h
   (:data:`.effects.ClockOffset.COARSE_S`) that keeps the sun above the limit by
   :data:`.run.CLOCK_START_MARGIN_DEG` over the whole session, the nominal instrument (unit
   gains, no offsets, a typical DoP scale) is oriented (:func:`.run.orient`: polarizer sense
   and offset, per-sweep headings from a 30-deg grid, then fitted) and scored by its sum of
   squared relative residuals. Offsets whose scores lie within :data:`.run.CLOCK_TIE` of the
   best go to the smallest, and then to the best score within :data:`BRANCH_S` of it: a sky
   symmetric about the solar meridian reads the same at the mirror time
   about noon (relative yaw absorbs the sun's azimuth), and a clock a few hours off is likelier
   than one many hours off.
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

__all__ = ["BRANCH_S", "coarse_clock_search", "diagnose_dark_clock"]

BRANCH_S = 3600.0
"""Coarse offsets within this many seconds of each other belong to one branch of the clock
search (its mirror about noon is hours away)."""


def coarse_clock_search(inst: Instrument, sun: SunTrack) -> tuple[float, list]:
    """Best whole or half-hour clock offset [s] (true minus recorded time) for a session
    whose recorded times are too dark, and the scored offsets ``[(offset_s, score)]``.

    Raises
    ------
    SunTooLowError
        When no offset within +-14 h keeps the sun above the twilight limit (a polar night).
    """
    from .run import CLOCK_START_MARGIN_DEG, CLOCK_TIE, NOMINAL_DOP_SCALE, _thin, orient
    thin = _thin(inst)
    lowest = TWILIGHT_LIMIT_DEG + CLOCK_START_MARGIN_DEG
    scored = []
    for dt in ClockOffset.COARSE_S:
        el, _ = elevation_azimuth(sun(thin.t_s + dt))
        if el.min() <= lowest:
            continue
        fwd = Forward(replace(thin, t_s=thin.t_s + dt), sun=sun)
        theta = np.zeros(fwd.layout.size)
        theta[fwd.layout.scale] = NOMINAL_DOP_SCALE
        _, theta = orient(fwd, theta)
        # headings refined from orient's 30-deg grid, which alone leaves residuals of a
        # heading up to 15 deg off that swamp the clock's (the score then follows how well
        # the grid happens to match the sun's azimuth at each offset)
        scored.append((float(dt), float(fit_headings(fwd, theta, coarse=False).cost)))
    if not scored:
        raise SunTooLowError(f"{inst.source.get('path', 'photodiode data')}: no clock offset "
                             "within +-14 h puts the sun above the twilight limit")
    best = min(s for _, s in scored)
    close = [dt for dt, s in scored if s <= best * (1.0 + CLOCK_TIE)]
    # ties between branches (the mirror time hours away) go to the smaller offset; within
    # a branch the best score wins (neighbouring half hours tie at a low sun, where the
    # nominal instrument's cost changes by 0.1 % per half hour)
    near = min(close, key=abs)
    branch = [(dt, s) for dt, s in scored if abs(dt - near) <= BRANCH_S]
    return min(branch, key=lambda x: x[1])[0], scored


def diagnose_dark_clock(inst: Instrument, effects, too_low: SunTooLowError, *, n_folds: int,
                        seed: int, max_iter: int) -> dict:
    """The diagnosis of a session whose recorded times are too dark (module doc).

    Raises
    ------
    SunTooLowError
        ``too_low`` again when the units read no usable sky at the corrected times either.
    """
    from .run import diagnose_instrument
    if screen(inst).unit_ok.sum() < 2:      # dark or dead at any clock: nothing to search
        raise too_low
    sun = SunTrack(inst.site, inst.t_s.min(), inst.t_s.max(), margin_s=15 * 3600.0)
    dt, scored = coarse_clock_search(inst, sun)
    doc = diagnose_instrument(replace(inst, t_s=inst.t_s + dt), effects, n_folds=n_folds,
                              seed=seed, max_iter=max_iter, pointing=None)
    at_corrected = doc["verdict"]
    if at_corrected.get("gap_before") is None:      # no usable sky: a dark session
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
                   f"below the twilight limit {TWILIGHT_LIMIT_DEG:g} deg, yet the units read a "
                   f"lit, polarized sky; the clock search puts the true time "
                   f"{(dt + fine) / 3600.0:+.2f} h from the recorded one"),
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
