"""Flat-field calibration of the polarization camera (Powell & Gruev 2013)."""

import numpy as np
import pytest

from calibration.camera_heading import heading_from_image
from calibration.dofp_calibration import calibrate_dofp, calibration_design
from calibration.exceptions import RankDeficientError, TooFewSamplesError
from sensor.camera import PolarizationCamera, camera_attitude, demosaic
from skysim.geometry import wrap_axial_deg, wrap_deg
from skysim.sky import RayleighSky

ANGLES = np.array([0.0, 30.0, 60.0, 90.0, 120.0, 150.0])


def _faulty_camera(n=64, seed=4):
    cam = PolarizationCamera.fisheye(n, n, exit_pupil_px=150.0)
    sensor = cam.sensor.with_random_errors(np.random.default_rng(seed), angle_std_deg=1.0,
                                           mosaic_rotation_deg=2.0, extinction_ratio=30.0,
                                           extinction_ratio_rel_std=0.2, gain_std=0.03)
    return PolarizationCamera(cam.lens, sensor, cam.photoelectrons_per_s, cam.exit_pupil_px)


def test_calibration_round_trip_within_noise():
    """Recovered analysis vectors and dark offsets minus the true ones, divided by the
    standard error predicted from the noise model (shot + read + quantisation per frame,
    propagated through the least-squares solve): mean 0 and standard deviation 1. Over ~3000
    pixels per parameter the sample standard deviation is known to 1.3 %; 8 % allows for the
    quantisation's departure from a uniform error at read noise ~1 DN."""
    cam = _faulty_camera()
    s = cam.sensor
    t = 0.6 * s.full_well_e / cam.photoelectrons_per_s
    n_frames = 8
    flats, dark = cam.calibration_frames(ANGLES, 1.0, t, n_frames, np.random.default_rng(9))
    cal = calibrate_dofp(flats, dark, ANGLES, saturation_dn=s.max_dn)
    inside = cam.pixel_directions[1]
    true = np.concatenate([cam.analysis_dn(t), (s.black_level_dn + s.dark_current_e_s * t
                                                / s.e_per_dn) * np.ones(s.shape)[..., None]],
                          -1)[inside]
    est = np.concatenate([cal.analysis_dn, cal.dark_dn[..., None]], -1)[inside]
    # per-frame variance [DN^2] of each source's reading, then through pinv(X)
    x = calibration_design(ANGLES)
    mean_e = np.stack([cam.expected_electrons(cam.uniform_scene(
        (1.0, np.cos(np.radians(2 * a)), np.sin(np.radians(2 * a)))), t) for a in ANGLES]
        + [cam.expected_electrons(cam.uniform_scene((0, 0, 0)), t)])[:, inside]
    var = ((mean_e + s.read_noise_e ** 2) / s.e_per_dn ** 2 + 1 / 12) / n_frames
    p = np.linalg.pinv(x)
    sigma = np.sqrt(np.einsum("jk,kn->nj", p ** 2, var))
    z = (est - true) / sigma
    assert np.all(np.abs(z.mean(0)) < 0.1)
    np.testing.assert_allclose(z.std(0), 1.0, atol=0.08)
    # the injected errors are what the calibration sees: mosaic rotation within 0.05 deg
    nominal = cam.sensor.nominal_angle_deg()[inside]
    got = wrap_axial_deg(cal.angle_deg[inside] - nominal)
    assert np.median(got) == pytest.approx(2.0, abs=0.05)


def test_heading_before_and_after_calibration():
    # a 2 deg mosaic rotation, 1 deg per-pixel angle errors, ER 30 +- 20 %, 3 % PRNU,
    # vignetting: the nominal model's heading is off by about the rotation, the calibrated one
    # within 4 sigma of the truth
    cam = _faulty_camera(128, seed=6)
    s = cam.sensor
    t_cal = 0.6 * s.full_well_e / cam.photoelectrons_per_s
    flats, dark = cam.calibration_frames(ANGLES, 1.0, t_cal, 8, np.random.default_rng(1))
    cal = calibrate_dofp(flats, dark, ANGLES, saturation_dn=s.max_dn)
    yaw, sun_el, sun_az = 75.0, 40.0, 210.0
    sc = cam.scene(RayleighSky(0.7), camera_attitude(yaw), sun_el, sun_az)
    raw = cam.capture(sc, t_cal, np.random.default_rng(2))  # the calibration's exposure
    before = demosaic(raw, cam.analysis_dn(t_cal, ideal=True), black_level_dn=cal.dark_dn,
                      valid=sc.valid, saturation_dn=s.max_dn)
    after = demosaic(raw, cal.analysis_dn, black_level_dn=cal.dark_dn, valid=sc.valid,
                     saturation_dn=s.max_dn)
    h0 = heading_from_image(before, cam.lens, sun_el, sun_az)
    h1 = heading_from_image(after, cam.lens, sun_el, sun_az)
    e0, e1 = abs(wrap_deg(h0.heading_deg - yaw)), abs(wrap_deg(h1.heading_deg - yaw))
    assert 1.0 < e0 < 3.0
    assert e1 < 4 * h1.sigma_deg and e1 < 0.1 * e0


def test_calibration_input_errors():
    flats = np.zeros((2, 4, 4))
    with pytest.raises(TooFewSamplesError, match="3 polarizer angles"):
        calibrate_dofp(flats, np.zeros((4, 4)), [0.0, 90.0])
    with pytest.raises(RankDeficientError, match="distinct"):
        calibrate_dofp(np.zeros((3, 4, 4)), np.zeros((4, 4)), [0.0, 180.0, 90.0])
