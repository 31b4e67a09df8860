"""Demosaicing a raw DoFP mosaic into Stokes images, DoLP and AoP.

Every method solves, for each output sample, the linear system ``d = A S`` of the four
polarizer channels ``d`` (dark-subtracted [DN]) with their analysis vectors ``A`` (4 x 3; the
nominal polarizers or a per-pixel calibration, Powell & Gruev 2013 [1]_, eqs. 4-6) by least
squares, ``S = (A^T A)^-1 A^T d``. The methods differ in where the four channels come from:

- ``"bilinear"`` (default): each channel and its analysis vectors are interpolated to every
  pixel with the bilinear kernel ``[[1, 2, 1], [2, 4, 2], [1, 2, 1]] / 4`` as a normalised
  convolution (masked pixels carry no weight) [2]_. Full resolution, and the four channels
  meet at the same point, so no instantaneous-field-of-view error: on a smooth sky the
  super-pixel's error biases the heading (0.7 deg at 70 deg sun elevation on a 128 x 128
  fisheye image, halving with each doubling of the resolution), the bilinear one does not
  (< 0.001 deg). Neighbouring outputs share raw pixels, so their noise is correlated.
- ``"centred"``: half resolution like the super-pixel, but each channel (value and analysis
  vector) is interpolated bilinearly from its own sub-grid to the super-pixel centre, with
  weights ``(3/4, 1/4)`` along each axis (the normalised convolution again), so the four
  channels meet at the same point: no first-order instantaneous-field-of-view error (exact for
  fields linear in the pixel coordinates, like bilinear) at a quarter of the samples, which
  makes it the fast path for the heading. A sample is valid where all 16 raw pixels of its
  stencil are measured (none saturated or masked: no extrapolation at the edges of masks).
  Neighbouring outputs share raw pixels. Its linear map depends on the analysis vectors only
  (:func:`demosaic_operator`), so a camera's nominal one is computed once.
- ``"superpixel"``: each 2x2 block gives one Stokes vector at the block centre
  (half resolution). Each block uses only its own four pixels, so a calibrated pixel's
  analysis vector applies exactly, a saturated or masked pixel spoils only its block, and the
  output samples have independent noise; a quarter of the samples and faster. The four
  pixels see directions half a pixel apart: the error is the field's change across one pixel
  (instantaneous-field-of-view error, [2]_).

Stokes ``S1``, ``S2`` and the AoP are in the image's polarization basis: angles
counter-clockwise in the displayed image from its right towards its top (Sony's and
polanalyser's sense, ``S1 = I0 - I90``, ``S2 = I45 - I135`` for ideal polarizers;
:mod:`sensor.camera.lens`); :func:`local_meridian_aop` converts the AoP to skysim's
local-meridian convention (docs/conventions.md).

References
----------
.. [1] S. B. Powell, V. Gruev, "Calibration methods for division-of-focal-plane
   polarimeters", Opt. Express 21(18):21039-21055 (2013), doi:10.1364/OE.21.021039.
.. [2] S. Gao, V. Gruev, "Bilinear and bicubic interpolation methods for division of
   focal plane polarimeters", Opt. Express 19(27):26161-26173 (2011),
   doi:10.1364/OE.19.026161.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from skysim.exceptions import InvalidParameterError
from skysim.geometry import aop_from_e_vector, elevation_azimuth, wrap_axial_deg

from .mosaic import camera_basis

__all__ = ["DEMOSAIC_METHODS", "DemosaicOperator", "StokesImage", "camera_stokes", "demosaic",
           "demosaic_operator", "local_meridian_aop", "solve_stokes", "e_vectors_camera",
           "image_e_vectors"]

DEMOSAIC_METHODS = ("bilinear", "centred", "superpixel")


@dataclass(frozen=True, eq=False)
class StokesImage:
    """Linear Stokes images in the image's polarization basis (module doc).

    Attributes
    ----------
    S0, S1, S2 : ndarray (h, w)
        Stokes parameters in the unit of the analysis vectors' inverse (scene radiance when
        the analysis is in DN per radiance); NaN where not ``valid``.
    valid : ndarray of bool (h, w)
        All four channels measured, none saturated or masked.
    row, col : ndarray (h, w)
        Sensor pixel coordinates [px] of each sample.
    method : str
    """

    S0: np.ndarray
    S1: np.ndarray
    S2: np.ndarray
    valid: np.ndarray
    row: np.ndarray
    col: np.ndarray
    method: str

    @functools.cached_property
    def dolp(self) -> np.ndarray:
        """Degree of linear polarization ``sqrt(S1^2 + S2^2) / S0``."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.hypot(self.S1, self.S2) / self.S0

    @functools.cached_property
    def aop_camera_deg(self) -> np.ndarray:
        """AoP [deg, in [-90, 90)] in the image: counter-clockwise from its right towards its
        top (:mod:`sensor.camera.lens`)."""
        return wrap_axial_deg(0.5 * np.degrees(np.arctan2(self.S2, self.S1)))


