"""Compound-eye sensor: frames, attitude, sampling any Sky along the actual unit directions."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.installation import polarization_from_photodiodes
from sensor.compound_eye import (FOUR_ANGLES_DEG, THREE_PAIR_ANGLES_DEG, CompoundEyeSensor,
                                 PhotodiodeModel, Unit, UnitBelowHorizonError, attitude_angles,
                                 body_attitude, patent_configuration, ring_configuration,
                                 with_random_installation_errors)
from skysim.geometry import angle_between_deg, direction_vector, elevation_azimuth
from skysim.sky import RayleighSky
from skysim.sun import Site, sun_vector

SITE = Site(39.98, 116.35, 50.0)
SKY = RayleighSky(0.7)


def _sun(n, rng):
    """Sun ENU vectors of an afternoon at the site (elevation 20-70 deg)."""
    times = pd.date_range("2020-06-15T12:00+08:00", "2020-06-15T17:30+08:00", periods=n)
    return sun_vector(times, SITE)[0]


def test_patent_and_ring_layouts():
    s = patent_configuration()
    assert s.n_units == 9 and s.units[0].elevation_deg == 90.0
    assert [u.azimuth_deg for u in s.units[1:]] == [45.0 * k for k in range(8)]
    assert all(u.photodiodes_deg == THREE_PAIR_ANGLES_DEG for u in s.units)
    r = ring_configuration(8, 45.0)
    assert all(u.elevation_deg == 45.0 and u.photodiodes_deg == FOUR_ANGLES_DEG for u in r.units)


def test_unit_frames_are_rotations_with_axis_along_view():
    s = with_random_installation_errors(patent_configuration(), 1.0, np.random.default_rng(1))
    M = s.unit_matrices(False)
    np.testing.assert_allclose(np.linalg.det(M), 1.0, atol=1e-12)
    el = np.array([u.elevation_deg for u in s.units])
    az = np.array([u.azimuth_deg for u in s.units])
    np.testing.assert_allclose(M[:, :, 2], direction_vector(el, az), atol=1e-12)
    # the installation error moves each axis by exactly the norm of its pointing (x, y) part
    err = np.array([u.installation_error_deg for u in s.units])
    moved = angle_between_deg(s.view_directions_sensor(True), s.view_directions_sensor(False))
    np.testing.assert_allclose(moved, np.hypot(err[:, 0], err[:, 1]), atol=1e-4)  # 2nd order


def test_attitude_conventions():
    fwd = np.array([0.0, 1.0, 0.0])
    np.testing.assert_allclose(body_attitude(90.0).apply(fwd)[0], [1, 0, 0], atol=1e-12)  # east
    el, _ = elevation_azimuth(body_attitude(0.0, 10.0, 0.0).apply(fwd))
    assert el[0] == pytest.approx(10.0)                                       # nose up
    right = body_attitude(0.0, 0.0, 5.0).apply([1.0, 0.0, 0.0])[0]
    assert np.degrees(np.arcsin(-right[2])) == pytest.approx(5.0)             # right side down


def test_body_attitude_is_scipys_intrinsic_zxy_rotation(rng):
    """The closed-form quaternion of the body attitude against scipy's own Euler
    conversion (``Rotation.from_euler("ZXY", [-yaw, pitch, roll])``, an independent
    implementation), at random angles beyond a turn and at the half and quarter turns where
    the half angles' tangents are extreme: the matrices agree to 2e-15 (a few ulp of 1; the
    two round differently)."""
    from scipy.spatial.transform import Rotation
    yaw = np.r_[rng.uniform(-720.0, 720.0, 500), 180.0, -180.0, 360.0, 90.0, 0.0]
    pitch = np.r_[rng.uniform(-90.0, 90.0, 500), 90.0, -90.0, 0.0, 180.0, 0.0]
    roll = np.r_[rng.uniform(-360.0, 360.0, 500), 180.0, 0.0, -180.0, 270.0, 0.0]
    ref = Rotation.from_euler("ZXY", np.stack([-yaw, pitch, roll], axis=-1), degrees=True)
    np.testing.assert_allclose(body_attitude(yaw, pitch, roll).as_matrix(), ref.as_matrix(),
                               rtol=0, atol=2e-15)


@settings(max_examples=40, deadline=None)
@given(st.floats(0, 359.9), st.floats(-60, 60), st.floats(-60, 60))
def test_attitude_angles_invert_body_attitude(yaw, pitch, roll):
    y, p, r = attitude_angles(body_attitude(yaw, pitch, roll))
    assert abs((y[0] - yaw + 180) % 360 - 180) < 1e-8
    assert p[0] == pytest.approx(pitch, abs=1e-8) and r[0] == pytest.approx(roll, abs=1e-8)


def test_level_unit_sees_the_sky_in_its_enu_direction(rng):
    """Independent reference: level carrier, unit at body azimuth a looks at ENU azimuth yaw + a;
    its DoP and radiance must be the sky model's at that direction."""
    s = patent_configuration()
    n = 30
    sun = _sun(n, rng)
    yaw = rng.uniform(0, 360, n)
    obs = s.observe(SKY, body_attitude(yaw), sun)
    el = np.array([u.elevation_deg for u in s.units])
    az = np.mod(yaw[:, None] + [u.azimuth_deg for u in s.units], 360.0)
    sel, saz = elevation_azimuth(sun)
    ref = SKY.field(el, az, sel[:, None], saz[:, None])
    np.testing.assert_allclose(obs.dop, ref.dop, atol=1e-12)
    np.testing.assert_allclose(obs.radiance, ref.I, atol=1e-12)
    np.testing.assert_allclose(obs.view_elevation_deg, np.broadcast_to(el, (n, 9)), atol=1e-9)


