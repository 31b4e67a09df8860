"""Incident light of a polarization sensor in lux: sky radiance scaled to illuminance, and water.

The photodiode model (:mod:`sensor.photodiode`) takes the incident intensity in *lux
equivalent*: the illuminance ``E = pi L`` that a uniform sky of the view direction's luminance
``L`` [cd/m^2] would give on a horizontal plane (the responsivity ``K_I`` [A/lx] of
:class:`sensor.photodiode.PhotodiodeChannels` and the integrating-sphere reference are stated
in the same unit). This module produces that quantity, with the angle and degree of
polarization, for any :class:`skysim.sky.Sky`.

**Air.** A sky model gives the Stokes vector ``(I, Q, U)`` of each view direction in a model
unit. Its horizontal diffuse illuminance is the hemispheric integral
``H = int I cos(theta) dOmega`` (:func:`hemispheric_integral`, Gauss-Legendre in
``mu = cos theta`` times the periodic trapezoid rule in azimuth). The absolute scale comes from
the clear-sky daylight-availability model of the IES [1]_ (:func:`clear_sky_illuminance_lx`)::

    E_dn = E_xn exp(-c m),  m = 1 / sin(h)                 direct normal  (IES eq. 9)
    E_kh = A + B sin(h)^C,  A = 0.8 klx, B = 15.5 klx, C = 0.5 (clear)  diffuse horizontal
    E_gh = E_dn sin(h) + E_kh                               global horizontal
    E_xn = E_sc (1 + 0.034 cos(2 pi (J - 2) / 365)),  E_sc = 127.5 klx,  c = 0.21 (clear)

so that the luminance is ``L = I E_kh / H`` [cd/m^2] and the lux equivalent ``pi L``
(:func:`sky_light`).

**Water** (:func:`underwater_light`, flat surface, sensor looking up). A view at zenith angle
``theta_w`` under water sees the sky at ``theta_a`` with ``sin(theta_a) = n sin(theta_w)``
(Snell's law [2]_): the whole sky is compressed into Snell's window of half angle
``asin(1/n)`` = 48.3 deg for ``n = 1.34`` (:func:`air_zenith_deg`); the zenith view is not
deflected. The surface transmits the Stokes vector by the Fresnel Mueller matrix [2]_
(:func:`fresnel_transmittance`, :func:`fresnel_transmit_stokes`); in the local-meridian basis
the plane of incidence is the meridian plane, so ``Q > 0`` is p-polarised. The ``n^2`` gain of
radiance entering water is undone when the light leaves the water into the sensor's internal
air gap behind a flat window (radiance ``/ n^2`` [3]_), so the lux equivalent is the air value
times the Fresnel transmittance. With depth ``z`` [m] the light is attenuated by
Beer-Lambert's law with the diffuse attenuation coefficient ``K_d`` [1/m] [3]_::

    E(z) = E(0-) exp(-K_d z)

(the zenith radiance decays with the radiance attenuation coefficient, which equals ``K_d``
in the asymptotic regime and is close to it above [3]_). The *polarized* part
``(Q, U)`` is modelled as the unscattered transmitted skylight, attenuated with the beam
attenuation coefficient ``c`` [1/m] (scattered light taken as unpolarized), so the degree
of polarization falls as::

    d(z) = d(0-) exp(-(c - K_d) z)                         (:func:`depolarization_factor`)

a first-order model of the decrease of underwater DoP with depth and turbidity observed by
Ivanoff & Waterman [4]_ and within Snell's window by Cronin & Shashar [5]_; it ignores the
in-water single-scattering polarization (which, away from the refracted sun, keeps the DoP of
deep clear water at ~0.1-0.3 [4]_), so it is a lower bound on the DoP at depth.

Water types (:data:`WATER_TYPES`): representative ``K_d`` and ``c`` near 480 nm (the blue
band of the sensor) for Jerlov's oceanic type I (clear ocean), coastal type 3 (coastal) and
coastal type 9 (turbid) [6]_, [7]_.

References
----------
.. [1] IES Daylighting Committee, "Recommended practice for the calculation of daylight
   availability", J. Illum. Eng. Soc. 13(4):381-392 (1984),
   doi:10.1080/00994480.1984.10748791 (clear-sky E_dn, E_kh; E_sc = 127.5 klx, c = 0.21,
   A = 0.8 klx, B = 15.5 klx, C = 0.5).
.. [2] M. Born, E. Wolf, Principles of Optics, 7th ed., Cambridge (1999), sect. 1.5.2-1.5.3
   (Snell's law, Fresnel formulae, transmissivity ``T = n cos(theta_t)/cos(theta_i) t^2``).
.. [3] C. D. Mobley, Light and Water: Radiative Transfer in Natural Waters, Academic Press
   (1994), sect. 3.3 (``K_d``, Beer-Lambert decay of irradiance), 4.3 (the ``n^2`` law of
   radiance at an interface), 9.3 (asymptotic radiance).
.. [4] A. Ivanoff, T. H. Waterman, "Factors, mainly depth and wavelength, affecting the degree
   of underwater light polarization", J. Marine Research 16(3):283-307 (1958).
.. [5] T. W. Cronin, N. Shashar, "The linearly polarized light field in clear, tropical marine
   waters: spatial and temporal variation of light intensity, degree of polarization and
   e-vector angle", J. Exp. Biol. 204:2461-2467 (2001).
.. [6] N. G. Jerlov, Marine Optics, Elsevier Oceanography Series 14 (1976), ch. 10 (water
   types, ``K_d`` of the types I-III and coastal 1-9).
.. [7] M. G. Solonenko, C. D. Mobley, "Inherent optical properties of Jerlov water types",
   Appl. Opt. 54(17):5392-5401 (2015), doi:10.1364/AO.54.005392 (``a``, ``b``, ``c`` of the
   types).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skysim.exceptions import InvalidParameterError
from skysim.geometry import wrap_axial_deg
from skysim.sky import Sky
from skysim.validation import check_in_range, check_sun_above_horizon

__all__ = ["OutsideSnellWindowError", "SOLAR_ILLUMINANCE_CONSTANT_LX",
           "CLEAR_SKY_EXTINCTION", "CLEAR_SKY_DIFFUSE_LX", "REFRACTIVE_INDEX_SEAWATER",
           "WaterType", "WATER_TYPES", "ClearSkyIlluminance", "IncidentLight",
           "clear_sky_illuminance_lx", "hemispheric_integral", "sky_light", "air_zenith_deg",
           "snell_window_half_angle_deg", "fresnel_transmittance", "fresnel_transmit_stokes",
           "beer_lambert", "depolarization_factor", "water_type", "underwater_light"]

SOLAR_ILLUMINANCE_CONSTANT_LX = 127_500.0
"""Solar illuminance constant ``E_sc`` [lx] of the IES model [1]_."""
CLEAR_SKY_EXTINCTION = 0.21
"""Clear-sky atmospheric extinction coefficient ``c`` per air mass of the IES model [1]_."""
CLEAR_SKY_DIFFUSE_LX = (800.0, 15_500.0, 0.5)
"""``(A [lx], B [lx], C)`` of the clear-sky diffuse horizontal illuminance ``A + B sin^C h``
[1]_."""
REFRACTIVE_INDEX_SEAWATER = 1.34
"""Refractive index of sea water near 480 nm, 20 degC, 35 PSU (Quan & Fry, Appl. Opt.
34:3477 (1995), doi:10.1364/AO.34.003477: 1.3390 at 589 nm, +0.004 in the blue)."""


class OutsideSnellWindowError(InvalidParameterError):
    """An underwater view direction lies outside Snell's window: no skylight reaches it
    through a flat surface (total internal reflection), it sees upwelling light reflected from
    below. Keep the underwater view zenith angle below ``asin(1/n)`` (48.3 deg for n = 1.34)."""


@dataclass(frozen=True)
class WaterType:
    """Optical properties of a water body near 480 nm.

    Attributes
    ----------
    name : str
    diffuse_attenuation_per_m : float
        ``K_d`` [1/m] (downwelling irradiance).
    beam_attenuation_per_m : float
        ``c = a + b`` [1/m] (absorption plus scattering), ``>= K_d``.
    reference : str
    """

    name: str
    diffuse_attenuation_per_m: float
    beam_attenuation_per_m: float
    reference: str = ""

    def __post_init__(self):
        kd = float(check_in_range("diffuse_attenuation_per_m", self.diffuse_attenuation_per_m,
                                  0.0, np.inf, low_open=True))
        c = float(check_in_range(
            "beam_attenuation_per_m", self.beam_attenuation_per_m, kd, np.inf,
            hint="the beam attenuation c = a + b is never below K_d (scattered light only "
                 "adds to the diffuse field)"))
        object.__setattr__(self, "diffuse_attenuation_per_m", kd)
        object.__setattr__(self, "beam_attenuation_per_m", c)


WATER_TYPES = {
    "clear_ocean": WaterType("clear_ocean", 0.03, 0.05,
                             "Jerlov oceanic type I at 475-490 nm [6]_, [7]_"),
    "coastal": WaterType("coastal", 0.2, 1.0, "Jerlov coastal type 3 at 475-490 nm [6]_, [7]_"),
    "turbid": WaterType("turbid", 1.0, 4.0, "Jerlov coastal type 9 at 475-490 nm [6]_, [7]_"),
}
"""Representative water types (order-of-magnitude values of the cited tables)."""


@dataclass(frozen=True)
class ClearSkyIlluminance:
    """Clear-sky illuminances [lx] of the IES model [1]_: direct normal, diffuse horizontal,
    global horizontal."""

    direct_normal_lx: np.ndarray
    diffuse_horizontal_lx: np.ndarray
    global_horizontal_lx: np.ndarray


@dataclass(frozen=True)
class IncidentLight:
    """Light arriving at a sensor along one view direction.

    Attributes
    ----------
    illuminance_lx : ndarray
        Lux equivalent ``pi L`` [lx] (``L`` the luminance in cd/m^2), the ``intensity`` of
        :mod:`sensor.photodiode`.
    aop_deg : ndarray
        Angle of polarization [deg, in [-90, 90)] in the local-meridian basis of the view.
    dop : ndarray
        Degree of linear polarization.
    """

    illuminance_lx: np.ndarray
    aop_deg: np.ndarray
    dop: np.ndarray


def _day_of_year(day_of_year):
    if day_of_year is None:
        return None
    return check_in_range("day_of_year", day_of_year, 1.0, 366.0,
                          hint="day of the year J, 1 = 1 January")


def clear_sky_illuminance_lx(sun_elevation_deg, day_of_year=None) -> ClearSkyIlluminance:
    """Clear-sky direct normal, diffuse and global horizontal illuminance [lx] (IES 1984 [1]_).

    Parameters
    ----------
    sun_elevation_deg : array-like
        Sun elevation ``h`` [deg], > 0.
    day_of_year : array-like, optional
        ``J`` in [1, 366] for the orbital eccentricity term ``1 + 0.034 cos(2 pi (J-2)/365)``;
        ``None`` uses the mean ``E_sc``.

    Returns
    -------
    ClearSkyIlluminance

    Raises
    ------
    SunBelowHorizonError
        If a sun elevation is <= 0 deg (the model is for daylight).
    """
    h = np.radians(check_sun_above_horizon(sun_elevation_deg))
    J = _day_of_year(day_of_year)
    e_xn = SOLAR_ILLUMINANCE_CONSTANT_LX * (
        1.0 if J is None else 1.0 + 0.034 * np.cos(2.0 * np.pi * (J - 2.0) / 365.0))
    s = np.sin(h)
    direct = e_xn * np.exp(-CLEAR_SKY_EXTINCTION / s)
    a, b, c = CLEAR_SKY_DIFFUSE_LX
    diffuse = a + b * s ** c
    return ClearSkyIlluminance(direct, diffuse, direct * s + diffuse)


def hemispheric_integral(sky: Sky, sun_elevation_deg, sun_azimuth_deg, *, n_mu: int = 24,
                         n_azimuth: int = 48) -> np.ndarray:
    """``H = int I cos(theta) dOmega`` over the upper hemisphere [model unit x sr].

    Gauss-Legendre in ``mu = cos(theta)`` on (0, 1) (``n_mu`` nodes) times the trapezoid rule
    in azimuth (``n_azimuth`` nodes; spectrally accurate for a periodic integrand). Exact for a
    uniform sky (``H = pi I``) and, with the default nodes, to ~1e-12 for the Rayleigh sky
    (``H = (3 pi/16)(5 + sin^2 h)``, tested).

    Parameters
    ----------
    sky : skysim.sky.Sky
    sun_elevation_deg, sun_azimuth_deg : array-like
        Sun position(s) [deg], broadcast together; the result has their shape.
    n_mu, n_azimuth : int
        Quadrature nodes.
    """
    el, az = np.broadcast_arrays(np.asarray(sun_elevation_deg, dtype=float),
                                 np.asarray(sun_azimuth_deg, dtype=float))
    x, w = np.polynomial.legendre.leggauss(int(n_mu))
    mu, w_mu = 0.5 * (x + 1.0), 0.5 * w
    psi = np.linspace(0.0, 360.0, int(n_azimuth), endpoint=False)
    view_el = np.degrees(np.arcsin(mu))[:, None]
    f = sky.field(view_el, psi[None, :], el[..., None, None], az[..., None, None])
    return (2.0 * np.pi / n_azimuth) * np.einsum("...ij,i->...", f.I * mu[:, None], w_mu)


def sky_light(sky: Sky, view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
              sun_azimuth_deg, *, day_of_year=None) -> IncidentLight:
    """Lux equivalent, AoP and DoP of the sky along view directions, scaled by the clear-sky
    diffuse horizontal illuminance of [1]_ (module docstring).

    ``pi L = pi I E_kh(h) / H`` with ``H`` from :func:`hemispheric_integral`; a uniform sky
    therefore gives ``E_kh`` for every view direction. Inputs broadcast; ``H`` is evaluated
    once per distinct sun position.

    Returns
    -------
    IncidentLight

    Raises
    ------
    SunBelowHorizonError, InvalidParameterError
        As :meth:`skysim.sky.Sky.field`.
    """
    f = sky.field(view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg)
    sun = np.stack(np.broadcast_arrays(np.asarray(sun_elevation_deg, dtype=float),
                                       np.asarray(sun_azimuth_deg, dtype=float)), axis=-1)
    uniq, inverse = np.unique(sun.reshape(-1, 2), axis=0, return_inverse=True)
    H = hemispheric_integral(sky, uniq[:, 0], uniq[:, 1])[inverse.ravel()].reshape(
        sun.shape[:-1])
    e_kh = clear_sky_illuminance_lx(sun[..., 0], day_of_year).diffuse_horizontal_lx
    return IncidentLight(np.pi * f.I * e_kh / H, f.aop_deg, f.dop)


def snell_window_half_angle_deg(n=REFRACTIVE_INDEX_SEAWATER) -> np.ndarray:
    """Half angle of Snell's window ``asin(1/n)`` [deg] [2]_."""
    n = check_in_range("n", n, 1.0, np.inf, hint="refractive index of the water (1.33-1.34)")
    return np.degrees(np.arcsin(1.0 / n))


