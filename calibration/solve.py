"""Heading (polarization azimuth) from pairs of opponent channels.

Ideal model, eqs. (5)-(9) of Yang et al. (2014) [1]_: invert each channel's log ratio to
``p_k = d cos 2(phi + a_k)`` (with gain g: ``p_k = tanh(U_k ln10 / (2g))``), then two channels
give a linear system in ``C = d cos 2phi`` and ``S = d sin 2phi``. ``atan`` alone gives phi
modulo 90 deg; requiring ``d > 0`` (``atan2(S, C)``) resolves it, so phi covers [-90, 90).

Compensated model: with calibrated mounting errors and transmittance terms the channel
equations are no longer linear in (C, S); :func:`solve_pair_compensated` solves the two
equations for (phi, d) per sample by Newton's method started from the ideal solution.

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424, eqs. (5)-(9).
"""

from __future__ import annotations

import functools

import numpy as np

from sensor.opponent import CHANNEL_ANGLES_DEG, GAIN
from skysim.exceptions import InvalidParameterError
from skysim.geometry import wrap_axial_deg
from skysim.validation import as_float_array

from .exceptions import ConvergenceError
from .model import channel_jacobian

__all__ = ["PAIRS", "pair_index", "solve_pair", "solve_pairs", "solve_pair_compensated",
           "heading_error_deg"]

PAIRS = ((1, 2), (1, 3), (2, 3))
"""Channel pairs of the paper (1-based channel numbers: U1 = 60 deg, U2 = 0, U3 = 120)."""


def pair_index(pair) -> tuple[int, int]:
    """0-based column indices of a pair such as ``(1, 2)``; raises
    :class:`~skysim.exceptions.InvalidParameterError` otherwise."""
    i, j = (int(pair[0]), int(pair[1]))
    if i == j or not {i, j} <= {1, 2, 3}:
        raise InvalidParameterError(
            f"pair must be two different channels of 1, 2, 3; got {pair!r}")
    return i - 1, j - 1


def solve_pair(U, pair=(1, 2), gain: float = GAIN) -> tuple[np.ndarray, np.ndarray]:
    """Ideal-model polarization azimuth [deg, in [-90, 90)] and DoP from a channel pair.

    Parameters
    ----------
    U : array (..., 3)
        Channel outputs U1, U2, U3 [V].
    pair : (int, int)
        Which two channels to use.
    gain : float
        Amplifier gain [V/decade].

    Returns
    -------
    (phi_deg, dop) : arrays of shape ``U.shape[:-1]``.
    """
    phi, d = solve_pairs(U, (pair,), gain)
    return phi[..., 0], d[..., 0]


SOLVE_BLOCK = 16384
"""Samples per block of :func:`solve_pairs`: its temporaries stay in a core's L2 cache."""


def solve_pairs(U, pairs=PAIRS, gain: float = GAIN) -> tuple[np.ndarray, np.ndarray]:
    """Ideal-model polarization azimuth [deg, in [-90, 90)] and DoP from several pairs at once.

    Each channel's log ratio is inverted once (eq. 5 of [1]_) and shared by the pairs; each
    pair then solves the linear system of eqs. (7)-(8) for ``C = d cos 2phi`` and
    ``S = d sin 2phi`` (one 2x2 matrix product per block gives ``-S`` and ``C``) and takes
    ``phi = atan2(S, C) / 2`` (eq. 9 with the 90-degree ambiguity resolved by ``d > 0``) and
    ``d = hypot(C, S)``. Samples are processed in blocks of :data:`SOLVE_BLOCK` so that the
    temporaries stay in cache; the result equals :func:`solve_pair` pair by pair.

    The half-open interval comes from the sign of zero, without a wrapping pass:
    ``phi = -atan2(-S + 0, C) / 2``, where ``-S + 0`` is never ``-0``, so the arctangent lies
    in ``(-180, 180]`` deg and ``phi`` in ``[-90, 90)`` (``S = 0, C < 0`` gives -90).

    Parameters
    ----------
    U : array (..., 3)
        Channel outputs U1, U2, U3 [V].
    pairs : sequence of (int, int)
        Channel pairs (default: the paper's three, :data:`PAIRS`).
    gain : float
        Amplifier gain [V/decade].

    Returns
    -------
    (phi_deg, dop) : arrays of shape ``U.shape[:-1] + (len(pairs),)``, pair ``k`` in
    ``[..., k]``.
    """
    U = as_float_array("U", U)
    if U.shape[-1:] != (3,):
        raise InvalidParameterError(
            f"U must have shape (..., 3) (channels U1, U2, U3); got {U.shape}")
    used, systems = _pair_systems(tuple(pair_index(pair) for pair in pairs))
    flat = U.reshape(-1, 3)
    flat = flat if len(used) == 3 else flat[:, used]
    n = flat.shape[0]
    phi = np.empty((len(systems), n))
    dop = np.empty((len(systems), n))
    scale = np.log(10.0) / (2.0 * gain)
    neg_half_deg = -90.0 / np.pi  # -atan2 [rad] -> phi [deg]
    m_max = min(SOLVE_BLOCK, n)
    x_buf = np.empty(len(used) * m_max)
    p_buf = np.empty(len(used) * m_max)
    sc_buf = np.empty(2 * m_max)
    for start in range(0, n, SOLVE_BLOCK):
        stop = min(start + SOLVE_BLOCK, n)
        m = stop - start
        # every step in the cache-sized buffers; each output row is written once. U is read
        # once, by a contiguous pass (memory bandwidth); tanh then reads it transposed from
        # the cache into (channel, block) rows
        x = x_buf[:len(used) * m].reshape(m, len(used))
        np.multiply(flat[start:stop], scale, out=x)
        p = p_buf[:len(used) * m].reshape(len(used), m)
        np.tanh(x.T, out=p)
        neg_s_c = sc_buf[:2 * m].reshape(2, m)
        neg_s, c = neg_s_c
        for k, (rows, matrix) in enumerate(systems):
            np.matmul(matrix, p[rows], out=neg_s_c)
            np.add(neg_s, 0.0, out=neg_s)                      # -0 -> +0 (see above)
            out = phi[k, start:stop]
            np.arctan2(neg_s, c, out=out)
            out *= neg_half_deg
            np.square(neg_s_c, out=neg_s_c)
            np.add(neg_s, c, out=neg_s)
            np.sqrt(neg_s, out=dop[k, start:stop])  # d = hypot(C, S) (|C|, |S| <= ~2)
    shape = U.shape[:-1] + (len(systems),)
    return phi.T.reshape(shape), dop.T.reshape(shape)


