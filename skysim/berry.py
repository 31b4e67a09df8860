"""Berry, Dennis & Lee (2004): the clear-sky polarization pattern from its four singularities.

Single Rayleigh scattering has two unstable index +1 singularities (zero polarization) at the
sun and the anti-sun. Multiple scattering splits each into two index +1/2 singularities on the
solar meridian: Babinet (above the sun) and Brewster (below it), Arago (above the anti-sun) and
the fourth point (below the anti-sun, under the horizon for a ground observer). Berry et al.
[1]_ describe the whole pattern by one complex function of the stereographic projection of
the sky,

``zeta = tan(theta / 2) exp(i beta)``     (theta: zenith angle; beta: plane angle of the
direction, here ``beta = 90 deg - azimuth``, so the plane is the sky seen from above with
x east and y north),

``w(zeta) = -4 (zeta - zeta_Bab)(zeta - zeta_Bre)(zeta - zeta_Ara)(zeta - zeta_4)
/ ((1 + |zeta|^2)^2 |zeta_Bab - zeta_4| |zeta_Bre - zeta_Ara|)``       ([1]_, eqs. (3.1)-(3.3))

with the singularities a distance ``delta / 2`` either side of the sun along its vertical and
the anti-sun pair antipodal to them (``zeta_Ara = -1 / conj(zeta_Bre)``,
``zeta_4 = -1 / conj(zeta_Bab)``). The polarization direction makes the plane angle
``alpha = arg(w exp(-2 i beta_sun)) / 2`` (the factor makes the pattern turn with the sun).

Degree of polarization (:data:`DOP_MAPPINGS`, ``dop_mapping=``):

- ``"paper"`` (default): ``d_max |w|``, the paper's reading of ``|w|`` as the (unnormalised)
  degree of polarization [1]_, sect. 3; for ``delta = 0`` it is ``d_max sin^2 g``;
- ``"rayleigh"``: ``d_max |w| / (2 - |w|)``, which for ``delta = 0`` is exactly the Rayleigh
  ``d_max sin^2 g / (1 + cos^2 g)`` since then ``|w| = sin^2 g`` (the form of some public
  implementations of the model). Both have the same zeros (the neutral points), the same
  maximum ``d_max`` (at ``|w| = 1``) and the same AoP.

Left out: the horizon depolarization of the later work on the model (no primary formula was
available to this project); the radiance ``I`` is the single-scattering relative radiance
``(3/4)(1 + cos^2 g)`` of :mod:`skysim.rayleigh` (the model describes polarization only).

References
----------
.. [1] M. V. Berry, M. R. Dennis, R. L. Lee Jr, "Polarization singularities in the clear sky",
   New J. Phys. 6:162 (2004), doi:10.1088/1367-2630/6/1/162.
"""

from __future__ import annotations

import numpy as np

from . import rayleigh
from .geometry import wrap_axial_deg
from .sky import Sky
from .validation import TWILIGHT_LIMIT_DEG, check_dop, check_in_range

__all__ = ["BerrySky", "DOP_MAPPINGS", "berry_polarization", "berry_w", "singularities",
           "stereographic"]

DOP_MAPPINGS = ("paper", "rayleigh")
"""Maps from ``|w|`` to DoP: ``paper`` ``d_max |w|`` ([1]_, sect. 3), ``rayleigh``
``d_max |w| / (2 - |w|)`` (exactly Rayleigh for coincident singularities)."""


def _check_mapping(dop_mapping: str) -> str:
    if dop_mapping not in DOP_MAPPINGS:
        raise ValueError(f"unknown dop_mapping {dop_mapping!r}; valid: {', '.join(DOP_MAPPINGS)}")
    return dop_mapping


def stereographic(elevation_deg, azimuth_deg) -> np.ndarray:
    """``zeta = tan(theta/2) exp(i (90 deg - azimuth))`` for directions (upper hemisphere in the
    unit disc, zenith at 0; directions below the horizon map outside it)."""
    theta = np.radians(90.0 - np.asarray(elevation_deg, dtype=float))
    beta = np.radians(90.0 - np.asarray(azimuth_deg, dtype=float))
    return np.tan(theta / 2.0) * np.exp(1j * beta)


def _pair_parameters(sun_elevation_deg, sun_azimuth_deg, delta_deg):
    """Signed ``t = tan(theta / 2)`` of Babinet and Brewster and the unit vector ``u`` of the
    sun's azimuth in the plane: ``zeta_Bab = t_bab u``, ``zeta_Bre = t_bre u``."""
    sun_theta = 90.0 - np.asarray(sun_elevation_deg, dtype=float)
    u = np.exp(1j * np.radians(90.0 - np.asarray(sun_azimuth_deg, dtype=float)))
    half = 0.5 * np.asarray(delta_deg, dtype=float)
    return (np.tan(np.radians(sun_theta - half) / 2.0), np.tan(np.radians(sun_theta + half) / 2.0),
            u)


def singularities(sun_elevation_deg, sun_azimuth_deg, delta_deg) -> dict:
    """Stereographic positions of the Babinet, Brewster, Arago and fourth points ([1]_, sect. 3).

    Babinet and Brewster lie ``delta/2`` above and below the sun on its vertical; Arago and the
    fourth point are the antipodes of Brewster and Babinet (the fourth point is at infinity,
    the nadir, when Babinet is at the zenith).
    """
    t_bab, t_bre, u = _pair_parameters(sun_elevation_deg, sun_azimuth_deg, delta_deg)
    with np.errstate(divide="ignore", invalid="ignore"):
        fourth = np.where(t_bab != 0, -u / np.where(t_bab != 0, t_bab, 1.0), np.inf)
    return {"babinet": t_bab * u, "brewster": t_bre * u, "arago": -u / t_bre, "fourth": fourth}


