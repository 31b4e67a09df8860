"""Raw polarization-camera images on disk: a 16-bit TIFF mosaic with a JSON sidecar.

The image is the raw mosaic exactly as digitised (uint16 [DN], ``adc_bits`` significant bits,
not rescaled), written with ``tifffile`` (optional extra ``skysim[camera]``). The sidecar
``<name>.json`` beside it (e.g. ``sky.tiff.json``) holds, under ``schema`` =
``"skysim.dofp/1"``:

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

import json
from pathlib import Path

import numpy as np

from skysim.io import atomic_write_many, find_sidecar, sidecar_path

from .lens import FisheyeLens
from .mosaic import MosaicSensor, PolarizationCamera

__all__ = ["SCHEMA", "DofpFormatError", "camera_from_sidecar", "read_raw", "require_tifffile",
           "write_raw"]

SCHEMA = "skysim.dofp/1"
_REQUIRED = ("site", "time", "attitude", "lens", "sensor", "exposure")


class DofpFormatError(ValueError):
    """A raw camera file or its sidecar does not follow ``skysim.dofp/1``."""


def require_tifffile():
    """The ``tifffile`` module; ImportError with the install command if it is missing."""
    try:
        import tifffile
    except ImportError as exc:
        from skysim.extras import missing_extra_message
        raise ImportError(missing_extra_message("tifffile", "reading and writing camera "
                                                "images")) from exc
    return tifffile


def write_raw(path, raw: np.ndarray, sidecar: dict) -> Path:
    """Write a raw mosaic (H, W) uint16 as TIFF and its sidecar, atomically (both or none).

    Raises
    ------
    DofpFormatError
        If ``raw`` is not a 2-D uint16 array or the sidecar lacks a required key.
    """
    tifffile = require_tifffile()
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
    atomic_write_many([
        (path, lambda tmp: tifffile.imwrite(tmp, raw, photometric="minisblack")),
        (sidecar_path(path), lambda tmp: tmp.write_text(text)),
    ])
    return path


def read_raw(path) -> tuple[np.ndarray, dict]:
    """The raw mosaic (H, W) uint16 [DN] and its sidecar.

    Raises
    ------
    DofpFormatError
        No sidecar, another schema, a missing key, or an image that does not match the
        sidecar's sensor size.
    """
    tifffile = require_tifffile()
    path = Path(path)
    side = find_sidecar(path)
    if side is None:
        raise DofpFormatError(f"no sidecar {sidecar_path(path).name} beside {path}: the lens "
                              "and sensor of the image are needed")
    doc = json.loads(side.read_text())
    if doc.get("schema") != SCHEMA:
        raise DofpFormatError(f"{side} has schema {doc.get('schema')!r}, expected {SCHEMA!r}")
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise DofpFormatError(f"{side} lacks {', '.join(missing)}")
    raw = tifffile.imread(path)
    sensor = doc["sensor"]
    if raw.shape != (sensor["height"], sensor["width"]) or raw.dtype != np.uint16:
        raise DofpFormatError(f"{path} holds {raw.dtype} {raw.shape}; the sidecar says uint16 "
                              f"({sensor['height']}, {sensor['width']})")
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
