"""Shared fixtures: the reference-data folder and a standard site."""

from pathlib import Path

import numpy as np
import pytest

from skysim.sun import Site

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
