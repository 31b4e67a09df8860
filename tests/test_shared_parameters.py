"""Combining a parameter over sessions: closed forms of the weighted mean, Cochran's Q and
the DerSimonian-Laird between-session SD, their calibration by simulation, and the table
built from diagnosis reports."""

import numpy as np
import pytest
from scipy import stats

from calibration.diagnosis.errors import InsufficientDataError
from calibration.diagnosis.report import Candidate, DiagnosisReport, Verdict
from calibration.diagnosis.shared_parameters import combine_sessions, shared_parameters
from skysim import SkysimError


def test_closed_form_two_sessions():
    # x = (1, 3), se = (1, 1): mean 2, se 1/sqrt(2), Q = 2, p = chi2.sf(2, 1);
    # tau^2 = (Q - 1) / (S1 - S2 / S1) = 1 / (2 - 1) = 1
    e = combine_sessions([1.0, 3.0], [1.0, 1.0])
    assert e.mean == pytest.approx(2.0, abs=1e-15)
    assert e.se == pytest.approx(np.sqrt(0.5), rel=1e-15)
    assert e.q == pytest.approx(2.0, rel=1e-15)
    assert e.p == pytest.approx(stats.chi2.sf(2.0, 1), rel=1e-12)
    assert e.between_sd == pytest.approx(1.0, rel=1e-12)
    assert e.spread == pytest.approx(np.sqrt(2.0), rel=1e-15)
    # agreeing sessions: no between-session SD
    assert combine_sessions([1.0, 1.5], [1.0, 1.0]).between_sd == 0.0


def test_calibrated_by_simulation():
    """Sessions that share one value: p uniform (5 % below 0.05 within 1.5 %); sessions
    whose values spread by a known SD: the moment estimate of that SD is unbiased in tau^2
    (DerSimonian & Laird 1986) to within 5 % over 4,000 days of 12 sessions."""
    rng = np.random.default_rng(0)
    se = rng.uniform(0.5, 2.0, (4000, 12))
    same = rng.normal(3.0, se)
    p = np.array([combine_sessions(x, s).p for x, s in zip(same, se)])
    assert abs(np.mean(p < 0.05) - 0.05) < 0.015
    spread = rng.normal(3.0, np.sqrt(se ** 2 + 1.5 ** 2))
    q = np.array([combine_sessions(x, s).q for x, s in zip(spread, se)])
    w = 1 / se ** 2
    c = w.sum(1) - (w ** 2).sum(1) / w.sum(1)
    tau2_raw = (q - 11) / c          # unbiased before truncation at 0
    assert np.mean(tau2_raw) == pytest.approx(1.5 ** 2, rel=0.05)


@pytest.mark.parametrize("values, se", [([1.0], [1.0]), ([1.0, np.nan], [1.0, 1.0]),
                                        ([1.0, 2.0], [1.0, 0.0]), ([1.0, 2.0], [1.0])])
def test_bad_input_named(values, se):
    with pytest.raises(InsufficientDataError) as err:
        combine_sessions(values, se)
    assert isinstance(err.value, SkysimError)


def _report(params):
    cands = [Candidate(effect=e, params={k: dict(v, unit="1") for k, v in p.items()})
             for e, p in params.items()]
    return DiagnosisReport(instrument="photodiodes", metric="relative reading", unit="1",
                           verdict=Verdict(effect="none", reason="test"), candidates=cands)


def test_table_from_reports_keeps_what_sessions_share():
    reports = {
        "a": _report({"fov": {"alpha_deg": {"value": 4.0, "uncertainty": 0.5}},
                      "clock_offset": {"clock_offset_s": {"value": 30.0, "uncertainty": 5.0}},
                      "stray_light": {"S_u0_p000": {"value": 0.1, "uncertainty": 0.01},
                                      "scale_deg": {"value": 10.0, "uncertainty": 1.0}}}),
        "b": _report({"fov": {"alpha_deg": {"value": 9.0, "uncertainty": 0.5}},
                      "clock_offset": {"clock_offset_s": {"value": -30.0, "uncertainty": 5.0}},
                      "stray_light": {"scale_deg": {"value": 11.0, "uncertainty": 1.0}}}),
        "c": _report({"fov": {"alpha_deg": {"value": 5.0, "uncertainty": None}}}),
    }
    t = shared_parameters(reports)
    assert list(t["candidate"]) == ["fov", "stray_light"]     # no clock, no per-photodiode
    fov = t.iloc[0]
    assert fov["sessions"] == 2 and not fov["agree"]          # 4 +- 0.5 against 9 +- 0.5
    assert fov["mean"] == pytest.approx(6.5) and fov["scope"] == "instrument"
    assert bool(t.iloc[1]["agree"])


