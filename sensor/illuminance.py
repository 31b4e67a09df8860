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

    E(z) = E(0-) exp(-K_d(lambda) z)

(the zenith radiance decays with the radiance attenuation coefficient, which equals ``K_d``
in the asymptotic regime and is close to it above [3]_). ``K_d(lambda)`` is Jerlov's Table
XXVII [6]_ (:data:`JERLOV_KD_PER_M`, 350-700 nm in 25 nm steps, linear interpolation in
wavelength: :func:`jerlov_kd`); the wavelength is an input (default 480 nm, the blue band
of the sensor).

**Polarization under water** (:func:`underwater_polarization`). The light seen looking up
is the sum of two parts:

- the *transmitted skylight* (the compressed sky pattern of Snell's window after the Fresnel
  surface), whose share of the radiance falls with depth as ``f(z) = exp(-kappa_p z)``
  (:func:`transmitted_fraction`), with ``kappa_p`` [1/m] the decay rate of the polarization
  of a directly viewed source measured by Shashar, Sabbah & Cronin [7]_ (half of the
  partial polarization lost over 1.25-3 m in clear reef water);
- the light *scattered in the water* from the refracted sun (at zenith angle
  ``asin(cos(h)/n)``), polarized by single scattering as in the model of Lerner, Sabbah,
  Erlick & Shashar [8]_ (refraction at the surface + Rayleigh single scattering; in clear
  oceanic water the measured DoP and AoP "are largely determined by an in-water
  single-scattering model", You et al. [11]_)::

      d_w(Theta) = P_max sin^2(Theta) / (1 + cos^2(Theta)),   E-vector normal to the
      plane through the view direction and the refracted sun,

  with ``Theta`` the angle between the view and the refracted sun, ``P_max`` per water type.

The polarized parts add as Stokes vectors (per unit radiance)::

    (q + i u)(z) = f(z) (q + i u)_sky + (1 - f(z)) d_w exp(2 i chi_w)

so at the surface the DoP is that of the transmitted sky and within metres it tends to the
in-water single-scattering value, which the model then keeps (the in-water light field
re-polarizes itself over the few metres where the model is validated, below): Ivanoff &
Waterman [4]_ and Cronin & Shashar [5]_ report DoP of ~0.1-0.3 below the surface; the coastal
measurements of Tonizzo et al. [9]_ peak near 100 deg scattering angle and never exceed 0.4
(tested against both). For a zenith view both parts have the E-vector normal to the solar
meridian.

**Where the polarization model holds** (:attr:`WaterType.polarization_validated_depth_m`,
:class:`DepthBeyondValidationWarning`). Lerner et al. [8]_ compared the refraction + single
scattering model with measurements at 2 m and 5 m depth in clear and semi-turbid coastal
water: the DoP followed the sun's elevation only in clear water, and the E-vector pattern
matched mainly near the horizontal viewing direction; they conclude that the model, and
navigation by it, hold under restricted conditions: clear water, near-horizontal views, little
influence of the sea floor. The transmitted share ``kappa_p`` comes from paths of 1.25-3 m
[7]_, and Shashar et al. [12]_ find sky-pattern navigation limited to shallow water even in
clear ocean. The model is therefore supported from the surface down to 5 m in clear water
(``clear_ocean``) and at the surface only in coastal and turbid water; deeper,
:func:`underwater_polarization` and :func:`underwater_light` still return the model's values
but warn with :class:`DepthBeyondValidationWarning`. What the model misses there is known:
it keeps the in-water single-scattering DoP at every depth, whereas with depth the radiance
distribution tends to the asymptotic one, independent of the sun's position and symmetric
about the vertical (Mobley [3]_, sect. 9.3), so that by symmetry the DoP of the zenith view
tends to zero. Beyond the validated depth the model's zenith DoP is an upper bound on what
the sources support, not an estimate. For upward views inside Snell's window (the views of
:func:`underwater_light`) the AoP at the zenith is normal to the solar meridian by symmetry
in both parts; their DoP is the model's less tested output.

