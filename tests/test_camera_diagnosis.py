"""Blind checks of the camera-image diagnosis (calibration.diagnosis.camera).

Each frame is simulated by the camera simulator (:class:`sensor.camera.PolarizationCamera`)
with an effect injected through the simulator's own parameters (a shifted lens, per-pixel
polarizer-angle errors, a finite extinction ratio); the sidecar describes the *nominal*
camera, as a user's sidecar would. The diagnosis is not told which effect was injected.
"""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from calibration import diagnosis
from calibration.diagnosis.camera import CameraFrame, CameraFrames, CameraInputError
from calibration.diagnosis.report import DiagnosisReport
from calibration.effects import UnknownEffectError
from sensor.camera import MosaicSensor, PolarizationCamera, camera_attitude
from sensor.camera.lens import FisheyeLens
from skysim.sky import make_sky
from skysim.sun import sun_position

SIZE = 128
DMAX = 0.7
SITE = {"latitude_deg": 34.25, "longitude_deg": 108.9, "altitude_m": 400.0}
TIME = dt.datetime(2024, 5, 22, 2, 30, tzinfo=dt.timezone.utc)   # sun about 55 deg high


def _frame(seed, *, lens_shift=(0.0, 0.0, 1.0), angle_offsets=None, extinction_ratio=np.inf,
           yaw=30.0, time=TIME):
    """A raw frame of the simulator with the given injected errors, and the nominal sidecar."""
    nominal = PolarizationCamera.fisheye(SIZE, SIZE)
    lens = FisheyeLens(nominal.lens.focal_px * lens_shift[2], nominal.lens.cx + lens_shift[0],
                       nominal.lens.cy + lens_shift[1], nominal.lens.fov_deg)
    kw = {"extinction_ratio": extinction_ratio}
    if angle_offsets is not None:
        kw["angle_error_deg"] = np.tile(np.reshape(angle_offsets, (2, 2)), (SIZE // 2,
                                                                            SIZE // 2))
    true = PolarizationCamera(lens, MosaicSensor(SIZE, SIZE, **kw))
    sun = sun_position([time], SITE["latitude_deg"], SITE["longitude_deg"],
                       SITE["altitude_m"]).iloc[0]
    sky = make_sky("rayleigh", dmax=DMAX)
    scene = true.scene(sky, camera_attitude(yaw), float(sun["elevation_deg"]),
                       float(sun["azimuth_deg"]))
    exposure = true.auto_exposure_s(scene)
    raw = true.capture(scene, exposure, np.random.default_rng(seed))
    doc = {"schema": "skysim.dofp/1", "site": SITE, "time": time.isoformat(),
           "attitude": {"yaw_deg": yaw, "pitch_deg": 0.0, "roll_deg": 0.0, "yaw_known": True},
           **nominal.describe(), "exposure": {"exposure_s": exposure},
           "generator": {"sky": sky.describe(), "seed": seed}}
    return CameraFrame(raw, doc, name=f"seed {seed}")


def test_clean_frame_is_none():
    rep = diagnosis.diagnose(_frame(1), seed=0)
    print(rep.to_markdown())
    assert rep.verdict.effect == "none"
