"""Time series of sky maps: many suns x many view directions, streamed in blocks.

A day at 1 s over a dome of 10^4 directions is 8.6e8 values per Stokes component: more than
a workstation holds. :func:`iter_sky_series` evaluates a sky for a fixed set of directions and
a sequence of suns in blocks of whole suns, each block within a stated memory budget, so a
writer can store block after block without ever holding the series.

Each block is one call ``sky.field(el[None, :], az[None, :], sun_el[:, None], sun_az[:, None])``:
the single-scattering model computes the trigonometry of the N directions and of the T suns
separately (``N + T`` values, not ``N T``) and only arithmetic and one arctan per value, so a
block costs the same per value as one full-sky map.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from .exceptions import InvalidParameterError
from .sky import Sky, SkyField

__all__ = ["SERIES_FIELDS", "DEFAULT_MAX_BLOCK_BYTES", "VALUES_PER_POINT", "BLOCK_VALUES",
           "suns_per_block", "iter_sky_series"]

SERIES_FIELDS = ("dop", "aop_deg", "I", "Q", "U")
"""The per-(sun, direction) quantities of a series, in output order."""

DEFAULT_MAX_BLOCK_BYTES = 256 * 2**20
"""Default memory budget of one block [bytes] (256 MiB)."""

VALUES_PER_POINT = 12
"""Arrays of one block alive at the peak, per (sun, direction) point: the model's five outputs
and its temporaries (six for the single-scattering model) plus a writer's index columns. A
block holds at most ``budget / (VALUES_PER_POINT * itemsize * n_directions)`` suns."""

BLOCK_VALUES = 2**17
"""Values per array of a block beyond which blocks are not made larger (about 1 MiB in
float64): numpy's passes over arrays of that size run near cache speed, while blocks of tens
of MiB run at memory speed (measured 2-3x slower per value on 10,000 directions)."""


def suns_per_block(n_directions: int, max_block_bytes: int = DEFAULT_MAX_BLOCK_BYTES,
                   itemsize: int = 8) -> int:
    """Number of suns per block: as many as fit ``max_block_bytes``, at most
    :data:`BLOCK_VALUES` values per array (at least one sun).

    Raises
    ------
    InvalidParameterError
        If not even one sun fits (the budget is below one sky map's arrays).
    """
    per_sun = VALUES_PER_POINT * itemsize * int(n_directions)
    if max_block_bytes < per_sun:
        raise InvalidParameterError(
            f"max_block_bytes {max_block_bytes} is below one sun's arrays ({per_sun} bytes for "
            f"{n_directions} directions); raise the budget or use fewer directions")
    return int(min(max_block_bytes // per_sun, max(1, BLOCK_VALUES // int(n_directions))))


def _as_1d(name: str, values) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1:
        raise InvalidParameterError(f"{name} must be one-dimensional; got shape {arr.shape}")
    return arr


def iter_sky_series(sky: Sky, view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                    sun_azimuth_deg, max_block_bytes: int = DEFAULT_MAX_BLOCK_BYTES,
                    block_suns: int | None = None) -> Iterator[tuple[slice, SkyField]]:
    """Yield ``(suns, field)`` blocks of a series of sky maps.

    Parameters
    ----------
    sky : Sky
        Any sky model (``make_sky(...)``).
    view_elevation_deg, view_azimuth_deg : array (N,)
        The fixed view directions [deg].
    sun_elevation_deg, sun_azimuth_deg : array (T,)
        One sun position per time step [deg] (e.g. from :func:`skysim.sun.sun_position`).
    max_block_bytes : int
        Memory budget of one block [bytes]; see :data:`VALUES_PER_POINT`.
    block_suns : int, optional
        Suns per block, at most what the budget allows (a writer aligning blocks to its
        chunks); default: as many as fit.

    Yields
    ------
    suns : slice
        The time steps of this block.
    field : SkyField
        The block's field, arrays of shape ``(len(suns), N)``.

    Raises
    ------
    InvalidParameterError
        For mismatched or non-1-D inputs, a budget below one sun, or invalid directions.
    SunBelowHorizonError
        When a block holds a sun at or below the horizon (the model's own check).
    """
    el = _as_1d("view_elevation_deg", view_elevation_deg)
    az = _as_1d("view_azimuth_deg", view_azimuth_deg)
    sel = _as_1d("sun_elevation_deg", sun_elevation_deg)
    saz = _as_1d("sun_azimuth_deg", sun_azimuth_deg)
    if el.shape != az.shape:
        raise InvalidParameterError(f"view elevations and azimuths differ in length: "
                                    f"{el.size} vs {az.size}")
    if sel.shape != saz.shape:
        raise InvalidParameterError(f"sun elevations and azimuths differ in length: "
                                    f"{sel.size} vs {saz.size}")
    itemsize = np.dtype(getattr(sky, "dtype", np.float64)).itemsize
    block = suns_per_block(el.size, max_block_bytes, itemsize)
    if block_suns is not None:
        if not 1 <= int(block_suns) <= block:
            raise InvalidParameterError(f"block_suns must lie in [1, {block}] for this budget; "
                                        f"got {block_suns}")
        block = int(block_suns)
    for start in range(0, sel.size, block):
        suns = slice(start, min(start + block, sel.size))
        yield suns, sky.field(el[None, :], az[None, :], sel[suns, None], saz[suns, None])
