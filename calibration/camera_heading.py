"""Heading from one polarization-camera image: the solar meridian from the AoP pattern.

In a single-scattering sky the E-vector of every direction is perpendicular to the sun
(docs/conventions.md). With the camera's tilt from gravity (pitch, roll) known, the E-vector
of sample ``i`` in the levelled body frame (x right, y forward along the image's top, z up;
:func:`sensor.camera.camera_attitude` at yaw 0, its mount included) is ``w_i = R_tilt E_c,i``
and the sun, at
elevation ``e`` and at azimuth ``alpha = sun_azimuth - heading`` relative to the reference
axis, is ``b(alpha) = (cos e sin alpha, cos e cos alpha, sin e)``. The heading minimises

``sum_i rho(r_i / s)``,  ``r_i = w_i . b(alpha) = a_i . (sin alpha, cos alpha, 1)``,
``a_i = (cos e w_x, cos e w_y, sin e w_z)``

(linear in ``(sin alpha, cos alpha)``: the weighted cost is the quadratic form
``x^T M x`` with ``M = sum_i u_i a_i a_i^T``, scanned over alpha on a fine grid and refined by
Newton steps; each iteration is one pass over the samples to form the 3 x 3 matrix, the
minimisation itself is on that matrix alone). ``rho`` is Cauchy's loss by iteratively
reweighted least squares with the residual scale ``s`` from the median absolute deviation
(the steps shrink by a constant ratio, so Aitken's extrapolation jumps to their limit and the
next step confirms it), so clouds, trees and other pixels whose E-vector does not follow the
sky's pattern get a small weight; saturated pixels, the sun disk and samples of low DoLP
(ill-defined AoP) are excluded first. Prior weights ``S0 * DoLP^2`` follow the AoP variance
``~ 1 / (S0 DoLP^2)`` of shot-noise-limited pixels.

The uncertainty is the heteroscedasticity-consistent (sandwich) standard error of alpha
(White 1980 [1]_) from the final weights and residuals. Super-pixel samples have independent
noise; bilinear and centred samples share raw pixels with their neighbours, so their scores
are summed over blocks of 8 x 8 pixels first (cluster-robust form, Liang & Zeger 1986 [3]_).
Super-pixel residuals also carry the smooth error of their instantaneous field of view, which
is the same in every image and no noise: their score variance is taken from the differences
of horizontally adjacent samples, which cancel a smooth part (difference-based variance, Rice
1984 [4]_). It covers noise only, not a sky that departs from E perpendicular to the sun
(multiple scattering), which shows as a bias.

References
----------
.. [1] H. White, "A heteroskedasticity-consistent covariance matrix estimator and a direct
   test for heteroskedasticity", Econometrica 48(4):817-838 (1980), doi:10.2307/1912934.
.. [2] P. W. Holland, R. E. Welsch, "Robust regression using iteratively reweighted
   least-squares", Commun. Stat. Theory Methods 6(9):813-827 (1977),
   doi:10.1080/03610927708827533 (Cauchy weights, tuning constant 2.385).
.. [3] K.-Y. Liang, S. L. Zeger, "Longitudinal data analysis using generalized linear
   models", Biometrika 73(1):13-22 (1986), doi:10.1093/biomet/73.1.13.
.. [4] J. Rice, "Bandwidth choice for nonparametric regression", Ann. Stat. 12(4):1215-1230
   (1984), doi:10.1214/aos/1176346788 (variance from first differences).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sensor.camera.demosaic import StokesImage, image_e_vectors
from sensor.camera.mosaic import camera_attitude
from skysim.exceptions import InvalidParameterError
from skysim.validation import check_in_range

from .exceptions import ConvergenceError, TooFewSamplesError

__all__ = ["DEFAULT_DEMOSAIC", "LOSSES", "CameraHeading", "heading_from_image"]

DEFAULT_DEMOSAIC = "centred"
"""Demosaicing of the heading's command and studies: half resolution with the four channels
met at each super-pixel centre (:mod:`sensor.camera.demosaic`). Its noise-free heading error
on a Rayleigh sky is that of full-resolution bilinear (both below 0.011 deg on 128 px images,
0.0006 deg on 512 px, falling with the square of the resolution), where the plain super-pixel
is biased by its instantaneous field of view (2 deg on 128 px, 0.1 deg on 2048 px, tilted camera,
sun at 80 deg), at a quarter of bilinear's samples."""

