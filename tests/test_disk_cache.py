"""Where the on-disk cache lives (skysim.disk_cache.cache_root) and that an entry is found
only under its own parameters (no engine needed)."""

from pathlib import Path

import numpy as np

from skysim.disk_cache import CACHE_DIR_ENV, cache_root, entry_key, load_entry, store_entry


def test_cache_root_order(monkeypatch, tmp_path):
    """``$SKYSIM_CACHE_DIR``, else ``$XDG_CACHE_HOME/skysim``, else ``~/.cache/skysim``."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv(CACHE_DIR_ENV, raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert cache_root() == tmp_path / "home" / ".cache" / "skysim"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == tmp_path / "xdg" / "skysim"
    monkeypatch.setenv(CACHE_DIR_ENV, str(tmp_path / "mine"))
    assert cache_root() == tmp_path / "mine"


def test_test_session_never_uses_the_users_cache():
    """tests/conftest.py points every test at a temporary folder."""
    assert not cache_root().is_relative_to(Path.home() / ".cache")


def test_entry_round_trip_and_key_separation(monkeypatch, tmp_path):
    monkeypatch.setenv(CACHE_DIR_ENV, str(tmp_path))
    params = {"a": 0.1, "b": [1.53, -0.006], "n": 16}
    arr = np.random.default_rng(0).normal(size=(16, 4))
    store_entry("k", params, {"x": arr})
    got = load_entry("k", params, ["x"])
    assert np.array_equal(got["x"], arr)
    # key order does not matter; a changed value or a missing array does
    assert load_entry("k", dict(reversed(params.items())), ["x"]) is not None
    assert entry_key({**params, "a": float("0.10000000000000000001")}) == entry_key(params)
    assert load_entry("k", {**params, "a": np.nextafter(0.1, 1.0)}, ["x"]) is None
    assert load_entry("k", params, ["x", "y"]) is None
    assert load_entry("other", params, ["x"]) is None
