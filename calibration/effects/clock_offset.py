"""Wrong timestamps: a clock offset or a timezone error of the recorded times.

The true time of every sample is ``t_true = t_recorded + dt``: a logger clock that drifted
by minutes, or a timezone mistake of whole hours (local time written as UTC, a missing
daylight-saving hour). The sun is then taken at the wrong place: its azimuth error shifts
``phi`` (absorbed by the common mounting term only while the azimuth rate is constant) and its
elevation error changes the DoP, so the effect shows as a drift of the residual over the
day. ``dt = 0`` is the base model.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from . import Effect

__all__ = ["EFFECT", "ClockOffset"]


class ClockOffset(Effect):
    """Constant clock offset ``dt`` [s] (true minus recorded)."""

    name = "clock_offset"
    parameter_names = ("clock_offset_s",)
    units = ("s",)
    bounds = np.array([[-14 * 3600.0, 14 * 3600.0]])
    prior_mean = np.array([0.0])
    prior_sd = np.array([3 * 3600.0])
    fd_step = np.array([5.0])
    stage = "geometry"
    null = np.zeros(1)
    generation_range: ClassVar[dict] = {"clock_offset_s": "half the draws a timezone error of +-3600 s, "
                                          "half a clock error of +-U(120, 1800) s"}

    def starts(self):
        return [np.array([x]) for x in (-3600.0, 0.0, 3600.0)]

    COARSE_S: ClassVar[np.ndarray] = np.arange(-28, 29) * 1800.0
    """Whole and half hours within +-14 h (timezone and daylight-saving errors)."""

    def coarse_starts(self, ctx, base):
        """Full parameter vectors for every offset of :attr:`COARSE_S`, the sun's azimuth change
        carried into the common mounting term (``phi = h - sun_az``: adding the change to all
        six mounting errors keeps the sensed angle), so that a timezone error of hours is
        found before a local refinement (a fit started at 0 stops in a local minimum)."""
        t_mid = float(np.mean(ctx.t_s))
        _, az0 = ctx.sun.elevation_azimuth(np.array([t_mid]))
        out = []
        for dt in self.COARSE_S:
            el, az = ctx.sun.elevation_azimuth(np.array([t_mid + dt]))
            if el[0] <= 1.0:
                continue
            b = np.array(base, float).copy()
            b[:6] += float(((az[0] - az0[0]) + 180.0) % 360.0 - 180.0)
            out.append(np.r_[b, dt])
        return out

    def draw(self, rng):
        sign = rng.choice([-1.0, 1.0])
        if rng.random() < 0.5:
            return np.array([sign * 3600.0])
        return np.array([sign * rng.uniform(120.0, 1800.0)])

    def time_shift_s(self, ctx, p):
        return float(p[0])


EFFECT = ClockOffset()
