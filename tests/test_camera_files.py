"""Raw camera files (16-bit TIFF + skysim.dofp/1 sidecar) and the camera commands."""

import json

import numpy as np
import pytest

from experiments.cli.main import main

pytest.importorskip("tifffile", reason="camera images need the 'camera' extra (tifffile)")

from sensor.camera.files import (DofpFormatError, camera_from_sidecar, check_sidecar, read_raw,  # noqa: E402
                                 write_raw)


def _sidecar(width: int, height: int) -> dict:
    """A complete skysim.dofp/1 sidecar (without ``schema``) for a width x height mosaic."""
    return {"site": {"latitude_deg": 34.0, "longitude_deg": 108.0}, "attitude": {},
            "lens": {"focal_px": 2.0, "cx": 3.0, "cy": 2.0, "fov_deg": 180.0,
                     "model": "equidistant"},
            "exposure": {"exposure_s": 0.01}, "time": "2020-01-01T00:00Z",
            "sensor": {"width": width, "height": height, "layout_deg": [[90, 45], [135, 0]],
                       "full_well_e": 1e4, "read_noise_e": 2.0, "dark_current_e_s": 1.0,
                       "adc_bits": 12, "black_level_dn": 0}}


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
    doc = _sidecar(8, 4)
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


def test_png_round_trip_is_bit_exact(tmp_path):
    pytest.importorskip("cv2", reason="PNG camera images need the 'camera' extra (OpenCV)")
    # every 16-bit value, odd sizes and the extremes: the file holds the DN exactly
    raw = np.random.default_rng(2).integers(0, 2 ** 16, (6, 10), dtype=np.uint16)
    raw[0, :2] = (0, 65535)
    write_raw(tmp_path / "a.png", raw, _sidecar(10, 6))
    back, side = read_raw(tmp_path / "a.png")
    assert back.dtype == np.uint16 and np.array_equal(back, raw)
    assert side["schema"] == "skysim.dofp/1" and (tmp_path / "a.png.json").exists()
    # and a reader other than OpenCV sees the same 16-bit greyscale image
    pil = pytest.importorskip("PIL.Image")
    with pil.open(tmp_path / "a.png") as im:
        assert np.array_equal(np.asarray(im).astype(np.uint16), raw)


def test_camera_command_writes_png_like_tiff(tmp_path, capsys):
    pytest.importorskip("cv2", reason="PNG camera images need the 'camera' extra (OpenCV)")
    common = ["camera", "--lat", "34.2", "--lon", "108.9", "--time", "2013-05-22T15:00+08:00",
              "--yaw", "123", "--width", "64", "--height", "48", "--seed", "3"]
    assert main(common + ["--out", str(tmp_path / "s.png")]) == 0
    assert main(common + ["--out", str(tmp_path / "s.tiff")]) == 0
    png, doc_png = read_raw(tmp_path / "s.png")
    tif, doc_tif = read_raw(tmp_path / "s.tiff")
    assert np.array_equal(png, tif) and doc_png == doc_tif
    capsys.readouterr()
    assert main(["camera-heading", str(tmp_path / "s.png")]) == 0
    assert "recorded yaw 123.000 deg" in capsys.readouterr().out


@pytest.mark.parametrize("flip", ["none", "horizontal", "vertical"])
@pytest.mark.parametrize("rotate", [0, 90, 180, 270])
def test_flipped_or_rotated_readout_is_undone(tmp_path, capsys, flip, rotate):
    """A frame recorded flipped and then rotated (as a camera's readout or mount would) reads
    back as the physical image, and its heading is the physical one."""
    from sensor.camera.files import undo_readout
    phys = tmp_path / "p.tiff"
    assert main(["camera", "--lat", "34.2", "--lon", "108.9", "--time",
                 "2013-05-22T15:00+08:00", "--yaw", "70", "--width", "64", "--height", "48",
                 "--seed", "4", "--out", str(phys)]) == 0
    raw, doc = read_raw(phys)
    rec = {"none": raw, "horizontal": raw[:, ::-1], "vertical": raw[::-1]}[flip]
    rec = np.rot90(rec, rotate // 90)
    np.testing.assert_array_equal(undo_readout(rec, flip, rotate), raw)
    write_raw(tmp_path / "r.tiff", np.ascontiguousarray(rec), doc)
    back, _ = read_raw(tmp_path / "r.tiff", flip=flip, rotate_deg=rotate)
    np.testing.assert_array_equal(back, raw)
    capsys.readouterr()
    assert main(["camera-heading", str(tmp_path / "r.tiff"), "--flip", flip, "--rotate",
                 str(rotate)]) == 0
    out = capsys.readouterr().out
    assert abs(float(out.split("error ")[1].split()[0])) < 0.5  # 64x48 px, noisy: ~0.05 deg


def test_readout_options_are_checked():
    from sensor.camera.files import FLIPS, ROTATIONS_DEG, undo_readout
    with pytest.raises(ValueError, match="none, horizontal, vertical; got 'mirror'"):
        undo_readout(np.zeros((2, 2)), "mirror")
    with pytest.raises(ValueError, match="0, 90, 180, 270; got 45"):
        undo_readout(np.zeros((2, 2)), rotate_deg=45)
    # the command line's literals are the module's
    from experiments.cli.main import build_parser
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    opts = {a.dest: a.choices for a in sub.choices["camera-heading"]._actions}
    assert tuple(opts["flip"]) == FLIPS and tuple(opts["rotate"]) == ROTATIONS_DEG


def test_large_frames_are_refused_before_the_work(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SKYSIM_MEMORY_LIMIT_MB", "100")
    out = tmp_path / "big.tiff"
    assert main(["camera", "--lat", "34", "--lon", "108", "--time", "2013-05-22T15:00+08:00",
                 "--width", "2448", "--height", "2048", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "2448x2048 camera image" in err and "--width/--height" in err
    assert not out.exists()


@pytest.mark.parametrize("edit", [
    lambda d: d["sensor"].pop("height"),
    lambda d: d["lens"].pop("focal_px"),
    lambda d: d["lens"].update(focal_px="wide"),
    lambda d: d["sensor"].update(width=512.5),
    lambda d: d["exposure"].pop("exposure_s"),
    lambda d: d["site"].update(latitude_deg=None),
    lambda d: d.update(lens=[1, 2]),
])
def test_incomplete_sidecar_names_the_key(tmp_path, edit):
    """A sidecar lacking a nested key, or holding a value of the wrong kind, is a
    DofpFormatError naming the section and key (was a KeyError: an internal error)."""
    out = tmp_path / "sky.tiff"
    assert main(["camera", "--lat", "34.14", "--lon", "108.55", "--time",
                 "2013-05-22T17:10+08:00", "--width", "64", "--height", "64",
                 "--out", str(out)]) == 0
    side = next(p for p in tmp_path.iterdir() if p.suffix == ".json")
    doc = json.loads(side.read_text())
    edit(doc)
    side.write_text(json.dumps(doc))
    with pytest.raises(DofpFormatError) as err:   # the reader's check, or the full one
        check_sidecar(read_raw(out)[1], side)
    assert side.name in str(err.value)
    assert main(["camera-heading", str(out)]) == 2
