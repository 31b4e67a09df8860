"""Directions, frames and angle wrapping.

Frames
------
ENU: x east, y north, z up (local topocentric). A direction is given by its elevation above
the horizon and its azimuth clockwise from geographic north, both in degrees.

The local sky basis at a view direction ``v`` is ``(e_el, e_az)``: ``e_el = dv/d(el)`` points
up along the local meridian (towards the zenith), ``e_az`` points towards increasing azimuth.
For an observer facing the view direction, ``e_el`` is "up" and ``e_az`` is "to the right",
so an angle measured from ``e_el`` towards ``e_az`` is clockwise as the observer sees it.
At the zenith the meridian is the one of the given view azimuth.

Rotations use :class:`scipy.spatial.transform.Rotation`.
"""

from __future__ import annotations

import math

import numpy as np

from .validation import check_in_range

__all__ = [
    "sky_grid",
    "sky_grid_size",
    "cos_sin_deg",
    "direction_vector",
    "elevation_azimuth",
    "local_basis",
    "angle_between_deg",
    "wrap_deg",
    "wrap_axial_deg",
    "e_vector_from_aop",
    "aop_from_e_vector",
]


def sky_grid_size(step_deg: float) -> int:
    """Number of directions of :func:`sky_grid` with spacing ``step_deg`` [deg]: 90/step + 1
    elevations times 360/step azimuths (without computing the grid)."""
    return (math.floor(90.0 / step_deg + 1e-9) + 1) * math.ceil(360.0 / step_deg - 1e-9)


def sky_grid(step_deg: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Full-sky grid of view directions: a regular elevation-azimuth grid, flattened.

    The default grid of the sky maps (``skysim sky``, ``skysim sky-series``, ``skysim
    generate``) and of the studies' polar maps: elevations 0, step, ... up to 90 deg (the
    horizon and the zenith included when ``step_deg`` divides 90) and azimuths 0, step, ...
    below 360 deg (clockwise from north, the ENU convention of this module). The grid is
    regular in angle, not in solid angle: the rows near the zenith are dense.

    Parameters
    ----------
    step_deg : float
        Spacing in elevation and azimuth [deg], in (0, 90].

    Returns
    -------
    elevation_deg, azimuth_deg : ndarray, shape (:func:`sky_grid_size`,)
        Elevation-major: all azimuths of the lowest elevation first.

    Raises
    ------
    InvalidParameterError
        If ``step_deg`` is not in (0, 90].
    """
    check_in_range("grid step [deg]", step_deg, 0.0, 90.0, low_open=True)
    el = np.arange(0.0, 90.0 + 1e-9, step_deg)
    az = np.arange(0.0, 360.0, step_deg)
    E, A = np.meshgrid(el, az, indexing="ij")
    return E.ravel(), A.ravel()


def wrap_deg(angle_deg, low: float = -180.0):
    """Wrap an angle [deg] into ``[low, low + 360)``."""
    return np.mod(np.asarray(angle_deg, dtype=float) - low, 360.0) + low


def wrap_axial_deg(angle_deg):
    """Wrap an axial angle (period 180 deg, e.g. an E-vector orientation) into [-90, 90)."""
    return np.mod(np.asarray(angle_deg, dtype=float) + 90.0, 180.0) - 90.0


def cos_sin_deg(angle_deg, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Cosine and sine of angles [deg] from one tangent of the half angle.

    With ``t = tan(x / 2)`` and ``r = 2 / (1 + t^2)``: ``cos x = r - 1`` and ``sin x = t r``,
    exact identities for every finite x (``t`` is large but finite near x = 180 deg, where
    they give -1 and ~0). One transcendental pass instead of two; numpy's ``tan`` is
    vectorised where its float64 ``sin``/``cos`` are not (6x faster on AVX-512 machines).
    Absolute errors against ``np.cos``/``np.sin`` of ``np.radians(x)`` are a few ulp of 1
    (4e-16 in float64, 2.4e-7 in float32).

    Parameters
    ----------
    angle_deg : array-like
        Angles [deg], any finite values.
    dtype : numpy dtype
        ``float64`` (default) or ``float32`` for the arithmetic and the result.

    Returns
    -------
    (cos, sin) : tuple of ndarray, shape of ``angle_deg``.
    """
    x = np.asarray(angle_deg)
    # degrees -> half angle [rad] before any rounding to dtype (float32 loses 3e-5 deg at 360)
    t = np.multiply(x, np.pi / 360.0, out=np.empty(x.shape, dtype), casting="same_kind")
    np.tan(t, out=t)
    r = np.multiply(t, t, out=np.empty_like(t))
    r += 1.0
    np.divide(2.0, r, out=r)
    t *= r
    r -= 1.0
    return r, t


