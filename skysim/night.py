"""The polarized night sky: moonlight (and sunlight) scattered in the air over an
unpolarized night-sky background.

Radiance of the scattered light: the moonlit-sky model of Krisciunas & Schaefer [1]_ with
the Moon's magnitude replaced by its irradiance from the ROLO model (:mod:`skysim.moon`).
For a source of irradiance ``E`` at zenith distance ``Z_s`` and a view direction at zenith
distance ``Z`` and scattering angle ``rho`` from the source ([1]_, eqs. 15, 16, 17, 21)::

    L = K E f(rho) 10^(-0.4 k X(Z_s)) (1 - 10^(-0.4 k X(Z)))
    f(rho) = 10^5.36 (1.06 + cos^2 rho) + 10^(6.15 - rho / 40 deg)
    X(Z) = (1 - 0.96 sin^2 Z)^(-1/2)

``k`` is the band's extinction coefficient [mag per airmass] and ``K`` converts the model's
units (nanolamberts per ``10^(-0.4 (m + 16.57))``, eqs. 1 and 20) into radiance per
irradiance [sr^-1]: ``K = 10^(-0.4 * 16.57) / (34.08 e^20.7233 arcsec^2)``. The first term of
``f`` is the Rayleigh scattering by the molecules, ``10^5.36 (1 + cos^2 rho)`` of it
scattered as by an ideal dipole and ``10^5.36 * 0.06`` unpolarized; the second is the
aerosol (Mie) scattering, taken as unpolarized.

Per band: K&S fitted ``f`` in V. In another band the molecules and the aerosol scatter in a
different ratio: the molecular optical thickness goes as ``lambda^-4.08`` (Bodhaine et al.
[4]_, :mod:`skysim.molecular`), the aerosol's at Paranal as ``lambda^-1.38`` (Patat et al.
[5]_: ``k_aer = 0.013 (lambda / 1 um)^-1.38`` mag per airmass). The aerosol term of band
``b`` is weighted by ``w_b = [tau_aer(b) / tau_aer(V)] / [tau_mol(b) / tau_mol(V)]``
(:func:`aerosol_weight`; 1 in V, about 0.55 in B, 1.55 in R, 2.8 in I), the molecular term
keeps K&S's scaling with the band's extinction ``k``. Both at the band's effective
wavelength (:mod:`skysim.bands`). The alternative of scaling the molecular term too, by
``tau_mol(b) / tau_mol(V) * k_V / k_b``, makes the blue sky brighter relative to the dark
sky than the FORS2 B and V polarimetry shows at large angles from the Moon (where the
aerosol term is negligible), see ``docs/moonlit_sky.md``.

Polarization: the dipole part carries the degree and angle of polarization of a skysim sky
model (:mod:`skysim.sky`) with the source in place of the Sun: the single-scattering
Rayleigh sky (DoP ``sin^2 rho / (1 + cos^2 rho)``, so that the Rayleigh term as a whole has
``sin^2 rho / (1.06 + cos^2 rho)``) or the multiple-scattering sky of
:mod:`skysim.multiple`, whose ground albedo carries the moonlight reflected by the ground and
scattered back, nearly unpolarized (a desert's albedo per band:
:attr:`skysim.bands.Band.ground_albedo`). Sources add as Stokes vectors (incoherent light);
the night-sky background adds to ``I`` only:

    DoP = |polarized radiance| / (moonlit + sunlit + background radiance).

Background: airglow, zodiacal light and integrated starlight, with the dark-sky zenith
brightness of the band [mag arcsec^-2] (:mod:`skysim.bands`, Paranal: measured through each
broadband filter, so the airglow lines and continuum in the band, OH and O2 in R and I, are
included) brightened towards the horizon as airglow ([1]_, eq. 2:
``B_zen 10^(-0.4 k (X - 1)) X``; ``X`` is the van Rhijn factor of a thin emitting layer at
the height where ``(R_E / (R_E + h))^2 = 0.96``, about 130 km). The split into its three
parts (Leinert et al. 1998 [2]_ give each; Noll et al. 2012 [3]_ model them at Paranal) is
not made: their sum is measured at the zenith, and the zodiacal light's and the Milky Way's
patterns across the sky are left out.

Units: radiance in the band [W m^-2 nm^-1 sr^-1] throughout (:func:`skysim.bands.
magnitude_to_radiance` for surface brightness).

Validity: sources above the horizon (K&S's model). A Moon below the horizon adds nothing
(the faint glow of a Moon just set is left out). A Sun between -18 deg and the horizon
(twilight) raises :class:`TwilightError`: the twilight sky's brightness is not modelled.

References
----------
.. [1] K. Krisciunas and B. E. Schaefer, "A model of the brightness of moonlight", PASP
   103:1033-1039 (1991), doi:10.1086/132921, eqs. 1-3, 15-21.
.. [2] Ch. Leinert et al., "The 1997 reference of diffuse night sky brightness", A&AS
   127:1-99 (1998), doi:10.1051/aas:1998105.
.. [3] S. Noll et al., "An atmospheric radiation model for Cerro Paranal", A&A 543:A92
   (2012), doi:10.1051/0004-6361/201219040.
.. [4] B. A. Bodhaine et al., "On Rayleigh optical depth calculations", J. Atmos. Oceanic
   Technol. 16:1854-1861 (1999).
.. [5] F. Patat et al., "Optical atmospheric extinction over Cerro Paranal", A&A 527:A91
   (2011), doi:10.1051/0004-6361/201015537: aerosol extinction ``k0 lambda^alpha`` with
   ``k0 = 0.013 +- 0.002`` mag per airmass (``lambda`` in um) and ``alpha = -1.38 +- 0.06``;
   mean surface pressure 744 hPa.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .bands import ARCSEC2_SR, get_band, magnitude_to_radiance, solar_irradiance
from .exceptions import InvalidParameterError, SunBelowHorizonError
from .geometry import angle_between_deg, direction_vector
from .sky import Sky, SkyField
from .validation import check_finite, check_in_range

__all__ = [
    "ASTRONOMICAL_NIGHT_DEG",
    "KS_RADIANCE_PER_IRRADIANCE_SR",
    "MoonBelowHorizonError",
    "MoonlitSky",
    "NightSky",
    "TwilightError",
    "aerosol_weight",
    "dark_sky_radiance",
    "extinction_components",
    "ks_airmass",
    "moon_band_irradiance",
    "night_sky",
    "scattered_radiance",
]

ASTRONOMICAL_NIGHT_DEG = -18.0
"""Sun elevation [deg] below which the Sun adds nothing to the night sky."""

KS_RADIANCE_PER_IRRADIANCE_SR = 10.0 ** (-0.4 * 16.57) / (34.08 * np.exp(20.7233) * ARCSEC2_SR)
"""``K`` of the module docstring [sr^-1]: radiance per unit source irradiance and unit of
K&S's ``f(rho) 10^(-0.4 k X) (1 - 10^(-0.4 k X))``."""

