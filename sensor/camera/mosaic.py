"""Division-of-focal-plane (DoFP) polarization camera: micro-polarizer mosaic sensor behind a
fisheye lens, imaging any :class:`skysim.sky.Sky`.

Signal chain of one pixel (Powell & Gruev 2013 [1]_, eq. 1; the analysis vector of a pixel
behind a partial polarizer):

``e = X[t * q * V(r) * (A . S)] + t * i_dark``, then photon shot noise (Poisson; its
skewness-corrected normal limit from :data:`POISSON_EXACT_BELOW_E` on), read noise (Gaussian),
clipping at the full well and an ADC of ``adc_bits`` bits with a black level. The sun disk's
photoelectrons are raised to the full well before crosstalk.

- ``S = (I, Q_c, U_c)``: the scene's linear Stokes vector in the image's polarization basis
  (angles counter-clockwise in the displayed image from its right towards its top, see
  :mod:`sensor.camera.lens`). An ideal rotationally symmetric lens maps the sky's local
  basis ``(e_theta, e_psi)`` of a ray onto the image's radial and tangential directions, so
  the E-vector angle from the image radius equals its angle from ``e_theta`` on the sky.
- ``A = g/2 * (1 + 1/ER, (1 - 1/ER) cos 2a, (1 - 1/ER) sin 2a)``: polarizer at angle
  ``a = a_nominal + error`` [deg] with extinction ratio ``ER`` (transmittance ``g`` along its
  axis, ``g / ER`` across it; ``g`` also carries the pixel's response non-uniformity). An
  ideal polarizer (``ER = inf``, ``g = 1``) gives Malus's law ``I/2 (1 + p cos 2(chi - a))``.
- ``V(r) = (1 + (r / p)^2)^-2``: the cos^4 law of natural vignetting with the chief ray's angle
  in image space, ``atan(r / p)`` for an exit pupil ``p`` [px] from the sensor (``p = inf``:
  no vignetting) [2]_.
- ``X``: crosstalk between neighbouring pixels, the linear superposition of the neighbours'
  analysed signals with constant weights (Xue et al. 2025 [3]_; review: Jin et al. 2025
  [4]_): each pixel keeps ``1 - 4c`` of its photoelectrons and receives ``c`` of each of
  its four edge neighbours' (light through a neighbour's micro-polarizer reaching its
  photodiode, and diffusing carriers). Energy conserving: a pixel on the sensor's border
  keeps the share it would pass to its missing neighbour. With the usual mosaic every edge
  neighbour's polarizer is at +-45 deg, so a uniform scene's apparent DoLP shrinks by exactly
  ``1 - 4c`` and its intensity is unchanged (tested). Default ``c = 0`` (off).
- ``q`` [e-/s]: photoelectron rate of a pixel with ``A = (1, 0, 0)`` for a scene radiance 1
  (in the sky model's unit); ``t`` [s] the exposure; ``i_dark`` [e-/s] the dark current.

The sun disk (radius ``sun_radius_deg`` plus half a pixel) saturates its pixels. Pixels outside
the lens's image circle or looking below the horizon receive no scene light and are masked.

References
----------
.. [1] S. B. Powell, V. Gruev, "Calibration methods for division-of-focal-plane
   polarimeters", Opt. Express 21(18):21039-21055 (2013), doi:10.1364/OE.21.021039.
.. [2] W. J. Smith, *Modern Optical Engineering*, 4th ed., McGraw-Hill (2008), sect. 9.8
   (cos^4 law of illumination).
.. [3] J. Xue, S. Qiu, W. Jin, X. Wang, L. Luo, Q. Liu, "Fixed linear superposition crosstalk
   model of division of focal plane polarization camera", Acta Optica Sinica 45(8):0811002
   (2025).
.. [4] W. Jin, J. Xue, S. Qiu, L. Luo, Q. Liu, "Review of crosstalk between pixels in
   division of focal plane polarization camera", Chinese Optics 18(4):725 (2025),
   doi:10.37188/CO.2024-0217.
.. [5] E. A. Cornish, R. A. Fisher, "Moments and cumulants in the specification of
   distributions", Rev. Inst. Int. Stat. 5(4):307-320 (1938), doi:10.2307/1400905 (the
   quantile expansion whose first term beyond the normal is ``gamma_1 (z^2 - 1) / 6``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from skysim import rayleigh
from skysim.exceptions import InvalidParameterError
from skysim.geometry import elevation_azimuth
from skysim.sky import RayleighSky
from skysim.validation import check_finite, check_sun_above_horizon

from .lens import FisheyeLens

__all__ = ["DEFAULT_LAYOUT_DEG", "POISSON_EXACT_BELOW_E", "SUN_RADIUS_DEG", "MosaicSensor",
           "PolarizationCamera", "Scene", "camera_attitude", "camera_basis", "sky_stokes_camera"]

POISSON_EXACT_BELOW_E = 30.0
"""Mean photo- and dark electrons [e-] below which shot noise is drawn from the Poisson law
itself. At and above it, shot plus read noise (variance ``v = lam + read^2``, third cumulant
``lam``) come from one normal draw ``z`` with the skewness (Cornish-Fisher) correction
[5]_: ``lam + sqrt(v) z + lam / (6 v) (z^2 - 1)``. Mean exact, variance exact within
``lam^2 / (18 v^2) <= 0.056 e-^2``, skewness exact to leading order; the largest difference of
the distribution function from Poisson's (no read noise, the worst case) is 4.4e-4 at the
threshold and falls like ``1 / lam`` above it (1.2e-5 at 1000 e-, tested against scipy's
Poisson law); the plain Gaussian limit would leave ``1 / (6 sqrt(2 pi lam))``, 0.012 at 30
e-."""

DEFAULT_LAYOUT_DEG = ((90.0, 45.0), (135.0, 0.0))
"""Polarizer angles [deg] of the 2x2 super-pixel, rows then columns of the image as the sensor
records it (row 0 at the top): 90 deg top left, 45 top right, 135 bottom left, 0 bottom right,
the layout of the Sony IMX250MZR/IMX253MZR sensors. Angles count counter-clockwise in the
displayed image from its right towards its top (:mod:`sensor.camera.lens`): the 45 deg
polarizer runs from the pixel's bottom left to its top right, as polanalyser draws the
IMX250MZR mosaic and computes ``S2 = I45 - I135`` (Sony's and polanalyser's convention)."""

SUN_RADIUS_DEG = 0.2666
"""Mean angular radius of the solar disk [deg]."""


def camera_attitude(yaw_deg: float, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> Rotation:
    """Camera-to-ENU rotation ``R_nc = R_nb R_bc`` [deg] of an upward-looking camera whose
    image top is its heading reference.

    ``R_nb = Rz(-yaw) Rx(pitch) Ry(roll)`` is the body attitude of
    :func:`sensor.compound_eye.body_attitude` (body x right, y forward, z up) and
    ``R_bc = Rz(180 deg)`` the camera's mount: the optical axis along the body's z, the
    image's top (camera -y) along the body's forward axis, hence the image's right (camera x)
    along the body's left. Level at yaw 0 the image's top is north and its right west: the
    sun due east appears on the image's left.
    """
    for name, v in (("yaw_deg", yaw_deg), ("pitch_deg", pitch_deg), ("roll_deg", roll_deg)):
        if not np.isfinite(v):
            raise InvalidParameterError(f"{name} must be finite; got {v!r}")
    return Rotation.from_euler("ZXY", [-yaw_deg, pitch_deg, roll_deg], degrees=True) * _MOUNT


_FRAME_BLOCK_PX = 1 << 18
"""Pixels per block of rows when a camera's per-pixel frame is built (float64 temporaries of
a few tens of MB, whatever the sensor's size)."""

