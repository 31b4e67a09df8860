"""Partly cloudy skies: the cost of a camera frame under broken clouds beside a clear one (run
with `make bench`; disabled in `make test`).

One 256 x 256 DoFP frame (scene, shot/read noise, ADC) of a single-scattering sky, clear
(float32 render, the baseline) and behind clouds of cover 0.5 and optical thickness 10
(:class:`skysim.partly_cloudy.PartlyCloudySky`: two evaluations of the cloud field, 256
random modes, per sky pixel, plus the cloud's light), and the cloud field alone on the same
directions. Goal reported (never asserted): a cloudy frame in <= 1 s. The cloud field's cover
threshold and the camera's pixel planes are computed before the timed rounds (once per field
and camera).
"""

import numpy as np
import pytest

from sensor.camera import PolarizationCamera, camera_attitude
from skysim.cloud_field import CloudField
from skysim.partly_cloudy import PartlyCloudySky
from skysim.sky import RayleighSky

N = 256
SUN = (40.0, 120.0)


@pytest.fixture(scope="module")
def camera():
    cam = PolarizationCamera.fisheye(N, N)
    cam.scene(RayleighSky(0.7, dtype="float32"), camera_attitude(0.0), *SUN)
    return cam


@pytest.fixture(scope="module")
def cloudy():
    sky = PartlyCloudySky(RayleighSky(0.7), CloudField(0.5, 10.0, 1))
    sky.field(90.0, 0.0, *SUN)      # the cover threshold (once per field)
    return sky


def _frame(cam, sky):
    scene = cam.scene(sky, camera_attitude(30.0), *SUN)
    return cam.capture(scene, cam.auto_exposure_s(scene), np.random.default_rng(0))


@pytest.mark.benchmark(group=f"camera frame {N}x{N}")
def test_clear_frame(benchmark, camera):
    benchmark.extra_info.update(items=N * N, baseline=True)
    benchmark(_frame, camera, RayleighSky(0.7, dtype="float32"))


@pytest.mark.benchmark(group=f"camera frame {N}x{N}")
def test_partly_cloudy_frame(benchmark, camera, cloudy):
    benchmark.extra_info.update(items=N * N, goal={"max_s": 1.0})
    raw = benchmark(_frame, camera, cloudy)
    assert raw.shape == (N, N)


@pytest.mark.benchmark(group=f"camera frame {N}x{N}")
def test_cloud_field_alone(benchmark, camera, cloudy):
    d, inside = camera.pixel_directions
    d = d[inside]
    el = np.degrees(np.arcsin(np.clip(d[:, 2], 0.0, 1.0)))
    az = np.degrees(np.arctan2(d[:, 0], d[:, 1])) % 360.0
    benchmark.extra_info.update(items=N * N)
    tau = benchmark(cloudy.clouds.optical_thickness, el, az)
    assert 0.3 < np.mean(tau > 0) < 0.7