def test_e_vectors_perpendicular_to_sun_and_actual_view(rng):
    """Single scattering: E is perpendicular to the sun and to the (erroneous) view direction."""
    s = with_random_installation_errors(patent_configuration(), 1.0, rng)
    n = 50
    sun = _sun(n, rng)
    att = body_attitude(rng.uniform(0, 360, n), rng.uniform(-15, 15, n), rng.uniform(-15, 15, n))
    obs = s.observe(SKY, att, sun)
    sun_s = (att * s.body_installation()).inv().apply(sun)
    np.testing.assert_allclose(np.einsum("nmi,ni->nm", obs.e_vector_sensor, sun_s), 0, atol=1e-12)
    view = s.view_directions_sensor(True)
    np.testing.assert_allclose(np.einsum("nmi,mi->nm", obs.e_vector_sensor, view), 0, atol=1e-12)


def test_unit_roll_error_shifts_the_measured_angle(rng):
    """A unit rotated by +d about its optical axis sees the E-vector at -d in its own frame."""
    base = CompoundEyeSensor((Unit(0.0, 90.0), Unit(30.0, 60.0)))
    turned = base.with_installation([0, 0, 0], [[0, 0, 0], [0, 0, 0.7]])
    sun, att = _sun(10, rng), body_attitude(rng.uniform(0, 360, 10))
    d = turned.observe(SKY, att, sun).aop_unit_deg - base.observe(SKY, att, sun).aop_unit_deg
    np.testing.assert_allclose(np.mod(d + 90, 180) - 90, [[0.0, -0.7]] * 10, atol=1e-9)


def test_photodiodes_follow_malus_and_invert(rng):
    """Readings of 4 and 6 photodiodes invert to the sky's AoP/DoP within the rounding to
    counts: 0.5 count on ~2e4 counts with d >= 0.1 is <= 0.5/(2e4 * 0.1) rad = 0.015 deg."""
    for angles in (FOUR_ANGLES_DEG, THREE_PAIR_ANGLES_DEG):
        s = CompoundEyeSensor((Unit(0.0, 90.0, angles), Unit(120.0, 45.0, angles)),
                              photodiode=PhotodiodeModel(noise_counts=0.0))
        obs = s.observe(SKY, body_attitude(rng.uniform(0, 360, 40)), _sun(40, rng))
        counts, names = s.photodiode_readings(obs, rng)
        assert names[:len(angles)] == [f"u0_p{int(a):03d}" for a in angles]
        k = len(angles)
        aop, dop = polarization_from_photodiodes(counts.reshape(40, 2, k), angles)
        ok = obs.dop > 0.1
        err = np.mod(aop - obs.aop_unit_deg + 90, 180) - 90
        assert np.abs(err[ok]).max() < 0.015
        np.testing.assert_allclose(dop[ok], obs.dop[ok], atol=1e-3)   # 0.5 count / 2e4 x 2


