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
.. [3] J. E. Hansen, L. D. Travis, "Light scattering in planetary atmospheres", Space Sci.
   Rev. 16:527-610 (1974), doi:10.1007/BF00168069.
"""

from __future__ import annotations

import numpy as np

from .geometry import aop_from_e_vector, angle_between_deg, cos_sin_deg, direction_vector
from .validation import check_in_range

__all__ = [
    "scattering_angle_deg",
    "degree_of_polarization",
    "e_vector",
    "angle_of_polarization_deg",
    "relative_radiance",
    "meridian_components",
    "polarization_field",
    "stokes",
    "stokes_from_sun_projections",
    "slab_transmission",
    "flux_pi_scale",
    "FLOAT32_AOP_ERROR_DEG",
    "FLOAT32_DOP_ERROR",
    "FLOAT32_MIN_SCATTERING_ANGLE_DEG",
]

FLOAT32_AOP_ERROR_DEG = 1e-3
"""Bound on the AoP error [deg] of the float32 path (:func:`polarization_field`) against float64,
for view directions at least :data:`FLOAT32_MIN_SCATTERING_ANGLE_DEG` from the sun and the
anti-sun (closer to them the AoP is ill-conditioned in any precision and the DoP tends to 0)."""

FLOAT32_DOP_ERROR = 1e-5
"""Bound on the absolute DoP error of the float32 path against float64, for every direction."""

FLOAT32_MIN_SCATTERING_ANGLE_DEG = 2.0
"""Scattering-angle margin [deg] from the sun and the anti-sun beyond which the float32 AoP bound
holds: the float32 components carry absolute errors up to ~5e-7, so the AoP error grows like
``5e-7 / sin(gamma)`` rad towards them (7e-4 deg at 2 deg, where DoP < 6e-4 d_max)."""


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


def meridian_components(view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                        sun_azimuth_deg, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Components ``(a, b)`` of the unnormalised E-vector ``v x s`` on ``(e_el, e_az)``.

    With ``Delta = view azimuth - sun azimuth``, elevations ``h`` (view) and ``h_s`` (sun):
    ``a = cos h_s sin Delta`` and ``b = cos h sin h_s - sin h cos h_s cos Delta`` (the E-vector
    of single scattering is perpendicular to the scattering plane [1]_); the AoP is ``atan2(b, a)`` (axial) and ``a^2 + b^2 = sin^2 gamma``. Written with the sun's
    ENU vector ``(s_x, s_y, s_z)``: ``a = s_y sin A - s_x cos A``,
    ``b = s_z cos h - sin h (s_x sin A + s_y cos A)`` (``A`` the view azimuth), so the
    direction trigonometry is computed on the view arrays as given and the sun's on the sun
    arrays: a ``(1, N)`` grid against ``(T, 1)`` suns costs ``N + T`` trigonometric values.

    Parameters
    ----------
    view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg : array-like
        Directions [deg] (broadcast together).
    dtype : numpy dtype
        ``float64`` or ``float32`` arithmetic.

    Returns
    -------
    (a, b) : tuple of ndarray of the broadcast shape.
    """
    ce, se = cos_sin_deg(view_elevation_deg, dtype)
    ca, sa = cos_sin_deg(view_azimuth_deg, dtype)
    # the sun's vector in float64 whatever dtype: it is small (one per sun) or shared by the
    # view arrays, and its rounding would otherwise dominate the float32 AoP error
    cs, sun_z = cos_sin_deg(sun_elevation_deg)
    csa, ssa = cos_sin_deg(sun_azimuth_deg)
    sx, sy, sz = ((cs * ssa).astype(dtype), (cs * csa).astype(dtype), sun_z.astype(dtype))
    shape = np.broadcast_shapes(ce.shape, ca.shape, sx.shape, sy.shape)
    # three full-shape buffers reused in place: every fresh large array costs memory traffic
    # (and page faults when the allocator has returned its memory)
    a = np.multiply(sa, sy, out=np.empty(shape, dtype))
    work = np.multiply(ca, sx, out=np.empty(shape, dtype))
    a -= work
    horizontal = np.multiply(ca, sy, out=work)
    b = np.multiply(sa, sx, out=np.empty(shape, dtype))
    horizontal += b
    horizontal *= se
    np.multiply(ce, sz, out=b)
    b -= horizontal
    return a, b


