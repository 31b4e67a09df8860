"""The Moon as a source: position, phase and libration against PyEphem (an independent
lunar theory: libastro), ROLO irradiance against the published lunar phase law."""

import math
import warnings

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("astropy", reason="the Moon's position needs astropy (extra 'moon')")
ephem = pytest.importorskip("ephem", reason="PyEphem is the independent lunar reference")

from skysim.bands import get_band, solar_irradiance  # noqa: E402
from skysim.exceptions import InvalidParameterError, NaiveDatetimeError  # noqa: E402
from skysim.geometry import angle_between_deg, direction_vector  # noqa: E402
from skysim.moon import (STANDARD_MOON_DISTANCE_KM, lunar_disk_reflectance,  # noqa: E402
                         lunar_irradiance, moon_position)


@pytest.fixture(scope="module")
def random_moons():
    """100 random times 1990-2045 at random sites: skysim's and PyEphem's Moon."""
    rng = np.random.default_rng(20240601)
    n = 100
    t = pd.to_datetime(rng.uniform(pd.Timestamp("1990-01-01").value,
                                   pd.Timestamp("2045-01-01").value, n).astype("int64"),
                       utc=True).floor("s")
    lat, lon, alt = rng.uniform(-70, 70, n), rng.uniform(-180, 180, n), rng.uniform(0, 4000, n)
    with warnings.catch_warnings():  # astropy: times past its bundled Earth-orientation data
        warnings.simplefilter("ignore")
        ours = moon_position(t, lat, lon, alt)
    ref = []
    for k in range(n):  # PyEphem has no array API
        o = ephem.Observer()
        o.lat, o.lon, o.elevation, o.pressure = str(lat[k]), str(lon[k]), alt[k], 0.0
        o.date = t[k].tz_localize(None).to_pydatetime()
        m = ephem.Moon(o)
        ref.append((math.degrees(m.alt), math.degrees(m.az), m.moon_phase,
                    math.degrees(m.libration_lat), math.degrees(m.libration_long),
                    math.degrees(m.colong)))
    return ours, np.array(ref)


def test_position_agrees_with_pyephem(random_moons):
    # Tolerance 30 arcsec: astropy's built-in ephemeris (ERFA moon98) is good to ~10 arcsec
    # and PyEphem's libastro lunar theory to a few arcsec; both far inside the few
    # arcminutes a sky map needs (measured max 19 arcsec).
    ours, ref = random_moons
    sep = angle_between_deg(direction_vector(ours.elevation_deg, ours.azimuth_deg),
                            direction_vector(ref[:, 0], ref[:, 1]))
    assert np.max(sep) * 3600 < 30.0


def test_illuminated_fraction_agrees_with_pyephem(random_moons):
    # PyEphem's phase is geocentric, ours topocentric: the diurnal parallax (<= 1.025 deg
    # of phase angle, times cos(elevation)) changes k by <= 0.5 sin(i) * that; 0.002 more
    # (0.25 deg of phase angle) for the two theories.
    ours, ref = random_moons
    i = np.radians(ours.phase_angle_deg)
    bound = 0.5 * np.sin(i) * np.radians(1.025) * np.cos(np.radians(ours.elevation_deg))
    assert np.all(np.abs(ours.illuminated_fraction - ref[:, 2]) <= bound + 0.002)
    np.testing.assert_allclose(ours.illuminated_fraction,
                               0.5 * (1 + np.cos(i)), atol=1e-12)


def test_libration_agrees_with_pyephem(random_moons):
    # Optical libration of Meeus ch. 53; the neglected physical libration is <= 0.04 deg
    # (Meeus), and 0.1 deg moves ROLO's ln A by < 2e-4 (c1, c2 of Kieffer & Stone).
    ours, ref = random_moons
    assert np.max(np.abs(ours.observer_selenographic_latitude_deg - ref[:, 3])) < 0.1
    dlon = (ours.observer_selenographic_longitude_deg - ref[:, 4] + 180) % 360 - 180
    assert np.max(np.abs(dlon)) < 0.1


def test_sun_selenographic_longitude_agrees_with_pyephem(random_moons):
    # colongitude = 90 deg - the Sun's selenographic longitude. 0.5 deg (measured 0.33)
    # moves ROLO's ln A by b1 * 0.0087 rad < 5e-4, i.e. 0.05 % of the irradiance.
    ours, ref = random_moons
    colong = np.mod(90.0 - ours.sun_selenographic_longitude_deg, 360.0)
    assert np.max(np.abs((colong - ref[:, 5] + 180) % 360 - 180)) < 0.5