def test_sun_trend_is_spearmans_rank_correlation():
    """Against the closed form for untied ranks, rho = 1 - 6 sum d^2 / (n (n^2 - 1))
    (Spearman 1904), to float rounding; the p-value exact: a perfect ordering of n sessions
    has two-sided p = 2 / n! (6: 2/720); nine sessions against the t approximation's
    p, which is close there (within a factor 3: exact 1.3e-3). Fewer than six sessions with
    a known elevation, or constant values, give no trend (NaN)."""
    from math import factorial

    from calibration.diagnosis.shared_parameters import TREND_MIN_SESSIONS, sun_trend
    x = np.array([187.0, 114.0, 51.0, 53.0, 62.0, 94.0, 155.0, 356.0, 60.0])
    h = np.array([33.2, 43.3, 63.9, 68.7, 65.7, 48.4, 36.8, 25.5, 54.2])
    d = stats.rankdata(x) - stats.rankdata(h)
    n = x.size
    rho, p = sun_trend(x, h)
    assert rho == pytest.approx(1 - 6 * np.sum(d ** 2) / (n * (n ** 2 - 1)), rel=1e-12)
    assert p == pytest.approx(stats.spearmanr(x, h).pvalue, rel=3.0) and 1e-3 < p < 2e-3
    assert TREND_MIN_SESSIONS == 6
    r6, p6 = sun_trend([6.0, 5.0, 4.0, 3.0, 2.0, 1.0], [10.0, 20.0, 30.0, 40.0, 50.0, 60.0])
    assert r6 == pytest.approx(-1.0) and p6 == pytest.approx(2 / factorial(6), rel=1e-9)
    assert np.isnan(sun_trend([5.0, 4.0, 3.0, 2.0, 1.0], [10.0, 20.0, 30.0, 40.0, 50.0])[1])
    assert np.isnan(sun_trend([1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
                              [10.0, np.nan, 30.0, 40.0, 50.0, 60.0])[0])
    assert np.isnan(sun_trend([2.0] * 6, [10.0, 20.0, 30.0, 40.0, 50.0, 60.0])[1])


def test_table_keeps_the_sessions_a_candidate_explains_and_flags_a_drift():
    """Six sessions whose glare fall-off shrinks as the sun rises, each with its SE: they
    disagree (Cochran's Q) and the disagreement follows the sun (rho = -1, p = 2/6!,
    flagged). With ``min_share=0.5`` the session where the candidate takes 20 % of the
    excess is left out of the combination, and five sessions are too few to test a trend;
    a share outside 0-1 is refused, naming it."""
    elevations = [20.0, 30.0, 40.0, 50.0, 60.0, 70.0]
    falloff = [300.0, 180.0, 120.0, 80.0, 50.0, 40.0]
    shares = [0.9, 0.8, 0.2, 0.7, 0.95, 0.1]
    reports = {}
    for i, (h, v, sh) in enumerate(zip(elevations, falloff, shares)):
        c = Candidate(effect="side_glare", explained_share=sh,
                      params={"scale_deg": {"value": v, "uncertainty": 5.0, "unit": "deg"},
                              "L_u0_p000": {"value": 0.1, "uncertainty": 0.01, "unit": "1"}})
        reports[f"s{i}"] = DiagnosisReport(
            instrument="photodiodes", metric="relative reading", unit="1",
            verdict=Verdict(effect="side_glare", reason="test"), candidates=[c],
            data={"sun_elevation_deg": [h - 1.0, h + 1.0]})
    every = shared_parameters(reports).set_index("parameter").loc["scale_deg"]
    assert every["sessions"] == 6 and not every["agree"]
    assert every["sun_trend_rho"] == pytest.approx(-1.0) and every["drifts_with_sun"]
    assert every["sun_trend_p"] == pytest.approx(2 / 720, rel=1e-9)
    kept = shared_parameters(reports, min_share=0.5).set_index("parameter").loc["scale_deg"]
    assert kept["sessions"] == 4 and kept["drifts_with_sun"] is None
    with pytest.raises(InsufficientDataError, match="min_share = 50"):
        shared_parameters(reports, min_share=50)
    w = 1 / 5.0 ** 2
    assert kept["mean"] == pytest.approx(np.mean([300.0, 180.0, 80.0, 50.0]), rel=1e-12)
    assert kept["q"] == pytest.approx(w * np.sum((np.array([300.0, 180.0, 80.0, 50.0])
                                                  - 152.5) ** 2), rel=1e-12)