def polarization_field(view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                       sun_azimuth_deg, dmax=1.0, dtype=np.float64) -> dict:
    """Single-scattering field: ``I, Q, U``, DoP and AoP [deg] from the E-vector components.

    With ``(a, b)`` from :func:`meridian_components` and ``s2 = a^2 + b^2 = sin^2 gamma``:
    ``I = (3/4)(2 - s2)`` (= (3/4)(1 + cos^2 gamma)), ``DoP = d_max s2 / (2 - s2)`` (eq. 1 of
    [2]_), ``Q = (3/4) d_max (a^2 - b^2)``, ``U = (3/2) d_max a b`` and
    ``AoP = atan(b / a)`` wrapped to [-90, 90): no angle round trips and no trigonometry per
    value other than one ``arctan``. AoP is 0 where it is undefined (at the sun and the
    anti-sun, where DoP = 0), as ``atan2(U, Q)`` gives there.

    Parameters
    ----------
    view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg : array-like
        Directions [deg] (broadcast together; not validated here, see
        :meth:`skysim.sky.Sky.field`).
    dmax : float
        Maximum degree of polarization, in (0, 1].
    dtype : numpy dtype
        ``float64`` (default; agrees with the vector formulation to ~1e-15) or ``float32``
        (about 3x faster again; errors within :data:`FLOAT32_AOP_ERROR_DEG` and
        :data:`FLOAT32_DOP_ERROR`).

    Returns
    -------
    dict with ``I``, ``Q``, ``U``, ``dop`` and ``aop_deg`` arrays of the broadcast shape.
    """
    dmax = float(check_in_range("dmax", dmax, 0.0, 1.0, low_open=True))
    a, b = meridian_components(view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                               sun_azimuth_deg, dtype)
    q = np.multiply(a, a, out=np.empty_like(a))
    u = np.multiply(b, b, out=np.empty_like(a))        # b^2 for now
    dop = np.add(q, u, out=np.empty_like(a))           # sin^2 gamma for now
    intensity = np.subtract(2.0, dop, out=np.empty_like(a))  # 1 + cos^2 gamma for now
    q -= u
    q *= 0.75 * dmax
    np.multiply(a, b, out=u)
    u *= 1.5 * dmax
    dop *= dmax
    dop /= intensity
    intensity *= 0.75
    with np.errstate(divide="ignore", invalid="ignore"):
        aop = np.divide(b, a, out=b)
    np.arctan(aop, out=aop)
    aop *= 180.0 / np.pi
    off = ~(aop < 90.0)  # +90 (a = 0) belongs to -90; NaN (a = b = 0) is undefined
    if off.any():
        aop[off] = np.where(np.isnan(aop[off]), 0.0, -90.0)
    return {"I": intensity, "Q": q, "U": u, "dop": dop, "aop_deg": aop}


def stokes_from_sun_projections(p1, p2, dmax: float = 1.0):
    """Single-scattering Stokes ``(I, Q, U)`` in any polarization basis of a ray, from the
    sun's projections on that basis: dot products only, no angles.

    For a right-handed basis ``(e1, e2, v)`` across the view direction ``v`` (``e1 x e2 = v``;
    e.g. the local meridian basis ``(e_el, e_az)``, or a camera pixel's image axes carried onto
    the sky) and the unit sun vector ``s``, the E-vector ``v x s`` [1]_ has the components
    ``(s . (e1 x v), s . (e2 x v)) = (-p2, p1)`` with ``p_k = s . e_k``, and
    ``p1^2 + p2^2 = sin^2 gamma``. Hence (as in :func:`polarization_field` with
    ``a = -p2``, ``b = p1``)

    ``I = (3/4)(2 - p1^2 - p2^2)``, ``Q = (3/4) d_max (p2^2 - p1^2)``,
    ``U = -(3/2) d_max p1 p2``,

    ``Q`` along ``e1``, ``U`` from ``e1`` towards ``e2``.

    Parameters
    ----------
    p1, p2 : ndarray
        Sun projections ``s . e1``, ``s . e2`` [1], same shape; the result keeps their dtype
        (float32 halves the memory traffic; every output is a few float32 ulps of its float64
        value, since ``|p_k| <= 1``).
    dmax : float
        Maximum degree of polarization, in (0, 1].

    Returns
    -------
    (I, Q, U) : tuple of ndarray, shape and dtype of ``p1``.
    """
    dmax = float(check_in_range("dmax", dmax, 0.0, 1.0, low_open=True))
    p1, p2 = np.asarray(p1), np.asarray(p2)
    intensity = np.multiply(p1, p1)
    q = np.multiply(p2, p2)
    u = np.multiply(p1, p2)
    q -= intensity                 # p2^2 - p1^2
    intensity *= 2.0
    intensity += q                 # p1^2 + p2^2 = sin^2 gamma
    intensity *= -0.75
    intensity += 1.5
    q *= 0.75 * dmax
    u *= -1.5 * dmax
    return intensity, q, u


