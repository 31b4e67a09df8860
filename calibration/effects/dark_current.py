"""Dark current of the photodiodes: an additive photocurrent that does not scale with the sky.

Each photodiode ``k`` of a channel delivers ``I_k = R_k t_k E_s (1 +/- eta d cos 2x) + D_k``:
the photocurrent of the polarized sky plus its dark current ``D_k`` (thermally generated,
independent of the light). Dividing by the signal scale ``R_k t_k E_s`` (which the
transmittance term ``f`` already holds) the opponent ratio becomes::

    (1 + d cos 2x_1 + delta_1) / (1 - d cos 2x_2 + delta_2),   delta_k = D_k / (R_k t_k E_s)

so the dark-to-signal ratio ``delta_k`` grows as the sky darkens. With ``E`` the scene
illuminance, ``delta_k(t) = rho_k * E_ref / E(t)`` where ``rho_k`` is the ratio at the reference
illuminance ``E_ref = 10 klx``. ``E(t)`` is the recorded ``illuminance_lx`` column when present,
otherwise the clear-sky global horizontal illuminance of the sun elevation (Haurwitz 1945 [1]_
irradiance ``1098 cos z exp(-0.059 / cos z)`` W/m^2 times a daylight luminous efficacy of
110 lm/W [2]_). The photodiode physics (signal plus dark level, log ratio) is that of
:mod:`sensor.photodiode`; this module holds the illuminance scaling. With every ``rho_k = 0``
the model is eq. (2) of Yang et al. (2014).

References
----------
.. [1] B. Haurwitz, "Insolation in relation to cloudiness and cloud density", J. Meteorology
   2:154-166 (1945); as implemented in pvlib ``clearsky.haurwitz``.
.. [2] P. J. Littlefair, "The luminous efficacy of daylight: a review", Lighting Research &
   Technology 17(4):162-182 (1985).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from . import Context, Effect

__all__ = [
    "EFFECT",
    "E_REF_LX",
    "LUMINOUS_EFFICACY_LM_PER_W",
    "DarkCurrent",
    "clear_sky_illuminance_lx",
]

E_REF_LX = 1.0e4
"""Reference illuminance [lx] at which the dark-to-signal ratios ``rho_k`` are stated."""

LUMINOUS_EFFICACY_LM_PER_W = 110.0
"""Luminous efficacy of clear-sky global daylight [lm/W] (Littlefair 1985: 100-120)."""


def clear_sky_illuminance_lx(sun_elevation_deg) -> np.ndarray:
    """Clear-sky global horizontal illuminance [lx] from the Haurwitz (1945) irradiance model.

    ``E = 110 lm/W * 1098 cos z exp(-0.059 / cos z)`` with ``z`` the solar zenith angle; 0 for a
    sun at or below the horizon.
    """
    cz = np.sin(np.radians(np.asarray(sun_elevation_deg, dtype=float)))
    with np.errstate(divide="ignore", invalid="ignore"):
        ghi = np.where(cz > 0, 1098.0 * cz * np.exp(-0.059 / np.where(cz > 0, cz, 1.0)), 0.0)
    return LUMINOUS_EFFICACY_LM_PER_W * ghi


def scene_illuminance_lx(ctx: Context) -> np.ndarray:
    """Recorded illuminance, else the clear-sky model at the recorded times (cached)."""
    if ctx.illuminance_lx is not None:
        return ctx.illuminance_lx
    if "illuminance_model_lx" not in ctx.cache:
        el, _ = ctx.sun.elevation_azimuth(ctx.t_s)
        ctx.cache["illuminance_model_lx"] = np.maximum(clear_sky_illuminance_lx(el), 1.0)
    return ctx.cache["illuminance_model_lx"]


class DarkCurrent(Effect):
    """Dark-to-signal ratio ``rho_k`` of the six photodiodes at 10 klx (module docstring)."""

    name = "dark_current"
    parameter_names = tuple(f"rho_{k}" for k in range(1, 7))
    units = ("1",) * 6
    bounds = np.tile([0.0, 0.3], (6, 1))
    prior_mean = np.full(6, 1e-3)
    prior_sd = np.full(6, 0.05)
    fd_step = np.full(6, 1e-4)
    null = np.zeros(6)
    generation_range: ClassVar[dict] = {"rho_level": "log-uniform [3e-4, 5e-2] at 10 klx",
                        "rho_k": "level x U(0.5, 1.5) per photodiode"}

    def draw(self, rng):
        level = np.exp(rng.uniform(np.log(3e-4), np.log(5e-2)))
        return level * rng.uniform(0.5, 1.5, 6)

    def channel_terms(self, ctx, p):
        ratio = (E_REF_LX / scene_illuminance_lx(ctx))[:, None]
        return {"dark_ratio": ratio * np.clip(np.asarray(p, float), 0.0, None)[None, :]}


    def output_jacobian(self, ctx, p, parts):
        # dU/d delta_num = (G/ln10) / A, dU/d delta_den = -(G/ln10) / B; delta = rho E_ref/E
        ratio = (E_REF_LX / scene_illuminance_lx(ctx))[:, None]
        J = np.empty(parts["A"].shape + (6,))
        J[:] = 0.0
        ch = np.arange(3)
        J[:, ch, 2 * ch] = parts["G_ln10"] / parts["A"] * ratio
        J[:, ch, 2 * ch + 1] = -parts["G_ln10"] / parts["B"] * ratio
        return J


EFFECT = DarkCurrent()
