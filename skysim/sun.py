"""Topocentric sun position: the NREL Solar Position Algorithm in numpy, over arrays.

:func:`sun_position` implements the Solar Position Algorithm (SPA) of Reda & Andreas [1]_
for arrays of times, each with its own site if wanted: Julian days (eqs. 4-8), ΔT
(:func:`delta_t_seconds`), the Earth's heliocentric longitude, latitude and radius from the
VSOP87 periodic terms (eqs. 9-12), geocentric longitude and latitude (eqs. 13-14), nutation
(eqs. 15-23), true obliquity (eqs. 24-25), aberration (eq. 26), apparent longitude (eq. 27),
apparent sidereal time (eqs. 28-29), geocentric right ascension and declination (eqs.
30-31), hour angle (eq. 32), topocentric parallax (eqs. 33-40, evaluated as the subtraction
of the observer's position from the sun's, which is the same rigorous transformation), the
topocentric elevation and azimuth (eqs. 41, 45-46) and the optional refraction (eqs. 42-43).
The periodic-term tables are pysolar's published copy of the paper's tables, so pysolar (the
per-time reference) and this module use one set of numbers.

Accuracy: the SPA itself is good to ±0.0003 deg over the years -2000 to 6000 [1]_ (given
ΔT). Evaluated directly, this implementation agrees with pvlib's NREL SPA and with per-time
pysolar (same ΔT) to about 1e-7 deg in elevation and in the angle between the directions
(measured at random sites and times); the knot interpolation adds at most
:data:`INTERPOLATION_ERROR_BOUND_DEG`. The project's tested guarantees are 0.01 deg in
elevation and 0.05 deg in azimuth against pvlib, and 0.001 deg against pysolar.

Speed: the expensive part (periodic terms and nutation, about 320 sines and cosines) depends
only on the terrestrial time, and it is smooth: its shortest periods are a few days. When
the times are many for their span (more times than knots), that part is evaluated at knots
every :data:`KNOT_SPACING_DAYS` and interpolated (4-point Lagrange) to each time; the Earth's
rotation, the parallax and everything site-dependent are always evaluated at each time
exactly. The interpolation adds less than :data:`INTERPOLATION_ERROR_BOUND_DEG` (measured in
the test suite). The knots lie on one fixed grid, so a time's result never depends on the
other times of the call, only on whether direct or interpolated evaluation was chosen.
``method="spa"`` forces direct evaluation at every time.

Time scales: the times are UTC and UT1 is taken equal to UTC (dUT1 = 0, as in SPA; UTC is kept
within 0.9 s of UT1, i.e. within 0.004 deg of Earth rotation). Terrestrial time is
UT1 + ΔT.

Refraction: by default the position is *geometric* (no refraction), the right geometry for
scattering calculations. ``refraction=True`` adds SPA's refraction (eq. 42, Bennett-type) for
the given pressure and temperature (useful to compare with apparent sunrise and sunset).

References
----------
.. [1] I. Reda and A. Andreas, "Solar position algorithm for solar radiation applications",
   Solar Energy 76(5):577-589 (2004), doi:10.1016/j.solener.2003.12.003; equation numbers
   of the report NREL/TP-560-34302 (revised January 2008).
.. [2] F. Espenak and J. Meeus, "Five millennium canon of solar eclipses: -1999 to +3000",
   NASA/TP-2006-214141 (2006), section 2.6 (polynomial expressions for ΔT).
"""

from __future__ import annotations

import datetime as _dt
import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd
from pysolar import constants as _pysolar_constants
from pysolar import solar as _solar
from pysolar import solartime as _solartime

from .exceptions import (
    BroadcastError,
    InvalidParameterError,
    InvalidTimeError,
    NaiveDatetimeError,
)
from .geometry import direction_vector, elevation_azimuth
from .validation import (
    as_float_array,
    check_finite,
    check_in_range,
    check_latitude,
    check_longitude,
)

__all__ = [
    "Site",
    "as_utc_index",
    "delta_t_seconds",
    "pysolar_delta_t_s",
    "sun_position",
    "sun_vector",
    "SunTrack",
    "apparent_solar_time",
    "clock_time_from_apparent_solar_time",
    "KNOT_SPACING_DAYS",
    "INTERPOLATION_ERROR_BOUND_DEG",
]

KNOT_SPACING_DAYS = 2.0
"""Spacing of the knots of the time-only part of the SPA [day] (terrestrial time). The
interpolation error grows as its fourth power: measured maxima over 1995-2025 are 1.2e-8,
1.9e-7, 3e-6 and 4e-5 deg for 0.5, 1, 2 and 4 days."""

INTERPOLATION_ERROR_BOUND_DEG = 1e-5
"""Upper bound of the angle the knot interpolation adds to the sun direction [deg] (3e-6
measured; 1/30 of the SPA's own uncertainty)."""

METHODS = ("auto", "spa", "interpolated", "pysolar")

_J2000_UTC_S = 946_728_000  # 2000-01-01T12:00:00 UTC [s since 1970], JD 2451545.0 (UT)
_UNITS_PER_S = {"s": 1, "ms": 10**3, "us": 10**6, "ns": 10**9}
_PARALLAX_RAD = np.radians(8.794 / 3600.0)  # eq. 33: R sin(xi) [AU rad]
_BLOCK = 4096  # times per block of the periodic-term evaluation (bounds the temporaries)

