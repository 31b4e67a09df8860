"""Polarization-camera benchmarks (run with `make bench`; disabled in `make test`).

Goals reported (never asserted as timings): a 2448 x 2048 raw image from a Rayleigh sky with
every camera effect (per-pixel angle error, extinction ratio, PRNU, vignetting, sun disk,
shot/read/dark noise, ADC) in <= 0.5 s, i.e. >= 1e7 pixels/s; the heading from it (demosaicing
and fit) in <= 0.5 s. Floor measured in the same run: one ``np.cos`` over the image's pixels.
"""

import numpy as np
import pytest

from calibration.camera_heading import heading_from_image
from sensor.camera import PolarizationCamera, camera_attitude, camera_stokes
from skysim.sky import RayleighSky

W, H = 2448, 2048
GOAL = {"min_items_per_s": W * H / 0.5}


@pytest.fixture(scope="module")
def camera():
    cam = PolarizationCamera.fisheye(W, H)
    sensor = cam.sensor.with_random_errors(np.random.default_rng(0), angle_std_deg=1.0,
                                           extinction_ratio=30.0,
                                           extinction_ratio_rel_std=0.2, gain_std=0.02)
    cam = PolarizationCamera(cam.lens, sensor, cam.photoelectrons_per_s, 1.5 * cam.lens.focal_px)
    cam.scene(RayleighSky(0.7), camera_attitude(0.0), 40.0, 120.0)  # camera-fixed caches
    return cam


@pytest.fixture(scope="module")
def image(camera):
    scene = camera.scene(RayleighSky(0.7), camera_attitude(30.0), 40.0, 120.0)
    return scene, camera.capture(scene, 0.02, np.random.default_rng(1))


@pytest.mark.benchmark(group="camera image 2448x2048")
def test_floor_one_cos_per_pixel(benchmark):
    x = np.linspace(0.0, 1.0, W * H)
    benchmark.extra_info.update(items=W * H, floor=True)
    benchmark(np.cos, x)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.benchmark(group="camera image 2448x2048")
def test_raw_image_all_effects(benchmark, camera, dtype):
    sky = RayleighSky(0.7, dtype=dtype)
    att = camera_attitude(30.0)
    rng = np.random.default_rng(2)
    benchmark.extra_info.update(items=W * H, goal=GOAL)
    raw = benchmark.pedantic(lambda: camera.capture(camera.scene(sky, att, 40.0, 120.0), 0.02,
                                                    rng), rounds=3, iterations=1)
    assert raw.shape == (H, W)


@pytest.mark.parametrize("method", ["superpixel", "bilinear"])
@pytest.mark.benchmark(group="camera heading 2448x2048")
def test_heading_from_image(benchmark, camera, image, method):
    scene, raw = image
    benchmark.extra_info.update(items=W * H, goal=GOAL)

    def heading():
        st = camera_stokes(camera, raw, 0.02, valid=scene.valid, method=method)
        return heading_from_image(st, camera.lens, 40.0, 120.0)

    h = benchmark.pedantic(heading, rounds=2, iterations=1)
    assert abs((h.heading_deg - 30.0 + 180) % 360 - 180) < 0.1  # random errors only: no bias
