"""The confusable-candidates rule of the one verdict (:func:`calibration.diagnosis.core.decide`):
a candidate that the instrument's identifiability matrix shows can be mistaken for another is
named alone only when that other was tried and lost; otherwise the verdict is the group of the
two, with the reason saying which was not tried, not applicable or not beaten.

The rows are hand-made (the paired comparison :func:`core.judge` fills is given), so each
branch of the rule is reached on purpose; one test runs :func:`core.judge` on constructed
held-out residuals, where the paired statistics are computed.
"""

import dataclasses

import numpy as np
import pytest

from calibration.diagnosis import Candidate, Thresholds, ThresholdsError, core, decide
from calibration.photodiode_diagnosis.run import RING_THRESHOLDS

PAIR = {"aureole": ("stray_light",), "stray_light": ("aureole",)}
T = Thresholds(confusable=PAIR)
FLOOR, GAP0 = 1.0, 3.0          # a base gap three times the floor: not ``none``


def _row(effect, score, *, d=None, d_se=1.0, base_d=5.0, base_se=1.0, share=0.9,
         share_se=0.05, at_bound=(), **details):
    """A scored, available candidate: ``d`` its paired difference against the best
    (± ``d_se``), ``base_d`` the base model's mean square minus its own (± ``base_se``)."""
    return Candidate(effect, gap_after=1.1, shrink=0.5, score=score, converged=True,
                     paired_difference=d, paired_difference_se=None if d is None else d_se,
                     explained_share=share, explained_share_se=share_se,
                     at_bound=list(at_bound),
                     details={"base_difference": base_d, "base_difference_se": base_se,
                              **details})


def _best():
    return _row("aureole", -50.0, d=0.0, d_se=0.0)


def test_named_alone_when_the_confuser_was_tried_and_lost():
    """Stray light tried and beaten by 3 paired SE (> 2), or tried and no better than the base
    model (difference 1 +- 1, share 10 +- 10 %): the aureole is named alone."""
    beaten = _row("stray_light", -40.0, d=3.0, d_se=1.0)
    v = decide([_best(), beaten], GAP0, FLOOR, T)
    assert (v.effect, v.group, v.share) == ("aureole", [], 0.9)
    assert "identifiability" not in v.reason
    useless = _row("stray_light", -45.0, d=1.0, d_se=1.0, base_d=1.0, base_se=1.0,
                   share=0.1, share_se=0.1)
    assert decide([_best(), useless], GAP0, FLOOR, T).effect == "aureole"


def test_group_when_the_confuser_was_not_among_the_candidates():
    """Stray light withheld: the aureole, which beats everything tried, becomes the group of
    the two; the share is still the aureole's, the reason names the missing stray light."""
    other = _row("occlusion", -30.0, d=4.0, d_se=1.0)
    v = decide([_best(), other], GAP0, FLOOR, T)
    assert v.effect == "group"
    assert v.group == ["aureole", "stray_light"]
    assert (v.share, v.share_se) == (0.9, 0.05)
    assert "aureole can be mistaken for stray_light" in v.reason
    assert "not among the candidates" in v.reason
    assert "identifiability matrix" in v.reason
    # the order of the rows given does not matter
    assert decide([other, _best()], GAP0, FLOOR, T).group == ["aureole", "stray_light"]
    # a generator of rows is read once: the confuser test sees the same rows
    assert decide((c for c in [_best(), other]), GAP0, FLOOR, T).effect == "group"


def test_group_when_the_confuser_was_not_applicable():
    """Stray light tried but its fit failed (not applicable): it was not tried in effect, so
    the aureole is not named alone, and the reason carries the failure."""
    failed = Candidate.unavailable("stray_light",
                                   "not applicable: LinAlgError: SVD did not converge")
    v = decide([_best(), failed], GAP0, FLOOR, T)
    assert (v.effect, v.group) == ("group", ["aureole", "stray_light"])
    assert "not tried (not applicable: LinAlgError: SVD did not converge)" in v.reason
    # an unavailable row without the "not applicable" wording says so too
    missing = Candidate.unavailable("stray_light", "missing engine")
    v2 = decide([_best(), missing], GAP0, FLOOR, T)
    assert v2.group == ["aureole", "stray_light"]
    assert "not applicable: missing engine" in v2.reason


