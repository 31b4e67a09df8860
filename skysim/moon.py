"""The Moon as a light source: topocentric position, phase, libration and irradiance.

Position: astropy's built-in ephemeris (``get_body("moon")`` with ``solar_system_ephemeris
"builtin"``: ERFA's ``moon98``, the ELP2000-82 truncation of Meeus, *Astronomical
Algorithms*, ch. 47 [3]_, good to about 10 arcsec in longitude and 4 arcsec in latitude), then
astropy's rigorous ICRS -> topocentric alt/az chain (precession, nutation, aberration,
diurnal parallax), without refraction (geometric, as :mod:`skysim.sun`). Nothing is
downloaded and no result depends on the day it is computed: the ephemeris is a series in the
code, and Earth-orientation data come from the tables bundled with astropy, used however old
they are. Past their end the last predicted UT1 - UTC is held; the IERS keeps |UT1 - UTC| below
0.9 s, so the error is below 1.8 s of Earth rotation (0.008 deg), and polar motion falls back
to its 50-year mean (arcseconds). Leap seconds not yet announced (ERFA's "dubious year") shift
UTC by whole seconds, within the same bound per leap second. It is vectorised over times and
sites, for any date.

Phase: the phase angle ``i`` (Sun-Moon-observer) from the elongation and the distances
(Meeus eq. 48.3 [3]_) and the illuminated fraction ``k = (1 + cos i) / 2`` (eq. 48.1).

Libration and the Sun's selenographic position: Meeus ch. 53 [3]_ (optical libration; the
physical libration, below 0.04 deg, is neglected), from the Moon's and the Sun's geocentric
ecliptic coordinates referred to the mean equinox of date.

Irradiance: the ROLO model of Kieffer & Stone [1]_: the disk-equivalent reflectance ``A``
(their eq. 10, coefficients of their Table 4 in ``skysim/data/rolo_kieffer_stone_2005.csv``)
and the irradiance ``E = A Omega_M E_sun / pi`` scaled to the actual distances (their
eq. 8 with the standard distances 384400 km and 1 AU). ``E_sun`` in a photometric band is
that band's solar irradiance (:mod:`skysim.bands`).

References
----------
.. [1] H. H. Kieffer and T. C. Stone, "The spectral irradiance of the Moon", Astron. J.
   129:2887-2901 (2005), doi:10.1086/430185, eqs. 8 and 10, Table 4.
.. [2] Astropy Collaboration, "The Astropy Project", ApJ 935:167 (2022),
   doi:10.3847/1538-4357/ac7c74.
.. [3] J. Meeus, *Astronomical Algorithms*, 2nd ed., Willmann-Bell (1998), ch. 47, 48, 53.
"""

from __future__ import annotations

import contextlib
import functools
from pathlib import Path

import numpy as np
import pandas as pd

from .exceptions import InvalidParameterError, MissingDependencyError
from .sun import _UNITS_PER_S, SunTrack, _as_site_arrays, _original_index, as_utc_index
from .validation import check_in_range

__all__ = [
    "MOON_SOLID_ANGLE_SR",
    "ROLO_WAVELENGTH_RANGE_NM",
    "MoonTrack",
    "lunar_disk_reflectance",
    "lunar_irradiance",
    "moon_position",
    "moon_vector",
]

MOON_SOLID_ANGLE_SR = 6.4177e-5
"""Solid angle of the Moon at the standard distance of 384400 km [sr] (Kieffer & Stone
2005 [1]_, eq. 8)."""

STANDARD_MOON_DISTANCE_KM = 384400.0
"""Standard Earth-Moon distance of the ROLO model [km]."""

ROLO_FILE = Path(__file__).with_name("data") / "rolo_kieffer_stone_2005.csv"
"""Coefficients of the ROLO model (Kieffer & Stone 2005 [1]_, Table 4), with the builder
beside it."""

ROLO_WAVELENGTH_RANGE_NM = (350.0, 2383.6)
"""Wavelengths [nm] of the first and last ROLO band; the model is not extrapolated."""