_RAYLEIGH = 10.0 ** 5.36   # K&S eq. 17
_DEPOLARIZED = 0.06        # K&S eq. 17: the 1.06 of (1.06 + cos^2 rho)

KS_BAND = "V"
"""The band in which Krisciunas & Schaefer fitted their scattering function ``f``."""

PARANAL_PRESSURE_HPA = 744.0
"""Mean surface pressure at Paranal [hPa] (Patat et al. 2011 [5]_), for the molecular optical
thickness of the per-band split."""
PARANAL_LATITUDE_DEG, PARANAL_ALTITUDE_M = -24.6272, 2635.0
"""Paranal's latitude [deg] and altitude [m] (gravity in the molecular optical thickness)."""
AEROSOL_K0_MAG = 0.013
"""Paranal aerosol extinction at 1 um [mag per airmass] (Patat et al. 2011 [5]_)."""
AEROSOL_ANGSTROM_EXPONENT = 1.38
"""Paranal aerosol extinction goes as ``lambda^-1.38`` (Patat et al. 2011 [5]_)."""
_MAG_PER_TAU = 2.5 / np.log(10.0)   # extinction [mag] of an optical thickness of 1


class TwilightError(InvalidParameterError):
    """The Sun is in twilight (between -18 deg and the horizon), whose sky brightness skysim
    does not model. Fix: choose a time when the Sun is above the horizon or below -18 deg."""


