"""Adapter of polarization-camera images: where an ideal DoFP camera under a single-scattering
sky misses raw frames, and which camera or sky effect explains it.

1. **Data.** One or more raw division-of-focal-plane mosaics (uint16 [DN]) with their
   ``skysim.dofp/1`` sidecars (:mod:`sensor.camera.files`): site, time, attitude, nominal
   lens and sensor, exposure. Each pixel is dark-subtracted, ``d = raw - black_level -
   i_dark t / (e-/DN)``. A super-pixel (2x2 block, one pixel per polarizer) is **usable**
   when its four pixels look at the sky above ``min_elevation_deg`` through the nominal lens,
   none is saturated (the sun disk, glints), none is flagged by the user's ``mask``
   (occluding objects, clouds: flagged, never fitted) and its mean signal exceeds
   ``min_signal_dn``.
2. **Compared quantity.** The four channel intensities of a super-pixel normalised by their
   mean, ``y_k = d_k / mean_j(d_j) - 1``. For an ideal camera (polarizers at 0/45/90/135 deg,
   infinite extinction ratio) this is ``p cos 2(chi - a_k)`` exactly (Malus's law; Powell &
   Gruev 2013 [1]_ eq. 1): the polarization alone, with the pixel gain, exposure, radiometric
   scale and the sky's radiance pattern divided out, so the unknown absolute radiance of a
   real sky and a camera's gain never enter. Channels rather than Stokes: every candidate
   acts on the channels (an angle error on one channel only, crosstalk between neighbouring
   pixels), the shot noise of the channels is independent, and no demosaicing error (the
   four pixels look half a pixel apart) enters the comparison because the model is
   evaluated at every pixel's own ray. The price: vignetting cancels from ``y`` to second
   order across a super-pixel and is not diagnosed. The gap is the held-out RMS of
   ``y_model - y_data`` per channel (unit ``1``: a fraction of the super-pixel mean).
3. **Base model.** The nominal camera of the sidecar (lens centre and focal length as
   written, ideal polarizers at the layout's angles, infinite extinction ratio, no
   crosstalk) under the single-scattering Rayleigh sky (Coulson 1988 [2]_ ch. 2) at each
   frame's time and site, rendered by :class:`sensor.camera.PolarizationCamera` itself. The
   DoP scale ``d_max`` is taken from the sidecar when it records the sky (``sky.dmax``, or
   ``generator.sky.dmax`` of a simulated frame) or from ``dmax=``; otherwise it is fitted on
   the calibration folds. A uniform loss of modulation from the extinction ratio (factor
   ``(1 - 1/ER) / (1 + 1/ER)``) or from crosstalk (``1 - 4c``, :mod:`sensor.camera.mosaic`)
   is exactly a smaller ``d_max``: with a fitted ``d_max`` these two candidates are not
   identifiable and are listed as unavailable, their row saying so in the field
   ``degenerate_with: "d_max"`` beside ``identifiable``, the product of ``d_max`` and the
   modulation factor that the frames do pin (the base's fitted ``d_max``, with its standard
   error). With ``d_max`` known they are fitted and named as any candidate. Every other
   candidate fitted with ``d_max`` reports ``correlation_with_d_max`` of each parameter (the
   overcast layer's ``tau``: 0.98 at ``tau = 1``, where its loss of the clear pattern is
   nearly uniform, 0.6 at ``tau = 3``; identifiable, with a standard error 5 times that
   with ``d_max`` given).
4. **Folds.** Whole frames when there are several, else spatial blocks of
   ``block_superpixels`` x ``block_superpixels`` super-pixels, dealt to folds round-robin
   (:func:`calibration.diagnosis.core.assign_folds`); every fold is held out once
   (:func:`calibration.diagnosis.judge.cross_validate`) and the held-out residuals of all
   folds are scored.
5. **Noise floor.** :func:`calibration.diagnosis.core.noise_floor` of the base model's
   held-out residuals, second differences along each row of super-pixels (never across two
   rows or frames), where they are white (:func:`calibration.diagnosis.core.checked_floor`);
   else unknown (a frame holds no repeated readings of one pixel), and the verdict measures
   against the whole gap.
6. **Candidates** (each fitted with ``d_max`` when that is free, by
   :func:`scipy.optimize.least_squares` on the calibration folds, all rendered by the camera
   simulator with the candidate's parameters): ``lens`` (principal-point offset ``dcx,
   dcy`` [px] and focal-length scale), ``polarizer_angles`` (an angle offset [deg] of each of
   the four polarizers of the layout), ``extinction_ratio`` (``1/ER`` of all polarizers),
   ``crosstalk`` (share ``c`` of each edge neighbour, on request), ``sky_dop`` (the
   neutral-point sky of Berry, Dennis & Lee 2004 [3]_, :class:`skysim.berry.BerrySky`, with
   its singularity separation ``delta`` free; ``delta = 0`` is the Rayleigh pattern),
   ``overcast`` (a uniform cloud layer over the whole sky in front of the base sky,
   :class:`skysim.partly_cloudy.PartlyCloudySky` with a
   ``CloudField(cover=1, tau, thickness="uniform")``, base 1 km, the layer of the ring
   diagnosis's :class:`calibration.photodiode_diagnosis.effects.Overcast`, its optical
   thickness ``tau`` free:
   the clear sky's pattern comes through as ``exp(-0.206 tau / mu)`` and the cloud adds its
   own weakly polarized light, Zege, Ivanov & Katsev 1991 [4]_; ``tau = 0`` is the base sky
   exactly). Every parameter's standard error is the sandwich covariance over super-pixels
   at the optimum (:meth:`calibration.diagnosis.FitResult.from_least_squares`).
7. **Score, verdict, shrink, where.** Scores by :mod:`calibration.diagnosis.core` (three
   independent values per super-pixel: the four ``y_k`` sum to zero); the paired judge,
   the verdict and the shrink with its bootstrap standard errors over held-out blocks by
   :func:`calibration.diagnosis.judge.verdict`, as for every instrument. Slices: angular distance from the
   sun, view elevation, view azimuth, image rings (radius as a fraction of the image circle)
   and image quadrants.

References
----------
.. [1] S. B. Powell, V. Gruev, "Calibration methods for division-of-focal-plane
   polarimeters", Opt. Express 21(18):21039-21055 (2013), doi:10.1364/OE.21.021039.
.. [2] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak
   (1988).
.. [3] M. V. Berry, M. R. Dennis, R. L. Lee, "Polarization singularities in the clear sky",
   New J. Phys. 6:162 (2004), doi:10.1088/1367-2630/6/1/162.
.. [4] E. P. Zege, A. P. Ivanov, I. L. Katsev, *Image Transfer through a Scattering Medium*,
   Springer (1991) (the small-angle transfer of an angular pattern through a cloud).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path

import numpy as np

from . import core, judge
from .core import Thresholds
from .errors import DiagnosisError
from .fit_result import FitResult
from .protocol import candidate_names
from .report import Candidate, DiagnosisReport

__all__ = ["CAMERA_CANDIDATES", "CameraAdapter", "CameraEffect", "CameraFrame",
           "CameraFrames", "CameraInputError", "DEFAULT_CAMERA_CANDIDATES", "diagnose_camera",
           "load_frames"]

METRIC = "held-out RMS of the super-pixel-normalised channel intensities, model - data"
CAMERA_CANDIDATES = ("lens", "polarizer_angles", "extinction_ratio", "crosstalk", "sky_dop",
                     "overcast")
"""Every candidate effect of the camera diagnosis."""
DEFAULT_CAMERA_CANDIDATES = ("lens", "polarizer_angles", "extinction_ratio", "sky_dop",
                             "overcast")
"""The default set. ``crosstalk`` is tried on request: on a smooth sky its loss of modulation
``1 - 4c`` equals the extinction ratio's to within the sky's change across one pixel, so the
two cannot be told apart from sky images (a flat field behind a rotating polarizer can,
:mod:`calibration.dofp_calibration`)."""
DEFAULT_THRESHOLDS = Thresholds()
_DEGENERATE = ("extinction_ratio", "crosstalk")
OVERCAST_MAX_TAU = 10.0
"""Upper bound of the overcast ``cloud_tau``: the ring diagnosis's
:data:`calibration.photodiode_diagnosis.effects.OVERCAST_MAX_TAU` (not imported: that package
imports this one; a test keeps the two equal)."""


class CameraInputError(DiagnosisError, ValueError):
    """Unusable camera frames: wrong shapes or sidecars, no usable super-pixel, bad options."""


@dataclass(frozen=True)
class CameraEffect:
    """A candidate camera or sky effect (:class:`calibration.diagnosis.protocol.Effect`)."""

    name: str
    parameter_names: tuple
    units: tuple
    null: tuple
    bounds: tuple
    starts: tuple = ()
    """Further starting vectors besides ``null``: the fit starts from whichever fits the
    calibration data best (a start on a bound can stall a bounded trust-region fit)."""

    @property
    def k(self) -> int:
        return len(self.parameter_names)

    def available(self) -> str | None:
        return None


CAMERA_EFFECTS = {
    "lens": CameraEffect("lens", ("dcx_px", "dcy_px", "focal_scale"), ("px", "px", "1"),
                         (0.0, 0.0, 1.0), ((-20.0, -20.0, 0.8), (20.0, 20.0, 1.25))),
    "polarizer_angles": CameraEffect(
        "polarizer_angles", ("offset_a00_deg", "offset_a01_deg", "offset_a10_deg",
                             "offset_a11_deg"), ("deg",) * 4, (0.0,) * 4,
        ((-20.0,) * 4, (20.0,) * 4)),
    "extinction_ratio": CameraEffect("extinction_ratio", ("inverse_extinction_ratio",), ("1",),
                                     (0.0,), ((0.0,), (0.5,))),
    "crosstalk": CameraEffect("crosstalk", ("crosstalk",), ("1",), (0.0,), ((0.0,), (0.2,))),
    "sky_dop": CameraEffect("sky_dop", ("delta_deg",), ("deg",), (0.0,), ((0.0,), (80.0,))),
    "overcast": CameraEffect("overcast", ("cloud_tau",), ("1",), (0.0,),
                             ((0.0,), (OVERCAST_MAX_TAU,)), ((0.3,), (1.0,), (3.0,))),
}
"""Parameters, units, null values (the base model) and fit bounds of each candidate.
``offset_aRC_deg`` is the angle error of the polarizer at row R, column C of the 2x2 layout
(``layout_deg`` of the sidecar). ``cloud_tau`` is the vertical optical thickness at 550 nm of
the overcast layer, up to :data:`calibration.photodiode_diagnosis.effects.OVERCAST_MAX_TAU`
(beyond it the clear sky's pattern is hidden and the cloud's own weak polarization is what is
left)."""


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One raw mosaic (H, W) uint16 [DN] and its ``skysim.dofp/1`` sidecar dict."""

    raw: np.ndarray
    sidecar: dict
    name: str = ""

    def __post_init__(self):
        from sensor.camera.files import check_sidecar
        raw = np.asarray(self.raw)
        if raw.ndim != 2 or raw.dtype != np.uint16:
            raise CameraInputError(f"frame {self.name!r}: raw must be a 2-D uint16 mosaic; got "
                                   f"{raw.dtype} {raw.shape}")
        check_sidecar(self.sidecar, f"sidecar of frame {self.name!r}")
        s = self.sidecar["sensor"]
        if raw.shape != (s["height"], s["width"]):
            raise CameraInputError(f"frame {self.name!r} is {raw.shape}; its sidecar says "
                                   f"({s['height']}, {s['width']})")
        object.__setattr__(self, "raw", raw)