def test_stokes_from_differences_and_opponent_agree():
    """4 photodiodes: LSQ Stokes equals the difference formulas; three-pair: the opponent solve
    (solve_pair) and the Stokes solve agree on exact Malus readings."""
    chi, d = np.radians(np.linspace(-89, 89, 37)), 0.6
    a4 = np.radians(FOUR_ANGLES_DEG)
    P = 1 + d * np.cos(2 * (chi[:, None] - a4))
    aop, dop = polarization_from_photodiodes(P, FOUR_ANGLES_DEG)
    ref = 0.5 * np.degrees(np.arctan2(P[:, 1] - P[:, 3], P[:, 0] - P[:, 2]))
    np.testing.assert_allclose(aop, ref, atol=1e-9)
    np.testing.assert_allclose(dop, d, atol=1e-12)
    a6 = np.radians(THREE_PAIR_ANGLES_DEG)
    P6 = 1 + d * np.cos(2 * (chi[:, None] - a6))
    a_op, d_op = polarization_from_photodiodes(P6, THREE_PAIR_ANGLES_DEG, method="opponent")
    a_st, _ = polarization_from_photodiodes(P6, THREE_PAIR_ANGLES_DEG)
    np.testing.assert_allclose(a_op, np.degrees(chi), atol=1e-9)
    np.testing.assert_allclose(a_st, np.degrees(chi), atol=1e-9)
    np.testing.assert_allclose(d_op, d, atol=1e-12)
    with pytest.raises(ValueError, match="three-pair"):
        polarization_from_photodiodes(P, FOUR_ANGLES_DEG, method="opponent")


def test_units_below_horizon_are_rejected(rng):
    with pytest.raises(UnitBelowHorizonError, match="unit 1 elevation_deg=-5"):
        CompoundEyeSensor((Unit(0.0, 90.0), Unit(0.0, -5.0)))
    ring = ring_configuration(4, 20.0)
    with pytest.raises(UnitBelowHorizonError, match="unit 2 looks .* below the horizon"):
        ring.observe(SKY, body_attitude([0.0], [30.0], [0.0]), _sun(1, rng))   # nose up 30


def test_sample_records_reference_attitude_gravity_and_saturation(rng):
    s = patent_configuration(photodiode=PhotodiodeModel(counts_per_radiance=60_000.0))
    n = 200
    times = pd.date_range("2020-06-15T14:00+08:00", periods=n, freq="10s")
    yaw, pitch = rng.uniform(0, 360, n), rng.uniform(-10, 10, n)
    data = s.sample(SKY, SITE, times, yaw, pitch, 0.0, rng, attitude_noise_deg=0.1,
                    accel_noise_mps2=0.0)
    t = data.table
    dy = np.mod(t["yaw_deg"] - yaw + 180, 360) - 180
    assert 0.08 < np.std(dy) < 0.12                     # 0.1 deg reference noise, n = 200
    up = t[["accel_x_mps2", "accel_y_mps2", "accel_z_mps2"]].to_numpy()
    tilt = np.degrees(np.arccos(up[:, 2] / np.linalg.norm(up, axis=1)))
    np.testing.assert_allclose(tilt, np.abs(pitch), atol=1e-9)   # roll 0: tilt = |pitch|
    # 60,000 counts per unit radiance: any I (1 + d cos) > 1.09 saturates the 16-bit ADC; flagged
    assert data.flags.saturated.any()
    assert data.readings.max() == s.photodiode.saturation_value
    assert data.sidecar["generator"]["attitude_noise_deg"] == 0.1


def test_reproduce_compound_eye_cli(tmp_path, capsys):
    """`skysim reproduce compound-eye` end to end with 2 trials: table printed, files written,
    goal met (with 2 trials x 27 angles the RMS is a rough but sufficient check)."""
    import json

    from experiments.cli.main import main
    assert main(["reproduce", "compound-eye", "--trials", "2", "--seed", "7",
                 "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "phi_1 sensor-to-body, axis x" in printed and "goal ≤ 0.05: met" in printed
    for name in ("table.md", "installation_errors.csv", "attitude_errors.csv", "summary.json",
                 "calibration_data.parquet", "calibration_data.parquet.json",
                 "fig_recovered_vs_injected.png", "fig_heading_error_vs_yaw.png"):
        assert (tmp_path / name).exists(), name
    summary = json.loads((tmp_path / "summary.json").read_text())
    h = summary["heading_rms_deg"]
    assert h["compensated"] < 0.25 * h["uncompensated"]