def test_confuser_at_a_bound_within_the_margin_is_not_beaten():
    """Stray light within 2 paired SE of the aureole (1.5 SE), better than the base, but at
    a bound of its range: the rule without a confusable table leaves it out of the group and
    names the aureole; with the table a bound is no proof that stray light is absent, so the
    verdict is the group and the reason names the bound."""
    bound = _row("stray_light", -45.0, d=1.5, d_se=1.0, at_bound=["stray_width_deg"])
    assert decide([_best(), bound], GAP0, FLOOR, Thresholds()).effect == "aureole"
    v = decide([_best(), bound], GAP0, FLOOR, T)
    assert (v.effect, v.group) == ("group", ["aureole", "stray_light"])
    assert "not beaten by more than 2 paired" in v.reason
    assert "fitted at a bound of its range: stray_width_deg" in v.reason


def test_confuser_tried_and_unbeaten_keeps_the_existing_group():
    """Stray light within 1.5 paired SE and better than the base: the group of the paired
    rule, as without the table (same group, same reason, the measurement that separates
    them where a candidate states it)."""
    close = _row("stray_light", -45.0, d=1.5, d_se=1.0,
                 separated_by="the sun-distance profile beyond 20 deg")
    with_table = decide([_best(), close], GAP0, FLOOR, T)
    without = decide([_best(), close], GAP0, FLOOR, Thresholds())
    assert with_table == without
    assert with_table.group == ["aureole", "stray_light"]
    assert "to separate them: stray_light: the sun-distance profile" in with_table.reason


def test_untried_confuser_of_a_group_member_joins_the_group():
    """Aureole withheld; occlusion best and stray light within 2 SE of it: the group of the
    paired rule is occlusion + stray light, and the aureole, which stray light can be
    mistaken for and which was not tried, joins it."""
    occ = _row("occlusion", -50.0, d=0.0, d_se=0.0)
    stray = _row("stray_light", -48.0, d=1.0, d_se=1.0)
    v = decide([occ, stray], GAP0, FLOOR, T)
    assert (v.effect, v.group) == ("group", ["occlusion", "stray_light", "aureole"])
    assert "stray_light can be mistaken for aureole, which was not tried" in v.reason
    assert decide([occ, stray], GAP0, FLOOR, Thresholds()).group == ["occlusion",
                                                                      "stray_light"]


def test_partly_explained_lists_the_untried_confuser():
    """An aureole removing 30 +- 5 % of the excess with stray light withheld: still
    ``partly_explained`` with the aureole's share, and the list says the share may be the
    stray light's."""
    part = _row("aureole", -50.0, d=0.0, d_se=0.0, share=0.3, share_se=0.05)
    v = decide([part], GAP0, FLOOR, T)
    assert (v.effect, v.share, v.share_se) == ("partly_explained", 0.3, 0.05)
    assert v.group == ["aureole", "stray_light"]
    assert "30 +- 5 %" in v.reason and "not among the candidates" in v.reason
    plain = decide([part], GAP0, FLOOR, Thresholds())
    assert (plain.effect, plain.group) == ("partly_explained", [])


def test_no_table_no_change():
    """Without a confusable table, or with one about other candidates, every branch gives
    the same decision as before: named, group, partly explained, unexplained, none."""
    cases = [
        [_best(), _row("stray_light", -40.0, d=3.0)],                     # named
        [_best()],                                                       # named, alone
        [_best(), _row("stray_light", -45.0, d=1.5)],                    # group
        [_row("aureole", -50.0, d=0.0, share=0.3)],                      # partly
        [_row("aureole", -5.0, d=0.0, base_d=0.5, share=0.1, share_se=0.1)],  # unexplained
        [_row("aureole", -50.0, d=0.0, at_bound=["g"])],                 # at a bound
    ]
    other = Thresholds(confusable={"fov": ("occlusion",)})
    expected = ["aureole", "aureole", "group", "partly_explained", "unexplained",
                "unexplained"]
    for rows, effect in zip(cases, expected):
        a = decide(rows, GAP0, FLOOR, Thresholds())
        assert a.effect == effect, a.reason
        assert decide(rows, GAP0, FLOOR, other) == a
        assert decide(rows, GAP0, FLOOR, Thresholds(confusable={})) == a
    # the gap within the floor is ``none`` whatever the table
    assert decide([_best()], 1.05, FLOOR, T).effect == "none"


