"""Topocentric sun position, vectorised over times, backed by pysolar.

pysolar implements the NREL Solar Position Algorithm of Reda & Andreas [1]_ one time per
call (about 0.3-0.5 ms each). :func:`sun_position` evaluates it only at *knots* on a regular
15-minute grid around the requested times and interpolates the sun's ENU unit vector with
4-point (cubic) Lagrange interpolation, then renormalises. The unit vector is smooth even
where azimuth is not (sun near the zenith). With 15-minute knots the interpolation error is
below 1e-5 deg (tested against direct pysolar calls to be <= 0.001 deg).

Refraction: by default the position is *geometric* (no refraction), the right geometry for
scattering calculations. ``refraction=True`` adds pysolar's Bennett-type correction for
standard pressure and temperature (useful to compare with apparent sunrise/sunset).

References
----------
.. [1] I. Reda and A. Andreas, "Solar position algorithm for solar radiation applications",
   Solar Energy 76(5):577-589 (2004), doi:10.1016/j.solener.2003.12.003.
"""

from __future__ import annotations

import datetime as _dt
import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd
from pysolar import solar as _solar
from pysolar import solartime as _solartime

from .exceptions import NaiveDatetimeError
from .geometry import direction_vector, elevation_azimuth
from .validation import check_in_range, check_latitude, check_longitude

__all__ = [
    "Site",
    "as_utc_index",
    "sun_position",
    "sun_vector",
    "apparent_solar_time",
    "clock_time_from_apparent_solar_time",
]

KNOT_SPACING_S = 900.0
"""Spacing of the pysolar knots [s]; see the module docstring for the error this gives."""


@dataclass(frozen=True)
class Site:
    """An observing site.

    Parameters
    ----------
    latitude_deg : float
        Geodetic latitude [deg], north positive, in [-90, 90].
    longitude_deg : float
        Longitude [deg], east positive.
    altitude_m : float
        Height above sea level [m].
    name : str
        Free text.
    """

    latitude_deg: float
    longitude_deg: float
    altitude_m: float = 0.0
    name: str = ""

    def __post_init__(self):
        check_latitude(self.latitude_deg)
        check_longitude(self.longitude_deg)
        check_in_range("altitude_m", self.altitude_m, -500.0, 9000.0)

    def to_dict(self) -> dict:
        return {"latitude_deg": float(self.latitude_deg),
                "longitude_deg": float(self.longitude_deg),
                "altitude_m": float(self.altitude_m), "name": self.name}

    @classmethod
    def from_dict(cls, d: dict) -> "Site":
        return cls(float(d["latitude_deg"]), float(d["longitude_deg"]),
                   float(d.get("altitude_m", 0.0)), str(d.get("name", "")))


def as_utc_index(times) -> pd.DatetimeIndex:
    """Convert timezone-aware times to a UTC :class:`pandas.DatetimeIndex`.

    Raises
    ------
    NaiveDatetimeError
        If any time has no timezone (skysim never guesses UTC).
    """
    if isinstance(times, (pd.DatetimeIndex, pd.Series)):
        idx = pd.DatetimeIndex(times)
        if idx.tz is None:
            raise NaiveDatetimeError(
                f"times are timezone-naive (first: {idx[0] if len(idx) else '<empty>'}); "
                "localise them, e.g. times.tz_localize('Asia/Shanghai')")
        return idx.tz_convert("UTC")
    if isinstance(times, (_dt.datetime, pd.Timestamp, str, np.datetime64)):
        seq = [times]
    elif isinstance(times, (list, tuple)):
        seq = list(times)
    else:
        seq = list(np.atleast_1d(times))
    out = []
    for t in seq:  # list input: per-element tz check (arrays should be DatetimeIndex)
        ts = pd.Timestamp(t)
        if ts.tzinfo is None:
            raise NaiveDatetimeError(
                f"time {t!r} is timezone-naive; give a UTC offset or zone, e.g. "
                "'2013-05-22T17:10:00+08:00' or datetime(..., tzinfo=timezone.utc)")
        out.append(ts.tz_convert("UTC"))
    return pd.DatetimeIndex(out)


