"""Model-free checks of a photodiode instrument (sum rule, gains, glare by side, motion)
against closed forms and simulated rings with a known fault planted."""

import numpy as np
import pandas as pd
import pytest

from calibration.photodiode_diagnosis.checks import (check_instrument, null_combinations,
                                                     sum_rule_residual, sun_geometry)
from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes
from sensor.compound_eye import ring_configuration
from skysim.sky import RayleighSky
from skysim.sun import Site, sun_vector

SITE = Site(39.258648, 8.440184, 0.0)


def _session(seed=1, n_sweeps=8):
    """A ring (8 units x 0/45/90/135) at 16:00 CEST in May: each sweep stands at four
    headings (10 samples each) and then turns once in 90 samples of 0.2 s."""
    rng = np.random.default_rng(seed)
    t0 = pd.Timestamp("2022-05-12T16:00:00+02:00")
    yaw, times, sweep = [], [], []
    for s in range(n_sweeps):
        seg = np.concatenate([np.repeat([0.0, 90.0, 180.0, 270.0], 10),
                              np.linspace(0.0, 360.0, 90, endpoint=False)]) + 20.0 * s
        yaw.append(seg)
        times += [t0 + pd.Timedelta(seconds=120 * s + 0.2 * j) for j in range(seg.size)]
        sweep += [s] * seg.size
    data = ring_configuration(8, 45.0).sample(
        RayleighSky(0.6), SITE, pd.DatetimeIndex(times), np.concatenate(yaw), 0.0, 0.0, rng,
        include_truth=False, sweep=np.array(sweep))
    inst = instrument_from_photodiodes(data)
    sun, _ = sun_vector(pd.to_datetime(inst.t_s, unit="s", utc=True), inst.site)
    return inst, sun


@pytest.fixture(scope="module")
def ring():
    return _session()


def test_null_combination_is_the_sum_rule_and_vanishes_under_malus():
    # closed form: for 0/45/90/135 the only combination is r0 - r45 + r90 - r135
    np.testing.assert_allclose(null_combinations([0, 45, 90, 135]), [[1, -1, 1, -1]],
                               atol=1e-12)
    assert null_combinations([0, 60, 120]).shape == (0, 3)      # no redundancy
    angles = np.arange(0.0, 180.0, 30.0)                          # six photodiodes
    null = null_combinations(angles)
    th = np.radians(angles)
    malus = np.stack([np.ones(6), np.cos(2 * th), np.sin(2 * th)])
    assert null.shape == (3, 6)
    np.testing.assert_allclose(malus @ null.T, 0.0, atol=1e-12)
    # any Stokes vector read through ideal analysers: residual 0 to rounding
    rng = np.random.default_rng(3)
    iqu = rng.uniform([1, -0.5, -0.5], [2, 0.5, 0.5], (50, 3))
    th4 = np.radians([0, 45, 90, 135])
    r = 0.5 * (iqu[:, :1] + iqu[:, 1:2] * np.cos(2 * th4) + iqu[:, 2:] * np.sin(2 * th4))
    s = sum_rule_residual(r, np.zeros(4, int), [0, 45, 90, 135])
    np.testing.assert_allclose(s, 0.0, atol=1e-13)
    expected = 4 * (r[:, 0] - r[:, 1] + r[:, 2] - r[:, 3]) / r.sum(axis=1)
    r2 = r * [1.0, 1.02, 1.0, 0.97]                                # unequal gains break it
    np.testing.assert_allclose(sum_rule_residual(r2, np.zeros(4, int), [0, 45, 90, 135])[:, 0],
                               4 * (r2[:, 0] - r2[:, 1] + r2[:, 2] - r2[:, 3]) / r2.sum(axis=1))
    assert np.allclose(expected, 0.0, atol=1e-13)


def test_sun_side_and_distance_against_geometry(ring):
    inst, sun = ring
    dist, side = sun_geometry(inst, 0.0, sun)
    # the sun's azimuth and elevation from its vector; unit k looks at heading + 45 k, 45 deg up
    sun_az = np.degrees(np.arctan2(sun[:, 0], sun[:, 1]))
    sun_el = np.degrees(np.arcsin(sun[:, 2]))
    view_az = inst.yaw_deg[:, None] + 45.0 * np.arange(8)
    daz = np.radians(sun_az[:, None] - view_az)
    cosd = (np.sin(np.radians(45)) * np.sin(np.radians(sun_el))[:, None]
            + np.cos(np.radians(45)) * np.cos(np.radians(sun_el))[:, None] * np.cos(daz))
    np.testing.assert_allclose(dist, np.degrees(np.arccos(cosd)), atol=1e-6)
    # the sun counter-clockwise from the view (seen from above) is on the unit's left
    expected = -np.sign(np.sin(daz))
    ok = np.abs(np.sin(daz)) > 1e-6
    assert np.array_equal(side[ok], expected[ok])


@pytest.mark.parametrize("dark_max", [0.0, 300.0])
def test_gains_recovered_from_the_sum_rule_alone(ring, dark_max):
    """Tolerance 1.5e-3: the readings' noise (3 counts on about 15,000) is 2e-4 relative; the
    gains average it over some 300 far-from-sun standing samples a unit, but the rule's
    constant (dark offsets, here none or up to 300 counts, 2 %) is estimated with them and
    trades with them where a unit's brightness varies little: measured max error 6.3e-4 in
    both cases, and 1.5e-3 is 20 times below the 3 % spread injected."""
    inst, sun = ring
    rng = np.random.default_rng(5)
    g = 1.0 + 0.03 * rng.standard_normal(inst.readings.shape[1])
    dark = rng.uniform(0.0, dark_max, inst.readings.shape[1])   # dark offsets [counts]
    checks = check_instrument(inst.with_readings(inst.readings * g + dark), 0.0, sun)
    truth = (g.reshape(8, 4) / g.reshape(8, 4).mean(axis=1, keepdims=True)).ravel()
    np.testing.assert_allclose(checks.gains, truth, atol=1.5e-3)
    assert checks.units_with_side_glare == [] and checks.units_failing_in_motion == []
    assert checks.sum_rule.rms.max() < 2e-3


