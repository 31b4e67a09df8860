"""The README's Python section tried as a reader would: every ```python block runs as it
stands, in README order, in one empty folder (a later block reads what an earlier one wrote),
each in a fresh namespace (a block imports what it uses)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
LAYERS = ("skysim", "sensor.camera", "experiments.workflows.generate", "calibration.pipeline",
          "calibration import diagnose")
"""What the section shows, one block each: the sky, a sensor, ground truth, calibration and
diagnosis."""


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_python_section_covers_each_layer():
    blocks = python_blocks()
    assert len(blocks) == len(LAYERS)
    for block, layer in zip(blocks, LAYERS):
        assert layer in block, layer


def test_readme_python_blocks_run_in_order(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for i, block in enumerate(python_blocks()):
        exec(compile(block, f"README.md python block {i + 1}", "exec"), {"__name__": "__main__"})
    out = capsys.readouterr().out
    # what the blocks promise: the files written, the calibration and the verdict printed
    for name in ("sky.tiff", "sky.tiff.json", "truth/sweep.csv", "truth/sweep.csv.json",
                 "truth/manifest.json"):
        assert (tmp_path / "results" / name).is_file(), name
    assert [p.name for p in tmp_path.iterdir()] == ["results"]  # nothing beside results/
    assert re.search(r"^1-2 \d+\.\d\d -> \d+\.\d\d$", out, flags=re.M), out
    # an image with noise only: no effect is named (README: "this image has noise only")
    assert out.rstrip().splitlines()[-1].startswith("none - "), out


@pytest.mark.parametrize("block", python_blocks(), ids=lambda b: b.splitlines()[0][:40])
def test_readme_python_blocks_compile(block):
    """Each README python block is valid Python: it compiles to a module code object."""
    try:
        code = compile(block, "README.md", "exec")
    except SyntaxError as exc:
        pytest.fail(f"README python block does not compile: {exc}")
    assert code.co_filename == "README.md"
