"""Finite extinction ratio of the polarizers.

A real polarizer passes ``T_max`` of the light polarized along its axis and ``T_min`` across
it; for partially polarized light of DoP ``d`` and angle ``x`` to the axis its transmission is
``(T_max + T_min)/2 * (1 + eta d cos 2x)`` with the polarizing efficiency
``eta = (T_max - T_min) / (T_max + T_min) = (1 - eps) / (1 + eps)``, ``eps = T_min / T_max``
the extinction ratio (Malus's law for a partial polarizer, Born & Wolf [1]_ sec. 1.4.2;
implemented in :func:`sensor.photodiode.extinction_factors`; the intensity factor
``k = 1 + eps`` only moves the transmittance term ``f``). Each photodiode ``k`` of the
sensor gets its own ``eps_k``, so the opponent ratio is
``(1 + eta_1 d cos 2x_1) / (1 - eta_2 d cos 2x_2)``; ``eps = 0`` (``eta = 1``) is eq. (2) of
Yang et al. (2014). A common ``eta`` only rescales ``d`` (degenerate with ``d_max``): the
prior fixes that direction, the data see the differences between photodiodes.

References
----------
.. [1] M. Born, E. Wolf, *Principles of Optics*, 7th ed., Cambridge University Press (1999).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from sensor.photodiode import extinction_factors

from . import Effect

__all__ = ["EFFECT", "ExtinctionRatio"]


class ExtinctionRatio(Effect):
    """Extinction ratios ``eps_1..6`` of the six polarizers (paper's photodiode order)."""

    name = "extinction_ratio"
    parameter_names = tuple(f"eps_{k}" for k in range(1, 7))
    units = ("1",) * 6
    bounds = np.tile([0.0, 0.5], (6, 1))
    prior_mean = np.full(6, 0.01)
    prior_sd = np.full(6, 0.05)
    fd_step = np.full(6, 1e-4)
    null = np.zeros(6)
    generation_range: ClassVar[dict] = {"eps_k": "log-uniform [1e-3, 0.1] per polarizer (film polarizers "
                                 "1:1000 to 1:10 over the visible)"}

    def draw(self, rng):
        return np.exp(rng.uniform(np.log(1e-3), np.log(0.1), 6))

    def channel_terms(self, ctx, p):
        return {"extinction": extinction_factors(np.clip(np.asarray(p, float), 0.0, 0.5))}


    def output_jacobian(self, ctx, p, parts):
        # U = G [log10(k_n A) - log10(k_m B) + f], k = 1 + eps, eta = (1 - eps)/(1 + eps):
        # dk/deps = 1, deta/deps = -2 / (1 + eps)^2
        e = np.clip(np.asarray(p, float), 0.0, 0.5)
        deta = -2.0 / (1.0 + e) ** 2
        kl = parts["G_ln10"]
        J = np.zeros(parts["A"].shape + (6,))
        ch = np.arange(3)
        J[:, ch, 2 * ch] = kl * (1.0 / (1.0 + e[0::2]) + deta[0::2] * parts["dc1"] / parts["A"])
        J[:, ch, 2 * ch + 1] = -kl * (1.0 / (1.0 + e[1::2])
                                      - deta[1::2] * parts["dc2"] / parts["B"])
        return J


EFFECT = ExtinctionRatio()
