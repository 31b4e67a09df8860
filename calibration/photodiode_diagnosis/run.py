"""The diagnosis of a photodiode instrument: faults, base fit, held-out gap, where, which, how
far (its dict is read into the shared report by :mod:`calibration.diagnosis.rings`; method in
``docs/diagnosis.md``, section "Photodiode instruments").

The ring-specific physics is here (forward model, fits, clock refinement, pointing, fault
screen); folds, noise floor, held-out score, verdict, shrink and slice shares are those of
every diagnosis, :mod:`calibration.diagnosis.core`, with the ring's thresholds
:data:`RING_THRESHOLDS`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sensor.photodiodes_io import PhotodiodeData
from skysim.geometry import angle_between_deg, direction_vector, wrap_deg
from skysim.exceptions import InvalidParameterError
from skysim.sky import RayleighSky
from skysim.validation import TWILIGHT_LIMIT_DEG

from ..diagnosis import core
from ..diagnosis.core import Thresholds
from ..diagnosis.errors import DiagnosisError, InsufficientDataError
from ..diagnosis.report import LEGACY_SCHEMA, Candidate
from .effects import RING_EFFECT_NAMES, RingEffect, get_ring_effect
from .errors import (InstrumentDataError, PointingCalibrationError,
                     SunTooLowError)
from .faults import bright_glare, malus_outliers, screen
from .fit import fit, fit_headings, fit_pinned
from .forward import Forward, SunTrack
from .instrument import Instrument, instrument_from_photodiodes

__all__ = ["RING_THRESHOLDS", "diagnose_instrument", "diagnose_photodiodes", "orient",
           "decode_headings", "clock_mirror", "solar_noon_s"]

RING_THRESHOLDS = Thresholds(block_consistency=0.75, block_name="sweeps")
"""The ring's thresholds of the one verdict rule (:func:`calibration.diagnosis.core.decide`):
a candidate is named when it beats every other and the base by more than 2 paired SE on the
same held-out sweeps, converged away from its bounds, removes at least half the excess
held-out variance over the floor, and lowers the held-out gap in at least 75 % of the
held-out sweeps. A real sky is never reproduced to the noise floor by one effect (aerosols,
clouds, the instrument's own optics all add), so a smaller share is reported as
``partly_explained`` with the share rather than named; the sweep-by-sweep consistency keeps a
candidate that wins on a few sweeps only from being named."""
FIT_SAMPLES = 1500
"""Fits use every k-th sample of a sweep so that about this many samples remain: a platform
turning once in ~400 samples moves ~1 deg per sample, far finer than the sky's polarization
pattern varies, so thinning loses only noise averaging; held-out gaps use every sample."""


EFFECT_MAX_ITER = 12
"""Iterations of a candidate's fit (it starts from the fold's base fit and its best coarse
start, so its descent is short); a fit stopped here is reported ``converged: false``."""


def _thin(inst: Instrument, target: int = FIT_SAMPLES) -> Instrument:
    """Every k-th sample (about ``target`` remain), and the first sample of any sweep shorter
    than k that this skips: each sweep keeps its heading offset, so the thinned fit has the
    same parameters as the full model."""
    k = max(1, int(np.ceil(inst.n / target)))
    if k == 1:
        return inst
    rows = np.arange(0, inst.n, k)
    ids, first = np.unique(inst.sweep, return_index=True)
    missed = first[~np.isin(ids, inst.sweep[rows])]
    return inst.subset(np.union1d(rows, missed) if missed.size else rows)


def orient(fwd: Forward, theta) -> tuple[float, np.ndarray]:
    """Polarizer-angle sense (+1/-1) and a common polarizer offset (0/45/90/135 deg) that fit
    the readings best, with per-sweep headings from a 30-deg grid; returns ``(sign, theta)``.

    The sky is sampled once per heading of the grid: sense and offset act on the output
    stage only.
    """
    L = fwd.layout
    grid = np.arange(0.0, 360.0, 30.0)
    key = np.zeros(fwd.inst.n, int) if fwd.inst.absolute_yaw else fwd.inst.sweep
    obs = []
    for off in grid:
        t = np.array(theta, float)
        t[L.heading] = off
        obs.append((t, fwd.observe(t)))
    best = (np.inf, 1.0, None)
    for sign in (1.0, -1.0):
        fwd.polarizer_sign = sign
        for d0 in (0.0, 45.0, 90.0, 135.0):
            score = np.empty((grid.size, L.n_heading))
            for g, (t, o) in enumerate(obs):
                t = t.copy()
                t[L.delta] = d0
                r2 = np.sum(fwd.residual(t, o) ** 2, axis=1)
                score[g] = np.bincount(key, weights=r2, minlength=L.n_heading)
            total = float(score.min(axis=0).sum())
            if total < best[0]:
                t = np.array(theta, float)
                t[L.delta] = d0
                t[L.heading] = grid[np.argmin(score, axis=0)]
                best = (total, sign, t)
    fwd.polarizer_sign = best[1]
    return best[1], best[2]


def _extend(theta_base, fwd_base: Forward, fwd: Forward, p_eff) -> np.ndarray:
    t = np.zeros(fwd.layout.size)
    t[:fwd_base.layout.size] = theta_base[:fwd_base.layout.size]
    t[fwd.layout.effect] = p_eff
    return t


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


def _nominal_instrument(theta, L, groups) -> np.ndarray:
    """``theta`` with the instrument parameter ``groups`` (slices of the layout ``L``) at
    their nominal value 0: a start that does not carry what a base fit under a strongly
    different sky or clock took up into gains, offsets and angles."""
    out = np.array(theta, float)
    for sl in groups:
        out[sl] = 0.0
    return out


def _clock_starts(fwd: Forward, theta_base, fwd_base, effect) -> list:
    """Starts of the clock offset: no offset, and the two best of the whole and half hours
    (each with the per-sweep headings carried by the sun's azimuth change)."""
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
        # bound and a DoP scale of 0.99), and the scores with them
        nominal = _nominal_instrument(t, L, (L.lam, L.off, L.angle, L.pointing))
        nominal[L.scale] = NOMINAL_DOP_SCALE
        scored.append((float(np.sum(fwd.residual(nominal) ** 2)), t))
    scored.sort(key=lambda x: x[0])
    return [_extend(theta_base, fwd_base, fwd, [0.0])] + [t for _, t in scored[:2]]




def _fit_and_hold_out(fe: Forward, theta_base, ftr: Forward, effect, sigma, iho, sun, sign,
                      continued: bool = True):
    """One candidate on one fold: its fit on the training sweeps (:func:`_fit_effect` from
    :func:`_start_effect`; ``continued=False`` leaves it as :data:`EFFECT_MAX_ITER` stopped
    it, for :func:`_continue_and_hold_out` to take on) and its residuals on the held-out
    sweeps ``iho``; returns ``(fit, aop_fit, held-out Forward, held-out theta, residuals)``."""
    start = _start_effect(fe, theta_base, ftr, effect, sigma)
    fr, fr_aop = _fit_effect(fe, start, sigma)
    if continued:
        fr, fr_aop = _continued(fe, (fr, fr_aop), sigma, fe.aop_sky)
    feho = Forward(iho, effect, sun=sun, polarizer_sign=sign)
    teho, re = _held_out(feho, fr.theta, fe.layout, sigma)
    return fr, fr_aop, feho, teho, re


def _continue_and_hold_out(fe: Forward, pair, sigma, feho: Forward):
    """A fold's fit stopped by :data:`EFFECT_MAX_ITER` continued (:func:`_continued`) and its
    held-out residuals; returns ``(fit, aop_fit, held-out theta, residuals)``."""
    fr, fr_aop = _continued(fe, pair, sigma, fe.aop_sky)
    teho, re = _held_out(feho, fr.theta, fe.layout, sigma)
    return fr, fr_aop, teho, re


def _fit_effect(fe: Forward, starts, sigma):
    """Fit from each start (:func:`fit_pinned`: a geometric effect on the angle of
    polarization first); the lowest cost wins, judged on the stage that fixes the effect (the
    AoP fit for a geometric one). For the clock offset, ties (:data:`CLOCK_TIE`) go to the
    start nearest the effect's null (the smaller offset). A start whose model leaves its
    valid range is dropped; :class:`InvalidParameterError` when every start does. Returns
    ``(fit, aop_fit)``."""
    geometric = fe.effect.geometric
    starts = starts if isinstance(starts, list) else [starts]
    fits, failed = [], None
    aop_sky = fe.aop_sky
    for s in starts:
        # a clock start far from the recorded time is fitted on the single-scattering AoP:
        # the sky candidates were fitted about the recorded sun, so under a clock hours off
        # their skies (a neutral-point separation, an optical thickness) are fitted to the
        # wrong sky and their AoP misleads the clock (on a real morning session recorded 2 h
        # early, a fit under the best such sky stopped at +58 +- 43 min)
        far = fe.effect.name == "clock_offset" and abs(float(s[fe.layout.effect][0])) > \
            CLOCK_REFINE_S
        fe.aop_sky = None if far else aop_sky
        try:
            fits.append(fit_pinned(fe, s, sigma=sigma, max_iter=EFFECT_MAX_ITER,
                                   geometry=geometric, covariance=geometric))
        except InvalidParameterError as exc:
            # a start outside the model's valid range (the recorded clock putting the sun
            # below the twilight limit, while a start hours away holds): the others decide
            failed = exc
        finally:
            fe.aop_sky = aop_sky
    if not fits:
        raise failed

    def cost(f):
        return (f[1] if geometric else f[0]).cost

    best = min(cost(f) for f in fits)
    if fe.effect.name != "clock_offset":
        chosen = min(fits, key=cost)
    else:
        L = fe.layout
        close = [f for f in fits if cost(f) <= best * (1 + CLOCK_TIE)]
        chosen = min(close, key=lambda f: float(np.sum(np.abs(
            f[0].theta[L.effect] - np.asarray(fe.effect.null)))))
    return chosen


EFFECT_CONTINUE_ITER = 150
"""Further iterations of the winning start's fit when :data:`EFFECT_MAX_ITER` stopped it: a
verdict names only a candidate whose fit converged, and the short descent that suffices to
rank the starts stops some fits on their way (an overcast's thickness along its shallow
valley with the gains: a simulated overcast of thickness 0.6 needed over 40 more; only fits
that did not converge pay for them, and outside the sky candidates only those of candidates
that can matter to the verdict, :func:`_continue_pending`)."""


def _continued(fe: Forward, pair, sigma, aop_sky):
    """The chosen start's ``(fit, aop_fit)``, continued from where it stopped when it did
    not converge (kept as it was when the continuation leaves the model's valid range)."""
    fit_, aop = pair
    if fit_.converged:
        return pair
    geometric = fe.effect.geometric
    fe.aop_sky = aop_sky
    try:
        more = fit_pinned(fe, fit_.theta, sigma=sigma, max_iter=EFFECT_CONTINUE_ITER,
                          geometry=geometric, covariance=geometric)
    except InvalidParameterError:
        return pair
    return more if (more[1] if geometric else more[0]).cost <= \
        (aop if geometric else fit_).cost * (1 + 1e-9) or more[0].converged else pair


DOP_SCALE_STARTS = (0.2, 0.4, 0.6, 0.8, 1.0)
"""DoP scales tried at each start of an effect whose sky takes the scale
(:attr:`~.effects.RingEffect.dop_scale_in_sky`): clear skies' maximum DoP runs from about 0.2
(hazy) to 0.8 (clean air, Coulson 1988)."""


def _carry_dop_scale(fwd: Forward, t, obs, base_dop: float) -> np.ndarray:
    """``t`` with its DoP scale set so that the candidate's sky, seen by the instrument,
    carries the polarized fraction the base fit found: ``s' = s m_0 / m_c``, with ``m_0`` and
    ``m_c`` the median DoP the units see under the base sky (``base_dop``) and under the
    candidate's sky (``obs``, its observation at ``t``), kept within the scale's bounds. A sky whose DoP is everywhere lower (an aerosol load, many
    orders of scattering) then starts where the base model's polarized radiance is, instead of
    a misfit its fit must first climb out of (from AOD 0.15 with the base scale, an aerosol fit
    on a real ring session started at 90 times the cost it ended at)."""
    L = fwd.layout
    m0, mc = base_dop, float(np.median(obs.dop))
    out = t.copy()
    if mc > 0.0 and m0 > 0.0:
        out[L.scale] = np.clip(t[L.scale] * m0 / mc, 1e-3, 1.0)
    return out


def _start_effect(fwd: Forward, theta_base, fwd_base, effect, sigma):
    """Best start of an effect: its coarse candidates scored with the headings carried (a
    list of starts for the clock offset, see :func:`_clock_starts`, and for effects with
    ``n_fits > 1``)."""
    L = fwd.layout
    starts = effect.starts(None)
    if effect.name == "clock_offset":
        # whole hours apart, skies differ in DoP as much as in AoP, so the coarse search
        # scores the full model; the refinement reads the AoP alone (fit_pinned)
        return _clock_starts(fwd, theta_base, fwd_base, effect)
    own_sky = _has_sky(effect)
    base_dop = float(np.median(fwd_base.observe(theta_base).dop)) if own_sky else None
    if len(starts) == 1 and not own_sky:
        return _extend(theta_base, fwd_base, fwd, starts[0])
    resamples = effect.observes or own_sky
    obs0 = None if resamples else fwd_base.observe(theta_base)
    sun = fwd.sun(fwd.inst.t_s)
    scored = []
    for p in starts:
        t = _extend(theta_base, fwd_base, fwd, p)
        # a sky of its own starts with the base fit's DoP scale or with the scale carried
        # over to its DoP, whichever fits better
        if effect.dop_scale_in_sky:
            # the DoP scale acts on the clear sky inside the effect's sky, so it trades
            # with the effect's parameters along a curved valley: each start takes the
            # best of a few scales (each a new sky)
            # the base fit's instrument may have absorbed much of a strong effect, so
            # the nominal instrument is tried as well
            for tb in (t, _nominal_instrument(t, L, (L.lam, L.off, L.angle, L.delta))):
                for sc in DOP_SCALE_STARTS:
                    tt = tb.copy()
                    tt[L.scale] = sc
                    scored.append((float(np.sum(fwd.residual(tt) ** 2)), tt))
            continue
        o = effect.modify(obs0, p, sun) if obs0 is not None else fwd.observe(t)
        for tt in ((t, _carry_dop_scale(fwd, t, o, base_dop)) if own_sky else (t,)):
            scored.append((float(np.sum(fwd.residual(tt, o) ** 2)), tt))
    scored.sort(key=lambda x: x[0])
    n_fits = getattr(effect, "n_fits", 1)
    if n_fits == 1:
        return scored[0][1]
    picked = []      # the best starts that differ in their first parameter (a sector centre)
    for _, t in scored:
        if all(abs(wrap_deg(t[L.effect][0] - q[L.effect][0])) > 45.0 for q in picked):
            picked.append(t)
        if len(picked) == n_fits:
            break
    return picked


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


def conversion_rows(inst: Instrument) -> np.ndarray:
    """Row (n, U) of the conversion each unit's reading holds at every sample (the sample
    itself where the reading is fresh; see
    :func:`calibration.photodiode_diagnosis.instrument.held_readings`)."""
    n = inst.n
    rows = np.tile(np.arange(n)[:, None], (1, inst.n_units))
    if inst.held is None:
        return rows
    first = np.array([np.flatnonzero(inst.pd_unit == u)[0] for u in range(inst.n_units)])
    return np.maximum.accumulate(np.where(inst.held[:, first], 0, rows), axis=0)


def instrument_output(inst: Instrument) -> Instrument:
    """The instrument as its output reads at every sample: a held reading (flagged, see
    :func:`calibration.photodiode_diagnosis.instrument.held_readings`) is usable where the
    conversion it holds was and lies in the same sweep. A compass reads its held outputs, so
    heading decoding uses them; fits and gaps use the conversions only."""
    if inst.held is None or not inst.held.any():
        return inst
    conv = conversion_rows(inst)[:, inst.pd_unit]              # (n, P)
    ok = ~inst.flagged[conv, np.arange(inst.readings.shape[1])[None, :]]
    ok &= inst.sweep[conv] == inst.sweep[:, None]
    return replace(inst, flagged=~ok)


def _sun_el_az(sun: SunTrack, t_s: float):
    from skysim.geometry import elevation_azimuth
    el, az = elevation_azimuth(sun(np.array([t_s])))
    return float(el[0]), float(az[0])


def _shared_mask(layout) -> np.ndarray:
    m = np.ones(layout.size, bool)
    m[layout.heading] = False
    return m


def _held_out(fwd_ho: Forward, theta_tr, layout_tr, sigma):
    """Held-out residuals: shared parameters from training, headings refitted per sweep (on
    every k-th sample, :data:`FIT_SAMPLES`), residuals on every sample."""
    t = np.zeros(fwd_ho.layout.size)
    sh_tr, sh_ho = _shared_mask(layout_tr), _shared_mask(fwd_ho.layout)
    t[sh_ho] = theta_tr[sh_tr]
    thin = Forward(_thin(fwd_ho.inst, FIT_SAMPLES // 2), fwd_ho.effect, sun=fwd_ho.sun,
                   polarizer_sign=fwd_ho.polarizer_sign)
    res = fit_headings(thin, t, sigma=sigma)
    return res.theta, fwd_ho.residual(res.theta)


def _grid_decode(fwd: Forward, theta, centre, offsets, lag=None) -> np.ndarray:
    """Headings ``centre + offsets[k]`` (n,) scored per sample, the best refined by a
    parabola through its neighbours; ``lag`` (n, U) shifts each unit's prediction to the
    heading of its conversion."""
    n, K = fwd.inst.n, offsets.size
    cost = np.zeros((K, n))
    groups = ([(slice(None), 0.0)] if lag is None else
              [(fwd.inst.pd_unit == u, lag[:, u]) for u in range(fwd.inst.n_units)])
    try:
        for cols, lag_u in groups:
            for g, d in enumerate(offsets):
                fwd.heading_override = centre + d - lag_u
                cost[g] += np.sum(fwd.residual(theta)[:, cols] ** 2, axis=1)
    finally:
        fwd.heading_override = None
    k = np.argmin(cost, axis=0)
    i = np.arange(n)
    wrap = offsets[-1] - offsets[0] + (offsets[1] - offsets[0]) >= 360.0 - 1e-9
    if wrap:
        km, kp = (k - 1) % K, (k + 1) % K
    else:
        km, kp = np.maximum(k - 1, 0), np.minimum(k + 1, K - 1)
    c0, cm, cp = cost[k, i], cost[km, i], cost[kp, i]
    den = cm - 2 * c0 + cp
    shift = np.where(den > 0, 0.5 * (cm - cp) / np.where(den > 0, den, 1.0), 0.0)
    return centre + offsets[k] + np.clip(shift, -1, 1) * (offsets[1] - offsets[0])


def decode_headings(fwd: Forward, theta, step_deg: float = 5.0) -> np.ndarray:
    """Heading of every sample [deg] that best explains its readings under the fitted model
    (grid over 360 deg, then a parabola through the best node and its neighbours); NaN for a
    sample without a usable reading (nothing to decode).

    A unit whose reading holds an earlier conversion (:func:`conversion_rows`) is predicted
    at the decoded heading minus the turn since that conversion (from the fitted headings of
    the two samples): a multiplexed compass knows when each unit converted, and so its
    decoded heading does not lag while it turns. That refinement searches +-10 deg around the
    heading decoded without it (the turn between a unit's conversions is a few degrees).
    """
    n = fwd.inst.n
    h = _grid_decode(fwd, theta, np.zeros(n), np.arange(0.0, 360.0, step_deg))
    conv = conversion_rows(fwd.inst)
    heading = fwd.headings(theta)
    lag = heading[:, None] - heading[conv]                      # (n, U) [deg]
    if np.any(lag):
        h = _grid_decode(fwd, theta, h, np.arange(-10.0, 10.0 + 1e-9, 2.5), lag)
    return np.where(fwd.usable.any(axis=1), h, np.nan)


def _slices(inst: Instrument, fwd: Forward, theta_ho, r, w, floor):
    """Held-out base residuals by slice (:func:`calibration.diagnosis.core.partition_slices`:
    each dimension partitions the readings, a slice's share is its part of the dimension's
    excess variance ``sum(r^2) - n floor^2``), as dicts sorted by share."""
    obs = fwd.observe(theta_ho)
    n, P = r.shape
    u = inst.pd_unit
    r2 = np.where(w, r, np.nan) ** 2
    sun = fwd.sun(inst.t_s)
    view = direction_vector(obs.view_elevation_deg, obs.view_azimuth_deg)    # (n, U, 3)
    sun_dist = angle_between_deg(view, sun[:, None, :])[:, u]
    sky_az = np.mod(obs.view_azimuth_deg, 360.0)[:, u]
    from skysim.geometry import elevation_azimuth
    sun_el, _ = elevation_azimuth(sun)
    full = np.ones((n, P), bool)
    col = np.arange(P)[None, :]
    dims = [("unit", [full & (u == k)[None, :] for k in range(inst.n_units)],
             [f"u{k}" for k in range(inst.n_units)], None),
            ("photodiode", [full & (col == p) for p in range(P)], list(inst.columns), None),
            ("sweep", [(inst.sweep == s)[:, None] & full for s in range(inst.n_sweeps)],
             [str(s) for s in range(inst.n_sweeps)], None)]
    for dim, values, width, top in (("sky_azimuth_deg", sky_az, 30, 360),
                                    ("sun_distance_deg", sun_dist, 30, 180)):
        lows = range(0, top, width)
        dims.append((dim, [(values >= lo) & (values < lo + width) for lo in lows],
                     [f"{lo}-{lo + width}" for lo in lows],
                     [(lo, lo + width) for lo in lows]))
    dims.append(("motion", [inst.rotating[:, None] & full, ~inst.rotating[:, None] & full],
                 ["rotating", "standing"], None))
    if np.ptp(sun_el) > 2.0:
        edges = np.quantile(sun_el, [0, 1 / 3, 2 / 3, 1])
        pairs = list(zip(edges[:-1], edges[1:]))
        dims.append(("sun_elevation_deg",
                     [((sun_el >= a) & (sun_el <= b))[:, None] & full for a, b in pairs],
                     [f"{a:.1f}-{b:.1f}" for a, b in pairs], pairs))
    out = []
    for dim, masks, labels, bounds in dims:
        out += core.partition_slices(dim, masks, labels, r2, floor,
                                     RING_THRESHOLDS.none_margin, bounds=bounds,
                                     bound_unit=None if bounds is None else "deg")
    return [sl.to_dict() for sl in core.sort_slices(out)]


def _params(effect, theta, layout):
    if effect is None:
        return {}
    return {n: {"value": float(v), "unit": un}
            for n, v, un in zip(effect.parameter_names, theta[layout.effect], effect.units)}


def _no_signal_report(inst, scr, why) -> dict:
    return {"schema": LEGACY_SCHEMA, "instrument": "photodiodes",
            "verdict": {"effect": "unexplained", "reason": why, "gap_before": None,
                        "gap_after": None, "shrink": None, "params": {},
                        "metric": "held-out RMS of relative photodiode residuals"},
            "candidates": [], "where": [], "faults": scr.faults,
            "noise_floor": None, "heading_error": None,
            "data": dict(inst.source, readings_excluded=scr.counts)}


def _refit(inst: Instrument, scr, theta, sun, sign, max_iter):
    """The base fit again after the screen excluded more readings: ``(work, base, fit,
    full)`` (the instrument with its exclusions, the thinned and the full forward models)."""
    work = replace(inst, flagged=~scr.reading_ok)
    base = Forward(_thin(work), sun=sun, polarizer_sign=sign)
    first = fit(base, theta, sigma=0.02, max_iter=max_iter)
    return work, base, first, Forward(work, sun=sun, polarizer_sign=sign)


CLOCK_NEAR_S = 1800.0
"""Offsets [s] nearer the recorded times than this (the nearest coarse start, half an hour)
are read under each sky model from the recorded times (:func:`clock_report`); farther ones
from the fitted offset, with the pointing re-read there."""

CLOCK_REFINE_S = 900.0
"""A clock offset larger than this [s] is refined (:func:`_refine_clock`)."""

CLOCK_PASSES = 3
"""Most refinement passes of a clock offset; they stop once a pass moves it by less than a
third of :data:`CLOCK_REFINE_S`."""


def _refine_clock(inst: Instrument, row: dict, *, n_folds: int, seed: int,
                  max_iter: int) -> None:
    """Refine a large clock offset by diagnosing the session again at the corrected times
    (clock candidate alone) and adding the offset that pass finds, until a pass moves it by
    less than ``CLOCK_REFINE_S / 3``; updates ``row`` (value, uncertainty, ``significant``,
    ``refinement``). The passes fit the clock alone, under single scattering; when they end
    within ``CLOCK_REFINE_S`` of the first fit, whose sky candidates were then fitted near the
    right times, its ``sky_model_spread_s`` is added in quadrature to the last pass's
    uncertainty.

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
        shifted = replace(inst, t_s=inst.t_s + total)
        try:
            doc = diagnose_instrument(shifted, ("clock_offset",), n_folds=n_folds, seed=seed,
                                      max_iter=max_iter, refine_clock=False)
        except (DiagnosisError, InvalidParameterError) as exc:
            row["refinement_error"] = str(exc)
            break
        c = next((r for r in doc["candidates"] if r["effect"] == "clock_offset"), None)
        if c is None or not c.get("available", True):
            row["refinement_error"] = (c or {}).get("error", "no clock fit at the corrected "
                                                             "times")
            break
        step = float(c["params"]["clock_offset_s"]["value"])
        total += step
        param["uncertainty"] = float(c["uncertainty_s"])
        passes.append({"offset_s": step, "uncertainty_s": float(c["uncertainty_s"]),
                       "by_sky": c["by_sky"]})
        if abs(step) < CLOCK_REFINE_S / 3.0:
            break
    if passes:
        row["refinement"] = {"first_fit_s": float(param["value"]), "passes": passes,
                             "method": "session diagnosed again at the corrected times "
                                       "(screen, base fit, clock candidate)"}
        if abs(total - float(param["value"])) <= CLOCK_REFINE_S:
            # the passes read the clock under single scattering alone; a first fit this
            # close to the corrected times had its sky candidates fitted to about the right
            # sky, so the spread of the clock over them still holds (on a real session an
            # hour past culmination, 745 s that the passes would drop)
            spread = float(row.get("sky_model_spread_s", 0.0))
            param["uncertainty"] = float(np.hypot(param["uncertainty"], spread))
            row["refinement"]["sky_model_spread_kept_s"] = spread
        param["value"] = total
        row["uncertainty_s"] = param["uncertainty"]
        row["significant"] = bool(abs(total) > 2.0 * param["uncertainty"])


def diagnose_instrument(inst: Instrument, effects=RING_EFFECT_NAMES, *, n_folds: int = 3,
                        seed: int = 0, max_iter: int = 25, pointing=None,
                        refine_clock: bool = True) -> dict:
    """Diagnose a photodiode instrument (see module doc); returns the report dict.

    ``pointing`` (2 U,) [deg]: the units' calibrated pointing offsets
    (:func:`calibrated_pointing` of other sessions' reports), held in every fit (NaN: a unit
    not calibrated, fitted); ``None`` fits them all on this session (where a common elevation offset and a clock error trade one
    for the other, :mod:`.pointing`).

    Raises
    ------
    PointingCalibrationError
        A ``pointing`` that is not 2 U angles within +-20 deg (or NaN).
    SunTooLowError
        With the sun below the twilight limit at a sample, unless the clock candidate is
        asked for and the units read a lit sky at a clock offset that puts the sun up
        (:mod:`.dark_clock`: the clock is then searched first).
    InstrumentDataError
        When every reading is saturated.
    InsufficientDataError
        For folds that do not fit the sweeps, or a fold whose training sweeps hold fewer
        usable readings than the base fit has parameters (the other sweeps have none).
    """
    path = inst.source.get("path", "photodiode data")
    if pointing is not None:
        inst = replace(inst, pointing_deg=_checked_pointing(pointing, inst.n_units))
    sun = light_track(inst)
    from skysim.geometry import elevation_azimuth
    sun_el, _ = elevation_azimuth(sun(inst.t_s))
    if inst.light == "moon":
        _check_moonlit(inst, sun_el, path)
    if sun_el.min() < TWILIGHT_LIMIT_DEG:
        i = int(np.argmin(sun_el))
        too_low = SunTooLowError(
            f"{path}: the sun is at {sun_el[i]:.2f} deg at sample {i}, below the twilight limit "
            f"{TWILIGHT_LIMIT_DEG:g} deg: the sky is too dark for a polarization compass. "
            "Check the times and their UTC offset, or drop the night samples")
        if not (refine_clock and "clock_offset" in effects) or inst.light != "sun":
            raise too_low
        # a lit sky stamped after dusk is a clock hours off: searched first
        from .dark_clock import diagnose_dark_clock
        return diagnose_dark_clock(inst, effects, too_low, n_folds=n_folds, seed=seed,
                                   max_iter=max_iter)
    if sun_el.min() < TWILIGHT_LIMIT_DEG + CLOCK_START_MARGIN_DEG and refine_clock \
            and "clock_offset" in effects and inst.light == "sun":
        # deep twilight: clock starts that keep the sun up are scored against the recorded
        # times first (a fit from the recorded times walks below the limit)
        from .dark_clock import diagnose_dark_clock
        doc = diagnose_dark_clock(inst, effects, None, n_folds=n_folds, seed=seed,
                                  max_iter=max_iter)
        if doc is not None:
            return doc
    finite = np.isfinite(inst.readings)
    if finite.any() and np.all(inst.readings[finite] >= inst.source["saturation_value"]):
        raise InstrumentDataError(
            f"{path}: all {int(finite.sum())} readings are at or above the saturation value "
            f"{inst.source['saturation_value']:g}: shorten the exposure or lower the gain")
    folds = core.assign_folds(inst.sweep, n_folds)
    cand = [get_ring_effect(e) for e in effects]
    scr = screen(inst)
    if scr.unit_ok.sum() < 2:
        return _no_signal_report(inst, scr, f"fewer than two units keep three working "
                                            f"photodiodes ({len(scr.faults)} faults)")
    work = replace(inst, flagged=~scr.reading_ok)
    base = Forward(_thin(work), sun=sun)
    L = base.layout
    theta = np.zeros(L.size)
    theta[L.scale] = 0.6
    sign, theta = orient(base, theta)
    # the screen (glare, Malus outliers) reads residuals of the plain fit, as it was tuned;
    # the base model proper is the pinned fit after it
    first = fit(base, theta, sigma=0.02, max_iter=max_iter)
    full = Forward(work, sun=sun, polarizer_sign=sign)
    scr2 = bright_glare(inst, scr, full.residual(first.theta), full.usable)
    if scr2.bright is not None and scr2.bright.any():
        work, base, first, full = _refit(inst, scr2, first.theta, sun, sign, max_iter)
    scr = scr2
    scr2 = malus_outliers(inst, scr, full.residual(first.theta), full.usable)
    if scr2 is not scr:
        scr = scr2
        if scr.unit_ok.sum() < 2:
            return _no_signal_report(inst, scr, "fewer than two units follow Malus's law")
        work, base, first, full = _refit(inst, scr, first.theta, sun, sign, max_iter)
    start = first.theta.copy()
    start[L.pointing] = 0.0     # the plain fit's pointing took up the DoP misfit
    first, _ = fit_pinned(base, start, sigma=0.02, max_iter=max_iter)
    sigma = max(core.noise_floor(full.residual(first.theta), full.usable, work.sweep)[0], 1e-4)

    shape = work.readings.shape
    res = {"base": np.zeros(shape)}
    res.update({e.name: np.zeros(shape) for e in cand})
    heads = {k: np.full(work.n, np.nan) for k in res}
    w_ho = np.zeros(shape, bool)
    fold_params = {e.name: [] for e in cand}
    fold_converged = {e.name: [] for e in cand}
    fold_sd = {e.name: [] for e in cand}
    fold_aop_sky = {e.name: [] for e in cand}
    unavailable, decoders, pending = {}, {}, {}
    output = instrument_output(work)
    for e in cand:
        why = e.available_at(sun_el)
        if why is not None:
            unavailable[e.name] = why
    for f in np.unique(folds):
        tr, ho = np.flatnonzero(folds != f), np.flatnonzero(folds == f)
        itr, iho = _thin(work.subset(tr)), work.subset(ho)
        ftr = Forward(itr, sun=sun, polarizer_sign=sign)
        if ftr.usable.sum() < ftr.layout.size:
            empty = [int(s) for s in range(work.n_sweeps) if not full.usable[work.sweep == s].any()]
            raise InsufficientDataError(
                f"{path}: held-out fold {int(f)}: its training sweeps hold "
                f"{int(ftr.usable.sum())} usable readings, fewer than the {ftr.layout.size} "
                f"parameters of the base fit; sweeps {empty} (0-based, in order of appearance) "
                "have no usable reading (all missing, zero or saturated): drop them from the file")
        t0 = np.r_[first.theta[:L.n_base], _sweep_headings(first.theta, L, work, tr, ftr)]
        btr, _ = fit_pinned(ftr, t0, sigma=sigma, max_iter=max_iter)
        fho = Forward(iho, sun=sun, polarizer_sign=sign)
        tho, r = _held_out(fho, btr.theta, ftr.layout, sigma)
        res["base"][ho], w_ho[ho] = r, fho.usable
        heads["base"][ho] = fho.headings(tho)
        decoders.setdefault("base", []).append((None, tho, ho))
        best_sky = None     # (training cost, sky) of the best-fitting sky candidate
        for e in sorted(cand, key=lambda c: c.geometric):   # sky candidates first
            if e.name in unavailable:
                continue
            fe = Forward(itr, e, sun=sun, polarizer_sign=sign)
            if e.geometric and best_sky is not None:
                fe.aop_sky = best_sky[1]
                fold_aop_sky[e.name].append(best_sky[2])
            # a fit that fails (leaves the model's valid range on the training or the
            # held-out sweeps, a numerical failure) or leaves non-finite held-out residuals
            # makes the candidate not applicable to this session; it never ends the diagnosis
            # a sky candidate's fit is continued here: the best-fitting sky of the fold (by
            # its continued cost) is the one the geometric candidates are fitted on; the
            # others' continuation waits for the ranking (:func:`_continue_pending`)
            out, why = core.run_candidate(_fit_and_hold_out, fe, btr.theta, ftr, e, sigma,
                                          iho, sun, sign, continued=_has_sky(e))
            if why is None:
                fr, fr_aop, feho, teho, re = out
                why = core.non_finite_reason(np.where(fho.usable, re, np.nan),
                                             np.where(fho.usable, r, np.nan))
            if why is not None:
                unavailable[e.name] = why
                continue
            if _has_sky(e) and (best_sky is None or fr.cost < best_sky[0]):
                p = fr.theta[fe.layout.effect]
                best_sky = (fr.cost, e.sky(p, RayleighSky(1.0), fe.sun(fe.inst.t_s)),
                            {"effect": e.name, **dict(zip(e.parameter_names, map(float, p)))})
            if not fr.converged and not _has_sky(e):    # a sky's fit was continued above
                pending.setdefault(e.name, []).append(dict(
                    fe=fe, pair=(fr, fr_aop), feho=feho, fho=fho, r=r, ho=ho,
                    i=len(fold_params[e.name]), i_sd=len(fold_sd[e.name]),
                    i_dec=len(decoders.get(e.name, []))))
            if fr_aop is not None:
                fold_sd[e.name].append(_effect_sd(fr_aop, fe.layout))
            fold_params[e.name].append(fr.theta[fe.layout.effect])
            fold_converged[e.name].append(bool(fr.converged))
            res[e.name][ho] = re
            heads[e.name][ho] = feho.headings(teho)
            decoders.setdefault(e.name, []).append((e, teho, ho))
    white, _ = core.noise_floor(res["base"], w_ho, work.sweep)
    replica = _replica_gap(work, first.theta, L, folds, sun, sign, sigma, white, max_iter, seed)
    floor = max(white, replica)
    n_ho = int(w_ho.sum())
    n_cal = int(n_ho * (1 - 1 / np.unique(folds).size))
    _continue_pending(pending, cand, unavailable, res, heads, w_ho, floor, n_ho, n_cal, sigma,
                      fold_params, fold_sd, fold_converged, decoders)
    # held-out residuals, NaN where a reading is not used
    held = {k: np.where(w_ho, r, np.nan) for k, r in res.items()}
    g0 = core.rms(held["base"])
    rows = []
    for e in cand:
        if e.name in unavailable:
            rows.append({"effect": e.name, "available": False, "error": unavailable[e.name]})
            continue
        gc = core.rms(held[e.name])
        P = np.array(fold_params[e.name])
        improved = core.blocks_improved(held["base"], held[e.name], work.sweep)
        rows.append({"effect": e.name, "gap_after": gc, "shrink": 1 - gc / g0,
                     "score": core.held_out_score(gc, g0, floor, n_ho, e.k, n_cal), "k": e.k,
                     "excess_removed": core.excess_removed(gc, g0, floor),
                     "sweeps_improved": improved, "blocks_improved": improved,
                     "converged": all(fold_converged[e.name]),
                     "at_bound": core.at_bound(P, e.lower, e.upper, e.parameter_names),
                     "params": _fold_params(e, P, fold_sd[e.name])})
        if e.geometric:
            rows[-1]["fitted_on"] = ("angle of polarization (DoP profiled out) of the "
                                     "best-fitting sky candidate of each fold, then held")
            rows[-1]["aop_sky_by_fold"] = fold_aop_sky[e.name]
        if e.name == "clock_offset":
            report, why = core.run_candidate(
                clock_report, work, e, first.theta, L, sun, sign, sigma,
                rows[-1]["params"]["clock_offset_s"], rows, cand)
            if why is not None:
                rows[-1] = {"effect": e.name, "available": False, "error": why}
                held.pop(e.name)
                continue
            rows[-1].update(report)
            # refined whether or not it is significant yet: under a clock hours off, the sky
            # candidates fitted at the recorded times scatter the clock (``by_sky``) so much
            # that a true 2 h came out as +58 +- 43 min
            if refine_clock and \
                    abs(rows[-1]["params"]["clock_offset_s"]["value"]) > CLOCK_REFINE_S:
                _refine_clock(inst, rows[-1], n_folds=n_folds, seed=seed, max_iter=max_iter)
        # a clock offset within twice its uncertainty is no finding, however it fits; nor is
        # an effect fitted at its null in every fold (its refit found a better optimum of the
        # instrument's own parameters, not the effect: an overcast of thickness 0 on an
        # open-sky session)
        rows[-1]["null_excluded"] = bool(rows[-1].get("significant", True)
                                         and not _at_null(e, P))
    ranked, decision = core.judge([Candidate.from_dict(r) for r in rows],
                                  {k: v for k, v in held.items()
                                   if k == "base" or k not in unavailable},
                                  work.sweep, floor, RING_THRESHOLDS)
    verdict, reason = decision
    rows = [c.to_dict() for c in ranked]
    avail = [r for r in rows if r["available"]]
    best = avail[0]["effect"] if avail else None
    named = best is not None and verdict == best
    herr = {}
    for key in ("base", best if named else None):
        if key is None:
            continue
        errs = []
        for effect, t, ho in decoders[key]:
            fwd = Forward(output.subset(ho), effect, sun=sun, polarizer_sign=sign)
            dec = decode_headings(fwd, t)
            ref = fwd.headings(t)
            errs.append(wrap_deg(dec - ref))
        e_all = np.concatenate(errs)
        e_all = e_all[np.isfinite(e_all)]
        herr[key] = float(np.sqrt(np.mean(e_all ** 2))) if e_all.size else None
    # slices of the held-out base residual
    fho_all = Forward(work, sun=sun, polarizer_sign=sign)
    theta_all = np.r_[first.theta[:L.n_base], np.zeros(L.n_heading)]
    theta_all[L.heading] = _assemble_headings(heads["base"], work)
    where = _slices(work, fho_all, theta_all, res["base"], w_ho, floor)
    # how far: the best candidate's gap (the base's for ``none``), with bootstrap standard
    # errors over the held-out sweeps
    after = best if best is not None and verdict != "none" else "base"
    se = core.shrink_uncertainty(held["base"], held[after], work.sweep,
                                 np.random.default_rng(seed))
    g1 = core.rms(held[after])
    v = {"effect": verdict, "reason": reason, "gap_before": g0, "gap_after": g1,
         "shrink": 1 - g1 / g0,
         "gap_before_se": se["gap_before_se"],
         "gap_after_se": se["gap_after_se" if after != "base" else "gap_before_se"],
         "shrink_se": se["shrink_se"] if after != "base" else 0.0,
         "metric": "held-out RMS of relative photodiode residuals (fraction of the unit's "
                   "mean reading)",
         "noise_floor": floor, "best_candidate": best,
         "params": avail[0]["params"] if named else {}, "group": decision.group,
         "explained_share": decision.share, "explained_share_se": decision.share_se,
         "separated_by": decision.separated_by}
    return {
        "schema": LEGACY_SCHEMA, "instrument": "photodiodes", "verdict": v,
        "thresholds": RING_THRESHOLDS.to_dict(), "candidates": rows, "where": where, "faults": scr.faults,
        "noise_floor": {"rms": floor, "method": NOISE_FLOOR_METHOD,
                        "white_noise_rms": white, "replica_held_out_gap": replica},
        "heading_error": {"metric": "RMS over held-out samples of decoded minus fitted "
                                    "heading [deg], decoded from the instrument's output "
                                    "(held readings at the heading of their conversion)"
                                    + ("" if work.absolute_yaw else
                                       " (relative yaw: per-sweep offset fitted)"),
                          "base_deg": herr.get("base"),
                          "best_deg": herr.get(best) if best in herr else None},
        "base_fit": _base_fit_report(first.theta, L, base, work, sign),
        "instrument_checks": _instrument_checks(work, first.theta, L, base, sun),
        "data": dict(inst.source, readings_excluded=scr.counts, glare=scr.glare,
                     sun_elevation_deg=[float(sun_el.min()), float(sun_el.max())]),
        "split": {"folds": int(n_folds), "by": "whole sweeps, round-robin in time order",
                  "held_out_readings": n_ho},
        "seed": seed}


CONTINUE_TOP = 3
"""The best-ranked candidates (held-out score of their fits as :data:`EFFECT_MAX_ITER` left
them) whose stopped fits are always continued (:func:`_continue_pending`)."""
CONTINUE_GAP_MARGIN = 0.10
"""A lower-ranked candidate's stopped fits are continued unless its held-out gap exceeds the
best-ranked candidate's by more than this fraction: three times the largest change of a
held-out gap by a continuation on a real ring session (a stray light's, 3.3 %)."""


def _effect_sd(fr_aop, layout) -> list:
    """Posterior SD of each effect parameter of an AoP fit."""
    return [fr_aop.sd(i) for i in range(layout.effect.start, layout.effect.stop)]


def _continue_pending(pending, cand, unavailable, res, heads, w_ho, floor, n_ho, n_cal, sigma,
                      fold_params, fold_sd, fold_converged, decoders) -> None:
    """Continue (:func:`_continued`) the stopped fold fits of the candidates that can matter
    to the verdict, updating their held-out residuals, headings, parameters and convergence
    in place.

    The candidates are ranked on the held-out residuals of their fits as they stand (sky
    candidates continued, the others as :data:`EFFECT_MAX_ITER` left them). The
    :data:`CONTINUE_TOP` best are continued, and so is any other whose held-out gap is
    within :data:`CONTINUE_GAP_MARGIN` of the best's. A candidate left out keeps its
    stopped fits and is reported ``converged: false``, which keeps it from being named; it
    could not be named or grouped with the best anyway: either needs it not to trail the
    best by the verdict's paired margin, and a continuation that closes a held-out gap
    more than 10 % wider than the best's has not been seen (the largest change measured,
    on a real ring session, was 3.3 % of the gap; the best's own continuation only widens
    the distance). ``converged`` of a continued candidate is that of its continued fits.
    """
    if not pending:
        return
    held = {k: np.where(w_ho, r, np.nan) for k, r in res.items()}
    g0 = core.rms(held["base"])
    live = [e for e in cand if e.name not in unavailable]
    gap = {e.name: core.rms(held[e.name]) for e in live}
    score = {e.name: core.held_out_score(gap[e.name], g0, floor, n_ho, e.k, n_cal)
             for e in live}
    ranked = sorted(live, key=lambda e: (score[e.name], gap[e.name]))
    best = ranked[0].name
    for pos, e in enumerate(ranked):
        if e.name not in pending:
            continue
        if pos >= CONTINUE_TOP and \
                gap[e.name] > gap[best] * (1 + CONTINUE_GAP_MARGIN):
            continue
        for p in pending[e.name]:
            out, why = core.run_candidate(_continue_and_hold_out, p["fe"], p["pair"], sigma,
                                          p["feho"])
            if why is None:
                fr, fr_aop, teho, re = out
                why = core.non_finite_reason(np.where(p["fho"].usable, re, np.nan),
                                             np.where(p["fho"].usable, p["r"], np.nan))
            if why is not None:
                unavailable[e.name] = why
                break
            ho, fe = p["ho"], p["fe"]
            if fr_aop is not None:
                fold_sd[e.name][p["i_sd"]] = _effect_sd(fr_aop, fe.layout)
            fold_params[e.name][p["i"]] = fr.theta[fe.layout.effect]
            fold_converged[e.name][p["i"]] = bool(fr.converged)
            res[e.name][ho] = re
            heads[e.name][ho] = p["feho"].headings(teho)
            decoders[e.name][p["i_dec"]] = (e, teho, ho)


NOISE_FLOOR_METHOD = ("the larger of the white-noise RMS (second differences along each "
                      "sweep) and the held-out gap of the base model on a noise-only replica "
                      "of the session (its fit plus white noise at that RMS, split and fitted "
                      "as the data)")


def _replica_gap(work: Instrument, theta, L, folds, sun, sign, sigma, white: float,
                 max_iter: int, seed: int) -> float:
    """Held-out gap [relative] the base model reaches on a noise-only replica of the session.

    The replica's readings are the base model's full fit (``theta``) plus Gaussian white
    noise of RMS ``white`` (relative to each unit's mean reading, as the residuals); it is
    split, fitted and scored fold by fold as the data are. Its held-out gap is what a
    correct base model reaches held out on these sweeps: white noise plus the spread of
    parameters fitted on fewer sweeps (on three sweeps, training folds of two read a unit's
    pointing from the angle of polarization alone, which leaves it loose, and the held-out
    gap of noise-only sessions came out at 1.7-1.9 x the white noise). A gap within it is no
    evidence of an unmodelled effect.
    """
    full = Forward(work, sun=sun, polarizer_sign=sign)
    rng = np.random.default_rng([int(seed), 20260])
    res = np.full((REPLICAS,) + work.readings.shape, np.nan)
    for k in range(REPLICAS):
        noise = white * rng.standard_normal(work.readings.shape)
        shift = full.level * full._scale * (noise - full.residual(theta))
        rep = replace(work, readings=np.where(full.usable, work.readings + shift,
                                              work.readings))
        for f in np.unique(folds):
            tr, ho = np.flatnonzero(folds != f), np.flatnonzero(folds == f)
            ftr = Forward(_thin(rep.subset(tr)), sun=sun, polarizer_sign=sign)
            t0 = np.r_[theta[:L.n_base], _sweep_headings(theta, L, rep, tr, ftr)]
            btr, _ = fit_pinned(ftr, t0, sigma=sigma, max_iter=max_iter)
            fho = Forward(rep.subset(ho), sun=sun, polarizer_sign=sign)
            _, r = _held_out(fho, btr.theta, ftr.layout, sigma)
            res[k, ho] = np.where(fho.usable, r, np.nan)
    return core.rms(res)


REPLICAS = 3
"""Noise-only replicas of a session whose held-out gaps (pooled) give the floor: the spread of
the parameters fitted on fewer sweeps differs from one noise realisation to the next (one
replica of a noise-only session read 0.88-1.15 x its data's held-out gap)."""


def _at_null(effect, P) -> bool:
    """True when every fold fitted every parameter of ``effect`` within its finite-difference
    step of its null (``P``: (folds, k))."""
    P = np.asarray(P, float)
    if P.size == 0:
        return False
    null = np.asarray(effect.null, float)
    return bool(np.all(np.abs(P - null) <= np.asarray(effect.fd_step, float)))


def _fold_params(effect, P, sds) -> dict:
    """Mean over folds of each effect parameter, its spread over folds and, for a geometric
    effect fitted with a covariance, its uncertainty: the root sum of squares of the mean
    posterior SD of the folds' AoP fits and the spread between folds."""
    out = {}
    for j, (n, un) in enumerate(zip(effect.parameter_names, effect.units)):
        out[n] = {"value": float(np.mean(P[:, j])), "fold_spread": float(np.std(P[:, j])),
                  "unit": un}
        sd = [f[j] for f in sds if f[j] is not None]
        if sd:
            out[n]["uncertainty"] = float(np.sqrt(np.mean(np.square(sd))
                                                  + np.var(P[:, j])))
    return out


def _has_sky(effect) -> bool:
    """True for an effect that replaces the sky model (its own DoP and AoP)."""
    return type(effect).sky is not RingEffect.sky


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
    instrument re-read from the AoP at ``start_s``, then the clock) started at ``start_s``,
    on the sky ``fe.aop_sky``."""
    t = np.zeros(fe.layout.size)
    t[:layout.size] = theta_base[:layout.size]
    t[fe.layout.effect] = start_s
    _, aop = fit_pinned(fe, t, sigma=sigma, max_iter=EFFECT_MAX_ITER, full=False)
    return float(aop.theta[fe.layout.effect][0])


def solar_noon_s(sun: SunTrack, t_s: float) -> float:
    """Time [s since epoch, UTC] of the sun's culmination nearest ``t_s`` (highest elevation
    on a 60-s grid over +-12 h, refined by a parabola through the top three)."""
    from skysim.geometry import elevation_azimuth
    t = t_s + np.arange(-12 * 3600.0, 12 * 3600.0 + 60.0, 60.0)
    el, _ = elevation_azimuth(sun(t))
    i = int(np.clip(np.argmax(el), 1, t.size - 2))
    a, b, c = el[i - 1], el[i], el[i + 1]
    den = a - 2 * b + c
    return float(t[i] + (0.5 * (a - c) / den * 60.0 if den != 0 else 0.0))


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


def _sweep_headings(theta, L, inst, rows, ftr):
    h = theta[L.heading]
    if inst.absolute_yaw:
        return h
    return h[np.unique(inst.sweep[rows])]


def _assemble_headings(heads, inst):
    """Per-sweep heading offsets from per-sample fitted headings (for the slices)."""
    if inst.absolute_yaw:
        return np.array([np.nanmean(heads - inst.yaw_deg)])
    off = np.zeros(inst.n_sweeps)
    for s in range(inst.n_sweeps):
        m = inst.sweep == s
        off[s] = float(np.median(heads[m] - inst.yaw_deg[m]))
    return off


def _instrument_checks(inst: Instrument, theta, L, fwd, sun) -> dict:
    """The model-free checks of :mod:`.checks` on the screened readings: the sum rule by sun
    distance, side and motion, side-dependent glare, units failing in motion. The base fit
    places the sun (its heading offsets) and lends its gains and dark offsets to the units
    whose readings do not define their own."""
    from .checks import check_instrument
    heading = np.asarray(theta[L.heading], float)
    offset = heading[inst.sweep] if heading.size == inst.n_sweeps else heading[0]
    fitted = fwd.usable.any(axis=0)
    gains = np.where(fitted, np.exp(theta[L.lam]), np.nan)
    dark = np.where(fitted, theta[L.off] * fwd.level, np.nan)
    return check_instrument(inst, offset, sun(inst.t_s), gains=gains,
                            dark_offsets=dark).to_dict()


def _base_fit_report(theta, L, fwd, inst, sign):
    """The base fit's parameters by unit and photodiode; ``None`` for those the screen
    excluded (they were never fitted)."""
    pd_fitted = fwd.usable.any(axis=0)
    unit_fitted = np.zeros(L.n_units, bool)
    unit_fitted[inst.pd_unit[pd_fitted]] = True

    def per_unit(values):
        return {f"u{u}": float(d) if unit_fitted[u] else None for u, d in enumerate(values)}

    def per_pd(values, f=float):
        return {c: f(v) if ok else None for c, v, ok in zip(inst.columns, values, pd_fitted)}

    point = theta[L.pointing] + (0.0 if inst.pointing_deg is None
                                 else np.nan_to_num(inst.pointing_deg))
    el = point[:L.n_units]
    return {"pointing_held": inst.pointing_deg is not None,"polarizer_sense": "as unit frame" if sign > 0 else "opposite to unit frame",
            "dop_scale": float(theta[L.scale]),
            "polarizer_offset_deg": per_unit(theta[L.delta]),
            "polarizer_angle_deviation_deg": per_pd(theta[L.angle]),
            "elevation_offset_deg": per_unit(el),
            "elevation_offset_mean_deg": (float(np.mean(el[unit_fitted])) if unit_fitted.any()
                                          else None),
            "azimuth_offset_deg": per_unit(point[L.n_units:]),
            "gain": per_pd(theta[L.lam], lambda g: float(np.exp(g))),
            "offset": per_pd(theta[L.off], lambda o: float(o * fwd.level)),
            "heading_offset_deg": [float(h) for h in theta[L.heading]]}


def diagnose_photodiodes(data: PhotodiodeData, effects=RING_EFFECT_NAMES, *, n_folds: int = 3,
                         seed: int = 0, where: str = "photodiode data", pointing=None,
                         light: str = "sun") -> dict:
    """:func:`diagnose_instrument` of a photodiode file; ``light="moon"`` for a session under
    the moonlit night sky.

    Raises
    ------
    InstrumentDataError
        For ``light`` other than "sun" or "moon".
    """
    if light not in LIGHTS:
        raise InstrumentDataError(f"{where}: light must be one of {', '.join(LIGHTS)}; "
                                  f"got {light!r}")
    inst = replace(instrument_from_photodiodes(data, where), light=light)
    return diagnose_instrument(inst, effects, n_folds=n_folds, seed=seed, pointing=pointing)


LIGHTS = ("sun", "moon")
"""The bodies whose light a ring session's sky may scatter."""

MOONLIT_SUN_LIMIT_DEG = -18.0
"""Highest sun elevation [deg] for a moonlit session: astronomical twilight ends at -18 deg,
below which the Sun adds no scattered light to the night sky (Krisciunas & Schaefer 1991,
PASP 103:1033, whose moonlit-sky model assumes it); above, the twilight sky outshines the
moonlit pattern of all but a full Moon."""


def light_track(inst: Instrument) -> SunTrack:
    """The track of the body that lights the session's sky (:attr:`Instrument.light`)."""
    if inst.light == "moon":
        from skysim.moon import MoonTrack
        return MoonTrack(inst.site, inst.t_s.min(), inst.t_s.max(), margin_s=15 * 3600.0)
    return SunTrack(inst.site, inst.t_s.min(), inst.t_s.max(), margin_s=15 * 3600.0)


def _check_moonlit(inst: Instrument, moon_el, path: str) -> None:
    """A moonlit session needs the Moon up and the Sun below astronomical twilight.

    Raises
    ------
    SunTooLowError
        With the Moon at or below the horizon at a sample.
    InstrumentDataError
        With the Sun above :data:`MOONLIT_SUN_LIMIT_DEG` at a sample.
    """
    from skysim.geometry import elevation_azimuth
    if moon_el.min() <= 0.0:
        i = int(np.argmin(moon_el))
        raise SunTooLowError(f"{path}: the Moon is at {moon_el[i]:.2f} deg at sample {i}: a Moon "
                             "below the horizon lights no sky; check the times and their UTC "
                             "offset, or drop those samples")
    sun_el, _ = elevation_azimuth(SunTrack(inst.site, inst.t_s.min(), inst.t_s.max(),
                                           margin_s=0.0)(inst.t_s))
    if sun_el.max() > MOONLIT_SUN_LIMIT_DEG:
        i = int(np.argmax(sun_el))
        raise InstrumentDataError(
            f"{path}: the Sun is at {sun_el[i]:.2f} deg at sample {i}, above "
            f"{MOONLIT_SUN_LIMIT_DEG:g} deg: twilight, not moonlight, lights that sky; "
            "diagnose it with the Sun as the light")


POINTING_LIMIT_DEG = 20.0
"""Largest calibrated pointing offset accepted [deg]: the fit's own bound on the offsets."""


def _checked_pointing(pointing, n_units: int) -> np.ndarray:
    p = np.asarray(pointing, float)
    if p.shape != (2 * n_units,):
        raise PointingCalibrationError(
            f"a calibrated pointing holds {2 * n_units} angles (elevation then azimuth offset "
            f"of each of the {n_units} units); got shape {p.shape}")
    bad = np.isinf(p) | (np.abs(p) > POINTING_LIMIT_DEG)
    if np.isnan(p).all():
        raise PointingCalibrationError("the calibrated pointing holds no unit (all NaN)")
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        kind = "elevation" if i < n_units else "azimuth"
        raise PointingCalibrationError(
            f"calibrated {kind} offset of unit {i % n_units} is {float(p[i])!r} deg: expected an "
            f"angle within +-{POINTING_LIMIT_DEG:g} deg (NaN: not calibrated, fitted)")
    return p