# --------------------------------------------------------------------------- tables


def _periodic_terms():
    """Every VSOP87 term of SPA's periodic-term table (A, B, C) and a (terms, 13) matrix that
    sums them into L0..L5, B0..B1, R0..R4 (eqs. 9-10: ``sum A cos(B + C JME)``)."""
    c = _pysolar_constants
    series = [*c.heliocentric_longitude_coeffs, *c.heliocentric_latitude_coeffs,
              *c.sun_earth_distance_coeffs]
    rows = np.array([r for s in series for r in s], dtype=float)
    group = np.repeat(np.arange(len(series)), [len(s) for s in series])
    weights = np.zeros((len(rows), len(series)))
    weights[np.arange(len(rows)), group] = rows[:, 0]
    orders = [len(c.heliocentric_longitude_coeffs), len(c.heliocentric_latitude_coeffs),
              len(c.sun_earth_distance_coeffs)]
    return rows[:, 1].copy(), rows[:, 2].copy(), weights, orders


_TERM_B, _TERM_C, _TERM_WEIGHTS, _ORDERS = _periodic_terms()
_NUTATION_Y = np.array(_pysolar_constants.aberration_sin_terms, dtype=float)       # (63, 5)
_NUTATION_ABCD = np.array(_pysolar_constants.nutation_coefficients, dtype=float)   # (63, 4)
_OBLIQUITY_TERMS = np.flatnonzero(np.any(_NUTATION_ABCD[:, 2:] != 0, axis=1))  # 38 of 63

# Fundamental arguments X0..X4 [deg] (eqs. 15-19): a + b JCE + c JCE^2 + JCE^3 / d.
_NUTATION_X = np.array([
    [297.85036, 445267.111480, -0.0019142, 189474.0],   # mean elongation of the moon
    [357.52772, 35999.050340, -0.0001603, -300000.0],   # mean anomaly of the sun
    [134.96298, 477198.867398, 0.0086972, 56250.0],     # mean anomaly of the moon
    [93.27191, 483202.017538, -0.0036825, 327270.0],    # moon's argument of latitude
    [125.04452, -1934.136261, 0.0020708, 450000.0],     # longitude of the moon's node
])

# Mean obliquity of the ecliptic [arcsec] in U = JME / 10 (eq. 24), lowest power first.
_OBLIQUITY = np.array([84381.448, -4680.93, -1.55, 1999.25, -51.38, -249.67, -39.05, 7.12,
                       27.87, 5.79, 2.45])

# ΔT [s] before 1972 (Espenak & Meeus 2006 [2]): (first year, origin, coefficients low first).
_DELTA_T_POLYNOMIALS = (
    (1900.0, 1900.0, (-2.79, 1.494119, -0.0598939, 0.0061966, -0.000197)),
    (1920.0, 1920.0, (21.20, 0.84493, -0.076100, 0.0020936)),
    (1941.0, 1950.0, (29.07, 0.407, -1 / 233, 1 / 2547)),
    (1961.0, 1975.0, (45.45, 1.067, -1 / 260, -1 / 718)),
)


def _days(when: str) -> float:
    """UT days since J2000.0 of an ISO date (UTC)."""
    return (pd.Timestamp(when + "T00:00Z").value / 1e9 - _J2000_UTC_S) / 86_400.0


_UTC_START_D = _days("1972-01-01")
_DELTA_T_START_D = _days("1900-01-01")


def _leap_second_table():
    """UT days since J2000.0 of the leap seconds and TAI - UTC [s] from each on (from
    1972-01-01 with 10 s), from pysolar's table of the IERS announcements."""
    year0 = _solartime.leap_seconds_base_year
    instants, offsets, tai_utc = [_UTC_START_D], [10], 10
    for k, (june, december) in enumerate(_solartime.leap_seconds_adjustments):
        for step, when in ((june, f"{year0 + k}-07-01"), (december, f"{year0 + k + 1}-01-01")):
            if step:
                tai_utc += step
                instants.append(_days(when))
                offsets.append(tai_utc)
    return np.array(instants), np.array(offsets, dtype=float)


_LEAP_D, _TAI_MINUS_UTC = _leap_second_table()
_TT_MINUS_TAI_S = 32.184

# --------------------------------------------------------------------------- sites


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
        """The site of a dict such as a sidecar's ``site``: ``latitude_deg``,
        ``longitude_deg`` [deg] and optionally ``altitude_m`` [m] (0 when absent) and
        ``name``; numbers may be given as text (``"34.1"``).

        Raises
        ------
        InvalidParameterError
            Naming the key that is missing, not a number, or out of range.
        """
        if not isinstance(d, dict):
            raise InvalidParameterError(f"a site must be an object with latitude_deg, "
                                        f"longitude_deg (and altitude_m); got {d!r}")

        def number(key: str, default=None) -> float:
            if key not in d:
                if default is not None:
                    return default
                raise InvalidParameterError(f"site lacks {key!r} (latitude_deg, longitude_deg "
                                            f"[deg] and altitude_m [m]); got {d!r}")
            value = d[key]
            try:
                x = None if isinstance(value, bool) else float(value)
            except (TypeError, ValueError):
                x = None
            if x is None:
                raise InvalidParameterError(f"{key} must be a number; got {value!r}")
            return x
        return cls(number("latitude_deg"), number("longitude_deg"), number("altitude_m", 0.0),
                   str(d.get("name", "")))