The first-order model ``d(z) = d(0-) exp(-(c - K_d) z)`` (polarized part attenuated with the
beam attenuation ``c``, scattered light unpolarized) is the transmitted part alone; it holds
for a directly viewed polarized source (the measurement of [7]_), not for the ambient light
field, whose DoP it would drive to zero within metres.

Water types (:data:`WATER_TYPES`): Jerlov's oceanic type I (``clear_ocean``), coastal type 3
(``coastal``) and coastal type 9 (``turbid``) [6]_ for ``K_d``; ``P_max`` and ``kappa_p`` in
:class:`WaterType`.

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
.. [6] N. G. Jerlov, Marine Optics, 2nd ed., Elsevier Oceanography Series 14 (1976),
   Table XXVII p. 135 (downward irradiance attenuation coefficient of the water types
   I-III and coastal 1-9, 310-700 nm).
.. [7] N. Shashar, S. Sabbah, T. W. Cronin, "Transmission of linearly polarized light in
   seawater: implications for polarization signaling", J. Exp. Biol. 207:3619-3628 (2004),
   doi:10.1242/jeb.01187 (partial polarization halves over 1.25-3 m in clear reef water).
.. [8] A. Lerner, S. Sabbah, C. Erlick, N. Shashar, "Navigation by light polarization in
   clear and turbid waters", Phil. Trans. R. Soc. B 366:671-679 (2011),
   doi:10.1098/rstb.2010.0189 (refraction + Rayleigh single-scattering model compared with
   measurements at 2 m and 5 m depth over sea floors of 6 m and 28 m; the DoP follows the
   sun only in clear water, the E-vector mainly near the horizontal viewing direction).
.. [9] A. Tonizzo, J. Zhou, A. Gilerson et al., "Polarized light in coastal waters:
   hyperspectral and multiangular analysis", Opt. Express 17(7):5666-5683 (2009),
   doi:10.1364/OE.17.005666 (maximum DoP <= 0.4, near 100 deg scattering angle).
.. [10] A. Ibrahim, A. Gilerson, T. Harmel et al., "The relationship between upwelling
   underwater polarization and attenuation/absorption ratio", Opt. Express
   20(23):25662-25680 (2012), doi:10.1364/OE.20.025662 (DoP falls as c/a rises).
.. [11] Y. You, A. Tonizzo, A. A. Gilerson et al., "Measurements and simulations of
   polarization states of underwater light in clear oceanic waters", Appl. Opt.
   50(24):4873-4893 (2011), doi:10.1364/AO.50.004873.
.. [12] N. Shashar, S. Johnsen, A. Lerner et al., "Underwater linear polarization: physical
   limitations to biological functions", Phil. Trans. R. Soc. B 366:649-654 (2011),
   doi:10.1098/rstb.2010.0190 (in clear oceanic water, navigation by the sky's polarization
   pattern appears limited to shallow water).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from skysim.exceptions import InvalidParameterError, SkysimWarning
from skysim.geometry import wrap_axial_deg
from skysim.sky import RayleighSky, Sky
from skysim.validation import check_dop, check_in_range, check_sun_above_horizon

__all__ = ["DepthBeyondValidationWarning", "OutsideSnellWindowError",
           "SOLAR_ILLUMINANCE_CONSTANT_LX", "CLEAR_SKY_EXTINCTION", "CLEAR_SKY_DIFFUSE_LX",
           "REFRACTIVE_INDEX_SEAWATER",
           "WaterType", "WATER_TYPES", "ClearSkyIlluminance", "IncidentLight",
           "clear_sky_illuminance_lx", "hemispheric_integral", "sky_light", "air_zenith_deg",
           "snell_window_half_angle_deg", "fresnel_transmittance", "fresnel_transmit_stokes",
           "beer_lambert", "JERLOV_WAVELENGTHS_NM", "JERLOV_KD_PER_M", "jerlov_kd",
           "refracted_sun_elevation_deg", "transmitted_fraction", "in_water_polarization",
           "check_validated_depth", "CLEAR_WATER_VALIDATED_DEPTH_M",
           "underwater_polarization", "water_type", "underwater_light",
           "DEFAULT_WAVELENGTH_NM"]

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


