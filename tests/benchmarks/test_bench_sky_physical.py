"""Multiple-scattering sky benchmarks (run with `make bench`; disabled in `make test`).

Goal from issue 3, reported by `make bench` (never asserted as a timing): a 10,000-direction
multiple-scattering map, cold (the engine call that builds the Fourier modes) and warm (modes
cached), against calling the engine once per direction (the baseline, measured in the same run
on a few directions and scaled per item by ratios.py); goal >= 50x at <= 1e-3 DoLP difference.
The DoLP difference between the map and the per-direction engine results is recorded in
``extra_info["max_abs_dDoLP_vs_direct"]``.
"""

import numpy as np
import pytest

pytest.importorskip("sasktran2", reason="sasktran2 (extra skysim[rt]) not installed")

from skysim import multiple
from skysim.rt_sasktran import transmitted_stokes

TAU, ALBEDO, SUN_EL, SUN_AZ = 0.25, 0.1, 30.0, 200.0
MU0 = float(np.sin(np.radians(SUN_EL)))
RNG = np.random.default_rng(7)
EL = np.degrees(np.arcsin(RNG.uniform(0.0, 1.0, 10_000)))  # uniform over the hemisphere
AZ = RNG.uniform(0.0, 360.0, 10_000)
N_BASE = 5


def _map():
    return multiple.MultipleScatteringSky(tau=TAU, albedo=ALBEDO).field(EL, AZ, SUN_EL, SUN_AZ)


@pytest.mark.benchmark(group="multiple-scattering map")
def test_engine_per_direction_baseline(benchmark):
    """Baseline: one sasktran2 call per direction (5 directions)."""
    def per_direction():
        return [transmitted_stokes(TAU, ALBEDO, MU0, np.sin(np.radians(e)), a - SUN_AZ)
                for e, a in zip(EL[:N_BASE], AZ[:N_BASE])]
    benchmark.extra_info.update(items=N_BASE, baseline=True)
    direct = benchmark.pedantic(per_direction, rounds=1, iterations=1)
    i, q, u = (np.array([float(r[k]) for r in direct]) for k in range(3))
    f = _map()
    benchmark.extra_info["max_abs_dDoLP_vs_direct"] = float(
        np.max(np.abs(f.dop[:N_BASE] - np.hypot(q, u) / i)))
    benchmark.extra_info["max_abs_dI_rel_vs_direct"] = float(np.max(np.abs(f.I[:N_BASE] / i - 1)))


@pytest.mark.benchmark(group="multiple-scattering map")
def test_map_10k_cold(benchmark):
    """One engine call (125 rays) + fit + spline evaluation; cache cleared before each round."""
    benchmark.extra_info.update(items=EL.size, baseline="test_engine_per_direction_baseline")
    f = benchmark.pedantic(_map, setup=multiple.clear_modes_cache, rounds=3,
                           iterations=1)
    assert f.I.shape == (10_000,) and np.all(f.I > 0)


@pytest.mark.benchmark(group="multiple-scattering map")
def test_map_10k_warm(benchmark):
    """Modes cached: spline evaluation and Fourier synthesis only."""
    _map()
    benchmark.extra_info.update(items=EL.size, baseline="test_engine_per_direction_baseline")
    f = benchmark(_map)
    assert np.all(np.isfinite(f.dop))
