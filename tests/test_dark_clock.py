"""A session stamped after dusk by a clock hours off, while its units read a lit sky: the
clock is searched first (:mod:`calibration.photodiode_diagnosis.dark_clock`)."""

from pathlib import Path

import pandas as pd
import pytest
from ring_sessions import ring_session

from calibration.photodiode_diagnosis import SunTooLowError, diagnose_photodiodes
from sensor.photodiodes_io import PhotodiodeData, read_photodiodes

REAL = Path(__file__).resolve().parents[2] / "shared" / "reference" / "gkanias2023"


@pytest.fixture(scope="module")
def evening():
    """An evening session (sun 10 -> 9 deg) recorded 2 h late: the recorded times put the sun
    at -10.9 to -11.7 deg, below the twilight limit (-10 deg)."""
    s = ring_session(start="2022-05-12T19:30:00+02:00", n_sweeps=3, per_sweep=60)
    t = s.table.copy()
    t["time"] = t["time"] + pd.Timedelta(hours=2)
    return PhotodiodeData(t, s.sidecar)


def test_clock_hours_off_after_dusk_is_found_first(evening):
    """Named, and fitted within 10 min of -2 h (the criterion for a clock error on a real
    ring; the sun moves 0.2 deg/min here, the fine fit reads far less)."""
    doc = diagnose_photodiodes(evening, ("clock_offset",), n_folds=3)
    v = doc["verdict"]
    assert v["effect"] == "clock_offset"
    assert v["params"]["clock_offset_s"]["value"] == pytest.approx(-7200.0, abs=600.0)
    assert "below the twilight limit" in v["reason"]
    assert v["gap_before"] is None and v["gap_after"] is not None
    assert doc["dark_clock"]["coarse_offset_s"] in (-7200.0, -5400.0, -9000.0)
    assert "at_corrected_times" in v


def test_deep_twilight_with_a_clock_hours_off_is_found():
    """The same evening session stamped 1 h 40 min late: the recorded times put the sun at
    -7.7 to -8.2 deg, inside the model's range but within 3 deg of its limit, where a clock
    fit from the recorded times walks below the limit. The coarse search, the recorded times
    among its offsets, finds the clock."""
    s = ring_session(start="2022-05-12T19:30:00+02:00", n_sweeps=3, per_sweep=60)
    t = s.table.copy()
    t["time"] = t["time"] + pd.Timedelta(minutes=100)
    doc = diagnose_photodiodes(PhotodiodeData(t, s.sidecar), ("clock_offset",), n_folds=3)
    v = doc["verdict"]
    assert v["effect"] == "clock_offset" and "deep twilight" in v["reason"]
    assert v["params"]["clock_offset_s"]["value"] == pytest.approx(-6000.0, abs=600.0)


def test_deep_twilight_with_the_right_clock_is_diagnosed_as_it_is():
    """A session at sun -7.7 to -8.2 deg with its clock right: the recorded times win the
    coarse search, the session is diagnosed at them and no clock is named."""
    s = ring_session(start="2022-05-12T21:10:00+02:00", n_sweeps=3, per_sweep=60)
    doc = diagnose_photodiodes(s, ("clock_offset",), n_folds=3)
    assert doc["verdict"]["effect"] != "clock_offset"
    assert "dark_clock" not in doc
    row = next(c for c in doc["candidates"] if c["effect"] == "clock_offset")
    assert abs(row["params"]["clock_offset_s"]["value"]) < 600.0


def test_without_the_clock_candidate_the_twilight_error_stands(evening):
    with pytest.raises(SunTooLowError, match="below the twilight limit"):
        diagnose_photodiodes(evening, ("yaw_scale",), n_folds=3)


@pytest.mark.skipif(not REAL.is_dir(), reason="needs ../shared/reference/gkanias2023")
def test_a_dark_session_keeps_the_twilight_error():
    """The real session at dusk (sun -6.5 deg, its converter reading 0/1 counts) stamped 2 h
    late: a clock search finds no time at which the units read a usable sky, so the twilight
    error stands instead of a clock fitted to darkness."""
    data = read_photodiodes(REAL / "tod_Thursday_12-05-22_21-03-00_CEST.csv")
    t = data.table.copy()
    t["time"] = pd.to_datetime(t["time"]) + pd.Timedelta(hours=2)
    with pytest.raises(SunTooLowError, match="below the twilight limit"):
        diagnose_photodiodes(PhotodiodeData(t, data.sidecar), ("clock_offset",), n_folds=3)