def air_zenith_deg(water_zenith_deg, n=REFRACTIVE_INDEX_SEAWATER) -> np.ndarray:
    """Zenith angle in air [deg] of the sky seen at ``water_zenith_deg`` below a flat surface:
    ``sin(theta_a) = n sin(theta_w)`` (Snell [2]_).

    Raises
    ------
    OutsideSnellWindowError
        If ``n sin(theta_w) >= 1`` (outside Snell's window).
    """
    tw = check_in_range("water_zenith_deg", water_zenith_deg, 0.0, 90.0,
                        hint="zenith angle of an upward view under water")
    n = check_in_range("n", n, 1.0, np.inf)
    s = n * np.sin(np.radians(tw))
    bad = s >= 1.0
    if bad.any():
        i = int(np.flatnonzero(bad.ravel())[0])
        raise OutsideSnellWindowError(
            f"underwater view zenith angle {np.broadcast_to(tw, s.shape).ravel()[i]!r} deg is "
            f"outside Snell's window (half angle {np.degrees(np.arcsin(1 / np.max(n))):.2f} "
            "deg): it sees light reflected from below; use a smaller zenith angle")
    return np.degrees(np.arcsin(s))


def fresnel_transmittance(air_zenith_deg, n=REFRACTIVE_INDEX_SEAWATER):
    """Fresnel power transmittances ``(T_s, T_p)`` from air into water [2]_.

    ``t_s = 2 cos i / (cos i + n cos t)``, ``t_p = 2 cos i / (n cos i + cos t)``,
    ``T = n cos t / cos i * t^2``; at normal incidence ``T = 4 n / (n + 1)^2``.

    Parameters
    ----------
    air_zenith_deg : array-like
        Incidence angle ``i`` [deg] in [0, 90).
    n : float
        Refractive index of the water relative to air.
    """
    i = np.radians(check_in_range("air_zenith_deg", air_zenith_deg, 0.0, 90.0,
                                  high_open=True))
    n = check_in_range("n", n, 1.0, np.inf)
    ci = np.cos(i)
    ct = np.sqrt(1.0 - (np.sin(i) / n) ** 2)
    ts = 2.0 * ci / (ci + n * ct)
    tp = 2.0 * ci / (n * ci + ct)
    k = n * ct / ci
    return k * ts ** 2, k * tp ** 2