# --------------------------------------------------------------------------- times


def as_utc_index(times) -> pd.DatetimeIndex:
    """Convert timezone-aware times to a UTC :class:`pandas.DatetimeIndex`.

    Raises
    ------
    NaiveDatetimeError
        If any time has no timezone (skysim never guesses UTC).
    InvalidTimeError
        If any time is missing (NaT), cannot be read as a time, or lies outside the years
        1678-2261.
    """
    if isinstance(times, (pd.DatetimeIndex, pd.Series)):
        try:
            idx = pd.DatetimeIndex(times)
        except (ValueError, TypeError, OverflowError) as exc:   # pandas' parse errors
            raise InvalidTimeError(f"times are not times ({exc}); give timezone-aware times, "
                                   "e.g. '2013-05-22T17:10:00+08:00'") from None
        if idx.tz is None:
            raise NaiveDatetimeError(
                f"times are timezone-naive (first: {idx[0] if len(idx) else '<empty>'}); "
                "localise them, e.g. times.tz_localize('Asia/Shanghai')")
        _check_no_nat(idx)
        return idx.tz_convert("UTC")
    if isinstance(times, (_dt.datetime, pd.Timestamp, str, np.datetime64)):
        seq = [times]
    elif isinstance(times, (list, tuple)):
        seq = list(times)
    else:
        seq = list(np.atleast_1d(times))
    out = []
    for k, t in enumerate(seq):  # list input: per-element tz check (arrays should be an index)
        try:
            ts = pd.Timestamp(t)
        except (ValueError, TypeError, OverflowError) as exc:   # pandas' parse errors
            raise InvalidTimeError(f"times[{k}] = {t!r:.60} is not a time ({exc}); give "
                                   "timezone-aware times, e.g. '2013-05-22T17:10:00+08:00'") \
                from None
        if ts is pd.NaT:
            raise InvalidTimeError(f"times[{k}] is missing (NaT); drop or fill missing times "
                                   "first")
        if ts.tzinfo is None:
            raise NaiveDatetimeError(
                f"time {t!r} is timezone-naive; give a UTC offset or zone, e.g. "
                "'2013-05-22T17:10:00+08:00' or datetime(..., tzinfo=timezone.utc)")
        out.append(ts.tz_convert("UTC"))
    try:
        return pd.DatetimeIndex(out)
    except (ValueError, OverflowError) as exc:   # e.g. a year nanoseconds cannot hold
        raise InvalidTimeError(f"times outside the supported years 1678-2261 ({exc})") \
            from None


def _check_no_nat(idx: pd.DatetimeIndex) -> None:
    missing = np.flatnonzero(idx.isna())
    if missing.size:
        more = f" (and {missing.size - 1} more)" if missing.size > 1 else ""
        raise InvalidTimeError(f"times[{missing[0]}] is missing (NaT){more}; drop or fill "
                               "missing times first, e.g. times.dropna()")


def delta_t_seconds(times) -> np.ndarray:
    """ΔT = TT - UT1 [s] for timezone-aware times, the model :func:`sun_position` uses.

    From 1972 on: ``32.184 s + (TAI - UTC)``, TAI - UTC from the table of leap seconds (UT1 is
    taken equal to UTC, which the IERS keeps within 0.9 s of it; after the table's last leap
    second the value stays constant, and each leap second it lacks would move the sun's
    longitude by 1.1e-5 deg). From 1900 to 1972: the polynomials of Espenak & Meeus [2]_.

    Raises
    ------
    InvalidTimeError
        For a time before 1900 (give ``delta_t_s`` to :func:`sun_position` instead).
    """
    d_ut = _utc_days(as_utc_index(times))
    return np.broadcast_to(_delta_t_s(d_ut), d_ut.shape).copy()


def _utc_days(idx: pd.DatetimeIndex) -> np.ndarray:
    """UT days since J2000.0 (2000-01-01T12:00 UTC) of a UTC index, in its own resolution
    (no conversion pass; float64 keeps 1e-7 s over centuries)."""
    per_s = _UNITS_PER_S[idx.unit]
    return (idx.asi8 - _J2000_UTC_S * per_s) * (1.0 / (86_400 * per_s))


