"""Atomic file writing shared by every writer: nothing is ever left half-written.

Each writer renders into a temporary file in the destination directory and renames it into
place with :func:`os.replace` (atomic on POSIX). A data file and its JSON sidecar are
committed together; if anything fails, the temporaries are removed and the old files (if
any) are untouched. Files get the permissions of an ordinary ``open()`` (``0666`` minus the
umask, usually ``0644``), not the ``0600`` of a temporary file.

A data file's JSON sidecar is named after the whole file name (``sky.csv`` ->
``sky.csv.json``), so ``sky.csv`` and ``sky.parquet`` side by side keep their own sidecars;
readers also accept the older ``<stem>.json`` spelling (:func:`find_sidecar`).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Callable, Iterable

from .exceptions import FileFormatError, SkysimError

__all__ = ["JsonValueError", "OutputPathError", "WriteError", "atomic_write", "atomic_write_many",
           "check_csv_header", "check_free_space", "check_output_dir", "check_output_file",
           "find_sidecar", "legacy_sidecar_path", "sidecar_path", "write_json_atomic"]

FREE_SPACE_MARGIN = 1.1
"""Free space a writer asks for, relative to its size estimate: room for the estimate's
error and for the file system's own blocks."""


class OutputPathError(SkysimError, OSError):
    """An output path cannot be written: it is a folder, lies under a file, or its folder is
    not writable. The message names the path and what to give instead."""


class WriteError(SkysimError, OSError):
    """Writing a file failed part-way (a full disk, a quota, a lost network share): the message
    names the destination and the reason; the destination is left as it was."""


class JsonValueError(SkysimError, TypeError):
    """A value to be written as JSON (a sidecar, a report) that JSON cannot hold: the message
    names its type; give numbers, text, lists or dicts of them."""


def sidecar_path(path) -> Path:
    """The JSON sidecar a writer writes for a data file: ``<name>.json`` after the whole file
    name (``data.csv`` -> ``data.csv.json``)."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def legacy_sidecar_path(path) -> Path:
    """The older sidecar spelling ``<stem>.json`` (``data.csv`` -> ``data.json``)."""
    return Path(path).with_suffix(".json")


def find_sidecar(path) -> Path | None:
    """The sidecar of a data file for reading: ``<name>.json`` if present, else the older
    ``<stem>.json``; None if neither is a file."""
    for side in (sidecar_path(path), legacy_sidecar_path(path)):
        if side.is_file():
            return side
    return None


def check_csv_header(path, error_cls: type[Exception] = FileFormatError, what: str = "") -> None:
    """Refuse a CSV file (``.csv`` or ``.csv.gz``) whose header line names a column twice.

    :func:`pandas.read_csv` would silently rename the second ``a`` to ``a.1`` and a reader
    would use the first: the header line itself is read (with :mod:`csv`, so quoted names
    count as written). A file without a header line passes (the table reader reports it).

    Raises
    ------
    error_cls
        Naming the file (after ``what``, e.g. ``"--directions "``) and the repeated column.
    """
    import csv
    import gzip
    import io
    from collections import Counter
    path = Path(path)
    opener = gzip.open if path.suffix.lower() == ".gz" else open
    try:
        with opener(path, "rb") as raw:
            line = raw.readline()
    except (OSError, EOFError):   # unreadable: the table reader says why
        return
    text = line.decode("utf-8-sig", "replace")
    header = next(csv.reader(io.StringIO(text)), [])
    repeated = [name for name, n in Counter(header).items() if n > 1 and name.strip()]
    if repeated:
        name = repeated[0]
        raise error_cls(f"{what}{path}: column {name!r} appears {header.count(name)} times in "
                        "the header line; name each column once")


def _umask_mode() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


_FILE_MODE = _umask_mode()
"""Permissions of written files: what ``open()`` would give (read once: ``os.umask`` can
only be read by setting it)."""


def _writable_ancestor(path: Path, what: str) -> None:
    """Raise :class:`OutputPathError` unless the nearest existing ancestor of ``path`` is a
    writable folder (the folders below it would be created)."""
    parent = path.parent
    while not parent.exists():
        if parent == parent.parent:
            break
        parent = parent.parent
    if not parent.is_dir():
        raise OutputPathError(f"{what} {path}: {parent} is a file, not a folder; "
                              "choose another location")
    _probe(parent, f"{what} {path}")


def _probe(folder: Path, what: str) -> None:
    """Create and remove a temporary file in ``folder``: the one test of writability that
    also holds for read-only file systems and privileged users (``os.access`` does not)."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise OutputPathError(f"{what}: cannot write in folder {folder} ({exc.strerror}); "
                              "choose another location") from None


