"""The shared diagnosis core, report and entry point: each formula against an independent
form (closed form, a second implementation, a Monte-Carlo rate), the report's round trips,
the readers of the earlier report dicts, the sun track, and the dispatch of
:func:`calibration.diagnose`.
"""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from calibration import DiagnosisReport, diagnose
from calibration.diagnosis import (
    DIAGNOSIS_SCHEMA,
    Candidate,
    InsufficientDataError,
    ReportFormatError,
    Thresholds,
    ThresholdsError,
    UnsupportedInstrumentError,
    assign_folds,
    core,
    decide,
    noise_floor,
)
from calibration.effects import UnknownEffectError
from skysim.sun import Site, SunTrack, sun_vector

GOLDEN = Path(__file__).resolve().parent / "golden"


# ------------------------------------------------------------------------------ core
def test_folds_hold_out_whole_blocks_round_robin():
    block = np.repeat([3, 5, 8, 9, 12], [4, 2, 3, 5, 1])
    f = assign_folds(block, 2)
    for b in np.unique(block):                      # a block never straddles the split
        assert np.unique(f[block == b]).size == 1
    assert [int(f[block == b][0]) for b in (3, 5, 8, 9, 12)] == [0, 1, 0, 1, 0]
    with pytest.raises(InsufficientDataError, match="at least 2"):
        assign_folds(np.zeros(10, int), 2)
    with pytest.raises(InsufficientDataError, match="folds=6"):
        assign_folds(block, 6)


def test_noise_floor_skips_excluded_readings_without_bias():
    """White noise: E[(r_{k+1} - 2 r_k + r_{k-1})^2] = 6 sigma^2 exactly, also when excluded
    readings are skipped (the skipped-over values are as independent as neighbours). 6000
    readings in 3 channels, a third of them excluded: ~12,000 squared differences with lag
    correlations -2/3 and 1/6, relative SE of the RMS ~1.1 %; 5 % is more than 4 SE."""
    rng = np.random.default_rng(4)
    sigma = np.array([1.0, 2.0, 0.5])
    r = rng.standard_normal((6000, 3)) * sigma
    usable = rng.random(r.shape) > 1 / 3
    r[~usable] = 1e6                                 # excluded readings never enter
    block = np.repeat(np.arange(6), 1000)
    pooled, per = noise_floor(r, usable, block)
    np.testing.assert_allclose(per, sigma, rtol=0.05)
    assert pooled == pytest.approx(np.sqrt(np.mean(sigma ** 2)), rel=0.05)
    # a channel without three consecutive usable readings has no floor (NaN, not 0)
    usable[:, 2] = False
    usable[:2, 2] = True
    assert np.isnan(noise_floor(r, usable, block)[1][2])


def test_held_out_score_is_the_bic_difference():
    """Gaps above the floor: the score equals BIC_c - BIC_0 of Gaussian residuals,
    ``n ln(RSS/n) + k ln n_cal``, written out here from the residual sums of squares."""
    n, n_cal, k0, kc = 900, 600, 10, 12
    rss0, rssc = n * 2.0 ** 2, n * 1.5 ** 2
    bic0 = n * np.log(rss0 / n) + k0 * np.log(n_cal)
    bicc = n * np.log(rssc / n) + kc * np.log(n_cal)
    got = core.held_out_score(1.5, 2.0, 0.5, n, kc - k0, n_cal)
    assert got == pytest.approx(bicc - bic0, rel=1e-12)
    # both below the floor: only the complexity remains (the simpler model wins)
    assert core.held_out_score(0.4, 0.45, 0.5, n, 2, n_cal) == pytest.approx(2 * np.log(n_cal))


def _cand(effect, gap, score, *, share=0.9, share_se=0.05, d=None, d_se=1.0, base_d=5.0,
          base_se=1.0, at_bound=(), converged=True, available=True, **details):
    """A scored candidate row carrying the paired comparison :func:`core.judge` fills:
    ``d`` (paired difference against the best, ± ``d_se``), ``base_d`` (base minus it)."""
    if not available:
        return Candidate.unavailable(effect, "missing engine")
    return Candidate(effect, gap_after=gap, shrink=0.0, score=score, converged=converged,
                     paired_difference=d, paired_difference_se=None if d is None else d_se,
                     explained_share=share, explained_share_se=share_se,
                     at_bound=list(at_bound),
                     details={"base_difference": base_d, "base_difference_se": base_se,
                              **details})


