"""Import time of a ``skysim`` command line, measured with ``python -X importtime``.

Usage: python tests/benchmarks/importtime.py [ARGS...]   (default: --help)

Prints the seconds spent importing modules for ``skysim ARGS`` (the top-level entries of
``-X importtime``, cumulative, without those a bare interpreter imports at start-up) and the
slowest top-level imports.
"""

from __future__ import annotations

import re
import subprocess
import sys

__all__ = ["import_times", "command_import_s"]

_LINE = re.compile(r"^import time:\s+(\d+) \|\s+(\d+) \|( *)(\S+)$")


def import_times(code: str, cwd=None) -> dict[str, float]:
    """Top-level modules imported by ``python -c code`` -> cumulative import time [s]."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-c", code], cwd=cwd,
                          capture_output=True, text=True)
    out = {}
    for line in proc.stderr.splitlines():
        m = _LINE.match(line)
        if m and not m.group(3).strip(" ") and len(m.group(3)) == 1:  # one space: top level
            out[m.group(4)] = out.get(m.group(4), 0.0) + int(m.group(2)) * 1e-6
    return out


def command_import_s(argv, cwd=None) -> tuple[float, dict[str, float]]:
    """Import seconds of ``skysim argv`` beyond the interpreter's own, and the per-module map."""
    bare = import_times("pass", cwd)
    code = ("import sys\nfrom experiments.cli.main import main\n"
            f"try:\n    main({list(argv)!r})\nexcept SystemExit:\n    pass\n")
    times = {k: v for k, v in import_times(code, cwd).items() if k not in bare}
    return sum(times.values()), times


if __name__ == "__main__":
    total, times = command_import_s(sys.argv[1:] or ["--help"])
    print(f"skysim {' '.join(sys.argv[1:]) or '--help'}: {total:.3f} s of imports")
    for name, t in sorted(times.items(), key=lambda kv: -kv[1])[:8]:
        print(f"  {t:7.3f} s  {name}")
