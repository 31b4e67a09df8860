"""The camera's image is laid out as a real sensor records it: checked against OpenCV's fisheye
model, against a photograph of the sky built here without skysim's camera frames, and at the
level of the raw mosaic (which polarizer reads most where)."""

import numpy as np
import pytest

from calibration.camera_heading import heading_from_image
from sensor.camera import FisheyeLens, PolarizationCamera, camera_attitude, camera_stokes
from skysim.sky import RayleighSky
from test_camera import random_rays

# Kannala-Brandt polynomial theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8) equal to the
# equisolid 2 sin(theta / 2) up to theta^9: the Taylor coefficients -1/24, 1/1920,
# -1/322560, 1/92897280 of 2 sin(theta / 2) / theta
_EQUISOLID_KB = np.array([-1 / 24, 1 / 1920, -1 / 322560, 1 / 92897280])


@pytest.mark.parametrize("model", ["equidistant", "equisolid"])
def test_projection_equals_opencv_fisheye(model):
    """The same rays through OpenCV's fisheye model (``cv2.fisheye.projectPoints``, identity
    pose) land on the same pixel. OpenCV's model projects only rays in front of the camera,
    so theta < 88 deg here. Tolerance 1e-6 px: the equidistant model is OpenCV's with D = 0
    (float64 rounding, ~1e-13 px); for equisolid the Kannala-Brandt series stops at theta^9,
    the first term left out being theta^11 / (2^10 11!) <= 2.2e-9 rad at 88 deg, 2e-7 px at
    this focal length."""
    cv2 = pytest.importorskip("cv2")
    lens = FisheyeLens(focal_px=83.7, cx=63.2, cy=61.9, fov_deg=180.0, model=model)
    d = random_rays(2000, 88.0, seed=4)
    row, col = lens.project(d)
    k = np.array([[lens.focal_px, 0.0, lens.cx], [0.0, lens.focal_px, lens.cy], [0, 0, 1.0]])
    dist = np.zeros(4) if model == "equidistant" else _EQUISOLID_KB
    uv, _ = cv2.fisheye.projectPoints(d.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k, dist)
    np.testing.assert_allclose(col, uv[:, 0, 0], atol=1e-6, rtol=0)
    np.testing.assert_allclose(row, uv[:, 0, 1], atol=1e-6, rtol=0)


def _photograph(shape, focal_px, yaw_deg, sun_el, sun_az, dmax):
    """Rayleigh sky as a level, upward-looking equidistant fisheye camera photographs it, built
    from what one sees looking up (no skysim frames): the image's top at azimuth ``yaw``,
    azimuth increasing counter-clockwise in the displayed image (north up, east left), zenith
    at the centre. Returns the pixels' intensity ``I = 1 + cos^2 gamma``, DoLP and AoLP
    counter-clockwise from the image's right [rad], and the in-circle mask."""
    h, w = shape
    cy, cx = 0.5 * (h - 1), 0.5 * (w - 1)
    rows, cols = np.indices(shape, dtype=float)
    right, up = cols - cx, cy - rows
    rho = np.hypot(right, up)
    zen = rho / focal_px
    az = np.radians(yaw_deg) + np.arctan2(-right, up)  # left of the top is clockwise on the sky
    v = np.stack([np.sin(zen) * np.sin(az), np.sin(zen) * np.cos(az), np.cos(zen)], -1)
    el_s, az_s = np.radians(sun_el), np.radians(sun_az)
    s = np.array([np.cos(el_s) * np.sin(az_s), np.cos(el_s) * np.cos(az_s), np.sin(el_s)])
    cos_g = v @ s
    e = np.cross(v, s)  # single-scattering E-vector
    # local basis on the sky: e_el towards the zenith, e_az towards increasing azimuth
    e_el = np.stack([-np.cos(zen) * np.sin(az), -np.cos(zen) * np.cos(az), np.sin(zen)], -1)
    e_az = np.stack([np.cos(az), -np.sin(az), np.zeros_like(az)], -1)
    # seen from below, e_el points to the image centre and e_az counter-clockwise
    with np.errstate(invalid="ignore", divide="ignore"):
        radial = np.stack([right, up], -1) / rho[..., None]
    ccw = np.stack([-radial[..., 1], radial[..., 0]], -1)
    img = (-np.sum(e * e_el, -1))[..., None] * radial + np.sum(e * e_az, -1)[..., None] * ccw
    aolp = np.arctan2(img[..., 1], img[..., 0])
    intensity = 1.0 + cos_g ** 2
    dolp = dmax * (1.0 - cos_g ** 2) / intensity
    return intensity, dolp, aolp, (zen < np.pi / 2) & (rho > 0)


