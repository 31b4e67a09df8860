"""Gap diagnosis: estimator round trips, noise floor, blind verdicts, bad input, both schemas.

Data come from :func:`experiments.workflows.diagnose.simulate_session` (the benchmark
generator: Yang 2014 error model, six sweeps over an afternoon); the diagnoser sees only the
tables.
"""

import json

import numpy as np
import pandas as pd
import pytest

from calibration import effects as E
from calibration.diagnosis import (
    DIAGNOSIS_SCHEMA,
    AllNaNChannelError,
    DiagnosisReport,
    InsufficientDataError,
    MissingSiteError,
    SingleHeadingError,
    UnsupportedInstrumentError,
    data_from_photodiodes,
    data_from_table,
    diagnose,
    fit_model,
    noise_floor_V,
)
from experiments.cli.main import main
from experiments.workflows.diagnose import run_benchmark, score_benchmark, simulate_session
from sensor.photodiodes_io import PHOTODIODES_SCHEMA, PhotodiodeData

SENSOR_EFFECTS = ("dark_current", "sun_motion", "clock_offset", "tilt", "turntable_periodic",
                  "extinction_ratio", "thermal_drift")


@pytest.fixture(scope="module")
def tilt_case():
    ds = simulate_session("tilt", np.random.default_rng(21), params=[1.2, -0.8])
    return ds, diagnose(ds["data"], SENSOR_EFFECTS)


@pytest.fixture(scope="module")
def none_case():
    ds = simulate_session(None, np.random.default_rng(22))
    return ds, diagnose(ds["data"], SENSOR_EFFECTS)


@pytest.mark.parametrize("name,params", [("tilt", [1.2, -0.8]),
                                         ("thermal_drift", [2e-3, 0.1, -0.15, 0.05]),
                                         ("sun_motion", [700.0])])
def test_fit_recovers_injected_effect_parameters(name, params):
    ds = simulate_session(name, np.random.default_rng(5), params=params)
    d = ds["data"]
    eff = E.get_effect(name)
    base = fit_model(d.ctx, d.U, d.valid, sigma_V=4e-4)
    fit = fit_model(d.ctx, d.U, d.valid, eff, base0=base.base, sigma_V=4e-4)
    se = np.sqrt(np.diag(fit.covariance)[10:])
    assert fit.converged
    # unbiased estimate with the noise the data carry: within 4 standard errors
    assert np.all(np.abs(fit.params - params) <= 4 * se), (fit.params, params, se)
    np.testing.assert_allclose(fit.base[:6], ds["truth"]["errors"]["misalignment_deg"],
                               atol=0.05)