def _delta_t_s(d_ut: np.ndarray):
    """ΔT [s] at UT days ``d_ut``: a float when one value holds for all (the usual case)."""
    lo, hi = float(d_ut.min()), float(d_ut.max())
    if lo < _DELTA_T_START_D:
        first = pd.Timestamp(_J2000_UTC_S, unit="s", tz="UTC") + pd.Timedelta(days=lo)
        raise InvalidTimeError(
            f"time {first.isoformat()} is before 1900, where skysim has no ΔT model; give "
            "delta_t_s (TT - UT1 [s], e.g. from Espenak & Meeus 2006) explicitly")
    k_lo, k_hi = np.searchsorted(_LEAP_D, [lo, hi], side="right") - 1
    if lo >= _UTC_START_D and k_lo == k_hi:
        return _TT_MINUS_TAI_S + float(_TAI_MINUS_UTC[k_lo])
    k = np.searchsorted(_LEAP_D, d_ut, side="right") - 1
    out = _TT_MINUS_TAI_S + _TAI_MINUS_UTC[np.maximum(k, 0)]
    pre = d_ut < _UTC_START_D
    if pre.any():
        year = 2000.0 + (d_ut[pre] + 0.5) / 365.2425
        dt = np.zeros_like(year)
        for start, origin, coeffs in _DELTA_T_POLYNOMIALS:  # four segments, not samples
            sel = year >= start
            dt[sel] = np.polynomial.polynomial.polyval(year[sel] - origin, coeffs)
        out[pre] = dt
    return out


# --------------------------------------------------------------------------- the SPA


def _geocentric(d_tt: np.ndarray) -> np.ndarray:
    """Time-only part of the SPA at terrestrial times ``d_tt`` [days since J2000.0].

    Returns (n, 3): the apparent geocentric sun ``R (cos d cos a', cos d sin a', sin d)`` [AU]
    (declination d, distance R) with ``a' = a - dpsi cos eps - (0.000387933 JC^2 -
    JC^3/38710000)``: the right ascension minus every slow term of the apparent sidereal time
    (eqs. 28-29), so that the local hour angle (eq. 32) is ``280.46061837 + 360.98564736629
    d_UT + longitude - a'``. (The slow terms are evaluated at TT instead of UT: 3e-12 deg.)
    """
    out = np.empty((d_tt.size, 3))
    for lo in range(0, d_tt.size, _BLOCK):  # blocks bound the (n, 195) temporaries
        out[lo:lo + _BLOCK] = _geocentric_block(d_tt[lo:lo + _BLOCK])
    return out


def _geocentric_block(d_tt: np.ndarray) -> np.ndarray:
    jce = d_tt / 36525.0                                              # eq. 7
    jme = jce / 10.0                                                  # eq. 8
    sums = np.cos(_TERM_B + jme[:, None] * _TERM_C) @ _TERM_WEIGHTS   # eqs. 9-10
    powers = jme[:, None] ** np.arange(max(_ORDERS))
    nl, nb, nr = _ORDERS
    L = np.einsum("nk,nk->n", sums[:, :nl], powers[:, :nl]) / 1e8     # eq. 11 [rad]
    B = np.einsum("nk,nk->n", sums[:, nl:nl + nb], powers[:, :nb]) / 1e8
    R = np.einsum("nk,nk->n", sums[:, nl + nb:], powers[:, :nr]) / 1e8  # [AU]
    theta = np.degrees(L) + 180.0                                     # eq. 13
    beta = -np.degrees(B)                                             # eq. 14
    # nutation (eqs. 15-23)
    a, b, c, d = _NUTATION_X.T
    x = a + jce[:, None] * (b + jce[:, None] * c) + jce[:, None] ** 3 / d
    arg = np.radians(x @ _NUTATION_Y.T)
    A, Bn = _NUTATION_ABCD[:, 0], _NUTATION_ABCD[:, 1]
    C, D = _NUTATION_ABCD[_OBLIQUITY_TERMS, 2], _NUTATION_ABCD[_OBLIQUITY_TERMS, 3]
    s = np.sin(arg)
    co = np.cos(arg[:, _OBLIQUITY_TERMS])  # the other terms have no obliquity part
    dpsi = (s @ A + jce * (s @ Bn)) / 36e6                            # eqs. 20, 22 [deg]
    deps = (co @ C + jce * (co @ D)) / 36e6                           # eqs. 21, 23 [deg]
    eps = np.polynomial.polynomial.polyval(jme / 10.0, _OBLIQUITY) / 3600.0 + deps  # 24-25
    lam = np.radians(theta + dpsi - 20.4898 / (3600.0 * R))           # eqs. 26-27
    eps_r, beta_r = np.radians(eps), np.radians(beta)
    cb, sb, ce, se = np.cos(beta_r), np.sin(beta_r), np.cos(eps_r), np.sin(eps_r)
    # eqs. 30-31 as the rotation of the ecliptic vector by eps: (x, y, z) = R (cos d cos a,
    # cos d sin a, sin d); then the rotation by the slow sidereal terms (eqs. 28-29)
    x_eq = R * cb * np.cos(lam)
    y_eq = R * (cb * np.sin(lam) * ce - sb * se)
    slow = np.radians(dpsi * ce + 0.000387933 * jce**2 - jce**3 / 38710000.0)
    cs, ss = np.cos(slow), np.sin(slow)
    return np.stack([x_eq * cs + y_eq * ss, y_eq * cs - x_eq * ss,
                     R * (cb * np.sin(lam) * se + sb * ce)], axis=-1)


