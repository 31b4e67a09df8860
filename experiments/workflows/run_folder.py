"""Output folders of reproductions: replaced as a whole, never mixed.

A reproduction writes many files into one folder. Written over an earlier run file by file,
the folder would mix the two: a quick run leaves the full run's extra files beside its own,
an interrupted run leaves files of two seeds. :func:`replacing_folder` moves the earlier
folder aside before the run and deletes it only when the run has succeeded; a failed or
interrupted run is removed and the earlier folder put back. Each folder records what made it
in ``run.json``, so that a ``--quick`` run does not silently replace a full one.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
from pathlib import Path

from skysim.io import OutputPathError

__all__ = ["RUN_FILE", "replacing_folder"]

RUN_FILE = "run.json"
"""The record of the run that wrote a folder: target, quick, trials, seed."""


def _check_replaceable(out: Path, run: dict, force: bool) -> None:
    """Refuse to replace a folder of other files, or a full run by a quick one."""
    if force or not out.is_dir() or not any(out.iterdir()):
        return
    try:
        before = json.loads((out / RUN_FILE).read_text())
    except (OSError, ValueError):
        before = None
    if not isinstance(before, dict) or before.get("target") != run["target"]:
        raise OutputPathError(
            f"--out {out} already holds files that are not a run of "
            f"{run['target']}; give a new or empty folder, or --force to replace "
            "the folder and everything in it")
    if run["quick"] and not before.get("quick", True):
        raise OutputPathError(
            f"--out {out} holds a full run of {run['target']} (seed "
            f"{before.get('seed')}); a --quick run would replace it: give another "
            "--out, or --force")


@contextlib.contextmanager
def replacing_folder(out, run: dict, force: bool = False):
    """Context for a run that writes into folder ``out``; yields ``out`` (a Path), empty.

    Parameters
    ----------
    out : str or Path
        The output folder.
    run : dict
        What the run is (``target``, ``quick``, ``trials``, ``seed``), written to
        ``out/run.json`` when it succeeds.
    force : bool
        Replace a folder that holds other files, or a full run by a quick one.

    Raises
    ------
    OutputPathError
        Before any work, if ``out`` holds files of something else, or a full run that a
        ``quick`` run would replace, and ``force`` is not set.
    """
    out = Path(out)
    _check_replaceable(out, run, force)
    out.parent.mkdir(parents=True, exist_ok=True)
    aside = None
    if out.exists():
        aside = Path(tempfile.mkdtemp(prefix=f".{out.name}.earlier-", dir=out.parent))
        aside.rmdir()
        out.rename(aside)
    try:
        out.mkdir()
        yield out
        (out / RUN_FILE).write_text(json.dumps(run, indent=2) + "\n")
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        if aside is not None:
            aside.rename(out)
        raise
    if aside is not None:
        shutil.rmtree(aside, ignore_errors=True)
