"""The ring's noise floor on smoothed readings: measured from standing readings, or reported
unknown with the verdict measured against the whole gap; clean rings keep their floor
(simulated rings of ``tests/ring_sessions.py``)."""

import numpy as np
import pandas as pd
import pytest
from ring_sessions import SITE, ring_session

from calibration.diagnosis.core import FLOOR_UNKNOWN_NOTE
from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes
from calibration.photodiode_diagnosis.run import (NOISE_FLOOR_METHOD, diagnose_instrument,
                                                  diagnose_photodiodes, result_dict,
                                                  standing_stretches)
from sensor.compound_eye import PhotodiodeModel, ring_configuration
from sensor.photodiodes_io import PhotodiodeData
from skysim.sky import RayleighSky


def stop_and_go(n_sweeps=3, stand=30, turn=90, seed=1, stops=(0.0,)):
    """A relative-yaw ring session (as :func:`ring_sessions.ring_session`) whose every sweep
    stands ``stand`` samples at each yaw of ``stops`` [deg], then turns once in ``turn``
    samples."""
    rng = np.random.default_rng(seed)
    sensor = ring_configuration(8, 45.0, photodiode=PhotodiodeModel())
    t0 = pd.Timestamp("2022-05-12T10:00:00+02:00")
    per = stand * len(stops) + turn
    times = pd.DatetimeIndex([t0 + pd.Timedelta(seconds=60 * s + 0.1 * k)
                              for s in range(n_sweeps) for k in range(per)])
    one = np.r_[np.repeat(stops, stand), np.linspace(0.0, 360.0, turn, endpoint=False)]
    yaw = np.tile(one, n_sweeps) + 20.0
    data = sensor.sample(RayleighSky(0.6), SITE, times, yaw, 0.0, 0.0, rng,
                         yaw_reference="relative", yaw_offset_deg=35.0, include_truth=False,
                         sweep=np.repeat(np.arange(n_sweeps), per))
    t = data.table.drop(columns=["pitch_deg", "roll_deg"])
    t["yaw_deg"] = -(((t["yaw_deg"] + 180.0) % 360.0) - 180.0)      # ccw, wrapped
    return PhotodiodeData(t, dict(data.sidecar, yaw_sense="counterclockwise"))