def _knot_plan(d_tt: np.ndarray, force: bool = False):
    """Knots of the time-only part where they pay, or None (evaluate directly).

    Knots lie every :data:`KNOT_SPACING_DAYS` of TT; a time in the interval starting at knot
    ``k`` uses knots ``k-1 .. k+2``. They pay when they are fewer than the times (a knot costs
    what one direct time costs, the interpolation about 1/30 of it). Of the contiguous run of
    knots over the span of the times and the union of the knots the times need (fewer for
    clustered times, e.g. a few days in each of several years), the shorter is used.

    Returns ``(knot_days, first, interval, x)``: knot times [days], the first knot of each
    interval, the interval of each time and its position in it, in [0, 1).
    """
    u = d_tt * (1.0 / KNOT_SPACING_DAYS)
    kf = np.floor(u)
    x = u - kf
    k0, k1 = float(kf.min()), float(kf.max())
    run = int(k1 - k0) + 4
    if 8 * run > d_tt.size:  # not clearly dense: are the needed knots fewer?
        distinct, interval = np.unique(kf, return_inverse=True)
        knots = np.unique(distinct[:, None] + np.arange(-1.0, 3.0))
        if min(run, knots.size) >= d_tt.size and not force:  # sparse: direct is cheaper
            return None
        if knots.size < run:
            return (knots * KNOT_SPACING_DAYS, np.searchsorted(knots, distinct - 1),
                    interval, x)
    return (np.arange(k0 - 1, k1 + 3) * KNOT_SPACING_DAYS, np.arange(run - 3),
            (kf - k0).astype(np.intp), x)


def _interpolate(values: np.ndarray, first: np.ndarray, interval: np.ndarray,
                 x: np.ndarray) -> list[np.ndarray]:
    """4-point Lagrange interpolation (nodes -1, 0, 1, 2) of knot ``values`` (m, q): the
    cubic of each interval in monomial form, then Horner's rule at each time; one 1-D array
    (n,) per column (contiguous passes are what makes this cheap)."""
    out = []
    for v in values.T:  # the q quantities
        v0, v1, v2, v3 = (v[first + j] for j in range(4))
        c0, c1, c2, c3 = (np.take(c, interval) for c in (
            v1, -v0 / 3 - v1 / 2 + v2 - v3 / 6, v0 / 2 - v1 + v2 / 2,
            (v3 - v0) / 6 + (v1 - v2) / 2))
        c3 *= x
        c3 += c2
        c3 *= x
        c3 += c1
        c3 *= x
        c3 += c0
        out.append(c3)
    return out


def _geocentric_at(d_tt: np.ndarray, method: str) -> list[np.ndarray]:
    """The time-only part at every time, directly or through knots (see
    :func:`_knot_plan`): X, Y, Z, each (n,)."""
    plan = None if method == "spa" else _knot_plan(d_tt, force=method == "interpolated")
    if plan is None:
        return list(_geocentric(d_tt).T)
    knot_days, first, interval, x = plan
    return _interpolate(_geocentric(knot_days), first, interval, x)


def _as_site_arrays(n_times: int, latitude_deg, longitude_deg, altitude_m):
    """Validated site arrays broadcast against the times; the common length."""
    named = {"latitude_deg": latitude_deg, "longitude_deg": longitude_deg,
             "altitude_m": altitude_m}
    arrays = {}
    for name, value in named.items():
        arr = as_float_array(name, value)
        if arr.ndim > 1:
            raise BroadcastError(f"{name} has shape {arr.shape}; give a scalar or a 1-D array "
                                 f"(one value per time, {n_times} times)")
        arrays[name] = arr
    n = n_times
    for name, arr in arrays.items():
        if arr.ndim == 1 and arr.size != 1:
            if n not in (1, arr.size):
                raise BroadcastError(
                    f"{name} has {arr.size} values but there are {n} times (or sites); give "
                    "a scalar or one value per time")
            n = arr.size
    check_latitude(arrays["latitude_deg"])
    check_longitude(arrays["longitude_deg"])
    check_in_range("altitude_m", arrays["altitude_m"], -500.0, 9000.0)
    return arrays["latitude_deg"], arrays["longitude_deg"], arrays["altitude_m"], n


def _topocentric_enu(d_ut, lat, lon, alt, method, delta_t_s):
    """Topocentric sun as ENU components (E, N, U), each (n,), unnormalised [AU].

    The hour-angle frame (eqs. 28-29, 32 through ``a'`` of :func:`_geocentric`):
    ``A = R cos d cos H``, ``B = R cos d sin H`` (H westward), ``C = R sin d``; the parallax
    (eqs. 33-40) subtracts the observer ``(x, 0, y)`` [Earth radii] times ``R sin xi``, which
    is the constant 8.794 arcsec (to 1e-14 rad); eqs. 41 and 45-46 turn ``(A, B, C)`` into
    east, north, up.
    """
    dt = _delta_t_s(d_ut) if delta_t_s is None else delta_t_s
    X, Y, Z = _geocentric_at(d_ut + dt / 86400.0, method)
    # eq. 28 with 360.98564736629 d = 360 frac(d) + 0.98564736629 d (mod 360)
    theta = np.radians(280.46061837 + 360.0 * (d_ut - np.floor(d_ut))
                       + 0.98564736629 * d_ut + lon)
    st, ct = np.sin(theta), np.cos(theta)
    phi = np.radians(lat)
    u = np.arctan(0.99664719 * np.tan(phi))                                  # eq. 34
    x_obs = (np.cos(u) + alt / 6378140.0 * np.cos(phi)) * _PARALLAX_RAD      # eq. 35
    y_obs = (0.99664719 * np.sin(u) + alt / 6378140.0 * np.sin(phi)) * _PARALLAX_RAD
    A = X * ct + Y * st - x_obs
    B = X * st - Y * ct
    C = Z - y_obs
    sp, cp = np.sin(phi), np.cos(phi)
    return -B, C * cp - A * sp, A * cp + C * sp


