"""Polarization sensors under the night sky: the light at their apertures in their own units,
and their photon and dark-current noise.

**From band radiance to light at the sensor.** The night sky of :mod:`skysim.night` is a
spectral radiance in a photometric band, ``L_V`` [W m^-2 nm^-1 sr^-1] in the V band. Moonlight
is sunlight reflected by a grey-ish surface, so the factor that turns the Sun's V-band
irradiance into its illuminance turns moonlight's too::

    K_V = E_sc / E_sun,V = 127.5 klx / 1.837 W m^-2 nm^-1 = 6.94e4 lx per W m^-2 nm^-1

with the solar illuminance constant ``E_sc`` of the IES daylight model [1]_
(:data:`sensor.illuminance.SOLAR_ILLUMINANCE_CONSTANT_LX`) and the Sun's V-band irradiance
from its V magnitude and the V zero point (:func:`skysim.bands.solar_irradiance`). The
luminance of a view direction is ``K_V L_V`` [cd m^-2] (:func:`luminance_cd_m2`) and its *lux
equivalent*, the unit of the photodiode models' responsivity (:mod:`sensor.photodiode`,
:mod:`sensor.illuminance`), is ``pi K_V L_V`` [lx] (:func:`lux_equivalent`). Checks
(``tests/test_night_sensors.py``): a star of V = 0 gives 2.54e-6 lx outside the atmosphere
(Allen's *Astrophysical Quantities* [2]_), and ``K_V`` agrees with it within 1 %; a flat
spectrum through the CIE photopic curve, ``683 lm/W * int V(lambda) dlambda`` = 7.3e4, within
5 %. The direct moonlight on a horizontal plane (:func:`moon_illuminance_lx`) is
``K_V E_moon 10^(-0.4 k X(Z)) sin(h)`` with the K&S airmass ``X`` (:func:`skysim.night.
ks_airmass`): a full Moon high in a clear sky gives 0.1-0.3 lx (Kyba, Mohar & Posch [3]_:
typically 0.05-0.1 lx, at most 0.32 lx for a perigee full Moon at culmination in the
tropics).

**Photodiodes** (:class:`NightPhotodiode`): the photocurrent of
:func:`sensor.photodiode.photodiode_signal`, ``K E k (1 + eta d cos 2(chi - p)) + D``, read by
a transimpedance amplifier and averaged over a window ``T`` [s]. The mean current over the
window carries the shot noise of photo- and dark current, variance ``q (I + D) / T`` (Poisson
statistics of the ``(I + D) T / q`` electrons; equal to ``2 q I B`` at the bandwidth
``B = 1 / (2 T)`` of the average [4]_), and the Johnson noise of the feedback resistor
``R_f``, variance ``4 k_B T_K B / R_f = 2 k_B T_K / (R_f T)`` [4]_; the electron counts are
in the 1e8-1e10 range, so their normal limit is exact for the purpose. A dark level
measured with the sensor capped over a window ``T_cap`` carries the same two noises at
``I = 0``.

**Closed form** (:func:`four_photodiode_aop_sd_deg`): for a unit of four photodiodes at 0,
45, 90 and 135 deg, dark-subtracted readings ``P_a = I0 (1 + d cos 2(chi - a)) + n_a`` with
noise variance ``s_a^2 = q (P_a + D) / T + c`` (``c``: Johnson and dark-estimate variance),
Stokes ``S1 = P_0 - P_90``, ``S2 = P_45 - P_135`` have ``|S| = 2 I0 d`` and the noise across
``S`` has variance ``2 (q (I0 + D) / T + c)`` (the ``cos`` terms cancel in each pair), so the
angle of polarization has the standard deviation

    sd(chi) = sqrt(2 (q (I0 + D) / T + c)) / (4 I0 d)    [rad]

to first order: ``~ 1 / sqrt(I0)`` when shot noise of the light dominates, ``~ 1 / I0`` when
the dark current (or the amplifier) does. The three-pair sensor's log-ratio channels follow
the same two regimes (the test checks both).

**Camera** (:func:`camera_photoelectron_rate`): photoelectrons per second of a pixel for a
unit band radiance, from the camera equation for an object at infinity on the axis, image
irradiance ``E = pi tau L / (4 N^2)`` (Smith [5]_), over the pixel's area, the quantum
efficiency and the filter's width ``Delta lambda`` at ``lambda / (h c)`` photons per joule::

    q = pi tau / (4 N^2) * a^2 * QE * Delta lambda * lambda / (h c)

the rate ``q`` of :class:`sensor.camera.PolarizationCamera` when the sky is in band radiance
units (the micro-polarizer's 1/2 is in the camera's analysis vectors). Defaults: the
IMX250MZR's 3.45 um pixel pitch [6]_, a V-band filter of 84 nm FWHM (Bessell [7]_), f/1.4,
quantum efficiency 0.5 and transmittance 0.8 (assumptions of the order of CMOS sensors and
coated lenses; give the values of your camera's EMVA 1288 sheet and lens).

References
----------
.. [1] IES Daylighting Committee, J. Illum. Eng. Soc. 13(4):381-392 (1984),
   doi:10.1080/00994480.1984.10748791 (``E_sc`` = 127.5 klx).
.. [2] A. N. Cox (ed.), *Allen's Astrophysical Quantities*, 4th ed., Springer (2000): a star
   of V = 0 gives 2.54e-6 lx.
.. [3] C. C. M. Kyba, A. Mohar, T. Posch, "How bright is moonlight?", Astron. Geophys.
   58(1):1.31-1.32 (2017), doi:10.1093/astrogeo/atx025.
.. [4] P. Horowitz, W. Hill, *The Art of Electronics*, 3rd ed., Cambridge (2015),
   sect. 8.1.1 (Johnson noise ``4 k T R B``) and 8.1.3 (shot noise ``2 q I B``).
.. [5] W. J. Smith, *Modern Optical Engineering*, 4th ed., McGraw-Hill (2008), ch. 9 (image
   illuminance ``pi tau L / (4 N^2)``).
.. [6] Sony Semiconductor Solutions, IMX250MZR/IMX253MZR polarization image sensor flyer
   (2018): 2448 x 2048 pixels of 3.45 um.
.. [7] M. S. Bessell, "UBVRI passbands", PASP 91:589-607 (1979): V band FWHM 84 nm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skysim.bands import get_band, solar_irradiance
from skysim.exceptions import InvalidParameterError
from skysim.validation import check_finite, check_in_range

from .illuminance import SOLAR_ILLUMINANCE_CONSTANT_LX
from .photodiode import ELEMENTARY_CHARGE_C, photodiode_signal

__all__ = ["BOLTZMANN_J_K", "LUX_PER_V_IRRADIANCE", "MOON_RADIUS_DEG", "NightPhotodiode",
           "camera_photoelectron_rate", "four_photodiode_aop_sd_deg", "luminance_cd_m2",
           "lux_equivalent", "moon_illuminance_lx", "photocurrent_sd_A"]

LUX_PER_V_IRRADIANCE = SOLAR_ILLUMINANCE_CONSTANT_LX / solar_irradiance("V")
"""``K_V`` [lx per W m^-2 nm^-1]: illuminance per V-band spectral irradiance of sunlight and
moonlight (module docstring)."""

BOLTZMANN_J_K = 1.380649e-23
"""Boltzmann constant [J/K] (exact, SI 2019)."""

_PLANCK_J_S = 6.62607015e-34
_LIGHT_M_S = 299_792_458.0

MOON_RADIUS_DEG = 0.2590
"""Mean angular radius of the Moon seen from the Earth's centre [deg] (semi-diameter
15'32.6" at the mean distance 384400 km, Meeus, *Astronomical Algorithms*, ch. 55)."""