@dataclass(frozen=True, eq=False)
class CameraFrames:
    """Frames of one camera for :func:`calibration.diagnosis.diagnose` (same sensor size)."""

    frames: tuple
    masks: tuple | None = None
    """Per frame an (H, W) bool array, True where an object or cloud occludes the sky."""
    labels: dict = field(default_factory=dict)

    def __post_init__(self):
        frames = tuple(self.frames)
        if not frames or not all(isinstance(f, CameraFrame) for f in frames):
            raise CameraInputError("CameraFrames needs one or more CameraFrame")
        shapes = {f.raw.shape for f in frames}
        if len(shapes) > 1:
            raise CameraInputError(f"frames of several sizes {sorted(shapes)}: diagnose one "
                                   "camera at a time")
        object.__setattr__(self, "frames", frames)
        if self.masks is not None:
            masks = tuple(np.asarray(m, bool) for m in self.masks)
            if len(masks) != len(frames) or any(m.shape != frames[0].raw.shape for m in masks):
                raise CameraInputError(f"masks: give one {frames[0].raw.shape} bool array per "
                                       f"frame ({len(frames)})")
            object.__setattr__(self, "masks", masks)


CAMERA_NOISE_METHOD = ("second differences of the base model's held-out residuals along rows "
                       "of super-pixels")