def check_output_file(path, what: str = "output file") -> Path:
    """Check before any work that ``path`` can be written as a file; return it as a Path.

    Raises
    ------
    OutputPathError
        If ``path`` is a folder, lies under a file or in a folder that is not writable.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputPathError(f"{what} {path} is a folder; give a file name")
    _writable_ancestor(path, what)
    return path


def check_output_dir(path, what: str = "output folder") -> Path:
    """Check before any work that ``path`` is (or can be created as) a writable folder.

    Raises
    ------
    OutputPathError
        If ``path`` is a file, lies under a file or is not writable.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"{what} {path} is a file; give a folder")
    if path.is_dir():
        _probe(path, f"{what} {path}")
    else:
        _writable_ancestor(path, what)
    return path


def check_free_space(path, nbytes: float, what: str) -> None:
    """Check before any work that the file system of ``path`` has room for ``nbytes``.

    A library writing into a full disk may fail in ways no caller can catch (HDF5 has been
    seen to crash the interpreter); the estimate is checked first instead.

    Parameters
    ----------
    path : str or Path
        The file to be written (its nearest existing folder is asked).
    nbytes : float
        Estimated size of what will be written [bytes].
    what : str
        What is written, for the message (e.g. ``"1440 times x 8280 directions"``).

    Raises
    ------
    WriteError
        If the free space is below ``FREE_SPACE_MARGIN * nbytes``.
    """
    import shutil
    folder = Path(path).absolute().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    free = shutil.disk_usage(folder).free
    nbytes = float(min(nbytes, 10**300))   # sizes beyond a float
    if FREE_SPACE_MARGIN * nbytes > free:
        raise WriteError(f"{path}: {what} would take about {_size(nbytes)} on disk; only "
                         f"{_size(free)} is free in {folder}; free some space or write "
                         "elsewhere")


def _size(n: float) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} B"


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

    Raises
    ------
    OutputPathError
        If a destination is a folder, lies under a file or its folder is not writable.
    WriteError
        If a writer fails with an ``OSError`` (e.g. the disk is full); no destination changes.
    """
    items = [(check_output_file(dest), fn) for dest, fn in items]
    with contextlib.ExitStack() as stack:
        temps = []
        for dest, fn in items:
            try:
                dest.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise OutputPathError(f"cannot create folder {dest.parent} ({exc.strerror})") \
                    from exc
            tmp = stack.enter_context(_temp_in(dest.parent, dest.suffix))
            try:
                fn(tmp)
            except OSError as exc:
                if isinstance(exc, (OutputPathError, WriteError)):
                    raise
                reason = exc.strerror or str(exc) or type(exc).__name__
                raise WriteError(f"writing {dest} failed ({reason}); {dest} is left as it "
                                 "was") from exc
            os.chmod(tmp, _FILE_MODE)
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
    # json.dumps calls this hook for what it cannot write and expects a TypeError: this one is
    # also a SkysimError, for a caller's metadata that has no JSON form
    raise JsonValueError(f"a {type(o).__name__} value ({o!r:.60}) cannot be written as JSON; "
                         "give numbers, text, lists or dicts of them")