class MoonBelowHorizonError(SunBelowHorizonError):
    """The Moon is at or below the horizon where moonlight is needed (a moonlit sky map, a
    compass reading the Moon's pattern). Fix: choose a time when the Moon is up
    (:func:`skysim.moon.moon_position` gives its elevation)."""


def ks_airmass(zenith_deg) -> np.ndarray:
    """Airmass of a scattering layer, ``X = (1 - 0.96 sin^2 Z)^(-1/2)`` ([1]_, eq. 3)."""
    z = np.radians(np.asarray(zenith_deg, float))
    return 1.0 / np.sqrt(1.0 - 0.96 * np.sin(z) ** 2)


def extinction_components(band: str) -> dict:
    """The band's extinction at Paranal split into its scattering parts [mag per airmass].

    ``rayleigh``: the molecules (Bodhaine et al. [4]_ at the band's effective wavelength,
    Paranal's pressure :data:`PARANAL_PRESSURE_HPA`); ``aerosol``: Patat et al.'s [5]_ power
    law ``0.013 (lambda / 1 um)^-1.38``; ``total``: the band's measured broadband coefficient
    (:mod:`skysim.bands`; the rest, ozone absorption and night-to-night changes, scatters
    nothing modelled here); ``wavelength_nm`` [nm].
    """
    from .molecular import bodhaine_optical_thickness
    b = get_band(band)
    tau = bodhaine_optical_thickness(b.wavelength_nm, PARANAL_PRESSURE_HPA,
                                     PARANAL_LATITUDE_DEG, PARANAL_ALTITUDE_M)
    return {"wavelength_nm": b.wavelength_nm, "rayleigh": float(_MAG_PER_TAU * tau),
            "aerosol": AEROSOL_K0_MAG * (b.wavelength_nm / 1000.0) ** -AEROSOL_ANGSTROM_EXPONENT,
            "total": b.extinction_mag_per_airmass}


def aerosol_weight(band: str) -> float:
    """Weight of K&S's aerosol term in ``band`` relative to its molecular term [1].

    ``[k_aer(b) / k_aer(V)] / [k_mol(b) / k_mol(V)]`` from :func:`extinction_components`:
    the ratio of aerosol to molecular scattering in the band over that ratio in V, where
    K&S fitted it. 1 in V.
    """
    b, v = extinction_components(band), extinction_components(KS_BAND)
    return float((b["aerosol"] / v["aerosol"]) / (b["rayleigh"] / v["rayleigh"]))


def dark_sky_radiance(view_elevation_deg, band: str = "V", zenith_mag_arcsec2=None,
                      extinction=None) -> np.ndarray:
    """Night-sky background (airglow, zodiacal light, starlight) [W m^-2 nm^-1 sr^-1].

    ``B_zen 10^(-0.4 k (X - 1)) X`` ([1]_, eq. 2) with ``X`` of :func:`ks_airmass`.

    Parameters
    ----------
    view_elevation_deg : array
        [deg], in [0, 90].
    band : str
        Photometric band (:data:`skysim.bands.BANDS`).
    zenith_mag_arcsec2 : float, optional
        Dark-sky zenith brightness [mag arcsec^-2]; default the band's Paranal value.
    extinction : float, optional
        [mag per airmass]; default the band's Paranal value.
    """
    b = get_band(band)
    zen = b.dark_sky_mag_arcsec2 if zenith_mag_arcsec2 is None else zenith_mag_arcsec2
    k = b.extinction_mag_per_airmass if extinction is None else extinction
    x = ks_airmass(90.0 - np.asarray(view_elevation_deg, float))
    return magnitude_to_radiance(zen, band) * 10.0 ** (-0.4 * k * (x - 1.0)) * x


