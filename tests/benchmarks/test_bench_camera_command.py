"""`skysim camera --out x.tiff` for one 2448 x 2048 frame against writing that frame (run with
`make bench`; disabled in `make test`).

Both in a fresh interpreter, the way a user pays them: the command (interpreter start,
imports, sun position, render, noise, TIFF and sidecar) and the floor, a fresh interpreter
that writes the same frame and sidecar through :func:`sensor.camera.files.write_raw` (its
imports, the TIFF encoder and the atomic writes: what any command that produces the file
pays). Each child reports its own peak resident memory (``VmHWM``: ``getrusage`` would
report the forking parent's peak on Linux) as ``extra_info["peak_mb"]``.

Goals reported by ``tests/benchmarks/ratios.py`` (never asserted as timings): the command
within 4x the floor (``max_floor_ratio``) and at most 800 MB resident (``max_peak_mb``).
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

W, H = 2448, 2048
ROOT = Path(__file__).resolve().parents[2]
COMMAND = ["camera", "--lat", "34.14", "--lon", "108.55", "--time", "2013-05-22T17:10+08:00",
           "--yaw", "40", "--width", str(W), "--height", str(H)]
GROUP = "camera command, fresh interpreter, 2448x2048 TIFF"
_PEAK = ("import re\nprint('PEAK_KB', re.search(r'VmHWM:\\s*(\\d+)', "
         "open('/proc/self/status').read())[1])\n")
_CHILD_COMMAND = ("import sys\nfrom experiments.cli.main import main\nrc = main(sys.argv[1:])\n"
                  + _PEAK + "sys.exit(rc)")
_CHILD_FLOOR = ("import json, sys\nimport numpy as np\nfrom sensor.camera.files import write_raw\n"
                "raw = np.load(sys.argv[1])\nwrite_raw(sys.argv[2], raw, json.loads(open("
                "sys.argv[3]).read()))\n" + _PEAK)

pytestmark = [pytest.mark.benchmark(group=GROUP)]


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    """The command's own frame and sidecar, written once (the floor writes the same bytes)."""
    pytest.importorskip("tifffile")
    if not Path("/proc/self/status").exists():
        pytest.skip("the children's peak memory is read from /proc (Linux)")
    from sensor.camera.files import read_raw
    d = tmp_path_factory.mktemp("camera_command")
    _run([*COMMAND, "--out", str(d / "frame.tiff")], _CHILD_COMMAND)
    raw, doc = read_raw(d / "frame.tiff")
    doc.pop("schema")
    np.save(d / "frame.npy", raw)
    (d / "sidecar.json").write_text(json.dumps(doc))
    return d


def _run(args, code) -> float:
    """Run ``code`` in a fresh interpreter; its peak resident memory [MB]."""
    proc = subprocess.run([sys.executable, "-c", code, *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, check=True)
    return int(proc.stdout.split("PEAK_KB")[1]) / 1024


def test_floor_fresh_interpreter_writes_the_frame(benchmark, frame):
    peaks = []
    args = [frame / "frame.npy", frame / "floor.tiff", frame / "sidecar.json"]
    benchmark.pedantic(lambda: peaks.append(_run(args, _CHILD_FLOOR)), rounds=5, iterations=1)
    benchmark.extra_info.update(floor=True, peak_mb=round(max(peaks), 1))
    assert (frame / "floor.tiff").stat().st_size > W * H * 2  # 16 bits a pixel, uncompressed


def test_camera_command_fresh_interpreter(benchmark, frame):
    from sensor.camera.files import read_raw
    peaks = []
    args = [*COMMAND, "--out", frame / "command.tiff"]
    benchmark.pedantic(lambda: peaks.append(_run(args, _CHILD_COMMAND)), rounds=5,
                       iterations=1)
    benchmark.extra_info.update(peak_mb=round(max(peaks), 1),
                                goal={"max_floor_ratio": 4.0, "max_peak_mb": 800.0})
    # the same seed writes the same frame every time
    np.testing.assert_array_equal(read_raw(frame / "command.tiff")[0],
                                  np.load(frame / "frame.npy"))
