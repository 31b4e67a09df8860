"""Single scattering of sunlight in a layered plane-parallel slab of molecules and particles,
seen from its base: the aureole of a cloud or haze layer, in closed form.

A slab of total optical thickness ``T`` lit from above by a beam at ``mu0`` (incident flux
``pi`` per unit area normal to the beam, the unit of :mod:`skysim.multiple`); an observer at
its base looks up along ``mu``. Light scattered once at optical depth ``t`` (from the top) is
attenuated by ``exp(-t/mu0)`` on its way in and ``exp(-(T - t)/mu)`` on its way down, so
(Chandrasekhar 1950 [1]_, ch. I, sect. 11; Hansen & Travis 1974 [2]_, sect. 3)

``I = (1/4) sum_j P_j(Theta) A_j``,
``A_j = (1/mu) int k_j(z) exp(-t(z)/mu0 - (T - t(z))/mu) dz``,

with ``k_j`` the scattering coefficient of constituent ``j`` (molecules, particles),
``P_j`` its phase function (mean 1 over the sphere) and the polarized part likewise with the
phase-matrix element ``P12`` (polarization perpendicular to the scattering plane where
positive). Where the extinction is constant over a run of levels the integral is elementary:
``int_ta^tb exp(-c t) dt = exp(-c ta) (1 - exp(-c dt)) / c``, ``c = 1/mu0 - 1/mu``, which for
a single homogeneous layer is :func:`skysim.rayleigh.slab_transmission`. Where the extinction
ramps linearly between two levels (the edges of a layer under linear interpolation, as the
radiative-transfer engine of :mod:`skysim.rt_sasktran` represents them) ``t(z)`` is quadratic
and the integral is taken by Gauss-Legendre quadrature (8 nodes per ramp interval: the
integrand is smooth there and the ramp holds a small share of the optical thickness).

The weights ``A_j`` depend on the directions only through ``mu`` and ``mu0``, the phase
functions only through the scattering angle: a sharp forward peak (the droplets' aureole)
costs nothing extra, and the result is exact at every direction however close to the sun.

References
----------
.. [1] S. Chandrasekhar, *Radiative Transfer*, Oxford (1950; Dover 1960), ch. I.
.. [2] J. E. Hansen, L. D. Travis, "Light scattering in planetary atmospheres", Space Sci.
   Rev. 16:527-610 (1974), doi:10.1007/BF00168069, sect. 3.
"""

from __future__ import annotations

import numpy as np

from .exceptions import InvalidParameterError

__all__ = ["perpendicular_stokes", "phase_at_angle", "single_scatter_weights"]

_GAUSS_NODES = 8


def _runs(k):
    """Split the level intervals into runs of constant extinction (every constituent) and
    ramp intervals. Returns ``(runs, ramps)``: index pairs ``(i0, i1)`` of the levels that
    bound each constant run, and the indices ``i`` of the intervals ``[i, i + 1]`` that ramp."""
    const = np.all(k[1:] == k[:-1], axis=1)
    runs, ramps, start = [], [], None
    for i, c in enumerate(const):
        if c:
            if start is None:
                start = i
            elif np.any(k[i] != k[start]):
                runs.append((start, i))
                start = i
        else:
            if start is not None:
                runs.append((start, i))
                start = None
            ramps.append(i)
    if start is not None:
        runs.append((start, const.size))
    return runs, ramps


