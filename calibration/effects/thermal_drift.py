"""Gain and offset of the log-ratio amplifiers drifting with temperature.

A translinear log-ratio amplifier computes ``V = (k T / q) ln(I_1 / I_2)`` [1]_: its scale is
proportional to absolute temperature (+0.33 %/K at 300 K when uncompensated, ~0.01-0.05 %/K
with on-chip compensation), and input offset currents and bias drift add an output offset that
changes with temperature. With ``x`` the temperature excursion::

    U_i = g (1 + k_g x) [ log10(ratio_i) + f_i ] + k_v,i x

``x = T - 25 degC`` from the recorded ``temperature_C`` column; without it the time since the
first sample [h] stands in for the temperature (a linear drift over the session), and the
coefficients are then per hour. ``k_g = k_v = 0`` is the base model.

References
----------
.. [1] B. Gilbert, "Translinear circuits: a proposed classification", Electronics Letters
   11(1):14-16 (1975); the ``kT/q`` scale of bipolar log amplifiers.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from . import Context, Effect

__all__ = ["EFFECT", "T_REF_C", "ThermalDrift", "drift_variable"]

T_REF_C = 25.0
"""Reference temperature [degC] of the drift coefficients."""


def drift_variable(ctx: Context) -> np.ndarray:
    """Temperature excursion [K] (or hours since the first sample without temperatures)."""
    if ctx.temperature_C is not None:
        return ctx.temperature_C - T_REF_C
    return (ctx.t_s - ctx.t_ref_s) / 3600.0


class ThermalDrift(Effect):
    """Gain coefficient ``k_g`` [1/K] and offset coefficients ``k_v,1..3`` [mV/K]."""

    name = "thermal_drift"
    parameter_names = ("k_gain_per_K", "k_offset1_mV_per_K", "k_offset2_mV_per_K",
                       "k_offset3_mV_per_K")
    units = ("1/K", "mV/K", "mV/K", "mV/K")
    bounds = np.array([[-0.02, 0.02]] + [[-5.0, 5.0]] * 3)
    prior_mean = np.zeros(4)
    prior_sd = np.array([0.005, 1.0, 1.0, 1.0])
    fd_step = np.array([1e-5, 1e-3, 1e-3, 1e-3])
    null = np.zeros(4)
    generation_range: ClassVar[dict] = {"k_gain_per_K": "+-U(3e-4, 3.3e-3)",
                        "k_offset_mV_per_K": "U(-0.2, 0.2) per channel"}

    def draw(self, rng):
        kg = rng.choice([-1.0, 1.0]) * rng.uniform(3e-4, 3.3e-3)
        return np.r_[kg, rng.uniform(-0.2, 0.2, 3)]

    def channel_terms(self, ctx, p):
        x = drift_variable(ctx)[:, None]
        p = np.asarray(p, float)
        return {"gain_factor": 1.0 + p[0] * x, "offset_V": 1e-3 * p[1:4] * x}


    def output_jacobian(self, ctx, p, parts):
        # dU/dk_g = g x log_ratio; dU/dk_v,i = 1e-3 x on channel i only
        x = drift_variable(ctx)[:, None]
        J = np.zeros(parts["A"].shape + (4,))
        J[:, :, 0] = parts["gain"] * x * parts["log_ratio"]
        ch = np.arange(3)
        J[:, ch, 1 + ch] = 1e-3 * x
        return J


EFFECT = ThermalDrift()
