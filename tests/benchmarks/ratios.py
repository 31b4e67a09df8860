"""Print benchmark ratios against the baseline measured in the same run.

Each benchmark group holds one test whose ``extra_info["baseline"]`` is true (e.g. the
direct, per-item approach); every other member of the group is reported as the baseline's
mean time divided by its own (speed-up), scaled by ``extra_info["items"]`` when the two
measure different numbers of items. Benchmarks without a baseline print their own time and
throughput. Nothing here asserts anything about time.

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
        print(f"\n[{group}]")
        for b in items:
            mean = b["stats"]["mean"]
            n = b.get("extra_info", {}).get("items", 1)
            line = f"  {b['name']:<55s} {mean * 1e3:10.2f} ms"
            if n != 1:
                line += f"  ({n / mean:,.0f} items/s)"
            if base is not None and b is not base:
                nb = base.get("extra_info", {}).get("items", 1)
                speedup = (base["stats"]["mean"] / nb) / (mean / n)
                line += f"  speed-up vs {base['name']}: {speedup:,.1f}x"
            elif b is base:
                line += "  (baseline)"
            print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
