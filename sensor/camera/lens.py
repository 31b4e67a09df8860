"""Fisheye lens projection of a polarization camera.

Camera frame c (right-handed, the frame of OpenCV's and Kannala & Brandt's camera models [1]_
[2]_): x towards the image's right (increasing column), y towards the image's bottom
(increasing row), z along the optical axis into the scene. Pixel ``(row, col)`` has its
centre at integer indices, row 0 the image's top as the sensor records it; the image-plane
coordinates are ``x = col - cx``, ``y = row - cy`` [px]. A camera looking up with the image's
top to the north therefore sees the east on the image's **left**, like any photograph of the
sky taken from below (:func:`sensor.camera.camera_attitude`).

A ray from the camera into direction ``d`` (unit, camera frame) makes the angle
``theta = angle(d, z)`` with the optical axis and the azimuth ``psi = atan2(d_y, d_x)`` in the
image plane; the lens maps it to the radius ``r(theta)`` [px] at the image azimuth ``psi``:

- ``"equidistant"``: ``r = f theta``;
- ``"equisolid"``: ``r = 2 f sin(theta / 2)``

with the focal length ``f`` [px] ([1]_, eqs. 1b and 1c). The equidistant model is OpenCV's
fisheye model without distortion (``cv2.fisheye.projectPoints`` with ``D = 0``); the
equisolid one is its Kannala-Brandt polynomial with the Taylor coefficients of
``2 sin(theta / 2)`` (both tested against OpenCV on the same rays).

Polarization angles in the image (the micro-polarizers' angles, the camera's Stokes ``S1``,
``S2`` and its AoP) count counter-clockwise in the image as displayed (row 0 at the top):
from the image's right (+x) towards its top (-y), i.e. right-handed about the direction the
light travels (-z), the sense of an observer looking at the source. :meth:`FisheyeLens.
polarization_axes` carries the directions of 0 and 90 deg onto the sky.
References
----------
.. [1] J. Kannala, S. S. Brandt, "A generic camera model and calibration method for
   conventional, wide-angle, and fish-eye lenses", IEEE Trans. Pattern Anal. Mach. Intell.
   28(8):1335-1340 (2006), doi:10.1109/TPAMI.2006.153.
.. [2] OpenCV, "Fisheye camera model" (``cv::fisheye``), https://docs.opencv.org/4.x/db/d58/
   group__calib3d__fisheye.html (``u = f_x x' + c_x``, ``v = f_y y' + c_y``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skysim.exceptions import InvalidParameterError

__all__ = ["LENS_MODELS", "FisheyeLens"]

LENS_MODELS = ("equidistant", "equisolid")
"""Fisheye projections by name."""


@dataclass(frozen=True)
class FisheyeLens:
    """A rotationally symmetric fisheye lens.

    Parameters
    ----------
    focal_px : float
        Focal length [px], > 0.
    cx, cy : float
        Principal point [px]: column and row of the optical axis.
    fov_deg : float
        Full field of view [deg], in (0, 360); rays farther than ``fov_deg / 2`` from the
        optical axis do not reach the sensor. The equisolid model reaches at most 360 deg.
    model : {"equidistant", "equisolid"}
        Projection (see module doc).
    """

    focal_px: float
    cx: float
    cy: float
    fov_deg: float = 180.0
    model: str = "equidistant"

    def __post_init__(self):
        if self.model not in LENS_MODELS:
            raise InvalidParameterError(f"lens model must be one of {', '.join(LENS_MODELS)}; "
                                        f"got {self.model!r}")
        if not (np.isfinite(self.focal_px) and self.focal_px > 0):
            raise InvalidParameterError(f"focal_px must be > 0; got {self.focal_px!r}")
        if not (0.0 < self.fov_deg < 360.0):
            raise InvalidParameterError(f"fov_deg must be in (0, 360); got {self.fov_deg!r}")
        for name in ("cx", "cy"):
            if not np.isfinite(getattr(self, name)):
                raise InvalidParameterError(f"{name} must be finite; got {getattr(self, name)!r}")

    @classmethod
    def fitting(cls, width: int, height: int, fov_deg: float = 180.0,
                model: str = "equidistant") -> "FisheyeLens":
        """The lens whose image circle of ``fov_deg`` just fits the sensor's short side,
        centred on a ``width`` x ``height`` [px] sensor."""
        radius = 0.5 * min(width, height)
        half = np.radians(0.5 * fov_deg)
        unit_r = half if model == "equidistant" else 2.0 * np.sin(0.5 * half)
        return cls(focal_px=radius / unit_r, cx=0.5 * (width - 1), cy=0.5 * (height - 1),
                   fov_deg=fov_deg, model=model)

    @property
    def max_theta_rad(self) -> float:
        """Largest angle from the optical axis that reaches the sensor [rad]."""
        return np.radians(0.5 * self.fov_deg)

    def radius_px(self, theta_rad):
        """Image radius [px] of rays at ``theta_rad`` [rad] from the optical axis."""
        t = np.asarray(theta_rad, dtype=float)
        if self.model == "equidistant":
            return self.focal_px * t
        return 2.0 * self.focal_px * np.sin(0.5 * t)

    def theta_rad(self, radius_px):
        """Inverse of :meth:`radius_px` [rad]; NaN where no ray maps to the radius."""
        r = np.asarray(radius_px, dtype=float)
        if self.model == "equidistant":
            return r / self.focal_px
        with np.errstate(invalid="ignore"):
            return 2.0 * np.arcsin(r / (2.0 * self.focal_px))

    def dtheta_dr(self, theta_rad):
        """Angular size of one pixel along the radius [rad/px] at ``theta_rad``."""
        t = np.asarray(theta_rad, dtype=float)
        if self.model == "equidistant":
            return np.full_like(t, 1.0 / self.focal_px)
        return 1.0 / (self.focal_px * np.cos(0.5 * t))

    def project(self, directions):
        """Pixel coordinates ``(row, col)`` [px] of camera-frame directions ``(..., 3)``.

        Directions need not be normalised. Rays outside the field of view get NaN.
        """
        d = np.asarray(directions, dtype=float)
        rho = np.hypot(d[..., 0], d[..., 1])
        theta = np.arctan2(rho, d[..., 2])
        psi = np.arctan2(d[..., 1], d[..., 0])
        r = np.where(theta <= self.max_theta_rad, self.radius_px(theta), np.nan)
        return self.cy + r * np.sin(psi), self.cx + r * np.cos(psi)

    def back_project(self, row, col):
        """Unit camera-frame directions ``(..., 3)`` of pixel coordinates, and a validity mask.

        Returns
        -------
        directions : ndarray, shape ``broadcast(row, col).shape + (3,)``
            NaN where the pixel lies outside the image circle of the field of view.
        valid : ndarray of bool
        """
        x = np.asarray(col, dtype=float) - self.cx
        y = np.asarray(row, dtype=float) - self.cy
        theta = self.theta_rad(np.hypot(x, y))
        valid = np.isfinite(theta) & (theta <= self.max_theta_rad)
        psi = np.arctan2(y, x)
        st = np.sin(theta)
        d = np.stack([st * np.cos(psi), st * np.sin(psi), np.cos(theta)], axis=-1)
        d[~valid] = np.nan
        return d, valid

    def polarization_axes(self, row, col):
        """The image's directions of polarization 0 and 90 deg carried onto the sky at pixel
        coordinates, and the ray: camera-frame unit vectors ``(e_0, e_90, d)``, each of shape
        ``broadcast(row, col).shape + (3,)``; NaN outside the image circle.

        ``e_0`` is the image's x axis (its right), ``e_90`` its top (-y). With ``theta``,
        ``psi`` the ray's angle from the axis and its image azimuth and ``(e_theta, e_psi)``
        the unit vectors of increasing ``theta`` and ``psi`` across the ray, the image's
        axes are ``e_x = cos psi e_theta - sin psi e_psi`` and ``e_y = sin psi e_theta +
        cos psi e_psi``: an ideal rotationally symmetric lens keeps a ray's polarization
        components in its meridional plane (along ``e_theta``) and across it (``e_psi``) as
        the components along the image radius and tangent, so a polarization at the image
        angle ``chi`` (module doc) is ``cos chi e_0 + sin chi e_90`` on the sky (this is the
        polarization's transport, not the lens's geometric map of tangent vectors, which
        stretches the tangential direction by ``r / (f sin theta)``). ``(e_0, e_90)`` is
        right-handed about ``-d``, the direction the light travels.
        """
        x = np.asarray(col, dtype=float) - self.cx
        y = np.asarray(row, dtype=float) - self.cy
        rho = np.hypot(x, y)
        with np.errstate(invalid="ignore", divide="ignore"):
            c_psi = np.where(rho > 0, x / rho, 1.0)
            s_psi = np.where(rho > 0, y / rho, 0.0)
        theta = self.theta_rad(rho)
        theta = np.where(theta <= self.max_theta_rad, theta, np.nan)
        c_th, s_th = np.cos(theta), np.sin(theta)
        one_minus = 1.0 - c_th
        e_x = np.stack([c_th * c_psi * c_psi + s_psi * s_psi, -one_minus * c_psi * s_psi,
                        -s_th * c_psi], axis=-1)
        e_up = np.stack([one_minus * c_psi * s_psi, -(c_th * s_psi * s_psi + c_psi * c_psi),
                         s_th * s_psi], axis=-1)
        d = np.stack([s_th * c_psi, s_th * s_psi, c_th], axis=-1)
        return e_x, e_up, d

    def describe(self) -> dict:
        """Lens parameters for sidecars."""
        return {"model": self.model, "focal_px": float(self.focal_px), "cx": float(self.cx),
                "cy": float(self.cy), "fov_deg": float(self.fov_deg)}
