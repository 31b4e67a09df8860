"""The night sky: K&S moonlit radiance in physical units, Rayleigh polarization with the Moon
as the source, the unpolarized background, sources adding as Stokes vectors."""

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("astropy", reason="the Moon's position needs astropy (extra 'moon')")

from skysim.bands import magnitude_to_radiance, radiance_to_magnitude  # noqa: E402
from skysim.exceptions import InvalidParameterError  # noqa: E402
from skysim.moon import moon_position  # noqa: E402
from skysim.molecular import bodhaine_optical_thickness_fit  # noqa: E402
from skysim.night import (MoonlitSky, TwilightError, aerosol_weight,  # noqa: E402
                          dark_sky_radiance, extinction_components, night_sky,
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


# --------------------------------------------------------------------------- per band
# Published Paranal values, typed here from the papers (independent of skysim.bands):
# Patat (2003, A&A 400:1183) abstract: zenith-corrected dark-sky brightness averaged over
# 2000-2001 [mag arcsec^-2]; Table A.1: weighted-mean broadband extinction [mag/airmass].
PATAT2003_DARK_SKY = {"U": 22.3, "B": 22.6, "V": 21.6, "R": 20.9, "I": 19.7}
PATAT2003_EXTINCTION = {"U": 0.47, "B": 0.22, "V": 0.11, "R": 0.07, "I": 0.05}
BESSELL_EFFECTIVE_NM = {"B": 438.0, "V": 545.0, "R": 641.0, "I": 798.0}  # Bessell 1998


@pytest.mark.parametrize("band", ["U", "B", "V", "R", "I"])
def test_dark_sky_zenith_per_band_is_patat_2003(band):
    # The background at the zenith (X = 1, no extinction excess) is the band's published
    # Paranal dark sky, which was measured through the broadband filter and so includes
    # the airglow lines of the band (OH and O2 in R and I). Tolerance 0.05 mag: the
    # published values are rounded to 0.1 mag.
    m = radiance_to_magnitude(dark_sky_radiance(90.0, band), band)
    assert abs(float(m) - PATAT2003_DARK_SKY[band]) <= 0.05


@pytest.mark.parametrize("band", ["U", "B", "V", "R", "I"])
def test_background_elevation_dependence_is_airglow_van_rhijn(band):
    # Towards the horizon the background brightens as a thin emitting layer seen through
    # a longer path (van Rhijn 1921) and dims by the band's extinction over the extra
    # airmass. Against van Rhijn's factor for a layer at 90 km (the OH, O2 and Na layers
    # at 85-95 km, Noll et al. 2012, A&A 543:A92) with Earth radius 6371 km, times
    # 10^(-0.4 k (X - 1)): K&S's 0.96 puts the layer at ~130 km, which differs from 90 km
    # by <= 2 % above 30 deg elevation (1.7 % at 30 deg): tolerance 2 %.
    el = np.array([30.0, 45.0, 60.0, 75.0, 90.0])
    z = np.radians(90.0 - el)
    van_rhijn = (1.0 - (6371.0 / 6461.0) ** 2 * np.sin(z) ** 2) ** -0.5
    k = PATAT2003_EXTINCTION[band]
    expected = van_rhijn * 10 ** (-0.4 * k * (van_rhijn - 1.0))
    ratio = dark_sky_radiance(el, band) / dark_sky_radiance(90.0, band)
    np.testing.assert_allclose(ratio, expected, rtol=0.02)


@pytest.mark.parametrize("band", ["B", "V", "R", "I"])
def test_extinction_parts_add_up_to_the_measured_broadband_coefficient(band):
    # Molecular scattering (Bodhaine at 744 hPa) plus Patat et al.'s (2011) aerosol power
    # law against the broadband coefficients measured by Patat (2003): within 0.02
    # mag/airmass, the spread of the bi-monthly means of Patat (2003) Table A.1 (ozone's
    # Chappuis absorption, ~0.01-0.02 in V and R, and the night-to-night aerosol change
    # are within it).
    c = extinction_components(band)
    assert abs(c["rayleigh"] + c["aerosol"] - PATAT2003_EXTINCTION[band]) <= 0.02
    assert c["rayleigh"] > 0 and c["aerosol"] > 0


@pytest.mark.parametrize("band", ["B", "V", "R", "I"])
def test_aerosol_weight_closed_form(band):
    # Aerosol over molecular scattering relative to V: (lambda/lambda_V)^-1.38 (Patat 2011)
    # over Bodhaine's closed-form fit (eq. 30) of the molecular optical thickness; pressure
    # and gravity cancel in the ratio. Tolerance 5e-4: the fit follows the full formula to
    # 1e-4 between 438 and 798 nm.
    lam, lam_v = BESSELL_EFFECTIVE_NM[band], BESSELL_EFFECTIVE_NM["V"]
    expected = (lam / lam_v) ** -1.38 / (bodhaine_optical_thickness_fit(lam)
                                         / bodhaine_optical_thickness_fit(lam_v))
    assert aerosol_weight(band) == pytest.approx(float(expected), rel=5e-4)
    assert aerosol_weight("V") == 1.0


def test_u_extinction_is_its_scattering_parts_within_patat_2003():
    # U's coefficient is the sum of its molecular (Bodhaine, 744 hPa) and aerosol (Patat
    # 2011) parts, rounded to 0.01 (ozone absorbs < 0.001 mag at 366 nm); it lies within
    # the bi-monthly U coefficients of Patat (2003) Table A.1, 0.41 +- 0.05 and 0.47 +- 0.01
    # (March-April and July-August 2000).
    c = extinction_components("U")
    assert abs(c["rayleigh"] + c["aerosol"] - c["total"]) <= 0.005
    assert 0.41 - 0.05 <= c["total"] <= 0.47 + 0.01


@pytest.mark.parametrize("pair, colour", [(("U", "B"), 0.166), (("B", "V"), 0.653),
                                          (("V", "R"), 0.352), (("V", "I"), 0.702)])
def test_sun_colours_are_ramirez_2012(pair, colour):
    # The Sun's band magnitudes (Willmer 2018) against its colours measured from solar
    # twins (Ramirez et al. 2012, ApJ 752:5: U-B 0.166 +- 0.022, B-V 0.653 +- 0.003,
    # V-R 0.352 +- 0.007, V-I 0.702 +- 0.010). Tolerance 0.03 mag: Willmer's 0.02 mag per
    # magnitude and Ramirez's error added in quadrature for the two magnitudes.
    from skysim.bands import get_band
    a, b = pair
    assert get_band(a).sun_magnitude - get_band(b).sun_magnitude == pytest.approx(colour,
                                                                                  abs=0.03)


def test_desert_albedo_is_aoki_2005_and_atacama():
    # The desert's spectral albedo against the ranges measured over gobi and sand (Aoki et
    # al. 2005): 0.05-0.11 at 350 nm, 0.2-0.3 at 600 nm, 0.37-0.49 at 1.8-2.2 um; rising
    # monotonically between. In the visible (B, V) not above the 0.25 of the Atacama's
    # brightest spots (Cordero et al. 2021).
    from skysim.bands import BANDS, desert_albedo
    assert 0.05 <= desert_albedo(350.0) <= 0.11
    assert 0.2 <= desert_albedo(600.0) <= 0.3
    assert 0.37 <= desert_albedo(2000.0) <= 0.49
    a = [BANDS[b].ground_albedo for b in "UBVRI"]
    assert all(np.diff(a) > 0) and max(BANDS["B"].ground_albedo, BANDS["V"].ground_albedo) <= 0.25
    with pytest.raises(InvalidParameterError, match="wavelength_nm=300"):
        desert_albedo([500.0, 300.0])


def test_red_sky_carries_more_aerosol_light():
    # The aerosol weight grows monotonically with wavelength (molecular scattering falls as
    # lambda^-4.08, aerosol as lambda^-1.38): B < V = 1 < R < I.
    w = [aerosol_weight(b) for b in "BVRI"]
    assert w[0] < w[1] == 1.0 < w[2] < w[3]


@pytest.mark.parametrize("band", ["U", "B", "V", "R", "I"])
def test_no_background_pure_rayleigh_limit_is_single_scattering(band):
    # Property: without background (40 mag/arcsec^2) and without aerosol (scale 0) every
    # band's DoP is the single-scattering Rayleigh value with K&S's molecular depolarization
    # term, sin^2 rho / (1.06 + cos^2 rho), whatever the band's extinction and Moon.
    el = np.linspace(5, 90, 25)
    az = np.linspace(0, 350, 25)
    ns = night_sky(el, az, NIGHT, PARANAL, band, dark_sky_mag_arcsec2=40.0, aerosol_scale=0.0)
    rho = np.radians(ns.components["moon_scattering_angle_deg"])
    np.testing.assert_allclose(ns.field.dop, np.sin(rho) ** 2 / (1.06 + np.cos(rho) ** 2),
                               atol=1e-9)


def test_band_selects_the_aerosol_weight_in_the_sky():
    # Without background the DoP is 10^5.36 sin^2 rho / (10^5.36 (1.06 + cos^2 rho)
    # + w 10^(6.15 - rho/40)), with w the band's aerosol weight (closed form).
    el, az = np.array([30.0, 50.0, 70.0]), np.array([0.0, 120.0, 240.0])
    for band in "BRI":
        ns = night_sky(el, az, NIGHT, PARANAL, band, dark_sky_mag_arcsec2=40.0)
        assert ns.sources["aerosol_scale"] == aerosol_weight(band)
        rho = np.radians(ns.components["moon_scattering_angle_deg"])
        f = (10 ** 5.36 * (1.06 + np.cos(rho) ** 2)
             + aerosol_weight(band) * 10 ** (6.15 - np.degrees(rho) / 40))
        np.testing.assert_allclose(ns.field.dop, 10 ** 5.36 * np.sin(rho) ** 2 / f, atol=1e-9)
    sky = MoonlitSky(1e-6, "R")
    assert sky.aerosol_scale == aerosol_weight("R") and sky.describe()["aerosol_scale"] > 1
    with pytest.raises(InvalidParameterError, match="aerosol_scale"):
        night_sky(45.0, 0.0, NIGHT, PARANAL, "R", aerosol_scale=-1.0)