_OBLIQUITY_I_DEG = 1.54242  # inclination of the lunar equator to the ecliptic (Meeus ch. 53)
_AU_KM = 149_597_870.7


# --------------------------------------------------------------------------- position


@contextlib.contextmanager
def _offline_astropy():
    """astropy with its built-in lunar ephemeris and bundled Earth-orientation tables only
    (no download, whatever today's date; past the tables' end see the module docstring).

    The warnings astropy and ERFA give past the tables (polar motion from its mean, a
    "dubious year" for leap seconds not yet announced) are silenced: their effect is within
    the accuracy the module docstring states.
    """
    import warnings

    from astropy.coordinates import solar_system_ephemeris
    from astropy.utils import iers
    # auto_max_age None: the bundled predictions are used whatever today's date (astropy
    # otherwise refuses predictions more than 30 days older than the computer's clock, which
    # would make a result depend on the day it is computed)
    with iers.conf.set_temp("auto_download", False), \
            iers.conf.set_temp("auto_max_age", None), \
            iers.conf.set_temp("iers_degraded_accuracy", "ignore"), \
            solar_system_ephemeris.set("builtin"), warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*polar motions for times after IERS")
        warnings.filterwarnings("ignore", message=r".*dubious year")
        yield


def _import_astropy():
    try:
        import astropy  # noqa: F401
    except ImportError as exc:  # the message names the extra that installs it
        from .extras import missing_extra_message
        raise MissingDependencyError(missing_extra_message("astropy", "the Moon's position"),
                                     name="astropy") from exc


def moon_position(times, latitude_deg, longitude_deg, altitude_m=0.0) -> pd.DataFrame:
    """Topocentric position, phase and libration of the Moon for each time.

    Parameters
    ----------
    times : timezone-aware datetimes (scalar, list, DatetimeIndex or Series), n of them
    latitude_deg, longitude_deg : float or array (n,)
        Site [deg], north and east positive; one per time or one for all.
    altitude_m : float or array (n,)
        Site height above sea level [m].

    Returns
    -------
    pandas.DataFrame indexed by the times, with columns
        ``elevation_deg``, ``azimuth_deg`` (clockwise from north, [0, 360)), ``zenith_deg``
        [deg] (geometric, no refraction); ``distance_km`` (observer-Moon) [km];
        ``sun_distance_au`` (Moon-Sun) [AU]; ``phase_angle_deg`` (Sun-Moon-observer, in
        [0, 180]) [deg]; ``illuminated_fraction`` [1]; ``waxing`` (bool: the Moon's
        ecliptic longitude runs ahead of the Sun's by less than 180 deg);
        ``sun_selenographic_longitude_deg``, ``observer_selenographic_latitude_deg``,
        ``observer_selenographic_longitude_deg`` [deg] (geocentric optical libration,
        Meeus ch. 53).

    Raises
    ------
    NaiveDatetimeError, InvalidTimeError, InvalidParameterError, BroadcastError
        As :func:`skysim.sun.sun_position`.
    MissingDependencyError
        Without astropy (extra ``moon``); the message gives the install command.
    """
    idx = as_utc_index(times)
    lat, lon, alt, n = _as_site_arrays(len(idx), latitude_deg, longitude_deg, altitude_m)
    if len(idx) == 1 and n > 1:
        idx = idx.repeat(n)
    columns = _moon_columns(idx, lat, lon, alt)
    index = _original_index(times, idx)
    if len(index) != len(idx):
        index = index.repeat(len(idx))
    return pd.DataFrame(columns, index=index)