def test_noise_floor_from_second_differences():
    rng = np.random.default_rng(0)
    n, blocks = 121, 6
    k = np.arange(n * blocks)
    smooth = 2e-3 * np.sin(2 * np.pi * (k % n) / n)[:, None] * np.ones(3)
    sigma = 4e-4
    r = smooth + sigma * rng.standard_normal((n * blocks, 3))
    est, per_channel = noise_floor_V(r, np.ones(r.shape, bool), k // n)
    # 2178 squared second differences with lag correlations -2/3, 1/6: relative SE of the
    # RMS estimate ~2.1 %; the smooth 5-sigma term leaks (2 pi / 121)^2 = 0.3 % of itself.
    # 8 % is ~4 standard errors.
    assert abs(est / sigma - 1) < 0.08
    assert np.all(np.abs(per_channel / sigma - 1) < 0.14)


def test_verdict_none_on_effect_free_data(none_case):
    _, doc = none_case
    v = doc.verdict
    assert v.effect == "none"
    assert v.gap_before <= 1.1 * doc.noise_floor
    assert v.shrink == 0.0


def test_verdict_names_the_hidden_effect_and_estimates_the_shrink(tilt_case):
    ds, doc = tilt_case
    v = doc.verdict
    assert v.effect == "tilt"
    clean = diagnose(ds["clean_data"], [])
    shrink_true = 1 - clean.verdict.gap_before / v.gap_before
    # acceptance of the issue: shrink within +-0.20 of the truth (same data without effect)
    assert abs(v.shrink - shrink_true) <= 0.20
    assert v.gap_before > 2 * doc.noise_floor
    p = v.params
    assert abs(p["tilt_x_deg"]["value"] - 1.2) <= 4 * p["tilt_x_deg"]["se"] + 1e-3


def test_leave_one_out_never_names_a_wrong_effect(tilt_case):
    """With the true effect withheld the others may remove part of the gap, but none is
    named: the verdict is ``unexplained``, ``partly_explained`` (with the share) or a
    ``group``, never a single wrong effect."""
    ds, doc = tilt_case
    others = [e for e in SENSOR_EFFECTS if e != "tilt"]
    rerun = diagnose(ds["data"], others)
    v = rerun.verdict
    assert v.effect in ("unexplained", "partly_explained", "group")
    assert v.gap_before == pytest.approx(doc.verdict.gap_before, rel=1e-12)
    if v.effect == "partly_explained":
        assert 0 < v.explained_share < 0.5 and v.explained_share_se > 0
    # the withheld effect's rows are the same fits: each keeps its share of the excess
    for c in rerun.candidates:
        if c.available:
            assert c.explained_share == pytest.approx(doc.candidate(c.effect).explained_share,
                                                      rel=1e-9)


def test_document_schema(tilt_case):
    _, report = tilt_case
    doc = report.to_dict()
    assert doc["schema"] == DIAGNOSIS_SCHEMA and doc["unit"] == "mV"
    for key in ("effect", "gap_before", "gap_after", "shrink", "best_candidate", "params"):
        assert key in doc["verdict"]
    scores = [c["score"] for c in doc["candidates"] if c.get("available", True)]
    assert scores == sorted(scores)
    assert {w["dimension"] for w in doc["where"]} == {"channel", "sweep", "illuminance_lx",
                                                      "sun_elevation_deg"}
    for dim in ("channel", "sweep"):   # each dimension partitions the held-out readings
        rows = [w for w in doc["where"] if w["dimension"] == dim]
        assert sum(w["n"] for w in rows) == doc["data"]["split"]["held_out_values"]
        assert sum(w["share"] for w in rows) == pytest.approx(1.0, abs=1e-12)
    assert all({"lo_lx", "hi_lx"} <= set(w) for w in doc["where"]
               if w["dimension"] == "illuminance_lx")
    assert report.carrying_gap(), "a strong tilt must show in some slice"
    assert len(doc["extra"]["harmonics"]) == 6
    text = json.dumps(doc)  # serialisable as is
    assert DiagnosisReport.from_dict(json.loads(text)).to_dict() == doc


def test_dirty_data_is_flagged_counted_and_still_diagnosed(none_case):
    ds, _ = none_case
    m = ds["measurement"]
    t = m.table.copy()
    t.loc[5:14, "U2_V"] = np.nan
    t.loc[100:102, "U1_V"] = 9.9997  # at the +10 V rail of the 16-bit DAQ
    t.loc[200:202, "time"] = t.loc[199, "time"]  # a logger that repeated a stamp
    data = data_from_table(t, m.sidecar)
    c = data.cleaning
    assert c["missing_readings"] == 10 and c["saturated_readings"] == 3
    assert c["repeated_timestamps"] == 3
    assert c["excluded_readings"] == 13
    doc = diagnose(data, ["tilt", "sun_motion"])
    assert doc.data["cleaning"]["saturated_readings"] == 3
    assert doc.verdict.effect == "none"


def test_bad_input_raises_specific_errors(none_case):
    ds, _ = none_case
    m = ds["measurement"]
    t = m.table
    with pytest.raises(InsufficientDataError, match="held-out"):
        diagnose(data_from_table(t.assign(sweep=0), m.sidecar), ["tilt"])
    with pytest.raises(SingleHeadingError, match="heading"):
        diagnose(data_from_table(t.assign(heading_deg=100.0), m.sidecar), ["tilt"])
    with pytest.raises(AllNaNChannelError, match="U3_V"):
        data_from_table(t.assign(U3_V=np.nan), m.sidecar)
    with pytest.raises(E.UnknownEffectError, match="valid"):
        diagnose(ds["data"], ["tilt", "gremlins"])
    side = {k: v for k, v in m.sidecar.items() if k != "site"}
    with pytest.raises(MissingSiteError, match="site"):
        data_from_table(t, side)


def _photodiode_data(m, angles):
    t = m.table
    U = t[["U1_V", "U2_V", "U3_V"]].to_numpy()
    cols = {}
    sky = 1000.0 * (1.0 + 0.3 * np.linspace(0.0, 1.0, len(t)))  # the sky darkens
    for c, (a, b) in enumerate(((60, 150), (0, 90), (120, 30))):
        cols[f"u0_p{b:03d}"] = sky
        cols[f"u0_p{a:03d}"] = sky * 10 ** (U[:, c] / 0.5)
    table = pd.DataFrame({"time": t["time"], "yaw_deg": t["heading_deg"], "sweep": t["sweep"],
                          **{k: cols[k] for k in sorted(cols) if int(k[-3:]) in angles}})
    side = {"schema": PHOTODIODES_SCHEMA, "site": m.sidecar["site"], "yaw_reference": "north",
            "yaw_sense": "clockwise", "readings": "raw", "reading_unit": "counts",
            "adc_full_scale": 65535,
            "saturation_value": 65535,
            "units": [{"azimuth_deg": 0.0, "elevation_deg": 90.0,
                       "photodiodes": sorted(angles)}]}
    return PhotodiodeData(table, side)


def test_photodiode_schema_round_trip_gives_the_same_channels(none_case):
    ds, _ = none_case
    m = ds["measurement"]
    data = data_from_photodiodes(_photodiode_data(m, [0, 30, 60, 90, 120, 150]))
    np.testing.assert_allclose(data.U, m.table[["U1_V", "U2_V", "U3_V"]].to_numpy(),
                               rtol=0, atol=1e-12)  # exact up to float rounding of 10**x
    assert data.cleaning["photodiode_flags"]["saturated"] == 0
    with pytest.raises(UnsupportedInstrumentError, match="60/150"):
        data_from_photodiodes(_photodiode_data(m, [0, 90, 60, 150]))


def test_cli_diagnose_writes_json_report_and_figures(tilt_case, tmp_path):
    ds, _ = tilt_case
    path = ds["measurement"].write(tmp_path / "tilted.csv")
    out = tmp_path / "diag"
    assert main(["diagnose", str(path), "--effects", "tilt,turntable_periodic",
                 "--out", str(out)]) == 0
    doc = json.loads((out / "diagnosis.json").read_text())
    assert doc["verdict"]["effect"] == "tilt"
    assert (out / "report.md").read_text().startswith("# Sim-to-real gap diagnosis")
    assert (out / "residuals_by_slice.png").stat().st_size > 0
    assert (out / "gap_before_after.png").stat().st_size > 0
    assert main(["diagnose", str(path), "--effects", "tilt,nonsense"]) == 2


def test_blind_benchmark_small_n_fixed_seed_meets_acceptance():
    """CI run of the blind benchmark (the full N >= 200 run is `skysim gap-benchmark`)."""
    cases = run_benchmark(8, seed=7, effects=SENSOR_EFFECTS, progress=False)
    assert set(cases.truth) == {"none", *SENSOR_EFFECTS}  # one data set per label
    s = score_benchmark(cases)["summary"]
    strong = cases[(cases.truth != "none") & (cases.gap_ratio >= 2)]
    assert len(strong) >= 4
    # named, or in the named group of indistinguishable effects; with the truth withheld,
    # never a single wrong effect
    assert s["found_strong"] >= 0.9
    assert s["loo_not_named_strong"] >= 0.9
    assert s["none_on_effect_free"] >= 0.9
    assert s["shrink_within_tol"] >= 0.9


def test_timezone_error_of_hours_found_by_the_half_hour_search():
    """Recorded times 8 h early (a timezone error): the coarse grid of whole and half hours
    finds it; the local refinement lands within 10 min (the data set's sun moves 0.25 deg/min,
    the fit's standard error is seconds)."""
    from experiments.workflows.diagnose import simulate_session
    ds = simulate_session("clock_offset", np.random.default_rng(5), params=np.array([8 * 3600.0]))
    doc = diagnose(ds["data"], ("clock_offset", "multiple_scattering", "sun_motion"))
    assert doc.verdict.effect == "clock_offset"
    assert abs(doc.verdict.params["clock_offset_s"]["value"] - 8 * 3600.0) < 600.0


@pytest.mark.parametrize("range_v, rails", [
    ([-10, 10], (-10 + 20 / 2 ** 16, 10 - 20 / 2 ** 16)),
    (5.0, (-5 + 10 / 2 ** 16, 5 - 10 / 2 ** 16)),
    ([0, 10], (10 / 2 ** 16, 10 - 10 / 2 ** 16))])
def test_daq_range_forms(range_v, rails):
    """``range_V`` as [lo, hi] or a symmetric full scale: rails one LSB inside."""
    from calibration.diagnosis import _daq_saturation_V
    got = _daq_saturation_V({"sensor": {"daq": {"bits": 16, "range_V": range_v}}}, "x")
    assert got == pytest.approx(rails, rel=1e-12)


@pytest.mark.parametrize("daq", [{"bits": 16, "range_V": "ten"}, {"bits": "sixteen"},
                                 {"bits": 16, "range_V": [10, -10]}, [16]])
def test_malformed_daq_sidecar(daq):
    from calibration.diagnosis import _daq_saturation_V
    from sensor.measurement import MeasurementFormatError
    with pytest.raises(MeasurementFormatError, match="daq"):
        _daq_saturation_V({"sensor": {"daq": daq}}, "x")


@pytest.mark.parametrize("folds", [0, 1, 100])
def test_folds_out_of_range_refused(folds):
    from calibration.diagnosis import InsufficientDataError, assign_folds
    with pytest.raises(InsufficientDataError, match="folds"):
        assign_folds(np.repeat(np.arange(6), 4), folds)
