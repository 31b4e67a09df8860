"""Johnson-Cousins photometric bands: zero points, the Sun's magnitudes, Paranal's sky.

A night sky is measured in magnitudes per square arcsecond; skysim's radiances are spectral
radiances in a band [W m^-2 nm^-1 sr^-1]. One zero point per band converts between them:
``L = F0 10^(-0.4 m) / (1 arcsec^2 in sr)`` with ``F0`` the band's flux density of a
zero-magnitude star (Vega system, Bessell, Castelli & Plez 1998 [1]_, Table A2). The Sun's
irradiance in a band follows from its apparent magnitude in that band (Willmer 2018 [2]_,
Table 3: absolute magnitude minus the distance modulus of 1 AU, -31.57), with the same zero
point, so the Moon (sunlight reflected) and the night sky are on one scale.

Site values (Cerro Paranal, the site of the FORS2 data): extinction coefficients rounded
from the bi-monthly means of Patat (2003) [3]_, Table A.1 (photometric nights 2000-2001;
they vary by about 0.02 mag per airmass), and the zenith-corrected
dark-sky brightness averaged over the same period [3]_ (airglow, zodiacal light and
integrated starlight together).

Ground albedo: the Lambertian albedo of the desert around the site at the band's effective
wavelength (:func:`desert_albedo`), for the ground-reflected light in the multiple-scattering
sky. Desert spectral albedo rises from 0.05-0.11 in the near ultraviolet (350 nm) to 0.2-0.3
at 600 nm and 0.37-0.49 at its maximum near 2 um (gobi and sand, Aoki et al. 2005 [4]_); in
the Atacama, MODIS albedos (within 5 % of ground spectral measurements at 18-27 deg S) reach
0.25 in the visible at the brightest spots (Cordero et al. 2021 [5]_).

References
----------
.. [1] M. S. Bessell, F. Castelli and B. Plez, "Model atmospheres broad-band colors,
   bolometric corrections and temperature calibrations for O-M stars", A&A 333:231-250
   (1998), Table A2.
.. [2] C. N. A. Willmer, "The absolute magnitude of the Sun in several filters", ApJS
   236:47 (2018), doi:10.3847/1538-4365/aabfdf, Table 3.
.. [3] F. Patat, "UBVRI night sky brightness during sunspot maximum at ESO-Paranal", A&A
   400:1183-1198 (2003), doi:10.1051/0004-6361:20030030, abstract and Table A.1.
.. [4] T. Aoki et al., "Spectral albedo of desert surfaces measured in western and central
   China", J. Meteor. Soc. Japan 83A:279-290 (2005), doi:10.2151/jmsj.83A.279, abstract.
.. [5] R. R. Cordero et al., "Evaluation of MODIS-derived estimates of the albedo over the
   Atacama Desert using ground-based spectral measurements", Sci. Rep. 11:19822 (2021),
   doi:10.1038/s41598-021-98622-4.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .exceptions import InvalidParameterError

__all__ = ["ARCSEC2_SR", "BANDS", "Band", "DESERT_ALBEDO_NODES", "desert_albedo", "get_band",
           "magnitude_to_radiance", "radiance_to_magnitude", "solar_irradiance"]

ARCSEC2_SR = (np.pi / 648000.0) ** 2
"""One square arcsecond [sr]."""

DESERT_ALBEDO_NODES = ((350.0, 0.08), (600.0, 0.25), (2000.0, 0.43))
"""(wavelength [nm], albedo) nodes of the desert's spectral albedo: the middle of each range
of Aoki et al. 2005 ([4]_: 0.05-0.11 at 350 nm, 0.2-0.3 at 600 nm, maximum 0.37-0.49 at
1.8-2.2 um)."""


def desert_albedo(wavelength_nm) -> np.ndarray:
    """Lambertian albedo of a bare desert surface at ``wavelength_nm`` [nm], 350-2000 nm:
    linear between :data:`DESERT_ALBEDO_NODES` ([4]_; about 0.09 in U, 0.14 in B, 0.21 in V,
    0.26 in R, 0.28 in I). Raises :class:`~skysim.exceptions.InvalidParameterError` outside."""
    w = np.asarray(wavelength_nm, dtype=float)
    lo, hi = DESERT_ALBEDO_NODES[0][0], DESERT_ALBEDO_NODES[-1][0]
    bad = ~((w >= lo) & (w <= hi))
    if np.any(bad):
        raise InvalidParameterError(f"wavelength_nm={float(w[bad].flat[0]):g}: the desert "
                                    f"albedo is tabulated between {lo:g} and {hi:g} nm")
    x, y = np.array(DESERT_ALBEDO_NODES).T
    return np.interp(w, x, y)


@dataclass(frozen=True)
class Band:
    """A photometric band.

    Attributes
    ----------
    name : str
    wavelength_nm : float
        Effective wavelength [nm] ([1]_, Table A2).
    zero_point_W_m2_nm : float
        Flux density of magnitude 0 [W m^-2 nm^-1] ([1]_, Table A2).
    sun_magnitude : float
        Apparent magnitude of the Sun at 1 AU ([2]_).
    extinction_mag_per_airmass : float
        Atmospheric extinction at Paranal [mag per airmass] ([3]_, Table A.1).
    dark_sky_mag_arcsec2 : float
        Dark-sky zenith brightness at Paranal [mag arcsec^-2] ([3]_).
    ground_albedo : float
        Lambertian albedo of the desert around the site at ``wavelength_nm``
        (:func:`desert_albedo`).
    """

    name: str
    wavelength_nm: float
    zero_point_W_m2_nm: float
    sun_magnitude: float
    extinction_mag_per_airmass: float
    dark_sky_mag_arcsec2: float

    @property
    def ground_albedo(self) -> float:
        return float(desert_albedo(self.wavelength_nm))


BANDS = {
    "U": Band("U", 366.0, 4.175e-11, -25.96, 0.47, 22.3),
    "B": Band("B", 438.0, 6.32e-11, -26.13, 0.22, 22.6),
    "V": Band("V", 545.0, 3.631e-11, -26.76, 0.11, 21.6),
    "R": Band("R", 641.0, 2.177e-11, -27.14, 0.07, 20.9),
    "I": Band("I", 798.0, 1.126e-11, -27.47, 0.05, 19.7),
}
"""Bands by name (Bessell U, B, V; Cousins R, I). The Sun's magnitudes are Willmer's absolute
magnitudes (U 5.61, B 5.44, V 4.81, R 4.43, I 4.10) minus 31.57. U's extinction, 0.47 mag per
airmass, is the sum of its molecular (Bodhaine et al. 1999 at Paranal's 744 hPa: 0.417) and
aerosol (Patat et al. 2011: 0.052) parts (:func:`skysim.night.extinction_components`), within
the spread of Patat's bi-monthly U coefficients ([3]_, Table A.1: 0.41 +- 0.05 in March-April,
0.47 +- 0.01 in July-August 2000)."""


def get_band(name: str) -> Band:
    """The :class:`Band` called ``name``; raises
    :class:`~skysim.exceptions.InvalidParameterError` listing the valid names."""
    try:
        return BANDS[name]
    except (KeyError, TypeError):
        raise InvalidParameterError(f"unknown band {name!r}; valid: {', '.join(BANDS)}") from None


def magnitude_to_radiance(mag_arcsec2, band: str) -> np.ndarray:
    """Surface brightness [mag arcsec^-2] -> spectral radiance [W m^-2 nm^-1 sr^-1] in ``band``."""
    b = get_band(band)
    return b.zero_point_W_m2_nm * 10.0 ** (-0.4 * np.asarray(mag_arcsec2, float)) / ARCSEC2_SR


def radiance_to_magnitude(radiance, band: str) -> np.ndarray:
    """Spectral radiance [W m^-2 nm^-1 sr^-1] -> surface brightness [mag arcsec^-2]."""
    b = get_band(band)
    with np.errstate(divide="ignore"):
        return -2.5 * np.log10(np.asarray(radiance, float) * ARCSEC2_SR / b.zero_point_W_m2_nm)


def solar_irradiance(band: str) -> float:
    """The Sun's spectral irradiance at 1 AU in ``band`` [W m^-2 nm^-1]."""
    b = get_band(band)
    return b.zero_point_W_m2_nm * 10.0 ** (-0.4 * b.sun_magnitude)
