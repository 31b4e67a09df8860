"""Raw camera files (16-bit TIFF + skysim.dofp/1 sidecar) and the camera commands."""

import json
import re

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


@pytest.fixture(scope="module")
def camera_png(tmp_path_factory):
    """A small simulated PNG frame and its sidecar (bytes), made once for the module."""
    pytest.importorskip("cv2", reason="PNG camera images need the 'camera' extra (OpenCV)")
    out = tmp_path_factory.mktemp("camera") / "sky.png"
    assert main(["camera", "--lat", "34.14", "--lon", "108.55", "--time",
                 "2013-05-22T10:00+08:00", "--width", "64", "--height", "64",
                 "--out", str(out)]) == 0
    return out.read_bytes(), json.loads(out.with_name("sky.png.json").read_text())


@pytest.mark.parametrize("edit,named", [
    (lambda d: d.update(time="2013-05-22T10:00:00"), "time '2013-05-22T10:00:00' has no UTC"),
    (lambda d: d.update(time="yesterday"), "time 'yesterday' is not a time"),
    (lambda d: d.update(time=5), "time must be text; got 5"),
    (lambda d: d.update(time="1500-01-01T00:00+00:00"), "outside the supported years"),
    (lambda d: d["attitude"].update(pitch_deg="level"),
     "attitude.pitch_deg must be a finite number; got 'level'"),
    (lambda d: d["attitude"].update(yaw_deg=None), "attitude.yaw_deg must be a finite number"),
    (lambda d: d["attitude"].update(yaw_known="yes"), "attitude.yaw_known must be true or false"),
    (lambda d: d["attitude"].pop("yaw_deg"), "attitude.yaw_known is true but attitude.yaw_deg"),
    (lambda d: d["site"].update(altitude_m="high"), "site.altitude_m must be a finite number"),
    (lambda d: d["site"].update(latitude_deg=95), "site: latitude_deg must lie in"),
    (lambda d: d["lens"].update(model="pinhole"), "lens: lens model must be one of"),
    (lambda d: d["sensor"].update(layout_deg=[1, 2]), "sensor.layout_deg must be a 2x2 list"),
    (lambda d: d["sensor"].update(exit_pupil_px="x"), "sensor.exit_pupil_px must be a finite"),
    (lambda d: d["sensor"].update(adc_bits=40), "sensor: adc_bits must be an integer in [8, 16]"),
    (lambda d: d["exposure"].update(exposure_s=-1), "exposure.exposure_s must be > 0"),
    (lambda d: d.pop("time"), "lacks time"),
])
def test_every_sidecar_field_is_checked_by_name(tmp_path, capsys, camera_png, edit, named):
    """A sidecar field of the wrong kind or out of range is one line naming the file and the
    field (exit 2), never an internal error of a later step."""
    data, doc = camera_png
    doc = json.loads(json.dumps(doc))
    edit(doc)
    image = tmp_path / "frame.png"
    image.write_bytes(data)
    (tmp_path / "frame.png.json").write_text(json.dumps(doc))
    with pytest.raises(DofpFormatError) as err:
        read_raw(image)
    assert named in str(err.value) and "frame.png.json" in str(err.value)
    capsys.readouterr()
    assert main(["camera-heading", str(image)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and named in lines[0] and "internal error" not in lines[0]


@pytest.mark.parametrize("suffix", [".png", ".tiff"])
@pytest.mark.parametrize("damage,reason", [
    (lambda b: b"", "is empty (0 bytes)"),
    (lambda b: b[:len(b) // 2], "truncated or damaged"),
    (lambda b: b"hello, not an image\n", "truncated or damaged"),
])
def test_damaged_images_are_named_and_codecs_kept_quiet(tmp_path, capfd, camera_png, suffix,
                                                        damage, reason):
    """An empty, truncated or foreign file is one line naming it; the codec's own output
    (libpng's ``libpng error:``, OpenCV's log lines) does not reach the terminal."""
    data, doc = camera_png
    good = tmp_path / f"good{suffix}"
    if suffix == ".png":
        good.write_bytes(data)
    else:
        raw, _ = read_raw(_png_beside(tmp_path, data, doc))
        write_raw(good, raw, {k: v for k, v in doc.items() if k != "schema"})
    image = tmp_path / f"bad{suffix}"
    image.write_bytes(damage(good.read_bytes()))
    (tmp_path / f"bad{suffix}.json").write_text(json.dumps(doc))
    capfd.readouterr()
    with pytest.raises(DofpFormatError, match=re.escape(reason)) as err:
        read_raw(image)
    assert str(image) in str(err.value)
    assert capfd.readouterr().err == ""
    assert main(["camera-heading", str(image)]) == 2
    lines = capfd.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and f"bad{suffix}" in lines[0] and reason in lines[0]


def _png_beside(folder, data, doc):
    path = folder / "source.png"
    path.write_bytes(data)
    (folder / "source.png.json").write_text(json.dumps(doc))
    return path


def test_a_png_codec_reason_is_given(tmp_path, capfd, camera_png):
    """A PNG with a damaged byte in its compressed image data: the message carries libpng's
    reason (a CRC, inflate or filter error), which does not reach the terminal itself."""
    data, doc = camera_png
    damaged = bytearray(data)
    damaged[len(data) // 2] ^= 0xFF
    image = tmp_path / "flip.png"
    image.write_bytes(bytes(damaged))
    (tmp_path / "flip.png.json").write_text(json.dumps(doc))
    capfd.readouterr()
    with pytest.raises(DofpFormatError, match=r"flip\.png is not a readable PNG image "
                                              r"\([^)]+\); is it truncated or damaged"):
        read_raw(image)
    assert capfd.readouterr().err == ""


def test_a_missing_image_beside_its_sidecar(tmp_path, camera_png):
    from skysim.exceptions import MissingFileError
    (tmp_path / "gone.png.json").write_text(json.dumps(camera_png[1]))
    with pytest.raises(MissingFileError, match="gone.png"):
        read_raw(tmp_path / "gone.png")
