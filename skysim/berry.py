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

Degree of polarization: ``d_max |w| / (2 - |w|)``. Berry et al. call ``|w|`` the *intensity
of polarization (unnormalized degree)* [1]_ (abstract): it plays the part of the polarized
radiance, not of the degree. For ``delta = 0`` the four singularities merge into the sun and
the anti-sun and ``|w| = sin^2 g`` (``g`` the angle from the sun), the Rayleigh polarized
radiance; ``2 - |w| = 1 + cos^2 g`` is then the Rayleigh radiance, so the ratio is exactly the
Rayleigh degree ``sin^2 g / (1 + cos^2 g)``. The public implementations of the model use
the same mapping: pyskylumos [2]_ (``absolute(omega) / (2 - absolute(omega))``) and OpenSky
[3]_ (``DoLP_Max * abs(W) / (2 - abs(W))``, Python and Matlab). It is zero at the four
singularities, ``d_max`` where ``|w| = 1`` and acts on ``|w|`` only, so the AoP is that of
``arg w``. ``d_max |w|`` alone is not offered: no source uses ``|w|`` as a degree (the paper
calls it unnormalized), and for ``delta = 0`` it gives ``sin^2 g``, not the Rayleigh degree.

Not modelled: the depolarization near the horizon. Berry et al. state that the intensity of
polarization needs "the strong depolarizing effect of multiple scattering near the horizon"
[1]_ (abstract) and compare the corrected intensity of polarization with sky images. That
correction is not reproduced here: its functional form and fitted parameters were not
available to be verified against the paper's equations, and neither public implementation
[2]_ [3]_ carries one, so none is invented. The DoP of this model is
therefore too high near the horizon; :class:`skysim.multiple.MultipleScatteringSky` (``model=
"multiple"``) gives a horizon-aware DoP. The radiance ``I`` is the single-scattering relative
radiance ``(3/4)(1 + cos^2 g)`` of :mod:`skysim.rayleigh` (the model describes polarization
only).

References
----------
.. [1] M. V. Berry, M. R. Dennis, R. L. Lee Jr, "Polarization singularities in the clear sky",
   New J. Phys. 6:162 (2004), doi:10.1088/1367-2630/6/1/162.
.. [2] pyskylumos, ``src/pyskylumos/sky_models/Berry.py`` (``Berry.__get_dop``),
   https://github.com/taciochi/pyskylumos.
.. [3] OpenSky, ``Python/Simu_Berry.py`` and ``Matlab_version/Simu_Berry.m``,
   https://github.com/ALGSS/OpenSky.
"""

from __future__ import annotations

import numpy as np

from . import rayleigh
from .geometry import wrap_axial_deg
from .sky import Sky
from .validation import TWILIGHT_LIMIT_DEG, check_dop, check_in_range

__all__ = ["BerrySky", "berry_polarization", "berry_w", "singularities", "stereographic"]


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
                       sun_azimuth_deg, delta_deg, dmax=1.0) -> tuple[np.ndarray, np.ndarray]:
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

    Returns
    -------
    dop : ndarray, in [0, dmax]
        ``dmax |w| / (2 - |w|)`` (module docstring); for ``delta_deg = 0`` the Rayleigh
        ``dmax sin^2 g / (1 + cos^2 g)``.
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
    return dmax * m / (2.0 - m), aop


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
        albedo (``experiments.studies.physical_sky.berry_delta_from`` turns them into delta).
    dmax : float
        Maximum degree of polarization, in (0, 1].

    Notes
    -----
    DoP ``dmax |w| / (2 - |w|)``, no horizon depolarization (module docstring). ``I`` is the
    relative single-scattering radiance ``(3/4)(1 + cos^2 g)``.
    """

    name = "berry"
    min_sun_elevation_deg = TWILIGHT_LIMIT_DEG   # a single-scattering pattern: holds in twilight

    def __init__(self, delta_deg: float = 40.0, dmax: float = 1.0):
        self.delta_deg = float(check_in_range("delta_deg", delta_deg, 0.0, 90.0, high_open=True,
                                              hint="neutral points lie 0-45 deg from the sun"))
        if dmax != 1.0:
            check_dop("dmax", dmax)
        self.dmax = float(dmax)

    def _stokes(self, vel, vaz, sel, saz):
        dop, aop = berry_polarization(vel, vaz, sel, saz, self.delta_deg, self.dmax)
        intensity = rayleigh.relative_radiance(rayleigh.scattering_angle_deg(vel, vaz, sel, saz))
        chi = np.radians(aop)
        return intensity, intensity * dop * np.cos(2 * chi), intensity * dop * np.sin(2 * chi)

    def flux_pi_scale(self, view_elevation_deg, sun_elevation_deg) -> np.ndarray:
        """As the Rayleigh sky's (``I`` is the same relative radiance):
        :func:`skysim.rayleigh.flux_pi_scale`."""
        return rayleigh.flux_pi_scale(view_elevation_deg, sun_elevation_deg)

    def describe(self) -> dict:
        return {"model": self.name, "delta_deg": self.delta_deg, "dmax": self.dmax,
                "dop": "dmax |w| / (2 - |w|)",
                "I": "relative single-scattering radiance (3/4)(1 + cos^2 g)"}