class DepthBeyondValidationWarning(SkysimWarning):
    """Underwater polarization asked for deeper than its sources compared the model with
    measurements (:attr:`WaterType.polarization_validated_depth_m`; module docstring): the
    model keeps the in-water single-scattering DoP, while the zenith DoP of the asymptotic
    light field tends to zero. Stay within the validated depth, or treat the DoP there as an
    upper bound."""


DEFAULT_WAVELENGTH_NM = 480.0
"""Default wavelength [nm] of the water optics: the blue band of the sensor."""

_JERLOV_TABLE_XXVII = """
        350   375   400   425   450   475   500   525   550   575   600   625   650   675   700
I       6.2   3.8   2.8   2.2   1.9   1.8   2.7   4.3   6.3   8.9  23.5  30.5  36    42    56
IA      7.8   5.2   3.8   3.1   2.6   2.5   3.2   4.8   6.7   9.4  24    31    37    43    57
IB     10     6.6   5.1   4.2   3.6   3.3   4.2   5.4   7.2   9.9  24.5  31.5  37.5  43.5  58
II     17.5  12.2   9.6   8.1   6.8   6.2   7.0   7.6   8.9  11.5  26    33.5  40    46.5  61
III    32    22    18.5  16    13.5  11.6  11.5  11.6  12    14.8  29.5  37.5  44.5  52    66
1     120    80    51    36    25    17    14    13    12    15    30    37    45    51    65
3     170   110    78    54    39    29    22    20    19    21    33    40    46    56    71
5     230   160   110    78    56    43    36    31    30    33    40    48    54    65    80
7     300   210   160   120    89    71    58    49    46    46    48    54    63    78    92
9     390   300   240   190   160   123    99    78    63    58    60    65    76    92   110
"""
"""Jerlov (1976), Table XXVII, p. 135 [6]_, in the table's unit (100 K_d [1/m]); the 310 nm
column is left out."""


def _parse_jerlov_table(text: str) -> tuple[np.ndarray, dict]:
    lines = text.strip().splitlines()
    return (np.array(lines[0].split(), dtype=float),
            {row.split()[0]: np.array(row.split()[1:], dtype=float) / 100.0
             for row in lines[1:]})


JERLOV_WAVELENGTHS_NM, JERLOV_KD_PER_M = _parse_jerlov_table(_JERLOV_TABLE_XXVII)
"""Wavelengths [nm] of :data:`JERLOV_KD_PER_M` (Jerlov 1976, Table XXVII; its 310 nm column
is left out)."""
"""Downward irradiance attenuation coefficient ``K_d`` [1/m] of Jerlov's water types
(oceanic I, IA, IB, II, III; coastal 1, 3, 5, 7, 9) at :data:`JERLOV_WAVELENGTHS_NM`:
Jerlov (1976), Table XXVII, p. 135 [6]_ (the table's 100 x K_d in 1/m divided by 100), as
arrays.
Transcribed from two independent public reproductions of the table, which agree in every
entry except type I at 400 nm (0.028 here, 0.027 in the other)."""


def jerlov_kd(jerlov_type: str, wavelength_nm=DEFAULT_WAVELENGTH_NM) -> np.ndarray:
    """``K_d`` [1/m] of a Jerlov water type at ``wavelength_nm`` [nm] (linear interpolation of
    Table XXVII [6]_ in wavelength).

    Parameters
    ----------
    jerlov_type : str
        One of ``I, IA, IB, II, III`` (oceanic) or ``1, 3, 5, 7, 9`` (coastal).
    wavelength_nm : array-like
        In [350, 700] nm.

    Raises
    ------
    InvalidParameterError
        For an unknown type or a wavelength outside the table.
    """
    if jerlov_type not in JERLOV_KD_PER_M:
        raise InvalidParameterError(
            f"unknown Jerlov water type {jerlov_type!r}; use one of "
            f"{', '.join(JERLOV_KD_PER_M)}")
    lam = check_in_range("wavelength_nm", wavelength_nm, JERLOV_WAVELENGTHS_NM[0],
                         JERLOV_WAVELENGTHS_NM[-1],
                         hint="Jerlov's Table XXVII covers 350-700 nm (and 310 nm)")
    return np.interp(lam, JERLOV_WAVELENGTHS_NM, np.asarray(JERLOV_KD_PER_M[jerlov_type]))


