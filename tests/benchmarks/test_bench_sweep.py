"""Sweep benchmarks (run with `make bench`; with benchmarks disabled, as in `make test`, each
runs once on a reduced size as a smoke test).

Goals from issue 8, reported by `make bench` (never asserted as timings):
- simulated samples + heading solves per second per core >= 1e6 (group "sweep samples":
  vectorised chunk vs the per-trial loop of the Yang 2014 reproduction);
- 10,000 full LSM calibrations in one sweep <= 10 s locally (group "sweep calibrations",
  baseline: the same calibrations one `fit_pair` call at a time);
- dask on a 2-worker LocalCluster >= 1.7x one worker (group "sweep dask").
"""

from dataclasses import replace

import numpy as np
import pytest

from calibration.lsq import fit_pair
from calibration.solve import PAIRS, solve_pair
from experiments.workflows.sweep import (common_noise, plan_chunks, run_chunk, run_sweep,
                                         simulate_trials, trial_parameters)
from experiments.workflows.sweep_backends import run_tasks
from experiments.workflows.sweep_config import parse_config
from sensor.daq import Daq
from sensor.opponent import channel_outputs
from skysim.sky import make_sky

CONFIG = {"sweep": {"name": "bench", "trials": 10_000, "seed": 1, "stops": 182},
          "parameters": {"misalignment_deg": {"uniform": [-1.0, 1.0]},
                         "transmittance": {"normal": [0.0, 0.0123]},
                         "noise_V": {"uniform": [2.5e-4, 5.5e-4]},
                         "turntable_error_deg": {"value": 0.01},
                         "dmax": {"uniform": [0.6, 0.8]},
                         "sun_elevation_deg": {"uniform": [5.0, 60.0]}}}


def _cfg(**sweep):
    raw = {k: dict(v) for k, v in CONFIG.items()}
    raw["sweep"].update(sweep)
    return parse_config(raw)


def _simulate_and_solve(cfg, n):
    rng = np.random.default_rng(0)
    p = trial_parameters(cfg, n, rng)
    noise, tnoise = common_noise(cfg, n)
    sim = simulate_trials(p, cfg.stops, make_sky("rayleigh", dmax=1.0), Daq(16, 10.0), noise,
                          tnoise, 0.5)
    return [solve_pair(sim["U"], pair)[0] for pair in PAIRS]


@pytest.mark.benchmark(group="sweep samples")
def test_samples_per_trial_loop_baseline(benchmark):
    """Baseline: one trial at a time (20 trials x 182 stops), as a per-trial loop would."""
    cfg = _cfg()
    benchmark.extra_info.update(items=20 * cfg.stops, baseline=True)
    benchmark.pedantic(lambda: [_simulate_and_solve(cfg, 1) for _ in range(20)], rounds=3,
                       iterations=1)


@pytest.mark.benchmark(group="sweep samples")
def test_samples_and_solves_vectorised_one_core(benchmark):
    """1,024 trials x 182 stops simulated (sky, tilt, eqs. 2-3, noise, DAQ) and solved for
    three pairs in one process: items/s is samples + heading solves per second per core."""
    cfg = _cfg()
    n = 1024 if not benchmark.disabled else 64
    benchmark.extra_info.update(items=n * cfg.stops, goal_items_per_s=1e6)
    phis = benchmark.pedantic(_simulate_and_solve, args=(cfg, n), rounds=3, iterations=1)
    assert phis[0].shape == (n, cfg.stops)


@pytest.mark.benchmark(group="sweep calibrations")
def test_calibrations_one_at_a_time_baseline(benchmark):
    """Baseline: 100 calibrations, one `fit_pair` call each (91 stops, DoP scale fitted)."""
    rng = np.random.default_rng(3)
    phi = np.linspace(-90, 90, 91, endpoint=False)
    data = [channel_outputs(phi, 0.5, rng.uniform(-1, 1, 6), rng.normal(0, 0.01, 3))
            + 4e-4 * rng.standard_normal((91, 3)) for _ in range(100)]
    benchmark.extra_info.update(items=100, baseline=True)
    benchmark.pedantic(lambda: [fit_pair(phi, u, (1, 2), 0.7, fit_dop_scale=True)
                                for u in data], rounds=2, iterations=1)


@pytest.mark.benchmark(group="sweep calibrations")
def test_sweep_10k_calibrations_local(benchmark, tmp_path):
    """10,000 trials x one pair = 10,000 full LSM calibrations (plus simulation, raw and
    compensated solves, chunk files, tables) on the local backend with both cores."""
    trials = 10_000 if not benchmark.disabled else 256
    cfg = _cfg(trials=trials, pairs=["1-2"])
    benchmark.extra_info.update(items=trials, goal={"max_s": 10})
    counter = iter(range(100))

    def run():
        return run_sweep(cfg, tmp_path / f"r{next(counter)}", progress=False, figures=False,
                         log=lambda m: None)
    res = benchmark.pedantic(run, rounds=2, iterations=1)
    assert len(res["trials"]) == trials


def _dask_round(address, tasks):
    return run_tasks(run_chunk, tasks, backend="dask", scheduler=address, progress=False)


@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.benchmark(group="sweep dask")
def test_dask_local_cluster_workers(benchmark, tmp_path, workers):
    """The same 16 chunks (4,096 trials, one pair) on a running LocalCluster of 1 (baseline)
    or 2 worker processes; the cluster start is outside the timing, workers are warmed up."""
    distributed = pytest.importorskip("dask.distributed", reason="dask.distributed not installed")
    if benchmark.disabled:
        pytest.skip("benchmarks disabled: starting clusters costs seconds; the dask backend "
                    "is tested in tests/test_sweep.py, this runs under `make bench`")
    trials = 4096
    cfg = replace(_cfg(trials=trials, pairs=["1-2"]), chunk_trials=256)
    tasks = plan_chunks(cfg, tmp_path, cfg.digest(), trials)
    benchmark.extra_info.update(items=trials, baseline=workers == 1,
                                goal={} if workers == 1 else {"min_speedup": 1.7})
    with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        _dask_round(cluster.scheduler_address, tasks[:workers])      # warm the workers
        reports = benchmark.pedantic(_dask_round, args=(cluster.scheduler_address, tasks),
                                     rounds=2, iterations=1)
    assert len(reports) == len(tasks)
