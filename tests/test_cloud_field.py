"""The cloud field (skysim.cloud_field): geometry, exact cover, correlation scale, seeds,
drift, thickness profiles and bad input."""

import numpy as np
import pytest

from skysim.cloud_field import (EARTH_RADIUS_M, QUANTILE_GRID, CloudField, air_below,
                                equal_area_grid, layer_intersection, matern_correlation,
                                matern_efold_ratio, time_offsets_s)
from skysim.exceptions import BroadcastError, InvalidParameterError


def test_layer_intersection_matches_vector_geometry_and_its_limits():
    # Independent reference: the ray from the site (0, R) along (cos e, sin e) meets the
    # circle of radius R + h where a root finder says so; arc distance and local zenith
    # cosine from those vectors. 1e-9 relative: root-finder tolerance.
    from scipy.optimize import brentq
    h = 1500.0
    R = EARTH_RADIUS_M
    el = np.array([0.0, 0.5, 3.0, 10.0, 30.0, 60.0, 89.0, 90.0])
    s, mu = layer_intersection(el, h)
    for e, s_k, mu_k in zip(np.radians(el), s, mu):
        d = np.array([np.cos(e), np.sin(e)])
        length = brentq(lambda t: np.hypot(t * d[0], R + t * d[1]) - (R + h), 0.0, 1e6,
                        xtol=1e-9)
        p = np.array([length * d[0], R + length * d[1]])
        assert s_k == pytest.approx((R + h) * np.arctan2(p[0], p[1]), rel=1e-9, abs=1e-9)
        assert mu_k == pytest.approx(d @ p / (R + h), rel=1e-9)
    # overhead: distance 0 and mu 1; at 45 deg the flat limit h cot e holds to h/R
    assert s[-1] == pytest.approx(0.0, abs=1e-6) and mu[-1] == pytest.approx(1.0)
    s45, mu45 = layer_intersection(45.0, h)
    assert s45 == pytest.approx(h, rel=2 * h / R)
    assert mu45 == pytest.approx(np.sin(np.radians(45.0)), rel=2 * h / R)


def test_air_below_the_layer_has_the_closed_form_limits():
    # Overhead and in the thin limit the share is 1 - exp(-h/H) (H = 8 km); the whole
    # path's air mass at the horizon is sqrt(pi R / (2 H)) (Chapman's grazing limit, to
    # O(H/R) = 1e-3); at 30 deg the plane-parallel 1/sin(e) within 1 %
    from skysim.clouds import MOLECULAR_SCALE_HEIGHT_M as H
    from skysim.clouds import molecular_fraction_below
    frac, trans = air_below(90.0, 1000.0, tau=1e-9)
    assert frac == pytest.approx(molecular_fraction_below(1000.0), rel=1e-4)
    tau = 1e-9
    # thin atmosphere: transmission exp(-tau m_b) gives m_b, the fraction m_b / m gives m
    f0, t0 = air_below(0.0, 1000.0, tau=tau)
    m_horizon = -np.log(t0) / tau / f0
    assert m_horizon == pytest.approx(np.sqrt(np.pi * EARTH_RADIUS_M / (2 * H)), rel=0.02)
    _, t30 = air_below(30.0, 1000.0, tau=tau)
    assert -np.log(t30) / tau == pytest.approx(molecular_fraction_below(1000.0) / 0.5,
                                               rel=0.01)
    assert air_below(0.0, 1000.0)[0] > 0.7 > 0.2 > air_below(60.0, 1000.0)[0]


def test_matern_correlation_is_exponential_for_one_half():
    # nu = 1/2 is the exponential correlation exp(-r/L) (Stein 1999, sect. 2.7): 1e-12
    x = np.array([0.0, 0.1, 1.0, 3.0])
    np.testing.assert_allclose(matern_correlation(x, 0.5), np.exp(-x), rtol=1e-12)
    assert matern_efold_ratio(0.5) == pytest.approx(1.0, rel=1e-10)


@pytest.mark.parametrize("cover", [0.0, 0.1, 0.5, 0.9, 1.0])
def test_cover_is_exact_on_its_grid_and_holds_on_independent_directions(cover):
    # Exact on the equal-solid-angle quantile grid (one cell = 1/18432); on 30000 directions
    # drawn uniformly over the dome's solid angle the cloudy share matches within 0.012:
    # binomial sampling (sd <= 0.003) plus the grid's own discretisation of the cloud edges
    # (at most 0.006 over 30 fields on a 300 x 600 grid, measured)
    f = CloudField(cover, 5.0, 11)
    grid = equal_area_grid(*QUANTILE_GRID)
    n = grid[0].size
    assert int(f.cloudy(*grid).sum()) == round(cover * n)
    rng = np.random.default_rng(3)
    el = np.degrees(np.arcsin(rng.uniform(0.0, 1.0, 30000)))
    az = rng.uniform(0.0, 360.0, 30000)
    assert f.cloudy(el, az).mean() == pytest.approx(cover, abs=0.012)