def scattered_radiance(view_elevation_deg, view_azimuth_deg, source_elevation_deg,
                       source_azimuth_deg, irradiance, extinction,
                       aerosol_scale: float = 1.0) -> dict:
    """Radiance of a point source's light scattered in the air ([1]_, eqs. 15-21).

    Parameters
    ----------
    view_elevation_deg, view_azimuth_deg : array
        View directions [deg].
    source_elevation_deg, source_azimuth_deg : array
        Source directions [deg]; a source at or below the horizon gives 0.
    irradiance : array
        Source irradiance above the atmosphere, normal to its direction (any spectral unit,
        e.g. [W m^-2 nm^-1]).
    extinction : float
        Extinction coefficient [mag per airmass].
    aerosol_scale : float
        Factor on the aerosol term (1: K&S's V-band fit; :func:`aerosol_weight` for a band).

    Returns
    -------
    dict of arrays (broadcast shape, unit of ``irradiance`` per sr):
        ``dipole`` (``10^5.36 (1 + cos^2 rho)`` part), ``depolarized`` (``10^5.36 * 0.06``
        part), ``mie`` (``10^(6.15 - rho/40)`` part) and ``scattering_angle_deg`` [deg].
    """
    rho = angle_between_deg(direction_vector(view_elevation_deg, view_azimuth_deg),
                            direction_vector(source_elevation_deg, source_azimuth_deg))
    src_el = np.asarray(source_elevation_deg, float)
    x_src = ks_airmass(90.0 - src_el)
    x_view = ks_airmass(90.0 - np.asarray(view_elevation_deg, float))
    scale = (KS_RADIANCE_PER_IRRADIANCE_SR * np.asarray(irradiance, float)
             * 10.0 ** (-0.4 * extinction * x_src) * (1.0 - 10.0 ** (-0.4 * extinction * x_view))
             * (src_el > 0.0))
    cos2 = np.cos(np.radians(rho)) ** 2
    return {"dipole": scale * _RAYLEIGH * (1.0 + cos2),
            "depolarized": scale * _RAYLEIGH * _DEPOLARIZED * np.ones_like(cos2),
            "mie": scale * aerosol_scale * 10.0 ** (6.15 - rho / 40.0),
            "scattering_angle_deg": rho}


def moon_band_irradiance(moon, band: str = "V"):
    """The Moon's irradiance in ``band`` above the atmosphere and its ROLO disk reflectance.

    Parameters
    ----------
    moon : pandas.DataFrame
        Rows of :func:`skysim.moon.moon_position` (phase, libration, distances).
    band : str
        Photometric band (:data:`skysim.bands.BANDS`).

    Returns
    -------
    irradiance : ndarray
        Normal to the Moon's direction [W m^-2 nm^-1] (:func:`skysim.moon.lunar_irradiance`).
    reflectance : ndarray
        Disk-equivalent reflectance [1] (:func:`skysim.moon.lunar_disk_reflectance`).
    """
    from .moon import lunar_disk_reflectance, lunar_irradiance
    b = get_band(band)
    reflectance = lunar_disk_reflectance(
        b.wavelength_nm, moon.phase_angle_deg.to_numpy(),
        moon.sun_selenographic_longitude_deg.to_numpy(),
        moon.observer_selenographic_latitude_deg.to_numpy(),
        moon.observer_selenographic_longitude_deg.to_numpy())
    e_moon = lunar_irradiance(reflectance, solar_irradiance(band), moon.distance_km.to_numpy(),
                              moon.sun_distance_au.to_numpy())
    return e_moon, reflectance


def _aerosol_scale(band: str, aerosol_scale) -> float:
    """The band's :func:`aerosol_weight`, or ``aerosol_scale`` checked (finite, >= 0)."""
    if aerosol_scale is None:
        return aerosol_weight(band)
    return float(check_in_range("aerosol_scale", aerosol_scale, 0.0, 100.0,
                                hint="factor on the aerosol term; 1 is K&S's V-band fit"))