def test_verdict_rule_branches():
    """Each branch of the paired rule: a single effect only when it (a) beats every other
    candidate and the base by more than 2 paired SE, (b) converged away from its bounds,
    (c) removes at least half the excess; else group, partly explained, unexplained, none."""
    t = Thresholds()
    floor = 1.0
    a = _cand("a", 1.05, -50.0, d=0.0, d_se=0.0)
    b = _cand("b", 1.5, -40.0, share=0.6, d=3.0, d_se=1.0)           # beaten by 3 SE
    c = _cand("c", 0.9, 0.0, available=False)
    assert decide([a, b, c], 1.09, floor, t).effect == "none"        # within 1.1 x floor
    named = decide([a, b, c], 3.0, floor, t)
    assert (named.effect, named.group, named.share) == ("a", [], 0.9)
    # b within 2 paired SE of a: the data cannot tell them apart
    close = _cand("b", 1.1, -45.0, d=1.5, d_se=1.0, separated_by="a clear-sky sweep at noon")
    g = decide([a, close], 3.0, floor, t)
    assert g.effect == "group" and g.group == ["a", "b"]
    assert "to separate them: b: a clear-sky sweep at noon" in g.reason
    # a significant share below one half: partly explained, with the share
    p = decide([_cand("a", 2.5, -50.0, share=0.3, share_se=0.05, d=0.0)], 3.0, floor, t)
    assert p.effect == "partly_explained" and p.share == 0.3 and "30 +- 5 %" in p.reason
    # not better than the base model by 2 paired SE, in its difference or in the share of
    # the excess it removes: unexplained
    assert decide([_cand("a", 2.9, -5.0, base_d=1.0, base_se=1.0, d=0.0, share=0.1,
                         share_se=0.1)], 3.0, floor, t).effect == "unexplained"
    # a difference within 2 SE (an effect whose size varies by block) but a share of the
    # excess far above 0 in every block: it beats the base
    assert decide([_cand("a", 1.0, -50.0, base_d=1.0, base_se=1.0, d=0.0, share=0.97,
                         share_se=0.01)], 3.0, floor, t).effect == "a"
    # a parameter at its bound, or no convergence: not named, the reason says why
    bound = decide([_cand("a", 1.0, -50.0, d=0.0, at_bound=["tau"])], 3.0, floor, t)
    assert bound.effect == "unexplained" and "tau sits at a bound" in bound.reason
    assert "form is wrong" in bound.reason and "range is too narrow" in bound.reason
    assert decide([_cand("a", 1.0, -50.0, d=0.0, converged=False)], 3.0, floor,
                  t).effect == "unexplained"
    assert tuple(decide([c], 3.0, floor, t)) == ("unexplained",
                                                "no candidate effect was applicable")
    # ties in score go to the smaller held-out gap; unavailable rows last
    ranked = core.rank([_cand("x", 1.2, -3.0), _cand("y", 1.1, -3.0), c])
    assert [r.effect for r in ranked] == ["y", "x", "c"]


def test_verdict_options_block_consistency_and_null():
    """The rule's options: ``block_consistency`` also asks the named effect to lower the gap
    in that fraction of the held-out blocks; a fitted effect indistinguishable from its null
    is never named; ``explains`` keeps its gap-only test."""
    t = Thresholds(block_consistency=0.75, block_name="sweeps")
    floor, g0 = 1.0, 3.0
    ok = decide([_cand("a", 1.2, -50.0, d=0.0, blocks_improved=0.8)], g0, floor, t)
    assert ok.effect == "a" and "held-out sweeps" in ok.reason
    few = decide([_cand("a", 1.2, -50.0, d=0.0, blocks_improved=0.7)], g0, floor, t)
    assert few.effect == "unexplained" and "75 %" in few.reason
    assert decide([_cand("a", 1.2, -50.0, d=0.0, blocks_improved=1.0, null_excluded=False)],
                  g0, floor, t).effect == "unexplained"
    g_5 = np.sqrt(9.0 - 0.05 * 8.0)                        # removes exactly 5 %
    assert core.excess_removed(g_5, g0, floor) == pytest.approx(0.05, rel=1e-12)
    t5 = Thresholds(residual_excess=0.95, block_consistency=0.75)
    assert core.explains(g_5 - 1e-9, g0, floor, t5, blocks_improved=0.75)
    assert not core.explains(g_5 - 1e-9, g0, floor, t5, blocks_improved=0.7)
    with pytest.raises(ThresholdsError, match="blocks_improved"):
        core.explains(2.0, g0, floor, t5)
    with pytest.raises(ThresholdsError, match="residual_excess=1.5"):
        Thresholds(residual_excess=1.5)
    with pytest.raises(ThresholdsError, match="min_share=2"):
        Thresholds(min_share=2)