@dataclass(frozen=True)
class WaterType:
    """Optical properties of a water body.

    Attributes
    ----------
    name : str
    jerlov_type : str
        Key of :data:`JERLOV_KD_PER_M`: ``K_d(lambda)`` comes from Jerlov's table.
    max_dop : float
        ``P_max`` in (0, 1): degree of polarization of the light scattered once in the water
        at 90 deg from the refracted sun (module docstring).
    polarization_decay_per_m : float
        ``kappa_p`` [1/m] > 0: decay rate of the transmitted skylight's share of the light
        (:func:`transmitted_fraction`).
    reference : str
    polarization_validated_depth_m : float
        Deepest depth [m], >= 0, at which the polarization model was found to agree with
        measurements in this kind of water; deeper, :func:`underwater_polarization` warns
        (:class:`DepthBeyondValidationWarning`). 0 (the default) where no such comparison is
        known: only the transmitted sky at the surface is then supported.
    """

    name: str
    jerlov_type: str
    max_dop: float
    polarization_decay_per_m: float
    reference: str = ""
    polarization_validated_depth_m: float = 0.0

    def __post_init__(self):
        jerlov_kd(self.jerlov_type)  # validates the type
        object.__setattr__(self, "max_dop", float(check_dop("max_dop", self.max_dop)))
        object.__setattr__(self, "polarization_decay_per_m", float(check_in_range(
            "polarization_decay_per_m", self.polarization_decay_per_m, 0.0, np.inf,
            low_open=True, hint="decay rate [1/m] of the transmitted skylight's share")))
        object.__setattr__(self, "polarization_validated_depth_m", float(check_in_range(
            "polarization_validated_depth_m", self.polarization_validated_depth_m, 0.0,
            np.inf, hint="depth [m] down to which measurements support the model")))

    def diffuse_attenuation_per_m(self, wavelength_nm=DEFAULT_WAVELENGTH_NM) -> np.ndarray:
        """``K_d`` [1/m] at ``wavelength_nm`` [nm] (:func:`jerlov_kd`)."""
        return jerlov_kd(self.jerlov_type, wavelength_nm)


_KAPPA_CLEAR = float(np.log(2.0) / np.sqrt(1.25 * 3.0))
"""``kappa_p`` [1/m] of clear water: half the polarization lost over 1.25-3 m in clear reef
water [7]_ (geometric mean of the range, 1.94 m)."""


def _kappa_scaled(jerlov_type: str) -> float:
    """``kappa_p`` of a more turbid type: the clear-water value scaled by the ratio of ``K_d``
    at 480 nm to that of type I (scattering and ``K_d`` both grow with the particle load;
    an assumption, stated in :data:`WATER_TYPES`)."""
    return _KAPPA_CLEAR * float(jerlov_kd(jerlov_type) / jerlov_kd("I"))


CLEAR_WATER_VALIDATED_DEPTH_M = 5.0
"""Deepest depth [m] at which Lerner et al. [8]_ compared the model with measurements (2 m and
5 m) and found it to hold in clear water."""

