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