def _photometric_band(band: str):
    b = get_band(band)
    if b.name != "V":
        raise InvalidParameterError(
            f"photometric quantities (lx, cd/m2) follow the eye's V(lambda) curve, "
            f"whose astronomical counterpart is the V band; got band {band!r}: "
            "evaluate the night sky in band 'V'")
    return b


def luminance_cd_m2(radiance, band: str = "V") -> np.ndarray:
    """Luminance [cd m^-2] of a V-band spectral radiance [W m^-2 nm^-1 sr^-1] of moonlit (or
    sunlit) sky, ``K_V L_V`` (module docstring).

    Raises
    ------
    InvalidParameterError
        For a band other than V, or a negative or non-finite radiance.
    """
    _photometric_band(band)
    return LUX_PER_V_IRRADIANCE * check_in_range("radiance", radiance, 0.0, np.inf)


def lux_equivalent(radiance, band: str = "V") -> np.ndarray:
    """Lux equivalent ``pi K_V L_V`` [lx] of a V-band spectral radiance [W m^-2 nm^-1 sr^-1]:
    the intensity unit of the photodiode models (:mod:`sensor.photodiode`)."""
    return np.pi * luminance_cd_m2(radiance, band)


def moon_illuminance_lx(moon_irradiance, moon_elevation_deg, extinction=None,
                        band: str = "V") -> np.ndarray:
    """Illuminance of the direct moonlight on a horizontal plane [lx].

    ``K_V E 10^(-0.4 k X(Z)) sin(h)`` with the K&S airmass ``X`` (:func:`skysim.night.
    ks_airmass`); the scattered skylight (a few per cent of it) is not included.

    Parameters
    ----------
    moon_irradiance : array
        The Moon's V-band irradiance above the atmosphere [W m^-2 nm^-1]
        (:func:`skysim.night.moon_band_irradiance`).
    moon_elevation_deg : array
        [deg], in (0, 90].
    extinction : float, optional
        [mag per airmass]; default the band's Paranal value.

    Raises
    ------
    skysim.night.MoonBelowHorizonError
        For a Moon at or below the horizon.
    """
    from skysim.night import MoonBelowHorizonError, ks_airmass
    b = _photometric_band(band)
    el = check_finite("moon_elevation_deg", moon_elevation_deg)
    if np.any(el <= 0.0) or np.any(el > 90.0):
        raise MoonBelowHorizonError(
            f"moon_elevation_deg must be in (0, 90]; got {el[(el <= 0) | (el > 90)].ravel()[0]!r}"
            ": no direct moonlight from a Moon at or below the horizon")
    k = b.extinction_mag_per_airmass if extinction is None else float(
        check_in_range("extinction", extinction, 0.0, 5.0))
    e = check_in_range("moon_irradiance", moon_irradiance, 0.0, np.inf)
    return (LUX_PER_V_IRRADIANCE * e * 10.0 ** (-0.4 * k * ks_airmass(90.0 - el))
            * np.sin(np.radians(el)))


