"""The night sky: K&S moonlit radiance in physical units, Rayleigh polarization with the Moon
as the source, the unpolarized background, sources adding as Stokes vectors."""

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("astropy", reason="the Moon's position needs astropy (extra 'moon')")

from skysim.bands import magnitude_to_radiance, radiance_to_magnitude  # noqa: E402
from skysim.exceptions import InvalidParameterError  # noqa: E402
from skysim.moon import moon_position  # noqa: E402
from skysim.night import (TwilightError, dark_sky_radiance, night_sky,  # noqa: E402
                          scattered_radiance)
from skysim.rayleigh import angle_of_polarization_deg  # noqa: E402
from skysim.sun import Site  # noqa: E402

PARANAL = Site(-24.6272, -70.4042, 2635.0)
NIGHT = "2021-01-27T05:00:00Z"  # Moon at 36 deg, 97 % lit; Sun at -47 deg


def test_unit_conversion_reproduces_krisciunas_schaefer_in_nanolamberts():
    # K&S (1991) eqs. 15-21 evaluated in their own units (I* from the Moon's magnitude,
    # B in nanolamberts, eq. 1 back to V mag/arcsec^2) against skysim's radiance for the
    # same Moon (irradiance from the same magnitude through the V zero point). The routes
    # are algebraically identical but for K&S's rounded 0.92104 for 0.4 ln 10 (6e-6
    # relative, 1.2e-4 mag at 19 mag/arcsec^2): tolerance 3e-4 mag.
    m_moon, k = -12.0, 0.172
    rho, z, zm = np.array([20.0, 60.0, 90.0, 120.0]), 30.0, 50.0
    X = lambda zd: (1 - 0.96 * np.sin(np.radians(zd)) ** 2) ** -0.5  # noqa: E731
    f = 10 ** 5.36 * (1.06 + np.cos(np.radians(rho)) ** 2) + 10 ** (6.15 - rho / 40)
    istar = 10 ** (-0.4 * (m_moon + 16.57))
    b_nl = f * istar * 10 ** (-0.4 * k * X(zm)) * (1 - 10 ** (-0.4 * k * X(z)))
    v_ks = (20.7233 - np.log(b_nl / 34.08)) / 0.92104
    e_moon = 3.631e-11 * 10 ** (-0.4 * m_moon)
    # the view at zenith distance z, the Moon at zm in the same vertical, then rotated in
    # azimuth so that the scattering angle is rho
    cos_az = (np.cos(np.radians(rho)) - np.cos(np.radians(z)) * np.cos(np.radians(zm))) / (
        np.sin(np.radians(z)) * np.sin(np.radians(zm)))
    az = np.degrees(np.arccos(np.clip(cos_az, -1, 1)))
    ok = np.abs(cos_az) <= 1
    parts = scattered_radiance(90 - z, az[ok], 90 - zm, 0.0, e_moon, k)
    total = parts["dipole"] + parts["depolarized"] + parts["mie"]
    np.testing.assert_allclose(radiance_to_magnitude(total, "V"), v_ks[ok], atol=3e-4)


def test_dop_is_rayleigh_over_ks_total_without_background():
    # With a negligible background (40 mag/arcsec^2) the DoP is the dipole part's
    # polarized radiance over K&S's whole f(rho): 10^5.36 sin^2 rho / f(rho), closed form.
    el = np.linspace(5, 90, 40)
    az = np.linspace(0, 350, 40)
    ns = night_sky(el, az, NIGHT, PARANAL, "V", dark_sky_mag_arcsec2=40.0)
    rho = np.radians(ns.components["moon_scattering_angle_deg"])
    f = 10 ** 5.36 * (1.06 + np.cos(rho) ** 2) + 10 ** (6.15 - np.degrees(rho) / 40)
    np.testing.assert_allclose(ns.field.dop, 10 ** 5.36 * np.sin(rho) ** 2 / f, atol=1e-9)


def test_aop_perpendicular_to_the_scattering_plane_through_the_moon():
    # Invariant of the conventions: the E-vector of single scattering is perpendicular to the
    # scattering plane; at the zenith, perpendicular to the lunar meridian.
    moon = moon_position(NIGHT, PARANAL.latitude_deg, PARANAL.longitude_deg,
                         PARANAL.altitude_m).iloc[0]
    el, az = np.array([90.0, 60.0, 30.0, 45.0]), np.array([0.0, 10.0, 200.0, 300.0])
    ns = night_sky(el, az, NIGHT, PARANAL, "B")
    expected = angle_of_polarization_deg(el, az, moon.elevation_deg, moon.azimuth_deg)
    np.testing.assert_allclose(ns.field.aop_deg, expected, atol=1e-9)
    zen = night_sky(90.0, moon.azimuth_deg, NIGHT, PARANAL)  # meridian of the Moon
    assert abs(abs(zen.field.aop_deg) - 90.0) < 1e-9


