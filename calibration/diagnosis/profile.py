"""The minimum of a costly function of one parameter on an interval: a profile cost, each of
whose values is a fit of every other parameter.

Optional Newton steps the caller supplies (a Gauss-Newton step along the profile, from
the fit at an evaluated point) while they lower the cost; then, or without them, downhill
bracketing from a start with steps growing by the golden ratio, then successive
parabolic interpolation through the best point and its two nearest evaluated neighbours,
with a golden-section step where the parabola does not help and steps of at least the
tolerance (Brent 1973, ch. 5 [1]_). Every value is kept: the profile's fits are warm-started
from the nearest evaluated point, and no point is evaluated twice. A minimum at a bound of
the interval is returned at the bound itself (a candidate's null at its bound stays
reachable exactly).

References
----------
.. [1] R. P. Brent, *Algorithms for Minimization without Derivatives*, Prentice-Hall (1973),
   ch. 5 (a one-dimensional minimizer combining golden section and parabolic interpolation).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from skysim.exceptions import InvalidParameterError

__all__ = ["ProfileMinimum", "profile_minimum"]

GOLDEN = 0.5 * (3.0 - np.sqrt(5.0))
"""Golden-section fraction (0.382): the step into the larger part of a bracket."""
GROW = 0.5 * (1.0 + np.sqrt(5.0))
"""Growth of the downhill steps while bracketing (the golden ratio, 1.618)."""


@dataclass(frozen=True)
class ProfileMinimum:
    """The minimum found by :func:`profile_minimum`.

    Attributes
    ----------
    x : float
        The best evaluated point.
    value : float
        The function there.
    points : dict
        Every evaluated point and its value.
    converged : bool
        True when the best point's nearest evaluated neighbours (or the bound it sits on)
        lie within ``xtol`` of it; False when ``max_eval`` ended the search first.
    """

    x: float
    value: float
    points: dict
    converged: bool


def profile_minimum(cost: Callable[[float], float], x0: float, step: float, lower: float,
                    upper: float, xtol: float, max_eval: int = 16,
                    newton: Callable[[float], float | None] | None = None) -> ProfileMinimum:
    """Minimum of ``cost`` on ``[lower, upper]`` from ``x0`` (module docstring).

    Parameters
    ----------
    cost : callable
        ``cost(x) -> float``; ``inf`` where the model cannot be evaluated (the search turns
        away from it).
    x0 : float
        Start, clipped into the interval.
    step : float
        First step of the bracketing, > 0 (in the parameter's unit).
    lower, upper : float
        The interval, ``lower < upper``.
    xtol : float
        Accuracy of the minimum's position, > 0: the search stops when the best point's
        evaluated neighbours on both sides are this close (its error is then below
        ``xtol`` for a unimodal function).
    max_eval : int
        Most evaluations of ``cost``.
    newton : callable, optional
        ``newton(x) -> step`` at an evaluated point (None where it has none): the search
        first takes these steps while each lowers the cost by more than ``xtol``'s move,
        then brackets and refines from the best point, with half a step that did not
        lower the cost or two tolerances along one that came within the tolerance. The
        minimum is the cost's own: a Newton step is only as good as its model's slope (a
        Gauss-Newton step of the acceptance's width stopped 0.03 deg from the minimum of
        its profile at 45 deg). From 10 deg away the steps reach the minimum's
        neighbourhood in three or four evaluations where the bracketing takes five or six.

    Returns
    -------
    ProfileMinimum

    Raises
    ------
    InvalidParameterError
        For a non-positive ``step`` or ``xtol``, ``lower >= upper``, ``max_eval < 3``, or
        when ``cost`` is infinite at every point tried (the model valid nowhere there).
    """
    if not (step > 0.0 and xtol > 0.0 and lower < upper and max_eval >= 3):
        raise InvalidParameterError(
            f"profile_minimum needs step > 0, xtol > 0, lower < upper and max_eval >= 3; got "
            f"step={step!r}, xtol={xtol!r}, lower={lower!r}, upper={upper!r}, "
            f"max_eval={max_eval!r}")
    seen: dict = {}

    def f(x):
        x = float(min(max(x, lower), upper))
        if x not in seen:
            seen[x] = float(cost(x))
        return x

    a = f(x0)
    if newton is not None:
        a, tried = _newton_descent(f, seen, newton, a, xtol, max_eval)
        # the bracketing takes on from the best point: with half the step that overshot, or
        # two tolerances along a step that came within one (a Newton step only as good as
        # its model's slope: the minimum is then checked on the cost itself)
        if tried:
            step = 0.5 * tried if abs(tried) > xtol else 2.0 * xtol * np.sign(tried)
    b = f(a + step)
    if b == a:
        b = f(a - step)
    if seen[b] > seen[a]:
        a, b = b, a
    while len(seen) < max_eval:        # downhill from a through b until it rises or binds
        c = f(b + GROW * (b - a))
        if c == b or seen[c] > seen[b]:
            break
        a, b = b, c
    while len(seen) < max_eval:
        u = _next_point(seen, lower, upper, xtol)
        if u is None:
            return _result(seen, True)
        f(u)
    return _result(seen, _next_point(seen, lower, upper, xtol) is None)


def _newton_descent(f, seen: dict, newton, x: float, xtol: float, max_eval: int):
    """Newton steps ``newton(x)`` from ``x`` while each lowers the cost by moving the best
    point more than ``xtol``: returns ``(best x, the last step proposed)`` (0 when
    ``newton`` gave none or the evaluations ran out)."""
    while len(seen) < max_eval:
        s = newton(x)
        if s is None or not np.isfinite(s):
            return x, 0.0
        u = f(x + s)
        if abs(u - x) <= xtol or not seen[u] < seen[x]:
            return x, u - x
        x = u
    return x, 0.0


def _result(seen: dict, converged: bool) -> ProfileMinimum:
    best = min(seen, key=seen.get)
    if not np.isfinite(seen[best]):
        raise InvalidParameterError("profile_minimum: the cost is infinite at every point "
                                    f"tried ({sorted(seen)})")
    return ProfileMinimum(best, seen[best], dict(seen), converged)


def _next_point(seen: dict, lower: float, upper: float, xtol: float):
    """The next point to evaluate around the best one, or None when its neighbours (or a
    bound it sits on) are within ``xtol``."""
    xs = np.array(sorted(seen))
    fs = np.array([seen[x] for x in xs])
    i = int(np.argmin(fs))
    x = xs[i]
    left = xs[i - 1] if i > 0 else (x if x == lower else None)
    right = xs[i + 1] if i + 1 < xs.size else (x if x == upper else None)
    if left is None or right is None:
        # not yet bracketed on one side (the bracketing ran out of steps): step outwards
        return x - GROW * max(x - xs[0], xtol) if left is None else \
            x + GROW * max(xs[-1] - x, xtol)
    near = xtol * (1.0 + 1e-6)          # a neighbour placed at x +- xtol, up to rounding
    if x - left <= near and right - x <= near:
        return None
    # the parabola through the best point and its two nearest neighbours
    j = np.sort(np.argsort(np.abs(xs - x), kind="stable")[:3])
    u = _vertex(xs[j], fs[j])
    wide_left = x - left >= right - x
    if u is None or not (left < u < right) or not np.isfinite(fs[j]).all():
        u = x - GOLDEN * (x - left) if wide_left else x + GOLDEN * (right - x)
    if abs(u - x) < xtol:
        # a step of the tolerance, towards the parabola's side unless that neighbour is
        # already within it: each such step brings a neighbour within the tolerance
        far_left, far_right = x - left > near, right - x > near
        u = (x + xtol if u >= x else x - xtol) if far_left and far_right else \
            (x - xtol if far_left else x + xtol)
    if u in seen or not (left < u < right):
        u = x - 0.5 * (x - left) if wide_left else x + 0.5 * (right - x)
    return float(u)


def _vertex(x, y):
    """Abscissa of the vertex of the parabola through three points, None when it is not
    convex (or the points are not distinct)."""
    (x1, x2, x3), (y1, y2, y3) = x, y
    den = (x2 - x1) * (y2 - y3) - (x2 - x3) * (y2 - y1)
    num = (x2 - x1) ** 2 * (y2 - y3) - (x2 - x3) ** 2 * (y2 - y1)
    curv = ((y3 - y2) / (x3 - x2) - (y2 - y1) / (x2 - x1)) / (x3 - x1) if \
        len({x1, x2, x3}) == 3 else 0.0
    if den == 0.0 or not curv > 0.0:
        return None
    return float(x2 - 0.5 * num / den)
