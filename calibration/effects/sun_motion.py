"""Sun motion during a sweep that the recorded times do not show (a static-sun reference).

Instruments without a per-sample clock stamp every sample of a sweep with the sweep's start
time, so a model that takes the sun at the recorded time holds the sun still while it moves
by ~0.25 deg per minute in azimuth near sunset. The effect restores the true time of each
sample from its position in the sweep (row order, :attr:`Context.frac`, 0 at the first and 1 at
the last row, with stops evenly spaced in time)::

    t_true = t_recorded + frac * T

with ``T`` [s] the sweep duration. ``T = 0`` is the base model. The sun itself comes from
the ephemeris (pysolar, :mod:`skysim.sun`), so only ``T`` is fitted.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from . import Effect

__all__ = ["EFFECT", "SunMotion"]


class SunMotion(Effect):
    """Unrecorded sweep duration ``T`` [s]."""

    name = "sun_motion"
    parameter_names = ("sweep_duration_s",)
    units = ("s",)
    bounds = np.array([[0.0, 7200.0]])
    prior_mean = np.array([0.0])
    prior_sd = np.array([3600.0])
    fd_step = np.array([2.0])
    stage = "geometry"
    null = np.zeros(1)
    generation_range: ClassVar[dict] = {"sweep_duration_s": "U(300, 1200); every recorded time = sweep start"}

    def starts(self):
        return [np.array([60.0]), np.array([900.0])]

    def draw(self, rng):
        return np.array([rng.uniform(300.0, 1200.0)])

    def time_shift_s(self, ctx, p):
        return ctx.frac * float(p[0])


EFFECT = SunMotion()
