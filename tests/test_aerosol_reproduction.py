"""The neutral-point finder of the aerosol reproduction (experiments/studies/aerosol_sky.py) on a
solar vertical with known zeros."""

import numpy as np
import pandas as pd
import pytest

from experiments.studies.aerosol_sky import vertical_zeros


def _vertical(q_sun_side, q_anti_side, step=0.05):
    el = np.arange(0.0, 90.0 + step / 2, step)
    return pd.concat([pd.DataFrame({"phi_deg": 0.0, "elevation_deg": el, "Q": q_sun_side(el)}),
                      pd.DataFrame({"phi_deg": 180.0, "elevation_deg": el,
                                    "Q": q_anti_side(el)})], ignore_index=True)


def test_zeros_on_both_half_meridians():
    """Q = (e - 4)(e - 30.01) towards a sun at 15 deg, Q = e - 12.02 away from it: Brewster
    11 deg below the sun, Babinet 15.01 above it, Arago 27.02 from the anti-sun (12.02 + 15).
    The zero at 4 deg falls on a sample. Linear interpolation between 0.05 deg samples of a
    parabola errs by < 1e-3 deg."""
    pp = _vertical(lambda e: (e - 4.0) * (e - 30.01), lambda e: e - 12.02)
    z = vertical_zeros(pp, 15.0)
    assert z["brewster_distance_deg"] == pytest.approx(11.0, abs=1e-3)
    assert z["babinet_distance_deg"] == pytest.approx(15.01, abs=1e-3)
    assert z["arago_distance_deg"] == pytest.approx(27.02, abs=1e-3)


def test_missing_points_are_nan():
    pp = _vertical(lambda e: e + 1.0, lambda e: -1.0 - e)
    z = vertical_zeros(pp, 20.0)
    assert all(np.isnan(v) for v in z.values())
