"""Foundation benchmarks (run with `make bench`; disabled in `make test`).

Goals from the issue, reported by `make bench` (never asserted as timings): full-sky
single-scattering map of 100k directions; sun positions for 1e6 times; heading solve for 1e6
samples; one calibration of 1,000 samples; the reproduction with 200 trials (< 30 s).
"""

import numpy as np
import pandas as pd
import pytest

from calibration.lsq import fit_pair, fit_pairs
from calibration.solve import solve_pair
from experiments.studies.yang2014 import run
from sensor.opponent import channel_outputs
from skysim.sky import RayleighSky
from skysim.sun import sun_position


@pytest.mark.benchmark(group="sky map")
def test_sky_map_per_direction_baseline(benchmark):
    """Baseline: the same model called one direction at a time (1,000 directions)."""
    rng = np.random.default_rng(0)
    el, az = rng.uniform(0, 90, 1000), rng.uniform(0, 360, 1000)
    sky = RayleighSky(0.7)
    benchmark.extra_info.update(items=el.size, baseline=True)
    benchmark.pedantic(lambda: [sky.field(e, a, 30.0, 275.0).dop for e, a in zip(el, az)],
                       rounds=3, iterations=1)


@pytest.mark.benchmark(group="sky map")
def test_sky_map_100k(benchmark):
    rng = np.random.default_rng(0)
    el, az = rng.uniform(0, 90, 100_000), rng.uniform(0, 360, 100_000)
    sky = RayleighSky(0.7)
    benchmark.extra_info["items"] = el.size
    f = benchmark(lambda: sky.field(el, az, 30.0, 275.0).dop)
    assert f.shape == (100_000,)


@pytest.mark.benchmark(group="sun position")
def test_sun_positions_1e6_interpolated(benchmark):
    times = pd.date_range("2013-05-22T00:00Z", periods=1_000_000, freq="250ms")
    benchmark.extra_info["items"] = len(times)
    pos = benchmark.pedantic(sun_position, args=(times, 34.1, 108.5), rounds=3, iterations=1)
    assert len(pos) == len(times)


@pytest.mark.benchmark(group="sun position")
def test_sun_positions_direct_pysolar_baseline(benchmark):
    times = pd.date_range("2013-05-22T00:00Z", periods=500, freq="1min")
    benchmark.extra_info.update(items=len(times), baseline=True)
    benchmark.pedantic(sun_position, args=(times, 34.1, 108.5), kwargs={"method": "pysolar"},
                       rounds=3, iterations=1)


@pytest.mark.benchmark(group="heading solve")
def test_heading_solve_per_sample_baseline(benchmark):
    """Baseline: the same solve called one sample at a time (10,000 samples)."""
    rng = np.random.default_rng(1)
    u = channel_outputs(rng.uniform(-90, 90, 10_000), 0.5)
    benchmark.extra_info.update(items=10_000, baseline=True)
    benchmark.pedantic(lambda: [solve_pair(row, (1, 2)) for row in u], rounds=3, iterations=1)


@pytest.mark.benchmark(group="heading solve")
def test_heading_solve_1e6(benchmark):
    rng = np.random.default_rng(1)
    u = channel_outputs(rng.uniform(-90, 90, 1_000_000), 0.5)
    benchmark.extra_info["items"] = 1_000_000
    phi, _ = benchmark(solve_pair, u, (1, 2))
    assert phi.shape == (1_000_000,)


def _sensor_sweeps(trials, n=91, seed=4):
    rng = np.random.default_rng(seed)
    phi = np.broadcast_to(np.linspace(-90, 90, n, endpoint=False), (trials, n))
    u = channel_outputs(phi, 0.6, rng.uniform(-1, 1, (trials, 1, 6)),
                        0.01 * rng.standard_normal((trials, 1, 3)))
    return phi, u + 4e-4 * rng.standard_normal(u.shape)


@pytest.mark.benchmark(group="batched calibration")
def test_calibrations_one_at_a_time_baseline(benchmark):
    """Baseline: 100 sensors' calibrations (91 samples each) by fit_pair in a Python loop."""
    phi, u = _sensor_sweeps(100)
    benchmark.extra_info.update(items=100, baseline=True)
    benchmark.pedantic(lambda: [fit_pair(phi[k], u[k], (1, 2), 0.6) for k in range(100)],
                       rounds=3, iterations=1)


@pytest.mark.benchmark(group="batched calibration")
def test_calibrations_batched_10000(benchmark):
    """10,000 sensors' calibrations in one batched Gauss-Newton (fit_pairs)."""
    phi, u = _sensor_sweeps(10_000)
    benchmark.extra_info["items"] = 10_000
    cal = benchmark.pedantic(fit_pairs, args=(phi, u, (1, 2), 0.6), rounds=3, iterations=1)
    assert cal.converged.all()


def test_calibration_1000_samples(benchmark):
    rng = np.random.default_rng(2)
    phi = rng.uniform(-90, 90, 1000)
    u = channel_outputs(phi, 0.5, (0.5, -0.3, 0.2, 0.8, -0.6, 0.1), (0.01, -0.01, 0.0))
    u += 4e-4 * rng.standard_normal(u.shape)
    cal = benchmark(fit_pair, phi, u, (1, 2), 0.5)
    assert cal.converged


def test_reproduction_200_trials(benchmark):
    benchmark.extra_info["goal"] = {"max_s": 30}
    res = benchmark.pedantic(run, kwargs={"trials": 200, "progress": False}, rounds=1,
                             iterations=1)
    assert len(res["table1"]) == 9