@pytest.mark.parametrize("smoothness, scale_deg", [(1.0 / 3.0, 10.0), (1.5, 20.0)])
def test_correlation_scale_is_recovered_from_the_empirical_autocorrelation(smoothness,
                                                                         scale_deg):
    # The field's correlation between the zenith and the directions at angle a from it,
    # estimated over 150 fields, each seen at 40 times far apart (a 50 m/s wind carries
    # 180 km of independent cloud over the zenith between them), falls to 1/e at the set
    # scale within 10 %: the estimate's sampling error is about 3 % (its spread over
    # independent seed sets, measured), the rest the interpolation between the 9 angles
    alphas = np.linspace(0.6, 1.4, 9) * scale_deg
    azimuths = np.arange(0.0, 360.0, 60.0)
    times = np.arange(40) * 3600.0
    acc = np.zeros(alphas.size)
    for seed in range(150):
        f = CloudField(0.5, 5.0, seed, correlation_deg=scale_deg, smoothness=smoothness,
                       wind_speed_m_s=50.0)
        g0 = f.gaussian(90.0, 0.0, times)
        g = f.gaussian(90.0 - alphas[:, None, None], azimuths[None, :, None],
                       times[None, None, :])
        acc += (g0 * g).mean(axis=(1, 2))
    r = acc / 150
    assert np.all(np.diff(r) < 0)
    efold = np.interp(-np.exp(-1.0), -r, alphas)
    assert efold == pytest.approx(scale_deg, rel=0.10)


def test_the_field_has_unit_variance_and_gaussian_marginals():
    # E[g^2] = 1 over fields (the modes' amplitude sqrt(2/N)); a sum of 256 random-phase
    # cosines has excess kurtosis -1.5/256 (Gaussian within 0.01): over 100 fields x 2000
    # directions the variance is 1 within 0.05 and the kurtosis 3 within 0.15 (sampling)
    el, az = equal_area_grid(20, 100)
    g = np.stack([CloudField(0.5, 5.0, s).gaussian(el, az) for s in range(100)])
    assert np.mean(g ** 2) == pytest.approx(1.0, abs=0.05)
    z = g.ravel() / np.sqrt(np.mean(g ** 2))
    assert np.mean(z ** 4) == pytest.approx(3.0, abs=0.15)


def test_seeds_reproduce_the_field():
    el, az = equal_area_grid(10, 20)
    a = CloudField(0.4, 3.0, 7).optical_thickness(el, az)
    b = CloudField(0.4, 3.0, 7).optical_thickness(el, az)
    c = CloudField(0.4, 3.0, 8).optical_thickness(el, az)
    d = CloudField(0.4, 3.0, np.random.default_rng(7)).optical_thickness(el, az)
    e = CloudField(0.4, 3.0, np.random.SeedSequence(7)).optical_thickness(el, az)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, d)      # a seed is default_rng(seed)
    np.testing.assert_array_equal(a, e)
    assert not np.array_equal(a, c)
    assert CloudField(0.4, 3.0, 7).describe()["seed"] == 7


def test_drift_moves_the_field_by_the_set_angle():
    # A 10 m/s wind from the west (270 deg) at 1000 m: after t seconds the cloud over the
    # zenith is the one that was seen at time 0 in the west, at the elevation whose ray meets
    # the layer 10 t m away (layer_intersection, inverted by a root finder): equal to 1e-9.
    # Overhead the angular speed is v / h = 0.573 deg/s.
    from scipy.optimize import brentq
    f = CloudField(0.5, 5.0, 2, wind_speed_m_s=10.0, wind_from_deg=270.0)
    assert f.zenith_angular_speed_deg_s == pytest.approx(np.degrees(10.0 / 1000.0))
    for t in (1.0, 30.0, 120.0):
        el = brentq(lambda e: layer_intersection(e, 1000.0)[0] - 10.0 * t, 1e-3, 90.0,
                    xtol=1e-12)
        if t == 1.0:   # small angles: the set angular speed
            assert 90.0 - el == pytest.approx(f.zenith_angular_speed_deg_s * t, rel=1e-3)
        assert f.gaussian(90.0, 0.0, t) == pytest.approx(f.gaussian(el, 270.0, 0.0), abs=1e-9)
        # and any other direction shifts the same way: a point seen east of the zenith
        s_e, _ = layer_intersection(60.0, 1000.0)
        el2 = brentq(lambda e: layer_intersection(e, 1000.0)[0] - abs(s_e - 10.0 * t), 1e-3,
                     90.0, xtol=1e-12)
        az2 = 90.0 if s_e > 10.0 * t else 270.0
        assert f.gaussian(60.0, 90.0, t) == pytest.approx(f.gaussian(el2, az2, 0.0), abs=1e-9)
    still = CloudField(0.5, 5.0, 2)
    assert still.gaussian(70.0, 10.0, 1e4) == still.gaussian(70.0, 10.0, 0.0)