_CAUCHY_C = 2.385
_CLUSTER_PX = 8
"""Side [px] of the blocks whose scores are summed for the standard error of interpolated
(correlated) samples: the bilinear kernel reaches one pixel, a channel's samples two."""
_GRID = np.radians(np.arange(0.0, 360.0, 0.25))
_SCALE_SAMPLES = 1 << 16
"""At most this many samples (an even stride through all) give the robust residual scale: the
MAD of 65536 samples has a relative standard error of 0.5 %, and the scale only sets the
width of the Cauchy loss."""


@dataclass(frozen=True)
class CameraHeading:
    """Result of :func:`heading_from_image`.

    Attributes
    ----------
    heading_deg : float
        Azimuth of the camera's reference axis (image top) [deg, in [0, 360)].
    sigma_deg : float
        Standard error of the heading [deg] (noise only, see module doc).
    n_used, n_rejected : int
        Samples in the fit, and samples given a weight below 0.1 by the robust loss.
    residual_scale : float
        Robust scale of the residuals ``cos(angle(E, sun))`` [1].
    ambiguity_ratio : float
        Cost of the best heading 180 deg away over the best cost (>> 1: unambiguous; near 1
        when the sun is close to the horizon, where E perpendicular to the sun cannot tell
        the sun from the anti-sun).
    iterations : int
    """

    heading_deg: float
    sigma_deg: float
    n_used: int
    n_rejected: int
    residual_scale: float
    ambiguity_ratio: float
    iterations: int


