"""Single-scattering Rayleigh sky: degree and angle of polarization, E-vector, Stokes.

Conventions (see ``docs/conventions.md``): directions are (elevation, azimuth clockwise from
north) in degrees; the angle of polarization (AoP) is the E-vector orientation measured from
the local meridian (``e_el``, towards the zenith) positive towards increasing azimuth
(``e_az``), wrapped to [-90, 90). Stokes ``Q = I d cos 2 AoP``, ``U = I d sin 2 AoP`` in that
basis, so Q < 0 where the E-vector is perpendicular to the meridian.

In single Rayleigh scattering the E-vector is perpendicular to the scattering plane
(spanned by the view direction v and the sun direction s): E ~ v x s [1]_.

References
----------
.. [1] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak
   (1988), ch. 2.
.. [2] J. Yang, N. Zhou, Y. Huang, X. Liu, "Analysis and compensation of angle errors of
   polarization navigation sensors", Opt. Precision Eng. 22(6):1424-1429 (2014),
   doi:10.3788/OPE.20142206.1424, eq. (1).
"""

from __future__ import annotations

import numpy as np

from .geometry import aop_from_e_vector, angle_between_deg, direction_vector, local_basis
from .validation import check_in_range

__all__ = [
    "scattering_angle_deg",
    "degree_of_polarization",
    "e_vector",
    "angle_of_polarization_deg",
    "relative_radiance",
    "stokes",
]


def scattering_angle_deg(view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                         sun_azimuth_deg) -> np.ndarray:
    """Scattering angle gamma [deg] between the view direction and the sun (broadcasts)."""
    v = direction_vector(view_elevation_deg, view_azimuth_deg)
    s = direction_vector(sun_elevation_deg, sun_azimuth_deg)
    return angle_between_deg(v, s)


def degree_of_polarization(scattering_angle_deg, dmax=1.0) -> np.ndarray:
    """Rayleigh degree of polarization ``d = d_max sin^2(g) / (1 + cos^2(g))`` (eq. 1 of [2]_).

    Parameters
    ----------
    scattering_angle_deg : array-like
        Scattering angle gamma [deg].
    dmax : float or array-like
        Maximum degree of polarization (at gamma = 90 deg), in (0, 1]. A real clear sky has
        d_max ~ 0.6-0.8 (multiple scattering, aerosols, ground reflection).

    Returns
    -------
    ndarray, in [0, d_max].
    """
    dmax = check_in_range("dmax", dmax, 0.0, 1.0, low_open=True)
    g = np.radians(np.asarray(scattering_angle_deg, dtype=float))
    c2 = np.cos(g) ** 2
    return dmax * (1.0 - c2) / (1.0 + c2)


def e_vector(view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
             sun_azimuth_deg) -> np.ndarray:
    """Unit E-vector (ENU), perpendicular to the scattering plane, shape ``(..., 3)``.

    The sign of an E-vector is meaningless (it is an axis); this returns ``v x s`` normalised.
    Where the view direction is parallel to the sun (gamma = 0 or 180) the E-vector is
    undefined and NaN is returned there (DoP is 0 at those points).
    """
    v = direction_vector(view_elevation_deg, view_azimuth_deg)
    s = direction_vector(sun_elevation_deg, sun_azimuth_deg)
    e = np.cross(v, s)
    n = np.linalg.norm(e, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 1e-12, e / n, np.nan)


def angle_of_polarization_deg(view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                              sun_azimuth_deg) -> np.ndarray:
    """AoP [deg, in [-90, 90)] from the local meridian, positive towards increasing azimuth."""
    e = e_vector(view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg)
    return aop_from_e_vector(view_elevation_deg, view_azimuth_deg, e)


def relative_radiance(scattering_angle_deg) -> np.ndarray:
    """Single-scattering Rayleigh radiance, ``(3/4)(1 + cos^2 g)`` [relative].

    The Rayleigh phase function normalised so that its mean over the sphere is 1. In the
    optically thin limit the sky radiance is proportional to it (times the airmass factor,
    which this single-scattering model leaves out).
    """
    g = np.radians(np.asarray(scattering_angle_deg, dtype=float))
    return 0.75 * (1.0 + np.cos(g) ** 2)


def stokes(view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg,
           dmax=1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stokes ``(I, Q, U)`` of the single-scattering sky in the local-meridian basis.

    ``I`` is :func:`relative_radiance`; ``Q = I d cos 2 chi``, ``U = I d sin 2 chi`` with
    ``chi`` the AoP. Shapes broadcast over all inputs.
    """
    gamma = scattering_angle_deg(view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                                 sun_azimuth_deg)
    d = degree_of_polarization(gamma, dmax)
    intensity = relative_radiance(gamma)
    v, e_el, e_az = local_basis(view_elevation_deg, view_azimuth_deg)
    s = direction_vector(sun_elevation_deg, sun_azimuth_deg)
    e = np.cross(v, s)  # unnormalised; |e| = sin(gamma)
    # cos 2chi and sin 2chi from the unnormalised components (well defined where d = 0 too)
    a = np.sum(e * e_el, axis=-1)
    b = np.sum(e * e_az, axis=-1)
    r2 = a * a + b * b
    with np.errstate(invalid="ignore", divide="ignore"):
        c2 = np.where(r2 > 0, (a * a - b * b) / r2, 1.0)
        s2 = np.where(r2 > 0, 2 * a * b / r2, 0.0)
    return intensity, intensity * d * c2, intensity * d * s2
