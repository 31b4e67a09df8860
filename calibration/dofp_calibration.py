"""Per-pixel calibration of a division-of-focal-plane polarimeter from flat polarized light.

The camera looks at a uniform, fully (or partly, ``dolp``) linearly polarized source of
radiance ``L`` at ``K >= 3`` known polarizer angles ``theta_k``, plus a dark frame. Each
pixel's mean reading is linear in the source's Stokes vector,

``d_k = A . S_k + b``,  ``S_k = L (1, p cos 2 theta_k, p sin 2 theta_k)``,  ``S_dark = 0``,

so its analysis vector ``A`` (gain, diattenuation and polarizer angle together, vignetting
included) and dark offset ``b`` follow by linear least squares, one small system per pixel
with one shared design matrix (Powell & Gruev 2013 [1]_, sect. 3, eqs. 7-9). The calibrated
analysis vectors then replace the nominal ones in the demosaicing's per-sample Stokes solve
(their eqs. 4-6; :func:`sensor.camera.demosaic`).

References
----------
.. [1] S. B. Powell, V. Gruev, "Calibration methods for division-of-focal-plane
   polarimeters", Opt. Express 21(18):21039-21055 (2013), doi:10.1364/OE.21.021039.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skysim.exceptions import InvalidParameterError

from .exceptions import RankDeficientError, TooFewSamplesError

__all__ = ["DofpCalibration", "calibrate_dofp", "calibration_design"]


@dataclass(frozen=True, eq=False)
class DofpCalibration:
    """Per-pixel calibration (:func:`calibrate_dofp`).

    Attributes
    ----------
    analysis_dn : ndarray (H, W, 3)
        Analysis vectors [DN per unit source radiance]; NaN outside the lit area.
    dark_dn : ndarray (H, W)
        Dark offset [DN] at the calibration exposure.
    residual_rms_dn : ndarray (H, W)
        RMS of the fit residuals [DN] (NaN with exactly 3 angles: no residual freedom).
    angles_deg : ndarray (K,)
    """

    analysis_dn: np.ndarray
    dark_dn: np.ndarray
    residual_rms_dn: np.ndarray
    angles_deg: np.ndarray

    @property
    def extinction_ratio(self) -> np.ndarray:
        """Per-pixel extinction ratio ``(A0 + |A12|) / (A0 - |A12|)`` [1]."""
        a = self.analysis_dn
        p = np.hypot(a[..., 1], a[..., 2])
        with np.errstate(divide="ignore", invalid="ignore"):
            return (a[..., 0] + p) / (a[..., 0] - p)

    @property
    def angle_deg(self) -> np.ndarray:
        """Per-pixel polarizer angle [deg, in [-90, 90)], counter-clockwise in the displayed
        image from its right towards its top (:mod:`sensor.camera.lens`)."""
        a = self.analysis_dn
        return np.mod(0.5 * np.degrees(np.arctan2(a[..., 2], a[..., 1])) + 90.0, 180.0) - 90.0


def calibration_design(angles_deg, radiance: float = 1.0, dolp: float = 1.0) -> np.ndarray:
    """Design matrix (K + 1, 4): rows ``(S_k, 1)`` of the lit frames, then ``(0, 0, 0, 1)``
    of the dark frame."""
    a = np.radians(2.0 * np.asarray(angles_deg, dtype=float))
    lit = np.c_[np.full(a.shape, radiance), radiance * dolp * np.cos(a),
                radiance * dolp * np.sin(a), np.ones(a.shape)]
    return np.vstack([lit, [0.0, 0.0, 0.0, 1.0]])


def calibrate_dofp(flat_frames_dn, dark_frame_dn, angles_deg, *, radiance: float = 1.0,
                   dolp: float = 1.0, saturation_dn: float | None = None) -> DofpCalibration:
    """Per-pixel analysis vectors and dark offsets from flat polarized frames.

    Parameters
    ----------
    flat_frames_dn : ndarray (K, H, W)
        Mean raw frames [DN] of the uniform source at each angle.
    dark_frame_dn : ndarray (H, W)
        Mean raw frame with the source off [DN], same exposure.
    angles_deg : array (K,)
        Source polarizer angles [deg], counter-clockwise in the displayed image from its
        right towards its top (:mod:`sensor.camera.lens`).
    radiance, dolp : float
        Source radiance (its unit becomes the calibration's) and degree of polarization.
    saturation_dn : float or None
        Pixels with a flat frame at or above it are left uncalibrated (NaN).

    Raises
    ------
    TooFewSamplesError
        Fewer than 3 angles.
    RankDeficientError
        Angles that do not determine the analysis vector (fewer than 3 distinct angles modulo
        180 deg, or ``dolp`` 0).
    InvalidParameterError
        For shapes that do not match.
    """
    angles = np.asarray(angles_deg, dtype=float)
    flats = np.asarray(flat_frames_dn, dtype=float)
    dark = np.asarray(dark_frame_dn, dtype=float)
    if angles.ndim != 1 or angles.size < 3:
        raise TooFewSamplesError(f"need at least 3 polarizer angles; got {angles.size}")
    if flats.shape != (angles.size,) + dark.shape or dark.ndim != 2:
        raise InvalidParameterError(f"flat_frames_dn must have shape (K={angles.size}, H, W) "
                                    f"matching dark_frame_dn; got {flats.shape} and "
                                    f"{dark.shape}")
    x = calibration_design(angles, radiance, dolp)
    if np.linalg.matrix_rank(x) < 4:
        raise RankDeficientError(f"polarizer angles {angles.tolist()} (dolp {dolp}) do not "
                                 "determine the analysis vectors: use at least 3 distinct "
                                 "angles modulo 180 deg, e.g. 0, 45, 90, 135")
    d = np.concatenate([flats, dark[None]]).reshape(angles.size + 1, -1)
    params = np.linalg.pinv(x) @ d
    resid = d - x @ params
    dof = x.shape[0] - 4
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.sum(resid ** 2, axis=0) / dof) if dof else np.full(d.shape[1], np.nan)
    shape = dark.shape
    analysis = params[:3].T.reshape(shape + (3,))
    lit = flats.max(axis=0) > dark + 1.0
    if saturation_dn is not None:
        lit &= flats.max(axis=0) < saturation_dn
    analysis[~lit] = np.nan
    return DofpCalibration(analysis, params[3].reshape(shape), rms.reshape(shape), angles)