def test_blocks_improved_counts_blocks_whose_sum_of_squares_falls():
    """Against a loop over blocks: block 0 improves, block 1 worsens, block 2 improves on
    its finite values (NaN = reading not used)."""
    block = np.repeat([0, 1, 2], 4)
    r0 = np.array([1, 1, 1, 1, 1, 1, 1, 1, 2, 2, np.nan, 2.0])[:, None] * np.ones((1, 2))
    r1 = np.array([0.5, 1, 1, 1, 1, 1, 1, 1.5, 1, 2, 9.0, 2])[:, None] * np.ones((1, 2))
    r1[10] = np.nan
    loop = np.mean([np.nansum(r1[block == b] ** 2) < np.nansum(r0[block == b] ** 2)
                    for b in range(3)])
    assert core.blocks_improved(r0, r1, block) == pytest.approx(loop) == pytest.approx(2 / 3)


def test_shrink_uncertainty_equals_a_direct_block_bootstrap():
    """Against a second implementation (a loop over resamples) with the same generator."""
    rng = np.random.default_rng(0)
    block = np.repeat(np.arange(7), 30)
    r0 = rng.standard_normal((210, 3)) * 2.0
    r1 = rng.standard_normal((210, 3))
    r0[5, 1] = np.nan
    r1[5, 1] = np.nan
    got = core.shrink_uncertainty(r0, r1, block, np.random.default_rng(9), n_boot=300)
    pick = np.random.default_rng(9).integers(0, 7, (300, 7))
    g0, g1 = [], []
    for row in pick:
        m = np.concatenate([np.flatnonzero(block == b) for b in row])
        g0.append(np.sqrt(np.nanmean(r0[m] ** 2)))
        g1.append(np.sqrt(np.nanmean(r1[m] ** 2)))
    g0, g1 = np.array(g0), np.array(g1)
    assert got["gap_before_se"] == pytest.approx(np.std(g0), rel=1e-12)
    assert got["gap_after_se"] == pytest.approx(np.std(g1), rel=1e-12)
    assert got["shrink_se"] == pytest.approx(np.std(1 - g1 / g0), rel=1e-12)
    assert core.shrink_uncertainty(r0, r1, np.zeros(210), rng) is None


def test_slice_limit_is_exceeded_by_white_noise_in_one_percent_of_slices():
    """Monte Carlo: 20,000 slices of 40 white-noise values at the floor, margin 0. The
    fraction above the limit is 1 % by construction (chi-square quantile); its binomial SE is
    0.07 %, so 0.6 %..1.4 % is more than 5 SE either side."""
    rng = np.random.default_rng(1)
    floor, n = 0.3, 40
    r = rng.normal(0.0, floor, (20_000, n))
    rms = np.sqrt(np.mean(r ** 2, axis=1))
    frac = np.mean(rms > core.slice_limit(floor, n, 0.0))
    assert 0.006 < frac < 0.014
    assert core.slice_limit(floor, n, 0.0) == pytest.approx(
        floor * np.sqrt(chi2.ppf(0.99, n) / n), rel=1e-12)


