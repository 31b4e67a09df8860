"""The ring's field-of-view candidate where the horizon cuts a wide acceptance: its rule
and the simulated sessions' against a brute-force integral with the ground dark."""

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import quad

from calibration.diagnosis.identifiability import RING_SITE, RING_START, _cone_readings
from calibration.photodiode_diagnosis.acceptance import (
    ACCEPTANCE_ORDER,
    _columns,
    _stokes_average,
    acceptance,
    acceptance_quadrature,
    horizon_quadrature,
    unit_up_vectors,
)
from calibration.photodiode_diagnosis.effects import FieldOfView
from sensor.compound_eye import PhotodiodeModel, body_attitude, ring_configuration
from skysim.exceptions import InvalidParameterError
from skysim.sky import RayleighSky
from skysim.sun import Site, sun_vector


@pytest.fixture(scope="module")
def ring():
    """Eight units at 45 deg elevation at six headings under the 16:01 sun of the reference
    day."""
    sensor = ring_configuration(8, 45.0, photodiode=PhotodiodeModel())
    yaw = np.linspace(0.0, 360.0, 6, endpoint=False) + 20.0
    att = body_attitude(yaw, np.zeros(yaw.size), np.zeros(yaw.size))
    times = pd.DatetimeIndex([pd.Timestamp(RING_START)] * yaw.size)
    sun, _ = sun_vector(times, Site(*RING_SITE))
    return sensor, RayleighSky(0.6), att, sun


def _brute(sensor, sky, att, sun, h, K=200, M=200):
    """Brute force: K equal-area rings out to where the acceptance falls to 1e-8 times M
    equal azimuth steps, every direction weighted by the acceptance and normalised by the
    whole acceptance, a direction adding no light at the samples where it looks below the
    horizon; returns ``I, Q/I, U/I`` (n, m)."""
    t_max = min(90.0, h * (np.log(1e8) / np.log(2.0)) ** (1.0 / ACCEPTANCE_ORDER))
    cos_t = 1.0 - (np.arange(K) + 0.5) / K * (1.0 - np.cos(np.radians(t_max)))
    theta = np.repeat(np.degrees(np.arccos(cos_t)), M)
    az = np.tile(360.0 * (np.arange(M) + 0.5) / M, K)
    w = acceptance(theta, h)
    o = _stokes_average(_columns(sensor, sky, att, sun, theta, az, w / w.sum(),
                                 dark_below=True, per_column=False), sensor.n_units)
    x = np.radians(2.0 * o.aop_unit_deg)
    return o.radiance, o.dop * np.cos(x), o.dop * np.sin(x)


def _malus(o, sensor):
    pu = np.array([i for i, u in enumerate(sensor.units) for _ in u.photodiodes_deg])
    ang = np.array([a for u in sensor.units for a in u.photodiodes_deg], float)
    return o[0][:, pu] * (1.0 + o[1][:, pu] * np.cos(2 * np.radians(ang))
                          + o[2][:, pu] * np.sin(2 * np.radians(ang)))


def test_up_vectors_give_the_units_elevation(ring):
    sensor, _, att, _ = ring
    up = unit_up_vectors(sensor, att)
    np.testing.assert_allclose(up[:, 2], np.sin(np.radians(45.0)), atol=1e-12)
    # the axis tilts up along the unit's x axis (towards the zenith in its meridian)
    np.testing.assert_allclose(up[:, 0], np.cos(np.radians(45.0)), atol=1e-12)
    np.testing.assert_allclose(up[:, 1], 0.0, atol=1e-12)


@pytest.mark.parametrize("h", [24.0, 25.0, 28.0, 30.0, 40.0, 50.0, 60.0])
def test_the_rule_weighs_the_visible_part_of_the_acceptance(h):
    """Its weights sum to the part of the acceptance above the horizon, against scipy's
    adaptive integral of ``a(theta) sin(theta) 2 beta(theta)`` (``beta`` the half-width of
    the visible arc) over the whole acceptance's ``a sin(theta) 2 pi``: with 12 nodes in
    each stretch to 1e-7 (measured 3e-8; the rule stops where the acceptance is 1e-6 of its
    peak), with the candidate's 6 to 1e-4 (measured 1e-8 to 7e-8 at 24-30 deg, up to 6.8e-5
    at 50 deg: a common factor on each unit's radiance, which its profiled radiance takes
    up). From 24 deg, just past where the horizon starts to cut a unit at 45 deg (23.8 deg),
    the sum must stay continuous with the uncut rule's 1: normalised by a separate fine
    integral it jumped to 0.997 there."""
    e = 45.0
    up = np.array([np.cos(np.radians(e)), 0.0, np.sin(np.radians(e))])

    def half(x):
        c = -np.tan(np.radians(e)) / np.tan(x) if x > 0 else -np.inf
        return np.arccos(np.clip(c, -1.0, 1.0))
    opts = {"limit": 400, "epsabs": 1e-14, "epsrel": 1e-12, "points": [np.radians(90 - e)]}
    seen = quad(lambda x: acceptance(np.degrees(x), h) * np.sin(x) * 2 * half(x), 0,
                np.pi / 2, **opts)[0]
    whole = quad(lambda x: acceptance(np.degrees(x), h) * np.sin(x) * 2 * np.pi, 0,
                 np.pi / 2, **opts)[0]
    assert seen / whole < 1.0       # the horizon cuts 1e-9 to 12 % of the acceptance away
    fine = horizon_quadrature(h, up, n_polar=12, n_azimuth=6, n_arc=8)[2][0].sum()
    assert fine == pytest.approx(seen / whole, abs=1e-7)
    t, b, w = horizon_quadrature(h, up, n_polar=6, n_azimuth=6, n_arc=8)
    assert w[0].sum() == pytest.approx(seen / whole, abs=1e-4)
    # every direction of the rule looks above the horizon: sin el = up . direction
    tr, br = np.radians(t[0]), np.radians(b[0])
    d = np.stack([np.sin(tr) * np.sin(br), -np.sin(tr) * np.cos(br), np.cos(tr)], -1)
    assert np.all(d @ up > 0.0)