def photocurrent_sd_A(current_A, window_s, feedback_ohm=np.inf,
                      temperature_K: float = 293.15) -> np.ndarray:
    """Standard deviation [A] of a current averaged over ``window_s`` [s]: shot noise
    ``q I / T`` plus the feedback resistor's Johnson noise ``2 k_B T_K / (R_f T)`` [4]_.

    Parameters
    ----------
    current_A : array
        Photo- plus dark current [A], >= 0.
    window_s : float or array
        Averaging window [s], > 0.
    feedback_ohm : float
        Transimpedance feedback resistor [ohm], > 0 (``inf``: no Johnson noise).
    temperature_K : float
        Resistor temperature [K], > 0.
    """
    i = check_in_range("current_A", current_A, 0.0, np.inf)
    t = check_in_range("window_s", window_s, 0.0, np.inf, low_open=True)
    r = float(check_in_range("feedback_ohm", feedback_ohm, 0.0, np.inf, low_open=True,
                             high_open=False))
    tk = float(check_in_range("temperature_K", temperature_K, 0.0, np.inf, low_open=True))
    return np.sqrt(ELEMENTARY_CHARGE_C * i / t + 2.0 * BOLTZMANN_J_K * tk / (r * t))


@dataclass(frozen=True)
class NightPhotodiode:
    """A photodiode behind a linear polarizer with a linear transimpedance readout, averaged
    over a window (module docstring).

    Parameters
    ----------
    responsivity_A_per_lx : float
        ``K`` [A/lx] per lux equivalent (default that of
        :class:`sensor.photodiode.PhotodiodeChannels`: 50 pA/lx).
    dark_A : float
        Dark current [A] (default 50 pA, as there: ~1 lx equivalent).
    feedback_ohm : float
        Feedback resistor of the transimpedance amplifier [ohm] (1 GOhm: 50 mV at 50 pA).
    temperature_K : float
        Its temperature [K].
    """

    responsivity_A_per_lx: float = 50e-12
    dark_A: float = 50e-12
    feedback_ohm: float = 1e9
    temperature_K: float = 293.15

    def __post_init__(self):
        check_in_range("responsivity_A_per_lx", self.responsivity_A_per_lx, 0.0, np.inf,
                       low_open=True)
        check_in_range("dark_A", self.dark_A, 0.0, np.inf)
        check_in_range("feedback_ohm", self.feedback_ohm, 0.0, np.inf, low_open=True,
                       high_open=False)
        check_in_range("temperature_K", self.temperature_K, 0.0, np.inf, low_open=True)

    def mean_A(self, lux_eq, aop_deg, dop, polarizer_deg) -> np.ndarray:
        """Noise-free photo- plus dark current [A] (:func:`sensor.photodiode.
        photodiode_signal`); every argument broadcasts."""
        return photodiode_signal(lux_eq, aop_deg, dop, polarizer_deg,
                                 responsivity=self.responsivity_A_per_lx, dark=self.dark_A)

    def sd_A(self, current_A, window_s) -> np.ndarray:
        """Noise [A] of the window's mean current (:func:`photocurrent_sd_A`)."""
        return photocurrent_sd_A(current_A, window_s, self.feedback_ohm, self.temperature_K)

    def read_A(self, lux_eq, aop_deg, dop, polarizer_deg, window_s,
               rng: np.random.Generator) -> np.ndarray:
        """Mean current over ``window_s`` [A] with shot and Johnson noise (one draw per
        element of the broadcast shape)."""
        mean = self.mean_A(lux_eq, aop_deg, dop, polarizer_deg)
        return mean + self.sd_A(mean, window_s) * rng.standard_normal(mean.shape)

    def dark_level_A(self, window_s, rng: np.random.Generator, shape=()) -> np.ndarray:
        """The dark level measured with the photodiode capped for ``window_s`` [s] [A]."""
        return self.dark_A + self.sd_A(self.dark_A, window_s) * rng.standard_normal(shape)