def fresnel_transmit_stokes(I, Q, U, air_zenith_deg, n=REFRACTIVE_INDEX_SEAWATER):
    """Stokes vector after the air-water surface, local-meridian basis (``Q > 0``: E in the
    meridian = plane of incidence = p) [2]_; radiance per unit of the in-air radiance after
    leaving the water through a flat window (``n^2`` factors cancel, module docstring)::

        I' = ((T_p + T_s) I + (T_p - T_s) Q) / 2
        Q' = ((T_p - T_s) I + (T_p + T_s) Q) / 2
        U' = sqrt(T_p T_s) U
    """
    ts, tp = fresnel_transmittance(air_zenith_deg, n)
    return (0.5 * ((tp + ts) * I + (tp - ts) * Q), 0.5 * ((tp - ts) * I + (tp + ts) * Q),
            np.sqrt(tp * ts) * U)


def beer_lambert(surface_value, depth_m, attenuation_per_m) -> np.ndarray:
    """``E(z) = E(0-) exp(-K z)`` [unit of ``surface_value``] (Beer-Lambert [3]_)."""
    z = check_in_range("depth_m", depth_m, 0.0, np.inf, hint="depth below the surface [m]")
    k = check_in_range("attenuation_per_m", attenuation_per_m, 0.0, np.inf)
    return np.asarray(surface_value, dtype=float) * np.exp(-k * z)