def test_partition_slices_shares_add_to_one_and_locate_the_excess():
    floor = 1.0
    r2 = np.ones((100, 2))
    r2[:50, 1] = 25.0                                  # channel 1, first half: rms 5
    masks = [np.arange(2)[None, :] == c for c in range(2)]
    rows = core.partition_slices("channel", [np.broadcast_to(m, r2.shape) for m in masks],
                                 ["c0", "c1"], r2, floor, 0.1)
    by = {s.label: s for s in rows}
    assert sum(s.share for s in rows) == pytest.approx(1.0)
    assert by["c1"].share == pytest.approx(1.0) and by["c1"].carries_gap
    assert by["c0"].share == 0.0 and not by["c0"].carries_gap
    assert by["c1"].rms == pytest.approx(np.sqrt((50 * 25 + 50) / 100))
    # below the floor everywhere: shares of the sum of squares
    quiet = core.partition_slices("channel", [np.broadcast_to(m, r2.shape) for m in masks],
                                  ["c0", "c1"], 0.25 * np.ones((100, 2)), floor, 0.1)
    assert [s.share for s in quiet] == [0.5, 0.5]


# ------------------------------------------------------------------------------ report
@pytest.mark.parametrize("family,instrument,unit", [("three_pair", "three_pair", "mV"),
                                                     ("sky", "sky", "DoLP"),
                                                     ("rings", "photodiodes", "1")])
def test_reads_the_earlier_report_dicts(family, instrument, unit):
    """The ``skysim.diagnosis/1`` dicts as each diagnosis wrote them (made by
    tests/golden/make_legacy_v1.py from that code) read into one report: verdict and gaps
    as written, slices as one list with shares adding to 1 per dimension, a v2 round trip."""
    d = json.loads((GOLDEN / f"legacy_{family}_v1.json").read_text())
    r = DiagnosisReport.from_dict(d)
    assert (r.instrument, r.unit) == (instrument, unit)
    v = d["verdict"]
    assert r.verdict.effect == v["effect"]
    assert r.verdict.gap_before == v["gap_before"] and r.verdict.gap_after == v["gap_after"]
    assert r.noise_floor == pytest.approx(v["noise_floor"], rel=0)
    avail = [c for c in d["candidates"] if c.get("available", True)]
    assert sorted(c.effect for c in r.candidates) == sorted(c["effect"] for c in avail)
    for c in avail:
        assert r.candidate(c["effect"]).gap_after == c["gap_after"]
    for dim in {s.dimension for s in r.where}:
        assert sum(s.share for s in r.where if s.dimension == dim) == pytest.approx(1.0)
    assert r.data["split"]["held_out_values"] > 0        # the split named as in v2
    doc = json.loads(json.dumps(r.to_dict()))
    assert doc["schema"] == DIAGNOSIS_SCHEMA
    assert DiagnosisReport.from_dict(doc).to_dict() == doc
    assert r.to_markdown().startswith("# Sim-to-real gap diagnosis")


def test_reads_reports_written_before_the_paired_verdict():
    """A ``skysim.diagnosis/2`` report (no group, shares, paired differences, at_bound or
    not_applicable) reads with those fields empty, and writes back as the current schema."""
    d = json.loads((GOLDEN / "legacy_three_pair_v1.json").read_text())
    v2 = DiagnosisReport.from_dict(d).to_dict()
    v2["schema"] = "skysim.diagnosis/2"
    for key in ("group", "explained_share", "explained_share_se", "separated_by"):
        v2["verdict"].pop(key)
    for c in v2["candidates"]:
        for key in ("paired_difference", "paired_difference_se", "explained_share",
                    "explained_share_se", "at_bound", "not_applicable"):
            c.pop(key, None)
    r = DiagnosisReport.from_dict(v2)
    assert r.verdict.group == [] and r.verdict.explained_share is None
    assert all(c.at_bound == [] and c.paired_difference is None for c in r.candidates)
    assert r.verdict.effect == d["verdict"]["effect"]
    assert r.to_dict()["schema"] == DIAGNOSIS_SCHEMA == "skysim.diagnosis/3"


