"""A clock start whose first AoP fit has already lost is given up there
(calibration/photodiode_diagnosis/run.py ``_fit_effect``, ``START_GIVE_UP``;
calibration/photodiode_diagnosis/fit.py ``fit_pinned``'s ``give_up_above``).

References: the same fits with nothing given up (the result must be the same start's, to
the last bit: giving up skips fits, it changes none), and the generator's truth on a
simulated three-sweep ring recorded 2 h early, whose start at the true hour is fitted after
the start at the recorded times (which then has the higher cost) and must not be given up.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from ring_sessions import base_fit_and_effect, ring_session

from calibration.photodiode_diagnosis import run
from calibration.photodiode_diagnosis.dark_clock import CLOCK_TIE
from calibration.photodiode_diagnosis.fit import fit_pinned
from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes
from sensor.photodiodes_io import PhotodiodeData


def _clock_ring(hours_early: float):
    """A three-sweep ring stamped ``hours_early`` h early, its base fit and the clock's
    starts: ``(hours early, Forward, starts, sigma)``."""
    s0 = ring_session(n_sweeps=3, per_sweep=60)
    t = s0.table.copy()
    t["time"] = t["time"] - pd.Timedelta(hours=hours_early)
    inst = instrument_from_photodiodes(PhotodiodeData(t, s0.sidecar), "simulated ring")
    s, fe, e, _ = base_fit_and_effect(inst, "clock_offset")
    return hours_early, fe, run._start_effect(fe, s.theta, s.base, e, s.sigma), s.sigma


@pytest.fixture(scope="module")
def right_clock():
    return _clock_ring(0.0)


@pytest.fixture(scope="module")
def early_clock():
    return _clock_ring(2.0)


def _logged_fit(fe, starts, sigma, monkeypatch):
    """``_fit_effect``'s result and what each of its calls of ``_fit_start`` returned
    (``(start offset, pair or None)``)."""
    calls = []
    fit_start = run._fit_start

    def logged(*args):
        out = fit_start(*args)
        calls.append((float(args[1][fe.layout.effect][0]), out))
        return out
    monkeypatch.setattr(run, "_fit_start", logged)
    return run._fit_effect(fe, starts, sigma), calls


@pytest.mark.parametrize("ring", ["right_clock", "early_clock"])
def test_a_start_that_lost_is_given_up_and_the_fit_is_unchanged(ring, request, monkeypatch):
    """Every start after the first whose first AoP fit ends above ``START_GIVE_UP`` times
    the best before it is given up, and the chosen fit is the one with nothing given up
    (``START_GIVE_UP`` infinite), bit for bit. Recorded times right: both starts hours
    away are given up (their first AoP fit far above the start at 0 s); fitted to the end
    they lose, by more than a tie. Recorded 2 h early: the start at 0 s, fitted first, ends
    far above the noise and the start at the true 7,200 s is kept."""
    early, fe, starts, sigma = request.getfixturevalue(ring)
    chosen, calls = _logged_fit(fe, starts, sigma, monkeypatch)
    assert len(calls) == 3 and calls[0][0] == 0.0 and calls[0][1] is not None
    given_up = [dt for dt, out in calls if out is None]
    if early == 0.0:
        assert given_up == [calls[1][0], calls[2][0]], given_up
    else:
        assert 7200.0 not in given_up, given_up
    monkeypatch.setattr(run, "START_GIVE_UP", np.inf)
    full, every = _logged_fit(fe, starts, sigma, monkeypatch)
    assert all(out is not None for _, out in every)
    np.testing.assert_array_equal(chosen[0].theta, full[0].theta)
    assert chosen[1].cost == full[1].cost
    # a given-up start, fitted to the end, lost, and not by a tie (which would have sent
    # the choice to the smaller offset)
    best = full[1].cost
    ends = dict(every)
    assert all(ends[dt][1].cost > (1.0 + CLOCK_TIE) * best for dt in given_up)


def test_the_true_hour_fitted_after_the_recorded_times_wins(early_clock, monkeypatch):
    """Recorded 2 h early: the clock's fit, with starts given up, within 3 SE of the true
    7,200 s (a calibrated SE holds 99.7 % of Gaussian errors; from the hour's start alone
    ``tests/test_clock_nominal_start.py`` measured 7,199.999 +- 4.4 s)."""
    _, fe, starts, sigma = early_clock
    (_, aop), _ = _logged_fit(fe, starts, sigma, monkeypatch)
    value = float(aop.theta[fe.layout.effect][0])
    se = run._sandwich_sd(fe, aop, sigma)[0]
    assert abs(value - 7200.0) <= 3.0 * se, (value, se)


def test_fit_pinned_gives_up_after_the_aop_stage_only_above_the_bound(right_clock):
    """``give_up_above`` below stage 1's cost returns ``(None, stage 1)``, stage 1 the same
    fit as without it; above it, both stages as without it."""
    _, fe, starts, sigma = right_clock
    kw = dict(sigma=sigma, max_iter=run.EFFECT_MAX_ITER, geometry=True, covariance=True)
    full, aop = fit_pinned(fe, starts[1], **kw)
    none, aop_low = fit_pinned(fe, starts[1], give_up_above=0.5 * aop.cost, **kw)
    assert none is None
    np.testing.assert_array_equal(aop_low.theta, aop.theta)
    kept, aop_high = fit_pinned(fe, starts[1], give_up_above=2.0 * aop.cost, **kw)
    np.testing.assert_array_equal(kept.theta, full.theta)
    assert kept.cost == full.cost and aop_high.cost == aop.cost
