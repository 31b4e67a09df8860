"""Periodic turntable reading error: once- and twice-per-revolution terms.

An eccentric or tilted encoder disc (once per revolution) and an elliptical bearing or gear
(twice per revolution) make the recorded turntable angle differ from the true one by a
Fourier series in the angle itself. For a disc of radius ``r`` mounted with eccentricity ``e``
and read by one head, plane geometry gives the error ``(e / r) sin(h - h0)`` to first order in
``e / r``; an elliptical gear or bearing adds the ``2h`` term::

    h_true = h_rec + c1 cos h_rec + s1 sin h_rec + c2 cos 2h_rec + s2 sin 2h_rec    [deg]

A constant offset between the turntable zero and north only rotates the phases, so the
recorded heading serves as the turntable angle. All four coefficients zero is the base model.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from . import Effect

__all__ = ["EFFECT", "TurntablePeriodic"]


class TurntablePeriodic(Effect):
    """Fourier coefficients [deg] of the turntable reading error."""

    name = "turntable_periodic"
    parameter_names = ("c1_deg", "s1_deg", "c2_deg", "s2_deg")
    units = ("deg",) * 4
    bounds = np.tile([-5.0, 5.0], (4, 1))
    prior_mean = np.zeros(4)
    prior_sd = np.full(4, 1.0)
    fd_step = np.full(4, 1e-3)
    stage = "geometry"
    null = np.zeros(4)
    generation_range: ClassVar[dict] = {"A1_deg": "U(0.03, 0.3), phase U(0, 360)",
                        "A2_deg": "U(0.03, 0.3), phase U(0, 360)"}

    def draw(self, rng):
        a = rng.uniform(0.03, 0.3, 2)
        ph = rng.uniform(0.0, 2 * np.pi, 2)
        return np.array([a[0] * np.cos(ph[0]), a[0] * np.sin(ph[0]),
                         a[1] * np.cos(ph[1]), a[1] * np.sin(ph[1])])

    def heading_shift_deg(self, ctx, p):
        h = np.radians(ctx.heading_deg)
        c1, s1, c2, s2 = np.asarray(p, float)
        return c1 * np.cos(h) + s1 * np.sin(h) + c2 * np.cos(2 * h) + s2 * np.sin(2 * h)


EFFECT = TurntablePeriodic()