def _refraction_deg(e0_deg, pressure_hPa, temperature_C):
    """SPA eq. 42: refraction [deg] at geometric elevation ``e0_deg``, zero below the
    apparent sunset elevation (-0.26667 - 0.5667 deg)."""
    e0 = np.asarray(e0_deg, float)
    lift = ((pressure_hPa / 1010.0) * (283.0 / (273.0 + temperature_C)) * 1.02
            / (60.0 * np.tan(np.radians(e0 + 10.3 / (e0 + 5.11)))))
    return np.where(e0 >= -(0.26667 + 0.5667), lift, 0.0)


def _pysolar_angles(when_utc: pd.DatetimeIndex, lat, lon, alt):
    """Per-time pysolar evaluation (the library has no array API): the reference of the
    tests. Geometric elevation and azimuth [deg]."""
    el = np.empty(len(when_utc))
    az = np.empty(len(when_utc))
    lat, lon, alt = (np.broadcast_to(v, el.shape) for v in (lat, lon, alt))
    for k, t in enumerate(when_utc.to_pydatetime()):
        t = t - _dt.timedelta(seconds=_ut1_shift_s(t))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # see _ut1_shift_s
            dec, ha = _pysolar_topocentric(float(lat[k]), float(lon[k]), t, float(alt[k]))
        el[k] = _solar.get_topocentric_elevation_angle(lat[k], dec, ha)
        az[k] = _solar.get_topocentric_azimuth_angle(ha, lat[k], dec)
    return el, az


def _pysolar_topocentric(lat: float, lon: float, when: _dt.datetime, alt: float):
    """Topocentric declination and hour angle [deg] from pysolar's steps, composed as its
    ``get_topocentric_position`` does, with three equations as SPA publishes them where
    pysolar 0.13 departs from them: eq. 29 (pysolar takes the cosine of the obliquity in
    degrees as if in radians: about 0.005 deg of hour angle), eq. 33 (it multiplies the
    parallax by R instead of dividing: 1e-4 deg) and eq. 39 (it uses the axial term y where
    the radial term x belongs: up to 0.0015 deg of declination)."""
    jd = _solartime.get_julian_solar_day(when)
    jce = _solartime.get_julian_ephemeris_century(_solartime.get_julian_ephemeris_day(when))
    jme = _solartime.get_julian_ephemeris_millennium(jce)
    beta = _solar.get_geocentric_latitude(jme)
    R = _solar.get_sun_earth_distance(jme)
    nutation = _solar.get_nutation(jce)
    eps = _solar.get_true_ecliptic_obliquity(jme, nutation)
    nu = (_solar.get_mean_sidereal_time(jd)
          + nutation["longitude"] * np.cos(np.radians(eps)))        # eq. 29
    lam = _solar.get_apparent_sun_longitude(_solar.get_geocentric_longitude(jme), nutation,
                                            _solar.get_aberration_correction(R))
    alpha = _solar.get_geocentric_sun_right_ascension(lam, eps, beta)
    delta = _solar.get_geocentric_sun_declination(lam, eps, beta)
    H = _solar.get_local_hour_angle(nu, lon, alpha)
    xi = 8.794 / (3600.0 * R)                                        # eq. 33
    x = _solar.get_projected_radial_distance(alt, lat)
    y = _solar.get_projected_axial_distance(alt, lat)
    d_alpha = _solar.get_parallax_sun_right_ascension(x, xi, H, delta)
    xi_r, h, d, da = (np.radians(v) for v in (xi, H, delta, d_alpha))
    dec = np.degrees(np.arctan2((np.sin(d) - y * np.sin(xi_r)) * np.cos(da),
                                np.cos(d) - x * np.sin(xi_r) * np.cos(h)))  # eq. 39
    return dec, _solar.get_topocentric_local_hour_angle(H, d_alpha)


def _ut1_shift_s(when: _dt.datetime) -> float:
    """Seconds pysolar's UT1 runs ahead of UTC: ``(TT - UTC) - dT_pysolar``.

    pysolar derives UT1 as ``UTC + (leap seconds + 32.184 s) - dT`` with a tabulated dT that
    stops in 2014 while TT - UTC has been 69.184 s since 2017, so later its Earth-rotation
    angle runs up to 2 s (0.008 deg) ahead. Evaluating pysolar at ``UTC - shift`` gives
    UT1 = UTC as here; its ΔT is then its own table's value, ``pysolar_delta_t_s``.
    """
    with warnings.catch_warnings():
        # pysolar warns when its leap-second table ends
        warnings.simplefilter("ignore", UserWarning)
        return _solartime.get_leap_seconds(when) + 32.184 - _solartime.get_delta_t(when)