def _moon_columns(idx: pd.DatetimeIndex, lat, lon, alt) -> dict:
    _import_astropy()
    import astropy.units as u
    from astropy.coordinates import (
        AltAz,
        EarthLocation,
        GeocentricMeanEcliptic,
        get_body,
    )
    from astropy.time import Time

    names = ("elevation_deg", "azimuth_deg", "zenith_deg", "distance_km", "sun_distance_au",
             "phase_angle_deg", "illuminated_fraction", "waxing",
             "sun_selenographic_longitude_deg", "observer_selenographic_latitude_deg",
             "observer_selenographic_longitude_deg")
    if len(idx) == 0:
        return {k: np.empty(0, dtype=bool if k == "waxing" else float) for k in names}
    t = Time(idx.asi8 / _UNITS_PER_S[idx.unit], format="unix", scale="utc")
    loc = EarthLocation.from_geodetic(lon * u.deg, lat * u.deg, alt * u.m)
    with _offline_astropy():
        moon = get_body("moon", t, loc)
        sun = get_body("sun", t, loc)
        altaz = moon.transform_to(AltAz(obstime=t, location=loc))
        geo_moon = get_body("moon", t).transform_to(GeocentricMeanEcliptic(equinox=t,
                                                                           obstime=t))
        geo_sun = get_body("sun", t).transform_to(GeocentricMeanEcliptic(equinox=t,
                                                                         obstime=t))
    el = altaz.alt.deg
    az = np.mod(altaz.az.deg, 360.0)
    d_moon = moon.distance.to_value(u.km)
    d_sun = sun.distance.to_value(u.km)
    psi = np.radians(sun.separation(moon).deg)                       # elongation
    phase = np.degrees(np.arctan2(d_sun * np.sin(psi), d_moon - d_sun * np.cos(psi)))
    sun_moon_km = np.sqrt(d_sun ** 2 + d_moon ** 2 - 2 * d_sun * d_moon * np.cos(psi))
    lib = selenographic_angles(
        idx, geo_moon.lon.deg, geo_moon.lat.deg, geo_moon.distance.to_value(u.km),
        geo_sun.lon.deg, geo_sun.distance.to_value(u.km))
    return {"elevation_deg": el, "azimuth_deg": np.where(az >= 360.0, 0.0, az),
            "zenith_deg": 90.0 - el, "distance_km": d_moon,
            "sun_distance_au": sun_moon_km / _AU_KM, "phase_angle_deg": phase,
            "illuminated_fraction": 0.5 * (1.0 + np.cos(np.radians(phase))),
            "waxing": np.mod(geo_moon.lon.deg - geo_sun.lon.deg, 360.0) < 180.0, **lib}


def selenographic_angles(times, moon_lon_deg, moon_lat_deg, moon_distance_km, sun_lon_deg,
                         sun_distance_km) -> dict:
    """Optical libration and the Sun's selenographic longitude (Meeus ch. 53 [3]_).

    Parameters
    ----------
    times : UTC DatetimeIndex (for the mean node and argument of latitude; TT - UTC is
        neglected: 69 s move them by 3e-4 deg)
    moon_lon_deg, moon_lat_deg : array
        The Moon's geocentric ecliptic longitude and latitude, mean equinox of date [deg].
    moon_distance_km : array
        Geocentric distance of the Moon [km].
    sun_lon_deg : array
        The Sun's geocentric ecliptic longitude, mean equinox of date [deg].
    sun_distance_km : array
        Geocentric distance of the Sun [km].

    Returns
    -------
    dict with ``observer_selenographic_longitude_deg`` (l'), ``..._latitude_deg`` (b') and
    ``sun_selenographic_longitude_deg`` (l0'), each in [-180, 180) [deg].
    """
    T = (as_utc_index(times).to_julian_date().to_numpy() - 2451545.0) / 36525.0
    node = 125.0445479 - 1934.1362891 * T + 0.0020754 * T ** 2 + T ** 3 / 467441.0 \
        - T ** 4 / 60616000.0                                                   # eq. 47.7
    arg_lat = 93.2720950 + 483202.0175233 * T - 0.0036539 * T ** 2 - T ** 3 / 3526000.0 \
        + T ** 4 / 863310000.0                                                  # eq. 47.5
    lam, beta = np.asarray(moon_lon_deg, float), np.asarray(moon_lat_deg, float)
    # the Sun as seen from the Moon (Meeus ch. 53, "selenographic position of the Sun")
    ratio = np.asarray(moon_distance_km, float) / np.asarray(sun_distance_km, float)
    lam_h = sun_lon_deg + 180.0 + np.degrees(ratio * np.cos(np.radians(beta))
                                             * np.sin(np.radians(sun_lon_deg - lam)))
    beta_h = ratio * beta
    l_obs, b_obs = _optical_libration(lam, beta, node, arg_lat)
    l_sun, _ = _optical_libration(lam_h, beta_h, node, arg_lat)
    return {"sun_selenographic_longitude_deg": l_sun,
            "observer_selenographic_latitude_deg": b_obs,
            "observer_selenographic_longitude_deg": l_obs}


