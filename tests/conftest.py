"""Shared fixtures: the reference-data folder, a standard site, and an on-disk cache folder
per test session (so tests never write into the user's ~/.cache)."""

from pathlib import Path

import numpy as np
import pytest

from skysim.sun import Site

from skysim.disk_cache import CACHE_DIR_ENV

REFERENCE_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "reference"


@pytest.fixture
def reference_dir():
    """``../shared/reference`` beside the repository; skip when absent (a user's clone)."""
    if not REFERENCE_DIR.is_dir():
        pytest.skip(f"reference data folder {REFERENCE_DIR} not present (CI and the project "
                    "workspace have it beside the repository)")
    return REFERENCE_DIR


@pytest.fixture
def xian():
    """The Yang et al. (2014) rooftop."""
    return Site(34 + 8 / 60 + 41 / 3600, 108 + 32 / 60 + 48 / 3600, 400.0)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def session_cache_dir(tmp_path_factory):
    """One empty on-disk cache folder (:mod:`skysim.disk_cache`) for the whole session."""
    return tmp_path_factory.mktemp("skysim-cache")


@pytest.fixture(autouse=True)
def _isolated_cache_dir(session_cache_dir, monkeypatch):
    """Point ``SKYSIM_CACHE_DIR`` at the session's folder in every test (and the processes it
    starts), never at the user's real cache."""
    monkeypatch.setenv(CACHE_DIR_ENV, str(session_cache_dir))


@pytest.fixture
def empty_cache_dir(tmp_path, monkeypatch):
    """An empty on-disk cache folder of this test alone (``SKYSIM_CACHE_DIR``), for tests of
    what a cache holds; the folder is created on first write."""
    path = tmp_path / "cache"
    monkeypatch.setenv(CACHE_DIR_ENV, str(path))
    return path


@pytest.fixture
def effect_jacobians():
    """``jacobians(ctx, base, eff, p, k)``: a three-pair effect's analytic Jacobian of the
    outputs with respect to its ``k`` parameters, and the same by central differences with
    steps 1e-2 of the fit's own, both of shape ``(ctx.n, 3, k)`` as computed."""
    from calibration import effects as E

    def jacobians(ctx, base, eff, p, k):
        phi, shape = E.geometry(ctx)
        _, analytic = E.jacobians(ctx, phi, shape, base, eff, p)
        central = []
        for j in range(k):
            h = eff.fd_step[j] * 1e-2
            up, dn = p.copy(), p.copy()
            up[j] += h
            dn[j] -= h
            central.append((E.forward(ctx, base, eff, up) - E.forward(ctx, base, eff, dn))
                           / (2 * h))
        return analytic, np.stack(central, axis=-1)
    return jacobians