def _ut1_shift_s(when: _dt.datetime) -> float:
    """Seconds pysolar's UT1 runs ahead of UTC: ``(TT - UTC) - dT_pysolar``.

    pysolar derives UT1 as ``UTC + (leap seconds + 32.184 s) - dT`` with a tabulated dT that
    stops in 2017 (67.389 s) while TT - UTC has been 69.184 s since then, so from 2017 on its
    Earth-rotation angle is 1.8 s (0.0075 deg) ahead. UTC is kept within 0.9 s of UT1 by
    definition, so we evaluate pysolar at ``UTC - shift``: UT1 = UTC as in NREL SPA with
    dUT1 = 0. The ephemeris time then moves by the same < 2 s (< 3e-5 deg of solar longitude).
    """
    with warnings.catch_warnings():
        # pysolar warns that its leap-second table ends; none was added after 2016-12-31.
        warnings.simplefilter("ignore", UserWarning)
        return _solartime.get_leap_seconds(when) + 32.184 - _solartime.get_delta_t(when)


def _pysolar_vectors(site: Site, when_utc: pd.DatetimeIndex, refraction: bool) -> np.ndarray:
    """Direct pysolar evaluation, one call per time (the library has no array API)."""
    lat, lon, alt = site.latitude_deg, site.longitude_deg, site.altitude_m
    el = np.empty(len(when_utc))
    az = np.empty(len(when_utc))
    for k, t in enumerate(when_utc.to_pydatetime()):
        t = t - _dt.timedelta(seconds=_ut1_shift_s(t))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # see _ut1_shift_s
            dec, ha = _solar.get_topocentric_position(lat, lon, t, alt)
        e = _solar.get_topocentric_elevation_angle(lat, dec, ha)
        if refraction:
            e = e + _solar.get_refraction_correction(101325.0, 283.0, e)
        el[k] = e
        az[k] = _solar.get_topocentric_azimuth_angle(ha, lat, dec)
    return direction_vector(el, az)


def sun_vector(times, site: Site, refraction: bool = False, method: str = "interpolated"):
    """Sun ENU unit vectors, shape ``(n, 3)``, and the UTC index of the times.

    Parameters
    ----------
    times : array-like of timezone-aware datetimes, DatetimeIndex or Series
    site : Site
    refraction : bool
        Apply atmospheric refraction (default False: geometric position).
    method : {'interpolated', 'pysolar'}
        'interpolated' evaluates pysolar on 15-minute knots and interpolates (fast; when
        the times are so sparse that they need more knots than times, pysolar is called
        directly instead); 'pysolar' calls pysolar for every time (reference, slow).
    """
    idx = as_utc_index(times)
    if method == "pysolar":
        return _pysolar_vectors(site, idx, refraction), idx
    if method != "interpolated":
        raise ValueError(f"unknown method {method!r}; valid: 'interpolated', 'pysolar'")
    if len(idx) == 0:
        return np.empty((0, 3)), idx
    t_s = idx.as_unit("ns").asi8 / 1e9  # seconds since epoch, UTC
    k = np.floor(t_s / KNOT_SPACING_S).astype(np.int64)
    x = t_s / KNOT_SPACING_S - k  # in [0, 1)
    offsets = np.arange(-1, 3)
    knots, inverse = np.unique(k[:, None] + offsets[None, :], return_inverse=True)
    if knots.size >= len(idx):  # sparse times: direct calls are fewer and exact
        return _pysolar_vectors(site, idx, refraction), idx
    inverse = inverse.reshape(len(k), 4)
    knot_times = pd.to_datetime(knots * int(KNOT_SPACING_S), unit="s", utc=True)
    knot_vec = _pysolar_vectors(site, knot_times, refraction)
    # 4-point Lagrange weights for nodes at -1, 0, 1, 2
    w = np.stack([-x * (x - 1) * (x - 2) / 6.0,
                  (x + 1) * (x - 1) * (x - 2) / 2.0,
                  -(x + 1) * x * (x - 2) / 2.0,
                  (x + 1) * x * (x - 1) / 6.0], axis=1)
    vec = np.einsum("nk,nkc->nc", w, knot_vec[inverse])
    vec /= np.linalg.norm(vec, axis=1, keepdims=True)
    return vec, idx