def pysolar_delta_t_s(times) -> np.ndarray:
    """ΔT [s] of a per-time pysolar evaluation (``method="pysolar"``) at each time: pass it
    as ``delta_t_s`` to compare the vectorised SPA with pysolar under one ΔT."""
    out = []
    for t in as_utc_index(times).to_pydatetime():  # pysolar's table lookup is per time
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            out.append(_solartime.get_delta_t(t - _dt.timedelta(seconds=_ut1_shift_s(t))))
    return np.array(out)


def _sun_angles(times, latitude_deg, longitude_deg, altitude_m, refraction, method,
                pressure_hPa, temperature_C, delta_t_s, want_vector: bool):
    """Shared core: UTC index (broadcast against the sites), elevation and azimuth [deg], and
    the ENU unit vectors when ``want_vector`` (else None)."""
    if method not in METHODS:
        raise InvalidParameterError(
            f"unknown method {method!r}; valid: {', '.join(map(repr, METHODS))}")
    idx = as_utc_index(times)
    lat, lon, alt, n = _as_site_arrays(len(idx), latitude_deg, longitude_deg, altitude_m)
    if len(idx) == 1 and n > 1:
        idx = idx.repeat(n)
    if len(idx) == 0:
        return idx, np.empty(0), np.empty(0), np.empty((0, 3))
    vec = None
    if method == "pysolar":
        el, az = _pysolar_angles(idx, lat, lon, alt)
    else:
        if delta_t_s is not None:
            delta_t_s = check_finite("delta_t_s", delta_t_s)
            if delta_t_s.ndim > 1 or delta_t_s.size not in (1, len(idx)):
                raise BroadcastError(f"delta_t_s has shape {delta_t_s.shape}; give a scalar or "
                                     f"one value per time ({len(idx)} times)")
            delta_t_s = np.broadcast_to(delta_t_s, (len(idx),))
        E, N, U = _topocentric_enu(_utc_days(idx), lat, lon, alt, method, delta_t_s)
        el = np.degrees(np.arctan2(U, np.hypot(E, N)))
        az = np.degrees(np.arctan2(E, N))
        az[az < 0] += 360.0  # [0, 360) (cheaper than np.mod) ...
        az[az >= 360.0] = 0.0  # ... including -1e-15 + 360, which rounds to 360
        if want_vector and not refraction:
            vec = np.stack([E, N, U], axis=-1)
            vec /= np.linalg.norm(vec, axis=1, keepdims=True)
    if refraction:
        el = el + _refraction_deg(el, pressure_hPa, temperature_C)
    if want_vector and vec is None:
        vec = direction_vector(el, az)
    return idx, el, az, vec


def sun_vector(times, site: Site, refraction: bool = False, method: str = "auto", *,
               pressure_hPa: float = 1013.25, temperature_C: float = 10.0,
               delta_t_s=None):
    """Sun ENU unit vectors, shape ``(n, 3)``, and the UTC index of the times.

    Parameters
    ----------
    times : array-like of timezone-aware datetimes, DatetimeIndex or Series
    site : Site
    refraction : bool
        Apply atmospheric refraction (default False: geometric position).
    method : {'auto', 'spa', 'interpolated', 'pysolar'}
        'auto' evaluates the time-only part of the SPA at knots when the times are more than
        the knots their span needs, else directly; 'spa' evaluates everything at every time;
        'interpolated' always uses knots; 'pysolar' calls pysolar once per time (reference,
        slow). See the module docstring for the accuracy of each.
    pressure_hPa, temperature_C : float
        Air pressure [hPa] and temperature [°C] of the refraction (used with
        ``refraction=True``).
    delta_t_s : float or array, optional
        TT - UT1 [s]; default :func:`delta_t_seconds`.
    """
    if not all(hasattr(site, k) for k in ("latitude_deg", "longitude_deg", "altitude_m")):
        raise InvalidParameterError(f"site must be a skysim.Site (latitude_deg, longitude_deg, "
                                    f"altitude_m); got {site!r:.80}")
    idx, _, _, vec = _sun_angles(times, site.latitude_deg, site.longitude_deg, site.altitude_m,
                                 refraction, method, pressure_hPa, temperature_C, delta_t_s,
                                 want_vector=True)
    return vec, idx