def test_thresholds_confusable_is_frozen_and_checked():
    """Stored as sorted pairs (hashable, equal however given), carried by ``replace`` and
    ``for_blocks``, written to the report dict; bad tables get a one-line error naming the
    entry."""
    t = Thresholds(confusable={"stray_light": ["aureole"], "aureole": ("stray_light",)})
    assert t.confusable == (("aureole", ("stray_light",)), ("stray_light", ("aureole",)))
    assert t == T and hash(t) == hash(T)
    assert t.confusers("aureole") == ("stray_light",) and t.confusers("fov") == ()
    assert t.for_blocks(12).confusable == t.confusable
    assert dataclasses.replace(t, min_share=0.6).confusable == t.confusable
    assert t.to_dict()["confusable"] == {"aureole": ["stray_light"],
                                         "stray_light": ["aureole"]}
    assert Thresholds().to_dict()["confusable"] == {}
    with pytest.raises(ThresholdsError, match=r"confusable\['aureole'\]='stray_light'"):
        Thresholds(confusable={"aureole": "stray_light"})
    with pytest.raises(ThresholdsError, match="lists 'aureole'"):
        Thresholds(confusable={"aureole": ("aureole",)})
    with pytest.raises(ThresholdsError, match="confusable='aureole'"):
        Thresholds(confusable="aureole")
    with pytest.raises(ThresholdsError, match="key 3"):
        Thresholds(confusable={3: ("aureole",)})
    with pytest.raises(ThresholdsError, match="lists None"):
        Thresholds(confusable={"aureole": (None,)})


def test_ring_thresholds_pair_the_aureole_and_the_stray_light():
    """The ring's table is the pairs its identifiability matrix confused, both ways, and
    the side glare: the stray light, which it holds, is named alone only over it, and it
    only over what the stray light can be mistaken for."""
    assert RING_THRESHOLDS.confusers("aureole") == ("stray_light",)
    assert RING_THRESHOLDS.confusers("stray_light") == ("aureole", "side_glare")
    assert RING_THRESHOLDS.confusers("side_glare") == ("stray_light", "aureole")
    assert RING_THRESHOLDS.confusers("fov") == ("neutral_points",)
    assert RING_THRESHOLDS.confusers("neutral_points") == ("fov",)
    assert RING_THRESHOLDS.block_consistency == 0.75


def _held(rng, n_blocks=8, n=40):
    """Held-out residuals with a white noise floor of 1: the base model misses a systematic
    part of RMS 2; the aureole leaves 10 % of it, the stray light 70 %."""
    e = rng.standard_normal((n_blocks * n, 1))
    g = 2.0 * rng.standard_normal((n_blocks * n, 1))
    held = {"base": e + g, "aureole": e + 0.1 * g, "stray_light": e + 0.7 * g}
    return held, np.repeat(np.arange(n_blocks), n)


def _scored(name, held):
    return Candidate(name, k=2, gap_after=core.rms(held[name]), shrink=0.0,
                     score={"aureole": -100.0, "stray_light": -50.0}[name],
                     details={"blocks_improved": 1.0})


def test_judge_names_the_aureole_only_with_the_stray_light_tried():
    """Through :func:`core.judge` with the ring's thresholds on eight held-out blocks: the
    stray light leaves 1 + 0.49 * 4 = 2.96 of mean square against the aureole's 1.04, a
    paired difference of ~1.9 whose jackknife SE over 8 blocks of 40 readings is ~0.2 (the
    per-reading difference has variance ~13; on this draw 2.03 +- 0.16), so it is beaten
    by ~10 SE, where the margin is 2.43 (2 SE as Student's t with 7 degrees of freedom) and
    the test asks for 5: the aureole is named. With the stray light
    withheld, the same aureole is the group of the two and the side glare, which holds the
    stray light; its ``explained`` column still says
    that its own fit meets the rule."""
    held, block = _held(np.random.default_rng(5))
    t = RING_THRESHOLDS.for_blocks(8)
    rows, v = core.judge([_scored("aureole", held), _scored("stray_light", held)], held,
                         block, FLOOR, t)
    stray = next(c for c in rows if c.effect == "stray_light")
    assert stray.paired_difference > 5 * stray.paired_difference_se
    assert v.effect == "aureole", v.reason
    held_w = {k: held[k] for k in ("base", "aureole")}
    rows_w, w = core.judge([_scored("aureole", held_w)], held_w, block, FLOOR, t)
    # the stray light untried, and the side glare that holds it with it
    assert (w.effect, w.group) == ("group", ["aureole", "stray_light", "side_glare"])
    assert "not among the candidates" in w.reason
    assert w.share == pytest.approx(v.share)
    assert rows_w[0].explained
