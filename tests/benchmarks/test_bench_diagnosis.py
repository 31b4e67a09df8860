"""Gap-diagnosis benchmarks (run with `make bench`; disabled in `make test`).

Goals from issue 7, reported by `make bench` (never asserted as timings): diagnosis of a
10,000-sample table with all eight candidates (goal <= 10 s on a 2-core machine;
multiple_scattering reads a precomputed zenith table), and the blind benchmark with N = 200. Baselines in the same run: the base-model-only diagnosis of the
same table (the cost every diagnosis pays before the candidates), and one blind case.
"""

import numpy as np
import pytest

from calibration.diagnosis import DEFAULT_CANDIDATES, diagnose
from experiments.workflows.diagnose import Session, run_benchmark, simulate_session

SESSION_10K = Session(n_sweeps=10, n_stops=1000, sweep_spacing_min=15.0)
"""10 sweeps x 1,000 stops = 10,000 samples, 15:30..17:45 local."""


@pytest.fixture(scope="module")
def table_10k():
    ds = simulate_session("tilt", np.random.default_rng(1), session=SESSION_10K)
    assert ds["data"].ctx.n == 10_000
    return ds["data"]


@pytest.mark.benchmark(group="diagnosis 10k samples")
def test_diagnose_10k_base_only_baseline(benchmark, table_10k):
    benchmark.extra_info.update(items=10_000, baseline=True)
    doc = benchmark.pedantic(diagnose, args=(table_10k, []), rounds=2, iterations=1)
    assert doc.verdict.effect == "unexplained"


@pytest.mark.benchmark(group="diagnosis 10k samples")
def test_diagnose_10k_all_candidates(benchmark, table_10k):
    """All eight candidates (multiple_scattering reads a precomputed zenith table)."""
    benchmark.extra_info.update(items=10_000, candidates=len(DEFAULT_CANDIDATES))
    doc = benchmark.pedantic(diagnose, args=(table_10k, DEFAULT_CANDIDATES), rounds=2,
                             iterations=1)
    assert doc.verdict.effect == "tilt"


@pytest.mark.benchmark(group="gap benchmark")
def test_gap_benchmark_one_case_baseline(benchmark):
    benchmark.extra_info.update(items=1, baseline=True)
    cases = benchmark.pedantic(run_benchmark, args=(1,), kwargs={"progress": False},
                               rounds=2, iterations=1)
    assert len(cases) == 1


@pytest.mark.benchmark(group="gap benchmark")
def test_gap_benchmark_n200(benchmark):
    benchmark.extra_info["items"] = 200
    cases = benchmark.pedantic(run_benchmark, args=(200,), kwargs={"progress": False},
                               rounds=1, iterations=1)
    assert len(cases) == 200
