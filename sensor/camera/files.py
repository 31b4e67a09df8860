"""Raw polarization-camera images on disk: a 16-bit TIFF or PNG mosaic with a JSON sidecar.

The image is the raw mosaic exactly as digitised (uint16 [DN], ``adc_bits`` significant bits,
not rescaled), row 0 the top of the image as the sensor records it
(:mod:`sensor.camera.lens`). TIFF (``.tif``, ``.tiff``) goes through ``tifffile``, PNG
(``.png``, 16-bit greyscale) through OpenCV's PNG codec (``cv2.imencode`` /
``cv2.imdecode`` with ``IMREAD_UNCHANGED``): OpenCV is already in the optional extra
``camera`` (polanalyser is built on it) and its libpng path keeps 16 bits exactly, where
imageio's PNG goes through Pillow's modes and pypng is pure Python (seconds for a 5
megapixel frame). The sidecar ``<name>.json`` beside it (e.g. ``sky.tiff.json``) holds,
under ``schema`` = ``"skysim.dofp/1"``:

- ``site``: ``latitude_deg``, ``longitude_deg``, ``altitude_m``;
- ``time``: ISO 8601 with UTC offset (the exposure's mid-time);
- ``attitude``: ``yaw_deg`` (azimuth of the image top, clockwise from north), ``pitch_deg``,
  ``roll_deg`` (camera-to-ENU ``Rz(-yaw) Rx(pitch) Ry(roll)``), and ``yaw_known`` (false for a
  heading to be estimated);
- ``lens``: ``model``, ``focal_px``, ``cx``, ``cy``, ``fov_deg``;
- ``sensor``: ``width``, ``height``, ``layout_deg`` (2x2, rows then columns), ``adc_bits``,
  ``black_level_dn``, ``saturation_dn``, ``full_well_e``, ``e_per_dn``, ``read_noise_e``,
  ``dark_current_e_s``, ``photoelectrons_per_s``, ``exit_pupil_px`` (null: no vignetting),
  ``crosstalk`` (share of each edge neighbour, :class:`~sensor.camera.MosaicSensor`),
  ``errors`` (parameters of injected per-pixel errors);
- ``exposure``: ``exposure_s``;
- for generated images ``generator``: package version, sky model, sun position, seed.

Readers keep unknown keys.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import numbers
import os
import tempfile
from pathlib import Path

import numpy as np

from skysim.exceptions import (
    FileFormatError,
    InvalidParameterError,
    MissingDependencyError,
    MissingFileError,
)
from skysim.io import atomic_write_many, find_sidecar, sidecar_path

from .lens import FisheyeLens
from .mosaic import MosaicSensor, PolarizationCamera

__all__ = ["FLIPS", "IMAGE_SUFFIXES", "ROTATIONS_DEG", "SCHEMA", "DofpFormatError",
           "camera_from_sidecar", "check_sidecar", "read_raw", "require_image_codec",
           "require_tifffile",
           "undo_readout", "write_raw"]

SCHEMA = "skysim.dofp/1"
_REQUIRED = ("site", "time", "attitude", "lens", "sensor", "exposure")
_FIELDS = {
    "site": {"latitude_deg": ("number", True), "longitude_deg": ("number", True),
             "altitude_m": ("number", False)},
    "attitude": {"yaw_deg": ("number", False), "pitch_deg": ("number", False),
                 "roll_deg": ("number", False), "yaw_known": ("boolean", False)},
    "lens": {"model": ("text", True), "focal_px": ("number", True), "cx": ("number", True),
             "cy": ("number", True), "fov_deg": ("number", True)},
    "sensor": {"width": ("integer", True), "height": ("integer", True),
               "layout_deg": ("2x2 angles", True), "full_well_e": ("number", True),
               "read_noise_e": ("number", True), "dark_current_e_s": ("number", True),
               "adc_bits": ("integer", True), "black_level_dn": ("number", True),
               "saturation_dn": ("number", False), "e_per_dn": ("number", False),
               "crosstalk": ("number", False), "photoelectrons_per_s": ("number", False),
               "exit_pupil_px": ("number or null", False), "sun_radius_deg": ("number", False),
               "errors": ("object", False)},
    "exposure": {"exposure_s": ("number", True)},
}
"""The fields of each sidecar section: ``key: (kind of value, required)``."""


def _is_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and bool(np.isfinite(v))


_KINDS = {
    "number": (_is_number, "a finite number"),
    "number or null": (lambda v: v is None or _is_number(v), "a finite number or null"),
    "integer": (lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool),
                "a whole number"),
    "text": (lambda v: isinstance(v, str), "text"),
    "boolean": (lambda v: isinstance(v, bool), "true or false"),
    "object": (lambda v: isinstance(v, dict), "an object {...}"),
    "2x2 angles": (lambda v: isinstance(v, list) and len(v) == 2 and all(
        isinstance(r, list) and len(r) == 2 and all(map(_is_number, r)) for r in v),
        "a 2x2 list of polarizer angles [deg], rows then columns"),
}
"""Kind of a sidecar value -> (test, what the message asks for)."""


def check_sidecar(doc, side) -> None:
    """Check every field of a ``skysim.dofp/1`` sidecar before any use.

    Each section holds the fields of :data:`_FIELDS` (the required ones present, every one
    given of its kind), ``time`` is ISO 8601 with a UTC offset, and the site, lens, sensor and
    exposure values lie in their ranges (those of :class:`skysim.sun.Site`,
    :class:`~sensor.camera.FisheyeLens`, :class:`~sensor.camera.MosaicSensor` and
    :class:`~sensor.camera.PolarizationCamera`). Unknown keys are kept, not checked.

    Raises
    ------
    DofpFormatError
        Naming ``side`` (the sidecar's path or a description), the field and its value.
    """
    if not isinstance(doc, dict):
        raise DofpFormatError(f"{side} holds a JSON {type(doc).__name__}, not an object")
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise DofpFormatError(f"{side} lacks {', '.join(missing)}")
    _check_sections(doc, side, _FIELDS)
    att = doc["attitude"]
    if att.get("yaw_known", False) and "yaw_deg" not in att:
        raise DofpFormatError(f"{side}: attitude.yaw_known is true but attitude.yaw_deg is "
                              "missing; give the heading of the image top [deg] or set "
                              "yaw_known to false")
    _check_time(doc["time"], side)
    exposure = doc["exposure"]["exposure_s"]
    if not exposure > 0:
        raise DofpFormatError(f"{side}: exposure.exposure_s must be > 0 [s]; got {exposure!r}")
    from skysim.sun import Site
    try:
        Site.from_dict(doc["site"])
    except InvalidParameterError as exc:
        raise DofpFormatError(f"{side}: site: {exc}") from None
    _camera(doc, side)


def _check_sections(doc, side, spec) -> None:
    for section, keys in spec.items():
        value = doc[section]
        if not isinstance(value, dict):
            raise DofpFormatError(f"{side}: {section!r} must be an object; got {value!r}")
        for key, (kind, required) in keys.items():
            if key not in value:
                if required:
                    raise DofpFormatError(f"{side}: {section!r} lacks {key!r}")
                continue
            test, what = _KINDS[kind]
            if not test(value[key]):
                raise DofpFormatError(f"{side}: {section}.{key} must be {what}; got "
                                      f"{value[key]!r}")


def _check_time(value, side) -> None:
    """The sidecar's ``time``: ISO 8601 text with a UTC offset, in the years pandas holds."""
    import pandas as pd
    example = "write ISO 8601 with a UTC offset, e.g. 2013-05-22T17:10:00+08:00 (or Z for UTC)"
    if not isinstance(value, str):
        raise DofpFormatError(f"{side}: time must be text; got {value!r}; {example}")
    try:
        t = pd.Timestamp(value)
        out_of_range = t is not pd.NaT and not 1678 <= t.year <= 2261
    except (pd.errors.OutOfBoundsDatetime, OverflowError):
        out_of_range = True
    except (ValueError, TypeError):
        t = pd.NaT
        out_of_range = False
    if out_of_range:  # the years of nanosecond timestamps, which the sun and the Moon use
        raise DofpFormatError(f"{side}: time {value!r} is outside the supported years "
                              "1678-2261")
    if t is pd.NaT:
        raise DofpFormatError(f"{side}: time {value!r} is not a time; {example}")
    if t.tzinfo is None:
        raise DofpFormatError(f"{side}: time {value!r} has no UTC offset (skysim never guesses "
                              f"the timezone); {example}")


IMAGE_SUFFIXES = (".tif", ".tiff", ".png")
"""Raw image formats by file suffix (lower case)."""
FLIPS = ("none", "horizontal", "vertical")
"""Readout flips :func:`undo_readout` undoes."""
ROTATIONS_DEG = (0, 90, 180, 270)
"""Readout rotations [deg, counter-clockwise as displayed] :func:`undo_readout` undoes."""


class DofpFormatError(FileFormatError):
    """A raw camera file or its sidecar does not follow ``skysim.dofp/1``."""


def _require(module: str, what: str):
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        from skysim.extras import missing_extra_message
        raise MissingDependencyError(missing_extra_message(module, what), name=module) from exc


def require_tifffile():
    """The ``tifffile`` module; ImportError with the install command if it is missing."""
    return _require("tifffile", "reading and writing TIFF camera images")


def require_cv2():
    """The ``cv2`` module (OpenCV); ImportError with the install command if it is missing."""
    return _require("cv2", "reading and writing PNG camera images")


def _suffix(path) -> str:
    suffix = Path(path).suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        raise DofpFormatError(f"raw image {Path(path).name!r} must end in "
                              f"{', '.join(IMAGE_SUFFIXES)}")
    return suffix


def require_image_codec(path):
    """The module that reads and writes ``path``'s format (``tifffile`` or ``cv2``), checked
    before any work; ImportError with the install command if it is missing, DofpFormatError
    for another suffix."""
    return require_cv2() if _suffix(path) == ".png" else require_tifffile()


def _encode_png(raw: np.ndarray) -> bytes:
    cv2 = require_cv2()
    ok, buf = cv2.imencode(".png", raw)
    if not ok:
        raise DofpFormatError("OpenCV could not encode the image as PNG")
    return buf.tobytes()


def _read_image(path: Path) -> np.ndarray:
    """The image of ``path`` as stored; a :class:`DofpFormatError` naming the file and the
    codec's reason for an empty, truncated or damaged one."""
    if path.stat().st_size == 0:
        raise DofpFormatError(f"{path} is empty (0 bytes): not a raw camera image")
    if _suffix(path) != ".png":
        tifffile = require_tifffile()
        try:
            return tifffile.imread(path)
        except (OSError, MemoryError):   # the file system's own errors, and memory: as they are
            raise
        except Exception as exc:  # tifffile raises ValueError, struct.error, KeyError, ...
            raise DofpFormatError(f"{path} is not a readable TIFF image ({exc}); is it "
                                  "truncated or damaged?") from None
    cv2 = require_cv2()
    data = np.fromfile(path, np.uint8)
    with _c_stderr_captured() as said:
        try:
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        except cv2.error:
            img = None
    if img is None:
        why = _codec_reason(said)
        raise DofpFormatError(f"{path} is not a readable PNG image"
                              f"{f' ({why})' if why else ''}; is it truncated or damaged?")
    return img


@contextlib.contextmanager
def _c_stderr_captured():
    """Collect what C code writes to file descriptor 2 inside the block into the yielded list
    (one string), instead of the terminal: OpenCV's PNG codec reports a damaged file there
    (``libpng error: ...`` and its own log lines) besides returning no image. The descriptor
    is shared by the whole process, so another thread's writes during the block (a few
    milliseconds of decoding) are collected too. Without a usable descriptor 2 the block runs
    as it is."""
    said: list[str] = []
    try:
        saved = os.dup(2)
    except OSError:
        yield said
        return
    try:
        with tempfile.TemporaryFile() as sink:
            os.dup2(sink.fileno(), 2)
            try:
                yield said
            finally:
                os.dup2(saved, 2)
            sink.seek(0)
            said.append(sink.read().decode("utf-8", "replace"))
    finally:
        os.close(saved)


def _codec_reason(said: list[str]) -> str:
    """The reason a PNG decoder gave, from its stderr text: libpng's error, else OpenCV's own
    error or warning line (without its time stamp and source line)."""
    import re
    lines = [ln.strip() for text in said for ln in text.splitlines() if ln.strip()]
    opencv = r"\]\s*(?:global\s+)?\S+\s+\w+\s+(.+)"   # "] global <file:line> <function> text"
    for pattern in (r"libpng error:\s*(.+)", r"\[\s*ERROR:[^\]]*" + opencv,
                    r"\[\s*WARN:[^\]]*" + opencv):
        for ln in lines:
            m = re.match(pattern, ln)
            if m:
                return m.group(1).strip()
    return ""


def undo_readout(recorded: np.ndarray, flip: str = "none", rotate_deg: int = 0) -> np.ndarray:
    """The physical image (row 0 at the top, :mod:`sensor.camera.lens`) of a frame whose
    readout is flipped or rotated.

    The recorded frame is taken as the physical image flipped first (``"horizontal"``: left
    to right, ``"vertical"``: top to bottom), then rotated by ``rotate_deg`` counter-clockwise
    as displayed; this rotates back, then flips. A view, no copy.

    Raises
    ------
    InvalidParameterError
        For a flip not in :data:`FLIPS` or a rotation not in :data:`ROTATIONS_DEG`.
    """
    if flip not in FLIPS:
        raise InvalidParameterError(f"flip must be one of {', '.join(FLIPS)}; got {flip!r}")
    if rotate_deg not in ROTATIONS_DEG:
        raise InvalidParameterError(
            f"rotate_deg must be one of {', '.join(map(str, ROTATIONS_DEG))}; got "
            f"{rotate_deg!r}")
    img = np.rot90(recorded, -int(rotate_deg) // 90)
    if flip == "horizontal":
        return img[:, ::-1]
    return img[::-1] if flip == "vertical" else img


def write_raw(path, raw: np.ndarray, sidecar: dict) -> Path:
    """Write a raw mosaic (H, W) uint16 as TIFF or PNG (by the suffix of ``path``) and its
    sidecar, atomically (both or none).

    Raises
    ------
    DofpFormatError
        If ``raw`` is not a 2-D uint16 array, the sidecar lacks a required key or ``path``
        has another suffix than :data:`IMAGE_SUFFIXES`.
    """
    suffix = _suffix(path)
    codec = require_image_codec(path)
    raw = np.asarray(raw)
    if raw.ndim != 2 or raw.dtype != np.uint16:
        raise DofpFormatError(f"raw image must be 2-D uint16; got {raw.dtype} of shape "
                              f"{raw.shape}")
    missing = [k for k in _REQUIRED if k not in sidecar]
    if missing:
        raise DofpFormatError(f"sidecar lacks {', '.join(missing)}")
    path = Path(path)
    doc = {"schema": SCHEMA, **sidecar}
    text = json.dumps(doc, indent=2) + "\n"
    if suffix == ".png":
        data = _encode_png(raw)  # before any file is touched

        def write_image(tmp):
            tmp.write_bytes(data)
    else:
        def write_image(tmp):
            codec.imwrite(tmp, raw, photometric="minisblack")
    atomic_write_many([(path, write_image),
                       (sidecar_path(path), lambda tmp: tmp.write_text(text))])
    return path


def read_raw(path, *, flip: str = "none", rotate_deg: int = 0) -> tuple[np.ndarray, dict]:
    """The raw mosaic (H, W) uint16 [DN] and its sidecar.

    ``flip``, ``rotate_deg``: the camera's readout, undone (:func:`undo_readout`) so that the
    image is the physical one the sidecar describes (its ``width``, ``height``,
    ``layout_deg``).

    Raises
    ------
    DofpFormatError
        No sidecar, another schema, a missing or invalid field (:func:`check_sidecar`), an
        empty, truncated or damaged image, or an image that does not match the sidecar's
        sensor size; each message names the file (and the field).
    MissingFileError
        If the image is not there.
    """
    path = Path(path)
    require_image_codec(path)
    if path.is_dir():
        raise DofpFormatError(f"{path} is a folder; give a raw image file")
    if not path.exists():
        raise MissingFileError(f"no raw image {path}")
    side = find_sidecar(path)
    if side is None:
        raise DofpFormatError(f"no sidecar {sidecar_path(path).name} beside {path}: the lens "
                              "and sensor of the image are needed")
    try:
        doc = json.loads(side.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise DofpFormatError(f"{side} is not valid JSON: {exc}") from None
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
        got = doc.get("schema") if isinstance(doc, dict) else doc
        raise DofpFormatError(f"{side} has schema {got!r}, expected {SCHEMA!r}")
    check_sidecar(doc, side)
    raw = np.ascontiguousarray(undo_readout(_read_image(path), flip, rotate_deg))
    sensor = doc["sensor"]
    if raw.shape != (sensor["height"], sensor["width"]) or raw.dtype != np.uint16:
        turn = f" after undoing the readout (flip {flip}, rotation {rotate_deg} deg)" \
            if (flip, rotate_deg) != ("none", 0) else ""
        raise DofpFormatError(f"{path} holds {raw.dtype} {raw.shape}{turn}; the sidecar says "
                              f"uint16 ({sensor['height']}, {sensor['width']})")
    return raw, doc


def camera_from_sidecar(doc: dict) -> PolarizationCamera:
    """The nominal camera a sidecar describes (no per-pixel errors: those are unknown until
    calibrated).

    Raises
    ------
    DofpFormatError
        For a ``lens`` or ``sensor`` section with a missing field, a value of the wrong kind
        or out of range (the message names the field).
    """
    if not isinstance(doc, dict):
        raise DofpFormatError(f"sidecar holds a {type(doc).__name__}, not an object")
    missing = [k for k in ("lens", "sensor") if k not in doc]
    if missing:
        raise DofpFormatError(f"sidecar lacks {', '.join(missing)}")
    _check_sections(doc, "sidecar", {k: _FIELDS[k] for k in ("lens", "sensor")})
    return _camera(doc, "sidecar")


def _camera(doc: dict, side) -> PolarizationCamera:
    """The camera of a sidecar whose fields have the right kinds; a range error of the lens or
    sensor as a :class:`DofpFormatError` naming ``side`` and the section."""
    try:
        lens = FisheyeLens(**{k: doc["lens"][k] for k in ("focal_px", "cx", "cy", "fov_deg",
                                                           "model")})
    except InvalidParameterError as exc:
        raise DofpFormatError(f"{side}: lens: {exc}") from None
    s = doc["sensor"]
    try:
        sensor = MosaicSensor(s["width"], s["height"], tuple(map(tuple, s["layout_deg"])),
                              s["full_well_e"], s["read_noise_e"], s["dark_current_e_s"],
                              s["adc_bits"], s["black_level_dn"])
        pupil = s.get("exit_pupil_px")
        return PolarizationCamera(lens, sensor, s.get("photoelectrons_per_s", 2.0e5),
                                  np.inf if pupil is None else pupil)
    except InvalidParameterError as exc:
        raise DofpFormatError(f"{side}: sensor: {exc}") from None