def sun_position(times, latitude_deg: float, longitude_deg: float, altitude_m: float = 0.0,
                 refraction: bool = False, method: str = "interpolated") -> pd.DataFrame:
    """Topocentric sun position for each time.

    Parameters
    ----------
    times : timezone-aware datetimes (scalar, list, DatetimeIndex or Series)
    latitude_deg, longitude_deg : float
        Site [deg], north and east positive.
    altitude_m : float
        Site height [m].
    refraction : bool
        Default False: geometric elevation (what scattering geometry needs).
    method : {'interpolated', 'pysolar'}
        See :func:`sun_vector`.

    Returns
    -------
    pandas.DataFrame
        Columns ``elevation_deg``, ``azimuth_deg`` (clockwise from north, [0, 360)),
        ``zenith_deg`` [deg]; indexed by the times in their original timezone.

    Raises
    ------
    NaiveDatetimeError
        For a time without timezone.
    InvalidParameterError
        For a latitude outside [-90, 90].
    """
    site = Site(latitude_deg, longitude_deg, altitude_m)
    vec, idx = sun_vector(times, site, refraction=refraction, method=method)
    el, az = elevation_azimuth(vec)
    index = _original_index(times, idx)
    return pd.DataFrame({"elevation_deg": el, "azimuth_deg": az, "zenith_deg": 90.0 - el},
                        index=index)


def _original_index(times, idx_utc: pd.DatetimeIndex) -> pd.DatetimeIndex:
    if isinstance(times, (pd.DatetimeIndex, pd.Series)):
        return pd.DatetimeIndex(times)
    try:
        return pd.DatetimeIndex([pd.Timestamp(t) for t in np.atleast_1d(times)])
    except (ValueError, TypeError):  # mixed offsets: keep UTC
        return idx_utc


def apparent_solar_time(times, longitude_deg: float, latitude_deg: float = 0.0) -> pd.Series:
    """Local apparent (true) solar time for each time, as hours in [0, 24).

    Computed from the sun's topocentric hour angle ``H`` given by pysolar: LAST = 12 h + H/15
    (Meeus, *Astronomical Algorithms*, ch. 28). Latitude only enters through parallax (< 1 s).

    Returns
    -------
    pandas.Series of float hours indexed like ``times``.
    """
    idx = as_utc_index(times)
    check_longitude(longitude_deg)
    hours = np.empty(len(idx))
    for k, t in enumerate(idx.to_pydatetime()):
        t = t - _dt.timedelta(seconds=_ut1_shift_s(t))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # see _ut1_shift_s
            _, ha = _solar.get_topocentric_position(latitude_deg, longitude_deg, t, 0.0)
        hours[k] = np.mod(12.0 + ha / 15.0, 24.0)
    return pd.Series(hours, index=_original_index(times, idx), name="apparent_solar_time_h")


def clock_time_from_apparent_solar_time(date, apparent_hours: float, longitude_deg: float,
                                        tz, latitude_deg: float = 0.0) -> pd.Timestamp:
    """Clock time (in zone ``tz``) at which local apparent solar time equals ``apparent_hours``.

    Fixed-point iteration on the equation of time (converges to < 1 ms in 3 steps).

    Parameters
    ----------
    date : date-like
        Calendar date of the observation (local).
    apparent_hours : float
        Local apparent solar time [h], e.g. 17.333 for 17:20.
    longitude_deg : float
        East positive [deg].
    tz : tzinfo or str
        Zone of the returned clock time.
    """
    day = pd.Timestamp(date).normalize().tz_localize(None)
    # first guess: mean solar time, UTC = LAST - lon/15
    guess = (day + pd.Timedelta(hours=apparent_hours - longitude_deg / 15.0)).tz_localize("UTC")
    for _ in range(5):
        last = apparent_solar_time([guess], longitude_deg, latitude_deg).iloc[0]
        diff_h = (apparent_hours - last + 12.0) % 24.0 - 12.0
        guess = guess + pd.Timedelta(hours=diff_h)
        if abs(diff_h) * 3600 < 1e-3:
            break
    return guess.tz_convert(tz)