def test_ring_where_keeps_its_angular_bounds():
    d = json.loads((GOLDEN / "legacy_rings_v1.json").read_text())
    r = DiagnosisReport.from_dict(d)
    az = [s for s in r.where if s.dimension == "sky_azimuth_deg"]
    assert az and all(s.bound_unit == "deg" and s.hi - s.lo == 30.0 for s in az)
    assert all({"lo_deg", "hi_deg"} <= set(s.to_dict()) for s in az)
    # shares as the ring diagnosis computed them (the same rule, recomputed here)
    written = {(w["dimension"], w["label"]): w["share"] for w in d["where"]}
    for s in r.where:
        assert s.share == pytest.approx(written[(s.dimension, s.label)], rel=1e-9, abs=1e-15)


def test_unknown_report_schema_refused():
    with pytest.raises(ReportFormatError, match="skysim.diagnosis/9"):
        DiagnosisReport.from_dict({"schema": "skysim.diagnosis/9"})
    with pytest.raises(ReportFormatError, match="verdict"):
        DiagnosisReport.from_dict({"schema": DIAGNOSIS_SCHEMA, "unit": "mV",
                                   "instrument": "sky", "metric": "m"})


# ------------------------------------------------------------------------------ sun track
def test_sun_track_within_its_stated_error_of_the_ephemeris():
    """Off-knot times (30 s after each knot, the worst place) over a day: within 1e-4 deg
    of :func:`skysim.sun.sun_vector` (the sagitta bound in the class docstring)."""
    site = Site(34.14, 108.55, 400.0)
    t0 = pd.Timestamp("2013-05-22T00:00:00Z").value / 1e9
    track = SunTrack(site, t0, t0 + 86400.0, margin_s=0.0)
    t = t0 + 30.0 + 60.0 * np.arange(0, 1440, 7)
    exact, _ = sun_vector(pd.to_datetime(np.round(t * 1e9).astype(np.int64), utc=True), site)
    cosang = np.clip(np.sum(track(t) * exact, axis=1), -1.0, 1.0)
    assert np.degrees(np.arccos(cosang)).max() < 1e-4
    el, _ = track.elevation_azimuth(t)
    assert el.max() > 70.0 and el.min() < -20.0        # the whole day was sampled


# ------------------------------------------------------------------------------ entry point
@pytest.fixture(scope="module")
def tilt_measurement():
    from experiments.workflows.diagnose import simulate_session
    return simulate_session("tilt", np.random.default_rng(21), params=[1.2, -0.8])


def test_one_entry_point_for_a_path_a_table_and_a_dataframe(tilt_measurement, tmp_path):
    m = tilt_measurement["measurement"]
    path = m.write(tmp_path / "tilted.csv")
    by_path = diagnose(path, ("tilt", "sun_motion"), folds=3, seed=1)
    by_table = diagnose(m, ("tilt", "sun_motion"), folds=3, seed=1)
    by_frame = diagnose(m.table, ("tilt", "sun_motion"), folds=3, seed=1, sidecar=m.sidecar)
    assert by_path.instrument == "three_pair" and by_path.verdict.effect == "tilt"
    # the CSV round trip rounds the readings: same verdict, gaps within 1e-6 relative
    for r in (by_table, by_frame):
        assert r.verdict.effect == "tilt"
        assert r.verdict.gap_before == pytest.approx(by_path.verdict.gap_before, rel=1e-6)
    assert by_table.to_dict()["verdict"] == by_frame.to_dict()["verdict"]
    assert by_path.data["path"] == str(path)


def test_entry_point_refuses_what_it_cannot_read(tilt_measurement, tmp_path):
    m = tilt_measurement["measurement"]
    with pytest.raises(UnknownEffectError, match="valid"):
        diagnose(m, ("gremlins",))
    with pytest.raises(UnsupportedInstrumentError, match="SkyCases"):
        diagnose(np.zeros(3))
    path = m.write(tmp_path / "other.csv")
    side = path.with_name("other.csv.json")
    side = side if side.exists() else path.with_suffix(".json")
    side.write_text(json.dumps(dict(m.sidecar, schema="skysim.something/1")))
    with pytest.raises(ValueError, match="skysim.something/1' is neither"):
        diagnose(path)


