"""The SE of a parameter's mean over cross-validation folds (`judge.fold_mean_se`) against the
closed form of a linear-Gaussian estimator.

Three blocks, each estimating mu with Gaussian error of variance s^2 + t^2 (s^2 the variance
the fit's model knows of, t^2 a spread between blocks it does not: a form wrong for the
data); fold f fits the other two (their mean, posterior SD s / sqrt 2). The fold mean is the
mean of the three blocks, error variance V = (s^2 + t^2) / 3. The model's SE is s / sqrt 3;
the jackknife's variance is V X with X ~ Exp(1), independent of the mean. With
r = s^2 / (s^2 + t^2):

    E[z^2] = E[1 / max(r, X)] = (1 - exp(-r)) / r + E1(r)

(E1 the exponential integral), 0.851 with no spread between blocks (r = 1) and 2.13 with
t = 2 s (r = 0.2), where the model's SE alone gives 1 / r = 5. Tolerance: four Monte-Carlo SEs
of the mean of z^2 over the trials.
"""

import numpy as np
import pytest
from scipy.special import exp1

from calibration.diagnosis.judge import fold_mean_se

TRIALS = 20000


def _z_squared(s: float, t: float, rng) -> tuple[np.ndarray, np.ndarray]:
    blocks = rng.normal(0.0, np.hypot(s, t), size=(TRIALS, 3))
    folds = (blocks.sum(axis=1, keepdims=True) - blocks) / 2.0     # each omits one block
    sd = [s / np.sqrt(2.0)] * 3
    out = np.array([fold_mean_se(f, sd)[:2] for f in folds])
    err = folds.mean(axis=1)
    return (err / out[:, 0]) ** 2, (err / out[:, 1]) ** 2


@pytest.mark.parametrize("t", [0.0, 2.0])
def test_fold_mean_se_matches_the_closed_form(t):
    z2, z2_model = _z_squared(1.0, t, np.random.default_rng(5))
    r = 1.0 / (1.0 + t ** 2)
    expected = (1.0 - np.exp(-r)) / r + exp1(r)
    mc_se = z2.std() / np.sqrt(TRIALS)
    assert abs(z2.mean() - expected) < 4 * mc_se, (z2.mean(), expected, mc_se)
    # the model's SE alone: calibrated without a spread between blocks, 1/r too small a
    # variance with one (the mean of z^2 is 1/r; chi-square(1) spread, SE sqrt(2/n)/r)
    assert abs(z2_model.mean() - 1.0 / r) < 4 * np.sqrt(2.0 / TRIALS) / r


def test_fold_mean_se_parts():
    # two folds fitted on disjoint halves: the jackknife is the SE of the mean of two
    # independent fits, std (ddof 1) / sqrt 2
    se, model, jack = fold_mean_se([1.0, 3.0], [0.5, 0.5])
    assert jack == pytest.approx(np.std([1.0, 3.0], ddof=1) / np.sqrt(2.0), rel=1e-12)
    assert model == pytest.approx(0.5 / np.sqrt(2.0), rel=1e-12)
    assert se == jack
    # one fold: its own SD, no jackknife; no SD anywhere: the jackknife alone
    assert fold_mean_se([2.0], [0.3]) == (pytest.approx(0.3), pytest.approx(0.3), None)
    se, model, jack = fold_mean_se([1.0, 2.0, 4.0], [None, None, None])
    assert model is None and se == jack == pytest.approx(np.sqrt(2 / 3 * 4.6666666666666), rel=1e-9)
    assert fold_mean_se([1.0], [None]) == (None, None, None)