def test_background_zenith_value_and_unpolarized():
    # At the zenith the background is the band's dark-sky value (X = 1), and it only adds
    # to I: Q, U are those of the moonlight alone.
    np.testing.assert_allclose(radiance_to_magnitude(dark_sky_radiance(90.0, "V"), "V"), 21.6,
                               atol=1e-12)
    a = night_sky([45.0, 70.0], [0.0, 90.0], NIGHT, PARANAL, "V")
    b = night_sky([45.0, 70.0], [0.0, 90.0], NIGHT, PARANAL, "V", dark_sky_mag_arcsec2=18.0)
    np.testing.assert_allclose(a.field.Q, b.field.Q, rtol=1e-12)
    extra = magnitude_to_radiance(18.0, "V") - magnitude_to_radiance(21.6, "V")
    x = (1 - 0.96 * np.cos(np.radians([45.0, 70.0])) ** 2) ** -0.5
    np.testing.assert_allclose(b.field.I - a.field.I,
                               extra * 10 ** (-0.4 * 0.11 * (x - 1)) * x, rtol=1e-9)


def test_moon_below_horizon_leaves_the_unpolarized_background():
    t = "2021-01-20T06:00:00Z"  # Paranal: Moon at -27 deg, Sun at -42 deg
    moon = moon_position(t, PARANAL.latitude_deg, PARANAL.longitude_deg).iloc[0]
    assert moon.elevation_deg < 0
    ns = night_sky([30.0, 80.0], [0.0, 180.0], t, PARANAL)
    assert np.all(ns.components["moon_I"] == 0) and np.all(ns.field.dop == 0)


def test_sources_add_as_stokes_vectors_in_daylight():
    # Sun and Moon both up (Paranal, 2021-01-26 23:00 UTC: Sun at +10 deg, Moon at +2 deg):
    # the total is the sum of the two K&S radiances and the background, and the sunlit
    # pattern dominates the polarization (the Moon is ~4e5 times fainter).
    t = "2021-01-26T23:00:00Z"
    el, az = np.array([50.0, 80.0]), np.array([90.0, 250.0])
    ns = night_sky(el, az, t, PARANAL, "V")
    c = ns.components
    np.testing.assert_allclose(ns.field.I, c["moon_I"] + c["sun_I"] + c["background_I"],
                               rtol=1e-12)
    sun_el, sun_az = ns.sources["sun_elevation_deg"][0], ns.sources["sun_azimuth_deg"][0]
    assert sun_el > 0 and ns.sources["moon"].elevation_deg.iloc[0] > 0
    expected = angle_of_polarization_deg(el, az, sun_el, sun_az)
    np.testing.assert_allclose(ns.field.aop_deg, expected, atol=1e-3)


def test_twilight_is_refused_with_the_sun_named():
    with pytest.raises(TwilightError, match=r"Sun is at -1\d\.\d deg"):
        night_sky(45.0, 0.0, "2021-01-27T00:48:59Z", PARANAL, "V")
    ns = night_sky(45.0, 0.0, "2021-01-27T00:48:59Z", PARANAL, "V", include_sun=False)
    assert 0 < ns.field.dop[()] < 1


def test_one_time_per_direction_broadcasts():
    times = pd.DatetimeIndex(["2021-01-27T03:00Z", "2021-01-27T05:00Z", "2021-01-27T07:00Z"])
    ns = night_sky([40.0, 50.0, 60.0], [0.0, 90.0, 180.0], times, PARANAL, "R")
    each = [night_sky(e, a, t, PARANAL, "R").field.dop[()]
            for e, a, t in zip([40.0, 50.0, 60.0], [0.0, 90.0, 180.0], times)]
    np.testing.assert_allclose(ns.field.dop, each, rtol=1e-12)


def test_bad_input_named():
    with pytest.raises(InvalidParameterError, match="view_elevation_deg"):
        night_sky(-5.0, 0.0, NIGHT, PARANAL)
    with pytest.raises(ValueError, match="unknown band 'K'"):
        night_sky(45.0, 0.0, NIGHT, PARANAL, "K")