def test_an_acceptance_the_horizon_does_not_reach_keeps_the_plain_rule():
    up = np.array([np.cos(np.radians(45.0)), 0.0, np.sin(np.radians(45.0))])
    t, b, w = horizon_quadrature(20.0, up)
    t0, b0, w0 = acceptance_quadrature(20.0, n_polar=6, n_azimuth=6)
    for got, ref in ((t, t0), (b, b0), (w, w0)):
        np.testing.assert_array_equal(got[0], ref)


@pytest.mark.parametrize("h, tol", [(24.0, 3e-4), (25.0, 3e-4), (28.0, 3e-4), (30.0, 6e-5),
                                    (40.0, 6e-5), (45.0, 6e-5), (50.0, 6e-5), (60.0, 6e-5)])
def test_candidate_matches_a_brute_force_integral_of_the_cut_acceptance(ring, h, tol):
    """The candidate's forward model against a 200 x 200 equal-area grid that drops every
    direction below the horizon at each sample (the ground dark, the normalisation the whole
    acceptance). Measured: ``Q/I`` and ``U/I`` within 1.7e-5 to 4.1e-5 of the grid at 40-60
    deg, the radiance within 2.5e-5 to 1.6e-4; the grid's own error, against 400 x 720, is
    up to 1.5e-5 in ``Q/I`` and 1.3e-4 in the radiance. The tolerances, 6e-5 and 3e-4, are
    the measured errors plus twice the grid's own, ten times below those of the rule that
    drops whole directions (4e-4 to 8e-3), and below the 3e-4 noise of one reading of the
    simulated ring (a HWHM 1 deg off moves ``Q/I`` by about 2e-3). Just past where the
    horizon starts to cut (24-28 deg for units at 45 deg) most of the acceptance is on the
    visible cap, whose 6 Gauss-Legendre nodes span its steep edge as the uncut rule's do:
    ``Q/I`` within 1.7e-4 to 2.7e-4 there (the uncut rule: 1.2e-4 at the measured 22.7 deg),
    tolerance 3e-4 in both; the radiance is continuous across the onset (the weights'
    normalisation, :func:`test_the_rule_weighs_the_visible_part_of_the_acceptance`)."""
    sensor, sky, att, sun = ring
    ref = _brute(sensor, sky, att, sun, h)
    o = FieldOfView().observe(sensor, sky, att, sun, np.array([h]))
    x = np.radians(2.0 * o.aop_unit_deg)
    got = (o.radiance, o.dop * np.cos(x), o.dop * np.sin(x))
    assert np.max(np.abs(got[0] / ref[0] - 1.0)) < 3e-4
    assert max(np.max(np.abs(got[1] - ref[1])), np.max(np.abs(got[2] - ref[2]))) < tol


@pytest.mark.parametrize("h", [40.0, 45.0])
def test_simulated_sessions_match_the_brute_force_integral(ring, h):
    """The generator's own rule (equal-area rings, midpoints on each visible arc) against
    the same 200 x 200 grid, per photodiode reading relative to the mean: measured 7.2e-5
    and 1.4e-4 at 40 and 45 deg, against 5e-4 for the rule that dropped whole directions;
    tolerance 2e-4 (the grid's own error in the radiance is up to 1.3e-4)."""
    sensor, sky, att, sun = ring
    ref = _malus(_brute(sensor, sky, att, sun, h), sensor)
    R = _cone_readings(sensor, sky, att, sun, h)
    assert np.max(np.abs(R - ref)) / ref.mean() < 2e-4


def test_a_unit_looking_below_the_horizon_is_named():
    with pytest.raises(InvalidParameterError, match="2.00 deg below the horizon"):
        horizon_quadrature(40.0, np.array([np.cos(np.radians(2.0)), 0.0,
                                           -np.sin(np.radians(2.0))]))
