"""The README tried top to bottom: every ``skysim ...`` line of its shell blocks runs on a
fresh copy of the checkout's inputs (``examples/``) and ends with exit code 0.

Sizes are cut for the test suite, never the commands themselves: reproductions get
``--quick``, and the Sobol example configuration is shrunk in the copy (same file name, same
parameters, fewer base samples and stops). The two sky-gap lines (about 150 s each with the
radiative-transfer engine) run only with ``SKYSIM_SLOW_TESTS=1``; the shipped tables they read
are checked in ``tests/test_reference_data.py``. Lines that need data not shipped (the real
recordings of ``reproduce real-sky-compass``, found in ``../shared/reference/`` beside the
checkout) run in their own test, skipped with the reason on a bare clone.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
from pathlib import Path

import pytest

from experiments.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"

SLOW = {("reproduce", "sky-gap"), ("sky-gap",)}
"""Command prefixes that need minutes (see the module docstring)."""
SLOW_WITH_DATA = {("reproduce", "real-sky-compass")}
"""Commands on the recordings not shipped that take about a minute (marked slow)."""


def _needs_data() -> dict:
    """Command prefixes that need data not shipped -> the folder they read by default."""
    from experiments.studies import moonlit_sky, real_compass
    return {("reproduce", "real-sky-compass"): real_compass.DEFAULT_DATA,
            ("reproduce", "moonlit-sky"): moonlit_sky.DEFAULT_DATA}


def _data_of(argv):
    """The folder of data ``argv`` needs and does not ship with, or None."""
    return next((d for k, d in _needs_data().items() if tuple(argv[:len(k)]) == k), None)


def readme_commands() -> list[list[str]]:
    """argv of every ``skysim`` line in the README's ``sh`` code blocks (comments removed)."""
    blocks = re.findall(r"```sh\n(.*?)```", README.read_text(), flags=re.S)
    lines = [ln.strip() for b in blocks for ln in b.splitlines()]
    return [shlex.split(ln, comments=True)[1:] for ln in lines if ln.startswith("skysim ")]


def _id(argv) -> str:
    return " ".join(argv)[:70]


def _small_sobol(path: Path) -> None:
    text = path.read_text()
    text = re.sub(r"base_samples = \d+", "base_samples = 4", text)
    text = re.sub(r"stops = \d+", "stops = 16", text)
    text = re.sub(r"sun_elevations_deg = \[.*?\]", "sun_elevations_deg = [20.0]", text)
    path.write_text(text)


@pytest.fixture(scope="module")
def fresh_copy(tmp_path_factory):
    """A folder holding what a bare clone has beside the README: ``examples/``."""
    d = tmp_path_factory.mktemp("readme")
    shutil.copytree(ROOT / "examples", d / "examples")
    _small_sobol(d / "examples" / "sweep_sobol.toml")
    return d


def test_readme_has_the_commands_it_promises():
    cmds = readme_commands()
    firsts = {c[0] for c in cmds}
    assert {"reproduce", "sky", "sample", "calibrate", "diagnose", "gap-benchmark", "sky-gap",
            "sweep", "generate", "compare", "--help"} <= firsts
    assert not [c for c in cmds if any(re.fullmatch(r"[A-Z_]+(\.\w+)?", a) for a in c)], \
        "README commands must not contain placeholders"


@pytest.mark.slow
def test_readme_commands_run_top_to_bottom(fresh_copy, monkeypatch, capsys):
    """One test, in README order (``sample`` before ``calibrate`` and ``diagnose``,
    ``generate`` before ``compare``)."""
    monkeypatch.chdir(fresh_copy)
    slow_ok = bool(os.environ.get("SKYSIM_SLOW_TESTS"))
    ran = []
    needs_data = [c for c in readme_commands() if _data_of(c) is not None]
    for argv in readme_commands():
        if any(tuple(argv[:k]) in SLOW for k in (1, 2)) and not slow_ok or argv in needs_data:
            continue
        run = argv + (["--quick"] if argv[0] == "reproduce" and "--quick" not in argv else [])
        rc = main(run)
        out = capsys.readouterr()
        assert rc == 0, f"{_id(argv)!r} exited {rc}: {out.err[-2000:]}"
        assert out.out.strip(), f"{_id(argv)!r} printed nothing"
        assert "Traceback" not in out.err, _id(argv)
        ran.append(argv)
    assert len(ran) >= len(readme_commands()) - (0 if slow_ok else len(SLOW)) - len(needs_data)
    for name in ("sky.parquet", "sky.parquet.json", "sky.csv", "sky.csv.json", "sweep.csv",
                 "sweeps.csv", "report.json", "truth/manifest.json", "mine/manifest.json"):
        assert (fresh_copy / "results" / name).is_file(), name
    # every output under results/ (which `make clean` removes), none beside the checkout's files
    assert sorted(p.name for p in fresh_copy.iterdir()) == ["examples", "results"]


@pytest.mark.parametrize("argv", [pytest.param(c, marks=pytest.mark.slow)
                                  if tuple(c[:2]) in SLOW_WITH_DATA else c
                                  for c in readme_commands() if _data_of(c) is not None],
                         ids=_id)
def test_readme_commands_that_need_data_not_shipped(argv, fresh_copy, monkeypatch, capsys):
    data = _data_of(argv)
    if not data.is_dir():
        pytest.skip(f"{_id(argv)!r} needs the recordings in {data}, which a bare clone does "
                    "not have (README, 'Command line')")
    monkeypatch.chdir(fresh_copy)
    rc = main(argv + (["--quick"] if argv[0] == "reproduce" and "--quick" not in argv else []))
    out = capsys.readouterr()
    assert rc == 0, f"{_id(argv)!r} exited {rc}: {out.err[-2000:]}"
    assert out.out.strip() and "Traceback" not in out.err


def test_readme_says_where_the_data_not_shipped_come_from():
    text = README.read_text()
    for needed in ("--data DIR", "InsectRobotics/CelestialCompassAnalysis",
                   "doi:10.1038/s44172-023-00132-w", "GPL"):
        assert needed in text, needed
