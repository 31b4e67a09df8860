"""The one-parameter minimizer of a profile cost (calibration/diagnosis/profile.py) against
functions whose minimum is known in closed form.

Tolerance: the search stops when the best point's evaluated neighbours lie within ``xtol``
of it, so for a unimodal function the true minimum lies between them: within ``xtol`` of the
returned point. A parabola's minimum is its interpolation's vertex, found exactly (to
rounding) once bracketed.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.diagnosis.profile import profile_minimum
from skysim.exceptions import InvalidParameterError

XTOL = 0.005


def _counted(fn):
    calls = []

    def cost(x):
        calls.append(x)
        return float(fn(x))
    return cost, calls


@pytest.mark.parametrize("x0", [36.8, 39.95, 44.0, 2.0])
def test_a_parabola_is_found_at_its_vertex(x0):
    """The profile of the acceptance's width near 40 deg is a parabola of curvature ~460:
    bracketed, the interpolation lands on the vertex, and two steps of ``xtol`` beside it
    end the search; no point is evaluated twice."""
    cost, calls = _counted(lambda x: 230.0 * (x - 39.95) ** 2 + 8423.0)
    r = profile_minimum(cost, x0, 1.0, 0.0, 60.0, XTOL)
    assert r.converged
    assert abs(r.x - 39.95) <= 1e-9
    assert r.value == pytest.approx(8423.0)
    assert len(calls) == len(set(calls)) == len(r.points)
    assert len(calls) <= 16


def test_an_asymmetric_minimum_is_found_within_the_tolerance():
    """Steeper on one side (three times the curvature above the minimum, as the width's
    profile at 45 deg with the elevations tied): the parabolas through unequal sides miss
    the minimum, the steps of ``xtol`` beside the best point close on it."""
    m = 45.07
    cost, _ = _counted(lambda x: np.where(x < m, 400.0, 1200.0) * (x - m) ** 2)
    r = profile_minimum(cost, 44.0, 1.0, 0.0, 60.0, XTOL)
    assert r.converged and abs(r.x - m) <= XTOL


@pytest.mark.parametrize("fn", [lambda x: x ** 2 + 3.0 * x, lambda x: x ** 4],
                         ids=["rising", "flat"])
def test_a_minimum_at_the_lower_bound_is_returned_at_the_bound(fn):
    """A cost rising from the bound (a candidate whose null is its bound, on data without
    it), steeply or as flat as ``x^4`` (a width enters the readings as its square): the
    bound itself is returned, not a point ``xtol`` inside it."""
    cost, _ = _counted(fn)
    r = profile_minimum(cost, 8.0, 1.0, 0.0, 60.0, XTOL)
    assert r.converged and r.x == 0.0


def test_a_minimum_at_the_upper_bound_is_returned_at_the_bound():
    cost, _ = _counted(lambda x: -x)
    r = profile_minimum(cost, 50.0, 1.0, 0.0, 60.0, XTOL)
    assert r.converged and r.x == 60.0


def test_a_quartic_minimum_inside_is_found_within_the_tolerance():
    """A flat minimum (``(x - 5)^4 + 0.1 (x - 5)^2``): the parabolas converge slowly; the
    neighbours' rule still puts it within ``xtol``."""
    cost, _ = _counted(lambda x: (x - 5.0) ** 4 + 0.1 * (x - 5.0) ** 2)
    r = profile_minimum(cost, 8.0, 1.0, 0.0, 60.0, XTOL)
    assert r.converged and abs(r.x - 5.0) <= XTOL


def test_points_where_the_model_fails_are_avoided():
    """An infinite cost (the model outside its valid range) above 42: the search turns
    back and finds the minimum at 39.95 below it."""
    cost, _ = _counted(lambda x: np.inf if x > 42.0 else (x - 39.95) ** 2)
    r = profile_minimum(cost, 41.5, 1.0, 0.0, 60.0, XTOL)
    assert r.converged and abs(r.x - 39.95) <= XTOL


def test_running_out_of_evaluations_is_reported():
    cost, calls = _counted(lambda x: (x - 30.0) ** 2)
    r = profile_minimum(cost, 0.0, 0.1, 0.0, 60.0, XTOL, max_eval=4)
    assert not r.converged and len(calls) == 4


@pytest.mark.parametrize("kw, word", [({"step": 0.0}, "step"), ({"xtol": -1.0}, "xtol"),
                                      ({"lower": 60.0}, "lower"), ({"max_eval": 2}, "max_eval")])
def test_bad_settings_are_named(kw, word):
    args = dict(step=1.0, lower=0.0, upper=60.0, xtol=XTOL, max_eval=16)
    args.update(kw)
    with pytest.raises(InvalidParameterError, match=word):
        profile_minimum(lambda x: x * x, 1.0, **args)


def test_a_cost_infinite_everywhere_is_named():
    with pytest.raises(InvalidParameterError, match="infinite at every point"):
        profile_minimum(lambda x: np.inf, 1.0, 1.0, 0.0, 60.0, XTOL)


def test_newton_steps_reach_a_parabola_in_few_evaluations():
    """Exact Newton steps on a parabola, from 10 deg away: one step lands on the vertex, the
    next is null, and the bracketing around it (two tolerances out, then the neighbours'
    rule) confirms it: at most 7 evaluations, where the bracketing alone takes more."""
    f = lambda x: 500.0 * (x - 45.07) ** 2
    cost, calls = _counted(f)
    r = profile_minimum(cost, 35.0, 1.0, 0.0, 60.0, XTOL, newton=lambda x: 45.07 - x)
    assert r.converged and abs(r.x - 45.07) <= XTOL
    assert len(calls) <= 7
    plain, plain_calls = _counted(f)
    profile_minimum(plain, 35.0, 1.0, 0.0, 60.0, XTOL)
    assert len(plain_calls) > len(calls)


@pytest.mark.parametrize("bias", [0.03, -0.03, 3.0])
def test_a_biased_newton_step_still_ends_at_the_cost_minimum(bias):
    """Newton steps aimed ``bias`` off the minimum (a slope from a model that is not quite
    the cost's: 0.03 deg at 45 deg for the acceptance's width, three tolerances; or an
    overshoot of 3 deg): the minimum returned is the cost's, within ``xtol``."""
    m = 45.07
    cost, _ = _counted(lambda x: 500.0 * (x - m) ** 2)
    r = profile_minimum(cost, 35.0, 1.0, 0.0, 60.0, XTOL, newton=lambda x: m + bias - x)
    assert r.converged and abs(r.x - m) <= XTOL


def test_no_newton_step_falls_back_to_the_bracketing():
    """``newton`` returning None (no positive curvature, an effect at its null): the
    bracketing alone finds the minimum at the bound."""
    cost, _ = _counted(lambda x: x ** 4)
    r = profile_minimum(cost, 8.0, 1.0, 0.0, 60.0, XTOL, newton=lambda x: None)
    assert r.converged and r.x == 0.0
