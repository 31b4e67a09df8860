"""The full-sky direction grid (:func:`skysim.geometry.sky_grid`) of the sky maps."""

from __future__ import annotations

import numpy as np
import pytest

from skysim.exceptions import InvalidParameterError
from skysim.geometry import sky_grid, sky_grid_size


@pytest.mark.parametrize("step", [90.0, 30.0, 10.0, 7.0, 2.0, 0.7])
def test_size_is_known_before_the_grid_is_built(step):
    """The memory checks size the grid from ``sky_grid_size`` alone: it must equal the grid's
    length, steps that do not divide 90 or 360 included (7 deg: 13 elevations x 52 azimuths)."""
    el, az = sky_grid(step)
    assert el.shape == az.shape == (sky_grid_size(step),)
    n_el, n_az = len(np.unique(el)), len(np.unique(az))
    assert n_el * n_az == sky_grid_size(step)
    if step == 7.0:
        assert (n_el, n_az) == (13, 52)


def test_grid_spans_horizon_to_zenith_and_every_azimuth_once():
    el, az = sky_grid(10.0)
    assert el.min() == 0.0 and el.max() == 90.0
    assert az.min() == 0.0 and az.max() == 350.0
    assert len({(e, a) for e, a in zip(el, az)}) == el.size   # no direction listed twice
    assert np.all(np.diff(el) >= 0)                           # elevation-major order


@pytest.mark.parametrize("step", [0.0, -1.0, 91.0, float("nan")])
def test_bad_step_is_refused_naming_it(step):
    with pytest.raises(InvalidParameterError, match="grid step"):
        sky_grid(step)