WATER_TYPES = {
    "clear_ocean": WaterType(
        "clear_ocean", "I", 0.45, _KAPPA_CLEAR,
        "Jerlov oceanic type I [6]_; kappa_p from clear reef water [7]_; validated to 5 m [8]_",
        CLEAR_WATER_VALIDATED_DEPTH_M),
    "coastal": WaterType(
        "coastal", "3", 0.35, _kappa_scaled("3"),
        "Jerlov coastal type 3 [6]_; P_max below the coastal maximum 0.4 of [9]_; the model "
        "did not follow the sun in semi-turbid water [8]_"),
    "turbid": WaterType(
        "turbid", "9", 0.25, _kappa_scaled("9"),
        "Jerlov coastal type 9 [6]_; the model did not follow the sun in semi-turbid "
        "water [8]_"),
}
"""The three water types of the experiments. ``K_d``: Jerlov's table [6]_. ``P_max``: coastal
0.35, inside the measured maxima of coastal water (<= 0.4 [9]_); clear ocean 0.45 and turbid
0.25 follow the ordering of [10]_ (DoP falls as scattering grows against absorption).
``kappa_p``: clear ocean from [7]_; coastal and turbid scaled by their ``K_d`` at 480 nm
(0.276/0.0198 and 1.18/0.0198 of type I), an assumption. Validated depth of the polarization
model: 5 m in clear water, none in coastal and turbid water (Lerner et al. [8]_; module
docstring)."""


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


def refracted_sun_elevation_deg(sun_elevation_deg, n=REFRACTIVE_INDEX_SEAWATER):
    """Elevation [deg] of the sun seen from under a flat surface: zenith angle
    ``asin(cos(h) / n)`` (Snell [2]_); always inside Snell's window."""
    h = check_in_range("sun_elevation_deg", sun_elevation_deg, -90.0, 90.0)
    n = check_in_range("n", n, 1.0, np.inf)
    return 90.0 - np.degrees(np.arcsin(np.cos(np.radians(h)) / n))


def transmitted_fraction(depth_m, water) -> np.ndarray:
    """``f(z) = exp(-kappa_p z)``: share of the transmitted skylight in the light at depth
    ``z`` [m] (module docstring, [7]_)."""
    return beer_lambert(1.0, depth_m, water_type(water).polarization_decay_per_m)


def in_water_polarization(water_zenith_deg, view_azimuth_deg, sun_elevation_deg,
                          sun_azimuth_deg, water="clear_ocean", *,
                          n=REFRACTIVE_INDEX_SEAWATER) -> tuple[np.ndarray, np.ndarray]:
    """DoP and AoP [deg] of the light scattered once in the water from the refracted sun
    (Lerner et al. [8]_): ``P_max sin^2 Theta / (1 + cos^2 Theta)``, E-vector normal to the
    plane of the view and the refracted sun; AoP in the local-meridian basis of the upward
    view (as in air, docs/conventions.md).

    Returns
    -------
    dop, aop_deg : ndarray
    """
    w = water_type(water)
    tw = check_in_range("water_zenith_deg", water_zenith_deg, 0.0, 90.0,
                        hint="zenith angle of an upward view under water")
    sun_w = refracted_sun_elevation_deg(sun_elevation_deg, n)
    f = RayleighSky(w.max_dop).field(90.0 - tw, view_azimuth_deg, sun_w, sun_azimuth_deg)
    return f.dop, f.aop_deg


def check_validated_depth(depth_m, water, stacklevel: int = 2) -> np.ndarray:
    """Warn with :class:`DepthBeyondValidationWarning` where ``depth_m`` [m] lies deeper than
    the water type's :attr:`WaterType.polarization_validated_depth_m`; returns the mask of
    those depths (``depth_m`` validated as >= 0)."""
    w = water_type(water)
    z = check_in_range("depth_m", depth_m, 0.0, np.inf, hint="depth below the surface [m]")
    beyond = np.asarray(z > w.polarization_validated_depth_m)
    if beyond.any():
        bound = w.polarization_validated_depth_m
        where = (f"is validated down to {bound:g} m" if bound > 0 else
                 "is validated at the surface only")
        warnings.warn(
            f"depth_m {float(np.max(z))!r} m: the underwater polarization model of {w.name!r} "
            f"water {where} (Lerner et al. 2011: clear water, 2 and 5 m); it keeps the "
            "in-water single-scattering DoP, whereas the zenith DoP of the asymptotic light "
            "field tends to zero (Mobley 1994, sect. 9.3): treat the DoP there as an upper "
            "bound", DepthBeyondValidationWarning, stacklevel=stacklevel + 1)
    return beyond