def four_photodiode_aop_sd_deg(photo_A, dark_A, dop, window_s, extra_variance_A2=0.0):
    """First-order standard deviation [deg] of the angle of polarization from four
    dark-subtracted photodiodes at 0/45/90/135 deg (module docstring, *Closed form*).

    Parameters
    ----------
    photo_A : array
        ``I0``: photocurrent of one photodiode for unpolarized light of the same intensity
        [A], > 0.
    dark_A : array
        Dark current [A], >= 0.
    dop : array
        Degree of polarization, in (0, 1].
    window_s : float
        Averaging window [s].
    extra_variance_A2 : array
        Signal-independent variance per photodiode [A^2] (Johnson noise, the dark estimate).
    """
    i0 = check_in_range("photo_A", photo_A, 0.0, np.inf, low_open=True)
    d = check_in_range("dop", dop, 0.0, 1.0, low_open=True)
    t = check_in_range("window_s", window_s, 0.0, np.inf, low_open=True)
    var = 2.0 * (ELEMENTARY_CHARGE_C * (i0 + check_in_range("dark_A", dark_A, 0.0, np.inf)) / t
                 + check_in_range("extra_variance_A2", extra_variance_A2, 0.0, np.inf))
    return np.degrees(np.sqrt(var) / (4.0 * i0 * d))


def camera_photoelectron_rate(*, f_number: float = 1.4, pixel_pitch_um: float = 3.45,
                              quantum_efficiency: float = 0.5, transmittance: float = 0.8,
                              bandwidth_nm: float = 84.0, band: str = "V") -> float:
    """Photoelectrons per second of a camera pixel per unit band radiance
    [e- s^-1 per W m^-2 nm^-1 sr^-1] (module docstring, *Camera*).

    Raises
    ------
    InvalidParameterError
        For a non-positive f-number, pitch or bandwidth, or a quantum efficiency or
        transmittance outside (0, 1].
    """
    for name, value in (("f_number", f_number), ("pixel_pitch_um", pixel_pitch_um),
                        ("bandwidth_nm", bandwidth_nm)):
        if not (np.isfinite(value) and value > 0):
            raise InvalidParameterError(f"{name} must be a positive number; got {value!r}")
    for name, value in (("quantum_efficiency", quantum_efficiency),
                        ("transmittance", transmittance)):
        check_in_range(name, value, 0.0, 1.0, low_open=True)
    wavelength_m = get_band(band).wavelength_nm * 1e-9
    area_m2 = (pixel_pitch_um * 1e-6) ** 2
    photons_per_joule = wavelength_m / (_PLANCK_J_S * _LIGHT_M_S)
    return float(np.pi * transmittance / (4.0 * f_number ** 2) * area_m2 * quantum_efficiency
                 * bandwidth_nm * photons_per_joule)