def _source_stokes(sky: Sky, vel, vaz, src_el, src_az, irradiance, extinction, w_aer):
    """(I, Q, U) of one source: K&S radiance, the dipole part polarized as ``sky``."""
    parts = scattered_radiance(vel, vaz, src_el, src_az, irradiance, extinction, w_aer)
    intensity = parts["dipole"] + parts["depolarized"] + parts["mie"]
    q = np.zeros_like(intensity)
    u = np.zeros_like(intensity)
    up = np.broadcast_to(src_el > 0.0, intensity.shape)
    if up.any():
        v_el, v_az, s_el, s_az = (np.broadcast_to(a, intensity.shape)[up]
                                  for a in (vel, vaz, src_el, src_az))
        f = sky.field(v_el, v_az, s_el, s_az)
        polarized = parts["dipole"][up] * f.dop
        two_chi = np.radians(2.0 * f.aop_deg)
        q[up] = polarized * np.cos(two_chi)
        u[up] = polarized * np.sin(two_chi)
    return intensity, q, u


@dataclass(frozen=True)
class NightSky:
    """The night sky of a band at given times and site.

    Attributes
    ----------
    field : SkyField
        Total Stokes ``I, Q, U`` [W m^-2 nm^-1 sr^-1], local-meridian basis
        (``docs/conventions.md``).
    components : dict
        ``moon_I``, ``sun_I``, ``background_I`` [W m^-2 nm^-1 sr^-1] and
        ``moon_scattering_angle_deg`` [deg].
    sources : dict
        The Moon's position, phase and irradiance, the Sun's elevation and azimuth, per time.
    """

    field: SkyField
    components: dict = field(default_factory=dict)
    sources: dict = field(default_factory=dict)


def night_sky(view_elevation_deg, view_azimuth_deg, times, site, band: str = "V",
              sky: Sky | None = None, *, include_sun: bool = True, extinction=None,
              dark_sky_mag_arcsec2=None, aerosol_scale=None) -> NightSky:
    """Stokes field of the night sky lit by the Moon (and the Sun when it is up).

    Parameters
    ----------
    view_elevation_deg, view_azimuth_deg : array
        View directions [deg], elevation in [0, 90]; broadcast against the times.
    times : timezone-aware time(s)
        One time, or one per view direction.
    site : skysim.sun.Site
    band : str
        Photometric band (:data:`skysim.bands.BANDS`).
    sky : Sky, optional
        The polarization pattern of the dipole-scattered light (default
        :class:`skysim.sky.RayleighSky` with d_max = 1).
    include_sun : bool
        Add the Sun's scattered light (False: the Moon and the background only, e.g. to
        compare with twilight data without modelling twilight).
    extinction : float, optional
        [mag per airmass]; default the band's Paranal value (:mod:`skysim.bands`).
    dark_sky_mag_arcsec2 : float, optional
        Dark-sky zenith brightness [mag arcsec^-2]; default the band's Paranal value.
    aerosol_scale : float, optional
        Factor on K&S's aerosol term [1], >= 0; default the band's :func:`aerosol_weight`
        (0: molecules only).

    Returns
    -------
    NightSky

    Raises
    ------
    TwilightError
        If ``include_sun`` and the Sun is between -18 deg and the horizon at any time.
    InvalidParameterError
        For a view direction below the horizon, an unknown band (``ValueError``), bad
        times or site (as :func:`skysim.sun.sun_position`).
    """
    from .moon import moon_position
    from .sky import RayleighSky
    from .sun import sun_position

    b = get_band(band)
    sky = RayleighSky() if sky is None else sky
    vel = check_in_range("view_elevation_deg", view_elevation_deg, 0.0, 90.0,
                         hint="ground-based sky models only look up")
    vaz = check_finite("view_azimuth_deg", view_azimuth_deg)
    k = b.extinction_mag_per_airmass if extinction is None else float(
        check_in_range("extinction", extinction, 0.0, 5.0))
    w_aer = _aerosol_scale(band, aerosol_scale)
    moon = moon_position(times, site.latitude_deg, site.longitude_deg, site.altitude_m)
    e_moon, reflectance = moon_band_irradiance(moon, band)
    m_el, m_az = moon.elevation_deg.to_numpy(), moon.azimuth_deg.to_numpy()
    if len(moon) > 1 and np.ndim(vel) == 0:
        vel, vaz = np.broadcast_to(vel, m_el.shape), np.broadcast_to(vaz, m_el.shape)
    if len(moon) == 1:
        m_el, m_az, e_moon = m_el[0], m_az[0], e_moon[0]
    I, Q, U = _source_stokes(sky, vel, vaz, m_el, m_az, e_moon, k, w_aer)
    moon_I = I.copy()
    sun = sun_position(moon.index, site.latitude_deg, site.longitude_deg, site.altitude_m)
    s_el, s_az = sun.elevation_deg.to_numpy(), sun.azimuth_deg.to_numpy()
    sun_I = np.zeros_like(I)
    if include_sun:
        twilight = (s_el > ASTRONOMICAL_NIGHT_DEG) & (s_el <= 0.0)
        if twilight.any():
            j = int(np.flatnonzero(twilight)[0])
            raise TwilightError(
                f"the Sun is at {s_el[j]:.1f} deg at {moon.index[j].isoformat()}: twilight "
                f"(between {ASTRONOMICAL_NIGHT_DEG:g} deg and the horizon), whose sky "
                "brightness is not modelled; choose a time when the Sun is above the horizon "
                f"or below {ASTRONOMICAL_NIGHT_DEG:g} deg")
        if np.any(s_el > 0.0):
            e_sun = solar_irradiance(band) / moon.sun_distance_au.to_numpy() ** 2
            se, sa, es = (a[0] if len(moon) == 1 else a for a in (s_el, s_az, e_sun))
            sun_I, sun_Q, sun_U = _source_stokes(sky, vel, vaz, se, sa, es, k, w_aer)
            I, Q, U = I + sun_I, Q + sun_Q, U + sun_U
    background = np.broadcast_to(dark_sky_radiance(vel, band, dark_sky_mag_arcsec2, k), I.shape)
    I = I + background
    vel_b, vaz_b = (np.broadcast_to(a, I.shape) for a in (vel, vaz))
    rho = angle_between_deg(direction_vector(vel_b, vaz_b),
                            direction_vector(m_el, m_az))
    sources = {"band": band, "aerosol_scale": w_aer,
               "moon": moon.assign(irradiance_W_m2_nm=e_moon, disk_reflectance=reflectance),
               "sun_elevation_deg": s_el, "sun_azimuth_deg": s_az}
    return NightSky(SkyField(vel_b, vaz_b, I, Q, U),
                    {"moon_I": moon_I, "sun_I": sun_I, "background_I": background.copy(),
                     "moon_scattering_angle_deg": rho}, sources)


