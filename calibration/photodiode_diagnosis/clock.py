"""The clock candidate's own pieces: its starts hours apart, what pins a clock offset in a
session (the sun's elevation and azimuth rates), how far the clock moves under each sky model
(:func:`clock_report`), the mirror time about the sun's culmination (:func:`clock_mirror`),
and the refinement of a clock hours off (:func:`refine_clock_offset`), an outer step that
shifts the times and fits the clock again there through a pass the caller supplies
(:mod:`.run`'s pipeline: screen, base fit, the clock's fold fits), never diagnosing the
session twice.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from skysim.exceptions import InvalidParameterError
from skysim.geometry import elevation_azimuth, wrap_deg
from skysim.sky import RayleighSky

from ..diagnosis.errors import DiagnosisError
from .dark_clock import CLOCK_START_MARGIN_DEG, CLOCK_TIE, NOMINAL_DOP_SCALE
from .effect_fit import EFFECT_MAX_ITER, _extend, _has_sky, _joint_aop, _nominal_instrument
from .fit import fit, fit_pinned
from .fit import thin as _thin
from .forward import Forward, SunTrack
from .instrument import Instrument

__all__ = ["CLOCK_NEAR_S", "CLOCK_PASSES", "CLOCK_REFINE_S", "REFINED_RULE", "clock_mirror",
           "clock_report", "clock_sensitivity", "far_clock", "refine_clock_offset",
           "refined_uncertainty", "solar_noon_s"]


CLOCK_NEAR_S = 1800.0
"""Offsets [s] nearer the recorded times than this (the nearest coarse start, half an hour)
are read under each sky model from the recorded times (:func:`clock_report`); farther ones
from the fitted offset, with the pointing re-read there."""


CLOCK_REFINE_S = 900.0
"""A clock offset larger than this [s] is refined (:func:`refine_clock_offset`)."""


CLOCK_PASSES = 3
"""Most refinement passes of a clock offset; they stop once a pass moves it by less than a
third of :data:`CLOCK_REFINE_S`."""


def far_clock(effect, p) -> bool:
    """True for a clock offset ``p`` (the clock candidate's parameters) farther than
    :data:`CLOCK_REFINE_S` from the recorded times: every fit of it (from a start, after a
    start near the recorded times walked there, and its continuation) reads the angle of
    polarization under single scattering, not under the fold's best sky candidate.

    The sky candidates are fitted about the recorded sun, so under a clock hours off their
    skies (a neutral-point separation, an optical thickness) take up part of the clock's
    misfit, and a clock read under them is held back towards the recorded times. On a
    simulated three-sweep ring whose clock is 2 h off (7,200 s), the start at the recorded
    times, read under each fold's neutral-point sky, walked to 5,940-6,006 s in the joint fit
    with the pointing (angle-of-polarization cost 96-165) and won every fold; read again under
    single scattering from there it reached 7,197-7,199 s at a lower cost (65-68). On a real
    morning session recorded 2 h early, a fit under the best such sky stopped at
    +58 +- 43 min. Whether a sky candidate explains the session is judged at the corrected
    times (:func:`refine_clock_offset`, :func:`clock_report`).
    """
    return effect.name == "clock_offset" and abs(float(np.asarray(p, float)[0])) > \
        CLOCK_REFINE_S


def _sun_el_az(sun: SunTrack, t_s: float):
    el, az = elevation_azimuth(sun(np.array([t_s])))
    return float(el[0]), float(az[0])


def clock_sensitivity(sun: SunTrack, t_s: float, absolute_yaw: bool,
                      offset_s: float | None = None, half_step_s: float = 300.0) -> dict:
    """What pins a clock offset in a session: the sun's elevation and azimuth rates at ``t_s``.

    A clock offset moves the sun along its daily path. With relative yaw the per-sweep heading
    offsets absorb the sun's azimuth, so the clock is read from the sun's elevation alone and
    ``s_per_deg_of_sun_elevation`` (= 3600 / |elevation rate|) is how far a misfit of one
    degree between the sky model and the real sky in the sun's apparent elevation moves the
    fitted clock; near the sun's culmination that runs to hours. Given a fitted
    ``offset_s``, ``sun_elevation_shift_deg`` is the change of the sun's elevation that it
    makes: with relative yaw, a clock error and a sky whose sun appears that much higher
    (or lower) than the ephemeris's are the same to the data.

    Parameters
    ----------
    sun : SunTrack
    t_s : float
        Time [s since epoch, UTC].
    absolute_yaw : bool
    offset_s : float, optional
        A fitted clock offset [s] (true minus recorded time).
    half_step_s : float
        Half-width of the central difference [s] (the rates change by < 1 % over 10 min).

    Returns
    -------
    dict
        ``sun_elevation_rate_deg_per_h``, ``sun_azimuth_rate_deg_per_h``, ``read_from`` and
        ``s_per_deg_of_sun_elevation`` (None when the elevation rate is below 1e-6 deg/h),
        and ``sun_elevation_shift_deg`` with ``offset_s``.
    """
    e1, a1 = _sun_el_az(sun, t_s + half_step_s)
    e0, a0 = _sun_el_az(sun, t_s - half_step_s)
    k = 3600.0 / (2.0 * half_step_s)
    rate_el, rate_az = (e1 - e0) * k, float(wrap_deg(a1 - a0)) * k
    out = {"sun_elevation_rate_deg_per_h": rate_el, "sun_azimuth_rate_deg_per_h": rate_az,
           "absolute_yaw": bool(absolute_yaw),
           "read_from": ("the sun's elevation and azimuth" if absolute_yaw else
                         "the sun's elevation only (relative yaw: the per-sweep heading "
                         "offsets absorb its azimuth)"),
           "s_per_deg_of_sun_elevation": (3600.0 / abs(rate_el) if abs(rate_el) > 1e-6
                                          else None)}
    if offset_s is not None:
        out["sun_elevation_shift_deg"] = (_sun_el_az(sun, t_s + offset_s)[0]
                                          - _sun_el_az(sun, t_s)[0])
    return out


def solar_noon_s(sun: SunTrack, t_s: float) -> float:
    """Time [s since epoch, UTC] of the sun's culmination nearest ``t_s`` (highest elevation
    on a 60-s grid over +-12 h, refined by a parabola through the top three)."""
    t = t_s + np.arange(-12 * 3600.0, 12 * 3600.0 + 60.0, 60.0)
    el, _ = elevation_azimuth(sun(t))
    i = int(np.clip(np.argmax(el), 1, t.size - 2))
    a, b, c = el[i - 1], el[i], el[i + 1]
    den = a - 2 * b + c
    return float(t[i] + (0.5 * (a - c) / den * 60.0 if den != 0 else 0.0))


def _clock_starts(fwd: Forward, theta_base, fwd_base, effect) -> list:
    """Starts of the clock offset: no offset, and the two best of the whole and half hours
    (each with the per-sweep headings carried by the sun's azimuth change, on the nominal
    instrument it is scored on).

    A whole or half hour starts from the nominal instrument, not the base fit's: the base
    fit, made under a clock hours off, put its error into the gains, offsets, polarizer
    angles and pointing, and the fit from there reads the clock through them. On a
    simulated three-sweep ring recorded 2 h early, the start at the true 7,200 s with the
    base fit's instrument walked to 7,952-11,128 s (AoP cost 507-2,492) in the three folds;
    from the nominal instrument it stayed at 7,200 s (AoP cost 66-68, the noise's)."""
    L = fwd.layout
    sun = fwd.sun
    t0 = float(np.mean(fwd.inst.t_s))
    _, az0 = _sun_el_az(sun, t0)
    scored = []
    sky = fwd.aop_sky if fwd.aop_sky is not None else fwd._sky
    lowest = sky.min_sun_elevation_deg + CLOCK_START_MARGIN_DEG
    for dt in effect.COARSE_S:
        el, az = _sun_el_az(sun, t0 + dt)
        if el <= lowest or dt == 0.0:
            continue
        t = _extend(theta_base, fwd_base, fwd, [dt])
        t[L.heading] = theta_base[fwd_base.layout.heading] + (az - az0)
        # scored on the nominal instrument (unit gains, no offsets or angle deviations,
        # nominal pointing, a typical DoP scale): a clock hours off corrupts every parameter
        # the base fitted under it (on a simulated ring 2.5 h off, pointing at its -20 deg
        # bound and a DoP scale of 0.99), and the scores with them; the units' polarizer
        # offsets stay the base's, with which the starts found the hour of a ring recorded
        # 2 h early (tests/test_clock_nominal_start.py; the sky effects' nominal start,
        # run._nominal, resets those and keeps the pointing)
        nominal = _nominal_instrument(t, L, (L.lam, L.off, L.angle, L.pointing))
        nominal[L.scale] = NOMINAL_DOP_SCALE
        scored.append((float(np.sum(fwd.residual(nominal) ** 2)), nominal))
    scored.sort(key=lambda x: x[0])
    return [_extend(theta_base, fwd_base, fwd, [0.0])] + [t for _, t in scored[:2]]


def clock_report(inst, effect, theta_base, layout, sun, sign, sigma, param: dict, rows,
                 cand) -> dict:
    """What the clock candidate reports beside its fit: what pins it (``sensitivity``), how
    far it moves when the angle of polarization is read under each sky model fitted here
    (``by_sky``: single scattering and every sky candidate at its fold-mean parameters, on the
    whole session, each read from the recorded times with the base's pointing held, or from
    the fitted offset when that is :data:`CLOCK_NEAR_S` or more away; half their range is
    ``sky_model_spread_s``, a systematic the noise does not show), the resulting
    ``uncertainty_s`` (root sum of squares of the statistical uncertainty, that spread and
    the recorded times' own uncertainty,
    :attr:`Instrument.time_uncertainty_s`) and the mirror time about the sun's culmination
    (:func:`clock_mirror`). The parameter's ``uncertainty`` is updated to ``uncertainty_s``."""
    offset = param["value"]
    fe = Forward(_thin(inst), effect, sun=sun, polarizer_sign=sign)
    skies = {"single_scattering": None}
    for e in cand:
        row = next((r for r in rows if r["effect"] == e.name), None)
        if _has_sky(e) and row is not None and row.get("available", True):
            p = np.array([row["params"][n]["value"] for n in e.parameter_names])
            skies[e.name] = e.sky(p, RayleighSky(1.0), fe.sun(fe.inst.t_s))
    by_sky, errors = {}, {}
    # read as the candidate reads an offset within its nearest coarse start: from the
    # recorded times, with the pointing where the base's AoP fit put it. A start at the
    # fitted offset re-reads the pointing there first (as a clock hours off needs), and that
    # pointing, having taken up the offset, hides how far the sky alone moves the clock (on
    # a real session an hour past culmination the three skies' clocks spanned 7.5 min read
    # from the fitted -20 min, 25 min read from the recorded times)
    start = offset if abs(offset) >= CLOCK_NEAR_S else 0.0
    for name, sky in skies.items():
        fe.aop_sky = sky
        try:
            by_sky[name] = _aop_clock_fit(fe, theta_base, layout, start, sigma)
        except InvalidParameterError as exc:   # this sky does not hold at the fitted time
            by_sky[name], errors[name] = None, str(exc)
    fe.aop_sky = None
    values = np.array([v for v in by_sky.values() if v is not None] or [offset])
    spread = 0.5 * float(np.ptp(values))
    stat = float(param.get("uncertainty", param["fold_spread"]))
    times = float(inst.time_uncertainty_s)
    param["uncertainty"] = float(np.sqrt(stat ** 2 + spread ** 2 + times ** 2))
    out = {"sensitivity": clock_sensitivity(sun, float(np.mean(inst.t_s)), inst.absolute_yaw,
                                            offset_s=offset),
           "by_sky": {k: None if v is None else float(v) for k, v in by_sky.items()},
           "by_sky_errors": errors, "sky_model_spread_s": spread, "statistical_uncertainty_s": stat,
           "recorded_times_uncertainty_s": times,
           "uncertainty_s": param["uncertainty"],
           "significant": bool(abs(offset) > 2.0 * param["uncertainty"])}
    out["mirror"] = clock_mirror(inst, effect, theta_base, layout, sun, sign, sigma, offset)
    return out


def _aop_clock_fit(fe: Forward, theta_base, layout, start_s, sigma) -> float:
    """Clock offset [s] from the clock candidate's AoP fit (:func:`fit_pinned`: the
    instrument re-read from the AoP at ``start_s``, then the clock; then the clock and the
    pointing together, :func:`_joint_aop`) started at ``start_s``, on the sky
    ``fe.aop_sky``."""
    t = np.zeros(fe.layout.size)
    t[:layout.size] = theta_base[:layout.size]
    t[fe.layout.effect] = start_s
    _, aop = fit_pinned(fe, t, sigma=sigma, max_iter=EFFECT_MAX_ITER, full=False)
    if fe.effect.pointing == "joint":
        aop = _joint_aop(fe, aop, sigma)
    return float(aop.theta[fe.layout.effect][0])


def clock_mirror(inst: Instrument, effect, theta_base, layout, sun, sign, sigma,
                 offset_s: float) -> dict:
    """The clock offset that mirrors the fitted one about the sun's culmination, and how well
    it fits: with relative yaw the per-sweep headings absorb the sun's azimuth, and the sun
    stands at the same elevation at ``t`` and ``2 t_noon - t``, so near culmination both
    clocks fit the angle of polarization alike and the data cannot choose. Both are scored
    by an AoP fit (DoP profiled out) of the instrument and headings at that clock, on the
    session thinned as for fits.
    """
    t_mid = float(np.mean(inst.t_s))
    noon = solar_noon_s(sun, t_mid)
    mirror = 2.0 * (noon - t_mid) - offset_s
    fe = Forward(_thin(inst), effect, sun=sun, polarizer_sign=sign)
    costs = []
    for dt in (offset_s, mirror):
        t = np.zeros(fe.layout.size)
        t[:layout.size] = theta_base[:layout.size]
        t[fe.layout.effect] = dt
        free = np.ones(fe.layout.size, bool)     # the instrument re-read at each clock
        free[fe.layout.scale] = False
        free[fe.layout.effect] = False
        fe.dop_free = True
        try:
            costs.append(fit(fe, t, free, sigma=sigma, max_iter=EFFECT_MAX_ITER).cost)
        finally:
            fe.dop_free = False
    ratio = costs[1] / max(costs[0], 1e-300)
    return {"solar_noon_utc": str(np.datetime64(int(round(noon)), "s")) + "Z",
            "mirror_offset_s": float(mirror), "cost_ratio": float(ratio),
            "fits_as_well": bool(ratio <= 1.0 + CLOCK_TIE)}


REFINED_RULE = ("the last pass's uncertainty, with its step added in quadrature when that "
                "step is a third of the refinement threshold or more (not settled)")
"""How a refined clock's uncertainty is made (:func:`refined_uncertainty`), for the report."""


def refined_uncertainty(passes) -> float:
    """Uncertainty [s] of a refined clock offset (:func:`refine_clock_offset`).

    The refined offset is a fixed shift (the first fit and the steps before the last) plus
    the last pass's step, and that step is the whole remaining offset fitted afresh at the
    shifted times, so the estimate's error is the last pass's error: its uncertainty is the
    last pass's ``uncertainty_s``. The earlier passes' uncertainties describe fits at times
    still far off (a base fit under the wrong sun); adding them in quadrature counts the same
    data again. When the last step is still ``CLOCK_REFINE_S / 3`` or more (the
    :data:`CLOCK_PASSES` ran out, or the next pass failed), the offset has not settled and
    that step is added in quadrature: the next would be of its order.

    Measured on 13 simulated three-sweep rings with clocks 3,300-7,200 s off (either sign,
    the clock alone or beside the neutral-point sky; table in the tests of the
    refinement), z = (fitted - true) / uncertainty has an RMS of 1.27 under this rule and
    1.22 with every pass in quadrature; the two differ only where there is more than one
    pass, and on those three cases this rule's z RMS is 1.01 and the quadrature's 0.64
    (over-covering). Every last step there was settled (under 300 s), so the unsettled term
    rests on the argument above, not on a measurement.

    Parameters
    ----------
    passes : sequence of dict
        The refinement passes in order, each with ``offset_s``, the step [s] it fitted at
        the times the passes before it corrected, and ``uncertainty_s`` [s], that fit's.

    Returns
    -------
    float
        The refined offset's uncertainty [s].
    """
    last = passes[-1]
    u = float(last["uncertainty_s"])
    step = float(last["offset_s"])
    if abs(step) >= CLOCK_REFINE_S / 3.0:
        u = float(np.hypot(u, step))
    return u


def refine_clock_offset(inst: Instrument, row: dict, clock_pass, sun: SunTrack) -> None:
    """Refine a large clock offset: shift the times by it, fit the clock again there
    (``clock_pass``) and add the offset that pass finds, until a pass moves it by less
    than ``CLOCK_REFINE_S / 3``; updates ``row`` (value, uncertainty, ``significant``,
    ``refinement``).

    Parameters
    ----------
    inst : Instrument
        The session at its recorded times.
    row : dict
        The clock candidate's row of the diagnosis (:func:`clock_report` merged in).
    clock_pass : callable
        ``clock_pass(shifted) -> dict | None``: the clock candidate's row on the session
        ``shifted`` (``inst`` with its times corrected), fitted as the diagnosis fits it
        (screen, base fit, the clock's fold fits and :func:`clock_report`); None when no
        unit reads a usable sky there. It may raise :class:`DiagnosisError` or
        :class:`InvalidParameterError`, which end the refinement (``refinement_error``).
    sun : SunTrack
        The track of the body lighting the sky (for the sun's shift at the refined clock).

    The refined offset is the sum of the first fit and every pass's step, each read at the
    times the ones before corrected; its uncertainty is :func:`refined_uncertainty` of the
    passes. The passes fit the clock alone, under single scattering; when they end within
    ``CLOCK_REFINE_S`` of the first fit, whose sky candidates were then fitted near the
    right times, its ``sky_model_spread_s`` is added in quadrature too.

    Under a clock hours off, everything read from the base fit's residuals is read wrong: the
    glare screen finds no brightness at which the residuals grow (they are large everywhere)
    and keeps the unit-samples the sun's glare spoils, the noise floor grows (on a real
    session 2 h off, 0.016 against 0.0044) and the instrument's parameters come from another
    minimum. A fit of the clock alone from there stopped 22 min to 42 min from the truth; a
    pass at the corrected times screens and fits as on a session with a right clock.
    """
    param = row["params"]["clock_offset_s"]
    total, passes = float(param["value"]), []
    for _ in range(CLOCK_PASSES):
        try:
            c = clock_pass(replace(inst, t_s=inst.t_s + total))
        except (DiagnosisError, InvalidParameterError) as exc:
            row["refinement_error"] = str(exc)
            break
        if c is None or not c.get("available", True):
            row["refinement_error"] = (c or {}).get("error", "no clock fit at the corrected "
                                                             "times")
            break
        step = float(c["params"]["clock_offset_s"]["value"])
        total += step
        passes.append({"offset_s": step, "uncertainty_s": float(c["uncertainty_s"]),
                       "by_sky": c["by_sky"]})
        if abs(step) < CLOCK_REFINE_S / 3.0:
            break
    if not passes:
        return
    row["refinement"] = {"first_fit_s": float(param["value"]), "passes": passes,
                         "method": "clock fitted again at the corrected times (screen, base "
                                   "fit, clock candidate); uncertainty: " + REFINED_RULE}
    param["uncertainty"] = refined_uncertainty(passes)
    if abs(total - float(param["value"])) <= CLOCK_REFINE_S:
        # the passes read the clock under single scattering alone; a first fit this close
        # to the corrected times had its sky candidates fitted to about the right sky, so
        # the spread of the clock over them still holds (on a real session an hour past
        # culmination, 745 s that the passes would drop)
        spread = float(row.get("sky_model_spread_s", 0.0))
        param["uncertainty"] = float(np.hypot(param["uncertainty"], spread))
        row["refinement"]["sky_model_spread_kept_s"] = spread
    param["value"] = total
    row["uncertainty_s"] = param["uncertainty"]
    row["significant"] = bool(abs(total) > 2.0 * param["uncertainty"])
    if "sensitivity" in row:    # the sun's shift at the refined clock, not the first fit's
        row["sensitivity"] = clock_sensitivity(sun, float(np.mean(inst.t_s)),
                                               inst.absolute_yaw, offset_s=total)