def smoothed(data: PhotodiodeData, width: int = 5) -> PhotodiodeData:
    """The photodiode readings through a ``width``-point moving average along each sweep
    (ends padded with the end value), as an author's pre-filtered file would hold them."""
    t = data.table.copy()
    cols = [c for c in t.columns if c.startswith("u") and "_p" in c]
    for s in np.unique(t["sweep"]):
        m = (t["sweep"] == s).to_numpy()
        x = np.pad(t.loc[m, cols].to_numpy(float), ((width // 2, width // 2), (0, 0)),
                   mode="edge")
        c = np.cumsum(np.vstack([np.zeros((1, len(cols))), x]), axis=0)
        t.loc[m, cols] = (c[width:] - c[:-width]) / width
    return PhotodiodeData(t, data.sidecar)


@pytest.fixture(scope="module")
def turning_smoothed():
    return diagnose_photodiodes(smoothed(ring_session(seed=2)), ("yaw_scale",), n_folds=3)


@pytest.fixture(scope="module")
def stop_and_go_docs():
    raw = stop_and_go()
    return (diagnose_photodiodes(raw, ("yaw_scale",), n_folds=3),
            diagnose_photodiodes(smoothed(raw), ("yaw_scale",), n_folds=3))


def test_smoothed_ring_without_standing_readings_has_an_unknown_floor(turning_smoothed):
    """Every sample turning: no standing readings, so the floor is unknown (null, with the
    reason), the verdict says so first and is never ``none``, and each candidate's share is
    of the whole held-out gap, ``(G_0^2 - G_c^2) / G_0^2`` on the same readings (to
    rounding, 1e-9)."""
    doc = turning_smoothed
    nf = doc["noise_floor"]
    assert nf["rms"] is None and nf["method"].startswith("unknown: the residuals are not white")
    assert nf["whiteness"]["white"] is False and nf["replica_held_out_gap"] is None
    assert nf["whiteness"]["lag1"] > -0.5       # -2/3 for white noise
    v = doc["verdict"]
    assert v["reason"].startswith(FLOOR_UNKNOWN_NOTE) and v["effect"] != "none"
    g0 = v["gap_before"]
    for c in doc["candidates"]:
        if c.get("available", True):
            assert c["explained_share"] == pytest.approx(1 - c["gap_after"] ** 2 / g0 ** 2,
                                                         abs=1e-9)


def test_standing_stretches_leave_out_the_turns_ends():
    """Each 30-sample stand keeps its middle half (the quarters next to a turn, where a
    filter carries the turn, left out); turning samples are -1."""
    inst = instrument_from_photodiodes(stop_and_go())
    st = standing_stretches(inst)
    ids, counts = np.unique(st[st >= 0], return_counts=True)
    long = counts[counts > 4]
    assert long.size == 3 and np.all((long >= 14) & (long <= 17))
    assert np.all(st[inst.rotating] == -1)


def test_smoothed_ring_with_standing_readings_measures_the_noise(stop_and_go_docs):
    """With standing stretches the floor is their scatter (then the noise-only replicas'
    gap at that RMS on top). The noise of 5-point averaged readings is the raw noise over
    sqrt(5) (the raw session's second-difference RMS, white, is that noise): the standing
    RMS reads 0.80-1.05 of it (closed form for 15 correlated readings a stretch: 0.87, see
    ``tests/test_noise_whiteness.py``; measured 0.9x), where the second differences of the
    smoothed residuals read 16 times it (the turns' smoothing outweighs the noise), so the
    white-noise floor would have been no measurement of it either way."""
    raw, smooth = stop_and_go_docs
    assert raw["noise_floor"]["whiteness"]["white"] is True
    assert raw["noise_floor"]["method"] == NOISE_FLOOR_METHOD
    assert raw["verdict"]["effect"] == "none"
    noise = raw["noise_floor"]["white_noise_rms"] / np.sqrt(5)
    nf = smooth["noise_floor"]
    assert nf["whiteness"]["white"] is False and "standing" in nf["method"]
    assert 0.80 < nf["standing_rms"] / noise < 1.05
    assert nf["rms"] == pytest.approx(max(nf["standing_rms"], nf["replica_held_out_gap"]))
    assert nf["white_noise_rms"] > 5 * noise
    assert smooth["verdict"]["effect"] != "none"
    assert not smooth["verdict"]["reason"].startswith(FLOOR_UNKNOWN_NOTE)


def late_while_turning(frac=1.0):
    """The session of ``tests/test_instrument_checks.py`` (8 sweeps, each standing at four
    headings and then turning) with unit 4's 45 and 90 deg photodiodes reading ``frac`` of
    a sample late while the ring turns (as that test plants it, 1 a whole sample)."""
    from test_instrument_checks import _session
    inst, _ = _session()
    r = inst.readings.copy()
    cols = [17, 18]
    late = (1 - frac) * r[:, cols] + frac * np.roll(r[:, cols], 1, axis=0)
    r[:, cols] = np.where(inst.rotating[:, None], late, r[:, cols])
    return inst.with_readings(r)


@pytest.fixture(scope="module")
def late_unit_doc():
    return result_dict(diagnose_instrument(late_while_turning(), ("yaw_scale",), n_folds=3))


@pytest.mark.parametrize("frac", [1.0, 0.25])
def test_unit_failing_in_motion_is_a_fault(frac, late_unit_doc):
    """Unit 4's photodiodes read late while the ring turns: off Malus's law then, so the
    fault screen excludes them (``not_malus``: it does so down to 3 % of a sample) and the
    checks of the screened readings no longer see the unit; the checks of the readings
    before the screen name it as failing only in motion (turning over standing sum-rule RMS
    measured 159 for a whole sample, 37 for a quarter), and the report's faults list it,
    kind ``fails_in_motion``, with that evidence and the screen's exclusions. The fault
    itself excludes nothing: the screen's faults are listed unchanged before it."""
    doc = late_unit_doc if frac == 1.0 else result_dict(
        diagnose_instrument(late_while_turning(frac), ("yaw_scale",), n_folds=3))
    motion = [f for f in doc["faults"] if f["kind"] == "fails_in_motion"]
    assert [f["channel"] for f in motion] == ["u4"]
    assert doc["faults"][-1] is motion[0]
    ev = motion[0]["evidence"]
    assert ev["readings"] == "unscreened" and "not_malus" in ev["excluded_by_screen"]
    assert ev["turning_over_standing"] > 10 * ev["factor"]
    assert ev["sum_rule_rms_turning"] > 10 * ev["factor"] * ev["units_median_rms_turning"]
    assert doc["instrument_checks"]["units_failing_in_motion"] == []


def test_motion_faults_from_screened_checks_exclude_nothing():
    """A unit the screened checks name is listed from them (``readings: screened``, nothing
    excluded by the screen); the unscreened checks add only units the screen excluded."""
    from calibration.photodiode_diagnosis.checks import motion_faults
    motion = [{"unit": u, "rms_standing": 1e-3, "rms_turning": t, "ratio": t / 1e-3,
               "fails_in_motion": u == 2} for u, t in enumerate([1e-3, 1.2e-3, 9e-3])]
    checks = {"motion": motion, "units_failing_in_motion": [2]}
    unscreened = {"motion": motion, "units_failing_in_motion": [1, 2]}
    out = motion_faults(checks, unscreened, [{"channel": "u1_p045", "kind": "not_malus"},
                                             {"channel": "u1", "kind": "too_few"}])
    assert [(f["channel"], f["evidence"]["readings"]) for f in out] == [
        ("u1", "unscreened"), ("u2", "screened")]
    assert out[1]["evidence"]["excluded_by_screen"] == []
    assert out[1]["evidence"]["turning_over_standing"] == pytest.approx(9.0)
    assert out[1]["evidence"]["units_median_rms_turning"] == pytest.approx(1.2e-3)
    assert motion_faults(checks) == out[1:]
    # a unit the screen excluded for a dead photodiode is no motion failure
    stuck = motion_faults(checks, unscreened, [{"channel": "u1_p045", "kind": "stuck"}])
    assert [f["channel"] for f in stuck] == ["u2"]


def test_where_crosses_motion_with_sun_distance(late_unit_doc):
    """``motion_sun_distance`` splits the held-out readings four ways (rotating/standing x
    within/beyond 50 deg of the sun, with those bounds), a partition of the readings of the
    ``motion`` dimension whose shares add to 1."""
    doc = late_unit_doc
    rows = [w for w in doc["where"] if w["dimension"] == "motion_sun_distance"]
    assert sorted(w["label"] for w in rows) == sorted(
        f"{m}, {n} 50 deg of the sun" for m in ("rotating", "standing")
        for n in ("within", "beyond"))
    for w in rows:
        assert (w["lo_deg"], w["hi_deg"]) == ((0.0, 50.0) if "within" in w["label"]
                                              else (50.0, 180.0))
    assert sum(w["share"] for w in rows) == pytest.approx(1.0, abs=1e-9)
    motion = {w["label"]: w["n"] for w in doc["where"] if w["dimension"] == "motion"}
    for m in ("rotating", "standing"):
        assert sum(w["n"] for w in rows if w["label"].startswith(m)) == motion[m]
