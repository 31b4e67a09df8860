"""Molecular (Rayleigh) scattering of dry air: optical thickness and depolarization.

The Rayleigh optical thickness of the whole atmosphere above a site and the depolarization
ratio of air, after Bodhaine et al. (1999) [1]_, from the wavelength, the surface pressure,
the site's latitude and altitude (gravity) and the CO2 mixing ratio. Every sky model that
needs the molecular optical thickness of a band (single scattering's d_max, the
multiple-scattering, aerosol and night skies, the diagnosis's sky candidates) takes it from
here.

References
----------
.. [1] B. A. Bodhaine, N. B. Wood, E. G. Dutton, J. R. Slusser, "On Rayleigh optical depth
   calculations", J. Atmos. Oceanic Technol. 16:1854-1861 (1999),
   doi:10.1175/1520-0426(1999)016<1854:ORODC>2.0.CO;2.
.. [2] P. J. Mohr et al., CODATA 2018 (Avogadro constant).
"""

from __future__ import annotations

import numpy as np

from .validation import check_in_range

__all__ = [
    "WAVELENGTH_RANGE_NM",
    "bodhaine_depolarization_ratio",
    "bodhaine_optical_thickness",
    "bodhaine_optical_thickness_fit",
]

WAVELENGTH_RANGE_NM = (250.0, 1000.0)
"""Supported wavelengths [nm]: the range of Bodhaine et al.'s tables and fit (eq. 30)."""

_AVOGADRO = 6.02214076e23  # [1/mol], CODATA 2018 [2]_
_NS_288 = 2.546899e19      # molecules per cm^3 at 288.15 K, 1013.25 hPa ([1]_, eq. (3))


def _check_wavelength(wavelength_nm) -> np.ndarray:
    lo, hi = WAVELENGTH_RANGE_NM
    return check_in_range("wavelength_nm", wavelength_nm, lo, hi,
                          hint="Bodhaine et al. (1999) cover 250-1000 nm; give tau directly "
                               "for other wavelengths")


def _king_factor_air(lam_um, co2_ppm):
    """King correction factor of air, [1]_ eqs. (5), (6) and (23), lam in [um]."""
    f_n2 = 1.034 + 3.17e-4 / lam_um**2
    f_o2 = 1.096 + 1.385e-3 / lam_um**2 + 1.448e-4 / lam_um**4
    c = co2_ppm * 1e-4  # percent by volume
    return ((78.084 * f_n2 + 20.946 * f_o2 + 0.934 * 1.00 + c * 1.15)
            / (78.084 + 20.946 + 0.934 + c))


def bodhaine_depolarization_ratio(wavelength_nm, co2_ppm: float = 360.0) -> np.ndarray:
    """Depolarization ratio of air ``rho`` from the King factor ``F = (6 + 3 rho)/(6 - 7 rho)``.

    [1]_, eqs. (5), (6), (23); about 0.028 in the visible.
    """
    lam = _check_wavelength(wavelength_nm) * 1e-3
    f = _king_factor_air(lam, co2_ppm)
    return 6.0 * (f - 1.0) / (3.0 + 7.0 * f)


def bodhaine_optical_thickness(wavelength_nm, pressure_hPa=1013.25, latitude_deg=45.0,
                               altitude_m=0.0, co2_ppm: float = 360.0) -> np.ndarray:
    """Rayleigh optical thickness of the whole atmosphere above a site.

    ``tau = sigma P A / (m_a g)`` ([1]_, eq. (29)) with the cross-section per molecule
    ``sigma = 24 pi^3 (n^2 - 1)^2 / (lam^4 Ns^2 (n^2 + 2)^2) F_air`` (eq. (2)), the refractive
    index of air from Peck & Reeder (eq. (4)) corrected for CO2 (eq. (19)), the King factor
    (eqs. (5), (6), (23)), the mean molecular weight of dry air (eq. (17)) and gravity at the
    mass-weighted column altitude ``0.73737 z + 5517.56`` m (eqs. (10)-(11)).

    Parameters
    ----------
    wavelength_nm : array-like
        Wavelength [nm] in :data:`WAVELENGTH_RANGE_NM`.
    pressure_hPa : array-like
        Surface pressure [hPa], in (0, 1100].
    latitude_deg : array-like
        Site latitude [deg] (gravity).
    altitude_m : array-like
        Site altitude [m] (gravity).
    co2_ppm : float
        CO2 volume mixing ratio [ppm].

    Returns
    -------
    ndarray
        Optical thickness [1] (0.36 at 400 nm, 0.097 at 550 nm at sea level).
    """
    lam_um = _check_wavelength(wavelength_nm) * 1e-3
    p = check_in_range("pressure_hPa", pressure_hPa, 0.0, 1100.0, low_open=True,
                       hint="surface pressure in hPa (sea level: 1013.25)")
    lat = np.radians(check_in_range("latitude_deg", latitude_deg, -90.0, 90.0))
    z = check_in_range("altitude_m", altitude_m, -500.0, 9000.0)
    inv2 = 1.0 / lam_um**2
    n300 = 1.0 + 1e-8 * (8060.51 + 2480990.0 / (132.274 - inv2) + 17455.7 / (39.32957 - inv2))
    n = 1.0 + (n300 - 1.0) * (1.0 + 0.54 * (co2_ppm * 1e-6 - 0.0003))
    lam_cm = lam_um * 1e-4
    sigma = (24.0 * np.pi**3 * (n * n - 1.0) ** 2 / (lam_cm**4 * _NS_288**2 * (n * n + 2.0) ** 2)
             * _king_factor_air(lam_um, co2_ppm))                       # [cm^2]
    m_air = 15.0556 * co2_ppm * 1e-6 + 28.9595                           # [g/mol]
    c2 = np.cos(2.0 * lat)
    g0 = 980.6160 * (1.0 - 0.0026373 * c2 + 0.0000059 * c2 * c2)         # [cm/s^2]
    zc = 0.73737 * z + 5517.56                                           # [m]
    g = (g0 - (3.085462e-4 + 2.27e-7 * c2) * zc + (7.254e-11 + 1.0e-13 * c2) * zc**2
         - (1.517e-17 + 6.0e-20 * c2) * zc**3)
    return sigma * (p * 1000.0) * _AVOGADRO / (m_air * g)                # P in dyn/cm^2


def bodhaine_optical_thickness_fit(wavelength_nm) -> np.ndarray:
    """Bodhaine et al.'s closed-form fit ([1]_, eq. (30)): sea level, 45 deg, 1013.25 hPa, 360 ppm.

    Used as an independent check of :func:`bodhaine_optical_thickness`.
    """
    lam = _check_wavelength(wavelength_nm) * 1e-3
    return (0.0021520 * (1.0455996 - 341.29061 / lam**2 - 0.90230850 * lam**2)
            / (1.0 + 0.0027059889 / lam**2 - 85.968563 * lam**2))