def _cost(m: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    x = np.stack([np.sin(alpha), np.cos(alpha), np.ones_like(alpha)])
    return np.einsum("in,ij,jn->n", x, m, x)


def _newton(m: np.ndarray, alpha: float) -> float:
    for _ in range(8):
        s, c = np.sin(alpha), np.cos(alpha)
        x, dx, ddx = np.array([s, c, 1.0]), np.array([c, -s, 0.0]), np.array([-s, -c, 0.0])
        g = 2 * x @ m @ dx
        h = 2 * (dx @ m @ dx + x @ m @ ddx)
        if h <= 0:
            break
        step = -g / h
        alpha += float(np.clip(step, -0.01, 0.01))
        if abs(step) < 1e-13:
            break
    return alpha


LOSSES = ("cauchy", "linear")
"""Losses of :func:`heading_from_image`: Cauchy's robust loss (default), or plain weighted
least squares (every usable sample keeps its prior weight: a reference showing what the
robust loss buys where clouds or trees break the pattern)."""


def heading_from_image(stokes: StokesImage, lens, sun_elevation_deg: float,
                       sun_azimuth_deg: float, *, pitch_deg: float = 0.0, roll_deg: float = 0.0,
                       min_dolp: float = 0.05, max_iter: int = 30,
                       loss: str = "cauchy") -> CameraHeading:
    """Heading of a camera from its Stokes image (see the module doc for the method).

    Parameters
    ----------
    stokes : StokesImage
        Demosaiced image (:func:`sensor.camera.demosaic`).
    lens : FisheyeLens
        The camera's lens (pixel -> ray).
    sun_elevation_deg, sun_azimuth_deg : float
        Sun position at the exposure [deg].
    pitch_deg, roll_deg : float
        Camera tilt from gravity [deg] (:func:`sensor.camera.camera_attitude`).
    min_dolp : float
        Samples of lower DoLP are excluded [1].
    loss : {"cauchy", "linear"}
        Cauchy's robust loss by reweighting (module doc), or weighted least squares with the
        prior weights alone (one solve, no reweighting).

    Raises
    ------
    TooFewSamplesError
        Fewer than 10 usable samples (overcast, blocked or overexposed image).
    ConvergenceError
        If the reweighting does not settle within ``max_iter`` iterations.
    """
    check_in_range("sun_elevation_deg", sun_elevation_deg, -10.0, 90.0)
    check_in_range("min_dolp", min_dolp, 0.0, 1.0, high_open=True)
    if loss not in LOSSES:
        raise InvalidParameterError(f"loss must be one of {', '.join(LOSSES)}; got {loss!r}")
    robust = loss == "cauchy"
    use = stokes.valid & (stokes.dolp >= min_dolp)
    n = int(use.sum())
    if n < 10:
        raise TooFewSamplesError(f"only {n} samples with DoLP >= {min_dolp} (need 10): the "
                                 "sky is overcast, blocked or saturated; lower the exposure "
                                 "or min_dolp")
    w = camera_attitude(0.0, pitch_deg, roll_deg).apply(image_e_vectors(stokes, lens, use))
    el = np.radians(sun_elevation_deg)
    # component-major (3, n): the 3 x 3 scatter matrix is one matrix product per iteration
    a = np.ascontiguousarray(w.T * np.array([[np.cos(el)], [np.cos(el)], [np.sin(el)]]))
    prior = stokes.S0[use] * stokes.dolp[use] ** 2
    prior = prior / prior.mean()
    u = prior.copy()
    alpha, scale = None, np.nan
    every = max(1, n // _SCALE_SAMPLES)
    sqrt_prior = np.sqrt(prior)
    prev_step = None
    au = np.empty_like(a)  # reused: a fresh 3 x n array per iteration costs page faults
    for it in range(1, max_iter + 1):
        m = np.multiply(a, u, out=au) @ a.T
        if alpha is None:
            grid_cost = _cost(m, _GRID)
            alpha0 = _GRID[np.argmin(grid_cost)]
        else:
            alpha0 = alpha
        new = _newton(m, alpha0)
        step = None if alpha is None else new - alpha
        if step is not None and prev_step is not None and abs(step) >= 1e-8 \
                and 0.0 < step / prev_step < 0.9:
            # the reweighting converges linearly (steps shrink by a constant ratio q):
            # Aitken's extrapolation jumps to the limit, the next step confirms it
            q = step / prev_step
            new += step * q / (1.0 - q)
            step, prev_step = None, None
        else:
            prev_step = step
        r = np.array([np.sin(new), np.cos(new), 1.0]) @ a
        z = r * sqrt_prior
        zs = z[::every]
        scale = 1.4826 * np.median(np.abs(zs - np.median(zs)))
        alpha = new
        if not robust:   # least squares: the prior weights, one solve
            break
        u = prior / (1.0 + (z / (_CAUCHY_C * max(scale, 1e-12))) ** 2)
        if step is not None and abs(step) < 1e-8:  # rad: 6e-7 deg
            break
    else:
        raise ConvergenceError(f"heading did not settle in {max_iter} reweighting iterations",
                               iterations=max_iter)
    m = np.multiply(a, u, out=au) @ a.T
    best = _cost(m, np.array([alpha]))[0]
    other = _cost(m, np.array([_newton(m, alpha + np.pi)]))[0]
    jac = np.array([np.cos(alpha), -np.sin(alpha), 0.0]) @ a
    score = u * jac * r
    if stokes.method != "superpixel":  # neighbours share raw pixels: sum scores per cluster
        rows, cols = stokes.row[use].astype(int), stokes.col[use].astype(int)
        key = (rows // _CLUSTER_PX) * (int(cols.max()) // _CLUSTER_PX + 1) + cols // _CLUSTER_PX
        score = np.bincount(key, weights=score)  # empty clusters add nothing below
        meat = np.sum(score ** 2)
    else:
        grid = np.zeros(use.shape)
        grid[use] = score
        pair = use[:, 1:] & use[:, :-1]
        diff = (grid[:, 1:] - grid[:, :-1])[pair]
        meat = n * 0.5 * np.mean(diff ** 2)
    # M-estimator sandwich: the bread is the derivative of the weighted score, psi'(z)
    # (1 for least squares)
    q = (z / (_CAUCHY_C * max(scale, 1e-12))) ** 2 if robust else np.zeros_like(z)
    bread = np.sum(prior * (1.0 - q) / (1.0 + q) ** 2 * jac ** 2)
    sigma = np.sqrt(meat) / bread
    heading = float(np.mod(sun_azimuth_deg - np.degrees(alpha), 360.0))
    return CameraHeading(heading, float(np.degrees(sigma)), n,
                         int(np.sum(u < 0.1 * prior)), float(scale),
                         float(other / best) if best > 0 else np.inf, it)
