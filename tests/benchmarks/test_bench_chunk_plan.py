"""Sweep chunk planning (run with `make bench`; with benchmarks disabled, as in `make test`,
each runs once as a smoke test).

Goal, reported by `make bench` (never asserted as a timing): planning a sweep takes constant
time whatever its size, so a large sweep starts at once instead of hanging with growing
memory (group "sweep chunk plan": the lazy plan of 64 M trials vs materialising every task,
the former behaviour, for the same 4000 chunks; the speed-up grows with the number of
chunks).
"""

from dataclasses import replace

from experiments.workflows.sweep import ChunkTask, chunk_trials, plan_chunks
from experiments.workflows.sweep_config import parse_config

TRIALS = 64 * 1_000_000
CFG = replace(parse_config({"sweep": {"name": "plan", "trials": TRIALS, "stops": 16},
                            "parameters": {"noise_V": {"uniform": [1e-4, 2e-3]}}}),
              chunk_trials=64 * 250)


def _eager(cfg, out, digest, n):
    """Every task built up front (the planner before it became lazy)."""
    size = chunk_trials(cfg)
    return [ChunkTask(cfg, k, s, min(s + size, n), str(out / "chunks" / f"chunk-{k:06d}.parquet"),
                      digest) for k, s in enumerate(range(0, n, size))]


def test_bench_chunk_plan_eager(benchmark, tmp_path):
    benchmark.group = "sweep chunk plan"
    benchmark.extra_info["baseline"] = True
    tasks = benchmark(_eager, CFG, tmp_path, "d", TRIALS)
    assert len(tasks) == 4000 and tasks[-1].stop == TRIALS


def test_bench_chunk_plan_lazy(benchmark, tmp_path):
    benchmark.group = "sweep chunk plan"
    plan = benchmark(plan_chunks, CFG, tmp_path, "d", TRIALS)
    assert len(plan) == 4000 and plan[-1] == _eager(CFG, tmp_path, "d", TRIALS)[-1]