def berry_w(zeta, sun_elevation_deg, sun_azimuth_deg, delta_deg) -> np.ndarray:
    """Berry et al.'s complex polarization function ``w(zeta)`` ([1]_, eqs. (3.1)-(3.3)).

    Each antipodal factor is written in a form that stays finite when the antipode goes to
    infinity: with ``zeta_k = t u``, ``(zeta + u/t) / |t u + u/t| = (t zeta + u)/(1 + t^2)``
    for ``t > 0`` (the published form), continued to ``t <= 0`` (Babinet at or beyond the
    zenith, sun higher than 90 - delta/2) without the sign jump of the published form.
    """
    t_bab, t_bre, u = _pair_parameters(sun_elevation_deg, sun_azimuth_deg, delta_deg)
    return (-4.0 * (zeta - t_bab * u) * (zeta - t_bre * u)
            * (t_bab * zeta + u) / (1.0 + t_bab**2) * (t_bre * zeta + u) / (1.0 + t_bre**2)
            / (1.0 + np.abs(zeta) ** 2) ** 2)


def berry_polarization(view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                       sun_azimuth_deg, delta_deg, dmax=1.0,
                       dop_mapping: str = "paper") -> tuple[np.ndarray, np.ndarray]:
    """Degree of polarization and AoP [deg] of the Berry-Dennis-Lee sky.

    Parameters
    ----------
    view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg : array-like
        Directions [deg] (azimuth clockwise from north); broadcast.
    delta_deg : float or array-like
        Angular separation [deg] of the two singularities near the sun (and of the two near
        the anti-sun); 0 gives the Rayleigh sky.
    dmax : float
        Maximum degree of polarization.
    dop_mapping : {"paper", "rayleigh"}
        ``d_max |w|`` (the paper) or ``d_max |w| / (2 - |w|)`` (module docstring).

    Returns
    -------
    dop : ndarray, in [0, dmax]
    aop_deg : ndarray, in [-90, 90)
        From the local meridian (towards the zenith) positive towards increasing azimuth
        (``docs/conventions.md``). The meridian is at plane angle ``270 deg - azimuth`` in the
        stereographic plane (pointing to the zenith) and ``e_az`` 90 deg counter-clockwise
        from it (the map is conformal and keeps the orientation seen from above).
    """
    zeta = stereographic(view_elevation_deg, view_azimuth_deg)
    w = berry_w(zeta, sun_elevation_deg, sun_azimuth_deg, delta_deg)
    beta_sun = np.radians(90.0 - np.asarray(sun_azimuth_deg, dtype=float))
    alpha = 0.5 * np.degrees(np.angle(w * np.exp(-2j * beta_sun)))
    meridian = 270.0 - np.asarray(view_azimuth_deg, dtype=float)
    # at the zenith the "meridian" is that of the stated view azimuth, as everywhere in skysim
    aop = wrap_axial_deg(alpha - meridian)
    m = np.clip(np.abs(w), 0.0, 1.0)
    if _check_mapping(dop_mapping) == "rayleigh":
        m = m / (2.0 - m)
    return dmax * m, aop


class BerrySky(Sky):
    """The Berry, Dennis & Lee (2004) singularity model as a :class:`~skysim.sky.Sky`.

    Parameters
    ----------
    delta_deg : float
        Separation [deg] of the singularity pairs, in [0, 90); the default 40 deg puts each
        neutral point 20 deg from the sun or anti-sun, as in the multiple-scattering sky of
        :mod:`skysim.multiple` at tau = 0.25 (Babinet 19.5 deg above and Brewster 22.7 deg
        below a sun at 23.6 deg; Babinet 17.8 and Brewster 22.3 deg at 30 deg).
        :func:`skysim.neutral_points.neutral_points` gives the values for any sun, tau and
        albedo (``experiments.physical_sky.berry_delta_from`` turns them into delta).
    dmax : float
        Maximum degree of polarization, in (0, 1].
    dop_mapping : {"paper", "rayleigh"}
        ``|w|`` to DoP (module docstring); default the paper's ``d_max |w|``.

    Notes
    -----
    ``I`` is the relative single-scattering radiance ``(3/4)(1 + cos^2 g)``.
    """

    name = "berry"
    min_sun_elevation_deg = TWILIGHT_LIMIT_DEG   # a single-scattering pattern: holds in twilight

    def __init__(self, delta_deg: float = 40.0, dmax: float = 1.0, dop_mapping: str = "paper"):
        self.delta_deg = float(check_in_range("delta_deg", delta_deg, 0.0, 90.0, high_open=True,
                                              hint="neutral points lie 0-45 deg from the sun"))
        if dmax != 1.0:
            check_dop("dmax", dmax)
        self.dmax = float(dmax)
        self.dop_mapping = _check_mapping(dop_mapping)

    def _stokes(self, vel, vaz, sel, saz):
        dop, aop = berry_polarization(vel, vaz, sel, saz, self.delta_deg, self.dmax,
                                       self.dop_mapping)
        intensity = rayleigh.relative_radiance(rayleigh.scattering_angle_deg(vel, vaz, sel, saz))
        chi = np.radians(aop)
        return intensity, intensity * dop * np.cos(2 * chi), intensity * dop * np.sin(2 * chi)

    def describe(self) -> dict:
        return {"model": self.name, "delta_deg": self.delta_deg, "dmax": self.dmax,
                "dop_mapping": self.dop_mapping,
                "I": "relative single-scattering radiance (3/4)(1 + cos^2 g)"}