def test_clean_ring_raises_no_alarm(ring):
    inst, sun = ring
    checks = check_instrument(inst, 0.0, sun)
    assert checks.units_failing_in_motion == []
    assert checks.units_with_side_glare == []
    assert not checks.motion_breaks_rule
    # residual at the noise: 3 counts per reading, four readings -> ~4 * 3 * 2 / 60,000
    assert checks.sum_rule.rms.max() < 2e-3


def test_glare_by_side_found_near_the_sun(ring):
    inst, sun = ring
    dist, side = sun_geometry(inst, 0.0, sun)
    r = inst.readings.copy()
    pattern = np.array([0.5, -0.5, 0.0, 0.0])   # light reaching the 0 and 45 deg diodes unequally
    for u in range(8):
        cols = np.arange(4 * u, 4 * u + 4)
        amp = 0.05 * np.exp(-dist[:, u] / 10.0) * r[:, cols].mean(axis=1)
        r[:, cols] += amp[:, None] * (1.0 + side[:, u][:, None] * pattern)
    checks = check_instrument(inst.with_readings(r), 0.0, sun)
    assert checks.units_with_side_glare == list(range(8))
    near = checks.sum_rule[checks.sum_rule.distance_deg == "(-0.001, 20.0]"]
    assert (near[near.side == "left"]["mean"] > 0.005).all()
    assert (near[near.side == "right"]["mean"] < -0.005).all()
    far = checks.sum_rule[checks.sum_rule.distance_deg == "(70.0, 90.0]"]
    assert (far.rms < 2e-3).all()                          # far from the sun: noise only
    assert checks.units_failing_in_motion == []


def test_unit_misreading_only_while_turning_is_named(ring):
    inst, sun = ring
    r = inst.readings.copy()
    cols = [17, 18]                                          # unit 4's 45 and 90 deg diodes
    stale = np.roll(r[:, cols], 1, axis=0)                   # read one sample late
    r[:, cols] = np.where(inst.rotating[:, None], stale, r[:, cols])
    checks = check_instrument(inst.with_readings(r), 0.0, sun)
    assert checks.units_failing_in_motion == [4]
    row = checks.motion.set_index("unit").loc[4]
    assert row.ratio > 10.0
    assert not checks.motion_breaks_rule          # one unit, not the instrument


def test_channels_converted_in_turn_break_the_rule_for_the_instrument(ring):
    """Every unit's 45, 90 and 135 deg diodes converted 1, 2 and 3 samples after its 0 deg
    diode (a multiplexed converter): turning breaks the rule everywhere, no single unit is
    named, and standing readings still obey it."""
    inst, sun = ring
    r = inst.readings.copy()
    for lag in (1, 2, 3):   # standing, a conversion later reads the same sky
        cols = np.arange(lag, 32, 4)
        r[:, cols] = np.where(inst.rotating[:, None], np.roll(r[:, cols], lag, axis=0),
                              r[:, cols])
    checks = check_instrument(inst.with_readings(r), 0.0, sun)
    assert checks.motion_breaks_rule and checks.turning_ratio > 10.0
    assert checks.units_failing_in_motion == []


def test_units_without_redundancy_are_skipped():
    r = np.random.default_rng(0).uniform(1, 2, (20, 6))
    s = sum_rule_residual(r, np.repeat([0, 1], 3), [0, 60, 120] * 2)
    assert np.isnan(s).all()


def test_given_gains_serve_units_whose_readings_do_not_define_them(ring):
    """Twelve samples (fewer than the rule's gains need): with the true gains and dark
    offsets handed in the residual is at the noise; without them it carries the gain and
    offset differences."""
    inst, sun = ring
    rng = np.random.default_rng(7)
    g = 1.0 + 0.03 * rng.standard_normal(32)
    dark = rng.uniform(0.0, 300.0, 32)
    few = inst.subset(np.arange(12)).with_readings(inst.readings[:12] * g + dark)
    given = check_instrument(few, 0.0, sun[:12], gains=g, dark_offsets=dark)
    assert given.gain_source == ["given"] * 8
    assert given.sum_rule.rms.max() < 2e-3
    bare = check_instrument(few, 0.0, sun[:12])
    assert bare.gain_source == ["none"] * 8
    assert bare.sum_rule.rms.max() > 10 * given.sum_rule.rms.max()


def test_ring_diagnosis_carries_the_checks():
    """Every ring diagnosis reports the checks, placed by its base fit: a clean simulated
    session (Rayleigh sky, read noise) raises no alarm and corrects every unit."""
    from calibration.photodiode_diagnosis.run import diagnose_photodiodes
    from ring_sessions import ring_session
    doc = diagnose_photodiodes(ring_session(seed=2), ("yaw_scale",), n_folds=3)
    checks = doc["instrument_checks"]
    assert checks["units_failing_in_motion"] == [] and checks["units_with_side_glare"] == []
    assert set(checks["gain_source"]) <= {"sum rule", "given"}
    assert max(row["rms"] for row in checks["sum_rule"]) < 2e-3