def test_thickness_profiles():
    # uniform: tau in every cloudy direction; excess: its mean over the cloudy cells of the
    # quantile grid is tau (round-off), thinning to 0 at the edges
    grid = equal_area_grid(*QUANTILE_GRID)
    u = CloudField(0.3, 4.0, 5).optical_thickness(*grid)
    assert set(np.unique(u)) == {0.0, 4.0}
    x = CloudField(0.3, 4.0, 5, thickness="excess").optical_thickness(*grid)
    assert np.array_equal(x > 0, u > 0)
    assert x[x > 0].mean() == pytest.approx(4.0, rel=1e-12)
    assert x[x > 0].min() < 0.05 * 4.0 < x.max()
    assert np.all(CloudField(1.0, 4.0, 5, thickness="excess").optical_thickness(*grid) > 0)
    assert not CloudField(0.0, 4.0, 5).cloudy(*grid).any()


def test_uniform_overcast_is_tau_everywhere_without_the_field():
    """Cover 1, uniform: every direction and layer point has tau, the same as the field's
    own path (every value above the threshold -inf) gives; the shortcut skips the field."""
    c = CloudField(1.0, 2.5, 7)
    assert c.overcast and not CloudField(1.0, 2.5, 7, thickness="excess").overcast
    assert c.threshold == -np.inf
    x, y, _ = c.layer_points(*equal_area_grid(24, 48))
    fast = c.optical_thickness_at(x, y)
    assert np.array_equal(fast, c.optical_thickness_of(c.gaussian(*equal_area_grid(24, 48))))
    assert np.all(fast == 2.5) and fast.shape == x.shape


def test_times_align_with_the_sun_positions():
    assert time_offsets_s(5.0, (3,)).shape == ()
    assert time_offsets_s([1.0, 2.0, 3.0], (3, 1)).shape == (3, 1)
    with pytest.raises(BroadcastError, match="one time per sun position"):
        time_offsets_s([1.0, 2.0], (3,))


@pytest.mark.parametrize("kwargs, match", [
    ({"cover": -0.1}, "cover"), ({"cover": 1.5}, "cover"), ({"cover": np.nan}, "cover"),
    ({"tau": -1.0}, "cloud tau"), ({"tau": 500.0}, "cloud tau"),
    ({"correlation_deg": 0.0}, "correlation_deg"), ({"correlation_deg": 90.0}, "correlation_deg"),
    ({"base_m": 10.0}, "base_m"), ({"thickness": "lumpy"}, "thickness"),
    ({"smoothness": 0.0}, "smoothness"), ({"wind_speed_m_s": -1.0}, "wind_speed_m_s"),
    ({"wind_from_deg": np.inf}, "wind_from_deg"), ({"n_modes": 4}, "n_modes"),
    ({"n_modes": 64.0}, "n_modes"), ({"rng": "seven"}, "rng"), ({"rng": -1}, "rng"),
    ({"rng": True}, "rng"),
])
def test_bad_input_names_the_value(kwargs, match):
    args = {"cover": 0.5, "tau": 5.0, **kwargs}
    cover, tau = args.pop("cover"), args.pop("tau")
    with pytest.raises(InvalidParameterError, match=match):
        CloudField(cover, tau, **args)


def test_bad_directions_and_times_are_refused():
    f = CloudField(0.5, 5.0, 0)
    with pytest.raises(InvalidParameterError, match="elevation_deg"):
        f.gaussian(-5.0, 0.0)
    with pytest.raises(InvalidParameterError, match="time_s"):
        f.gaussian(45.0, 0.0, np.nan)