def test_conventions_naive_time_and_bad_site():
    with pytest.raises(NaiveDatetimeError):
        moon_position("2021-01-27T05:00:00", -24.6, -70.4)
    with pytest.raises(InvalidParameterError, match="latitude"):
        moon_position("2021-01-27T05:00:00Z", 124.6, -70.4)
    p = moon_position(pd.Timestamp("2021-01-27T02:00:00-03:00"), -24.6, -70.4)
    assert 0.0 <= p.azimuth_deg.iloc[0] < 360.0
    assert p.index[0].utcoffset() == pd.Timedelta(hours=-3)  # the caller's zone is kept


def _moon_v_magnitude(phase_deg):
    """The Moon's V magnitude at the standard distances from ROLO (waxing, zero libration)."""
    a = lunar_disk_reflectance(get_band("V").wavelength_nm, phase_deg, phase_deg)
    e = lunar_irradiance(a, solar_irradiance("V"), STANDARD_MOON_DISTANCE_KM, 1.0)
    return get_band("V").sun_magnitude - 2.5 * np.log10(e / solar_irradiance("V"))


def test_rolo_against_published_lunar_phase_law():
    # The Moon's V magnitude vs phase angle, -12.73 + 0.026 |a| + 4e-9 a^4 (Allen 1973, as
    # eq. 20 of Krisciunas & Schaefer 1991, doi:10.1086/132921), against ROLO with the Sun's
    # V magnitude (Willmer 2018). Tolerance 0.15 mag: ROLO's absolute scale is good to
    # ~5-10 % (Kieffer & Stone 2005) and the phase law's fit to ~0.05 mag; the opposition
    # surge below 5 deg (where the two laws differ by design) is excluded.
    phase = np.array([7.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0])
    allen = -12.73 + 0.026 * phase + 4e-9 * phase ** 4
    assert np.max(np.abs(_moon_v_magnitude(phase) - allen)) < 0.15


def test_rolo_reflectance_redder_and_darker_with_phase():
    # Lunar reflectance rises with wavelength (the Moon is red; Kieffer & Stone fig. 7) and
    # falls with phase angle, at every ROLO band used by skysim's photometric bands.
    waves = [get_band(b).wavelength_nm for b in "BVRI"]
    a = lunar_disk_reflectance(np.array(waves)[:, None], [10.0, 40.0, 80.0], [10.0, 40.0, 80.0])
    assert np.all(np.diff(a, axis=0) > 0) and np.all(np.diff(a, axis=1) < 0)


def test_irradiance_inverse_square_and_bad_input():
    a = lunar_disk_reflectance(545.0, 30.0, 30.0)
    e1 = lunar_irradiance(a, 1.87, STANDARD_MOON_DISTANCE_KM, 1.0)
    e2 = lunar_irradiance(a, 1.87, 2 * STANDARD_MOON_DISTANCE_KM, 2.0)
    assert e2 == pytest.approx(e1 / 16.0, rel=1e-12)
    with pytest.raises(InvalidParameterError, match="wavelength_nm"):
        lunar_disk_reflectance(3000.0, 30.0, 30.0)
    with pytest.raises(InvalidParameterError, match="phase_angle_deg"):
        lunar_disk_reflectance(545.0, -5.0, 0.0)
    with pytest.raises(InvalidParameterError, match="distance"):
        lunar_irradiance(a, 1.87, 0.0)


def test_offline_for_any_date_and_any_clock(monkeypatch):
    """The Moon's position needs no network and no fresh Earth-orientation data: five years
    after today (past astropy's bundled predictions) with every socket refused and with the
    computer's clock set ten years ahead, it matches PyEphem. Tolerance 60 arcsec: the 30 of
    the random-date test plus UT1 - UTC held at its last predicted value (the IERS keeps
    |UT1 - UTC| < 0.9 s, so the held value is off by < 1.8 s, i.e. < 27 arcsec of Earth
    rotation)."""
    import socket

    import astropy.time
    import astropy.units as u

    def refuse(*args, **kwargs):
        raise OSError("network unavailable in this test")

    monkeypatch.setattr(socket, "socket", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)
    real_now = astropy.time.Time.now
    monkeypatch.setattr(astropy.time.Time, "now",
                        classmethod(lambda cls: real_now() + 3652 * u.day))
    when = pd.Timestamp.now(tz="UTC").floor("h") + pd.Timedelta(days=5 * 365)
    times = pd.date_range(when, periods=6, freq="4h")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing said past the tables either
        ours = moon_position(times, 34.14, 108.55, 400.0)
    for k, t in enumerate(times):
        o = ephem.Observer()
        o.lat, o.lon, o.elevation, o.pressure = "34.14", "108.55", 400.0, 0.0
        o.date = t.tz_localize(None).to_pydatetime()
        m = ephem.Moon(o)
        sep = angle_between_deg(
            direction_vector(ours.elevation_deg.iloc[k], ours.azimuth_deg.iloc[k]),
            direction_vector(math.degrees(m.alt), math.degrees(m.az)))
        assert float(sep) * 3600 < 60.0, (t, float(sep) * 3600)
