"""Photodiode-instrument diagnosis benchmark (run with `make bench`; disabled in `make test`).

Goal: a 5,000-sample, 32-photodiode session with all candidates in <= 60 s on one core
(reported, never asserted as a time). Baseline in the same run: the base model alone (the fault
screen, orientation, base fit and held-out gap every diagnosis pays). Data: a real ring-compass
session of the reference folder (skipped when it is absent).
"""

from pathlib import Path

import numpy as np
import pytest

from calibration.photodiode_diagnosis import RING_EFFECT_NAMES, diagnose_photodiodes

REAL = (Path(__file__).resolve().parents[3] / "shared" / "reference" / "gkanias2023"
        / "tod_Thursday_12-05-22_16-01-54_CEST.csv")


@pytest.fixture(scope="module")
def session():
    if not REAL.exists():
        pytest.skip("reference recordings ../shared/reference/gkanias2023 not present")
    from sensor.photodiodes_io import read_photodiodes
    return read_photodiodes(REAL)


@pytest.mark.benchmark(group="photodiode diagnosis 5k x 32")
def test_photodiode_base_only_baseline(benchmark, session):
    benchmark.extra_info.update(items=len(session.table), baseline=True)
    doc = benchmark.pedantic(diagnose_photodiodes, args=(session, ()), rounds=1, iterations=1)
    assert np.isfinite(doc["verdict"]["gap_before"])


@pytest.mark.benchmark(group="photodiode diagnosis 5k x 32")
def test_photodiode_all_candidates(benchmark, session):
    benchmark.extra_info.update(items=len(session.table), candidates=len(RING_EFFECT_NAMES),
                                goal={"max_s": 60})
    doc = benchmark.pedantic(diagnose_photodiodes, args=(session, RING_EFFECT_NAMES), rounds=1,
                             iterations=1)
    assert len(doc["candidates"]) == len(RING_EFFECT_NAMES)