def single_scatter_weights(altitudes, scattering, extinction, mu, mu0) -> np.ndarray:
    """Weights ``A_j`` of the single scatter seen from the slab's base (module docstring).

    Parameters
    ----------
    altitudes : array-like (n,)
        Levels [m], strictly increasing from the base to the top of the slab.
    scattering : array-like (n, J)
        Scattering coefficient [1/m] of each constituent at the levels (linear in between).
    extinction : array-like (n,)
        Total extinction coefficient [1/m] at the levels (>= the summed scattering).
    mu, mu0 : array-like
        Cosines of the view zenith angle (looking up) and of the sun's zenith angle, in
        (0, 1], broadcast together.

    Returns
    -------
    ndarray (J, ...)
        ``A_j`` [1] on the broadcast shape of ``mu, mu0``.
    """
    z = np.asarray(altitudes, float)
    ks = np.asarray(scattering, float)
    ke = np.asarray(extinction, float)
    if z.ndim != 1 or z.size < 2 or np.any(np.diff(z) <= 0.0):
        raise InvalidParameterError(f"altitudes must increase strictly; got {z!r}")
    if ks.shape[0] != z.size or ke.shape != z.shape:
        raise InvalidParameterError(
            f"scattering (n, J) and extinction (n,) must follow the {z.size} levels; got "
            f"shapes {ks.shape} and {ke.shape}")
    mu, mu0 = np.broadcast_arrays(np.asarray(mu, float), np.asarray(mu0, float))
    if np.any(~(mu > 0.0)) or np.any(~(mu0 > 0.0)):
        raise InvalidParameterError("mu and mu0 must lie in (0, 1]: the view looks up and "
                                    "the sun is above the horizon")
    # optical depth from the top at each level (trapezoid: exact for linear interpolation)
    dtau = 0.5 * (ke[1:] + ke[:-1]) * np.diff(z)
    t = np.concatenate([np.cumsum(dtau[::-1])[::-1], [0.0]])
    T = t[0]
    m, m0 = mu[..., None], mu0[..., None]
    c = 1.0 / m0 - 1.0 / m
    out = np.zeros((ks.shape[1],) + mu.shape)
    runs, ramps = _runs(np.column_stack([ks, ke]))
    if runs:
        i0, i1 = np.array(runs).T
        ta, tb = t[i1], t[i0]                # top and bottom of each run (t grows downwards)
        share = ks[i0] / np.where(ke[i0] > 0.0, ke[i0], 1.0)[:, None]   # (runs, J)
        dt = tb - ta
        x = c * dt
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            # exp(-c t) integrated over [ta, tb], factored at the end where it is largest
            phi = np.where(np.abs(x) < 1e-8, 1.0 - 0.5 * np.abs(x), -np.expm1(-np.abs(x))
                           / np.abs(x))
            t_ref = np.where(x >= 0.0, ta, tb)
        integral = np.exp(-t_ref / m0 - (T - t_ref) / m) * dt * phi / m  # (..., runs)
        out += np.moveaxis(integral @ share, -1, 0)
    if ramps:
        xg, wg = np.polynomial.legendre.leggauss(_GAUSS_NODES)
        i = np.array(ramps)
        h = z[i + 1] - z[i]
        s = 0.5 * (xg[None, :] + 1.0)                                     # (ramps, nodes)
        ke_i, ke_j = ke[i][:, None], ke[i + 1][:, None]
        # optical depth at height z_i + s h: t_i - h (ke_i s + (ke_j - ke_i) s^2 / 2)
        tn = t[i][:, None] - h[:, None] * (ke_i * s + 0.5 * (ke_j - ke_i) * s * s)
        kn = ks[i][:, None, :] + (ks[i + 1] - ks[i])[:, None, :] * s[..., None]
        wn = 0.5 * h[:, None] * wg[None, :]
        e = np.exp(-tn.ravel() / m0 - (T - tn.ravel()) / m) / m          # (..., ramps*nodes)
        out += np.moveaxis(e @ (kn * wn[..., None]).reshape(-1, ks.shape[1]), -1, 0)
    return out


def phase_at_angle(angle_deg, p11, p12, scattering_angle_deg):
    """Phase-matrix elements ``(P11, P12)`` at ``scattering_angle_deg`` [deg] from a table:
    ``log P11`` and ``P12 / P11`` interpolated linearly (a forward peak falls by decades over
    a degree; its logarithm and the polarization ratio vary smoothly)."""
    a = np.asarray(angle_deg, float)
    p11, p12 = np.asarray(p11, float), np.asarray(p12, float)
    theta = np.clip(np.asarray(scattering_angle_deg, float), a[0], a[-1])
    q11 = np.exp(np.interp(theta, a, np.log(p11)))
    return q11, q11 * np.interp(theta, a, p12 / p11)


def perpendicular_stokes(intensity, polarized, a, b):
    """``(I, Q, U)`` of light of polarized radiance ``polarized`` whose E-vector is
    perpendicular to the scattering plane (negative: parallel), on the local meridian basis.

    ``a, b`` are the components of that E-vector direction
    (:func:`skysim.rayleigh.meridian_components`, ``a^2 + b^2 = sin^2 Theta``): ``Q = p (a^2 -
    b^2) / sin^2``, ``U = 2 p a b / sin^2``; unpolarized along the sun's line (``Theta`` 0 or
    180 deg), where no scattering plane exists.
    """
    s2 = a * a + b * b
    with np.errstate(invalid="ignore", divide="ignore"):
        pol = np.where(s2 > 0.0, polarized / s2, 0.0)
    return intensity, pol * (a * a - b * b), pol * 2.0 * a * b