def depolarization_factor(depth_m, water: WaterType) -> np.ndarray:
    """``d(z) / d(0-) = exp(-(c - K_d) z)``: unscattered (polarized) skylight decays with the
    beam attenuation ``c``, total light with ``K_d`` (module docstring, [3]_-[5]_)."""
    return beer_lambert(1.0, depth_m, water.beam_attenuation_per_m
                        - water.diffuse_attenuation_per_m)


def water_type(water) -> WaterType:
    """A :class:`WaterType` or the name of one of :data:`WATER_TYPES`."""
    if isinstance(water, WaterType):
        return water
    if water not in WATER_TYPES:
        raise InvalidParameterError(
            f"unknown water type {water!r}; use one of {', '.join(WATER_TYPES)} or a WaterType")
    return WATER_TYPES[water]


def underwater_light(sky: Sky, water_zenith_deg, view_azimuth_deg, sun_elevation_deg,
                     sun_azimuth_deg, depth_m, water="clear_ocean", *,
                     n=REFRACTIVE_INDEX_SEAWATER, day_of_year=None) -> IncidentLight:
    """Lux equivalent, AoP and DoP seen by an upward-looking sensor at ``depth_m`` [m].

    Snell's window maps the underwater view to the sky at :func:`air_zenith_deg`; the Stokes
    vector of :func:`sky_light` there is transmitted by :func:`fresnel_transmit_stokes`, its
    intensity attenuated with ``K_d`` and its polarized part with ``c`` (module docstring).
    All inputs broadcast.

    Parameters
    ----------
    sky : skysim.sky.Sky
    water_zenith_deg : array-like
        Underwater view zenith angle [deg], inside Snell's window.
    view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg : array-like
        [deg]; the view azimuth is unchanged by refraction.
    depth_m : array-like
        Depth below a flat surface [m], >= 0.
    water : WaterType or str
        See :data:`WATER_TYPES`.
    n : float
        Refractive index of the water.

    Raises
    ------
    OutsideSnellWindowError, SunBelowHorizonError, InvalidParameterError
    """
    w = water_type(water)
    theta_a = air_zenith_deg(water_zenith_deg, n)
    air = sky_light(sky, 90.0 - theta_a, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg,
                    day_of_year=day_of_year)
    two = np.radians(2.0 * air.aop_deg)
    I, Q, U = fresnel_transmit_stokes(air.illuminance_lx, air.illuminance_lx * air.dop
                                      * np.cos(two), air.illuminance_lx * air.dop * np.sin(two),
                                      theta_a, n)
    I_z = beer_lambert(I, depth_m, w.diffuse_attenuation_per_m)
    pol = beer_lambert(np.hypot(Q, U), depth_m, w.beam_attenuation_per_m)
    aop = wrap_axial_deg(0.5 * np.degrees(np.arctan2(U, Q)))
    return IncidentLight(*np.broadcast_arrays(I_z, aop, pol / I_z))
