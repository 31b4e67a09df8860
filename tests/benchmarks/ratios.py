"""Print benchmark ratios against the baseline measured in the same run.

Each benchmark group holds one test whose ``extra_info["baseline"]`` is true (e.g. the
direct, per-item approach); every other member of the group is reported as the baseline's
median time divided by its own (speed-up), scaled by ``extra_info["items"]`` when the two
measure different numbers of items. Benchmarks without a baseline print their own time and
throughput. Medians, not means: on a shared machine a few preempted rounds skew a mean.

A group may also hold a *floor* (``extra_info["floor"]`` true): a bare numpy pass that bounds
what any implementation can reach (one ``np.cos`` over the grid); the others print how many
times the floor's per-item time they take. A member's ``extra_info["goal"]`` states its goal,
printed as met or not: ``min_speedup`` (against the baseline), ``max_floor_ratio``,
``min_items_per_s``, ``max_import_s`` (against ``extra_info["import_s"]``), ``max_s`` (the
median wall time of one round, in seconds) or ``max_peak_mb`` (against
``extra_info["peak_mb"]``, a child process's peak resident memory). Nothing here
asserts anything about time.

Usage: python tests/benchmarks/ratios.py BENCHMARK_JSON
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict


def main(path: str) -> int:
    data = json.load(open(path))
    groups = defaultdict(list)
    for b in data["benchmarks"]:
        groups[b.get("group") or b["name"]].append(b)
    print(f"\nmachine: {data['machine_info'].get('cpu', {}).get('brand_raw', '?')}, "
          f"{data['machine_info'].get('cpu', {}).get('count', '?')} cores")
    for group, items in sorted(groups.items()):
        base = next((b for b in items if b.get("extra_info", {}).get("baseline")), None)
        floor = next((b for b in items if b.get("extra_info", {}).get("floor")), None)
        print(f"\n[{group}]")
        for b in items:
            t = _per_item(b)
            n = b.get("extra_info", {}).get("items", 1)
            line = f"  {b['name']:<55s} {b['stats']['median'] * 1e3:10.2f} ms"
            if n != 1:
                line += f"  ({1.0 / t:,.0f} items/s)"
            measured = {"items_per_s": 1.0 / t, "s": b["stats"]["median"],
                        "import_s": b.get("extra_info", {}).get("import_s"),
                        "peak_mb": b.get("extra_info", {}).get("peak_mb")}
            if base is not None and b is not base:
                measured["speedup"] = _per_item(base) / t
                line += f"  speed-up vs {base['name']}: {measured['speedup']:,.1f}x"
            elif b is base:
                line += "  (baseline)"
            if floor is not None and b is not floor:
                measured["floor_ratio"] = t / _per_item(floor)
                line += f"  {measured['floor_ratio']:,.1f}x the floor"
            elif b is floor:
                line += "  (floor)"
            if measured["import_s"] is not None:
                line += f"  imports {measured['import_s']:.3f} s"
            if b.get("extra_info", {}).get("peak_mb") is not None:
                line += f"  peak memory {b['extra_info']['peak_mb']:,.0f} MB"
            print(line)
            for goal in _goals(b, measured):
                print(f"    goal {goal}")
    return 0


def _per_item(bench) -> float:
    return bench["stats"]["median"] / bench.get("extra_info", {}).get("items", 1)


_GOALS = {"min_speedup": ("speedup", ">=", "x"), "max_floor_ratio": ("floor_ratio", "<=", "x"),
          "min_items_per_s": ("items_per_s", ">=", "/s"), "max_import_s": ("import_s", "<=", "s"),
          "max_s": ("s", "<=", "s"), "max_peak_mb": ("peak_mb", "<=", " MB")}


def _goals(bench, measured):
    for key, target in bench.get("extra_info", {}).get("goal", {}).items():
        what, op, unit = _GOALS[key]
        value = measured.get(what)
        if value is None:
            yield f"{what} {op} {target:g}{unit}: not measured (no baseline/floor in this run)"
            continue
        met = value >= target if op == ">=" else value <= target
        yield f"{what} {op} {target:g}{unit}: {'met' if met else 'NOT MET'} ({value:,.3g}{unit})"


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