_MOUNT = Rotation.from_euler("z", 180.0, degrees=True)
"""Camera-to-body rotation ``R_bc`` of the upward-looking camera (:func:`camera_attitude`)."""


def camera_basis(directions):
    """``(theta, psi, e_theta, e_psi)`` of unit camera-frame directions ``(..., 3)``: angle from
    the optical axis and image azimuth [rad], and the unit vectors of increasing ``theta``
    and ``psi`` (the image's radial and tangential directions)."""
    d = np.asarray(directions, dtype=float)
    theta = np.arctan2(np.hypot(d[..., 0], d[..., 1]), d[..., 2])
    psi = np.arctan2(d[..., 1], d[..., 0])
    ct, st, cp, sp = np.cos(theta), np.sin(theta), np.cos(psi), np.sin(psi)
    e_theta = np.stack([ct * cp, ct * sp, -st], axis=-1)
    e_psi = np.stack([-sp, cp, np.zeros_like(sp)], axis=-1)
    return theta, psi, e_theta, e_psi


def _check_positive(name, value, allow_zero=False):
    v = float(value)
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise InvalidParameterError(f"{name} must be {'>= 0' if allow_zero else '> 0'}; "
                                    f"got {value!r}")
    return v


@dataclass(frozen=True, eq=False)
class MosaicSensor:
    """A W x H pixel sensor with a 2x2 micro-polarizer mosaic.

    Parameters
    ----------
    width, height : int
        Pixels; both even (whole super-pixels).
    layout_deg : 2x2 nested sequence
        Nominal polarizer angles [deg] of a super-pixel (rows, columns of the image as
        recorded), counter-clockwise in the displayed image from its right towards its top
        (:data:`DEFAULT_LAYOUT_DEG`).
    full_well_e : float
        Full-well capacity [e-].
    read_noise_e : float
        RMS read noise [e-].
    dark_current_e_s : float
        Dark current [e-/s].
    adc_bits : int
        ADC resolution, 8 to 16 bits.
    black_level_dn : int or None
        Offset added before quantisation [DN]; None: ``2**(adc_bits - 6)``.
    angle_error_deg : ndarray (H, W) or None
        Per-pixel polarizer-angle error [deg] (None: none).
    extinction_ratio : float or ndarray (H, W)
        Polarizer extinction ratio (> 1; ``inf`` for an ideal polarizer).
    gain : ndarray (H, W) or None
        Relative pixel response (photo-response non-uniformity; None: 1).
    crosstalk : float
        Fraction of a pixel's photoelectrons reaching each of its four edge neighbours, in
        [0, 0.25) (module doc; 0: none).
    """

    width: int
    height: int
    layout_deg: tuple = DEFAULT_LAYOUT_DEG
    full_well_e: float = 10500.0
    read_noise_e: float = 2.3
    dark_current_e_s: float = 3.0
    adc_bits: int = 12
    black_level_dn: int | None = None
    angle_error_deg: np.ndarray | None = None
    extinction_ratio: float | np.ndarray = np.inf
    gain: np.ndarray | None = None
    crosstalk: float = 0.0
    error_parameters: dict = field(default_factory=dict)

    def __post_init__(self):
        for name in ("width", "height"):
            n = getattr(self, name)
            if int(n) != n or n < 2 or n % 2:
                raise InvalidParameterError(f"{name} must be an even number of pixels >= 2; "
                                            f"got {n!r}")
        layout = np.asarray(self.layout_deg, dtype=float)
        if layout.shape != (2, 2) or not np.isfinite(layout).all():
            raise InvalidParameterError(f"layout_deg must be 2x2 finite angles; got "
                                        f"{self.layout_deg!r}")
        object.__setattr__(self, "layout_deg", tuple(map(tuple, layout.tolist())))
        if not (isinstance(self.adc_bits, (int, np.integer)) and 8 <= self.adc_bits <= 16):
            raise InvalidParameterError(f"adc_bits must be an integer in [8, 16]; got "
                                        f"{self.adc_bits!r}")
        _check_positive("full_well_e", self.full_well_e)
        _check_positive("read_noise_e", self.read_noise_e, allow_zero=True)
        _check_positive("dark_current_e_s", self.dark_current_e_s, allow_zero=True)
        if not (0.0 <= self.crosstalk < 0.25):
            raise InvalidParameterError(f"crosstalk must be in [0, 0.25) (the share of each of "
                                        f"four neighbours); got {self.crosstalk!r}")
        if self.black_level_dn is None:
            object.__setattr__(self, "black_level_dn", 2 ** (self.adc_bits - 6))
        if not (0 <= self.black_level_dn < self.max_dn // 2):
            raise InvalidParameterError(f"black_level_dn must be in [0, {self.max_dn // 2}) for "
                                        f"{self.adc_bits} bits; got {self.black_level_dn!r}")
        er = np.asarray(self.extinction_ratio, dtype=float)
        if np.any(~(er > 1.0)):
            raise InvalidParameterError(f"extinction_ratio must be > 1; got min {er.min()!r}")
        for name in ("angle_error_deg", "gain"):
            a = getattr(self, name)
            if a is not None and np.shape(a) != self.shape:
                raise InvalidParameterError(f"{name} must have shape {self.shape}; got "
                                            f"{np.shape(a)}")
        if np.ndim(er) and er.shape != self.shape:
            raise InvalidParameterError(f"extinction_ratio must be scalar or shape {self.shape}")

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)`` [px]."""
        return (int(self.height), int(self.width))

    @property
    def max_dn(self) -> int:
        """Largest ADC output [DN] (``2**adc_bits - 1``): the saturation value."""
        return 2 ** int(self.adc_bits) - 1

    @property
    def e_per_dn(self) -> float:
        """Conversion gain [e-/DN]: the full well spans the ADC range above the black level."""
        return self.full_well_e / (self.max_dn - self.black_level_dn)

    def nominal_angle_deg(self) -> np.ndarray:
        """Nominal polarizer angle of every pixel [deg], shape (H, W)."""
        return np.tile(np.asarray(self.layout_deg), (self.height // 2, self.width // 2))

    def analysis_vectors(self, ideal: bool = False) -> np.ndarray:
        """Per-pixel analysis vectors ``A`` (H, W, 3) (module doc); ``ideal``: without errors.
        A view of :meth:`analysis_planes`."""
        return np.moveaxis(self.analysis_planes(ideal), 0, -1)

    def analysis_planes(self, ideal: bool = False, dtype=np.float64) -> np.ndarray:
        """:meth:`analysis_vectors` as three contiguous planes (3, H, W) of ``dtype``."""
        out = np.empty((3,) + self.shape, dtype)
        two_a = np.radians(2.0 * np.asarray(self.layout_deg))
        if ideal or self.angle_error_deg is None:  # the 2x2 cell's cosines, tiled
            _tile_cell(np.cos(two_a), out[1])
            _tile_cell(np.sin(two_a), out[2])
        else:
            a = np.radians(2.0 * np.asarray(self.angle_error_deg))
            a += _tile_cell(two_a, np.empty(self.shape))
            np.cos(a, out=out[1], casting="same_kind")
            np.sin(a, out=out[2], casting="same_kind")
        if ideal:
            out[0] = 0.5
            out[1:] *= 0.5
            return out
        inv_er = 1.0 / np.asarray(self.extinction_ratio, float)
        g = 1.0 if self.gain is None else np.asarray(self.gain, float)
        out[0] = 0.5 * g * (1.0 + inv_er)
        out[1:] *= 0.5 * g * (1.0 - inv_er)
        return out

    def apply_crosstalk(self, electrons: np.ndarray) -> np.ndarray:
        """Crosstalk (module doc) on photoelectrons ``(..., H, W)``: ``(1 - 4c) e`` plus ``c``
        times the sum of the four edge neighbours, a missing neighbour on the border replaced
        by the pixel itself (energy conserving). Returns ``electrons`` itself when ``c = 0``,
        else a new array of its dtype."""
        c = float(self.crosstalk)
        e = np.asarray(electrons)
        if c == 0.0:
            return e
        nb = np.empty_like(e)
        nb[..., 1:, :] = e[..., :-1, :]
        nb[..., :1, :] = e[..., :1, :]
        nb[..., :-1, :] += e[..., 1:, :]
        nb[..., -1:, :] += e[..., -1:, :]
        nb[..., :, 1:] += e[..., :, :-1]
        nb[..., :, :1] += e[..., :, :1]
        nb[..., :, :-1] += e[..., :, 1:]
        nb[..., :, -1:] += e[..., :, -1:]
        nb *= c
        out = np.multiply(e, 1.0 - 4.0 * c)
        out += nb
        return out

    def with_random_errors(self, rng: np.random.Generator, *, angle_std_deg: float = 0.0,
                           mosaic_rotation_deg: float = 0.0, extinction_ratio: float = np.inf,
                           extinction_ratio_rel_std: float = 0.0,
                           gain_std: float = 0.0) -> "MosaicSensor":
        """A copy with per-pixel errors drawn from ``rng``.

        Parameters
        ----------
        angle_std_deg : float
            Standard deviation of the independent per-pixel polarizer-angle errors [deg].
        mosaic_rotation_deg : float
            Rotation of the whole polarizer array against the pixel grid [deg] (common to all
            pixels).
        extinction_ratio, extinction_ratio_rel_std : float
            Mean extinction ratio and its relative per-pixel standard deviation (log-normal).
        gain_std : float
            Relative standard deviation of the pixel response (PRNU).
        """
        er_mean = float(extinction_ratio)
        er = er_mean
        if np.isfinite(er_mean) and extinction_ratio_rel_std > 0:
            s = np.sqrt(np.log1p(extinction_ratio_rel_std ** 2))
            er = np.maximum(er_mean * rng.lognormal(-0.5 * s * s, s, self.shape), 1.0 + 1e-6)
        angle = mosaic_rotation_deg + angle_std_deg * rng.standard_normal(self.shape)
        gain = 1.0 + gain_std * rng.standard_normal(self.shape)
        params = {"angle_std_deg": angle_std_deg, "mosaic_rotation_deg": mosaic_rotation_deg,
                  "extinction_ratio": er_mean, "extinction_ratio_rel_std":
                  extinction_ratio_rel_std, "gain_std": gain_std}
        return replace(self, angle_error_deg=angle, extinction_ratio=er, gain=gain,
                       error_parameters=params)

    def describe(self) -> dict:
        """Sensor parameters for sidecars (per-pixel errors by their generating parameters)."""
        return {"width": int(self.width), "height": int(self.height),
                "layout_deg": [list(r) for r in self.layout_deg],
                "full_well_e": float(self.full_well_e), "read_noise_e": float(self.read_noise_e),
                "dark_current_e_s": float(self.dark_current_e_s), "adc_bits": int(self.adc_bits),
                "black_level_dn": int(self.black_level_dn), "saturation_dn": self.max_dn,
                "e_per_dn": self.e_per_dn, "crosstalk": float(self.crosstalk),
                # JSON has no infinity: an ideal polarizer's extinction ratio is written null
                "errors": {k: (v if np.isfinite(v) else None)
                           for k, v in self.error_parameters.items()}}


@dataclass(frozen=True, eq=False)
class Scene:
    """What reaches each pixel: camera-frame Stokes (H, W) of the sky (float64, or the
    float32 of a float32 sky), masks, and the view directions (computed when first asked
    for: a render does not need them)."""

    I: np.ndarray
    Q: np.ndarray
    U: np.ndarray
    valid: np.ndarray
    """in the image circle and above the horizon"""
    sun: np.ndarray
    """pixels covered by the sun disk (saturated)"""
    view: object = field(default=None, repr=False)
    """callable returning the view ``(elevation, azimuth)`` [deg] of every pixel, or None"""

    @functools.cached_property
    def _view(self):
        if self.view is None:
            z = np.zeros(self.valid.shape)
            return z, z
        el, az = self.view()
        return np.where(self.valid, el, 0.0), np.where(self.valid, az, 0.0)

    @property
    def view_elevation_deg(self) -> np.ndarray:
        """View elevation [deg] of every pixel (0 where not valid)."""
        return self._view[0]

    @property
    def view_azimuth_deg(self) -> np.ndarray:
        """View azimuth [deg, clockwise from north] of every pixel (0 where not valid)."""
        return self._view[1]

    @property
    def stokes(self) -> np.ndarray:
        return np.stack([self.I, self.Q, self.U], axis=-1)


@dataclass(frozen=True, eq=False)
class PolarizationCamera:
    """A fisheye lens on a :class:`MosaicSensor` (see the module doc for the signal chain).

    Parameters
    ----------
    lens : FisheyeLens
    sensor : MosaicSensor
    photoelectrons_per_s : float
        ``q`` [e-/s] for a scene radiance 1 in the sky model's unit.
    exit_pupil_px : float
        Exit-pupil distance [px] of the vignetting law; ``inf``: no vignetting.
    sun_radius_deg : float
        Angular radius of the saturating sun disk [deg].
    """

    lens: FisheyeLens
    sensor: MosaicSensor
    photoelectrons_per_s: float = 2.0e5
    exit_pupil_px: float = np.inf
    sun_radius_deg: float = SUN_RADIUS_DEG

    def __post_init__(self):
        _check_positive("photoelectrons_per_s", self.photoelectrons_per_s)
        if not self.exit_pupil_px > 0:
            raise InvalidParameterError(f"exit_pupil_px must be > 0 (inf: no vignetting); got "
                                        f"{self.exit_pupil_px!r}")

    @classmethod
    def fisheye(cls, width: int, height: int, *, fov_deg: float = 180.0,
                model: str = "equidistant", **kwargs) -> "PolarizationCamera":
        """A camera whose image circle fits the sensor (``kwargs``: sensor parameters, then
        camera parameters by name)."""
        cam_keys = {"photoelectrons_per_s", "exit_pupil_px", "sun_radius_deg"}
        cam = {k: kwargs.pop(k) for k in list(kwargs) if k in cam_keys}
        return cls(FisheyeLens.fitting(width, height, fov_deg, model),
                   MosaicSensor(width, height, **kwargs), **cam)

    @functools.cached_property
    def pixel_directions(self) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame unit directions (H, W, 3) of the pixel centres and the image-circle
        mask (H, W)."""
        rows, cols = np.indices(self.sensor.shape, dtype=float)
        return self.lens.back_project(rows, cols)

    @functools.cached_property
    def _in_circle(self) -> np.ndarray:
        """Image-circle mask (H, W): ``pixel_directions[1]`` without the directions."""
        out = np.empty(self.sensor.shape, bool)
        for rows, x, y in self._row_blocks():
            with np.errstate(invalid="ignore"):
                np.less_equal(self.lens.theta_rad(np.sqrt(np.add(x * x, y * y))),
                              self.lens.max_theta_rad, out=out[rows])
        return out

    def _row_blocks(self):
        """Blocks of rows of the sensor, ``(rows slice, x (W,), y (h, 1))`` with the
        image-plane coordinates [px] (:mod:`sensor.camera.lens`), so that per-pixel float64
        temporaries of a whole image stay a few MB."""
        h, w = self.sensor.shape
        x = np.arange(w, dtype=float) - self.lens.cx
        step = max(1, _FRAME_BLOCK_PX // w)
        for r0 in range(0, h, step):
            r1 = min(r0 + step, h)
            yield slice(r0, r1), x, (np.arange(r0, r1, dtype=float) - self.lens.cy)[:, None]

    def sky_pixels(self, attitude: Rotation) -> np.ndarray:
        """Pixels (H, W) in the image circle whose ray looks above the horizon for a camera at
        ``attitude`` (camera-to-ENU; the heading does not move the horizon), computed in
        blocks of rows without the camera's per-pixel directions."""
        up = attitude.inv().apply([0.0, 0.0, 1.0])
        out = np.empty(self.sensor.shape, bool)
        for rows, x, y in self._row_blocks():
            rho = np.hypot(x, y)
            with np.errstate(invalid="ignore", divide="ignore"):
                theta = self.lens.theta_rad(rho)
                radial = np.where(rho > 0, (x * up[0] + y * up[1]) / rho, 0.0)
            np.greater_equal(np.sin(theta) * radial + np.cos(theta) * up[2], 0.0,
                             out=out[rows])
            out[rows] &= theta <= self.lens.max_theta_rad
        return out

    @functools.cached_property
    def _rays(self):
        """Flat indices of the pixels in the image circle and their camera basis."""
        d_c, in_circle = self.pixel_directions
        rays = np.flatnonzero(in_circle)
        return rays, camera_basis(d_c.reshape(-1, 3)[rays])

    @functools.cached_property
    def _per_dtype(self) -> dict:
        return {}

    def _cached(self, key, make):
        out = self._per_dtype.get(key)
        if out is None:
            out = self._per_dtype[key] = make()
        return out

    def _analysis_components(self, ideal: bool, dtype) -> np.ndarray:
        """Analysis vectors with vignetting (:meth:`analysis_dn` per unit radiance rate) as
        three contiguous (H, W) planes of ``dtype``."""
        def make():
            planes = self.sensor.analysis_planes(ideal, dtype)
            if np.isfinite(self.exit_pupil_px):
                planes *= self.vignetting().astype(dtype)
            return planes
        return self._cached(("analysis", bool(ideal), np.dtype(dtype)), make)

    def _pixel_polar(self, dtype) -> np.ndarray:
        """Camera-fixed planes of every pixel's ray, (5, H, W) in ``dtype``: ``cos psi``,
        ``sin psi`` of its image azimuth, ``sin theta``, ``cos theta`` and ``1 - cos theta``
        of its angle from the optical axis (:mod:`sensor.camera.lens`); all zero outside the
        image circle. The ray is ``d = (sin theta cos psi, sin theta sin psi, cos theta)``
        and the sun's projections on its polarization axes follow in closed form
        (:func:`_sun_projections`)."""
        # The radius, the angle theta and the image azimuth's cosines come from float64 (the
        # radius squared of half-integer offsets is exact); the trigonometric functions of
        # theta run in the planes' dtype: in float32 they take a tenth of the float64 time
        # and miss the rounded float64 value by at most about one float32 ulp, the size of
        # the rounding to float32 that storing them already makes (the render's float32
        # error bounds are tested against float64).
        def make():
            t = np.dtype(dtype).type
            out = np.zeros((5,) + self.sensor.shape, t)
            circle = None if "_in_circle" in self.__dict__ else np.empty(self.sensor.shape,
                                                                          bool)
            for rows, x, y in self._row_blocks():
                rho = np.sqrt(np.add(x * x, y * y))
                with np.errstate(invalid="ignore", divide="ignore"):
                    theta = self.lens.theta_rad(rho)
                    inside = theta <= self.lens.max_theta_rad
                    theta = theta.astype(t, copy=False)
                    half = np.sin(np.multiply(theta, t(0.5)))
                    planes = (np.where(rho > 0, x / rho, 1.0), np.where(rho > 0, y / rho, 0.0),
                              np.sin(theta), np.cos(theta),
                              np.multiply(np.multiply(half, half), t(2.0)))
                if circle is not None:  # the image-circle mask on the way (as _in_circle)
                    circle[rows] = inside
                for k, plane in enumerate(planes):
                    np.copyto(out[k, rows], plane, casting="same_kind", where=inside)
            if circle is not None:
                self.__dict__["_in_circle"] = circle
            return out
        return self._cached(("polar", np.dtype(dtype)), make)

    def vignetting(self, rows=None, cols=None) -> np.ndarray:
        """Relative illumination ``V`` at pixel coordinates (default: every pixel centre)."""
        if rows is None:
            rows, cols = np.indices(self.sensor.shape, dtype=float)
        if not np.isfinite(self.exit_pupil_px):
            return np.ones(np.broadcast(rows, cols).shape)
        r2 = ((cols - self.lens.cx) ** 2 + (rows - self.lens.cy) ** 2) / self.exit_pupil_px ** 2
        return 1.0 / (1.0 + r2) ** 2

    def analysis_dn(self, exposure_s: float, ideal: bool = False) -> np.ndarray:
        """Per-pixel analysis vectors in DN per unit scene radiance (H, W, 3), vignetting
        included: the expected dark-subtracted pixel value is ``analysis_dn . S``.
        ``ideal``: the nominal polarizers (what a camera without calibration assumes)."""
        scale = self.photoelectrons_per_s * exposure_s / self.sensor.e_per_dn
        return np.moveaxis(self._analysis_components(ideal, np.float64), 0, -1) * scale

    def scene(self, sky, attitude: Rotation, sun_elevation_deg: float,
              sun_azimuth_deg: float) -> Scene:
        """Camera-frame Stokes of ``sky`` at every pixel for a camera at ``attitude``
        (camera-to-ENU rotation, :func:`camera_attitude`) and the given sun [deg].

        A :class:`skysim.sky.RayleighSky` is rendered in its own dtype from dot products of
        the sun with each pixel's camera-fixed frame (:func:`skysim.rayleigh.
        stokes_from_sun_projections`): no angles per pixel; any other sky through its
        :meth:`~skysim.sky.Sky.field` at each pixel's view direction.
        """
        if type(sky) is RayleighSky:
            return self._rayleigh_scene(sky, attitude, sun_elevation_deg, sun_azimuth_deg)
        d_c, in_circle = self.pixel_directions
        shape = self.sensor.shape
        rays, basis = self._rays
        idx, stokes, el, az = sky_stokes_camera(sky, attitude, sun_elevation_deg,
                                                sun_azimuth_deg, d_c.reshape(-1, 3)[rays],
                                                np.ones(rays.size, bool), basis=basis)
        idx = rays[idx]
        out = {k: np.zeros(shape) for k in ("I", "Q", "U", "el", "az")}
        for k, v in (("I", stokes[:, 0]), ("Q", stokes[:, 1]), ("U", stokes[:, 2]),
                     ("el", el), ("az", az)):
            out[k].reshape(-1)[idx] = v
        valid = np.zeros(shape, bool)
        valid.reshape(-1)[idx] = True
        s_c = attitude.inv().apply(_enu(sun_elevation_deg, sun_azimuth_deg))
        sun = np.zeros(shape, bool)
        sun.reshape(-1)[rays] = d_c.reshape(-1, 3)[rays] @ s_c >= self._sun_reach_cos(s_c)
        return Scene(out["I"], out["Q"], out["U"], valid, sun, lambda: (out["el"], out["az"]))

    def _sun_reach_cos(self, s_c) -> float:
        """Cosine of the angle from the sun within which a pixel centre is on the sun disk
        (its radius plus half a pixel at the sun's place in the image)."""
        sun_theta = np.arctan2(np.hypot(s_c[0], s_c[1]), s_c[2])
        return float(np.cos(np.radians(self.sun_radius_deg)
                            + 0.5 * float(self.lens.dtheta_dr(sun_theta))))

    def _sun_disk(self, polar: np.ndarray, s_c, work: np.ndarray) -> np.ndarray:
        """Pixels whose centre is on the sun disk (:meth:`_sun_reach_cos`), from the dot
        products of their rays (:meth:`_pixel_polar`) with the sun ``s_c`` in a box around
        the sun's image (the whole frame when the sun is outside the field of view)."""
        reach_cos = self._sun_reach_cos(s_c)
        sun = np.zeros(self.sensor.shape, bool)
        row, col = self.lens.project(s_c)
        if not (np.isfinite(row) and np.isfinite(col)):
            return np.greater_equal(_ray_dot(polar, s_c, out=work), reach_cos)
        # the smallest angle a pixel spans at the sun's place: radially dtheta/dr, tangentially
        # sin(theta) / r (1 / f on the axis)
        theta = float(np.arccos(np.clip(s_c[2], -1.0, 1.0)))
        r = float(self.lens.radius_px(theta))
        per_px = min(float(self.lens.dtheta_dr(theta)),
                     np.sin(theta) / r if r > 0 else 1.0 / self.lens.focal_px)
        k = int(np.ceil(np.arccos(reach_cos) / per_px)) + 2
        rows = slice(max(int(row) - k, 0), max(int(row) + k + 2, 0))
        cols = slice(max(int(col) - k, 0), max(int(col) + k + 2, 0))
        sun[rows, cols] = _ray_dot(polar[:, rows, cols], s_c) >= reach_cos
        return sun

    def _rayleigh_scene(self, sky, attitude, sun_elevation_deg, sun_azimuth_deg) -> Scene:
        """:meth:`scene` of a single-scattering sky: camera Stokes from the sun's projections
        on each pixel's polarization axes ``(e_0, e_90)`` (:func:`_sun_projections`), the
        horizon and the sun disk from dot products with the ray; all in the sky's dtype
        (float32: Stokes within a few 1e-7 of float64, tested)."""
        check_sun_above_horizon(sun_elevation_deg, sky.min_sun_elevation_deg)
        check_finite("sun_azimuth_deg", sun_azimuth_deg)
        polar = self._pixel_polar(sky.dtype)
        inside = self._in_circle
        inv = attitude.inv()
        s_c = inv.apply(_enu(sun_elevation_deg, sun_azimuth_deg))
        up_c = inv.apply([0.0, 0.0, 1.0])
        work = np.empty(self.sensor.shape, sky.dtype)
        # (e_0, e_90) is right-handed about -d: the E-vector d x s has the components
        # (p2, -p1) instead of (-p2, p1), the same axis, so the Stokes are the same
        i, q, u = rayleigh.stokes_from_sun_projections(*_sun_projections(polar, s_c, work),
                                                       sky.dmax)
        valid = np.greater_equal(_ray_dot(polar, up_c, out=work), 0.0)
        valid &= inside
        sun = self._sun_disk(polar, s_c, work)
        sun &= inside
        dark = ~valid
        for a in (i, q, u):
            np.copyto(a, 0.0, where=dark)  # one streaming pass, no gather

        def view():
            d_n = attitude.apply(self.pixel_directions[0].reshape(-1, 3))
            return tuple(x.reshape(self.sensor.shape) for x in elevation_azimuth(d_n))
        return Scene(i, q, u, valid, sun, view)

    def expected_electrons(self, scene: Scene, exposure_s: float) -> np.ndarray:
        """Mean photo- and dark electrons of every pixel (H, W) before noise and clipping, in
        the scene's dtype: photoelectrons (the sun disk's raised to the full well), then
        crosstalk, then dark current."""
        _check_positive("exposure_s", exposure_s)
        dtype = np.result_type(scene.I, np.float32)
        a0, a1, a2 = self._analysis_components(False, dtype)
        e = np.multiply(a0, scene.I, dtype=dtype)
        work = np.multiply(a1, scene.Q, dtype=dtype)
        e += work
        e += np.multiply(a2, scene.U, out=work, dtype=dtype)
        e *= self.photoelectrons_per_s * exposure_s
        np.maximum(e, self.sensor.full_well_e, out=e, where=scene.sun)
        e = self.sensor.apply_crosstalk(e)
        e += self.sensor.dark_current_e_s * exposure_s
        return e

    def auto_exposure_s(self, scene: Scene, fill: float = 0.6, percentile: float = 99.0):
        """Exposure [s] putting the ``percentile`` of the sky pixels (sun disk excluded) at
        ``fill`` of the full well."""
        sky = scene.valid & ~scene.sun
        if not sky.any():
            raise InvalidParameterError("no sky pixel in view: cannot set an exposure")
        per_s = self.expected_electrons(scene, 1.0)[sky]
        return float(fill * self.sensor.full_well_e / np.percentile(per_s, percentile))

    def digitise(self, electrons: np.ndarray) -> np.ndarray:
        """Clip electrons at the full well and convert to DN (uint16, black level added; read
        noise below zero electrons stays above 0 DN thanks to the black level). Works in the
        input's float dtype (float32 holds every DN of 16 bits exactly)."""
        s = self.sensor
        dn = np.minimum(electrons, s.full_well_e, dtype=np.result_type(electrons, np.float32))
        dn /= s.e_per_dn
        np.rint(dn, out=dn)
        dn += s.black_level_dn
        np.clip(dn, 0, s.max_dn, out=dn)
        return dn.astype(np.uint16)

    def noisy_frames(self, mean_electrons: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Raw frames (..., H, W) uint16 [DN] for mean electrons (..., H, W): photon and
        dark-current shot noise and read noise from ``rng``, full-well clipping, ADC.

        Shot noise is Poisson below :data:`POISSON_EXACT_BELOW_E` mean electrons; at and above
        it shot and read noise come from one skewness-corrected normal draw per pixel (see
        there). Works in the input's dtype.
        """
        lam = np.asarray(mean_electrons)
        shape = lam.shape
        lam = lam.reshape((1,) * (2 - lam.ndim) + shape)  # rows of pixels, whatever the shape
        dtype = np.result_type(lam, np.float32)
        read = float(self.sensor.read_noise_e)
        # every normal draw first, then every Poisson draw (the random stream of one frame
        # does not depend on the blocks below)
        z = rng.standard_normal(lam.shape, dtype=dtype)
        low = lam < POISSON_EXACT_BELOW_E
        poisson = None
        if low.any():
            poisson = rng.poisson(lam[low]) + read * z[low]
        # the normal law in blocks of rows: temporaries of a few hundred kB instead of four
        # frames (on a fresh process most of the time of a full-frame temporary is spent
        # faulting its memory in)
        raw = np.empty(lam.shape, np.uint16)
        h, w = lam.shape[-2:]
        step = max(1, _FRAME_BLOCK_PX // w)
        for lead in np.ndindex(lam.shape[:-2]):
            for r0 in range(0, h, step):
                at = lead + (slice(r0, min(r0 + step, h)),)
                lam_b, z_b = lam[at], z[at]
                var = np.add(lam_b, read * read, dtype=dtype)
                skew = np.divide(lam_b, var, dtype=dtype)
                skew *= 1.0 / 6.0
                e = np.multiply(z_b, z_b)
                e -= 1.0
                e *= skew
                np.sqrt(var, out=var)
                var *= z_b
                e += var
                e += lam_b
                raw[at] = self.digitise(e)
        if poisson is not None:
            raw[low] = self.digitise(poisson.astype(dtype, copy=False))
        return raw.reshape(shape)

    def capture(self, scene: Scene, exposure_s: float, rng: np.random.Generator) -> np.ndarray:
        """A raw mosaic image (H, W) uint16 [DN] of ``scene`` (:meth:`noisy_frames`); the sun
        disk saturated."""
        raw = self.noisy_frames(self.expected_electrons(scene, exposure_s), rng)
        raw[scene.sun] = self.sensor.max_dn
        return raw

    def calibration_frames(self, angles_deg, radiance: float, exposure_s: float,
                           n_frames: int, rng: np.random.Generator):
        """Flat-field calibration data: the mean of ``n_frames`` raw frames [DN] of a fully
        polarized uniform source of ``radiance`` at each polarizer angle [deg] (camera
        frame), shape (K, H, W), and the mean dark frame (H, W) (source off)."""
        a = np.radians(2.0 * np.asarray(angles_deg, dtype=float))
        if a.ndim != 1 or n_frames < 1:
            raise InvalidParameterError(f"angles_deg must be 1-D and n_frames >= 1; got "
                                        f"shape {a.shape}, n_frames={n_frames!r}")
        scenes = [(radiance, radiance * np.cos(x), radiance * np.sin(x)) for x in a] + [(0, 0, 0)]
        mean = np.stack([self.expected_electrons(self.uniform_scene(s), exposure_s)
                         for s in scenes])  # K + 1 sources, not samples
        frames = self.noisy_frames(np.broadcast_to(mean[:, None], (len(scenes), n_frames)
                                                   + mean.shape[1:]), rng)
        avg = frames.mean(axis=1)
        return avg[:-1], avg[-1]

    def uniform_scene(self, stokes) -> Scene:
        """A flat scene of camera-frame Stokes ``(I, Q, U)`` filling the image circle (an
        integrating sphere behind a polarizer in front of the lens)."""
        in_circle = self._in_circle
        i, q, u = (np.where(in_circle, float(v), 0.0) for v in stokes)
        return Scene(i, q, u, in_circle, np.zeros(self.sensor.shape, bool))

    def describe(self) -> dict:
        """Lens, sensor and radiometry for sidecars."""
        return {"lens": self.lens.describe(),
                "sensor": {**self.sensor.describe(),
                           "photoelectrons_per_s": float(self.photoelectrons_per_s),
                           "exit_pupil_px": None if not np.isfinite(self.exit_pupil_px)
                           else float(self.exit_pupil_px),
                           "sun_radius_deg": float(self.sun_radius_deg)}}


def sky_stokes_camera(sky, attitude: Rotation, sun_elevation_deg: float, sun_azimuth_deg: float,
                      directions, in_view, basis=None):
    """Camera Stokes ``(n, 3)`` (image polarization basis, :mod:`sensor.camera.lens`) of
    ``sky`` along camera-frame unit ``directions``
    ``(N, 3)`` where ``in_view`` (N,) holds and the ray looks above the horizon.

    ``basis``: :func:`camera_basis` of ``directions`` if already known. Returns
    ``(index, stokes, elevation_deg, azimuth_deg)`` of those ``n`` rays.
    """
    east, north, up = attitude.inv().apply(np.eye(3))  # ENU axes in the camera frame
    sin_el = np.clip(directions @ up, -1.0, 1.0)
    keep = np.asarray(in_view, bool) & (sin_el >= 0.0)
    if keep.all():  # a level camera: no copies
        idx, d_c = np.arange(len(keep)), directions
    else:
        idx = np.flatnonzero(keep)
        d_c, sin_el = directions[idx], sin_el[idx]
    el = np.degrees(np.arcsin(sin_el))
    az = np.mod(np.degrees(np.arctan2(d_c @ east, d_c @ north)), 360.0)
    fld = sky.field(el, az, sun_elevation_deg, sun_azimuth_deg)
    if basis is None:
        basis = camera_basis(directions)
    _, psi, e_th, e_ps = basis if keep.all() else (b[idx] for b in basis)
    # rotation of the Stokes basis from the local meridian (e_el, e_az) to camera x, y by the
    # camera-plane angle delta = beta + psi of e_el, where beta is the angle of the zenith's
    # component across the ray, (p, q) = (up . e_theta, up . e_psi), from e_theta (both bases
    # are right-handed about the ray); double angles without trigonometry. The image's
    # polarization angles count from x towards -y (lens module doc): U changes sign.
    p, q = e_th @ up, e_ps @ up
    with np.errstate(invalid="ignore", divide="ignore"):
        r2 = 1.0 / (p * p + q * q)
    c2b, s2b = (p * p - q * q) * r2, 2.0 * p * q * r2
    c2p, s2p = np.cos(2.0 * psi), np.sin(2.0 * psi)
    c2, s2 = c2b * c2p - s2b * s2p, s2b * c2p + c2b * s2p
    stokes = np.stack([fld.I, fld.Q * c2 - fld.U * s2, -(fld.Q * s2 + fld.U * c2)], axis=-1)
    return idx, stokes, el, az


def _tile_cell(cell: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out`` (H, W) filled with the 2x2 ``cell`` repeated (a strided copy: ``np.tile``
    repeats element by element, ten times slower on a sensor)."""
    h, w = out.shape
    out.reshape(h // 2, 2, w // 2, 2)[...] = np.asarray(cell)[None, :, None, :]
    return out


def _ray_dot(polar: np.ndarray, v, out=None) -> np.ndarray:
    """``d . v`` of every pixel's ray ``d`` (:meth:`PolarizationCamera._pixel_polar` planes
    ``(5, ...)``) with a camera-frame 3-vector ``v``: ``sin theta (cos psi v_x + sin psi v_y)
    + cos theta v_z``, in the planes' dtype; ``out``: a buffer to reuse."""
    t = polar.dtype.type
    out = np.multiply(polar[0], t(v[0]), out=out)
    out += polar[1] * t(v[1])
    out *= polar[2]
    out += polar[3] * t(v[2])
    return out


def _sun_projections(polar: np.ndarray, s, work: np.ndarray):
    """The sun's projections ``(p1, p2) = (s . e_0, s . e_90)`` on every pixel's polarization
    axes (:meth:`FisheyeLens.polarization_axes`), from the planes of
    :meth:`PolarizationCamera._pixel_polar`. With ``c, n = cos psi, sin psi``,
    ``u = 1 - cos theta``, ``m = s_x c + s_y n`` (the sun along the image radius) and
    ``k = u m + s_z sin theta``, the closed forms of ``e_0`` and ``e_90`` give
    ``p1 = s_x - c k`` and ``p2 = -s_y + n k`` (eight operations per pixel, no frame of
    nine planes). ``work``: an (H, W) buffer of the planes' dtype."""
    t = polar.dtype.type
    c, n, s_th, _, u = polar
    k = np.multiply(c, t(s[0]))
    k += np.multiply(n, t(s[1]), out=work)
    k *= u
    k += np.multiply(s_th, t(s[2]), out=work)
    p1 = np.multiply(c, k)
    np.subtract(t(s[0]), p1, out=p1)
    k *= n
    k -= t(s[1])
    return p1, k


def _enu(elevation_deg, azimuth_deg) -> np.ndarray:
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.array([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