"""How the camera's noise floor is measured where the residuals are white."""


def load_frames(paths) -> CameraFrames:
    """Frames from a folder (every ``.tif``/``.tiff``/``.png`` with a sidecar), one image
    file, or a list of them (:func:`sensor.camera.files.read_raw`).

    Raises
    ------
    CameraInputError
        For a folder without a raw image.
    DofpFormatError
        For a file without a ``skysim.dofp/1`` sidecar.
    """
    from sensor.camera.files import IMAGE_SUFFIXES, read_raw
    from skysim.io import find_sidecar
    items = [paths] if isinstance(paths, (str, Path)) else list(paths)
    files = []
    for p in map(Path, items):
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES
                           and find_sidecar(f) is not None)
            if not found:
                raise CameraInputError(f"{p} holds no raw image ({', '.join(IMAGE_SUFFIXES)}) "
                                       "with a sidecar")
            files.extend(found)
        else:
            files.append(p)
    return CameraFrames(tuple(CameraFrame(*read_raw(f), name=str(f)) for f in files))


# ------------------------------------------------------------------------------ geometry

@dataclass(frozen=True, eq=False)
class _Frame:
    """A frame prepared once: nominal camera, attitude, sun, data ``y`` and usable mask."""

    doc: dict
    attitude: object
    sun_el: float
    sun_az: float
    exposure_s: float
    y: np.ndarray          # (n_sp, 4) normalised channels of the data
    usable: np.ndarray     # (n_sp,)
    sp_rows: int
    sp_cols: int
    geometry: dict         # per super-pixel: view el/az, sun distance, ring, quadrant