def _optical_libration(lam_deg, beta_deg, node_deg, arg_lat_deg):
    """Meeus eq. 53.1: selenographic longitude and latitude [deg] of the direction with
    ecliptic longitude ``lam`` and latitude ``beta`` (mean equinox of date)."""
    w = np.radians(lam_deg - node_deg)
    b = np.radians(beta_deg)
    inc = np.radians(_OBLIQUITY_I_DEG)
    a = np.degrees(np.arctan2(np.sin(w) * np.cos(b) * np.cos(inc) - np.sin(b) * np.sin(inc),
                              np.cos(w) * np.cos(b)))
    lon = np.mod(a - arg_lat_deg + 180.0, 360.0) - 180.0
    lat = np.degrees(np.arcsin(-np.sin(w) * np.cos(b) * np.sin(inc)
                               - np.sin(b) * np.cos(inc)))
    return lon, lat


# --------------------------------------------------------------------------- ROLO


@functools.lru_cache(maxsize=1)
def _rolo_table():
    """(wavelengths [nm], (n_bands, 10) per-band coefficients, c1..c4, p1..p4 [deg])."""
    lines = ROLO_FILE.read_text().splitlines()
    meta = {ln.split("=")[0].strip("# ").split()[0]: np.array(ln.split("=")[1].split(), float)
            for ln in lines if ln.startswith("#") and "=" in ln}
    rows = np.array([ln.split(",") for ln in lines if ln and ln[0].isdigit()], dtype=float)
    return rows[:, 0], rows[:, 1:], meta["c1..c4"], meta["p1..p4"]


def lunar_disk_reflectance(wavelength_nm, phase_angle_deg, sun_selenographic_longitude_deg,
                           observer_selenographic_latitude_deg=0.0,
                           observer_selenographic_longitude_deg=0.0) -> np.ndarray:
    """ROLO disk-equivalent reflectance ``A`` of the Moon (Kieffer & Stone 2005 [1]_, eq. 10).

    ``ln A = sum_i a_i g^i + sum_j b_j Phi^(2j-1) + c1 theta + c2 phi + c3 Phi theta
    + c4 Phi phi + d1 exp(-g/p1) + d2 exp(-g/p2) + d3 cos((g - p3)/p4)``, with the phase
    angle ``g`` and the Sun's selenographic longitude ``Phi`` in radians in the polynomials
    and ``g`` in degrees in the opposition terms (``p`` in degrees), the observer's
    selenographic latitude ``theta`` and longitude ``phi`` in degrees. Between the 32 ROLO
    bands ``ln A`` is interpolated linearly in wavelength.

    Parameters
    ----------
    wavelength_nm : float or array
        Wavelength [nm], within :data:`ROLO_WAVELENGTH_RANGE_NM`.
    phase_angle_deg : array
        Absolute phase angle [deg], in [0, 180]; the model was fitted over 1.5-97 deg [1]_.
    sun_selenographic_longitude_deg, observer_selenographic_latitude_deg,
    observer_selenographic_longitude_deg : array
        [deg], as :func:`moon_position` gives them.

    Returns
    -------
    ndarray : reflectance [1], broadcast shape.
    """
    lam = check_in_range("wavelength_nm", wavelength_nm, *ROLO_WAVELENGTH_RANGE_NM,
                         hint="the ROLO lunar model covers 350-2384 nm")
    g_deg = check_in_range("phase_angle_deg", phase_angle_deg, 0.0, 180.0)
    waves, coef, c, p = _rolo_table()
    k = np.clip(np.searchsorted(waves, lam, side="right") - 1, 0, waves.size - 2)
    w = (lam - waves[k]) / (waves[k + 1] - waves[k])
    g = np.radians(g_deg)
    phi_sun = np.radians(np.asarray(sun_selenographic_longitude_deg, float))
    theta = np.asarray(observer_selenographic_latitude_deg, float)
    phi = np.asarray(observer_selenographic_longitude_deg, float)

    def ln_a(cf):
        a0, a1, a2, a3, b1, b2, b3, d1, d2, d3 = np.moveaxis(cf, -1, 0)
        return (a0 + a1 * g + a2 * g ** 2 + a3 * g ** 3
                + b1 * phi_sun + b2 * phi_sun ** 3 + b3 * phi_sun ** 5
                + c[0] * theta + c[1] * phi + c[2] * phi_sun * theta + c[3] * phi_sun * phi
                + d1 * np.exp(-g_deg / p[0]) + d2 * np.exp(-g_deg / p[1])
                + d3 * np.cos((g_deg - p[2]) / p[3]))

    return np.exp((1.0 - w) * ln_a(coef[k]) + w * ln_a(coef[k + 1]))