def solve_stokes(analysis: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Least-squares Stokes ``(..., 3)`` from channel values ``(..., n)`` and analysis
    vectors ``(..., n, 3)`` (normal equations, closed-form symmetric 3x3 inverse; NaN where
    singular)."""
    return _solve_normal(np.moveaxis(analysis, (-2, -1), (0, 1)), np.moveaxis(values, -1, 0))


_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _solve_normal(a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """:func:`solve_stokes` for channel-first arrays: ``a`` (n, 3, ...), ``d`` (n, ...)."""
    m = [np.sum(a[:, i] * a[:, j], axis=0) for i, j in _PAIRS]
    b = [np.sum(a[:, i] * d, axis=0) for i in range(3)]
    return _solve_terms(m, b)


def _inverse_terms(m):
    """Inverse of the symmetric 3x3 matrices ``m = (m00, m11, m22, m01, m02, m12)`` (arrays)
    by the adjugate, as the full 3x3 nested list: elementwise arithmetic only (NaN or inf
    where singular)."""
    m00, m11, m22, m01, m02, m12 = m
    c00, c11, c22 = m11 * m22 - m12 * m12, m00 * m22 - m02 * m02, m00 * m11 - m01 * m01
    c01, c02, c12 = m02 * m12 - m01 * m22, m01 * m12 - m02 * m11, m01 * m02 - m00 * m12
    with np.errstate(all="ignore"):
        inv = 1.0 / (m00 * c00 + m01 * c01 + m02 * c02)
        c00, c11, c22, c01, c02, c12 = (c * inv for c in (c00, c11, c22, c01, c02, c12))
    return [[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]]


def _solve_terms(m, b) -> np.ndarray:
    """Solve the symmetric 3x3 normal equations given as ``m = (m00, m11, m22, m01, m02,
    m12)`` and ``b = (b0, b1, b2)`` (arrays) by the adjugate: elementwise arithmetic only."""
    inv = _inverse_terms(m)
    with np.errstate(invalid="ignore"):
        return np.stack([row[0] * b[0] + row[1] * b[1] + row[2] * b[2] for row in inv], axis=-1)


def _upsample(v: np.ndarray, offset: int, axis: int) -> np.ndarray:
    """Bilinear 2x upsampling along ``axis`` of one channel's sub-grid ``v`` (indices
    ``offset``, ``offset + 2``, ... of the full grid): the zero-filled full grid correlated
    with ``[1, 2, 1] / 2``, i.e. own samples copied and those between averaged (zero beyond the
    border), by slicing instead of a convolution over the zeros."""
    def at(sl):
        return (slice(None),) * (axis % v.ndim) + (sl,)
    shape = list(v.shape)
    shape[axis] *= 2
    out = np.empty(shape)
    out[at(slice(offset, None, 2))] = v
    between = out[at(slice(1 - offset, None, 2))]
    pairs = 0.5 * (v[at(slice(None, -1))] + v[at(slice(1, None))])
    if offset == 0:  # index 2k+1 lies between sub-grid samples k and k+1
        between[at(slice(None, -1))] = pairs
        between[at(-1)] = 0.5 * v[at(-1)]
    else:  # index 2k lies between sub-grid samples k-1 and k
        between[at(slice(1, None))] = pairs
        between[at(0)] = 0.5 * v[at(0)]
    return out


def _toward_centre(v: np.ndarray, offset: int, axis: int) -> np.ndarray:
    """One channel's sub-grid ``v`` (indices ``offset``, ``offset + 2``, ... of the full grid)
    interpolated along ``axis`` to the super-pixel centres ``2k + 1/2``: ``3/4`` of sample
    ``k`` and ``1/4`` of its neighbour on the centre's side (zero beyond the border)."""
    def at(sl):
        return (slice(None),) * (axis % v.ndim) + (sl,)
    out = np.multiply(v, 0.75)
    if offset == 0:  # centre 2k + 1/2 lies between samples k and k + 1
        out[at(slice(None, -1))] += 0.25 * v[at(slice(1, None))]
    else:  # centre 2k + 1/2 lies between samples k - 1 and k
        out[at(slice(1, None))] += 0.25 * v[at(slice(None, -1))]
    return out


