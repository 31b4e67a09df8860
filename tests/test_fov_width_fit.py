"""The acceptance's width (the ring's ``fov`` candidate) read at the minimum of its profile
cost, the units' pointing read from the angle of polarization under each width
(calibration/photodiode_diagnosis/run.py ``_pointing_under_effect``), and its SE along that
path (``_two_step_sd``, ``_two_step_variance``).

References: a linear two-step model whose estimator is closed-form, against the spread of
its estimates over noise draws; and the generator's truth on simulated rings
(:func:`calibration.diagnosis.identifiability.ring_session`, the sensor simulator weighing
the sky by the acceptance with its own quadrature), which the fit never sees.
"""

from __future__ import annotations

import numpy as np
import pytest

from ring_sessions import fitted_on_whole_session

from calibration.photodiode_diagnosis.run import _two_step_variance

LINEAR_DRAWS = 4000
"""Noise draws of the linear model (the Monte-Carlo SD's relative error: 1.1 %)."""
SANDWICH_DRAWS = 20
"""Draws whose sandwich variances are averaged (each one's relative error about 1/sqrt(2 n)
= 3.5 % in SD with n = 400 samples; averaged over 20, under 1 %)."""


def _linear_model(rng, n=400):
    """Jacobians of a linear two-step model: parameters (p0, p1, e, r0, r1), the pointing
    p, the effect e, the rest r. The first stage (the angle of polarization) sees p and e
    only, e trading with p0 (``dp/de = -2``, as a width trades with the elevations); the
    second (the full model) sees all. Two readings of each of ``n`` samples in the first
    stage, three in the second, each sample's noise SD drawn in [0.5, 2] (the fit weighs
    them alike: the sandwich's case)."""
    J1 = np.zeros((2 * n, 5))
    J1[:, :2] = rng.normal(size=(2 * n, 2))
    J1[:, 2] = 2.0 * J1[:, 0] + 0.3 * rng.normal(size=2 * n)
    J2 = rng.normal(size=(3 * n, 5))
    return J1, J2, np.repeat(rng.uniform(0.5, 2.0, n), 2), np.repeat(rng.uniform(0.5, 2.0, n), 3)


def _profile_estimates(J1, J2, y1, y2):
    """The profile estimator in closed form, every draw (columns of ``y1``, ``y2``) at once:
    ``p(e)`` the least-squares pointing of the first stage at ``e``, then ``(e, r)`` the
    least squares of the second with the pointing ``p(e)``. Returns ``(theta (5, draws))``."""
    J1p, J1e = J1[:, :2], J1[:, 2:3]
    P1 = np.linalg.solve(J1p.T @ J1p, J1p.T)
    X = np.hstack([J2[:, 2:3] - J2[:, :2] @ P1 @ J1e, J2[:, 3:]])
    er = np.linalg.lstsq(X, y2 - J2[:, :2] @ (P1 @ y1), rcond=None)[0]
    return np.vstack([P1 @ (y1 - J1e @ er[:1]), er])


def _scores(J, r, per_sample):
    """Per-sample scores (samples, parameters): each sample's residuals times its rows."""
    n = J.shape[0] // per_sample
    return (r[:, None] * J).reshape(n, per_sample, -1).sum(axis=1)


def test_the_sandwich_along_the_pointing_matches_the_spread_of_a_linear_profile_estimator():
    """The effect's SD from :func:`_two_step_variance` with the pointing following the
    effect is the spread of the closed-form profile estimator over 4000 noise draws within
    5 % (three times the combined relative error of the Monte-Carlo SD, 1.1 %, and the
    averaged sandwich, under 1 %; measured 0.8 %). The sandwich with the pointing's
    influence taken at a held effect, the SE before, is 51 % high on the same model:
    it misses that the pointing moves with the effect."""
    rng = np.random.default_rng(7)
    J1, J2, s1, s2 = _linear_model(rng)
    y1 = s1[:, None] * rng.normal(size=(J1.shape[0], LINEAR_DRAWS))
    y2 = s2[:, None] * rng.normal(size=(J2.shape[0], LINEAR_DRAWS))
    theta = _profile_estimates(J1, J2, y1, y2)
    spread = theta[2].std(ddof=1)
    along, held = [], []
    idx1, idx2, ptg = np.arange(3), np.arange(5), np.arange(2)
    for d in range(SANDWICH_DRAWS):
        G1 = _scores(J1[:, idx1], J1 @ theta[:, d] - y1[:, d], 2)
        G2 = _scores(J2, J2 @ theta[:, d] - y2[:, d], 3)
        A1, A2 = J1[:, idx1].T @ J1[:, idx1], J2.T @ J2
        v, own = _two_step_variance(A1, G1, idx1, A2, G2, idx2, ptg, slice(2, 3))
        along.append(v[own == 2][0])
        v, own = _two_step_variance(A1[:2, :2], G1[:, :2], idx1[:2], A2, G2, idx2, ptg)
        held.append(v[own == 2][0])
    assert np.sqrt(np.mean(along)) == pytest.approx(spread, rel=0.05)
    assert np.sqrt(np.mean(held)) > 1.3 * spread


def _fitted(hwhm: float, seed: int):
    """``(value, SE, mean elevation offset of the units)`` on a whole simulated ring."""
    return fitted_on_whole_session("fov", {"hwhm_deg": hwhm}, seed)


@pytest.mark.slow
@pytest.mark.parametrize("hwhm", [40.0, 45.0])
def test_a_wide_acceptance_the_horizon_cuts_is_read_within_its_se(hwhm):
    """HWHM 40 and 45 deg, where the horizon cuts the acceptance and the base model reads
    every elevation 0.59 and 1.52 deg high: the width within 3 SE of the truth on seed 37,
    outside the seeds the SE was calibrated on (31-36: z RMS 0.84 at 40 deg and 1.45 at 45,
    1.13 at 30; a calibrated SE leaves a Gaussian error outside 3 SE in 0.3 % of draws).
    Measured: 39.953 +- 0.055 (z -0.86) and 44.991 +- 0.042 (z -0.21); the fit by turns
    read 36.8 and 40.1 deg on seed 31 (z -321 and -398). The SE under 1 % of the width
    (0.04-0.08 deg measured). The units' common elevation within 0.05 deg of the truth (0;
    measured 0.012 and 0.010 deg, and within 0.02 deg on seeds 31-36): the AoP's reading
    under the width, where the base's was off by 0.6-1.5 deg."""
    width, se, el = _fitted(hwhm, 37)
    assert abs(width - hwhm) <= 3.0 * se, (width, se)
    assert se < 0.01 * hwhm, se
    assert abs(el) < 0.05, el