def test_sky_field_through_the_entry_point_cross_validates_by_case():
    """Two suns, two folds: each sun is withheld in turn (the golden sky case gives its split
    explicitly); the base's d_max is the mean of the two fold fits, and its standard error
    that of two independent fits (each on one sun); a sky field needs its noise floor."""
    from test_sky_gap import FLOOR, make_cases

    from calibration.diagnosis.sky import dmax_se, fit_dmax
    from skysim.sky import RayleighSky
    c = make_cases(RayleighSky(dmax=0.7), np.random.default_rng(1))
    r = diagnose(c, ("d_max",), folds=2, noise_floor=FLOOR)
    assert r.data["withheld_cases"] == [0, 1] and r.verdict.effect == "none"
    assert r.data["split"]["folds"] == [[0], [1]]
    p = r.verdict.params["d_max"]
    # fold 0 withholds sun 0 and fits sun 1, and the other way round
    fits = [fit_dmax(c.subset([k]))["d_max"] for k in (1, 0)]
    ses = [dmax_se(c.subset([k]), d) for k, d in zip((1, 0), fits)]
    assert p["fold_values"] == pytest.approx(fits, rel=1e-12)
    assert p["value"] == pytest.approx(np.mean(fits), rel=1e-12)
    # the larger of the two-fit SE and the fold spread's (module doc of sky._fold_params)
    assert p["se"] == pytest.approx(max(np.sqrt(np.mean(np.square(ses)) / 2),
                                        np.std(fits, ddof=1) / np.sqrt(2)), rel=1e-12)
    with pytest.raises(ValueError, match="noise_floor"):
        diagnose(c, ("d_max",))


def test_adapters_and_effects_implement_the_protocol():
    from calibration.diagnosis.api import ADAPTERS
    from calibration.diagnosis.camera import CAMERA_EFFECTS
    from calibration.diagnosis.protocol import Effect, InstrumentAdapter
    from calibration.diagnosis.sky import SKY_EFFECTS
    from calibration.effects import EFFECT_NAMES, get_effect
    from calibration.photodiode_diagnosis.effects import (OPTIONAL_EFFECT_NAMES,
                                                          RING_EFFECT_NAMES, get_ring_effect)
    assert [a.name for a in ADAPTERS] == ["three_pair", "photodiodes", "sky", "camera"]
    assert all(isinstance(a, InstrumentAdapter) for a in ADAPTERS)
    ring = [get_ring_effect(n) for n in RING_EFFECT_NAMES + OPTIONAL_EFFECT_NAMES]
    for e in ([get_effect(n) for n in EFFECT_NAMES] + list(SKY_EFFECTS.values())
              + list(CAMERA_EFFECTS.values()) + ring):
        assert isinstance(e, Effect), e.name
        why = e.available()
        assert why is None or (isinstance(why, str) and why), e.name
    # a ring effect names, and gives a unit to, each parameter it adds
    for e in ring:
        assert e.k == len(e.parameter_names) == len(e.units), e.name
    # k counts the parameters added to the base: all of a three-pair effect's; a sky model
    # that trades d_max for tau adds none
    assert all(get_effect(n).k == len(get_effect(n).parameter_names) for n in EFFECT_NAMES)
    assert {n: e.k for n, e in SKY_EFFECTS.items()} == {"d_max": 0, "multiple_scattering": 0,
                                                        "ground_albedo": 1}


def test_pointing_calibration_reads_reports_of_either_schema(tmp_path, tilt_measurement):
    """The unit pointing held by ``--pointing-from`` is the same whether the calibration
    sessions' reports are the ring diagnosis's own dicts, the v2 dicts ``skysim diagnose``
    writes, their files or report objects; a three-pair table refuses it with the reason."""
    from calibration.diagnosis.rings import pointing_from_reports
    from calibration.photodiode_diagnosis import PointingCalibrationError, calibrated_pointing
    v1 = json.loads((GOLDEN / "legacy_rings_v1.json").read_text())
    want = calibrated_pointing([v1], n_units=8)
    report = DiagnosisReport.from_dict(v1)
    path = tmp_path / "diagnosis.json"
    path.write_text(json.dumps(report.to_dict()))
    for item in (v1, report, report.to_dict(), path, str(path)):
        np.testing.assert_array_equal(pointing_from_reports([item], n_units=8), want)
    with pytest.raises(PointingCalibrationError, match="applies to photodiode instruments"):
        diagnose(tilt_measurement["measurement"], ("tilt",), pointing_from=[path])