def stokes(view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg,
           dmax=1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stokes ``(I, Q, U)`` of the single-scattering sky in the local-meridian basis.

    ``I`` is :func:`relative_radiance`; ``Q = I d cos 2 chi``, ``U = I d sin 2 chi`` with
    ``chi`` the AoP (computed by :func:`polarization_field`). Shapes broadcast over all
    inputs, ``dmax`` included.
    """
    dmax = np.asarray(dmax, dtype=float)
    f = polarization_field(view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                           sun_azimuth_deg, float(dmax) if dmax.ndim == 0 else 1.0)
    if dmax.ndim == 0:
        return f["I"], f["Q"], f["U"]
    return f["I"], f["Q"] * dmax, f["U"] * dmax


def slab_transmission(tau, mu, mu0) -> np.ndarray:
    """``h = mu0 (exp(-tau/mu0) - exp(-tau/mu)) / (mu0 - mu)`` [1]: singly scattered light
    leaving the base of a slab of optical thickness ``tau`` along ``mu`` for a beam at
    ``mu0`` is ``w F0 P h / (4 pi)`` (Hansen & Travis 1974 [3]_, sect. 3; any phase
    function ``P`` of mean 1 over the sphere); ``tau / mu`` for a thin slab.

    Computed as ``(tau / mu) exp(-tau / mu0) (1 - exp(-x)) / x``, ``x = tau (mu0 - mu) /
    (mu mu0)``, without cancellation at ``mu = mu0`` (broadcast; ``mu, mu0 > 0``).
    """
    tau, mu, mu0 = np.broadcast_arrays(*(np.asarray(a, float) for a in (tau, mu, mu0)))
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # mu = 0: the horizon
        x = tau * (mu0 - mu) / (mu * mu0)
        small = np.abs(x) < 1e-4
        direct = mu0 * (np.exp(-tau / mu0) - np.exp(-tau / mu)) / (mu0 - mu)
        series = (tau / mu) * np.exp(-tau / mu0) * (1.0 - 0.5 * x + x * x / 6.0)
    return np.where(small, series, direct)



def flux_pi_scale(view_elevation_deg, sun_elevation_deg, tau: float | None = None):
    """The relative radiance (:func:`relative_radiance`) for a radiance of 1 in the unit of an
    incident solar flux ``pi`` (the unit of :mod:`skysim.multiple`).

    Below a thin Rayleigh slab of optical thickness ``tau`` the sky's radiance in that unit is
    ``P h / 4`` (:func:`slab_transmission`, ``P`` the relative radiance, ``mu = sin(view
    elevation)``, ``mu0 = sin(sun elevation)``), so the factor is ``4 / h`` (about
    ``4 mu / tau`` overhead). ``tau`` defaults to the molecular optical thickness at 550 nm
    at sea level, 0.0973 (Bodhaine et al. 1999, :func:`skysim.molecular.bodhaine_optical_thickness`).
    Broadcast; the sun above the horizon.
    """
    if tau is None:
        from .molecular import bodhaine_optical_thickness
        tau = float(bodhaine_optical_thickness(550.0))
    mu = np.sin(np.radians(np.asarray(view_elevation_deg, float)))
    mu0 = np.sin(np.radians(np.asarray(sun_elevation_deg, float)))
    return 4.0 / slab_transmission(tau, mu, mu0)
