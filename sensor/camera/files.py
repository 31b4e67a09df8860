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

import importlib
import json
from pathlib import Path

import numpy as np

from skysim.exceptions import SkysimError
from skysim.io import atomic_write_many, find_sidecar, sidecar_path

from .lens import FisheyeLens
from .mosaic import MosaicSensor, PolarizationCamera

__all__ = ["FLIPS", "IMAGE_SUFFIXES", "ROTATIONS_DEG", "SCHEMA", "DofpFormatError",
           "camera_from_sidecar", "read_raw", "require_image_codec", "require_tifffile",
           "undo_readout", "write_raw"]

SCHEMA = "skysim.dofp/1"
_REQUIRED = ("site", "time", "attitude", "lens", "sensor", "exposure")
_REQUIRED_NESTED = {
    "site": {"latitude_deg": "number", "longitude_deg": "number"},
    "time": None,
    "attitude": {},
    "lens": {"focal_px": "number", "cx": "number", "cy": "number", "fov_deg": "number",
             "model": "text"},
    "sensor": {"width": "integer", "height": "integer", "layout_deg": "list",
               "full_well_e": "number", "read_noise_e": "number", "dark_current_e_s": "number",
               "adc_bits": "integer", "black_level_dn": "number"},
    "exposure": {"exposure_s": "number"},
}
"""The keys of each sidecar section a reader uses, with the kind of value each must hold."""


def check_sidecar(doc, side) -> None:
    """Every key a heading or calibration from the image uses is present with a value of the right kind;
    otherwise a :class:`DofpFormatError` naming the key and the value."""
    if not isinstance(doc, dict):
        raise DofpFormatError(f"{side} holds a JSON {type(doc).__name__}, not an object")
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise DofpFormatError(f"{side} lacks {', '.join(missing)}")
    _check_sections(doc, side, _REQUIRED_NESTED)


def _check_sections(doc, side, spec) -> None:
    import numbers
    kinds = {"number": lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool)
             and np.isfinite(v),
             "integer": lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool),
             "text": lambda v: isinstance(v, str), "list": lambda v: isinstance(v, list)}
    for section, keys in spec.items():
        if keys is None:
            continue
        value = doc[section]
        if not isinstance(value, dict):
            raise DofpFormatError(f"{side}: {section!r} must be an object; got {value!r}")
        for key, kind in keys.items():
            if key not in value:
                raise DofpFormatError(f"{side}: {section!r} lacks {key!r}")
            if not kinds[kind](value[key]):
                raise DofpFormatError(f"{side}: {section}.{key} must be a finite {kind}; got "
                                      f"{value[key]!r}")
IMAGE_SUFFIXES = (".tif", ".tiff", ".png")
"""Raw image formats by file suffix (lower case)."""
FLIPS = ("none", "horizontal", "vertical")
"""Readout flips :func:`undo_readout` undoes."""
ROTATIONS_DEG = (0, 90, 180, 270)
"""Readout rotations [deg, counter-clockwise as displayed] :func:`undo_readout` undoes."""


class DofpFormatError(SkysimError, ValueError):
    """A raw camera file or its sidecar does not follow ``skysim.dofp/1``."""


def _require(module: str, what: str):
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        from skysim.extras import missing_extra_message
        raise ImportError(missing_extra_message(module, what)) from exc


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
    if _suffix(path) != ".png":
        return require_tifffile().imread(path)
    cv2 = require_cv2()
    img = cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DofpFormatError(f"{path} is not a readable PNG image")
    return img


def undo_readout(recorded: np.ndarray, flip: str = "none", rotate_deg: int = 0) -> np.ndarray:
    """The physical image (row 0 at the top, :mod:`sensor.camera.lens`) of a frame whose
    readout is flipped or rotated.

    The recorded frame is taken as the physical image flipped first (``"horizontal"``: left
    to right, ``"vertical"``: top to bottom), then rotated by ``rotate_deg`` counter-clockwise
    as displayed; this rotates back, then flips. A view, no copy.

    Raises
    ------
    ValueError
        For a flip not in :data:`FLIPS` or a rotation not in :data:`ROTATIONS_DEG`.
    """
    if flip not in FLIPS:
        raise ValueError(f"flip must be one of {', '.join(FLIPS)}; got {flip!r}")
    if rotate_deg not in ROTATIONS_DEG:
        raise ValueError(f"rotate_deg must be one of {', '.join(map(str, ROTATIONS_DEG))}; got "
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
        No sidecar, another schema, a missing key, or an image that does not match the
        sidecar's sensor size.
    """
    path = Path(path)
    require_image_codec(path)
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
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise DofpFormatError(f"{side} lacks {', '.join(missing)}")
    _check_sections(doc, side, {"sensor": {"width": "integer", "height": "integer"}})
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
    calibrated)."""
    lens = FisheyeLens(**{k: doc["lens"][k] for k in ("focal_px", "cx", "cy", "fov_deg",
                                                       "model")})
    s = doc["sensor"]
    sensor = MosaicSensor(s["width"], s["height"], tuple(map(tuple, s["layout_deg"])),
                          s["full_well_e"], s["read_noise_e"], s["dark_current_e_s"],
                          s["adc_bits"], s["black_level_dn"])
    pupil = s.get("exit_pupil_px")
    return PolarizationCamera(lens, sensor, s.get("photoelectrons_per_s", 2.0e5),
                              np.inf if pupil is None else pupil)