_RESAMPLE = {
    "bilinear": lambda v, i, j: _upsample(_upsample(v, i, 1), j, 2),
    "centred": lambda v, i, j: _toward_centre(_toward_centre(v, i, 1), j, 2),
    "superpixel": lambda v, i, j: v,
}
"""How each method carries a channel's sub-grid (row offset ``i``, column offset ``j``) to its
output grid: full resolution (bilinear) or the super-pixel centres."""

_DTYPE = {"bilinear": np.float64, "centred": np.float32, "superpixel": np.float64}
"""Arithmetic of each method: the centred fast path in float32 (Stokes within a few 1e-7
relative of float64, tested), the others in float64."""


_CHANNELS = ((0, 0), (0, 1), (1, 0), (1, 1))
"""Row and column offsets of the four mosaic channels in a super-pixel."""


@dataclass(frozen=True, eq=False)
class DemosaicOperator:
    """The linear map of a half-resolution method (``"centred"``, ``"superpixel"``) for one
    set of analysis vectors: ``S = sum_k P_k R_k(d)`` at every sample whose stencil is all
    measured, with ``R_k`` the channel's resampling (:data:`_RESAMPLE`).

    Attributes
    ----------
    method : str
    P : ndarray (4, 3, h, w)
        Per channel, the row of the least-squares pseudo-inverse divided by the channel's
        resampled weight ``R_k(1)``.
    weight : ndarray (4, h, w)
        ``R_k(1)``: a sample's stencil is complete where ``R_k(good) == R_k(1)`` for all ``k``.
    """

    method: str
    P: np.ndarray
    weight: np.ndarray