def solve_pair_compensated(U, pair, misalignment_deg, transmittance, gain: float = GAIN,
                           max_iter: int = 30, tol_deg: float = 1e-10):
    """Polarization azimuth [deg] and DoP from a pair, with calibrated errors.

    Parameters
    ----------
    U : array (..., 3)
        Channel outputs [V].
    pair : (int, int)
    misalignment_deg : array (4,) or (*B, 4)
        ``(e1_i, e2_i, e1_j, e2_j)`` [deg]: numerator/denominator mounting errors of the pair.
        With a batch shape ``B`` (one calibration per batch element), ``U`` is (*B, m, 3).
    transmittance : array (2,) or (*B, 2)
        ``(f_i, f_j)``.

    Raises
    ------
    ConvergenceError
        If Newton's method has not converged for every sample after ``max_iter`` steps.
    """
    i, j = pair_index(pair)
    U = as_float_array("U", U)
    e = np.asarray(misalignment_deg, dtype=float)
    f = np.asarray(transmittance, dtype=float)
    e1, e2 = e[..., 0::2], e[..., 1::2]
    mean_e = 0.25 * e.sum(axis=-1)
    if e.ndim > 1:  # batched calibrations: align with the sample axis of U (*B, m, 3)
        e1, e2, f, mean_e = e1[..., None, :], e2[..., None, :], f[..., None, :], mean_e[..., None]
    a = CHANNEL_ANGLES_DEG[[i, j]]
    Up = U[..., [i, j]]
    # start: ideal solve on outputs with the transmittance offsets and mean mounting error removed
    U0 = np.zeros(U.shape)
    U0[..., [i, j]] = Up - gain * f
    phi, d = solve_pair(U0, pair, gain)
    phi = phi - mean_e
    d = np.clip(d, 1e-3, 0.999)
    step = np.inf
    for it in range(max_iter):
        val, jac = channel_jacobian(phi[..., None], d[..., None], a, e1, e2, f, gain,
                                    wrt=("phi", "dop"))
        r = val - Up                               # (..., 2)
        J_phi, J_d = jac["phi"], jac["dop"]        # (..., 2) each; phi derivative per deg
        det = J_phi[..., 0] * J_d[..., 1] - J_phi[..., 1] * J_d[..., 0]
        dphi = -(J_d[..., 1] * r[..., 0] - J_d[..., 0] * r[..., 1]) / det
        dd = -(-J_phi[..., 1] * r[..., 0] + J_phi[..., 0] * r[..., 1]) / det
        phi = phi + dphi
        d = np.clip(d + dd, 1e-6, 0.999999)
        # converged when both unknowns have stopped moving: phi alone can settle a step
        # before d does
        step = float(np.nanmax(np.abs(dphi))) if dphi.size else 0.0
        d_step = float(np.nanmax(np.abs(dd))) if dd.size else 0.0
        if step < tol_deg and d_step < 1e-12:
            break
    else:
        raise ConvergenceError(
            f"compensated heading solve did not converge in {max_iter} iterations "
            f"(last step {step:.3g} deg)", last_step=step, iterations=max_iter)
    return wrap_axial_deg(phi), d


@functools.lru_cache(maxsize=64)
def _pair_systems(pairs: tuple) -> tuple[list, list]:
    """Channels to invert and, per pair, ``(rows, matrix)``: the rows of the inverted
    channels (a slice) and the 2x2 matrix that maps them to ``(-S, C)`` by Cramer's rule on
    eqs. (7)-(8): ``C = (p_j sin 2a_i - p_i sin 2a_j) / det``,
    ``S = (p_j cos 2a_i - p_i cos 2a_j) / det``, ``det = sin 2(a_i - a_j)``."""
    used = sorted({ch for pair in pairs for ch in pair})   # invert only these channels
    systems = []
    for i, j in pairs:
        ai, aj = np.radians(2.0 * CHANNEL_ANGLES_DEG[[i, j]])
        det = np.sin(ai - aj)
        matrix = np.array([[np.cos(aj) / det, -np.cos(ai) / det],     # -S
                           [-np.sin(aj) / det, np.sin(ai) / det]])    # C
        ri, rj = used.index(i), used.index(j)
        if ri > rj:                                  # rows in increasing order: a slice
            ri, rj, matrix = rj, ri, matrix[:, ::-1]
        matrix = np.ascontiguousarray(matrix)
        matrix.flags.writeable = False               # shared by every call (cached)
        systems.append((slice(ri, rj + 1, rj - ri), matrix))
    return used, systems


def heading_error_deg(phi_estimated_deg, phi_reference_deg) -> np.ndarray:
    """Axial heading error [deg] in [-90, 90): ``wrap(phi_est - phi_ref)``."""
    return wrap_axial_deg(np.asarray(phi_estimated_deg) - np.asarray(phi_reference_deg))
