"""The SE of the ring's ``aureole`` and ``stray_light`` parameters (the two-step sandwich over
samples, calibration/photodiode_diagnosis/run.py ``_two_step_sd``) against the spread of the
fitted parameters over independent noise draws.

The reference is the empirical SD of each parameter over ``N_DRAWS`` simulated sessions that
differ only in their noise: the identifiability matrix's ring generator
(:func:`calibration.diagnosis.identifiability.ring_session`, the sensor simulator with its
read and shot noise, an aureole made in the sky or stray light added to the counts), which
shares only the physics library with the candidate. Each draw is fitted as a cross-validation
fold is (the base fit reads the units' pointing from the angle of polarization, the candidate
is fitted with it held), on a short ring of 4 sweeps of 36 samples so that the draws are
cheap.

Tolerance: the empirical SD of ``N`` Gaussian draws has a relative sampling SD of
``1 / sqrt(2 (N - 1))`` (0.113 for N = 40), while the reported SE changes little from one draw
to the next (by 5 % for the aureole's amplitude), so the ratio of the empirical SD to the
RMS of the reported SE must lie within ``z_k`` of those sampling SDs of 1, ``z_k`` the
normal quantile that a correct SE passes with probability 99.73 % for all ``k`` parameters
of a candidate at once (Bonferroni: a two-sided tail of 0.27 % / k each; ``k = 2``: 3.2,
[0.64, 1.36]; the stray light's ``k = 33``: 3.9, [0.55, 1.45]). A parameter outside it in
this fixed set of draws has an SE off by more than the draws can tell.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from calibration.diagnosis.identifiability import ring_session
from calibration.photodiode_diagnosis import run
from calibration.photodiode_diagnosis.effects import Aureole, StrayLight
from calibration.photodiode_diagnosis.fit import thin
from calibration.photodiode_diagnosis.forward import Forward
from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes

N_DRAWS = 40
"""Noise draws (seeds 100 to 139)."""


def _band(k: int) -> float:
    """Accepted relative difference of the empirical SD from the RMS reported SE for ``k``
    parameters tested together (module docstring)."""
    return norm.isf(0.0027 / (2 * k)) / np.sqrt(2.0 * (N_DRAWS - 1))


SHORT_RING = {"n_sweeps": 4, "per_sweep": 36}


def _draws(name, effect, truth):
    """Fitted effect parameters (draws, k) and their two-step SE."""
    values, se = [], []
    for seed in range(100, 100 + N_DRAWS):
        inst = instrument_from_photodiodes(ring_session(name, truth, seed, **SHORT_RING))
        s, why = run._fit_session(inst, run.light_track(inst), 25)
        assert why is None, why
        fe = Forward(thin(s.work), effect, sun=s.sun, polarizer_sign=s.sign)
        start = run._start_effect(fe, s.theta, s.base, effect, s.sigma)
        fr, fr_aop = run._fit_effect(fe, start, s.sigma)
        if not fr.converged:
            fr, fr_aop = run._continued(fe, (fr, fr_aop), s.sigma, None)
        assert fr.converged, (seed, fr.theta[fe.layout.effect])
        values.append(fr.theta[fe.layout.effect])
        se.append(run._effect_sd(fe, fr, fr_aop, s.sigma))
    return np.array(values), np.array(se, float)


def _ratio(values, se):
    return np.std(values, axis=0, ddof=1) / np.sqrt(np.mean(se ** 2, axis=0))


@pytest.mark.slow
def test_aureole_se_matches_the_spread_over_noise_draws():
    """An aureole of twice the sky's radiance at the sun, falling off over 15 deg: the
    empirical SD over 40 draws is 0.89 and 0.91 times the RMS two-step SE of the amplitude
    and the fall-off (measured). The model covariance at the readings' white-noise RMS is
    several times too wide here: the fit weighs every reading's relative residual alike
    while the read noise is a fixed number of counts."""
    values, se = _draws("aureole", Aureole(), {"amplitude": 2.0, "scale_deg": 15.0})
    ratio = _ratio(values, se)
    assert np.all(np.abs(ratio - 1.0) <= _band(ratio.size)), (ratio, values.std(axis=0, ddof=1))


@pytest.mark.slow
def test_stray_light_se_matches_the_spread_over_noise_draws():
    """Stray light of 0.2 times the session's median reading, falling off over 20 deg: the
    empirical SD over 40 draws is 0.71-1.02 times the RMS two-step SE of the 32 strengths
    and 1.05 times that of the fall-off (measured)."""
    values, se = _draws("stray_light", StrayLight(), {"S": 0.2, "scale_deg": 20.0})
    ratio = _ratio(values, se)
    assert np.all(np.abs(ratio - 1.0) <= _band(ratio.size)), (ratio, values.std(axis=0, ddof=1))


def test_stray_light_truth_is_in_units_of_the_recorded_median_reading():
    """The ring generator's stray light is ``S`` times the median of the readings it is in
    (the unit of the candidate's strengths, which divides the recorded readings by their
    median): the added counts over ``S`` times that median are the same fall-off
    ``exp(-psi / psi_0)`` at S = 0.1 and 0.2 (same noise draw, so the same views and
    readings beneath). In the median of the readings without it, the two would differ by
    the ratio of the two medians with it (1.6 % on this short ring). Tolerance: each added
    count is rounded to a whole count, so readings with at least 500 added counts carry a
    relative error of at most 2 x 0.5 / 500 = 0.2 %."""
    scale = 20.0
    clean = ring_session(None, None, 31, **SHORT_RING)
    cols = list(clean.columns)
    R = clean.table[cols].to_numpy(float)
    fall_off = []
    for S in (0.1, 0.2):
        rec = ring_session("stray_light", {"S": S, "scale_deg": scale}, 31, **SHORT_RING)
        Rs = rec.table[cols].to_numpy(float)
        fall_off.append((Rs - R) / (S * np.median(Rs)))
    big = (fall_off[0] * 0.1 * np.median(R)) >= 500.0
    assert big.sum() > 100, big.sum()
    rel = fall_off[1][big] / fall_off[0][big] - 1.0
    assert np.max(np.abs(rel)) <= 2e-3, np.max(np.abs(rel))
