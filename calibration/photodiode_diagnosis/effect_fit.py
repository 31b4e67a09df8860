"""Pieces every candidate's fit on one fold shares: the start built from the base fit, the
nominal instrument, the joint fit of the angle of polarization with the units' pointing free,
and the iteration budgets (used by :mod:`.run` and :mod:`.clock`)."""

from __future__ import annotations

import numpy as np

from skysim.exceptions import InvalidParameterError

from .effects import RingEffect
from .fit import fit
from .forward import Forward

__all__ = ["EFFECT_JOINT_ITER", "EFFECT_MAX_ITER"]


EFFECT_MAX_ITER = 12
"""Iterations of a candidate's fit (it starts from the fold's base fit and its best coarse
start, so its descent is short); a fit stopped here is reported ``converged: false``."""


def _extend(theta_base, fwd_base: Forward, fwd: Forward, p_eff) -> np.ndarray:
    t = np.zeros(fwd.layout.size)
    t[:fwd_base.layout.size] = theta_base[:fwd_base.layout.size]
    t[fwd.layout.effect] = p_eff
    return t


def _nominal_instrument(theta, L, groups) -> np.ndarray:
    """``theta`` with the instrument parameter ``groups`` (slices of the layout ``L``) at
    their nominal value 0: a start that does not carry what a base fit under a strongly
    different sky or clock took up into gains, offsets and angles."""
    out = np.array(theta, float)
    for sl in groups:
        out[sl] = 0.0
    return out


def _joint_aop(fe: Forward, aop, sigma):
    """The AoP fit ``aop`` (pointing held) continued with the pointing free beside the effect
    and everything else but the DoP scale, with its covariance (:func:`.run._joint_geometry`);
    ``aop`` itself when that does not lower its cost or leaves the model's valid range."""
    L = fe.layout
    free = np.ones(L.size, bool)
    free[L.scale] = False
    fe.dop_free = True
    try:
        joint = fit(fe, aop.theta, free, sigma=sigma, max_iter=EFFECT_JOINT_ITER,
                    covariance=True)
    except InvalidParameterError:
        return aop
    finally:
        fe.dop_free = False
    return aop if joint.cost > aop.cost * (1 + 1e-9) else joint


EFFECT_JOINT_ITER = 40
"""Iterations of :func:`.run._joint_geometry`'s AoP fit (it starts from the pinned fit's optimum;
on simulated rings it converged in fewer)."""


def _has_sky(effect) -> bool:
    """True for an effect that replaces the sky model (its own DoP and AoP)."""
    return type(effect).sky is not RingEffect.sky
