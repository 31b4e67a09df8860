"""Unit pointing calibrated on other sessions of a photodiode ring, and the clock it pins.

One session cannot tell a common offset of the units' elevations from a shift of the sun
(a clock error): both change the angle of polarization the units see almost alike, and the
per-sweep headings take up the sun's azimuth. Held at the pointing fitted on a session whose
clock is right, a +2 h clock error is found within the 10 min a navigator needs (the sun
moves about 0.25 deg of azimuth a minute).
"""

import json

import numpy as np
import pandas as pd
import pytest

from calibration.photodiode_diagnosis import (PointingCalibrationError, calibrated_pointing,
                                              diagnose_photodiodes)
from sensor.compound_eye import ring_configuration
from sensor.photodiodes_io import PhotodiodeData
from skysim.sky import RayleighSky
from test_photodiode_diagnosis import SITE

TILT_DEG = -4.0
"""Common elevation offset of the simulated ring's units (the reference ring's units sit
3-5.5 deg below their nominal 45 deg)."""


def tilted_session(start, seed=2):
    """A ring whose units look at 41 deg while its sidecar says 45 deg (3 turns)."""
    rng = np.random.default_rng(seed)
    sensor = ring_configuration(8, 45.0 + TILT_DEG)
    t0 = pd.Timestamp(start)
    times = pd.DatetimeIndex([t0 + pd.Timedelta(seconds=60 * s + 0.1 * k)
                              for s in range(3) for k in range(90)])
    yaw = np.tile(np.linspace(0.0, 360.0, 90, endpoint=False), 3) + 20.0
    data = sensor.sample(RayleighSky(0.6), SITE, times, yaw, 0.0, 0.0, rng,
                         yaw_reference="relative", yaw_offset_deg=35.0, include_truth=False,
                         sweep=np.repeat(np.arange(3), 90))
    side = json.loads(json.dumps(data.sidecar))
    for u in side["units"]:
        u["elevation_deg"] = 45.0
    return PhotodiodeData(data.table.drop(columns=["pitch_deg", "roll_deg"]), side)


@pytest.fixture(scope="module")
def calibration_report():
    """The diagnosis of a session with a right clock (another hour of the same day)."""
    return diagnose_photodiodes(tilted_session("2022-05-12T15:00:00+02:00"), ("yaw_scale",))


def test_calibrated_pointing_reads_the_fitted_tilt(calibration_report):
    """The units' fitted elevation offsets are the simulated tilt within 0.5 deg: the AoP
    pins a common elevation offset only as well as it pins the sun's elevation, a few tenths
    of a degree in three 9-s turns with the photodiodes' noise (0.3 deg measured, the same on
    every unit); 0.5 deg is 3 min of clock at a morning sun, well inside the 10 min asked of
    the clock below."""
    p = calibrated_pointing([calibration_report], n_units=8)
    np.testing.assert_allclose(p[:8], TILT_DEG, atol=0.5)
    np.testing.assert_allclose(p[8:], 0.0, atol=0.5)


@pytest.mark.slow
def test_clock_error_found_with_the_pointing_held(calibration_report):
    """A +2 h clock error (recorded times 2 h early) on a morning session: named, and fitted
    within 10 min once the pointing is held at the calibration."""
    data = tilted_session("2022-05-12T09:00:00+02:00")
    t = data.table.copy()
    t["time"] = t["time"] - pd.Timedelta(hours=2)
    wrong = PhotodiodeData(t, data.sidecar)
    pointing = calibrated_pointing([calibration_report])
    doc = diagnose_photodiodes(wrong, ("clock_offset",), pointing=pointing)
    assert doc["verdict"]["effect"] == "clock_offset"
    assert abs(doc["verdict"]["params"]["clock_offset_s"]["value"] - 7200.0) < 600.0
    assert doc["base_fit"]["pointing_held"] is True
    assert doc["base_fit"]["elevation_offset_mean_deg"] == pytest.approx(TILT_DEG, abs=0.5)


def test_units_never_calibrated_are_fitted():
    """A unit the screen excluded in every report is NaN (fitted), the others the median."""
    def report(el):
        return {"base_fit": {"elevation_offset_deg": {"u0": el, "u1": None},
                             "azimuth_offset_deg": {"u0": 1.0, "u1": None}}}
    p = calibrated_pointing([report(-3.0), report(-5.0), report(-4.5)])
    assert p[0] == pytest.approx(-4.5) and p[2] == pytest.approx(1.0)
    assert np.isnan(p[1]) and np.isnan(p[3])


def test_bad_calibrations_are_named(tmp_path, calibration_report):
    with pytest.raises(PointingCalibrationError, match="no diagnosis report"):
        calibrated_pointing([])
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(PointingCalibrationError, match="broken.json"):
        calibrated_pointing([broken])
    with pytest.raises(PointingCalibrationError, match="no fitted unit pointing"):
        calibrated_pointing([{"verdict": {}}])
    with pytest.raises(PointingCalibrationError, match="describe 8 units.*has 7"):
        calibrated_pointing([calibration_report], n_units=7)
    held = json.loads(json.dumps(calibration_report))
    held["base_fit"]["pointing_held"] = True
    with pytest.raises(PointingCalibrationError, match="held at a calibration"):
        calibrated_pointing([held])
    data = tilted_session("2022-05-12T15:00:00+02:00")
    with pytest.raises(PointingCalibrationError, match="16 angles"):
        diagnose_photodiodes(data, ("yaw_scale",), pointing=np.zeros(3))
    with pytest.raises(PointingCalibrationError, match="unit 2 is 25.0"):
        p = np.zeros(16)
        p[2] = 25.0
        diagnose_photodiodes(data, ("yaw_scale",), pointing=p)


def test_diagnose_command_holds_the_pointing(tmp_path, calibration_report):
    """``skysim diagnose --pointing-from`` reads the reports and says the pointing is held;
    on a measurement table it is refused with the reason."""
    from experiments.cli.main import main
    data = tilted_session("2022-05-12T15:00:00+02:00")
    path = tmp_path / "ring.csv"
    data.write(path)
    rep = tmp_path / "calib.json"
    rep.write_text(json.dumps(calibration_report))
    out = tmp_path / "out"
    assert main(["diagnose", str(path), "--effects", "yaw_scale", "--pointing-from", str(rep),
                 "--out", str(out)]) == 0
    doc = json.loads((out / "diagnosis.json").read_text())
    assert doc["extra"]["base_fit"]["pointing_held"] is True
