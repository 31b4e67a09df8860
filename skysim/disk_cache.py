"""A persistent on-disk cache of computed arrays, shared by the processes of one machine.

Results that take seconds to compute and depend only on a few parameters (the Mie optics of
an aerosol component, :mod:`skysim.aerosol_types`) are kept as one ``.npz`` file per entry,
named by the SHA-256 of a canonical JSON of everything the result depends on (:func:`entry_key`),
so a changed parameter or an upgraded engine simply misses and computes anew.

Location: ``$SKYSIM_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/skysim``, else
``~/.cache/skysim`` (:func:`cache_root`), one subfolder per kind of result (e.g. ``mie/``).
Deleting the folder, or any file in it, is always safe: missing entries are recomputed.

Failure policy: the cache never makes a computation fail.

- A folder that cannot be created or written (a read-only home, a file in the way): the
  result is computed and returned without being stored.
- An entry that cannot be read, is truncated or corrupt, or holds other arrays than expected:
  treated as missing; the result is recomputed and the entry overwritten.
- Writes are atomic (:func:`skysim.io.atomic_write`: a temporary file in the same folder
  renamed into place), so concurrent processes and interrupted runs never leave a half-written
  entry under an entry's name.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from .io import atomic_write

__all__ = ["CACHE_DIR_ENV", "cache_root", "entry_key", "load_entry", "store_entry",
           "library_versions", "finite_float_arrays"]

CACHE_DIR_ENV = "SKYSIM_CACHE_DIR"
"""Environment variable that moves the cache (read at every access)."""

_KEY_FIELD = "_cache_key"
"""Name under which an entry stores its own canonical key (checked on reading)."""


def cache_root() -> Path:
    """The cache folder: ``$SKYSIM_CACHE_DIR``, else ``$XDG_CACHE_HOME/skysim``, else
    ``~/.cache/skysim`` (XDG Base Directory Specification, ``XDG_CACHE_HOME``)."""
    explicit = os.environ.get(CACHE_DIR_ENV)
    if explicit:
        return Path(explicit).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "skysim"


def _canonical(params: dict) -> str:
    """Canonical JSON of ``params`` (sorted keys, no spaces; floats by their shortest exact
    ``repr``, so equal floats give equal text and different ones different text)."""
    return json.dumps(params, sort_keys=True, separators=(",", ":"), allow_nan=False)


def entry_key(params: dict) -> str:
    """SHA-256 (hex) of the canonical JSON of ``params``: the entry's file stem."""
    return hashlib.sha256(_canonical(params).encode()).hexdigest()


def _entry_path(kind: str, params: dict) -> Path:
    return cache_root() / kind / f"{entry_key(params)}.npz"


def load_entry(kind: str, params: dict, names) -> dict | None:
    """The arrays ``names`` stored for ``params`` under ``kind``, or None when there is no
    usable entry (missing, unreadable, corrupt, another key, or an array missing).

    Parameters
    ----------
    kind : str
        Subfolder of the cache (e.g. ``"mie"``).
    params : dict
        JSON-serialisable description of everything the result depends on.
    names : iterable of str
        The arrays expected in the entry.
    """
    path = _entry_path(kind, params)
    try:
        with np.load(path, allow_pickle=False) as npz:
            if str(npz[_KEY_FIELD]) != _canonical(params):
                return None
            return {n: npz[n] for n in names}
    except Exception:  # any bad file is a miss: zip, pickle, OS, key and value errors alike
        return None


def store_entry(kind: str, params: dict, arrays: dict) -> None:
    """Store ``arrays`` for ``params`` under ``kind`` atomically; silently do nothing when
    the cache folder cannot be created or written."""
    path = _entry_path(kind, params)

    def _write(tmp: Path):
        with open(tmp, "wb") as f:     # a file object: np.savez would append ".npz" to a name
            np.savez(f, **{_KEY_FIELD: np.array(_canonical(params))}, **arrays)

    try:
        atomic_write(path, _write)
    except OSError:  # OutputPathError, WriteError (both OSError) or a stray OS error
        pass


def library_versions(*names: str) -> dict:
    """Installed versions of the libraries ``names`` (their distribution names), for an
    entry's key: an upgraded library then misses instead of returning old results; a
    library not installed as a distribution is ``"unknown"``."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for n in names:
        try:
            out[n] = version(n)
        except PackageNotFoundError:  # pragma: no cover - an unpackaged build
            out[n] = "unknown"
    return out


def finite_float_arrays(entry: dict, shapes: dict) -> bool:
    """Whether every array ``name`` of ``shapes`` in ``entry`` is finite float64 of shape
    ``shapes[name]``: what a loaded entry must hold to be used rather than recomputed."""
    return all(entry[k].dtype == np.float64 and entry[k].shape == tuple(shape)
               and bool(np.isfinite(entry[k]).all()) for k, shape in shapes.items())