def _superpixels(a: np.ndarray) -> np.ndarray:
    """(H, W) -> (H/2 * W/2, 4): channels in layout order (row 0 col 0, 0 1, 1 0, 1 1)."""
    h, w = a.shape[-2:]
    return a.reshape(a.shape[:-2] + (h // 2, 2, w // 2, 2)).swapaxes(-3, -2).reshape(
        a.shape[:-2] + (h * w // 4, 4))


def _normalised(d: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return d / d.mean(axis=-1, keepdims=True) - 1.0


def _sun(doc: dict) -> tuple[float, float]:
    import pandas as pd

    from skysim.sun import sun_position
    t = pd.Timestamp(doc["time"])
    if t.tzinfo is None:
        raise CameraInputError(f"sidecar time {doc['time']!r} has no UTC offset: give the "
                               "exposure time with its offset (e.g. +00:00)")
    site = doc["site"]
    sun = sun_position([t], site["latitude_deg"], site["longitude_deg"],
                       site.get("altitude_m", 0.0) or 0.0).iloc[0]
    return float(sun["elevation_deg"]), float(sun["azimuth_deg"])


def _prepare(frame: CameraFrame, mask, min_elevation_deg: float,
             min_signal_dn: float) -> _Frame:
    from sensor.camera import camera_attitude
    from sensor.camera.files import camera_from_sidecar
    from skysim.geometry import elevation_azimuth
    from skysim.rayleigh import scattering_angle_deg
    doc = frame.sidecar
    cam = camera_from_sidecar(doc)
    att = doc["attitude"]
    attitude = camera_attitude(att.get("yaw_deg", 0.0), att.get("pitch_deg", 0.0),
                               att.get("roll_deg", 0.0))
    sun_el, sun_az = _sun(doc)
    if sun_el <= 0:
        raise CameraInputError(f"frame {frame.name!r}: the sun is {sun_el:.2f} deg below the "
                               "horizon; the single-scattering sky needs it above")
    s = cam.sensor
    t = float(doc["exposure"]["exposure_s"])
    raw = frame.raw.astype(float)
    d = raw - s.black_level_dn - s.dark_current_e_s * t / s.e_per_dn
    bad = (frame.raw >= s.max_dn) | ~cam.sky_pixels(attitude)
    if mask is not None:
        bad |= mask
    dsp = _superpixels(d)
    h2, w2 = s.height // 2, s.width // 2
    rows = np.repeat(np.arange(h2) * 2.0 + 0.5, w2)
    cols = np.tile(np.arange(w2) * 2.0 + 0.5, h2)
    dirs, inside = cam.lens.back_project(rows, cols)
    el, az = elevation_azimuth(attitude.apply(np.where(inside[:, None], dirs, [0, 0, 1.0])))
    el, az = np.asarray(el, float), np.asarray(az, float)
    usable = (~_superpixels(bad).any(axis=1) & inside & (el >= min_elevation_deg)
              & (dsp.mean(axis=1) > min_signal_dn))
    radius = np.hypot(cols - cam.lens.cx, rows - cam.lens.cy) / float(
        cam.lens.radius_px(cam.lens.max_theta_rad))
    quadrant = np.where(rows < cam.lens.cy, 0, 2) + np.where(cols < cam.lens.cx, 0, 1)
    geometry = {"elevation_deg": el, "azimuth_deg": az,
                "sun_distance_deg": scattering_angle_deg(el, az, sun_el, sun_az),
                "radius": radius, "quadrant": quadrant, "row": rows // 2}
    return _Frame(doc, attitude, sun_el, sun_az, t, _normalised(dsp), usable, h2, w2,
                  geometry)


def _known_dmax(frames: list[_Frame]) -> float | None:
    """``d_max`` recorded in the sidecars (``sky.dmax`` or ``generator.sky.dmax`` of a
    Rayleigh sky), the same in every frame; None otherwise."""
    vals = set()
    for f in frames:
        sky = f.doc.get("sky") or (f.doc.get("generator") or {}).get("sky") or {}
        if sky.get("model", "rayleigh") != "rayleigh" or sky.get("dmax") is None:
            return None
        vals.add(float(sky["dmax"]))
    return vals.pop() if len(vals) == 1 else None


# ------------------------------------------------------------------------------ the model

def _camera(doc: dict, effect: str, theta) -> object:
    """The camera of a sidecar with a candidate's parameters (``effect`` None: nominal)."""
    from sensor.camera import MosaicSensor, PolarizationCamera
    from sensor.camera.files import camera_from_sidecar
    cam = camera_from_sidecar(doc)
    lens, sensor = cam.lens, cam.sensor
    if effect == "lens":
        from sensor.camera import FisheyeLens
        lens = FisheyeLens(lens.focal_px * theta[2], lens.cx + theta[0], lens.cy + theta[1],
                           lens.fov_deg, lens.model)
    elif effect in ("polarizer_angles", "extinction_ratio", "crosstalk"):
        kw = {}
        if effect == "polarizer_angles":
            kw["angle_error_deg"] = np.tile(np.reshape(theta, (2, 2)),
                                            (sensor.height // 2, sensor.width // 2))
        elif effect == "extinction_ratio":
            kw["extinction_ratio"] = np.inf if theta[0] <= 0 else 1.0 / theta[0]
        else:
            kw["crosstalk"] = float(theta[0])
        sensor = MosaicSensor(sensor.width, sensor.height, sensor.layout_deg,
                              sensor.full_well_e, sensor.read_noise_e, sensor.dark_current_e_s,
                              sensor.adc_bits, sensor.black_level_dn, **kw)
    return PolarizationCamera(lens, sensor, cam.photoelectrons_per_s, np.inf)


def _sky(effect: str | None, theta, dmax: float):
    """The sky of the base model or of a sky candidate (module doc, items 3 and 6); a null
    parameter gives the base sky itself."""
    from skysim.sky import make_sky
    base = make_sky("rayleigh", dmax=dmax)
    if effect == "sky_dop" and theta[0] > 0:
        return make_sky("berry", delta_deg=float(theta[0]), dmax=dmax)
    if effect == "overcast" and theta[0] > 0:   # the same layer as the ring diagnosis's
        from ..photodiode_diagnosis.effects import Overcast
        return Overcast().sky(theta, base, None)
    return base


def _predict(f: _Frame, effect: str | None, theta, dmax: float) -> np.ndarray:
    """Model ``y`` (n_sp, 4) of frame ``f`` (module doc, items 2-3 and 6)."""
    cam = _camera(f.doc, effect, theta)
    sky = _sky(effect, theta, dmax)
    scene = cam.scene(sky, f.attitude, f.sun_el, f.sun_az)
    e = cam.expected_electrons(scene, f.exposure_s) - cam.sensor.dark_current_e_s * f.exposure_s
    return _normalised(_superpixels(np.asarray(e, float)))


def _fit(frames, effect, dmax_known, theta0=None) -> tuple[FitResult, float]:
    """Least squares of a candidate's parameters (and ``d_max`` when not known, last in
    ``theta``) on the usable super-pixels of ``frames`` [(frame, row mask)]; returns the fit
    and ``d_max``. Its covariance is the sandwich over super-pixels
    (:meth:`FitResult.from_least_squares`): the shot noise of ``y`` varies with the sky's
    brightness across the image, and the four ``y_k`` of a super-pixel sum to zero (three
    independent values each)."""
    from scipy.optimize import least_squares
    eff = CAMERA_EFFECTS.get(effect)
    null = list(eff.null) if eff else []
    lo = list(eff.bounds[0]) if eff else []
    hi = list(eff.bounds[1]) if eff else []
    k = len(null)
    free_d = dmax_known is None
    x0 = list(theta0 if theta0 is not None else null) + ([0.7] if free_d else [])
    lo, hi = lo + ([1e-3] if free_d else []), hi + ([1.0] if free_d else [])
    if not x0:
        return FitResult(np.zeros(0), 0.0, None, 0, True, np.zeros((0, 0))), dmax_known

    def resid(x):
        th, d = (x[:k], x[k]) if free_d else (x, dmax_known)
        return np.concatenate([(_predict(f, effect, th, d)[m] - f.y[m]).ravel()
                               for f, m in frames])

    lo_, hi_ = np.asarray(lo) + 1e-9, np.asarray(hi) - 1e-9
    x0 = np.clip(np.asarray(x0, float), lo_, hi_)
    if eff is not None and eff.starts and theta0 is None:
        trial = [x0] + [np.clip(np.r_[st, x0[k:]], lo_, hi_) for st in eff.starts]
        x0 = min(trial, key=lambda x: float(np.sum(resid(x) ** 2)))
    r = least_squares(resid, x0, bounds=(lo, hi), x_scale="jac", diff_step=1e-4,
                      max_nfev=200)
    n_sp = sum(int(m.sum()) for _, m in frames)
    fit = FitResult.from_least_squares(r, 3 * n_sp, slice(0, k), group_size=4)
    return fit, float(r.x[k]) if free_d else dmax_known


def _parameters(fit: FitResult, effect: CameraEffect | None, free_d: bool) -> dict:
    """``name -> {"value", "se", "unit"}`` of a fit: the effect's parameters, the extinction
    ratio ``ER`` itself for that candidate (standard error by the delta method,
    ``se(ER) = se(1/ER) / (1/ER)^2``) and ``d_max`` when it was fitted."""
    out = {}
    if effect is not None:
        out = fit.parameters(slice(0, effect.k), effect.parameter_names, effect.units)
        if effect.name == "extinction_ratio":
            inv = out["inverse_extinction_ratio"]
            out["extinction_ratio"] = {
                "value": 1 / inv["value"] if inv["value"] > 0 else None,
                "se": inv["se"] / inv["value"] ** 2 if inv["value"] > 0 else None,
                "unit": "1"}
    if free_d:
        k = 0 if effect is None else effect.k
        out.update(fit.parameters(slice(k, k + 1), ("d_max",), ("1",)))
    return out


def _dmax_correlation(fit: FitResult, effect: CameraEffect) -> dict:
    """``{"correlation_with_d_max": {name: r}}``: the correlation of each of the effect's
    parameters with the fitted ``d_max`` from the fit's covariance (near +-1: the frames
    tell the two apart only through the fitted values' standard errors, which it inflates
    by ``1 / sqrt(1 - r^2)``)."""
    c = fit.covariance
    k = effect.k
    with np.errstate(invalid="ignore", divide="ignore"):
        r = c[:k, k] / np.sqrt(np.diag(c)[:k] * c[k, k])
    return {"correlation_with_d_max": {n: float(v) for n, v in zip(effect.parameter_names,
                                                                    r)}}


def _degeneracy(name: str, d0: float, d0_se: float) -> dict:
    """What an unavailable extinction-ratio or crosstalk candidate reports with a fitted
    ``d_max`` (module doc, item 3): ``degenerate_with`` (``"d_max"``), and the one quantity
    the frames do pin, the product of the sky's DoP scale and the camera's modulation
    (the base's fitted ``d_max``, with its standard error)."""
    modulation = ("(1 - 1/ER) / (1 + 1/ER)" if name == "extinction_ratio" else "(1 - 4 c)")
    return {"degenerate_with": "d_max",
            "identifiable": {"quantity": f"d_max * {modulation}", "value": d0, "se": d0_se,
                             "unit": "1"}}


# ------------------------------------------------------------------------------ where

def _slices(geom: dict, r2: np.ndarray, floor: float, margin: float) -> list:
    out = []

    def add(dim, masks, labels, bounds=None, unit=None):
        out.extend(core.partition_slices(dim, masks, labels, r2, floor, margin,
                                         dof_per_value=3, bounds=bounds, bound_unit=unit))

    for dim, x, edges in (("sun_distance_deg", geom["sun_distance_deg"],
                           (0.0, 30.0, 60.0, 90.0, 120.0, 150.0, 180.01)),
                          ("elevation_deg", geom["elevation_deg"],
                           (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.01)),
                          ("azimuth_deg", geom["azimuth_deg"],
                           (0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0, 360.01))):
        top = edges[-1] - 0.01
        bounds = [(a, min(b, top)) for a, b in pairwise(edges)]
        add(dim, [(x >= a) & (x < b) for a, b in pairwise(edges)],
            [f"{a:g}-{b:g}" for a, b in bounds], bounds, "deg")
    rad = geom["radius"]
    ring_edges = (0.0, 1 / 3, 2 / 3, 1.01)
    add("image_ring", [(rad >= a) & (rad < b) for a, b in pairwise(ring_edges)],
        ["centre (r < 1/3)", "middle (1/3-2/3)", "edge (r > 2/3)"])
    add("image_quadrant", [geom["quadrant"] == q for q in range(4)],
        ["top left", "top right", "bottom left", "bottom right"])
    return core.sort_slices(out)


# ------------------------------------------------------------------------------ diagnosis

def diagnose_camera(data: CameraFrames, candidates=DEFAULT_CAMERA_CANDIDATES, *,
                    folds: int = 3, seed: int = 0, dmax: float | None = None,
                    min_elevation_deg: float = 10.0, min_signal_dn: float = 20.0,
                    block_superpixels: int = 8,
                    thresholds: Thresholds = DEFAULT_THRESHOLDS) -> DiagnosisReport:
    """Camera-image gap diagnosis (module docstring); gaps in units of the super-pixel mean.

    Parameters
    ----------
    data : CameraFrames
    candidates : sequence of str
        Subset of :data:`CAMERA_CANDIDATES`.
    folds : int
        Held-out folds: of whole frames with several frames, else of spatial blocks.
    seed : int
        Seed of the bootstrap of the standard errors (over held-out blocks).
    dmax : float, optional
        Known sky DoP scale in (0, 1] (overrides the sidecars'); None: from the sidecars
        when they record it, else fitted.
    min_elevation_deg : float
        Super-pixels looking lower are not used [deg].
    min_signal_dn : float
        Super-pixels with a lower mean dark-subtracted signal are not used [DN].
    block_superpixels : int
        Side of a spatial block [super-pixels] (single frame).
    thresholds : Thresholds
        Its ``paired_se`` is a normal-equivalent level, applied as the t quantile for the
        number of held-out blocks (:func:`.core.paired_margin`; the report's thresholds show
        the value applied).

    Raises
    ------
    UnknownEffectError
        For a candidate outside :data:`CAMERA_CANDIDATES`.
    CameraInputError
        For a bad option or frames without usable super-pixels.
    InsufficientDataError
        When the blocks allow no held-out split.
    """
    t0 = time.perf_counter()
    candidates = candidate_names(candidates, CAMERA_CANDIDATES, DEFAULT_CAMERA_CANDIDATES,
                                 "camera")
    if dmax is not None and not 0 < dmax <= 1:
        raise CameraInputError(f"dmax must be in (0, 1]; got {dmax!r}")
    if int(block_superpixels) != block_superpixels or block_superpixels < 1:
        raise CameraInputError(f"block_superpixels must be a whole number >= 1; got "
                               f"{block_superpixels!r}")
    masks = data.masks or (None,) * len(data.frames)
    prepared = [_prepare(f, m, min_elevation_deg, min_signal_dn)
                for f, m in zip(data.frames, masks)]
    if not any(p.usable.any() for p in prepared):
        raise CameraInputError("no usable super-pixel: every one is saturated, masked, dark "
                               f"or below {min_elevation_deg:g} deg elevation")
    dmax_known = dmax if dmax is not None else _known_dmax(prepared)

    # blocks: whole frames, or spatial blocks of one frame
    blocks = []
    for i, p in enumerate(prepared):
        if len(prepared) > 1:
            blocks.append(np.full(p.usable.size, i))
        else:
            r = np.repeat(np.arange(p.sp_rows), p.sp_cols) // block_superpixels
            c = np.tile(np.arange(p.sp_cols), p.sp_rows) // block_superpixels
            blocks.append(r * (-(-p.sp_cols // block_superpixels)) + c)
    use = np.concatenate([p.usable for p in prepared])
    block = np.concatenate(blocks)
    fold_all = np.full(use.size, -1)
    fold_all[use] = core.assign_folds(block[use], folds)
    offsets = np.cumsum([0] + [p.usable.size for p in prepared])
    y_data = np.concatenate([p.y for p in prepared])

    used = np.flatnonzero(use)

    def fit_all(effect):
        """The fit on every usable super-pixel: ``(fit, d_max)``."""
        return _fit([(p, p.usable) for p in prepared], effect, dmax_known)

    def fit_one(effect, train, held):
        """``effect`` fitted on the ``train`` usable super-pixels; its held-out residuals
        ``y_model - y`` on the ``held`` ones."""
        cal, ho = np.zeros(use.size, bool), np.zeros(use.size, bool)
        cal[used[train]], ho[used[held]] = True, True
        fit, d = _fit([(p, cal[a:b]) for p, a, b in zip(prepared, offsets, offsets[1:])],
                      effect, dmax_known)
        pred = np.full(y_data.shape, np.nan)
        for p, a, b in zip(prepared, offsets, offsets[1:]):
            if ho[a:b].any():
                pred[a:b][ho[a:b]] = _predict(p, effect, fit.params, d)[ho[a:b]]
        return judge.FoldFit((pred - y_data)[ho], fit.params, bool(fit.converged))

    def fit_fold(train, held, skip):
        fits = {"base": fit_one(None, train, held)}
        for name in tried:
            if name not in skip:
                out, why = core.run_candidate(fit_one, name, train, held)
                fits[name] = out if why is None else why
        return np.ones((held.size, 4), bool), fits

    fit0, d0 = fit_all(None)
    d0_se = _parameters(fit0, None, True)["d_max"]["se"] if dmax_known is None else None
    degenerate = {name: Candidate.unavailable(
        name, "its uniform loss of modulation equals a smaller sky DoP scale, which is "
        "fitted here: give the sky's d_max (dmax=..., or 'sky': {'dmax': ...} in the "
        "sidecar) to tell them apart", _degeneracy(name, d0, d0_se))
        for name in candidates if name in _DEGENERATE and dmax_known is None}
    tried = [name for name in candidates if name not in degenerate]
    cv = judge.cross_validate(fold_all[use], tried, (used.size, 4), fit_fold)

    def residual(name):
        """Held-out residuals (n, 4) over every super-pixel, NaN where not usable."""
        out = np.full(y_data.shape, np.nan)
        out[use] = cv.held(name)
        return out

    ok0 = all(f.converged for f in cv.fits["base"]) and fit0.converged
    res0 = residual("base")
    line = np.concatenate([i * 100000 + p.geometry["row"] for i, p in enumerate(prepared)])
    noise = core.checked_floor(res0, np.repeat(use[:, None], 4, 1), line, CAMERA_NOISE_METHOD,
                               block_name="row of super-pixels")
    floor = noise.value
    G0 = core.rms(res0, use[:, None] & np.ones((1, 4), bool))
    n_sp = int(use.sum())
    N = 3 * n_sp                                     # the four y_k sum to zero
    n_cal = int(round(3 * n_sp * (folds - 1) / folds))
    rows, residuals = [], {}
    for name in candidates:
        eff = CAMERA_EFFECTS[name]
        if name in degenerate:
            rows.append(degenerate[name])
            continue
        why = cv.unavailable.get(name)
        if why is None:
            out, why = core.run_candidate(fit_all, name)
        if why is None:
            fit, _ = out
            params, why = core.run_candidate(_parameters, fit, eff, dmax_known is None)
        if why is not None:
            rows.append(Candidate.unavailable(name, why))
            continue
        residuals[name] = res = residual(name)
        ok = all(f.converged for f in cv.fits[name]) and fit.converged
        P = np.array([f.params for f in cv.fits[name]] + [fit.params])
        Gc = core.rms(res, use[:, None] & np.ones((1, 4), bool))
        rows.append(Candidate(
            name, k=eff.k, gap_after=Gc, shrink=1 - Gc / G0,
            score=core.held_out_score(Gc, G0, floor, N, eff.k, n_cal), converged=ok,
            params=params,
            at_bound=core.at_bound(P[:, :eff.k], eff.bounds[0], eff.bounds[1],
                                   eff.parameter_names, null=eff.null),
            details=_dmax_correlation(fit, eff) if dmax_known is None else {}))
    held = {name: r[use] for name, r in {"base": res0, **residuals}.items()}
    thresholds = thresholds.for_blocks(np.unique(block[use]).size)
    rows, verdict = judge.verdict(rows, held, block[use], floor, thresholds,
                                  np.random.default_rng(seed), floor_note=noise.note)
    best = next((r.effect for r in rows if r.available), None)
    after = residuals.get(best, res0) if verdict.effect != "none" else res0
    geom = {k: np.concatenate([p.geometry[k] for p in prepared])[use]
            for k in ("sun_distance_deg", "elevation_deg", "azimuth_deg", "radius",
                      "quadrant")}
    margin = thresholds.none_margin
    r2 = np.nanmean(res0[use] ** 2, axis=1)
    r2_after = np.nanmean(after[use] ** 2, axis=1)
    return DiagnosisReport(
        instrument="camera", metric=METRIC, unit="1", verdict=verdict, candidates=rows,
        where=_slices(geom, r2, floor, margin), where_after=_slices(geom, r2_after, floor,
                                                                    margin),
        noise_floor=noise.rms, noise_floor_method=noise.method,
        data={"frames": [f.name for f in data.frames], "usable_superpixels": n_sp,
              "flagged_superpixels": int((~use).sum()),
              "masked_pixels": int(sum(m.sum() for m in masks if m is not None)),
              "split": {"method": ("whole frames" if len(prepared) > 1 else
                                   f"spatial blocks of {block_superpixels}x{block_superpixels}"
                                   " super-pixels") + ", round-robin into folds",
                        "folds": folds, "held_out_values": N, "calibration_values": n_cal}},
        thresholds=thresholds.to_dict(), seed=seed,
        extra={"noise_floor_whiteness": noise.whiteness.to_dict(),
               "base": {"d_max": d0, "d_max_fitted": dmax_known is None,
                        "d_max_se": d0_se,
                        "converged": ok0},
               "sun": [{"elevation_deg": p.sun_el, "azimuth_deg": p.sun_az}
                       for p in prepared],
               "seconds": time.perf_counter() - t0},
        notes=([] if dmax_known is not None else [
            "The sky's DoP scale was fitted: extinction ratio and crosstalk are not "
            "separable from it and were not tried."]))


class CameraAdapter:
    """Polarization-camera frames as an instrument of :func:`calibration.diagnosis.diagnose`
    (:class:`.protocol.InstrumentAdapter`): a :class:`CameraFrames`, one
    :class:`CameraFrame`, or files with ``skysim.dofp/1`` sidecars."""

    name = "camera"

    def accepts(self, data, sidecar: dict | None = None) -> bool:
        from sensor.camera.files import SCHEMA
        if isinstance(data, (CameraFrames, CameraFrame)):
            return True
        return data is None and sidecar is not None and sidecar.get("schema") == SCHEMA

    def load(self, path) -> CameraFrames:
        return load_frames(path)

    def candidates(self, names=None) -> tuple:
        return candidate_names(names, CAMERA_CANDIDATES, DEFAULT_CAMERA_CANDIDATES, "camera")

    def diagnose(self, data, candidates, *, folds: int = 3, seed: int = 0,
                 **options) -> DiagnosisReport:
        if isinstance(data, CameraFrame):
            data = CameraFrames((data,))
        if len(data.frames) > 1:
            folds = min(folds, len(data.frames))
        return diagnose_camera(data, self.candidates(candidates), folds=folds, seed=seed,
                               **options)