class SunTrack:
    """The sun's direction over a span of times, from ephemeris knots, for fits that ask for
    it at many (shifted) times.

    Knots every ``step_s`` from :func:`sun_vector`; between knots the ENU vector is
    interpolated linearly and renormalised. The error is the sagitta of the arc the sun
    turns between knots: at most 0.25 deg/min, so 60-s knots err by ``(0.25 deg in
    rad)^2 / 8`` rad, < 1e-4 deg (tested against :func:`sun_vector` at off-knot times).

    Parameters
    ----------
    site : Site
    t_min_s, t_max_s : float
        Span of times [s since 1970-01-01 UTC].
    margin_s : float
        Span added before and after [s] (fits shift times by up to this: 15 h covers a
        timezone error).
    step_s : float
        Knot spacing [s].
    """

    def __init__(self, site: Site, t_min_s: float, t_max_s: float,
                 margin_s: float = 15 * 3600.0, step_s: float = 60.0):
        t = np.arange(t_min_s - margin_s, t_max_s + margin_s + step_s, step_s)
        times = pd.to_datetime(np.round(t * 1e9).astype(np.int64), unit="ns", utc=True)
        self.t_s = t
        self.vectors = self._vectors(times, site)

    @staticmethod
    def _vectors(times, site) -> np.ndarray:
        """ENU unit vectors of the source at the knot ``times`` (the Sun's here)."""
        return sun_vector(times, site)[0]

    def __call__(self, t_s) -> np.ndarray:
        """Unit sun vectors in ENU, shape ``(n, 3)``, at times ``t_s`` [s since epoch, UTC]."""
        t_s = np.asarray(t_s, float)
        v = np.stack([np.interp(t_s, self.t_s, self.vectors[:, c]) for c in range(3)], axis=-1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    def elevation_azimuth(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """Sun elevation and azimuth [deg] at times ``t_s`` [s since epoch, UTC]."""
        return elevation_azimuth(self(t_s))


def sun_position(times, latitude_deg, longitude_deg, altitude_m=0.0,
                 refraction: bool = False, method: str = "auto", *,
                 pressure_hPa: float = 1013.25, temperature_C: float = 10.0,
                 delta_t_s=None) -> pd.DataFrame:
    """Topocentric sun position for each time, each with its own site if wanted.

    Parameters
    ----------
    times : timezone-aware datetimes (scalar, list, DatetimeIndex or Series), n of them
    latitude_deg, longitude_deg : float or array (n,)
        Site [deg], north and east positive; one per time or one for all. A single time with
        arrays of sites gives the sun at that instant from every site.
    altitude_m : float or array (n,)
        Site height above sea level [m].
    refraction : bool
        Default False: geometric elevation (what scattering geometry needs).
    method : {'auto', 'spa', 'interpolated', 'pysolar'}
        See :func:`sun_vector`.
    pressure_hPa, temperature_C : float
        Refraction conditions [hPa], [°C] (with ``refraction=True``).
    delta_t_s : float or array (n,), optional
        TT - UT1 [s]; default :func:`delta_t_seconds` (required before 1900).

    Returns
    -------
    pandas.DataFrame
        Columns ``elevation_deg``, ``azimuth_deg`` (clockwise from north, [0, 360)),
        ``zenith_deg`` [deg]; indexed by the times in their original timezone.

    Raises
    ------
    NaiveDatetimeError
        For a time without timezone.
    InvalidTimeError
        For a missing time (NaT), or a time before 1900 without ``delta_t_s``.
    InvalidParameterError
        For a latitude outside [-90, 90] (or NaN), a longitude outside [-180, 360], an
        altitude outside [-500, 9000] m.
    BroadcastError
        When the sites' lengths do not match the times' (the message names the argument).
    """
    idx, el, az, _ = _sun_angles(times, latitude_deg, longitude_deg, altitude_m, refraction,
                                 method, pressure_hPa, temperature_C, delta_t_s,
                                 want_vector=False)
    index = _original_index(times, idx)
    if len(index) != len(idx):
        index = index.repeat(len(idx))
    return pd.DataFrame({"elevation_deg": el, "azimuth_deg": az, "zenith_deg": 90.0 - el},
                        index=index)


def _original_index(times, idx_utc: pd.DatetimeIndex) -> pd.DatetimeIndex:
    if isinstance(times, (pd.DatetimeIndex, pd.Series)):
        return pd.DatetimeIndex(times)
    try:
        return pd.DatetimeIndex([pd.Timestamp(t) for t in np.atleast_1d(times)])
    except (ValueError, TypeError):  # mixed offsets: keep UTC
        return idx_utc


def apparent_solar_time(times, longitude_deg, latitude_deg=0.0) -> pd.Series:
    """Local apparent (true) solar time for each time, as hours in [0, 24).

    From the sun's topocentric hour angle ``H'`` of the SPA: LAST = 12 h + H'/15 (Meeus,
    *Astronomical Algorithms*, ch. 28). Latitude only enters through parallax (< 1 s).
    Longitude and latitude broadcast against the times like :func:`sun_position`'s.

    Returns
    -------
    pandas.Series of float hours indexed like ``times``.
    """
    idx = as_utc_index(times)
    lat, lon, _, n = _as_site_arrays(len(idx), latitude_deg, longitude_deg, 0.0)
    if len(idx) == 0:
        hours = np.empty(0)
    else:
        if len(idx) == 1 and n > 1:
            idx = idx.repeat(n)
        E, N, U = _topocentric_enu(_utc_days(idx), lat, lon, 0.0, "auto", None)
        phi = np.radians(lat)  # back from ENU to the hour-angle frame: H' = atan2(B, A)
        A = U * np.cos(phi) - N * np.sin(phi)
        hours = np.mod(12.0 + np.degrees(np.arctan2(-E, A)) / 15.0, 24.0)
    index = _original_index(times, idx)
    if len(index) != len(idx):
        index = index.repeat(len(idx))
    return pd.Series(hours, index=index, name="apparent_solar_time_h")


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