def demosaic_operator(analysis_dn, method: str = "centred") -> DemosaicOperator:
    """:class:`DemosaicOperator` of analysis vectors ``(H, W, 3)`` [DN per unit radiance]:
    per sample, the analysis vector of each channel resampled to the sample (normalised by its
    weight) and the inverse of the 4-channel normal matrix. Depends on the analysis only, so a
    camera computes it once for its nominal analysis (:func:`camera_stokes`)."""
    if method not in ("centred", "superpixel"):
        raise InvalidParameterError(
            f"a demosaicing operator is for 'centred' or 'superpixel'; got "
            f"{method!r}")
    analysis = np.asarray(analysis_dn)
    dtype = _DTYPE[method]
    shape = (analysis.shape[0] // 2, analysis.shape[1] // 2)
    m = [np.zeros(shape, dtype) for _ in _PAIRS]
    ahat, weight = [], np.empty((4,) + shape, dtype)
    for k, (i, j) in enumerate(_CHANNELS):
        stack = np.empty((4,) + shape, dtype)
        stack[0] = 1.0
        for c in range(3):
            stack[1 + c] = analysis[i::2, j::2, c]
        q = _RESAMPLE[method](stack, i, j)
        weight[k] = q[0]
        q[1:] /= q[0]  # > 0: every sample has weight from its own block
        for t, (u, v) in zip(m, _PAIRS):
            t += q[1 + u] * q[1 + v]
        ahat.append(q[1:])
    inv = _inverse_terms(m)
    P = np.empty((4, 3) + shape, dtype)
    with np.errstate(all="ignore"):  # singular where the analysis is missing: NaN, invalid
        for k in range(4):
            for c in range(3):
                P[k, c] = (inv[c][0] * ahat[k][0] + inv[c][1] * ahat[k][1]
                           + inv[c][2] * ahat[k][2]) / weight[k]
    return DemosaicOperator(method, P, weight)


def _apply_operator(op: DemosaicOperator, d, good):
    """Stokes ``(h, w, 3)`` of ``op`` on dark-subtracted values ``d`` (zero where not
    ``good``), and where each sample's stencil is complete."""
    shape = op.weight.shape[1:]
    s = np.zeros((3,) + shape, op.P.dtype)
    complete = np.ones(shape, bool)
    work = np.empty(shape, op.P.dtype)
    for k, (i, j) in enumerate(_CHANNELS):
        stack = np.empty((2,) + shape, op.P.dtype)
        stack[0] = good[i::2, j::2]
        stack[1] = d[i::2, j::2]
        q = _RESAMPLE[op.method](stack, i, j)
        complete &= q[0] == op.weight[k]
        for c in range(3):
            s[c] += np.multiply(op.P[k, c], q[1], out=work)
    return np.moveaxis(s, 0, -1), complete


def _interpolated(d, analysis, good, method):
    """Least-squares Stokes of the four channels on ``method``'s output grid.

    Each channel's weight (1 for a good pixel, else 0), weighted value and weighted analysis
    vector are taken from its sub-grid, resampled (:data:`_RESAMPLE`) and normalised by the
    resampled weight (a normalised convolution: bad pixels carry no weight), then the normal
    equations of the four channels are accumulated and solved. Returns the Stokes
    ``(h, w, 3)`` and where every channel had support.
    """
    dtype = _DTYPE[method]
    shape = d.shape if method == "bilinear" else (d.shape[0] // 2, d.shape[1] // 2)
    m = [np.zeros(shape, dtype) for _ in _PAIRS]
    b = [np.zeros(shape, dtype) for _ in range(3)]
    support = np.ones(shape, bool)
    for i, j in _CHANNELS:  # four channels, accumulated one at a time
        g = good[i::2, j::2]
        stack = np.empty((5,) + g.shape, dtype)
        stack[0] = g
        np.multiply(d[i::2, j::2], stack[0], out=stack[1])
        for c in range(3):
            np.multiply(analysis[i::2, j::2, c], stack[0], out=stack[2 + c])
        q = _RESAMPLE[method](stack, i, j)
        support &= q[0] > 0
        q[1:] *= np.divide(1.0, q[0], out=np.zeros_like(q[0]), where=q[0] > 0)
        work = np.empty(shape, dtype)
        for t, (u, v) in zip(m, _PAIRS):
            t += np.multiply(q[2 + u], q[2 + v], out=work)
        for c, t in enumerate(b):
            t += np.multiply(q[2 + c], q[1], out=work)
    return _solve_terms(m, b), support


def demosaic(raw_dn, analysis_dn, *, black_level_dn: float = 0.0, valid=None,
             saturation_dn: float | None = None, method: str = "bilinear",
             operator: DemosaicOperator | None = None) -> StokesImage:
    """Stokes images from a raw mosaic.

    Parameters
    ----------
    raw_dn : ndarray (H, W)
        Raw image [DN].
    analysis_dn : ndarray (H, W, 3)
        Per-pixel analysis vectors [DN per unit radiance], e.g.
        :meth:`PolarizationCamera.analysis_dn` (nominal) or a calibration's.
    black_level_dn : float or ndarray (H, W)
        Dark offset subtracted first [DN] (a calibration's per-pixel dark frame, or the black
        level).
    valid : ndarray of bool (H, W) or None
        Pixels that see the sky (e.g. the image circle above the horizon).
    saturation_dn : float or None
        Pixels at or above this value are excluded (with their super-pixel).
    method : {"bilinear", "centred", "superpixel"}
        See the module doc (bilinear is the default: full resolution and no
        instantaneous-field-of-view error).
    operator : DemosaicOperator or None
        :func:`demosaic_operator` of ``analysis_dn`` for ``method`` if already known (the
        half-resolution methods; computed here otherwise).

    Raises
    ------
    InvalidParameterError
        For an unknown method (the message lists the valid ones), shapes that do not match
        or an odd image size.
    """
    if method not in DEMOSAIC_METHODS:
        raise InvalidParameterError(
            f"demosaicing method must be one of {', '.join(DEMOSAIC_METHODS)}; "
            f"got {method!r}")
    raw = np.asarray(raw_dn)
    if raw.ndim != 2 or raw.shape[0] % 2 or raw.shape[1] % 2:
        raise InvalidParameterError(f"raw image must be 2-D with even sides; got shape "
                                    f"{raw.shape}")
    analysis = np.asarray(analysis_dn, dtype=float)
    if analysis.shape != raw.shape + (3,):
        raise InvalidParameterError(f"analysis_dn must have shape {raw.shape + (3,)}; got "
                                    f"{analysis.shape}")
    good = np.ones(raw.shape, bool) if raw.dtype.kind in "iu" else np.isfinite(raw)
    if not np.isfinite(np.sum(analysis)):  # one fast pass when all is finite
        bad_a = ~np.isfinite(analysis).all(-1)
        good &= ~bad_a
        analysis = np.where(bad_a[..., None], 0.0, analysis)
    if valid is not None:
        good &= np.asarray(valid, bool)
    if saturation_dn is not None:
        good &= raw < saturation_dn
    d = np.subtract(raw, black_level_dn, dtype=_DTYPE[method])
    np.copyto(d, 0.0, where=~good)
    if method == "bilinear":
        s, ok = _interpolated(d, analysis, good, method)
        row, col = np.indices(d.shape, dtype=float)
        ok &= good
    else:
        if operator is None:
            operator = demosaic_operator(analysis, method)
        elif operator.method != method or operator.P.shape[2:] != (d.shape[0] // 2,
                                                                   d.shape[1] // 2):
            raise InvalidParameterError(f"operator is for {operator.method!r} on "
                                        f"{operator.P.shape[2:]} samples; need {method!r} on "
                                        f"{(d.shape[0] // 2, d.shape[1] // 2)}")
        s, ok = _apply_operator(operator, d, good)  # ok: every stencil pixel measured
        h, w = ok.shape
        row, col = np.meshgrid(2.0 * np.arange(h) + 0.5, 2.0 * np.arange(w) + 0.5,
                               indexing="ij")
    ok &= np.isfinite(s).all(-1)
    s = np.where(ok[..., None], s, np.nan)
    return StokesImage(s[..., 0], s[..., 1], s[..., 2], ok, row, col, method)


def e_vectors_camera(lens, row, col, s1, s2):
    """Camera-frame unit E-vectors (..., 3) and ray directions (..., 3) at pixel coordinates
    for the linear Stokes ``s1``, ``s2`` there: ``cos chi e_0 + sin chi e_90`` with ``chi``
    the AoP in the image and ``e_0``, ``e_90`` its polarization directions carried onto the
    sky (:meth:`FisheyeLens.polarization_axes`)."""
    e_0, e_90, d = lens.polarization_axes(row, col)
    c_chi, s_chi = _half_angle(s1, s2)
    return c_chi[..., None] * e_0 + s_chi[..., None] * e_90, d


def _half_angle(s1, s2):
    """``(cos chi, sin chi)`` of the AoP ``chi`` in [-90, 90] [deg] of linear Stokes
    ``(s1, s2)`` by half-angle identities instead of an arctangent:
    ``cos chi = sqrt((1 + cos 2chi) / 2) >= 0``, ``sin chi`` with the sign of ``s2``."""
    with np.errstate(invalid="ignore", divide="ignore"):
        c2 = s1 / np.hypot(s1, s2)
    c_chi = np.sqrt(np.clip(0.5 * (1.0 + c2), 0.0, 1.0))
    s_chi = np.copysign(np.sqrt(np.clip(0.5 * (1.0 - c2), 0.0, 1.0)), s2)
    return c_chi, s_chi


def image_e_vectors(stokes: StokesImage, lens, where) -> np.ndarray:
    """:func:`e_vectors_camera` of the samples ``where`` (mask over ``stokes``) of a Stokes
    image on a demosaicing grid, shape (n, 3): the grid's polarization axes come from a small cache
    (they depend on the lens and the grid only)."""
    rows, cols = stokes.row, stokes.col
    h, w = rows.shape
    grid = (float(rows[0, 0]), float(cols[0, 0]),
            float(rows[1, 0] - rows[0, 0]) if h > 1 else 1.0,
            float(cols[0, 1] - cols[0, 0]) if w > 1 else 1.0)
    axes = _grid_axes(lens, (h, w), grid)
    if not (np.array_equal(rows, axes[2]) and np.array_equal(cols, axes[3])):
        return e_vectors_camera(lens, rows[where], cols[where], stokes.S1[where],
                                stokes.S2[where])[0]
    c_chi, s_chi = _half_angle(stokes.S1[where], stokes.S2[where])
    return c_chi[:, None] * axes[0][where] + s_chi[:, None] * axes[1][where]


@functools.lru_cache(maxsize=2)
def _grid_axes(lens, shape, grid):
    """Polarization axes ``e_0``, ``e_90`` (h, w, 3) and the pixel coordinates of a regular
    grid ``(row0, col0, row_step, col_step)`` of ``shape``."""
    r0, c0, dr, dc = grid
    rows, cols = np.meshgrid(r0 + dr * np.arange(shape[0]), c0 + dc * np.arange(shape[1]),
                             indexing="ij")
    e_0, e_90, _ = lens.polarization_axes(rows, cols)
    return e_0, e_90, rows, cols


def local_meridian_aop(stokes: StokesImage, lens, attitude: Rotation):
    """View elevation, azimuth and AoP in skysim's local-meridian convention [deg] of each
    sample of a Stokes image taken at ``attitude`` (camera-to-ENU); NaN where not valid."""
    e_c, d_c = e_vectors_camera(lens, stokes.row, stokes.col, stokes.S1, stokes.S2)
    shape = stokes.row.shape
    d_n = attitude.apply(d_c.reshape(-1, 3)).reshape(shape + (3,))
    e_n = attitude.apply(np.nan_to_num(e_c).reshape(-1, 3)).reshape(shape + (3,))
    el, az = elevation_azimuth(d_n)
    aop = aop_from_e_vector(el, az, e_n)
    bad = ~stokes.valid
    return (np.where(bad, np.nan, el), np.where(bad, np.nan, az), np.where(bad, np.nan, aop))


def camera_stokes(camera, raw_dn, exposure_s: float, *, valid=None, method: str = "bilinear",
                  analysis_dn=None, dark_dn=None) -> StokesImage:
    """Stokes image of a raw frame from ``camera`` (:class:`PolarizationCamera`).

    Without ``analysis_dn`` the nominal polarizers of the camera (what an uncalibrated camera
    assumes) and its black level plus nominal dark current are used; with a calibration pass
    its per-pixel ``analysis_dn`` and dark frame ``dark_dn`` [DN] (at this exposure).
    Saturated pixels are excluded.
    """
    s = camera.sensor
    scale = 1.0
    if analysis_dn is None:
        # the camera's cached nominal analysis per unit radiance rate (an (H, W, 3) view of its
        # planes, no copy); the Stokes are linear in 1 / scale
        analysis_dn = np.moveaxis(camera._analysis_components(True, np.float64), 0, -1)
        scale = camera.photoelectrons_per_s * exposure_s / s.e_per_dn
    if dark_dn is None:
        dark_dn = s.black_level_dn + s.dark_current_e_s * exposure_s / s.e_per_dn
    operator = None
    if scale != 1.0 and method != "bilinear":  # the nominal analysis: its operator is fixed
        planes = analysis_dn
        operator = camera._cached(("demosaic", method),
                                  lambda: demosaic_operator(planes, method))
    st = demosaic(raw_dn, analysis_dn, black_level_dn=dark_dn, valid=valid,
                  saturation_dn=s.max_dn, method=method, operator=operator)
    if scale == 1.0:
        return st
    return replace(st, S0=st.S0 / scale, S1=st.S1 / scale, S2=st.S2 / scale)
