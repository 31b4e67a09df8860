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
)

FOUND_MIN = 0.9
Z_RMS_RANGE = (0.7, 1.5)


def _goals(score: dict) -> list[str]:
    """The goals a matrix misses (empty when it meets them all)."""
    missed = []
    if not score["found_rate"] >= FOUND_MIN:
        missed.append(f"named or in group {score['found_rate']:.2f} "
                      f"({score['found_rate_by_effect']})")
    if score["clean_none_rate"] != 1.0:
        missed.append(f"clean none {score['clean_none_rate']:.2f}")
    if score["withheld_ok_rate"] != 1.0:
        missed.append(f"withheld never a single effect {score['withheld_ok_rate']:.2f}")
    missed += [f"z RMS {e} {r:.2f}" for e, r in score["z_rms"].items()
               if not Z_RMS_RANGE[0] <= r <= Z_RMS_RANGE[1]]
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
@pytest.mark.xfail(strict=True, reason=(
    "measured on seeds 11-13: named or in group 94 %, clean none 100 %; the strong "
    "extinction_ratio is not named (a common eps is d_max: the lowest eps lands on its "
    "bound); with clock_offset 600 s withheld, multiple_scattering is named once (tau 0.59); "
    "the multiple_scattering z-score RMS is 0.54 (its SE about twice its spread)"))
def test_three_pair_matrix_meets_the_goals():
    s = score_matrix(run_matrix(matrix_spec("three-pair")))
    assert _goals(s) == []


@pytest.mark.slow
@pytest.mark.matrix
def test_sky_field_matrix_meets_the_goals():
    """The verdict goals (the sky candidates report no standard errors, so no z-scores)."""
    pytest.importorskip("sasktran2", reason="sasktran2 (extra skysim[rt]) not installed")
    s = score_matrix(run_matrix(matrix_spec("sky")))
    assert _goals(s) == []


@pytest.mark.slow
@pytest.mark.matrix
@pytest.mark.xfail(strict=True, reason=(
    "measured on seeds 50-54: every verdict goal met (named 100 %, clean none 100 %, withheld "
    "never a single effect 100 %), but the overcast candidate's z-score RMS is 0.61 over 20 "
    "(cloud_tau 0.40-0.70, d_max 0.65): its standard errors are about 1.6 times the spread "
    "of its estimates"))
def test_camera_matrix_meets_the_goals():
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
    wide = ring_session("fov", {"alpha_deg": 20.0}, seed=3)
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
@pytest.mark.xfail(strict=True, reason=(
    "measured on seed 31, the default candidates, twelve one-turn sweeps over 12 min: the "
    "clock (900 s, -3300 s) and the gyro scale (1.02, 0.95) named, the strong occluded "
    "sector named, clean data none, no single effect named with the truth withheld; "
    "missed: the neutral-point sky partly_explained and the cone of view none (both "
    "strengths), the moderate occluded sector partly_explained, the occlusion's z RMS 0.13 "
    "(its SE several times its error); the aureole and stray light not re-run on this "
    "design"))
def test_ring_matrix_meets_the_goals():
    """The strong strengths over one seed (each ring diagnosis takes about 70 s of CPU)."""
    spec = matrix_spec("ring")
    spec = replace(spec, strengths={e: {"strong": v["strong"]}
                                    for e, v in spec.strengths.items()})
    s = score_matrix(run_matrix(spec))
    assert _goals(s) == []


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