def underwater_polarization(transmitted_dop, transmitted_aop_deg, depth_m, water_zenith_deg,
                            view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg,
                            water="clear_ocean", *, n=REFRACTIVE_INDEX_SEAWATER):
    """DoP and AoP [deg] at depth: ``f (q + i u)_sky + (1 - f) d_w exp(2 i chi_w)`` (module
    docstring) from the transmitted skylight's DoP and AoP just below the surface.

    Returns
    -------
    dop, aop_deg : ndarray

    Warns
    -----
    DepthBeyondValidationWarning
        Deeper than the water type's validated depth (5 m in clear water, the surface in
        coastal and turbid water; module docstring).
    """
    check_validated_depth(depth_m, water)
    return _mixed_polarization(transmitted_dop, transmitted_aop_deg, depth_m, water_zenith_deg,
                               view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg, water, n)


def _mixed_polarization(transmitted_dop, transmitted_aop_deg, depth_m, water_zenith_deg,
                        view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg, water, n):
    f = transmitted_fraction(depth_m, water)
    d_w, chi_w = in_water_polarization(water_zenith_deg, view_azimuth_deg, sun_elevation_deg,
                                       sun_azimuth_deg, water, n=n)
    p = (f * np.asarray(transmitted_dop, float) * np.exp(2j * np.radians(transmitted_aop_deg))
         + (1.0 - f) * d_w * np.exp(2j * np.radians(chi_w)))
    return np.abs(p), wrap_axial_deg(0.5 * np.degrees(np.angle(p)))


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
                     n=REFRACTIVE_INDEX_SEAWATER, day_of_year=None,
                     wavelength_nm=DEFAULT_WAVELENGTH_NM) -> IncidentLight:
    """Lux equivalent, AoP and DoP seen by an upward-looking sensor at ``depth_m`` [m].

    Snell's window maps the underwater view to the sky at :func:`air_zenith_deg`; the Stokes
    vector of :func:`sky_light` there is transmitted by :func:`fresnel_transmit_stokes`, its
    intensity attenuated with ``K_d(wavelength_nm)`` of Jerlov's table and its polarization
    mixed with the in-water single scattering (:func:`underwater_polarization`; module
    docstring). All inputs broadcast.

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
    wavelength_nm : float
        Wavelength [nm] of ``K_d``, in [350, 700].

    Raises
    ------
    OutsideSnellWindowError, SunBelowHorizonError, InvalidParameterError

    Warns
    -----
    DepthBeyondValidationWarning
        Deeper than the water type's validated depth: the DoP there is an upper bound
        (module docstring); the lux equivalent is unaffected.
    """
    w = water_type(water)
    check_validated_depth(depth_m, w)
    kd = w.diffuse_attenuation_per_m(wavelength_nm)
    theta_a = air_zenith_deg(water_zenith_deg, n)
    air = sky_light(sky, 90.0 - theta_a, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg,
                    day_of_year=day_of_year)
    two = np.radians(2.0 * air.aop_deg)
    I, Q, U = fresnel_transmit_stokes(air.illuminance_lx, air.illuminance_lx * air.dop
                                      * np.cos(two), air.illuminance_lx * air.dop * np.sin(two),
                                      theta_a, n)
    I_z = beer_lambert(I, depth_m, kd)
    dop, aop = _mixed_polarization(np.hypot(Q, U) / I, 0.5 * np.degrees(np.arctan2(U, Q)),
                                   depth_m, water_zenith_deg, view_azimuth_deg,
                                   sun_elevation_deg, sun_azimuth_deg, w, n)
    return IncidentLight(*np.broadcast_arrays(I_z, aop, dop))
