"""Aerosol sky benchmark (run with `make bench`; disabled in `make test`).

Goal (reported by ratios.py, never asserted as a timing): a 10,000-direction aerosol sky map,
warm (table cached), within 2x the time of the molecular multiple-scattering map, warm
(Fourier modes cached), measured in the same run: ``min_speedup`` 0.5 against that baseline.
"""

import numpy as np
import pytest

pytest.importorskip("sasktran2", reason="sasktran2 (extra skysim[rt]) not installed")

from skysim.aerosol import AerosolSky
from skysim.multiple import MultipleScatteringSky, bodhaine_optical_thickness

SUN_EL, SUN_AZ, LAM, ALBEDO = 30.0, 200.0, 450.0, 0.1
RNG = np.random.default_rng(7)
EL = np.degrees(np.arcsin(RNG.uniform(0.0, 1.0, 10_000)))  # uniform over the hemisphere
AZ = RNG.uniform(0.0, 360.0, 10_000)


@pytest.mark.benchmark(group="aerosol map")
def test_molecular_map_10k_warm(benchmark):
    """Baseline: the molecular sky at the same Rayleigh tau, modes cached."""
    sky = MultipleScatteringSky(tau=float(bodhaine_optical_thickness(LAM)), albedo=ALBEDO)
    sky.field(EL, AZ, SUN_EL, SUN_AZ)
    benchmark.extra_info.update(items=EL.size, baseline=True)
    benchmark(sky.field, EL, AZ, SUN_EL, SUN_AZ)


@pytest.mark.benchmark(group="aerosol map")
def test_aerosol_map_10k_warm(benchmark):
    """Table cached: the tabulated multiple scatter (bilinear) plus the closed-form single
    scatter."""
    sky = AerosolSky("continental_average", 0.2, ALBEDO, LAM)
    sky.field(EL, AZ, SUN_EL, SUN_AZ)
    benchmark.extra_info.update(items=EL.size, goal={"min_speedup": 0.5})
    f = benchmark(sky.field, EL, AZ, SUN_EL, SUN_AZ)
    assert f.I.shape == (10_000,) and np.all(f.I > 0)
