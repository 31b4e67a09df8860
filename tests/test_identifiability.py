"""Identifiability matrix of the gap diagnosis (calibration/diagnosis/identifiability.py).

Goals, per instrument, over every default candidate simulated at two strengths and over clean
data: each effect named or in the named group in >= 90 % of its cases; clean data ``none`` in
all; with the true effect withheld, never a single (wrong) effect; the RMS of the parameter
z-scores ``(fitted - true) / SE`` within 0.7-1.5 per candidate that reports standard errors
(an RMS of 1 is a calibrated SE; 0.7-1.5 is what 6-30 z-scores of a calibrated SE reach
with high probability: the RMS of n standard normals has a relative spread ~ 1/sqrt(2 n),
0.29 at n = 6, and the cases share one session geometry).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from calibration.diagnosis.identifiability import (
    IdentifiabilityInputError,
    matrix_markdown,
    matrix_spec,
    run_matrix,
    score_matrix,
    z_draws_markdown,
    z_draws_summary,
    z_rms_interval,
)
from calibration.photodiode_diagnosis.effects import RING_EFFECT_NAMES

FOUND_MIN = 0.9
Z_RMS_RANGE = (0.7, 1.5)


def _goals(score: dict, z: bool = True) -> list[str]:
    """The goals a matrix misses (empty when it meets them all); ``z=False`` leaves out the
    z-score RMS, for a matrix whose SEs are calibrated over noise draws of their own."""
    missed = []
    if not score["found_rate"] >= FOUND_MIN:
        missed.append(f"named or in group {score['found_rate']:.2f} "
                      f"({score['found_rate_by_effect']})")
    if score["clean_none_rate"] != 1.0:
        missed.append(f"clean none {score['clean_none_rate']:.2f}")
    if score["withheld_ok_rate"] != 1.0:
        missed.append(f"withheld never a single effect {score['withheld_ok_rate']:.2f}")
    missed += [f"z RMS {e} {r:.2f}" for e, r in score["z_rms"].items()
               if z and not Z_RMS_RANGE[0] <= r <= Z_RMS_RANGE[1]]
    return missed


def test_score_counts_groups_clean_and_withheld_verdicts():
    """The scoring on a hand-made table: a group holding the truth counts as found, a group
    without it does not; a withheld verdict naming an effect fails; z RMS per effect."""
    rows = pd.DataFrame([
        dict(truth="none", strength="-", seed=1, verdict="none", group=[], gap_ratio=1.0,
             found=True, withheld_verdict=None, withheld_group=[], withheld_ok=True, z={},
             seconds=1.0, withheld_seconds=0.0),
        dict(truth="tilt", strength="strong", seed=1, verdict="group", group=["tilt", "fov"],
             gap_ratio=5.0, found=True, withheld_verdict="fov", withheld_group=[],
             withheld_ok=False, z={"a": 1.0, "b": -3.0}, seconds=1.0, withheld_seconds=1.0),
        dict(truth="fov", strength="strong", seed=1, verdict="group", group=["tilt", "x"],
             gap_ratio=5.0, found=False, withheld_verdict="group", withheld_group=["tilt"],
             withheld_ok=True, z={}, seconds=1.0, withheld_seconds=1.0)])
    s = score_matrix(rows)
    assert s["found_rate"] == 0.5 and s["clean_none_rate"] == 1.0
    assert s["withheld_ok_rate"] == 0.5
    assert s["z_rms"] == {"tilt": pytest.approx(np.sqrt(5.0))}
    assert s["seconds"]["total"] == 5.0 and s["seconds"]["per_diagnosis"] == 1.0
    assert "| tilt | strong | 5 | group(tilt+fov) | 1/1 | fov |" in matrix_markdown(s, "x")


def test_unknown_instrument_and_empty_seeds_refused():
    with pytest.raises(IdentifiabilityInputError, match="'dome'"):
        matrix_spec("dome")
    with pytest.raises(IdentifiabilityInputError, match="seeds"):
        run_matrix(matrix_spec("three-pair"), seeds=())


def test_z_rms_interval_against_its_definition_and_a_calibrated_sample():
    """The RMS is that of every z-score pooled over draws of different lengths (by hand:
    sqrt((1 + 4 + 9 + 0) / 4)); on 400 draws of two independent standard normal z-scores
    (a calibrated SE) the RMS is within 4 of its sampling SDs of 1 (1/sqrt(2 * 800) = 0.025)
    and the bootstrap's 95 % interval holds it and spans about 2 x 1.96 of those SDs
    (0.08-0.12 wide)."""
    rms, (lo, hi) = z_rms_interval([[1.0, -2.0], [3.0], [0.0]])
    assert rms == pytest.approx(np.sqrt(14.0 / 4.0))
    assert lo <= rms <= hi
    z = np.random.default_rng(5).standard_normal((400, 2))
    rms, (lo, hi) = z_rms_interval(list(z), np.random.default_rng(1))
    assert abs(rms - 1.0) < 4 * 0.025, rms
    assert lo < rms < hi and 0.08 < hi - lo < 0.12, (lo, hi)
    with pytest.raises(IdentifiabilityInputError, match="empty"):
        z_rms_interval([])


def test_z_draws_summary_and_table_on_a_hand_made_table():
    """Counts, draws, data sets without a z-score and times from a hand-made table of two
    effects (one data set of the second with no z-score)."""
    rows = pd.DataFrame([
        dict(effect="tilt", seed=1, strength="strong", parameter="a", z=1.0, verdict="tilt",
             seconds=2.0),
        dict(effect="tilt", seed=1, strength="strong", parameter="b", z=-1.0,
             verdict="tilt", seconds=2.0),
        dict(effect="tilt", seed=2, strength="strong", parameter="a", z=2.0, verdict="tilt",
             seconds=4.0),
        dict(effect="fov", seed=1, strength="strong", parameter=None, z=np.nan,
             verdict="none", seconds=1.0)])
    s = z_draws_summary(rows)
    assert s["tilt"]["rms"] == pytest.approx(np.sqrt(2.0)) and s["tilt"]["draws"] == 2
    assert s["tilt"]["z_count"] == 3 and s["tilt"]["without_z"] == 0
    assert (s["tilt"]["seconds_min"], s["tilt"]["seconds_max"]) == (2.0, 4.0)
    assert s["fov"]["without_z"] == 1 and s["fov"]["draws"] == 0
    assert "| tilt | 2 | 3 | 1.41 |" in z_draws_markdown(s, "x")


def test_z_over_draws_on_the_three_pair_and_its_refusals(tmp_path):
    """The sun's motion on the three-pair (one seed, both strengths, the candidate alone):
    one z-score per strength, the verdict naming the effect; an effect the matrix does not
    simulate, no seeds, and a negative number of draws are refused naming the value."""
    from calibration.diagnosis.identifiability import write_matrix, z_over_draws
    spec = matrix_spec("three-pair")
    rows = z_over_draws(spec, "sun_motion", [11])
    assert len(rows) == 2 and set(rows.strength) == {"moderate", "strong"}
    assert rows.parameter.notna().all() and (rows.verdict == "sun_motion").all()
    assert np.all(np.abs(rows.z) < 3.0), rows.z.tolist()
    with pytest.raises(IdentifiabilityInputError, match="'dome_glare'"):
        z_over_draws(spec, "dome_glare", [1])
    with pytest.raises(IdentifiabilityInputError, match="seeds"):
        z_over_draws(spec, "sun_motion", [])
    with pytest.raises(IdentifiabilityInputError, match="-2"):
        write_matrix("three-pair", tmp_path, z_draws=-2)
    assert not any(tmp_path.iterdir())


def test_three_pair_geometric_effects_named_and_clean_is_none():
    """A cheap slice of the three-pair matrix (one seed, the effects that move the sun or
    the heading): each named or in the group, clean data none, withheld never a wrong single
    effect. Two z-scores per parameter cannot test an RMS; each must be within 3 (a
    calibrated SE exceeds it with probability 0.3 %)."""
    spec = matrix_spec("three-pair")
    spec = replace(spec, strengths={e: spec.strengths[e] for e in ("sun_motion", "tilt")})
    rows = run_matrix(spec, seeds=(11,))
    s = score_matrix(rows)
    assert [g for g in _goals(s) if not g.startswith("z RMS")] == []
    z = [v for d in rows.z for v in d.values()]
    assert len(z) == 6 and np.all(np.abs(z) < 3.0), z


@pytest.mark.slow
@pytest.mark.matrix
def test_three_pair_matrix_meets_the_goals():
    """Seeds 11-16, each case its own noise draw (measured: every goal met, z RMS
    0.76-1.24 per candidate; about 7 min on the loaded 2-core machine)."""
    s = score_matrix(run_matrix(matrix_spec("three-pair")))
    assert _goals(s) == []


@pytest.mark.slow
@pytest.mark.matrix
def test_sky_field_matrix_meets_the_goals():
    """The verdict goals and the z-score RMS of tau and the albedo (Gauss-Newton standard
    errors; seeds 21-28: 16 z-scores of the multiple-scattering tau, 32 of the ground
    albedo's tau and albedo). Measured: every goal met, z RMS 1.19 and 1.07; with the
    multiple-scattering sky withheld all 16 are ``unexplained``, the one whose calibration
    noise drew an albedo 3.1 SE from black (tau 0.1, seed 21) held 4.6 paired SE behind the
    black-ground sky it nests on the withheld sun; about 10 min on the loaded 2-core
    machine."""
    pytest.importorskip("sasktran2", reason="sasktran2 (extra skysim[rt]) not installed")
    s = score_matrix(run_matrix(matrix_spec("sky")))
    assert _goals(s) == []


@pytest.mark.slow
@pytest.mark.matrix
def test_camera_matrix_meets_the_goals():
    """Seeds 50-54, each case its own shot-noise draw (measured: every goal met, z RMS
    0.74-1.21 per candidate; about 7 min on the shared 2-core machine)."""
    s = score_matrix(run_matrix(matrix_spec("camera")))
    assert _goals(s) == []


def test_ring_session_generator_injects_what_it_is_told():
    """The ring generator's injections: a 900 s clock error leaves the readings exactly those
    of clean data (same noise draw) and moves every recorded time by 900 s; a gyro scale of 1.05 makes the recorded turn of a sweep 5 % longer; a cone of
    view of half-angle 20 deg changes the readings by about 2 % (the DoP of a Rayleigh sky
    averaged over +-20 deg: a few 1e-2), far above the 0.4 % noise."""
    from calibration.diagnosis.identifiability import ring_session
    clean = ring_session(seed=3)
    R0 = clean.table[clean.columns].to_numpy(float)
    late = ring_session("clock_offset", {"clock_offset_s": 900.0}, seed=3)
    np.testing.assert_array_equal(late.table[late.columns].to_numpy(float), R0)
    dt = (pd.to_datetime(clean.table.time) - pd.to_datetime(late.table.time)).dt.total_seconds()
    np.testing.assert_allclose(dt, 900.0, atol=1e-6)
    scaled = ring_session("yaw_scale", {"factor": 1.05}, seed=3)

    def turn(t):
        y = t.yaw_deg.to_numpy(float)[:60]
        return np.degrees(np.unwrap(np.radians(y)))[-1] - y[0]
    assert turn(scaled.table) == pytest.approx(1.05 * turn(clean.table), rel=1e-9)
    wide = ring_session("fov", {"hwhm_deg": 20.0}, seed=3)
    change = np.median(np.abs(wide.table[wide.columns].to_numpy(float) / R0 - 1.0))
    assert 0.005 < change < 0.05, change


GKANIAS = Path(__file__).resolve().parents[2] / "shared" / "reference" / "gkanias2023"


@pytest.mark.skipif(not GKANIAS.is_dir(), reason="needs ../shared/reference/gkanias2023")
def test_ring_session_design_is_a_real_sessions():
    """The simulated ring session spans what a real one does: as many sweeps as the longest
    reference sessions (11-12) and a first-to-last sample time within the reference
    sessions' range (``reference/gkanias2023/sessions.csv``, 11-13 min); one turn takes
    ``turn_s`` and samples are evenly spread over it. A turn longer than the sweep spacing
    is refused, naming the value."""
    from calibration.diagnosis.identifiability import RING_TURN_S, ring_session
    ref = pd.read_csv(GKANIAS / "sessions.csv")
    ref = ref[ref.category == "tod"]
    span_ref = (pd.to_datetime(ref.last_sample_utc)
                - pd.to_datetime(ref.first_sample_utc)).dt.total_seconds()
    s = ring_session(seed=3)
    t = pd.to_datetime(s.table.time)
    span = (t.iloc[-1] - t.iloc[0]).total_seconds()
    assert s.table.sweep.nunique() == ref.sweeps.max()
    assert span_ref.min() <= span <= span_ref.max(), (span, span_ref.min(), span_ref.max())
    first = t[s.table.sweep == 0]
    turn = (first.iloc[-1] - first.iloc[0]).total_seconds()
    assert turn == pytest.approx(RING_TURN_S * (len(first) - 1) / len(first), rel=1e-9)
    with pytest.raises(IdentifiabilityInputError, match="turn_s = 70.0"):
        ring_session(turn_s=70.0)


@pytest.mark.slow
@pytest.mark.matrix
def test_ring_matrix_meets_the_goals():
    """The strong strengths over one seed (each ring diagnosis takes about 70 s of CPU): every
    effect named or in the named group, clean data ``none``, no single effect named with the
    truth withheld. The z-score goal is not asked of one seed here: it gives one or two
    z-scores per parameter (and the 32 stray-light strengths of one fit err together), and a
    calibrated SE puts the RMS of one z-score outside 0.7-1.5 with probability 0.65, of two
    with 0.49; it is asked of twelve noise draws in
    :func:`test_ring_standard_errors_are_calibrated`."""
    spec = matrix_spec("ring")
    spec = replace(spec, strengths={e: {"strong": v["strong"]}
                                    for e, v in spec.strengths.items()})
    s = score_matrix(run_matrix(spec))
    assert _goals(s, z=False) == []


RING_Z_SEEDS = range(100, 112)
"""Noise draws of the ring's SE calibration (12: the RMS of a calibrated SE's z-scores over
12 independent draws has a relative spread of 1/sqrt(24) = 0.2 for one parameter and one
strength, less for more)."""


@pytest.mark.slow
@pytest.mark.matrix
@pytest.mark.parametrize("effect", RING_EFFECT_NAMES)
def test_ring_standard_errors_are_calibrated(effect):
    """Each ring candidate's reported SE (the fold mean's, :func:`.judge.fold_mean_se`) over
    the twelve noise draws ``RING_Z_SEEDS`` of the matrix's ring session at both strengths,
    each diagnosed with the candidate alone: the RMS of all its z-scores within 0.7-1.5 (the
    matrix's goal). The 95 % interval from a bootstrap over draws (a draw's z-scores are
    resampled together: its parameters, and for the stray light its two strengths, which add
    light to the same noisy readings, err together) is printed with it. Every data set must
    rank the candidate best and give it a z-score."""
    from calibration.diagnosis.identifiability import z_over_draws
    rows = z_over_draws(matrix_spec("ring"), effect, RING_Z_SEEDS)
    missing = rows[rows.parameter.isna()]
    assert missing.empty, missing[["seed", "strength", "verdict"]].to_dict("records")
    by_draw = [g.z.to_numpy(float) for _, g in rows.groupby("seed")]
    rms, (lo, hi) = z_rms_interval(by_draw, np.random.default_rng(0))
    print(f"{effect}: {len(rows)} z-scores over {len(by_draw)} draws, RMS {rms:.2f} "
          f"(95 % interval {lo:.2f}-{hi:.2f}); diagnoses {rows.seconds.min():.0f}-"
          f"{rows.seconds.max():.0f} s")
    assert Z_RMS_RANGE[0] <= rms <= Z_RMS_RANGE[1], (rms, lo, hi)


def test_ring_generator_skies_against_closed_forms():
    """The generator's occluded and aureole skies against their definitions on a Rayleigh
    sky: inside the sector (10 and 20 deg from its centre of a 90-deg sector, edges 2 deg) the
    DoP is (1 - k) times and the radiance (1 - k/2) times the clear sky's, outside unchanged;
    the aureole divides the DoP by 1 + A exp(-psi / psi_0) (psi the view's distance from
    the sun). Within 1e-5: the logistic edge leaves w = 1 - 4e-6 at 20 deg from the centre
    (the aureole is exact up to float rounding)."""
    from calibration.diagnosis.identifiability import _modified_sky
    from skysim.sky import RayleighSky
    base = RayleighSky(0.6)
    el, az = np.array([40.0, 40.0, 60.0]), np.array([100.0, 280.0, 130.0])
    sel, saz = np.full(3, 30.0), np.full(3, 200.0)
    I0, Q0, U0 = base._stokes(el, az, sel, saz)
    I, Q, U = _modified_sky(base, "occlusion", {"center_deg": 110.0, "width_deg": 90.0,
                                                "edge_deg": 2.0, "depolarization": 0.7}
                            )._stokes(el, az, sel, saz)
    inside = np.array([True, False, True])
    np.testing.assert_allclose(np.hypot(Q, U) / I, np.hypot(Q0, U0) / I0
                               * np.where(inside, 0.3, 1.0), rtol=1e-5)
    np.testing.assert_allclose(I, I0 * np.where(inside, 0.65, 1.0), rtol=1e-5)
    I, Q, U = _modified_sky(base, "aureole", {"amplitude": 2.0, "scale_deg": 15.0}
                            )._stokes(el, az, sel, saz)
    from skysim.geometry import direction_vector
    psi = np.degrees(np.arccos(np.sum(direction_vector(el, az) * direction_vector(sel, saz),
                                      axis=-1)))
    np.testing.assert_allclose(np.hypot(Q, U) / I, np.hypot(Q0, U0) / I0
                               / (1.0 + 2.0 * np.exp(-psi / 15.0)), rtol=1e-12)


def test_three_pair_multiple_scattering_standard_errors_are_calibrated():
    """The multiple-scattering candidate's reported SE (its fit on all data, Gauss-Newton
    covariance) over 24 noise draws per strength of the matrix's generator: z RMS within
    0.7-1.5 and its 95 % bootstrap interval inside 0.6-1.6. The matrix itself holds too few
    independent draws to say (its tau and albedo z-scores correlate at 0.99, so six seeds give
    six numbers per strength); a calibrated SE gives an RMS of 48 draws within 0.8-1.2 with
    probability ~0.98 (relative spread 1/sqrt(2 n) = 0.10), an SE twice the spread gives 0.5."""
    from calibration.diagnosis import diagnose
    spec = matrix_spec("three-pair")
    rows = []
    for strength, truth in spec.strengths["multiple_scattering"].items():
        for seed in range(100, 124):
            data = spec.simulate("multiple_scattering", truth, seed)
            c = diagnose(data, ("multiple_scattering",), seed=0).candidate(
                "multiple_scattering")
            assert c.details["params_from"].startswith("all data") and not c.at_bound
            rows.append([(c.params[n]["value"] - truth[n]) / c.params[n]["se"]
                         for n in ("tau", "albedo")])
    rms, (lo, hi) = z_rms_interval(rows, np.random.default_rng(0))
    assert Z_RMS_RANGE[0] <= rms <= Z_RMS_RANGE[1], (rms, lo, hi)
    assert 0.6 <= lo and hi <= 1.6, (rms, lo, hi)


def test_camera_overcast_standard_errors_are_calibrated():
    """The overcast candidate's reported SE (its fit on all usable super-pixels with d_max,
    sandwich covariance over super-pixels: the fit the report gives) over 16 shot-noise draws
    per strength of the matrix's camera frames (cloud_tau 0.5 and 2): z RMS of cloud_tau and
    d_max within 0.7-1.5, its 95 % bootstrap interval inside 0.6-1.6 (32 draws: relative
    spread of a calibrated RMS 0.125)."""
    from calibration.diagnosis import camera as C
    spec = matrix_spec("camera")
    rows = []
    for strength, truth in spec.strengths["overcast"].items():
        for seed in range(60, 76):
            frame = C._prepare(spec.simulate("overcast", truth, seed), None, 10.0, 20.0)
            assert C._known_dmax([frame]) is None          # d_max fitted with the cloud
            fit, _ = C._fit([(frame, frame.usable)], "overcast", None)
            P = C._parameters(fit, C.CAMERA_EFFECTS["overcast"], True)
            rows.append([(P[n]["value"] - truth[n]) / P[n]["se"]
                         for n in ("cloud_tau", "d_max")])
    rms, (lo, hi) = z_rms_interval(rows, np.random.default_rng(0))
    assert Z_RMS_RANGE[0] <= rms <= Z_RMS_RANGE[1], (rms, lo, hi)
    assert 0.6 <= lo and hi <= 1.6, (rms, lo, hi)


def test_ring_generator_side_glare():
    """The generator's side glare: as much light from either side is its stray light (the
    same readings, same noise draw); its sun's side (the cross product with the vertical)
    is the candidate's (explicit components) to 1e-12 on random views and suns; light from
    the left only never takes light away (beyond the rounding of counts, 1) and adds some
    (at least 2.5 % of the session's median reading somewhere: a strength of 0.2 within
    20 deg of the sun on the left adds up to 0.2 exp(-psi / 20) of it)."""
    from calibration.diagnosis.identifiability import _sun_side, ring_session
    from calibration.photodiode_diagnosis.effects import sun_side
    from sensor.compound_eye import SkySample
    from skysim.geometry import direction_vector
    kw = dict(n_sweeps=2, per_sweep=24)
    stray = ring_session("stray_light", {"S": 0.1, "scale_deg": 20.0}, seed=3, **kw)
    even = ring_session("side_glare", {"L": 0.1, "R": 0.1, "scale_deg": 20.0}, seed=3, **kw)
    np.testing.assert_array_equal(even.table[even.columns].to_numpy(float),
                                  stray.table[stray.columns].to_numpy(float))
    rng = np.random.default_rng(4)
    el, az = rng.uniform(5.0, 85.0, (50, 8)), rng.uniform(0.0, 360.0, (50, 8))
    sun = direction_vector(rng.uniform(-10.0, 80.0, 50), rng.uniform(0.0, 360.0, 50))
    views = direction_vector(el, az)
    cos_psi = np.clip(np.einsum("nuk,nk->nu", views, sun), -1.0, 1.0)
    obs = SkySample(np.ones_like(el), np.zeros_like(el), np.zeros_like(el),
                    np.zeros(el.shape + (3,)), el, az)
    np.testing.assert_allclose(_sun_side(views, cos_psi, sun), sun_side(obs, sun),
                               atol=1e-12)
    left = ring_session("side_glare", {"L": 0.2, "R": 0.0, "scale_deg": 20.0}, seed=3, **kw)
    added = (left.table[left.columns].to_numpy(float)
             - ring_session(seed=3, **kw).table[left.columns].to_numpy(float))
    assert np.all(added >= -1.0)          # no light taken away (rounding of counts: 1)
    median = float(np.median(left.table[left.columns].to_numpy(float)))
    assert np.max(added) > 0.025 * median, (np.max(added), median)


@pytest.mark.slow
def test_cli_writes_the_z_draws(tmp_path, capsys):
    """``skysim identifiability --instrument three-pair --quick --z-draws 1``: the quick
    matrix and each candidate alone on one noise draw; the CSV holds every candidate at the
    strong strength (the quick matrix's only one), the JSON its summary, the Markdown both
    tables, and the summary is printed."""
    import json

    from experiments.cli.main import main
    assert main(["identifiability", "--instrument", "three-pair", "--quick", "--z-draws", "1",
                 "--out", str(tmp_path)]) == 0
    spec = matrix_spec("three-pair")
    rows = pd.read_csv(tmp_path / "z_over_draws.csv")
    assert set(rows.effect) == set(spec.strengths)
    assert (rows.strength == "strong").all() and (rows.seed == 100).all()
    score = json.loads((tmp_path / "identifiability.json").read_text())["score"]
    assert set(score["z_over_draws"]) == set(spec.strengths)
    text = (tmp_path / "identifiability.md").read_text()
    assert "standard errors over noise draws" in text and "| effect | strength |" in text
    assert "z RMS" in capsys.readouterr().out
