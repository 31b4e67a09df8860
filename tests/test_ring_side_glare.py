"""The ring's side glare recovers its own effect on the identifiability matrix's simulated
ring (twelve one-turn sweeps, ``calibration.diagnosis.identifiability.ring_session``), is not
named on clean data, and with it withheld no single other effect is named."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.diagnosis.api import diagnose
from calibration.diagnosis.identifiability import ring_session

CONFUSERS = ("side_glare", "stray_light", "aureole")
"""The side glare and what it can stand in for (the ring's confusable candidates): named
alone only over these."""


@pytest.mark.slow
@pytest.mark.parametrize("L, R", [(0.15, 0.05), (0.3, 0.1)])
def test_side_glare_named_and_recovered(L, R):
    """Light three times as strong with the sun on each unit's left as on its right
    (strengths 0.15/0.05 and 0.3/0.1 of the session's median reading), falling off over
    20 deg: named, converged away from its bounds, and its 65 parameters recovered with
    z-scores of RMS within 0.6-1.6 (measured 1.05 and 1.07 on seed 31; with 65 z-scores
    the RMS of calibrated ones lies within 1 +- 0.18 at 2 SD, widened for the correlation of
    one fit's strengths) and the fall-off within 3 SE (20.27 +- 0.22, 20.08 +- 0.11)."""
    truth = {"L": L, "R": R, "scale_deg": 20.0}
    rep = diagnose(ring_session("side_glare", truth, 31), CONFUSERS, seed=0)
    v = rep.verdict
    assert v.effect == "side_glare", v.reason
    c = rep.candidate("side_glare")
    assert c.converged and not c.at_bound
    z = np.array([(p["value"] - truth[k.split("_")[0] if k[:2] in ("L_", "R_") else k])
                  / p["uncertainty"] for k, p in c.params.items()])
    assert z.size == 65
    assert 0.6 <= np.sqrt(np.mean(z ** 2)) <= 1.6, z
    scale = c.params["scale_deg"]
    assert abs(scale["value"] - 20.0) <= 3.0 * scale["uncertainty"], scale


@pytest.mark.slow
def test_side_glare_not_named_on_clean_data_nor_stood_in_for():
    """Clean data: `none`. The side glare withheld (0.3/0.1): the stray light, which it
    nests, comes close (94 % of the excess on seed 31) but is not named alone: the verdict
    is their group."""
    clean = diagnose(ring_session(None, None, 31), CONFUSERS, seed=0)
    assert clean.verdict.effect == "none", clean.verdict.reason
    truth = {"L": 0.3, "R": 0.1, "scale_deg": 20.0}
    held = diagnose(ring_session("side_glare", truth, 31), CONFUSERS[1:], seed=0)
    assert held.verdict.effect in ("group", "partly_explained", "unexplained"), \
        held.verdict.reason
    assert held.verdict.effect != "group" or "side_glare" in held.verdict.group


def _views():
    from types import SimpleNamespace
    rng = np.random.default_rng(5)
    n, U = 40, 4
    obs = SimpleNamespace(view_elevation_deg=np.full((n, U), 45.0),
                          view_azimuth_deg=rng.uniform(0.0, 360.0, (n, U)))
    el, az = np.radians(rng.uniform(5.0, 70.0, n)), np.radians(rng.uniform(0.0, 360.0, n))
    sun = np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], axis=1)
    inst = SimpleNamespace(columns=[f"u{u}_p{a:03d}" for u in range(U) for a in (0, 90)])
    return obs, sun, inst, np.repeat(np.arange(U), 2)


@pytest.mark.parametrize("name", ["side_glare", "stray_light"])
def test_fall_off_held_at_a_day_value(name):
    """``name(scale_deg=94)`` fits the strengths only: its parameters are the free one's
    without the fall-off, its start has no fall-off, its reading term equals the free
    one's at a fall-off of 94 deg (the same formula, to float rounding)."""
    from calibration.photodiode_diagnosis.effects import get_ring_effect
    obs, sun, inst, pd_unit = _views()
    free, held = get_ring_effect(name), get_ring_effect(f"{name}(scale_deg=94)")
    free.bind(inst)
    held.bind(inst)
    assert held.name == free.name and held.held_values == {"scale_deg": 94.0}
    assert free.held_values == {}
    assert held.parameter_names == free.parameter_names[:-1]
    assert free.parameter_names[-1] == "scale_deg"
    for f in ("units", "null", "lower", "upper", "prior_sd", "fd_step"):
        assert len(getattr(held, f)) == held.k, f
    assert all(len(s) == held.k for s in held.starts(None))
    p = np.random.default_rng(1).uniform(0.0, 0.3, held.k)
    np.testing.assert_allclose(held.additive(p, obs, sun, pd_unit),
                               free.additive(np.r_[p, 94.0], obs, sun, pd_unit), rtol=1e-15)


@pytest.mark.parametrize("name, match", [
    ("side_glare(width_deg=3)", "cannot hold width_deg; it can hold: scale_deg"),
    ("side_glare(scale_deg=wide)", "'scale_deg=wide' is not parameter=value"),
    ("side_glare(scale_deg=1)", "scale_deg = 1.0 is outside its range"),
    ("fov(hwhm_deg=20)", "fov cannot hold hwhm_deg; it can hold: nothing"),
    ("glare(scale_deg=94)", "unknown effect 'glare"),
    ("side_glare()", "'' is not parameter=value"),
    ("stray_light( )", "'' is not parameter=value"),
    ("side_glare(scale_deg=94, scale_deg=20)", "scale_deg is given twice"),
])
def test_held_value_errors_name_it(name, match):
    """A held candidate that cannot be read or held is refused, naming what is wrong."""
    from calibration.effects import UnknownEffectError
    from calibration.photodiode_diagnosis.effects import get_ring_effect
    with pytest.raises(UnknownEffectError, match=match.replace("(", r"\(")):
        get_ring_effect(name)


def test_a_candidate_asked_for_twice_is_refused():
    """The free and the held side glare are one candidate, named once in a report: asking
    for both is refused, naming both."""
    from calibration.diagnosis.rings import ring_candidates
    from calibration.effects import UnknownEffectError
    assert ring_candidates(["side_glare(scale_deg=94)", "fov"]) == (
        "side_glare(scale_deg=94)", "fov")
    with pytest.raises(UnknownEffectError,
                       match=r"'side_glare' and 'side_glare\(scale_deg=94\)' are the same"):
        ring_candidates(["side_glare", "side_glare(scale_deg=94)"])


def test_report_says_what_was_held():
    """A candidate row carrying ``held`` (as the ring diagnosis writes it) survives the
    report's JSON round trip and is shown in its markdown beside the candidate's name."""
    from calibration.diagnosis.report import Candidate, DiagnosisReport, Verdict
    c = Candidate.from_dict({"effect": "side_glare", "k": 64, "gap_after": 0.004, "shrink": 0.4,
                             "score": -10.0, "explained": True, "held": {"scale_deg": 94.0}})
    rep = DiagnosisReport(instrument="photodiodes", metric="relative reading", unit="1",
                          verdict=Verdict(effect="side_glare", reason="test"), candidates=[c])
    back = DiagnosisReport.from_dict(rep.to_dict())
    assert back.candidate("side_glare").details["held"] == {"scale_deg": 94.0}
    assert "| side_glare (scale_deg held at 94) | 64 |" in back.to_markdown()
