"""The diagnosis of a photodiode instrument: faults, base fit, held-out gap, where, which, how
far, returned as the shared :class:`calibration.diagnosis.report.DiagnosisReport` (method in
``docs/diagnosis.md``, section "Photodiode instruments").

The ring-specific pieces are here (the fault screen and base fit of a session, fitting the
base model and every candidate on one fold, the noise-only replicas of the floor, the clock
candidate's report and refinement, heading decoding, slices); the method that runs them
(folds, held-out scores, the paired judge, the verdict and the shrink) is every
instrument's, :mod:`calibration.diagnosis.judge`, with the ring's thresholds
:data:`RING_THRESHOLDS`. A clock hours off is searched before the diagnosis
(:mod:`.dark_clock`) and refined after the candidates' fits
(:func:`.clock.refine_clock_offset`): both shift the times and fit again, neither diagnoses
the session twice.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from sensor.photodiodes_io import PhotodiodeData, heading_error_deg
from skysim.exceptions import InvalidParameterError
from skysim.geometry import angle_between_deg, direction_vector, elevation_azimuth, wrap_deg
from skysim.sky import RayleighSky
from skysim.validation import TWILIGHT_LIMIT_DEG

from ..diagnosis import core, judge
from ..diagnosis.core import Thresholds
from ..diagnosis.errors import InsufficientDataError
from ..diagnosis.report import LEGACY_SCHEMA, Candidate, DiagnosisReport, Verdict
from .checks import GLARE_NEAR_DEG, motion_faults
from .clock import (CLOCK_REFINE_S, _clock_starts, clock_mirror, clock_report,
                    clock_sensitivity, far_clock, refine_clock_offset, solar_noon_s)
from .dark_clock import (CLOCK_START_MARGIN_DEG, CLOCK_TIE, NOMINAL_DOP_SCALE, clock_found,
                         search_clock)
from .effect_fit import (EFFECT_JOINT_ITER, EFFECT_MAX_ITER, _extend, _has_sky, _joint_aop,
                         _nominal_instrument)
from .effects import RING_EFFECT_NAMES, RingEffect, get_ring_effect
from .errors import InstrumentDataError, PointingCalibrationError, SunTooLowError
from .faults import bright_glare, malus_outliers, rotating_units, screen
from .fit import FIT_SAMPLES, fit, fit_headings, fit_pinned, geometry_mask, orient
from .fit import thin as _thin
from .forward import Forward, SunTrack
from .instrument import Instrument, instrument_from_photodiodes

__all__ = ["RING_THRESHOLDS", "diagnose_instrument", "diagnose_photodiodes", "orient",
           "decode_headings", "clock_mirror", "clock_sensitivity", "solar_noon_s"]

RING_THRESHOLDS = Thresholds(
    block_consistency=0.75, block_name="sweeps",
    # what the ring's identifiability matrix measured (docs/diagnosis.md, "ring"): the
    # aureole and the stray light both brighten the sky near the sun (with the stray light
    # withheld the aureole was named alone); a wide acceptance flattens the DoP as the
    # neutral-point sky does (an acceptance of HWHM 45 deg is their group, and with the
    # width withheld the neutral-point sky was named alone); the side glare holds the stray
    # light (as much light from either side): the stray light is named alone only over it,
    # and it only over what the stray light can be mistaken for
    confusable={"aureole": ("stray_light",),
                "stray_light": ("aureole", "side_glare"),
                "side_glare": ("stray_light", "aureole"),
                "fov": ("neutral_points",), "neutral_points": ("fov",)})
"""The ring's thresholds of the one verdict rule (:func:`calibration.diagnosis.core.decide`):
a candidate is named when it beats every other and the base by more than 2 paired SE on the
same held-out sweeps (applied as Student's t for the number of sweeps,
:func:`calibration.diagnosis.core.paired_margin`: 2.25 with twelve), converged away from its bounds, removes at least half the excess
held-out variance over the floor, and lowers the held-out gap in at least 75 % of the
held-out sweeps. A real sky is never reproduced to the noise floor by one effect (aerosols,
clouds, the instrument's own optics all add), so a smaller share is reported as
``partly_explained`` with the share rather than named; the sweep-by-sweep consistency keeps a
candidate that wins on a few sweeps only from being named. The pairs the ring's
identifiability matrix confused (the aureole and the stray light, the field of view and the
neutral-point sky) are named alone only when the other of the pair was tried and lost
(``confusable``)."""


def _fit_and_hold_out(fe: Forward, theta_base, base_train: Forward, effect, sigma, held_inst,
                      sun, sign, continued: bool = True):
    """One candidate on one fold: its fit on the training sweeps (:func:`_fit_effect` from
    :func:`_start_effect`; ``continued=False`` leaves it as :data:`EFFECT_MAX_ITER` stopped
    it, for :func:`_continue_and_hold_out` to take on) and its residuals on the held-out
    sweeps ``held_inst``; returns ``(fit, aop_fit, held-out Forward, held-out theta,
    residuals)``."""
    start = _start_effect(fe, theta_base, base_train, effect, sigma)
    fr, fr_aop = _fit_effect(fe, start, sigma)
    if continued:
        fr, fr_aop = _continued(fe, (fr, fr_aop), sigma, fe.aop_sky)
    effect_held = Forward(held_inst, effect, sun=sun, polarizer_sign=sign)
    theta_held, r_effect = _held_out(effect_held, fr.theta, fe.layout, sigma)
    return fr, fr_aop, effect_held, theta_held, r_effect


def _continue_and_hold_out(fe: Forward, pair, sigma, effect_held: Forward):
    """A fold's fit stopped by :data:`EFFECT_MAX_ITER` continued (:func:`_continued`) and its
    held-out residuals; returns ``(fit, aop_fit, held-out theta, residuals)``."""
    fr, fr_aop = _continued(fe, pair, sigma, fe.aop_sky)
    theta_held, r_effect = _held_out(effect_held, fr.theta, fe.layout, sigma)
    return fr, fr_aop, theta_held, r_effect


def _fit_effect(fe: Forward, starts, sigma):
    """Fit from each start (:func:`fit_pinned`: a geometric effect on the angle of
    polarization first); the lowest cost wins, judged on the stage that fixes the effect (the
    AoP fit for a geometric one). For the clock offset, ties (:data:`CLOCK_TIE`) go to the
    start nearest the effect's null (the smaller offset). A geometric effect's start whose
    first AoP fit ends above :data:`START_GIVE_UP` times the lowest AoP cost of the starts
    fitted before it is given up there (its later stages, the costly part, are skipped). A
    start whose model leaves its valid range is dropped; :class:`InvalidParameterError`
    when every start does. Returns ``(fit, aop_fit)``."""
    geometric = fe.effect.geometric
    starts = starts if isinstance(starts, list) else [starts]
    fits, failed = [], None
    L = fe.layout

    def cost(f):
        return (f[1] if geometric else f[0]).cost

    for s in starts:
        give_up = START_GIVE_UP * min(map(cost, fits)) if geometric and fits else np.inf
        try:
            pair = _fit_start(fe, s, sigma, give_up)
            if pair is not None and fe.aop_sky is not None and \
                    not far_clock(fe.effect, s[L.effect]) and \
                    far_clock(fe.effect, pair[0].theta[L.effect]):
                # a clock that walked far under a sky candidate's angle of polarization is
                # read again under single scattering from where it stopped
                pair = _fit_start(fe, pair[0].theta, sigma, give_up)
            if pair is not None:
                fits.append(pair)
        except InvalidParameterError as exc:
            # a start outside the model's valid range (the recorded clock putting the sun
            # below the twilight limit, while a start hours away holds): the others decide
            failed = exc
    if not fits:
        raise failed
    best = min(cost(f) for f in fits)
    if fe.effect.name != "clock_offset":
        chosen = min(fits, key=cost)
    else:
        close = [f for f in fits if cost(f) <= best * (1 + CLOCK_TIE)]
        chosen = min(close, key=lambda f: float(np.sum(np.abs(
            f[0].theta[L.effect] - np.asarray(fe.effect.null)))))
    return chosen


def _fit_start(fe: Forward, start, sigma, give_up_above: float = np.inf):
    """The fit from one start (:func:`fit_pinned`, then :func:`_joint_geometry` for an effect
    fitted with the pointing, or :func:`_pointing_under_effect` for one whose pointing is
    re-read under it); a clock start far from the recorded times
    (:func:`.clock.far_clock`) reads the angle of polarization under single scattering, not
    under ``fe.aop_sky``. Returns ``(fit, aop_fit)``, or None when the AoP stage's cost
    exceeds ``give_up_above`` (the later stages skipped)."""
    geometric = fe.effect.geometric
    offered = fe.aop_sky
    if far_clock(fe.effect, start[fe.layout.effect]):
        fe.aop_sky = None
    try:
        pair = fit_pinned(fe, start, sigma=sigma, max_iter=EFFECT_MAX_ITER,
                          geometry=geometric, covariance=geometric,
                          give_up_above=give_up_above)
        if pair[0] is None:
            return None
        stage = _POINTING_STAGES.get(fe.effect.pointing)
        if stage is not None:
            pair = stage(fe, pair, sigma)
    finally:
        fe.aop_sky = offered
    return pair


def _pointing_in_full_fit(fe: Forward, pair, sigma):
    """A sky effect's fit whose full-model stage held the units' pointing where its AoP
    stage read it (:func:`.fit.fit_pinned`), continued with the pointing free beside the
    effect in the full model, tied to the AoP stage's reading by
    :data:`POINTING_TURN_SD_DEG`; returns ``(fit, aop_fit)`` (the pair as it was when the
    continuation leaves the model's valid range or does not lower the cost).

    The AoP stage reads the effect and the pointing together, and the AoP alone leaves a
    common shift of the units' elevations poorly fixed where the effect changes the AoP
    only near a few points of the sky (the neutral points): on simulated rings of twelve
    sweeps (read noise 3 counts) its common elevation came out 0.02-0.05 deg off from
    draw to draw, and a neutral-point separation read with that pointing held moved 4.5
    times as much (20 deg: 19.81 to 20.22; held at the true pointing, 20.002 on every
    draw), while its SD (the pointing profiled in the full model, :func:`_effect_sd`) is
    0.022 deg: the SD of an estimate that reads the pointing in the full model, as this
    continuation does (19.97-20.03 deg for 20, 39.99-40.02 for 40). The tie keeps the
    pointing where the angle of polarization put it within a tenth of a degree, so a DoP
    profile the sky model lacks cannot pull it by degrees."""
    from .fit import Priors
    L = fe.layout
    fr, fr_aop = pair
    pri = Priors.for_model(fe, fr.theta)
    pri.mu[L.pointing] = fr.theta[L.pointing]
    pri.sd[L.pointing] = POINTING_TURN_SD_DEG
    try:
        full = fit(fe, fr.theta, np.ones(L.size, bool), priors=pri, sigma=sigma,
                   max_iter=EFFECT_CONTINUE_ITER)
    except InvalidParameterError:
        return pair
    if full.cost > fr.cost * (1 + 1e-9):
        return pair
    return full, fr_aop


def _joint_geometry(fe: Forward, pair, sigma):
    """A geometric fit that held the base model's pointing, redone with the pointing free
    beside the effect on the angle of polarization (the DoP profiled out), then the full
    model with that geometry held; returns ``(fit, aop_fit)``, the AoP fit with its
    covariance (the original pair when the joint fit does not lower the AoP cost, or leaves
    the model's valid range).

    The base fit, made without the effect, lets the units' pointing take up what it can of
    the effect's misfit: on a simulated ring of twelve sweeps over 12 min, a 900 s clock
    error became a +2.75 deg elevation of every unit, and the clock fitted with that
    pointing held came out at -7 +- 11 s; a 5 % gyro scale became azimuth offsets up to 12
    deg, and the factor 0.9517 for 0.95 (15 of its SE). Fitted together on the angle of
    polarization, the clock came out at 923 +- 16 s (z 1.4) and the factor at 0.95000: over
    a session of real length the angle of polarization tells a clock (the sun's elevation
    and azimuth moving through the session) and a gyro scale (a heading error growing along
    each turn) from constant pointing offsets. The joint covariance is the effect's SE with
    the pointing unknown."""
    fr, fr_aop = pair
    joint = _joint_aop(fe, fr_aop, sigma)
    if joint is fr_aop:
        return pair
    try:
        pair = fit(fe, joint.theta, ~geometry_mask(fe), sigma=sigma,
                   max_iter=EFFECT_MAX_ITER), joint
    except InvalidParameterError:
        return pair
    # then the pointing and the effect in turn (the pointing re-read with the effect held,
    # the effect with the pointing held): on three short sweeps the joint descent can stop
    # in a valley the alternation leaves (a 4 % gyro scale: residuals from 50 to 10 times
    # the noise); on twelve sweeps the joint fit reaches the noise and two turns that leave
    # the cost as it is end them (a turn may first raise the AoP cost: the full model's
    # stage moves the gains and angles the next turn's AoP fit starts from); the best kept
    best, last, cur = pair, None, pair
    for _ in range(ALTERNATION_PASSES):
        try:
            cur = fit_pinned(fe, cur[0].theta, sigma=sigma, max_iter=EFFECT_JOINT_ITER,
                             covariance=True)
        except InvalidParameterError:
            break
        if cur[1].cost < best[1].cost:
            best = cur
        if last is not None and abs(last - cur[1].cost) <= ALTERNATION_GAIN * cur[1].cost:
            break
        last = cur[1].cost
    return best


def _pointing_under_effect(fe: Forward, pair, sigma):
    """A one-parameter effect whose units' pointing is read from the angle of polarization
    under it, fitted by its profile cost (:func:`calibration.diagnosis.profile.profile_minimum`
    from ``pair``'s fitted value, :data:`PROFILE_STEP` and :data:`PROFILE_XTOL`): at each
    value, the pointing, polarizer angles, gains, offsets and headings read from the angle
    of polarization (the DoP profiled out, the effect held), then the full model with that
    pointing and the effect held (:func:`_under_effect`); the value of least full-model cost
    wins. Returns ``(fit, aop_fit)`` at that value (``fit`` not converged when the search
    ran out of evaluations or the fits there did not converge; ``pair`` when no value could
    be evaluated).

    The base model reads the pointing under a pencil beam; an acceptance the horizon cuts
    (:class:`.effects.FieldOfView`) moves the angle of polarization the way a higher
    elevation does, so that reading is off by what the width implies: every unit's
    elevation +0.02, +0.59 and +1.52 deg on simulated rings of twelve sweeps with an
    acceptance of HWHM 30, 40 and 45 deg. Read under the width, the AoP puts it within
    0.01 deg of the truth, and a hundredth of a degree of elevation moves the width by
    0.07 deg at 40 deg: the width and the pointing are read together. Fitted in turns
    (the pointing under the width, then the width under that pointing) they approach the
    solution by 6 % of the distance a turn at 40 deg (the width one turn reaches rises 0.94
    deg for every degree it starts higher), and the turns' own fixed point is not the
    solution either: it neglects what the pointing the width implies does to the full
    model's cost (it came out at 39.74 for 40 over six draws, at 44.0 for 45). The profile's
    minimum read 40.04 +- 0.04 and 45.07 +- 0.03 (mean and spread over six draws; 29.96 +-
    0.04 for 30), and 45.08 on the same ring with the generator's read noise off: what is
    left at 45 deg is the generator's and the candidate's quadratures of the cut acceptance,
    not the search.

    The pointing keeps the base model's prior except the azimuths, tied to the base
    model's reading by :data:`POINTING_TURN_SD_DEG`: an acceptance symmetric about a unit's
    axis leaves the azimuth the AoP reads (mirror symmetry about the vertical plane through
    the view; moved by under 0.001 deg at 45 deg), while the elevations move by what the
    width implies, 1.5 deg at 45 deg: tied to the base's reading within 0.1 deg they were
    held back the more the wider the width, and the profile's minimum fell at 44.6 for 45.
    """
    from ..diagnosis.profile import profile_minimum
    L = fe.layout
    j = L.effect.start
    fits = {}

    def cost(w):
        near = min(fits, key=lambda v: abs(v - w)) if fits else None
        try:
            fits[w] = _under_effect(fe, pair[0].theta[L.pointing],
                                    fits[near] if near is not None else (pair[0], None),
                                    w, sigma)
        except InvalidParameterError:
            return np.inf
        return fits[w][0].cost

    def newton(w):
        if w not in fits:
            return None
        try:
            return _profile_newton_step(fe, fits[w][0].theta, sigma)
        except InvalidParameterError:
            return None

    e = fe.effect
    try:
        found = profile_minimum(cost, float(pair[0].theta[j]), PROFILE_STEP, e.lower[0],
                                e.upper[0], PROFILE_XTOL, PROFILE_EVALUATIONS, newton)
    except InvalidParameterError:
        return pair
    full, aop = fits[found.x]
    return replace(full, converged=bool(found.converged and full.converged)), aop


def _under_effect(fe: Forward, base_pointing, near, value: float, sigma):
    """``(fit, aop_fit)`` with the effect held at ``value``: the AoP stage (pointing,
    polarizer angles, gains, offsets, headings; the DoP profiled out; the azimuths tied to
    ``base_pointing``'s by :data:`POINTING_TURN_SD_DEG`) from ``near``'s AoP fit (its full
    fit when it has none), then the full model with the pointing held, from ``near``'s full
    fit with the AoP stage's pointing, both to :data:`PROFILE_FIT_TOL`.

    Raises
    ------
    InvalidParameterError
        When either stage leaves the model's valid range.
    """
    from .fit import Priors
    L = fe.layout
    full0, aop0 = near
    t = (full0 if aop0 is None else aop0).theta.copy()
    t[L.effect] = value
    aop_free = np.ones(L.size, bool)
    aop_free[L.scale] = False
    aop_free[L.effect] = False
    pri = Priors.for_model(fe, t)
    az = np.arange(L.size)[L.pointing][L.n_units:]
    pri.mu[az] = np.asarray(base_pointing)[L.n_units:]
    pri.sd[az] = POINTING_TURN_SD_DEG
    fe.dop_free = True
    try:
        aop = fit(fe, t, aop_free, priors=pri, sigma=sigma, max_iter=EFFECT_CONTINUE_ITER,
                  tol=PROFILE_FIT_TOL)
    finally:
        fe.dop_free = False
    t = full0.theta.copy()
    t[L.pointing] = aop.theta[L.pointing]
    t[L.effect] = value
    held = ~geometry_mask(fe)
    held[L.effect] = False
    full = fit(fe, t, held, sigma=sigma, max_iter=EFFECT_CONTINUE_ITER, tol=PROFILE_FIT_TOL)
    return replace(full, converged=full.converged and aop.converged), aop


def _profile_newton_step(fe: Forward, theta, sigma) -> float | None:
    """Gauss-Newton step of a one-parameter effect along :func:`_pointing_under_effect`'s
    profile at a point of it (``theta``: the full model's fit there, the pointing the AoP
    stage's): ``-g / S``, ``g`` the derivative of the data's cost along the path
    (the effect's Jacobian column plus the pointing's times ``dp/de``,
    :func:`_along_pointing`) and ``S`` its Gauss-Newton curvature with the full model's other
    parameters profiled (the Schur complement). None where the curvature is not positive (an
    effect at its null, whose readings change with its square).

    Costs one Jacobian of each stage (about ten evaluations of the model), where a point of
    the profile costs 45-130."""
    L = fe.layout
    A1, G1, idx1, A2, G2, idx2, ptg = _stage_scores(fe, theta, sigma, True)
    _, _, _, A2, G2 = _along_pointing(A1, G1, idx1, A2, G2, idx2, ptg, L.effect)
    own = np.flatnonzero(~np.isin(idx2, ptg))
    k = int(np.flatnonzero(idx2[own] == L.effect.start)[0])
    inv_kk = np.linalg.pinv(A2[np.ix_(own, own)])[k, k]
    if not inv_kk > 0.0:
        return None
    return float(-inv_kk * G2[:, own[k]].sum())


PROFILE_STEP = 1.0
"""First step [deg] of :func:`_pointing_under_effect`'s search: about the distance from the
width read under the base model's pointing to the profile's minimum at 30-40 deg (3.2 deg at
40: the bracketing's steps grow by 1.6)."""
PROFILE_XTOL = 0.01
"""Accuracy [deg] of the profile's minimum: a fifth of the width's smallest SE measured on a
simulated ring of twelve sweeps (0.05 deg at 45 deg); an error spread evenly over +-0.01 deg
adds 1.3 % to that SE's square."""
PROFILE_EVALUATIONS = 16
"""Most values of the effect :func:`_pointing_under_effect` fits at (7-9 sufficed from
30-45 deg on simulated rings)."""
PROFILE_FIT_TOL = 1e-9
"""Relative cost change that ends each fit of the profile: a value :data:`PROFILE_XTOL` from
the minimum costs about 1.6e-7 more where the profile is flattest (curvature 44 on a cost
of 14,000 at 30 deg; 460 on 8,400 at 40). Measured on simulated rings against 1e-10: the
width within 0.0004 deg at 30, 40 and 45 deg, 10 % fewer model evaluations; at 1e-7 the
width at 30 deg moved by 0.027 deg (half its SE)."""
POINTING_TURN_SD_DEG = 0.1
"""Prior SD [deg] of a quantity the units' pointing is tied to the base model's reading by
when a sky effect is read: the azimuths under an acceptance (:func:`_pointing_under_effect`;
an acceptance symmetric about a unit's axis keeps the axis's angle of polarization azimuth
by mirror symmetry, tested in ``tests/test_fov_acceptance.py``), the whole pointing under a
neutral-point sky (:func:`_pointing_in_full_fit`). Shifts of degrees are the real sky's
angle of polarization that the model lacks (on a real session's folds, free in the full
model, the elevations moved by 2-5 deg and the width ran to its 60-deg bound)."""


_POINTING_STAGES = {"joint": _joint_geometry, "under_effect": _pointing_under_effect,
                    "full_fit": _pointing_in_full_fit}
"""The stage that reads the units' pointing with an effect, by its
:attr:`~.effects.RingEffect.pointing` (``"held"``: none)."""


START_GIVE_UP = 3.0
"""A geometric effect's start whose first AoP fit (:func:`.fit.fit_pinned`'s stage 1) ends
above this many times the lowest final AoP cost of the starts fitted before it is given up
(:func:`_fit_effect`; only the clock has several starts). What follows (the full model,
:func:`_joint_geometry`'s joint fit and turns) lowered a clock start's AoP cost by a factor
of 1.99 at most (measured: 1.01-1.02 on the real 16:01 session's folds; 1.5-1.99 on a
simulated twelve-sweep ring 2 h off, where a start 1,800 s from the best ended its first
AoP fit at 1.74 times the best and tied with it after every stage), so a start given up
would have needed three times that to come within :data:`CLOCK_TIE` of the best. On the
real session the starts 5.5-6 h away ended their first AoP fit at 3.9-4.6 times the best
before them (at 4,500 times on the simulated ring), after 0.6-0.9 s of the 4.3-5.3 s of
CPU their every stage took."""


ALTERNATION_PASSES = 4
"""Most turns of pointing and effect after :func:`_joint_geometry`'s joint fit."""
ALTERNATION_GAIN = 1e-3
"""A turn that lowers the AoP cost by less than this fraction is the last."""


EFFECT_CONTINUE_ITER = 150
"""Further iterations of the winning start's fit when :data:`EFFECT_MAX_ITER` stopped it: a
verdict names only a candidate whose fit converged, and the short descent that suffices to
rank the starts stops some fits on their way (an overcast's thickness along its shallow
valley with the gains: a simulated overcast of thickness 0.6 needed over 40 more; only fits
that did not converge pay for them, and outside the sky candidates only those of candidates
that can matter to the verdict, :func:`_continue_pending`)."""


def _continued(fe: Forward, pair, sigma, aop_sky):
    """The chosen start's ``(fit, aop_fit)``, continued from where it stopped when it did
    not converge (kept as it was when the continuation leaves the model's valid range); the
    angle of polarization read under ``aop_sky``, or under single scattering for a clock
    far from the recorded times (:func:`.clock.far_clock`), as :func:`_fit_effect` read it.

    The continuation holds the pointing where the fit's own stage put it (a geometric
    effect's joint AoP fit), or runs that stage again: the acceptance's profile search
    from where it stopped (a full-model fit with the pointing held would move the width
    off the profile's minimum), and for a sky with its own angle of polarization, whose
    AoP stage reads the pointing again (:func:`.fit.fit_pinned`), the pointing freed in the
    full model again (:func:`_pointing_in_full_fit`), or the continuation would report the
    separation with the pointing the AoP stage left, the estimate whose spread its SD does
    not describe."""
    fit_, aop = pair
    if fit_.converged:
        return pair
    geometric = fe.effect.geometric
    offered = fe.aop_sky
    fe.aop_sky = None if far_clock(fe.effect, fit_.theta[fe.layout.effect]) else aop_sky
    try:
        if fe.effect.pointing == "under_effect":
            more = _pointing_under_effect(fe, pair, sigma)
        else:
            more = fit_pinned(fe, fit_.theta, sigma=sigma,
                              max_iter=fe.effect.continue_iter or EFFECT_CONTINUE_ITER,
                              geometry=geometric, covariance=geometric)
    except InvalidParameterError:
        return pair
    finally:
        fe.aop_sky = offered
    if fe.effect.pointing == "full_fit":
        more = _pointing_in_full_fit(fe, more, sigma)
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


def _best_dop_scale(fwd: Forward, t, obs) -> tuple:
    """``(cost, t)`` with the DoP scale of ``t`` at the least squared residual of the
    readings under the sky sample ``obs`` (a bounded scalar search over (0, 1], to 1e-4):
    for effects with few starts (the aureole's six), where the grid of
    :func:`_with_dop_scales` would leave a start's cost off by the scale's step."""
    from scipy.optimize import minimize_scalar
    L = fwd.layout

    def at(sc):
        tt = t.copy()
        tt[L.scale] = sc
        return tt

    res = minimize_scalar(lambda sc: float(np.sum(fwd.residual(at(sc), obs) ** 2)),
                          bounds=(1e-3, 1.0), method="bounded", options={"xatol": 1e-4})
    return float(res.fun), at(float(res.x))


def _start_effect(fwd: Forward, theta_base, fwd_base, effect, sigma):
    """Best start of an effect: its coarse candidates scored with the headings carried (a
    list of starts for the clock offset, see :func:`_clock_starts`, and for effects with
    ``n_fits > 1``: the best starts at distinct centres, :func:`_distinct_centres`, taken in
    turn from the ranking under the base fit's instrument and, for an effect on the sky the
    base fit observed, from that under the nominal instrument at the best DoP scale of
    :data:`DOP_SCALE_STARTS`)."""
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
    # a geometric effect moves the views (headings, times, attitude): each start is seen anew
    resamples = effect.observes or own_sky or effect.geometric
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
            scored.extend(_with_dop_scales(fwd, t, also=_nominal(t, L)))
            continue
        o = effect.modify(obs0, p, sun) if obs0 is not None else fwd.observe(t)
        for tt in ((t, _carry_dop_scale(fwd, t, o, base_dop)) if own_sky else (t,)):
            scored.append((float(np.sum(fwd.residual(tt, o) ** 2)), tt))
        if getattr(effect, "nominal_starts", False):
            # the base fit's offsets, gains and DoP scale may have taken up much of the
            # effect (unpolarized light near the sun read as dark offsets of -0.2): each start
            # is scored on the nominal instrument too, each at its best DoP scale
            for tb in (t, _nominal(t, L)):
                scored.append(_best_dop_scale(fwd, tb, o))
    scored.sort(key=lambda x: x[0])
    n_fits = getattr(effect, "n_fits", 1)
    if n_fits == 1:
        return scored[0][1]
    if own_sky or effect.dop_scale_in_sky or resamples:
        return _distinct_centres([t for _, t in scored], L, n_fits)
    # the base fit's instrument took up part of the effect (a partly depolarizing sector:
    # dark offsets of a third of the median reading and the DoP scale at its bound), so the
    # starts are also scored under the nominal instrument with the best of a few DoP scales,
    # and the picks alternate between the two rankings
    nominal = []
    for p in starts:
        o = effect.modify(obs0, p, sun)
        t = _nominal(_extend(theta_base, fwd_base, fwd, p), L)
        nominal.append(min(_with_dop_scales(fwd, t, o), key=lambda x: x[0]))
    nominal.sort(key=lambda x: x[0])
    return _distinct_centres([t for pair in zip(scored, nominal) for _, t in pair], L, n_fits)


def _nominal(t, L) -> np.ndarray:
    """``t`` with the instrument's gains, dark offsets, photodiode and unit polarizer angles
    at their nominal 0 (:func:`.effect_fit._nominal_instrument`): a start that does not carry
    what the base fit, made without the effect, took up of it. The units' pointing stays
    the base fit's: read from the angle of polarization, it is near the truth under a sky
    effect, which changes the DoP far more than the AoP (the clock's starts, hours off,
    reset it too: there the sun the AoP was read against has moved,
    :func:`.clock._clock_starts`)."""
    return _nominal_instrument(t, L, (L.lam, L.off, L.angle, L.delta))


def _with_dop_scales(fwd: Forward, t, obs=None, also=None):
    """``(cost, theta)`` of ``t`` (and of ``also``, a start with the same geometry and
    effect: the nominal instrument) at each DoP scale of :data:`DOP_SCALE_STARTS`: the sky
    sample ``obs`` held, or (``None``) seen once at each scale, for an effect whose sky takes
    the scale (:attr:`~.effects.RingEffect.dop_scale_in_sky`). The grid, not
    :func:`_best_dop_scale`'s search, for effects with many starts (an occlusion's dozens:
    five residuals a start instead of some twenty)."""
    L = fwd.layout
    out = []
    for sc in DOP_SCALE_STARTS:
        at = []
        for start in (t,) if also is None else (t, also):
            tt = start.copy()
            tt[L.scale] = sc
            at.append(tt)
        seen = fwd.observe(at[0]) if obs is None else obs
        out.extend((float(np.sum(fwd.residual(tt, seen) ** 2)), tt) for tt in at)
    return out


def _distinct_centres(ranked, L, n_fits: int) -> list:
    """The first ``n_fits`` of the ``ranked`` starts whose first effect parameter (a sector
    centre [deg]) lies more than 45 deg from that of every start kept before."""
    picked = []
    for t in ranked:
        if all(abs(wrap_deg(t[L.effect][0] - q[L.effect][0])) > 45.0 for q in picked):
            picked.append(t)
        if len(picked) == n_fits:
            break
    return picked


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


def _grid_decode(fwd: Forward, theta, centre, offsets, lag=None, cycle=None) -> np.ndarray:
    """Headings ``centre + offsets[k]`` (n,) scored per sample, the best refined by a
    parabola through its neighbours; ``lag`` (n, U) shifts each unit's prediction to the
    heading of its conversion. ``cycle`` (n,) of int: the samples of each label share one
    heading, scored by the sum of their costs (``centre`` must be equal within a label)."""
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
    if cycle is not None:
        label = np.unique(cycle, return_inverse=True)[1].ravel()
        total = np.zeros((K, int(label.max()) + 1 if n else 0))
        np.add.at(total.T, label, cost.T)
        cost = total[:, label]
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

    With a rotating analyser (:attr:`Instrument.analyser_cycle`) a unit's photodiodes read
    one polarizer angle per sample, and the modulation that carries the angle of
    polarization is read over a half-turn of the analyser: the costs of a half-turn's
    samples are summed and the half-turn gets one heading (that of all its samples).
    """
    n = fwd.inst.n
    cycle = fwd.inst.analyser_cycle
    h = _grid_decode(fwd, theta, np.zeros(n), np.arange(0.0, 360.0, step_deg), cycle=cycle)
    conv = conversion_rows(fwd.inst)
    heading = fwd.headings(theta)
    lag = heading[:, None] - heading[conv]                      # (n, U) [deg]
    if np.any(lag):
        h = _grid_decode(fwd, theta, h, np.arange(-10.0, 10.0 + 1e-9, 2.5), lag, cycle)
    return np.where(fwd.usable.any(axis=1), h, np.nan)


def _slices(inst: Instrument, fwd: Forward, theta_ho, r, w, floor):
    """Held-out base residuals by slice (:func:`calibration.diagnosis.core.partition_slices`:
    each dimension partitions the readings, a slice's share is its part of the dimension's
    excess variance ``sum(r^2) - n floor^2``), sorted by share: by unit, photodiode, sweep,
    sky azimuth, sun distance, motion, motion crossed with the sun's distance
    (``motion_sun_distance``: rotating or standing, within or beyond
    :data:`.checks.GLARE_NEAR_DEG` of the sun; its slices carry that distance range as
    bounds) and, when it varies, sun elevation."""
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
    # motion crossed with the sun's distance: whether the moving samples' gap sits near the
    # sun (glare seen while turning) or everywhere (a lag, a read order)
    near = sun_dist < GLARE_NEAR_DEG
    crossed = [(m, n) for m in ("rotating", "standing") for n in (True, False)]
    dims.append(("motion_sun_distance",
                 [(inst.rotating if m == "rotating" else ~inst.rotating)[:, None]
                  & (near if n else ~near) for m, n in crossed],
                 [f"{m}, {'within' if n else 'beyond'} {GLARE_NEAR_DEG:g} deg of the sun"
                  for m, n in crossed],
                 [(0.0, GLARE_NEAR_DEG) if n else (GLARE_NEAR_DEG, 180.0) for _, n in crossed]))
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
    return core.sort_slices(out)


METRIC = ("held-out RMS of relative photodiode residuals (fraction of the unit's mean "
          "reading)")
"""What the ring's gap measures (:attr:`DiagnosisReport.metric`)."""


@dataclass
class _Session:
    """A session screened for faults and fitted by the base model (:func:`_fit_session`):
    what every fold's fits start from."""

    inst: Instrument
    work: Instrument
    """The session with the screen's exclusions flagged."""
    screen: object
    sun: SunTrack
    sign: float
    """Polarizer-angle sense (:func:`orient`)."""
    base: Forward
    """The base model on the samples thinned for fits."""
    layout: object
    theta: np.ndarray
    """The base fit (pointing pinned)."""
    sigma: float
    """White-noise RMS of its residuals: the weight of every fit."""
    max_iter: int


_FEWER = {1: "no unit", 2: "fewer than two units"}


def _units_needed(inst: Instrument, unit_ok=None) -> int:
    """Working units a session needs: one when a working unit's analyser turns (it sweeps
    every polarizer angle, and the sky's angle of polarization at one view fixes the heading
    modulo 180 deg), else two (fixed units each read one angle per photodiode; two views
    are what tell the sky's pattern from the instrument's polarizer offsets). ``unit_ok``
    (U,) bool: the working units (default: all)."""
    turning = rotating_units(inst)
    return 1 if turning[slice(None) if unit_ok is None else unit_ok].any() else 2


def _fit_session(inst: Instrument, sun: SunTrack, max_iter: int):
    """Screen the faults and fit the base model: ``(session, None)``, or ``(None, (screen,
    why))`` when fewer than two units read a usable sky."""
    scr = screen(inst)
    need = _units_needed(inst, scr.unit_ok)
    if scr.unit_ok.sum() < need:
        return None, (scr, f"{_FEWER[need]} keep{'s' if need == 1 else ''} enough working "
                           f"photodiodes ({len(scr.faults)} faults)")
    work = replace(inst, flagged=~scr.reading_ok)
    base = Forward(_thin(work), sun=sun)
    L = base.layout
    theta = np.zeros(L.size)
    theta[L.scale] = NOMINAL_DOP_SCALE
    sign, theta = orient(base, theta)
    # the screen (glare, Malus outliers) reads residuals of the plain fit, as it was tuned;
    # the base model proper is the pinned fit after it
    plain = fit(base, theta, sigma=0.02, max_iter=max_iter)
    full = Forward(work, sun=sun, polarizer_sign=sign)
    glare = bright_glare(inst, scr, full.residual(plain.theta), full.usable)
    if glare.bright is not None and glare.bright.any():
        work, base, plain, full = _refit(inst, glare, plain.theta, sun, sign, max_iter)
    scr = glare
    outliers = malus_outliers(inst, scr, full.residual(plain.theta), full.usable)
    if outliers is not scr:
        scr = outliers
        if scr.unit_ok.sum() < need:
            return None, (scr, f"{_FEWER[need]} follow{'s' if need == 1 else ''} Malus's law")
        work, base, plain, full = _refit(inst, scr, plain.theta, sun, sign, max_iter)
    start = plain.theta.copy()
    start[L.pointing] = 0.0     # the plain fit's pointing took up the DoP misfit
    pinned, _ = fit_pinned(base, start, sigma=0.02, max_iter=max_iter)
    sigma = max(core.noise_floor(full.residual(pinned.theta), full.usable, work.sweep)[0], 1e-4)
    return _Session(inst, work, scr, sun, sign, base, L, pinned.theta, sigma, max_iter), None


def _refit(inst: Instrument, scr, theta, sun, sign, max_iter):
    """The base fit again after the screen excluded more readings: ``(work, base, fit,
    full)`` (the instrument with its exclusions, the thinned and the full forward models)."""
    work = replace(inst, flagged=~scr.reading_ok)
    base = Forward(_thin(work), sun=sun, polarizer_sign=sign)
    first = fit(base, theta, sigma=0.02, max_iter=max_iter)
    return work, base, first, Forward(work, sun=sun, polarizer_sign=sign)


@dataclass
class _FoldState:
    """What the ring keeps of one fold fit (:attr:`.judge.FoldFit.state`)."""

    effect: RingEffect | None
    theta: np.ndarray
    """Parameters on the held-out sweeps (their headings refitted)."""
    headings: np.ndarray
    """Fitted heading of every held-out sample [deg]."""
    aop_sky: dict | None = None
    """The sky a geometric candidate's angle of polarization was read under."""
    resume: tuple | None = None
    """``(training Forward, (fit, aop_fit), held-out Forward)`` of a fit stopped by
    :data:`EFFECT_MAX_ITER`, to continue (:func:`_continue_stopped`)."""


def _cross_validate(s: _Session, cand, folds, unavailable: dict) -> judge.HeldOut:
    """Every fold's base fit and candidate fits (:func:`.judge.cross_validate`).

    A sky candidate's fit is continued within its fold: the best-fitting sky of the fold (by
    its continued cost) is the one the geometric candidates read the angle of polarization
    under; the others' stopped fits wait for the ranking (:func:`_continue_stopped`).

    Raises
    ------
    InsufficientDataError
        For a fold whose training sweeps hold fewer usable readings than the base fit has
        parameters.
    """
    work, sun, sign, sigma, L = s.work, s.sun, s.sign, s.sigma, s.layout

    def fit_fold(tr, ho, skip):
        train_inst, held_inst = _thin(work.subset(tr)), work.subset(ho)
        base_train = Forward(train_inst, sun=sun, polarizer_sign=sign)
        if base_train.usable.sum() < base_train.layout.size:
            full = Forward(work, sun=sun, polarizer_sign=sign)
            empty = [int(k) for k in range(work.n_sweeps)
                     if not full.usable[work.sweep == k].any()]
            raise InsufficientDataError(
                f"{work.source.get('path', 'photodiode data')}: held-out fold "
                f"{int(folds[ho[0]])}: its training sweeps hold {int(base_train.usable.sum())} "
                f"usable readings, fewer than the {base_train.layout.size} parameters of the base "
                f"fit; sweeps {empty} (0-based, in order of appearance) have no usable "
                "reading (all missing, zero or saturated): drop them from the file")
        start = np.r_[s.theta[:L.n_base], _sweep_headings(s.theta, L, work, tr, base_train)]
        base_fit, _ = fit_pinned(base_train, start, sigma=sigma, max_iter=s.max_iter)
        base_held = Forward(held_inst, sun=sun, polarizer_sign=sign)
        theta_ho, r = _held_out(base_held, base_fit.theta, base_train.layout, sigma)
        fits = {"base": judge.FoldFit(r, state=_FoldState(None, theta_ho,
                                                          base_held.headings(theta_ho)))}
        best_sky = None     # (training cost, sky, description) of the best sky candidate
        for e in sorted(cand, key=lambda c: c.geometric):   # sky candidates first
            if e.name in skip:
                continue
            fe = Forward(train_inst, e, sun=sun, polarizer_sign=sign)
            aop_sky = None
            if e.geometric and best_sky is not None:
                fe.aop_sky, aop_sky = best_sky[1], best_sky[2]
            out, why = core.run_candidate(_fit_and_hold_out, fe, base_fit.theta, base_train, e,
                                          sigma, held_inst, sun, sign, continued=_has_sky(e))
            if why is None:
                fr, fr_aop, effect_held, theta_held, r_effect = out
                why = core.non_finite_reason(np.where(base_held.usable, r_effect, np.nan),
                                             np.where(base_held.usable, r, np.nan))
            if why is None:
                # its SD is the candidate's too: a failure there is its own, not the run's
                sd, why = core.run_candidate(_effect_sd, fe, fr, fr_aop, sigma)
            if why is not None:
                fits[e.name] = why
                continue
            p = fr.theta[fe.layout.effect]
            if _has_sky(e) and (best_sky is None or fr.cost < best_sky[0]):
                best_sky = (fr.cost, e.sky(p, RayleighSky(1.0), fe.sun(fe.inst.t_s)),
                            {"effect": e.name, **dict(zip(e.parameter_names, map(float, p)))})
            stopped = not fr.converged and not _has_sky(e)   # a sky's was continued above
            fits[e.name] = judge.FoldFit(
                r_effect, p, bool(fr.converged), sd,
                _FoldState(e, theta_held, effect_held.headings(theta_held), aop_sky,
                           (fe, (fr, fr_aop), effect_held) if stopped else None))
        return base_held.usable, fits

    return judge.cross_validate(folds, [e.name for e in cand], work.readings.shape, fit_fold,
                          unavailable)


def _candidate_rows(s: _Session, held: judge.HeldOut, cand, floor: float, n_cal: int) -> list:
    """Each candidate's row: its held-out scores (:func:`.judge.score`), fold-mean
    parameters, parameters at a bound, and what a geometric or clock candidate reports
    beside (:func:`clock_report`); a clock report that fails makes the clock not
    applicable."""
    rows = []
    for e in cand:
        if e.name in held.unavailable:
            rows.append({"effect": e.name, "available": False,
                         "error": held.unavailable[e.name]})
            continue
        fits = held.fits[e.name]
        P = np.array([f.params for f in fits])
        row = judge.score(held, e.name, e.k, s.work.sweep, floor, n_cal)
        row["sweeps_improved"] = row["blocks_improved"]
        row["at_bound"] = core.at_bound(P, e.lower, e.upper, e.parameter_names, null=e.null)
        row["params"] = _fold_params(e, P, [f.sd for f in fits if f.sd is not None])
        if e.held_values:
            row["held"] = e.held_values
        rows.append(row)
        if e.geometric:
            row["fitted_on"] = ("angle of polarization (DoP profiled out) of the "
                                "best-fitting sky candidate of each fold, then held")
            if e.name == "clock_offset":
                row["fitted_on"] += (f"; a clock more than {CLOCK_REFINE_S:g} s from the "
                                     "recorded times under single scattering")
            row["aop_sky_by_fold"] = [f.state.aop_sky for f in fits
                                      if f.state.aop_sky is not None
                                      and not far_clock(e, f.params)]
        if e.name == "clock_offset":
            report, why = core.run_candidate(
                clock_report, s.work, e, s.theta, s.layout, s.sun, s.sign, s.sigma,
                row["params"]["clock_offset_s"], rows, cand)
            if why is not None:
                rows[-1] = {"effect": e.name, "available": False, "error": why}
                held.unavailable[e.name] = why
                continue
            row.update(report)
    return rows


def _diagnose_once(inst: Instrument, effects, *, n_folds: int, seed: int, max_iter: int,
                   refine_clock: bool) -> DiagnosisReport:
    """The diagnosis of a session at its times (:func:`diagnose_instrument` without the
    clock search): screen, base fit, folds, candidates, clock refinement, judge, report."""
    sun = light_track(inst)
    sun_el = elevation_azimuth(sun(inst.t_s))[0]
    _check_not_saturated(inst)
    folds = core.assign_folds(inst.sweep, n_folds)
    cand = [get_ring_effect(e) for e in effects]
    s, silent = _fit_session(inst, sun, max_iter)
    if silent is not None:
        return _no_signal_report(inst, *silent, seed)
    unavailable = {e.name: why for e in cand
                   if (why := e.available_at(sun_el) or e.applicable_to(s.work)) is not None}
    unavailable.update(_unreadable(s.work, cand, sun, unavailable))
    held = _cross_validate(s, cand, folds, unavailable)
    noise = _noise_floor(s, held, folds, seed)
    floor = noise.value
    n_cal = int(held.usable.sum() * (1 - 1 / np.unique(folds).size))
    _continue_stopped(held, cand, floor, n_cal, s.sigma)
    rows = _candidate_rows(s, held, cand, floor, n_cal)
    clock = next((r for r in rows if r["effect"] == "clock_offset"
                  and r.get("available", True)), None)
    # refined whether or not it is significant yet: under a clock hours off, the sky
    # candidates fitted at the recorded times scatter the clock (``by_sky``) so much that a
    # true 2 h came out as +58 +- 43 min
    if refine_clock and clock is not None and \
            abs(clock["params"]["clock_offset_s"]["value"]) > CLOCK_REFINE_S:
        refine_clock_offset(inst, clock, partial(_clock_pass, n_folds=n_folds,
                                                 max_iter=max_iter), sun)
    for e, row in zip(cand, rows):
        # a clock offset within twice its uncertainty is no finding, however it fits; nor
        # is an effect fitted at its null in every fold (its refit found a better optimum
        # of the instrument's own parameters, not the effect: an overcast of thickness 0 on
        # an open-sky session)
        if row.get("available", True):
            P = np.array([f.params for f in held.fits[e.name]])
            row["null_excluded"] = bool(row.get("significant", True) and not _at_null(e, P))
    names = ["base"] + held.available([e.name for e in cand])
    # the paired margin as Student's t for the sweeps the paired SEs are jackknifed over
    thresholds = RING_THRESHOLDS.for_blocks(np.unique(s.work.sweep).size)
    ranked, verdict = judge.verdict([Candidate.from_dict(r) for r in rows],
                                    {k: held.held(k) for k in names}, s.work.sweep, floor,
                                    thresholds, np.random.default_rng(seed),
                                    floor_note=noise.floor.note)
    return _report(s, held, ranked, verdict, noise, n_folds, sun_el, seed, thresholds)


UNREADABLE_SAMPLES = 64
"""Samples (evenly spread over the session) on which :func:`_unreadable` compares a
candidate's angle of polarization with the base sky's."""


def _unreadable(inst: Instrument, cand, sun: SunTrack, skip) -> dict:
    """``{name: "not applicable: <reason>"}`` of the candidates the readings cannot tell.

    A candidate that acts on the yaw alone (a yaw scale, which stretches the turn within a
    sweep) is not applicable when a probe of its parameters (5 % of the way from its null
    to its upper bound) leaves every recorded yaw as it is: no sweep turns.

    Normalised readings keep no degree of polarization (:meth:`Forward.held_by_readings`):
    their fit reads the angle of polarization alone. A candidate that changes the degree of
    polarization (or the radiance) the units see but not their angle of polarization (a
    depolarizing occluder, an aureole; on a zenith unit, the unit's view holding no azimuth
    sector, an occluder of the horizon too) leaves them unchanged: it is reported as not
    applicable instead of fitted. Which candidates do is read from the model itself, not
    from their names: each start's angle of polarization at every unit, on
    :data:`UNREADABLE_SAMPLES` samples, against the base sky's; a change below 1e-6 deg
    (round-off of the Stokes arithmetic is below 1e-9 deg) is none. Candidates with a sky of
    their own (they change the angle near the neutral points) and geometric or output-stage
    ones (they act on the headings, the times or the readings) are not tested."""
    out = {}
    for e in cand:
        if e.name in skip or not _acts_on_yaw_only(e):
            continue
        p = np.asarray(e.null, float)
        p = p + 0.05 * np.where(np.isfinite(e.upper), np.asarray(e.upper, float) - p, 1.0)
        if np.array_equal(e.yaw(inst, p), inst.yaw_deg):
            out[e.name] = (f"not applicable: {e.name} acts on the yaw turned within a sweep, "
                           "and no sweep turns (the recorded yaw is constant within each)")
    if inst.readings_kind != "normalised":
        return out
    rows = np.unique(np.linspace(0, inst.n - 1, min(UNREADABLE_SAMPLES, inst.n)).astype(int))
    sub = inst.subset(rows)
    base = None
    for e in cand:
        if e.name in skip or e.name in out or e.geometric or e.output_only or _has_sky(e):
            continue
        fe = Forward(sub, e, sun=sun)
        if base is None:
            t0 = np.zeros(fe.layout.size)
            t0[fe.layout.scale] = NOMINAL_DOP_SCALE
            base = Forward(sub, sun=sun).observe(t0[:fe.layout.n_base + fe.layout.n_heading])
        change = 0.0
        for p in e.starts(None):
            t = np.zeros(fe.layout.size)
            t[fe.layout.scale] = NOMINAL_DOP_SCALE
            t[fe.layout.effect] = p
            obs = fe.observe(t)
            d = np.mod(obs.aop_unit_deg - base.aop_unit_deg + 90.0, 180.0) - 90.0
            change = max(change, float(np.nanmax(np.abs(d))) if d.size else 0.0)
        if change < 1e-6:
            out[e.name] = ("not applicable: the readings are normalised (no degree of "
                           f"polarization survives them) and {e.name} changes the degree of "
                           "polarization the units see, not their angle of polarization "
                           f"(at most {change:.1g} deg over its starts)")
    return out


def _acts_on_yaw_only(effect) -> bool:
    """True for a candidate whose model changes the recorded yaw alone (neither the times,
    the attitude, the sky nor the readings)."""
    kind = type(effect)
    return (kind.yaw is not RingEffect.yaw and kind.time_shift_s is RingEffect.time_shift_s
            and kind.attitude is RingEffect.attitude and not _has_sky(effect)
            and kind.modify is RingEffect.modify and kind.observe is RingEffect.observe
            and kind.additive is RingEffect.additive
            and not effect.output_only)


def _report(s: _Session, held: judge.HeldOut, ranked, verdict: Verdict, noise: _Noise,
            n_folds: int, sun_el, seed: int, thresholds) -> DiagnosisReport:
    """The report: where the base model's held-out gap lies, the heading error of the base
    model and of a named effect, the base fit and the model-free checks."""
    floor = noise.value
    work, L = s.work, s.layout
    output = instrument_output(work)
    named = verdict.best_candidate is not None and verdict.effect == verdict.best_candidate
    ambiguity = work.heading_ambiguity_deg
    heading_error = {}
    for key in ("base", verdict.best_candidate if named else None):
        if key is None:
            continue
        errs = []
        for f, ho in zip(held.fits[key], held.rows[key]):
            fwd = Forward(output.subset(ho), f.state.effect, sun=s.sun, polarizer_sign=s.sign)
            errs.append(heading_error_deg(decode_headings(fwd, f.state.theta),
                                          fwd.headings(f.state.theta), ambiguity))
        e_all = np.concatenate(errs)
        e_all = e_all[np.isfinite(e_all)]
        heading_error[key] = float(np.sqrt(np.mean(e_all ** 2))) if e_all.size else None
    headings = np.full(work.n, np.nan)
    for f, ho in zip(held.fits["base"], held.rows["base"]):
        headings[ho] = f.state.headings
    theta_all = np.r_[s.theta[:L.n_base], np.zeros(L.n_heading)]
    theta_all[L.heading] = _assemble_headings(headings, work)
    where = _slices(work, Forward(work, sun=s.sun, polarizer_sign=s.sign), theta_all,
                    held.residual["base"], held.usable, floor)
    best = verdict.best_candidate
    data = dict(s.inst.source, readings_excluded=s.screen.counts, glare=s.screen.glare,
                sun_elevation_deg=[float(sun_el.min()), float(sun_el.max())],
                split={"folds": int(n_folds), "by": "whole sweeps, round-robin in time order",
                       "held_out_values": int(held.usable.sum())})
    extra = {"heading_error": {
                 "metric": "RMS over held-out samples of decoded minus fitted heading [deg], "
                           "decoded from the instrument's output (held readings at the "
                           "heading of their conversion)"
                           + ("" if work.absolute_yaw else
                              " (relative yaw: per-sweep offset fitted)")
                           + f", wrapped into +-{ambiguity / 2:g} deg",
                 "ambiguity_deg": ambiguity,
                 "ambiguity": AMBIGUITY_NOTE[ambiguity],
                 "base_deg": heading_error.get("base"),
                 "best_deg": heading_error.get(best) if best in heading_error else None},
             "base_fit": _base_fit_report(s.theta, L, s.base, work, s.sign),
             "instrument_checks": _instrument_checks(work, s.theta, L, s.base, s.sun),
             "noise_floor_parts": noise.parts()}
    # a unit the screen excluded is still checked for failing only in motion, on its
    # readings before the screen
    faults = list(s.screen.faults) + motion_faults(
        extra["instrument_checks"], _instrument_checks(s.inst, s.theta, L, s.base, s.sun),
        s.screen.faults)
    return DiagnosisReport("photodiodes", METRIC, "1", verdict, ranked, where, None,
                           noise.rms, noise.method, faults, data,
                           thresholds.to_dict(), seed, extra)


AMBIGUITY_NOTE = {
    180.0: "every unit looks at the zenith: a zenith-only compass knows its heading modulo "
           "180 deg (the sky's angle of polarization there is the same for a heading and its "
           "opposite), so a decoded heading 180 deg from the fitted one is no error",
    360.0: "the units' views off the zenith tell a heading from its opposite: errors over "
           "the full circle"}
"""What the heading error's wrap (:attr:`Instrument.heading_ambiguity_deg`) means, for the
report."""


def _no_signal_report(inst: Instrument, scr, why: str, seed: int) -> DiagnosisReport:
    """``unexplained`` with the reason, for a session whose units read no usable sky."""
    return DiagnosisReport(
        "photodiodes", METRIC, "1", Verdict("unexplained", why), faults=scr.faults,
        data=dict(inst.source, readings_excluded=scr.counts),
        thresholds=RING_THRESHOLDS.to_dict(), seed=seed)


def _clock_pass(inst: Instrument, *, n_folds: int, max_iter: int) -> dict | None:
    """The clock candidate's row on a session at its times (one pass of
    :func:`.clock.refine_clock_offset`): screen, base fit, the clock's fold fits and its
    report, as the diagnosis makes them; None when no unit reads a usable sky.

    Raises
    ------
    SunTooLowError, InstrumentDataError, InsufficientDataError
        As :func:`diagnose_instrument` at these times.
    """
    too_low = _too_low(inst, _sun_elevation(inst))
    if too_low is not None:
        raise too_low
    _check_not_saturated(inst)
    folds = core.assign_folds(inst.sweep, n_folds)
    clock = get_ring_effect("clock_offset")
    s, silent = _fit_session(inst, light_track(inst), max_iter)
    if silent is not None:
        return None
    held = _cross_validate(s, [clock], folds, {})
    # one candidate: its stopped fits are continued whatever the floor, and nothing read
    # from the pass depends on it, so the white-noise floor stands in for the replicas'
    white, _ = core.noise_floor(held.residual["base"], held.usable, s.work.sweep)
    n_cal = int(held.usable.sum() * (1 - 1 / np.unique(folds).size))
    _continue_stopped(held, [clock], white, n_cal, s.sigma)
    return _candidate_rows(s, held, [clock], white, n_cal)[0]


def diagnose_instrument(inst: Instrument, effects=RING_EFFECT_NAMES, *, n_folds: int = 3,
                        seed: int = 0, max_iter: int = 25, pointing=None,
                        refine_clock: bool = True) -> DiagnosisReport:
    """Diagnose a photodiode instrument (see module doc).

    A session whose recorded times put the sun below the twilight limit, or within
    :data:`.dark_clock.CLOCK_START_MARGIN_DEG` of it, while the clock candidate is asked
    for, has its clock searched first (:mod:`.dark_clock`): the times are shifted by the
    offset found and the session diagnosed once there.

    Parameters
    ----------
    inst : Instrument
    effects : sequence of str
        Candidates (:data:`.effects.RING_EFFECT_NAMES` by default).
    n_folds, seed, max_iter : int
    pointing : ndarray (2 U,), optional
        The units' calibrated pointing offsets [deg] (:func:`calibrated_pointing` of other
        sessions' reports), held in every fit (NaN: a unit not calibrated, fitted); None
        fits them all on this session (where a common elevation offset and a clock error
        trade one for the other, :mod:`.pointing`).
    refine_clock : bool
        Refine a clock offset found (:func:`.clock.refine_clock_offset`) and search the clock
        of a dark session.

    Returns
    -------
    DiagnosisReport
        Gaps as fractions of each unit's mean reading; heading error [deg], base fit and
        instrument checks in ``extra``.

    Raises
    ------
    PointingCalibrationError
        A ``pointing`` that is not 2 U angles within +-20 deg (or NaN).
    SunTooLowError
        With the sun below the twilight limit at a sample, unless the clock candidate is
        asked for and the units read a lit sky at a clock offset that puts the sun up.
    InstrumentDataError
        When every reading is saturated.
    InsufficientDataError
        For folds that do not fit the sweeps, or a fold whose training sweeps hold fewer
        usable readings than the base fit has parameters (the other sweeps have none).
    """
    if pointing is not None:
        inst = replace(inst, pointing_deg=_checked_pointing(pointing, inst.n_units))
    sun_el = _sun_elevation(inst)
    too_low = _too_low(inst, sun_el)
    search = refine_clock and "clock_offset" in effects and inst.light == "sun"
    if too_low is not None and not search:
        raise too_low
    options = dict(n_folds=n_folds, seed=seed, max_iter=max_iter, refine_clock=refine_clock)
    if search and sun_el.min() < TWILIGHT_LIMIT_DEG + CLOCK_START_MARGIN_DEG:
        # a lit sky stamped after dusk, or in deep twilight (where a fit from the recorded
        # times walks below the limit), is a clock hours off: searched first
        found = search_clock(inst, too_low)
        if found is not None:
            report = _diagnose_once(replace(inst, t_s=inst.t_s + found.offset_s), effects,
                                    **options)
            if report.verdict.gap_before is not None:
                return clock_found(report, found, sun_el)
        if too_low is not None:
            raise too_low
    return _diagnose_once(inst, effects, **options)


def _sun_elevation(inst: Instrument) -> np.ndarray:
    """Elevation [deg] of the body lighting the sky (:func:`light_track`) at every sample."""
    return elevation_azimuth(light_track(inst)(inst.t_s))[0]


def _too_low(inst: Instrument, sun_el) -> SunTooLowError | None:
    """The error of a session whose sun is below the twilight limit at a sample (None when
    it is not), ``sun_el`` its elevations [deg]; a moonlit session is checked for its Moon
    and Sun (:func:`_check_moonlit`).
    """
    path = inst.source.get("path", "photodiode data")
    if inst.light == "moon":
        _check_moonlit(inst, sun_el, path)
    if sun_el.min() >= TWILIGHT_LIMIT_DEG:
        return None
    i = int(np.argmin(sun_el))
    return SunTooLowError(
        f"{path}: the sun is at {sun_el[i]:.2f} deg at sample {i}, below the twilight limit "
        f"{TWILIGHT_LIMIT_DEG:g} deg: the sky is too dark for a polarization compass. "
        "Check the times and their UTC offset, or drop the night samples")


def _check_not_saturated(inst: Instrument) -> None:
    """Raise :class:`InstrumentDataError` when every reading is saturated."""
    finite = np.isfinite(inst.readings)
    if inst.source.get("saturation_value") is None:     # normalised readings: no rail
        return
    if finite.any() and np.all(inst.readings[finite] >= inst.source["saturation_value"]):
        raise InstrumentDataError(
            f"{inst.source.get('path', 'photodiode data')}: all {int(finite.sum())} readings "
            f"are at or above the saturation value {inst.source['saturation_value']:g}: "
            "shorten the exposure or lower the gain")


CONTINUE_TOP = 3
"""The best-ranked candidates (held-out score of their fits as :data:`EFFECT_MAX_ITER` left
them) whose stopped fits are always continued (:func:`_continue_stopped`)."""
CONTINUE_GAP_MARGIN = 0.10
"""A lower-ranked candidate's stopped fits are continued unless its held-out gap exceeds the
best-ranked candidate's by more than this fraction: three times the largest change of a
held-out gap by a continuation on a real ring session (a stray light's, 3.3 %)."""


def _effect_sd(fe: Forward, fr, fr_aop, sigma: float) -> list:
    """Posterior SD of each effect parameter: from the AoP fit of a geometric effect (which
    has its covariance), else from the full model's posterior covariance at the fit, the
    held pointing profiled (:func:`.fit.fit`, ``profiled``): the trade of an effect's
    parameters with the DoP scale, the gains and the offsets is in it (an overcast's
    thickness and the DoP scale correlate at 0.998 on a simulated ring). An effect with
    ``two_step_sd`` (the acceptance's width, the occlusion, the aureole, the stray light)
    takes the two-step sandwich over samples instead (:func:`_two_step_sd`)."""
    L = fe.layout
    if getattr(fe.effect, "two_step_sd", False):
        return _two_step_sd(fe, fr.theta, sigma)
    if fr_aop is None or fr_aop.covariance is None:
        held = geometry_mask(fe)
        fr_aop = fit(fe, fr.theta, ~held, sigma=sigma, max_iter=0, covariance=True,
                     profiled=held)
    elif fe.effect.pointing == "joint":
        return _sandwich_sd(fe, fr_aop, sigma)
    return [fr_aop.sd(i) for i in range(L.effect.start, L.effect.stop)]


def _sandwich_sd(fe: Forward, aop, sigma: float) -> list:
    """SD of the effect parameters of a joint AoP fit (:func:`_joint_geometry`) from the
    sandwich ``A^-1 B A^-1`` (Huber 1967; White 1980 [1]_), ``A`` the fit's information
    (data and prior) and ``B`` the sum over samples of the outer products of each sample's
    score (its readings' residuals times their Jacobian rows, over ``sigma^2``): a sample's
    readings share its heading and its profiled polarized radiance, so they are one cluster.

    The model covariance ``sigma^2 A^-1`` takes ``sigma``, the white-noise RMS of the full
    model's residuals; the angle of polarization's fit profiles a polarized radiance per
    sample out, so its residuals run at 0.2-0.4 of ``sigma`` and the model SD of a gyro
    scale came out 2.5 times its error's spread on simulated rings (z RMS 0.4); the
    sandwich reads the spread from the residuals themselves, and from the brighter readings
    that carry most of the information where the relative noise is lower.

    References
    ----------
    .. [1] H. White, "A heteroskedasticity-consistent covariance matrix estimator and a
       direct test for heteroskedasticity", Econometrica 48, 817-838 (1980).
    """
    from .fit import Priors, _jacobian, _not_calibrated
    L = fe.layout
    # the pointing is in the joint set whether this fit freed it or held it at the joint
    # fit's values (a continued fit): the effect's SD is with the pointing unknown
    free = np.asarray(aop.free, bool).copy()
    free[L.pointing] = True
    fe.dop_free = True
    try:
        free &= _not_calibrated(fe) & ~(fe.held_by_readings() | fe.absorbed_by_profile())
        obs = fe.observe(aop.theta)
        r = fe.residual(aop.theta, obs)
        usable_idx = np.flatnonzero(fe.usable.ravel())
        pri = Priors.for_model(fe, aop.theta)
        J = _jacobian(fe, aop.theta, r, obs, free, pri.step, usable_idx, pri.upper)
    finally:
        fe.dop_free = False
    fidx = np.flatnonzero(free)
    w = np.where(np.isfinite(pri.sd[fidx]), 1.0 / pri.sd[fidx] ** 2, 0.0)
    A = (J.T @ J).toarray() / sigma ** 2 + np.diag(w)
    Ainv = np.linalg.pinv(A)
    sample = usable_idx // fe.y.shape[1]
    rv = r.ravel()[usable_idx] / sigma ** 2
    out = []
    for i in range(L.effect.start, L.effect.stop):
        if not free[i]:
            out.append(None)
            continue
        a = Ainv[int(np.sum(free[:i]))]
        per_reading = (J @ a) * rv
        out.append(float(np.sqrt(np.sum(np.bincount(sample, weights=per_reading) ** 2))))
    return out


def _sample_scores(fe: Forward, theta, free, sigma: float, dop_free: bool):
    """Per-sample scores and information of a fit at ``theta`` over the parameters ``free``
    (those the fit can move: calibrated, unread and profiled ones dropped): returns ``(A,
    G, free)``, ``A`` the information (data and prior), ``G`` (samples, free) the sum over
    each sample's readings of their residuals times their Jacobian rows over ``sigma^2``
    (a sample's readings share its heading and its profiled radiance: one cluster)."""
    import scipy.sparse as sp

    from .fit import Priors, _jacobian, _not_calibrated
    free = np.asarray(free, bool) & _not_calibrated(fe) & ~(
        fe.held_by_readings() | fe.absorbed_by_profile())
    fe.dop_free = dop_free
    try:
        obs = fe.observe(theta)
        r = fe.residual(theta, obs)
        usable_idx = np.flatnonzero(fe.usable.ravel())
        pri = Priors.for_model(fe, theta)
        J = _jacobian(fe, theta, r, obs, free, pri.step, usable_idx, pri.upper)
    finally:
        fe.dop_free = False
    fidx = np.flatnonzero(free)
    w = np.where(np.isfinite(pri.sd[fidx]), 1.0 / pri.sd[fidx] ** 2, 0.0)
    A = (J.T @ J).toarray() / sigma ** 2 + np.diag(w)
    sample = usable_idx // fe.y.shape[1]
    scores = sp.csr_matrix((r.ravel()[usable_idx] / sigma ** 2,
                            (sample, np.arange(usable_idx.size))),
                           shape=(fe.y.shape[0], usable_idx.size)) @ J
    return A, np.asarray(scores.todense()), free


def _two_step_sd(fe: Forward, theta, sigma: float) -> list:
    """SD of the effect parameters of a fit whose units' pointing is read from the angle of
    polarization (the DoP profiled out, the effect held) and held in the full model's fit
    (:func:`.fit.fit_pinned`, :func:`_pointing_under_effect`; for an effect that leaves the
    angle of polarization as the base model has it, an aureole that lowers the DoP alone or
    unpolarized stray light, which the profiled radiance takes up where it reaches a unit's
    photodiodes alike, the base fit's reading is that of the effect's model): the sandwich
    of the two-step estimator (Newey & McFadden 1994, sect. 6 [1]_; Murphy & Topel 1985
    [2]_), clustered by sample.

    Each sample's influence on an effect parameter is its score in the full model times the
    row of the inverse information (the gains, offsets, polarizer angles, headings and DoP
    scale free beside the effect), plus the pointing's influence from the AoP fit carried
    through ``-A_ee^-1 A_ep``, how the full model's optimum moves with the held pointing. The
    spread comes from the residuals themselves: the fit weighs every reading's relative
    residual alike, while the read noise is a fixed number of counts, so bright readings
    carry most of the information at a lower relative noise and the model covariance
    ``sigma^2 A^-1`` (``sigma`` the white-noise RMS of all readings) is too wide (on
    simulated rings eight times for the acceptance's width, several times for an
    occlusion, 3-11 times for an aureole, about three times for stray light's strengths;
    over 40 noise draws of a short ring the aureole's and the stray light's errors spread
    0.7-1.05 times this SD). And the pointing's own error enters: at a ring's noise a
    hundredth of a degree of every unit's elevation moves an acceptance of HWHM 30 deg by
    0.7 deg. For an effect whose pointing is the AoP reading under it
    (:func:`_pointing_under_effect`, the acceptance's width) the full model's effect
    column moves the pointing with it (:func:`_along_pointing`): the estimator is the
    profile cost's minimum, whose score is the derivative along that path.

    References
    ----------
    .. [1] W. K. Newey, D. McFadden, "Large sample estimation and hypothesis testing", in
       Handbook of Econometrics IV, ch. 36, 2111-2245 (1994).
    .. [2] K. M. Murphy, R. H. Topel, "Estimation and inference in two-step econometric
       models", J. Business & Economic Statistics 3(4), 370-379 (1985).
    """
    L = fe.layout
    follows = fe.effect.pointing == "under_effect"
    var, own = _two_step_variance(*_stage_scores(fe, theta, sigma, follows),
                                  L.effect if follows else None)
    out = []
    for i in range(L.effect.start, L.effect.stop):
        k = np.flatnonzero(own == i)
        out.append(float(np.sqrt(var[k[0]])) if k.size else None)
    return out


def _stage_scores(fe: Forward, theta, sigma: float, effect_in_aop: bool):
    """Information and per-sample scores (:func:`_sample_scores`) of the two stages at
    ``theta``: the AoP stage (the DoP profiled out; the DoP scale held, the effect held
    unless ``effect_in_aop``) and the full model with the pointing among its parameters.
    Returns ``(A1, G1, idx1, A2, G2, idx2, ptg)``, ``idx`` the parameters of each and
    ``ptg`` the pointing's."""
    L = fe.layout
    aop_free = np.ones(L.size, bool)
    aop_free[L.scale] = False
    aop_free[L.effect] = effect_in_aop
    A1, G1, f1 = _sample_scores(fe, theta, aop_free, sigma, dop_free=True)
    full = ~geometry_mask(fe)
    full[L.pointing] = True
    A2, G2, f2 = _sample_scores(fe, theta, full, sigma, dop_free=False)
    return (A1, G1, np.flatnonzero(f1), A2, G2, np.flatnonzero(f2),
            np.arange(L.size)[L.pointing])


def _two_step_variance(A1, G1, idx1, A2, G2, idx2, ptg, follows: slice | None = None):
    """Variance of the full model's own free parameters under the two-step estimator of
    :func:`_two_step_sd`, from each stage's information ``A`` and per-sample scores ``G``
    (:func:`_sample_scores`) over the parameters ``idx1`` (the AoP stage) and ``idx2`` (the
    full model, the pointing ``ptg`` among them); with ``follows`` (the effect's slice, in
    both sets) the effect's pointing is the AoP reading under it (:func:`_along_pointing`).
    Returns ``(variance, parameter indices)`` of the full model's parameters other than the
    pointing."""
    if follows is not None:
        A1, G1, idx1, A2, G2 = _along_pointing(A1, G1, idx1, A2, G2, idx2, ptg, follows)
    p1 = np.flatnonzero(np.isin(idx1, ptg))          # pointing among the AoP fit's
    p2 = np.flatnonzero(np.isin(idx2, ptg))          # and among the full model's
    e2 = np.flatnonzero(~np.isin(idx2, ptg))         # the full model's own free set
    Aee_inv = np.linalg.pinv(A2[np.ix_(e2, e2)])
    infl = G2[:, e2] @ Aee_inv                        # (samples, own free) at held pointing
    if p1.size and p2.size:
        move = -Aee_inv @ A2[np.ix_(e2, p2)]          # d optimum / d pointing
        ptg_infl = G1 @ np.linalg.pinv(A1)[:, p1]     # pointing's influence in the AoP fit
        common = np.intersect1d(idx1[p1], idx2[p2])
        a = np.flatnonzero(np.isin(idx2[p2], common))
        b = np.flatnonzero(np.isin(idx1[p1], common))
        infl = infl + ptg_infl[:, b] @ move[:, a].T
    infl = infl - infl.mean(axis=0)       # the scores' mean off the optimum of either stage
    n = infl.shape[0]
    return np.sum(infl ** 2, axis=0) * n / max(n - 1, 1), idx2[e2]


def _along_pointing(A1, G1, idx1, A2, G2, idx2, ptg, effect: slice):
    """The two stages' information and per-sample scores for an effect whose pointing is
    the AoP reading under it (:func:`_pointing_under_effect`): the AoP stage's without the
    effect (the pointing's influence at a held effect), and the full model's with each
    effect column moved along the pointing the AoP reads under it,
    ``J_e + J_p dp/de``, ``dp/de = -A_pp^-1 A_pe`` from the AoP stage's information (the
    implicit function of its optimum). Returns ``(A1, G1, idx1, A2, G2)``."""
    eff = np.arange(effect.start, effect.stop)
    own = ~np.isin(idx1, eff)
    de = -np.linalg.pinv(A1[np.ix_(own, own)]) @ A1[np.ix_(own, ~own)]   # (own, effect)
    shared = np.flatnonzero(np.isin(idx1[own], ptg) & np.isin(idx1[own], idx2))
    T = np.eye(idx2.size)        # idx1, idx2 ascending (np.flatnonzero)
    T[np.ix_(np.searchsorted(idx2, idx1[own][shared]),
             np.searchsorted(idx2, idx1[~own]))] = de[shared]
    return (A1[np.ix_(own, own)], G1[:, own], idx1[own], T.T @ A2 @ T, G2 @ T)


def _continue_stopped(held: judge.HeldOut, cand, floor: float, n_cal: int, sigma: float) -> None:
    """Continue (:func:`_continued`) the stopped fold fits of the candidates that can matter
    to the verdict, replacing their fold fits in ``held``.

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
    live = [e for e in cand if e.name not in held.unavailable]
    stopped = {e.name: [i for i, f in enumerate(held.fits[e.name]) if f.state.resume]
               for e in live}
    if not any(stopped.values()):
        return
    g0 = core.rms(held.held("base"))
    n_ho = int(held.usable.sum())
    gap = {e.name: core.rms(held.held(e.name)) for e in live}
    rank_key = {e.name: (core.held_out_score(gap[e.name], g0, floor, n_ho, e.k, n_cal),
                         gap[e.name]) for e in live}
    ranked = sorted(live, key=lambda e: rank_key[e.name])
    best = ranked[0].name
    for pos, e in enumerate(ranked):
        if not stopped[e.name] or (pos >= CONTINUE_TOP and
                                   gap[e.name] > gap[best] * (1 + CONTINUE_GAP_MARGIN)):
            continue
        for i in stopped[e.name]:
            f, ho = held.fits[e.name][i], held.rows[e.name][i]
            fe, pair, effect_held = f.state.resume
            out, why = core.run_candidate(_continue_and_hold_out, fe, pair, sigma, effect_held)
            if why is None:
                fr, fr_aop, theta_held, r_effect = out
                why = core.non_finite_reason(
                    np.where(held.usable[ho], r_effect, np.nan),
                    np.where(held.usable[ho], held.residual["base"][ho], np.nan))
            if why is None:
                sd, why = core.run_candidate(_effect_sd, fe, fr, fr_aop, sigma)
            if why is not None:
                held.unavailable[e.name] = why
                break
            state = _FoldState(e, theta_held, effect_held.headings(theta_held), f.state.aop_sky)
            held.put(e.name, ho, judge.FoldFit(r_effect, fr.theta[fe.layout.effect],
                                               bool(fr.converged), sd, state), index=i)


NOISE_FLOOR_METHOD = ("the larger of the white-noise RMS (second differences along each "
                      "sweep) and the held-out gap of the base model on a noise-only replica "
                      "of the session (its fit plus white noise at that RMS, split and fitted "
                      "as the data)")

NOISE_FLOOR_STANDING = ("; the floor is the larger of that standing RMS and the held-out gap "
                        "of the base model on a noise-only replica of the session (its fit "
                        "plus white noise at that RMS, split and fitted as the data)")
"""Said after :data:`calibration.diagnosis.core.STANDING_METHOD` of a ring's floor."""


@dataclass(frozen=True)
class _Noise:
    """The ring's noise floor: the whiteness-checked estimate (:func:`.core.checked_floor`)
    and the replicas' held-out gap (None when the floor is unknown)."""

    floor: core.Floor
    replica: float | None

    @property
    def rms(self) -> float | None:
        if self.floor.rms is None:
            return None
        return max(self.floor.rms, self.replica)

    @property
    def value(self) -> float:
        """The floor the verdict measures against (0 when unknown: the whole gap)."""
        return 0.0 if self.rms is None else self.rms

    @property
    def method(self) -> str:
        if self.floor.rms is None or self.floor.standing_dof == 0:
            return self.floor.method
        return self.floor.method + NOISE_FLOOR_STANDING

    def parts(self) -> dict:
        return dict(self.floor.parts(), replica_held_out_gap=self.replica)


def standing_stretches(inst: Instrument) -> np.ndarray:
    """Standing stretch of every sample: one id per run of consecutive samples of one sweep
    that are not rotating (:attr:`Instrument.rotating`), -1 for rotating samples and for the
    first and last quarter of each run.

    The ends are left out because a filter or a lag of the record carries the turn into
    them: a 5-point moving average puts readings 8-16 deg of turn away into the two samples
    next to a turn, and the rotating flag itself is read over a 5-sample window. On a
    smoothed simulated ring with 30-sample stands the floor from whole runs came out 23 times
    the noise; the middle halves' standing RMS reads 0.92 of it.
    """
    standing = ~np.asarray(inst.rotating, bool)
    sweep = np.asarray(inst.sweep)
    new = standing & np.r_[True, ~standing[:-1] | (sweep[1:] != sweep[:-1])]
    run_id = np.where(standing, np.cumsum(new) - 1, -1)
    if not standing.any():
        return run_id
    idx = np.flatnonzero(standing)
    ids = run_id[idx]
    length = np.bincount(ids)
    first = np.r_[0, np.flatnonzero(np.diff(ids)) + 1]
    pos = np.arange(idx.size) - np.repeat(first, length[length > 0])
    quarter = length[ids] // 4
    keep = (pos >= quarter) & (pos < length[ids] - quarter)
    out = np.full(run_id.shape, -1)
    out[idx[keep]] = ids[keep]
    return out


def _noise_floor(s: _Session, held: judge.HeldOut, folds, seed: int) -> _Noise:
    """The session's noise floor from the base model's held-out residuals.

    Whiteness is tested on the held-out residuals of the model that fits best (the base or
    a candidate: :func:`.core.checked_floor`). Where they are white along each sweep,
    :data:`NOISE_FLOOR_METHOD`. Where they are not
    (smoothed or pre-filtered readings: their second differences read below the noise),
    the noise RMS from the scatter of the standing stretches' readings
    (:func:`standing_stretches`) in its place, with the replicas' gap on top; without
    standing readings the floor is unknown and the verdict measures against a zero floor.
    """
    models = ["base"] + held.available(list(held.fits))
    best = min(models, key=lambda k: core.rms(held.held(k)))
    floor = core.checked_floor(held.residual["base"], held.usable, s.work.sweep,
                               NOISE_FLOOR_METHOD, standing_stretches(s.work),
                               block_name="sweep", tested=held.residual[best])
    if floor.rms is None:
        return _Noise(floor, None)
    return _Noise(floor, _replica_gap(s, folds, floor.rms, seed))


def _replica_gap(s: _Session, folds, white: float, seed: int) -> float:
    """Held-out gap [relative] the base model reaches on a noise-only replica of the session.

    The replica's readings are the base model's full fit plus Gaussian white noise of RMS
    ``white`` (relative to each unit's mean reading, as the residuals); it is split, fitted
    and scored fold by fold as the data are. Its held-out gap is what a correct base model
    reaches held out on these sweeps: white noise plus the spread of parameters fitted on
    fewer sweeps (on three sweeps, training folds of two read a unit's pointing from the
    angle of polarization alone, which leaves it loose, and the held-out gap of noise-only
    sessions came out at 1.7-1.9 x the white noise). A gap within it is no evidence of an
    unmodelled effect.
    """
    work, theta, L, sun, sign = s.work, s.theta, s.layout, s.sun, s.sign
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
            base_train = Forward(_thin(rep.subset(tr)), sun=sun, polarizer_sign=sign)
            t0 = np.r_[theta[:L.n_base], _sweep_headings(theta, L, rep, tr, base_train)]
            train_fit, _ = fit_pinned(base_train, t0, sigma=s.sigma, max_iter=s.max_iter)
            base_held = Forward(rep.subset(ho), sun=sun, polarizer_sign=sign)
            _, r = _held_out(base_held, train_fit.theta, base_train.layout, s.sigma)
            res[k, ho] = np.where(base_held.usable, r, np.nan)
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
    """Mean over folds of each effect parameter, its spread over folds and its uncertainty:
    the SE of the fold mean (:func:`.judge.fold_mean_se`), the larger of the folds' posterior
    SD (:func:`_effect_sd`) scaled to a fit of every sweep and the folds' jackknife SE, each
    reported beside it."""
    out = {}
    for j, (n, un) in enumerate(zip(effect.parameter_names, effect.units)):
        out[n] = {"value": float(np.mean(P[:, j])), "fold_spread": float(np.std(P[:, j])),
                  "unit": un}
        sd = [f[j] for f in sds if f[j] is not None]
        if sd:
            se, model, jack = judge.fold_mean_se(P[:, j], sd)
            out[n].update(uncertainty=se, uncertainty_model=model,
                          uncertainty_jackknife=jack)
    return out


def _sweep_headings(theta, L, inst, rows, base_train):
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
    excluded (they were never fitted) and for those the readings cannot inform
    (:meth:`Forward.held_by_readings`, :meth:`Forward.absorbed_by_profile`: held, never
    fitted), with what the data cannot
    recover (``not_recoverable``, :attr:`Instrument.unrecoverable`) and the fitted
    parameters that ended at a bound of the fit (``at_bound``: a bound that binds is a
    parameter taking up a misfit of the model, not a measurement)."""
    pd_fitted = fwd.usable.any(axis=0)
    unit_fitted = np.zeros(L.n_units, bool)
    unit_fitted[inst.pd_unit[pd_fitted]] = True
    held = fwd.held_by_readings() | fwd.absorbed_by_profile()

    def per_unit(values):
        return {f"u{u}": float(d) if unit_fitted[u] else None for u, d in enumerate(values)}

    def per_pd(values, f=float, held_too=None):
        ok = pd_fitted if held_too is None else pd_fitted & ~held_too
        return {c: f(v) if k else None for c, v, k in zip(inst.columns, values, ok)}

    point = theta[L.pointing] + (0.0 if inst.pointing_deg is None
                                 else np.nan_to_num(inst.pointing_deg))
    el = point[:L.n_units]
    return {"pointing_held": inst.pointing_deg is not None,"polarizer_sense": "as unit frame" if sign > 0 else "opposite to unit frame",
            "dop_scale": None if held[L.scale] else float(theta[L.scale]),
            "polarizer_offset_deg": per_unit(theta[L.delta]),
            "polarizer_angle_deviation_deg": per_pd(theta[L.angle]),
            "elevation_offset_deg": per_unit(el),
            "elevation_offset_mean_deg": (float(np.mean(el[unit_fitted])) if unit_fitted.any()
                                          else None),
            "azimuth_offset_deg": per_unit(point[L.n_units:]),
            "gain": per_pd(theta[L.lam], lambda g: float(np.exp(g)), held[L.lam]),
            "offset": per_pd(theta[L.off], lambda o: float(o * fwd.level), held[L.off]),
            "heading_offset_deg": [float(h) for h in theta[L.heading]],
            "at_bound": _base_at_bound(theta, L, fwd, inst, held),
            "not_recoverable": [dict(u) for u in inst.unrecoverable]}


def _base_at_bound(theta, L, fwd, inst, held) -> list:
    """Names of the base fit's fitted parameters at a bound of :class:`.fit.Priors` (within
    1e-6 of the bound's magnitude, at least 1e-9): ``dop_scale``, ``offset:<column>``,
    ``polarizer_angle_deviation_deg:<column>``, ``elevation_offset_deg:u<k>``,
    ``azimuth_offset_deg:u<k>``."""
    from .fit import Priors
    pri = Priors.for_model(fwd, theta)
    tol = np.maximum(1e-6 * np.maximum(np.abs(pri.lower), np.abs(pri.upper)), 1e-9)
    tol = np.where(np.isfinite(tol), tol, 1e-9)
    at = (np.isfinite(pri.lower) & (theta <= pri.lower + tol)) | \
         (np.isfinite(pri.upper) & (theta >= pri.upper - tol))
    at &= ~held & _not_pinned(fwd, inst, L)
    names = np.empty(L.size, object)
    names[L.scale] = "dop_scale"
    names[L.off] = [f"offset:{c}" for c in inst.columns]
    names[L.angle] = [f"polarizer_angle_deviation_deg:{c}" for c in inst.columns]
    names[L.pointing] = ([f"elevation_offset_deg:u{u}" for u in range(L.n_units)]
                         + [f"azimuth_offset_deg:u{u}" for u in range(L.n_units)])
    return [str(names[i]) for i in np.flatnonzero(at) if names[i] is not None]


def _not_pinned(fwd, inst, L) -> np.ndarray:
    """(size,) bool: parameters the base fit was free to move (not a screened-out
    photodiode's or unit's, not calibrated pointing)."""
    m = np.ones(L.size, bool)
    pd_fitted = fwd.usable.any(axis=0)
    unit_fitted = np.zeros(L.n_units, bool)
    unit_fitted[inst.pd_unit[pd_fitted]] = True
    for sl in (L.lam, L.off, L.angle):
        m[sl] = pd_fitted
    m[L.pointing] = np.r_[unit_fitted, unit_fitted]
    if inst.pointing_deg is not None:
        m[np.arange(L.size)[L.pointing][np.isfinite(inst.pointing_deg)]] = False
    return m


def diagnose_photodiodes(data: PhotodiodeData, effects=RING_EFFECT_NAMES, *, n_folds: int = 3,
                         seed: int = 0, where: str = "photodiode data", pointing=None,
                         light: str = "sun") -> dict:
    """:func:`diagnose_instrument` of a photodiode file, as the ring's result dict
    (:func:`result_dict`); ``light="moon"`` for a session under the moonlit night sky.

    Raises
    ------
    InstrumentDataError
        For ``light`` other than "sun" or "moon".
    """
    if light not in LIGHTS:
        raise InstrumentDataError(f"{where}: light must be one of {', '.join(LIGHTS)}; "
                                  f"got {light!r}")
    inst = replace(instrument_from_photodiodes(data, where), light=light)
    return result_dict(diagnose_instrument(inst, effects, n_folds=n_folds, seed=seed,
                                           pointing=pointing))


def result_dict(report: DiagnosisReport) -> dict:
    """The ring's result dict of a report (:func:`diagnose_photodiodes`): the report's
    verdict, candidates and slices, with what the ring reports beside them at the top level
    (``heading_error``, ``base_fit``, ``instrument_checks``, ``dark_clock``), the noise floor
    with its parts (``noise_floor``: ``rms``, ``method``, ``white_noise_rms``,
    ``replica_held_out_gap``) and the split (``split``). Labelled ``skysim.diagnosis/1``:
    :meth:`DiagnosisReport.from_dict` reads it back."""
    d = report.to_dict()
    extra = d.pop("extra")
    parts = extra.pop("noise_floor_parts", {})
    verdict = dict(d["verdict"], metric=report.metric)
    dark = extra.get("dark_clock")
    if dark is not None and "at_corrected_times" in dark:
        verdict["at_corrected_times"] = dict(dark.pop("at_corrected_times"),
                                             metric=report.metric,
                                             noise_floor=report.noise_floor)
    data = d["data"]
    split = data.pop("split", None)
    if split is not None:
        split["held_out_readings"] = split.pop("held_out_values")
    floor = None if report.noise_floor is None and not report.noise_floor_method else {
        "rms": report.noise_floor, "method": report.noise_floor_method, **parts}
    return {"schema": LEGACY_SCHEMA, "instrument": report.instrument, "verdict": verdict,
            "thresholds": d["thresholds"], "candidates": d["candidates"], "where": d["where"],
            "faults": d["faults"], "noise_floor": floor,
            "heading_error": extra.pop("heading_error", None), **extra, "data": data,
            "split": split, "seed": report.seed}


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
