"""Sun position: pysolar knots + interpolation, cross-checked against pvlib's NREL SPA."""

import datetime as dt

import numpy as np
import pandas as pd
import pytest

from skysim.exceptions import InvalidParameterError, NaiveDatetimeError
from skysim.sun import (Site, apparent_solar_time, clock_time_from_apparent_solar_time,
                        sun_position)

pvlib = pytest.importorskip("pvlib", reason="pvlib is the independent SPA reference (test extra)")

SITES = [(34.1447, 108.5467, 400.0),   # Xi'an (Yang et al. 2014)
         (-33.87, 151.21, 0.0),        # Sydney: southern hemisphere, sun passes north
         (69.65, 18.96, 0.0)]          # Tromso: polar day and night


@pytest.mark.parametrize("lat,lon,alt", SITES)
def test_against_pvlib_spa_over_a_year(lat, lon, alt):
    """Tolerances of the issue: <= 0.01 deg elevation, <= 0.05 deg azimuth vs NREL SPA.

    Both implement Reda & Andreas (2004); pvlib's 'elevation' is the geometric topocentric
    elevation (no refraction), as is ours by default. Azimuth is compared where the sun is
    below 85 deg elevation (near the zenith azimuth is ill-conditioned: a 0.001 deg position
    difference can be a large azimuth difference).
    """
    rng = np.random.default_rng(int(abs(lat) * 100))
    seconds = np.sort(rng.uniform(0, 365 * 86400, 1500))  # 1500 random times over 2021
    times = pd.DatetimeIndex(pd.Timestamp("2021-01-01T00:00Z") + pd.to_timedelta(seconds, "s"))
    ref = pvlib.solarposition.get_solarposition(times, lat, lon, altitude=alt,
                                                method="nrel_numpy")
    ours = sun_position(times, lat, lon, alt)
    d_el = np.abs(ours.elevation_deg.to_numpy() - ref.elevation.to_numpy())
    d_az = np.abs((ours.azimuth_deg.to_numpy() - ref.azimuth.to_numpy() + 180) % 360 - 180)
    assert d_el.max() <= 0.01
    assert d_az[ref.elevation.to_numpy() < 85].max() <= 0.05


def test_interpolation_matches_direct_pysolar():
    """Knot interpolation error <= 0.001 deg (angle between unit vectors) vs direct calls,
    including a tropical site where the sun passes within 0.5 deg of the zenith."""
    rng = np.random.default_rng(3)
    base = pd.Timestamp("2024-03-20T00:00:00Z")  # dense: 2000 times in 2 days use knots
    times = pd.DatetimeIndex(base + pd.to_timedelta(np.sort(rng.uniform(0, 2 * 86400, 2000)),
                                                    unit="s"))
    for lat, lon in [(34.1447, 108.5467), (0.5, 0.0)]:
        fast = sun_position(times, lat, lon)
        slow = sun_position(times, lat, lon, method="pysolar")
        from skysim.geometry import angle_between_deg, direction_vector
        err = angle_between_deg(direction_vector(fast.elevation_deg, fast.azimuth_deg),
                                direction_vector(slow.elevation_deg, slow.azimuth_deg))
        assert err.max() <= 1e-3


def test_index_keeps_timezone_and_accepts_mixed_inputs():
    t = pd.date_range("2013-05-22T17:10:00+08:00", periods=3, freq="10min")
    pos = sun_position(t, 34.1, 108.5)
    assert pos.index.equals(t)
    single = sun_position(dt.datetime(2013, 5, 22, 9, 10, tzinfo=dt.timezone.utc), 34.1, 108.5)
    assert single.elevation_deg.iloc[0] == pytest.approx(pos.elevation_deg.iloc[0], abs=1e-9)
    np.testing.assert_allclose(pos.zenith_deg, 90 - pos.elevation_deg)


def test_refraction_raises_low_sun():
    """Refraction lifts the sun by ~0.5 deg at the horizon and ~0.01 deg at 80 deg (Bennett)."""
    t = pd.date_range("2013-05-22T00:00Z", periods=24, freq="1h")
    geo = sun_position(t, 34.1, 108.5)
    app = sun_position(t, 34.1, 108.5, refraction=True)
    lift = (app.elevation_deg - geo.elevation_deg)[geo.elevation_deg > 5]
    assert (lift > 0).all() and lift.max() < 0.2


@pytest.mark.parametrize("bad", [dt.datetime(2013, 5, 22, 17, 10), "2013-05-22T17:10",
                                 pd.date_range("2013-05-22", periods=2, freq="1h")])
def test_naive_time_raises(bad):
    with pytest.raises(NaiveDatetimeError, match="naive"):
        sun_position(bad, 34.1, 108.5)


@pytest.mark.parametrize("lat", [90.5, -91, np.nan])
def test_bad_latitude_raises(lat):
    with pytest.raises(InvalidParameterError, match="latitude"):
        sun_position(["2013-05-22T17:10+08:00"], lat, 108.5)


def test_site_rejects_bad_values():
    with pytest.raises(InvalidParameterError, match="longitude"):
        Site(10.0, 400.0)


def test_apparent_solar_time_against_spa_equation_of_time():
    """LAST = UTC + lon/15 + EoT; pvlib's SPA gives EoT [min]. Agreement within 0.05 min
    (3 s; pysolar and SPA differ by ~1 s of rotation, and EoT itself is exact in both)."""
    t = pd.date_range("2018-01-01T04:00Z", periods=12, freq="30D")
    lon = 121.53
    ours = apparent_solar_time(t, lon, 38.88).to_numpy()
    eot = pvlib.solarposition.get_solarposition(t, 38.88, lon, method="nrel_numpy")[
        "equation_of_time"].to_numpy()
    utc_h = t.hour + t.minute / 60
    expected = (utc_h + lon / 15 + eot / 60) % 24
    assert np.max(np.abs(ours - expected)) * 60 <= 0.05


def test_clock_time_from_apparent_solar_time_round_trip():
    """Jin et al. (2020): at Dalian on 2018-05-25 apparent solar time runs ~9.2 min ahead of
    Beijing time (lon 121.53 E is 1.53 deg east of 120 E: +6.1 min; EoT +3.1 min)."""
    clock = clock_time_from_apparent_solar_time("2018-05-25", 17 + 20 / 60, 121.53,
                                                "Asia/Shanghai", 38.88)
    back = apparent_solar_time([clock], 121.53, 38.88).iloc[0]
    assert back == pytest.approx(17 + 20 / 60, abs=1e-6)
    lead_min = (17 + 20 / 60 - (clock.hour + clock.minute / 60 + clock.second / 3600)) * 60
    assert lead_min == pytest.approx(9.2, abs=0.2)
