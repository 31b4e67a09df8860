"""The uncertainty of a geometric effect (the clock) with the held pointing profiled out.

The clock candidate is fitted on the angle of polarization with the units' pointing held
where the base model's AoP fit put it, since a common shift of the units' elevations and a
shift of the sun's trade one for the other when freed together. Its uncertainty must still
carry that trade: it is the marginal variance of the clock from the joint information of the
clock and the pointing (data and prior), which for a model linear near the solution is the
clock's variance in a fit with the pointing free as well (the Schur complement of the joint
information; Pawitan 2001, sect. 3.4).
"""

from dataclasses import replace

import numpy as np
import pytest
from ring_sessions import ring_session

from calibration.photodiode_diagnosis import instrument_from_photodiodes
from calibration.photodiode_diagnosis.effects import get_ring_effect
from calibration.photodiode_diagnosis.fit import fit
from calibration.photodiode_diagnosis.forward import Forward
from calibration.photodiode_diagnosis.run import orient

SIGMA = 0.01
"""Noise level of the fits: above the simulated readings' own (counts' rounding and shot
noise, ~1e-3 relative), so the reduced chi-square stays below 1 and no covariance is
rescaled by it; the identities below then hold for the information matrices alone."""


def _aop_solution(start):
    """A simulated ring session (3 turns, relative yaw), the clock candidate's forward model,
    and the AoP fit (DoP profiled out) with the clock and the pointing free together."""
    inst = instrument_from_photodiodes(ring_session(start=start))
    base = Forward(inst)
    th = np.zeros(base.layout.size)
    th[base.layout.scale] = 0.6
    sign, th = orient(base, th)
    fwd = Forward(inst, get_ring_effect("clock_offset"), polarizer_sign=sign)
    L = fwd.layout
    t = np.zeros(L.size)
    t[:base.layout.size] = th
    free = np.ones(L.size, bool)
    free[L.scale] = False
    fwd.dop_free = True
    joint = fit(fwd, t, free, sigma=SIGMA, max_iter=25, covariance=True)
    return fwd, joint, free


@pytest.fixture(scope="module", params=["2022-05-12T13:40:00+02:00",
                                        "2022-05-12T09:00:00+02:00"],
                ids=["near_culmination", "morning"])
def solution(request):
    return _aop_solution(request.param)


def _held(fwd, joint, free, profiled=None):
    """The clock's fit with the pointing held at the joint solution (as the candidate does),
    its covariance with ``profiled`` parameters profiled out."""
    L = fwd.layout
    held = free.copy()
    held[L.pointing] = False
    return fit(fwd, joint.theta, held, sigma=SIGMA, max_iter=3, covariance=True,
               profiled=profiled)


def test_profiled_clock_sd_is_that_of_the_joint_fit(solution):
    """Profiling the pointing out of the held fit gives the clock the posterior SD it has
    when fitted together with the pointing, within 1 % (the held fit may take a step of its
    own from the joint solution, which moves the Jacobian by a negligible amount), while the
    held fit alone reports a smaller SD: what it leaves out is the trade with the pointing."""
    fwd, joint, free = solution
    L = fwd.layout
    i = L.effect.start
    pointing = np.zeros(L.size, bool)
    pointing[L.pointing] = True
    assert joint.converged
    sd_joint = joint.sd(i)
    sd_held = _held(fwd, joint, free).sd(i)
    sd_prof = _held(fwd, joint, free, profiled=pointing).sd(i)
    assert sd_prof == pytest.approx(sd_joint, rel=0.01)
    assert sd_held < sd_prof


def test_profiling_a_parameter_that_is_fitted_changes_nothing(solution):
    """A parameter both free and profiled is simply fitted: the covariance is that of the
    plain fit, to rounding."""
    fwd, joint, free = solution
    i = fwd.layout.effect.start
    a = _held(fwd, joint, free)
    b = _held(fwd, joint, free, profiled=np.where(free, True, False) & ~_pointing(fwd))
    assert b.sd(i) == pytest.approx(a.sd(i), rel=1e-12)


def _pointing(fwd):
    m = np.zeros(fwd.layout.size, bool)
    m[fwd.layout.pointing] = True
    return m


def test_calibrated_pointing_is_not_profiled(solution):
    """Pointing calibrated on other sessions (:attr:`Instrument.pointing_deg`) is held as
    known: profiling it is a no-op, the clock's SD is the held fit's."""
    fwd, joint, free = solution
    L = fwd.layout
    cal = Forward(replace(fwd.inst, pointing_deg=joint.theta[L.pointing].copy()), fwd.effect,
                  sun=fwd.sun, polarizer_sign=fwd.polarizer_sign)
    cal.dop_free = True
    i = L.effect.start
    a = _held(cal, joint, free)
    b = _held(cal, joint, free, profiled=_pointing(cal))
    assert b.sd(i) == pytest.approx(a.sd(i), rel=1e-12)
