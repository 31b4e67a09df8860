"""The method written once (:mod:`calibration.diagnosis.judge`): bookkeeping checked against
values worked out by hand (the ring's clock refinement: ``test_clock_refinement.py``)."""

import numpy as np
import pytest

from calibration.diagnosis import judge


def _toy_fold(train, held, skip):
    """Base residual 1 on every held-out row; ``a`` halves it; ``b`` fails in the first
    fold (and would fit in the second); ``c`` returns NaN on a usable reading; the last row
    is never usable."""
    usable = held != 5
    fits = {"base": judge.FoldFit(np.ones(held.size))}
    fits["a"] = judge.FoldFit(0.5 * np.ones(held.size), np.array([float(held[0])]))
    if "b" not in skip:
        fits["b"] = ("not applicable: LinAlgError: SVD did not converge" if 0 in held
                     else judge.FoldFit(np.zeros(held.size)))
    if "c" not in skip:
        fits["c"] = judge.FoldFit(np.where(held == held[0], np.nan, 0.0))
    return usable, fits


def test_cross_validate_collects_every_fold_and_sets_failures_aside():
    folds = np.array([0, 1, 0, 1, 0, 1])
    held = judge.cross_validate(folds, ["a", "b", "c"], (6,), _toy_fold)
    assert held.unavailable["b"].startswith("not applicable: LinAlgError")
    assert held.fits["b"] == []          # not fitted again once it failed
    # NaN at one usable reading of three in the first fold (rows 0, 2, 4)
    assert held.unavailable["c"] == ("not applicable: non-finite held-out residuals at 1 of "
                                     "3 readings")
    assert held.available(["a", "b", "c"]) == ["a"]
    np.testing.assert_array_equal(held.usable, [True] * 5 + [False])
    np.testing.assert_array_equal(held.held("a"), [0.5] * 5 + [np.nan])
    assert [r.tolist() for r in held.rows["a"]] == [[0, 2, 4], [1, 3, 5]]
    assert [float(f.params[0]) for f in held.fits["a"]] == [0.0, 1.0]
    row = judge.score(held, "a", 1, folds, floor=0.1, n_cal=3)
    # gaps 1 and 0.5: shrink 1/2; excess removed (1 - 0.25) / (1 - 0.01)
    assert row["gap_after"] == 0.5 and row["shrink"] == 0.5
    assert row["excess_removed"] == pytest.approx(0.75 / 0.99, rel=1e-12)
    assert row["blocks_improved"] == 1.0 and row["converged"]


def test_verdict_with_one_held_out_block_has_no_bootstrap_se():
    """One held-out block leaves no spread between blocks to resample: the gaps are
    reported, their standard errors are None (not an error)."""
    from calibration.diagnosis.core import Thresholds
    from calibration.diagnosis.report import Candidate
    rng = np.random.default_rng(0)
    base = rng.normal(0.0, 1.0, 400)
    held = {"base": base, "a": 0.1 * base}
    g0, ga = np.sqrt(np.mean(base ** 2)), 0.1 * np.sqrt(np.mean(base ** 2))
    rows = [Candidate("a", k=1, gap_after=ga, shrink=0.9, score=-1.0)]
    ranked, v = judge.verdict(rows, held, np.zeros(400, int), 0.05, Thresholds(),
                              np.random.default_rng(1))
    assert v.best_candidate == "a" and ranked[0].effect == "a"
    assert v.gap_before == pytest.approx(g0, rel=1e-12)
    assert v.gap_after == pytest.approx(ga, rel=1e-12)
    assert v.gap_before_se is None and v.gap_after_se is None and v.shrink_se is None