def direction_vector(elevation_deg, azimuth_deg) -> np.ndarray:
    """Unit vector(s) in ENU for elevation [deg] and azimuth [deg, clockwise from north].

    Returns an array of shape ``broadcast(elevation, azimuth).shape + (3,)``.
    """
    el = np.radians(np.asarray(elevation_deg, dtype=float))
    az = np.radians(np.asarray(azimuth_deg, dtype=float))
    el, az = np.broadcast_arrays(el, az)
    cos_el = np.cos(el)
    return np.stack([cos_el * np.sin(az), cos_el * np.cos(az), np.sin(el)], axis=-1)


def elevation_azimuth(vectors) -> tuple[np.ndarray, np.ndarray]:
    """Elevation [deg] and azimuth [deg, clockwise from north, in [0, 360)] of ENU vectors.

    Vectors need not be normalised; shape ``(..., 3)``.
    """
    v = np.asarray(vectors, dtype=float)
    horiz = np.hypot(v[..., 0], v[..., 1])
    el = np.degrees(np.arctan2(v[..., 2], horiz))
    az = np.mod(np.degrees(np.arctan2(v[..., 0], v[..., 1])), 360.0)
    return el, az


def local_basis(elevation_deg, azimuth_deg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(v, e_el, e_az)``: view direction and the local sky basis (see module doc)."""
    el = np.radians(np.asarray(elevation_deg, dtype=float))
    az = np.radians(np.asarray(azimuth_deg, dtype=float))
    el, az = np.broadcast_arrays(el, az)
    se, ce, sa, ca = np.sin(el), np.cos(el), np.sin(az), np.cos(az)
    v = np.stack([ce * sa, ce * ca, se], axis=-1)
    e_el = np.stack([-se * sa, -se * ca, ce], axis=-1)
    e_az = np.stack([ca, -sa, np.zeros_like(az)], axis=-1)
    return v, e_el, e_az


def angle_between_deg(a, b) -> np.ndarray:
    """Angle [deg] between vectors ``a`` and ``b`` (shape ``(..., 3)``), robust near 0 and 180."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    return np.degrees(np.arctan2(cross, dot))


def e_vector_from_aop(elevation_deg, azimuth_deg, aop_deg) -> np.ndarray:
    """ENU unit E-vector for an angle of polarization [deg] measured from ``e_el`` towards ``e_az``."""
    _, e_el, e_az = local_basis(elevation_deg, azimuth_deg)
    chi = np.radians(np.asarray(aop_deg, dtype=float))[..., None]
    return np.cos(chi) * e_el + np.sin(chi) * e_az


def aop_from_e_vector(elevation_deg, azimuth_deg, e_vector) -> np.ndarray:
    """Angle of polarization [deg, in [-90, 90)] of an ENU E-vector in the local sky basis."""
    _, e_el, e_az = local_basis(elevation_deg, azimuth_deg)
    e = np.asarray(e_vector, dtype=float)
    chi = np.degrees(np.arctan2(np.sum(e * e_az, axis=-1), np.sum(e * e_el, axis=-1)))
    return wrap_axial_deg(chi)