def lunar_irradiance(reflectance, solar_irradiance, moon_distance_km,
                     sun_distance_au=1.0) -> np.ndarray:
    """Irradiance of the Moon at the observer (Kieffer & Stone 2005 [1]_, eq. 8).

    ``E = A Omega_M E_sun / pi * (384400 km / d)^2 * (1 AU / r)^2``.

    Parameters
    ----------
    reflectance : array
        Disk-equivalent reflectance ``A`` (:func:`lunar_disk_reflectance`) [1].
    solar_irradiance : float or array
        Solar irradiance at 1 AU in the same spectral unit as the result (e.g. a band's
        [W m^-2 nm^-1], :func:`skysim.bands.solar_irradiance`).
    moon_distance_km : array
        Observer-Moon distance [km].
    sun_distance_au : array
        Moon-Sun distance [AU].

    Returns
    -------
    ndarray : irradiance normal to the Moon's direction, unit of ``solar_irradiance``.
    """
    d = np.asarray(moon_distance_km, float)
    r = np.asarray(sun_distance_au, float)
    if np.any(~(d > 0)) or np.any(~(r > 0)):
        raise InvalidParameterError(f"distances must be positive; got moon_distance_km "
                                    f"{d.min()!r}, sun_distance_au {r.min()!r}")
    return (np.asarray(reflectance, float) * MOON_SOLID_ANGLE_SR * np.asarray(solar_irradiance)
            / np.pi * (STANDARD_MOON_DISTANCE_KM / d) ** 2 / r ** 2)


def moon_vector(times, site):
    """Moon ENU unit vectors, shape ``(n, 3)``, and the UTC index of the times (topocentric,
    geometric: :func:`moon_position`), the counterpart of :func:`skysim.sun.sun_vector`.

    Raises
    ------
    As :func:`moon_position`.
    """
    from .geometry import direction_vector
    pos = moon_position(times, site.latitude_deg, site.longitude_deg, site.altitude_m)
    return (direction_vector(pos["elevation_deg"].to_numpy(float),
                             pos["azimuth_deg"].to_numpy(float)), as_utc_index(times))


class MoonTrack(SunTrack):
    """The Moon's direction over a span of times, from ephemeris knots (:func:`moon_vector`),
    with the interface of :class:`skysim.sun.SunTrack`, for fits of a sky lit by the Moon.
    The Moon crosses the sky at most ~0.25 deg/min as the Sun does, so 60-s knots keep the
    same < 1e-4 deg interpolation error (tested)."""

    @staticmethod
    def _vectors(times, site):
        return moon_vector(times, site)[0]
