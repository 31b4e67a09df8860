"""Atomic file writing shared by every writer: nothing is ever left half-written.

Each writer renders into a temporary file in the destination directory and renames it into
place with :func:`os.replace` (atomic on POSIX). A data file and its JSON sidecar are
committed together; if anything fails, the temporaries are removed and the old files (if
any) are untouched.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Callable, Iterable

__all__ = ["atomic_write", "atomic_write_many", "write_json_atomic", "sidecar_path"]


def sidecar_path(path) -> Path:
    """The JSON sidecar of a data file: ``<name>.json`` beside it (``data.csv`` -> ``data.json``)."""
    p = Path(path)
    return p.with_suffix(".json")


@contextlib.contextmanager
def _temp_in(directory: Path, suffix: str):
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=".tmp-", suffix=suffix)
    os.close(fd)
    try:
        yield Path(tmp)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


def atomic_write_many(items: Iterable[tuple[Path, Callable[[Path], None]]]) -> None:
    """Write several files so that either all appear (complete) or none changes.

    ``items`` pairs each destination with a function that writes a given temporary path.
    """
    items = [(Path(dest), fn) for dest, fn in items]
    with contextlib.ExitStack() as stack:
        temps = []
        for dest, fn in items:
            dest.parent.mkdir(parents=True, exist_ok=True)
            tmp = stack.enter_context(_temp_in(dest.parent, dest.suffix))
            fn(tmp)
            temps.append((tmp, dest))
        for tmp, dest in temps:
            os.replace(tmp, dest)


def atomic_write(path, write: Callable[[Path], None]) -> None:
    """Write one file atomically via ``write(tmp_path)``."""
    atomic_write_many([(Path(path), write)])


def write_json_atomic(path, obj) -> None:
    """Dump ``obj`` as indented JSON atomically."""
    def _w(tmp: Path):
        tmp.write_text(json.dumps(obj, indent=2, sort_keys=False, default=_json_default) + "\n")
    atomic_write(path, _w)


def _json_default(o):
    import numpy as np
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