class MoonlitSky(Sky):
    """The moonlit night sky of one Moon as a :class:`skysim.sky.Sky`: the Moon takes the
    Sun's place in :meth:`field`, whose ``I, Q, U`` are radiances in the band
    [W m^-2 nm^-1 sr^-1] (K&S scattered moonlight over the dark-sky background, as
    :func:`night_sky`, without the Sun). For sensors that image any ``Sky`` along their own
    view directions (:mod:`sensor.camera`, :mod:`sensor.compound_eye`).

    Parameters
    ----------
    moon_irradiance : float
        The Moon's irradiance above the atmosphere in ``band`` [W m^-2 nm^-1]
        (:func:`moon_band_irradiance`).
    band : str
        Photometric band (:data:`skysim.bands.BANDS`).
    pattern : Sky, optional
        Polarization pattern of the dipole-scattered light (default
        :class:`skysim.sky.RayleighSky` with d_max = 1).
    extinction : float, optional
        [mag per airmass]; default the band's Paranal value.
    dark_sky_mag_arcsec2 : float, optional
        Dark-sky zenith brightness [mag arcsec^-2]; default the band's Paranal value.
    aerosol_scale : float, optional
        Factor on K&S's aerosol term [1]; default the band's :func:`aerosol_weight`.
    """

    name = "moonlit"
    min_sun_elevation_deg = 0.0

    def __init__(self, moon_irradiance: float, band: str = "V", pattern: Sky | None = None,
                 extinction=None, dark_sky_mag_arcsec2=None, aerosol_scale=None):
        from .sky import RayleighSky
        b = get_band(band)
        e = float(check_finite("moon_irradiance", moon_irradiance))
        if not e > 0.0:
            raise InvalidParameterError(f"moon_irradiance must be > 0 [W m-2 nm-1]; got {e!r}")
        self.moon_irradiance, self.band = e, band
        self.pattern = RayleighSky() if pattern is None else pattern
        self.extinction = b.extinction_mag_per_airmass if extinction is None else float(
            check_in_range("extinction", extinction, 0.0, 5.0))
        self.dark_sky_mag_arcsec2 = (b.dark_sky_mag_arcsec2 if dark_sky_mag_arcsec2 is None
                                     else float(check_finite("dark_sky_mag_arcsec2",
                                                             dark_sky_mag_arcsec2)))
        self.aerosol_scale = _aerosol_scale(band, aerosol_scale)

    @classmethod
    def at(cls, time, site, band: str = "V", pattern: Sky | None = None, **kwargs):
        """The sky of the Moon at one ``time`` (timezone-aware) and ``site``
        (:class:`skysim.sun.Site`); returns ``(sky, moon)`` with ``moon`` the row of
        :func:`skysim.moon.moon_position` (elevation, azimuth, phase ...).

        Raises
        ------
        MoonBelowHorizonError
            If the Moon is at or below the horizon then.
        """
        from .moon import moon_position
        moon = moon_position([time], site.latitude_deg, site.longitude_deg, site.altitude_m)
        row = moon.iloc[0]
        if not row.elevation_deg > 0.0:
            raise MoonBelowHorizonError(
                f"the Moon is at {row.elevation_deg:.2f} deg elevation at {moon.index[0]}: "
                "below the horizon, no moonlit sky; choose a time when the Moon is up")
        e_moon, _ = moon_band_irradiance(moon, band)
        return cls(float(e_moon[0]), band, pattern, **kwargs), row

    def field(self, view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
              sun_azimuth_deg) -> SkyField:
        """Stokes field [W m^-2 nm^-1 sr^-1] for view directions and the Moon's position
        (``sun_*`` arguments: the Moon's elevation and azimuth [deg]).

        Raises
        ------
        MoonBelowHorizonError
            If a Moon elevation is at or below the horizon.
        InvalidParameterError
            A view direction below the horizon or a value that is not finite.
        """
        m_el = check_finite("moon_elevation_deg", sun_elevation_deg)
        if np.any(m_el <= 0.0) or np.any(m_el > 90.0):
            bad = m_el[(m_el <= 0.0) | (m_el > 90.0)].ravel()[0]
            raise MoonBelowHorizonError(
                f"moon elevation must be in (0, 90] deg; got {bad!r}: a Moon at or below the "
                "horizon lights no sky in this model; choose a time when the Moon is up")
        return super().field(view_elevation_deg, view_azimuth_deg, m_el, sun_azimuth_deg)

    def _stokes(self, vel, vaz, mel, maz):
        I, Q, U = _source_stokes(self.pattern, vel, vaz, mel, maz, self.moon_irradiance,
                                 self.extinction, self.aerosol_scale)
        I = I + dark_sky_radiance(vel, self.band, self.dark_sky_mag_arcsec2, self.extinction)
        return I, Q, U

    def flux_pi_scale(self, view_elevation_deg, sun_elevation_deg) -> np.ndarray:
        """``E / pi`` [W m^-2 nm^-1 sr^-1]: a radiance of 1 in the unit of an incident flux
        ``pi`` is ``E / pi`` for the Moon's irradiance ``E`` (above the atmosphere)."""
        return np.full(np.broadcast_shapes(np.shape(view_elevation_deg),
                                           np.shape(sun_elevation_deg)),
                       self.moon_irradiance / np.pi)

    def describe(self) -> dict:
        return {"model": self.name, "band": self.band,
                "moon_irradiance_W_m2_nm": self.moon_irradiance,
                "pattern": self.pattern.describe(), "extinction_mag_per_airmass": self.extinction,
                "dark_sky_mag_arcsec2": self.dark_sky_mag_arcsec2,
                "aerosol_scale": self.aerosol_scale,
                "radiance_unit": "W m-2 nm-1 sr-1"}