def _mosaic(intensity, dolp, aolp, layout_deg):
    """Ideal polarizers at the layout's angles (counter-clockwise in the displayed image):
    Malus's law ``I / 2 (1 + p cos 2(chi - a))``."""
    h, w = intensity.shape
    a = np.radians(np.tile(np.asarray(layout_deg, float), (h // 2, w // 2)))
    return 0.5 * intensity * (1.0 + dolp * np.cos(2.0 * (aolp - a)))


def test_scene_equals_a_photograph_of_the_sky():
    """Every pixel's camera Stokes equal those of the photograph built from what one sees
    looking up (float64 arithmetic of two different formulations: 1e-12)."""
    cam = PolarizationCamera.fisheye(96, 80)
    for yaw, sun in ((0.0, (30.0, 90.0)), (37.0, (55.0, 200.0)), (300.0, (5.0, 10.0))):
        sc = cam.scene(RayleighSky(0.7), camera_attitude(yaw), *sun)
        i, p, chi, ok = _photograph(cam.sensor.shape, cam.lens.focal_px, yaw, *sun, 0.7)
        ok &= sc.valid & ~sc.sun
        scale = sc.I[ok] / i[ok]  # the sky model's radiance unit
        np.testing.assert_allclose(scale, scale[0], rtol=1e-12)
        np.testing.assert_allclose(sc.Q[ok] / scale, (i * p * np.cos(2 * chi))[ok], atol=1e-12)
        np.testing.assert_allclose(sc.U[ok] / scale, (i * p * np.sin(2 * chi))[ok], atol=1e-12)


def test_sun_due_east_is_on_the_left_of_a_north_up_frame():
    """Level camera, image top north, sun due east at 30 deg: the saturated sun disk of the raw
    frame lies on the image's left, on the horizontal through the centre, at the
    equidistant radius f * 60 deg."""
    cam = PolarizationCamera.fisheye(128, 128)
    sc = cam.scene(RayleighSky(0.7), camera_attitude(0.0), 30.0, 90.0)
    raw = cam.capture(sc, cam.auto_exposure_s(sc), np.random.default_rng(1))
    rows, cols = np.nonzero(raw == cam.sensor.max_dn)
    assert rows.size >= 1
    # the disk (0.27 deg plus half a pixel, 1.4 deg per pixel) covers a pixel or two
    assert np.abs(cols.mean() - (cam.lens.cx - cam.lens.focal_px * np.pi / 3)) < 1.0
    assert np.abs(rows.mean() - cam.lens.cy) < 1.0


def test_45_degree_pixels_read_most_at_the_zenith_with_the_sun_north_east():
    """Sun at azimuth 45 deg: the zenith's E-vector runs north-west to south-east, which in a
    north-up frame (east left) is the image's bottom-left to top-right diagonal, the direction
    of the IMX250MZR's 45 deg polarizers (the top-right pixel of each super-pixel). Around
    the centre those read most and the 135 deg pixels (bottom left) least, in the raw DN."""
    cam = PolarizationCamera.fisheye(64, 64, read_noise_e=0.0, dark_current_e_s=0.0)
    sc = cam.scene(RayleighSky(0.7), camera_attitude(0.0), 40.0, 45.0)
    e = cam.expected_electrons(sc, 1e-3)
    block = e[30:34, 30:34].reshape(2, 2, 2, 2).mean(axis=(0, 2))  # (row in cell, col in cell)
    assert cam.sensor.layout_deg == ((90.0, 45.0), (135.0, 0.0))
    assert block[0, 1] == block.max() and block[1, 0] == block.min()
    assert block[0, 1] > 1.5 * block[1, 0]


@pytest.mark.parametrize("yaw", [0.0, 73.0, 250.0])
def test_heading_of_a_photograph_of_the_sky(yaw):
    """The heading decoded from the mosaic of the photograph (built without skysim's camera
    chain, Sony's layout) is the photograph's yaw. Noise-free: the error is the centred
    demosaicing's, < 0.011 deg on 128 px (calibration.camera_heading.DEFAULT_DEMOSAIC); a
    mirrored frame would give 2 * 135 - yaw - 180, an off-by-180 one yaw + 180."""
    cam = PolarizationCamera.fisheye(128, 128, read_noise_e=0.0, dark_current_e_s=0.0)
    sun = (40.0, 135.0)
    i, p, chi, ok = _photograph(cam.sensor.shape, cam.lens.focal_px, yaw, *sun, 0.7)
    t = 1e-3
    scale = cam.photoelectrons_per_s * t / cam.sensor.e_per_dn * 0.05
    raw = cam.sensor.black_level_dn + scale * np.where(ok, _mosaic(i, p, chi,
                                                                   cam.sensor.layout_deg), 0.0)
    st = camera_stokes(cam, raw, t, valid=ok, method="centred")
    h = heading_from_image(st, cam.lens, *sun)
    assert abs((h.heading_deg - yaw + 180.0) % 360.0 - 180.0) < 0.011
