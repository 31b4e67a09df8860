"""Raw camera files (16-bit TIFF + skysim.dofp/1 sidecar) and the camera commands."""

import json

import numpy as np
import pytest

from experiments.cli import main

pytest.importorskip("tifffile", reason="camera images need the 'camera' extra (tifffile)")

from sensor.camera.files import (DofpFormatError, camera_from_sidecar, read_raw,  # noqa: E402
                                 write_raw)


def test_camera_then_heading_round_trip(tmp_path, capsys):
    out = tmp_path / "sky.tiff"
    assert main(["camera", "--lat", "34.2", "--lon", "108.9", "--time",
                 "2013-05-22T15:00+08:00", "--yaw", "217", "--pitch", "3", "--roll", "-4",
                 "--width", "128", "--height", "96", "--lens", "equisolid", "--seed", "5",
                 "--out", str(out), "--figure", str(tmp_path / "f.png")]) == 0
    raw, doc = read_raw(out)
    assert raw.dtype == np.uint16 and raw.shape == (96, 128) and raw.max() <= 4095
    assert doc["schema"] == "skysim.dofp/1" and doc["lens"]["model"] == "equisolid"
    assert (tmp_path / "f.png").stat().st_size > 10_000
    cam = camera_from_sidecar(doc)
    assert cam.lens.focal_px == pytest.approx(doc["lens"]["focal_px"])
    capsys.readouterr()
    assert main(["camera-heading", str(out)]) == 0
    text = capsys.readouterr().out
    err = float(text.split("error ")[1].split()[0])
    sigma = float(text.split("± ")[1].split()[0])
    assert abs(err) < 5 * sigma + 0.01  # the noise, plus interpolation error (< 0.01 deg)


def test_sidecar_is_strict_json(tmp_path):
    out = tmp_path / "e.tiff"
    assert main(["camera", "--lat", "34.2", "--lon", "108.9", "--time",
                 "2013-05-22T15:00+08:00", "--width", "32", "--height", "32",
                 "--angle-error-std", "0.5", "--crosstalk", "0.02", "--out", str(out)]) == 0
    text = (tmp_path / "e.tiff.json").read_text()
    doc = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON {c}"))
    assert doc["sensor"]["errors"]["extinction_ratio"] is None
    assert doc["sensor"]["errors"]["angle_std_deg"] == 0.5
    assert doc["sensor"]["crosstalk"] == 0.02


def test_writer_is_atomic_and_reader_checks(tmp_path):
    raw = np.zeros((4, 6), np.uint16)
    with pytest.raises(DofpFormatError, match="lacks"):
        write_raw(tmp_path / "a.tiff", raw, {"site": {}})
    assert not list(tmp_path.iterdir())  # nothing half-written
    with pytest.raises(DofpFormatError, match="uint16"):
        write_raw(tmp_path / "a.tiff", raw.astype(float), {})
    doc = {k: {} for k in ("site", "attitude", "lens", "exposure")}
    doc.update(time="2020-01-01T00:00Z", sensor={"width": 8, "height": 4})
    write_raw(tmp_path / "a.tiff", raw, doc)
    with pytest.raises(DofpFormatError, match="sidecar says"):
        read_raw(tmp_path / "a.tiff")
    side = tmp_path / "a.tiff.json"
    side.write_text(json.dumps({**doc, "schema": "other/1"}))
    with pytest.raises(DofpFormatError, match="schema"):
        read_raw(tmp_path / "a.tiff")
    side.unlink()
    with pytest.raises(DofpFormatError, match="no sidecar"):
        read_raw(tmp_path / "a.tiff")


def test_camera_command_errors(tmp_path, capsys):
    assert main(["camera", "--lat", "34", "--lon", "108", "--time", "2013-05-22T23:00+08:00",
                 "--out", str(tmp_path / "x.tiff")]) == 2  # night
    assert "sun" in capsys.readouterr().err.lower()
    assert main(["camera", "--lat", "34", "--lon", "108", "--time", "2013-05-22T12:00",
                 "--out", str(tmp_path / "x.tiff")]) == 2  # naive time
    assert "UTC offset" in capsys.readouterr().err
    assert main(["camera", "--lat", "34", "--lon", "108", "--time", "2013-05-22T12:00+08:00",
                 "--width", "31", "--out", str(tmp_path / "x.tiff")]) == 2
    assert "even" in capsys.readouterr().err
