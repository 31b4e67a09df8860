"""The three-pair diagnosis fits what its outputs identify, and judges with the right margin.

- The extinction-ratio candidate is fitted as the six polarizers' differences from their
  mean (``RelativeExtinction``): its forward model is the library effect's up to a common
  efficiency (a DoP scale), its Jacobian is analytic, and a strong extinction ratio is named
  with its differences recovered.
- The paired margin is Student's t at the normal level for the jackknife's degrees of
  freedom (``paired_margin``), which turns the one false attribution of a withheld clock error
  into a group.
"""

import numpy as np
import pytest
from scipy.stats import t as student_t

from calibration import effects as E
from calibration.diagnosis import diagnose
from calibration.diagnosis.core import paired_margin
from calibration.diagnosis.three_pair import DEFAULT_CANDIDATES
from calibration.diagnosis.three_pair_fit import RelativeExtinction, fit_form
from experiments.workflows.diagnose import simulate_session

PATTERN = np.array([1.2, 0.7, 1.0, 1.4, 0.6, 1.1])
BASE = E.base_vector([0.3, -0.2, 0.5, 0.1, -0.4, 0.2], [0.01, -0.02, 0.005], 0.7)


@pytest.fixture(scope="module")
def ctx():
    return simulate_session(None, np.random.default_rng(3))["data"].ctx


def test_relative_extinction_is_the_library_effect_up_to_a_dop_scale(ctx):
    """For eps = 0.06 x a spread, the relative form's outputs equal the library effect's
    when the base's DoP scale carries the common efficiency: eta_k = exp(-2 atanh eps_k)
    exactly (Born & Wolf's (1 - eps)/(1 + eps)), so the relative form's eta_k times
    exp(-2 mean atanh eps) M is the library's; agreement to 1e-12 V (float rounding), while
    the library effect itself moves the outputs by ~1e-2 V."""
    eps = 0.06 * PATTERN
    rel = RelativeExtinction()
    r = rel.from_eps(eps)
    assert r.sum() == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose(r, eps - eps.mean(), atol=0.01 * eps.max())
    lib = E.forward(ctx, BASE, E.get_effect("extinction_ratio"), eps)
    eta_rel = rel.efficiencies(r[:5])
    eta_lib = (1 - eps) / (1 + eps)
    common = eta_lib / eta_rel
    np.testing.assert_allclose(common, common[0], rtol=1e-12)
    assert np.all(eta_rel <= 1.0) and eta_rel.max() > 1 / 1.04
    base = BASE.copy()
    base[9] *= common[0]
    # the library's intensity factor 1 + eps is a transmittance term: f_i += log10 of the
    # ratio of the pair's factors
    base[6:9] += np.log10((1 + eps[0::2]) / (1 + eps[1::2]))
    out = E.forward(ctx, base, rel, r[:5])
    assert np.max(np.abs(lib - E.forward(ctx, BASE))) > 5e-3
    np.testing.assert_allclose(out, lib, rtol=0, atol=1e-12)


@pytest.mark.parametrize("scale", [0.0, 0.02, 0.06])
def test_relative_extinction_jacobian_matches_finite_differences(ctx, scale,
                                                                 effect_jacobians):
    """Central differences with steps 1e-2 of the fit's own (relative error ~1e-7), at
    equal polarizers (scale 0: every eta tied, where the smooth maximum matters) and at
    spread ones."""
    rel = RelativeExtinction()
    analytic, central = effect_jacobians(ctx, BASE, rel,
                                         rel.from_eps(scale * PATTERN + 1e-3)[:5], 5)
    assert analytic.shape == (ctx.n, 3, 5)
    # central differences err by ~1e-7 relative at these steps, hence rtol 1e-5; atol 1e-9
    # for entries near zero
    np.testing.assert_allclose(analytic, central, rtol=1e-5, atol=1e-9)


def test_relative_extinction_reports_six_differences_with_their_covariance():
    """The sixth difference is minus the sum of the five fitted ones; its SE is that of the
    sum, sqrt(1' C 1)."""
    rel = RelativeExtinction()
    C = np.diag([1.0, 2.0, 3.0, 4.0, 5.0]) * 1e-6
    C[0, 1] = C[1, 0] = 0.5e-6
    out = rel.report(np.array([0.01, -0.02, 0.0, 0.03, -0.005]), C)
    assert list(out) == [f"eps_{k}_rel" for k in range(1, 7)]
    assert out["eps_6_rel"]["value"] == pytest.approx(-0.015)
    assert out["eps_6_rel"]["se"] == pytest.approx(np.sqrt(C.sum()))
    assert out["eps_2_rel"]["se"] == pytest.approx(np.sqrt(2e-6))
    assert fit_form(E.get_effect("extinction_ratio")) is not E.get_effect("extinction_ratio")
    assert fit_form(E.get_effect("tilt")) is E.get_effect("tilt")


def test_strong_extinction_ratio_is_named_with_its_differences():
    """eps 0.036-0.084 (seed 11 of the identifiability matrix's strong case), all
    candidates: extinction_ratio named, no parameter at a bound, and each difference from
    the mean within 4 SE of the truth (a calibrated SE exceeds 4 with probability 6e-5 per
    parameter)."""
    eps = 0.06 * PATTERN
    data = simulate_session("extinction_ratio", np.random.default_rng(11), params=eps)["data"]
    rep = diagnose(data, DEFAULT_CANDIDATES, seed=0)
    assert rep.verdict.effect == "extinction_ratio", rep.verdict.reason
    c = rep.candidate("extinction_ratio")
    assert c.at_bound == [] and c.converged
    truth = RelativeExtinction.from_eps(eps)
    z = [(c.params[f"eps_{k}_rel"]["value"] - truth[k - 1]) / c.params[f"eps_{k}_rel"]["se"]
         for k in range(1, 7)]
    assert np.all(np.abs(z) < 4.0), z


def test_paired_margin_is_student_t_at_the_normal_level():
    """2 normal SEs one-sided (97.7 %) with six sweeps (5 degrees of freedom) is the t
    quantile 2.6486, given to 0.01; it falls to 2 as the sweeps grow; one sweep keeps the
    margin."""
    level = 0.9772498680518208          # Phi(2)
    assert paired_margin(2.0, 6) == round(student_t.ppf(level, 5), 2) == 2.65
    assert paired_margin(2.0, 12) == 2.25
    assert paired_margin(2.0, 10_000) == 2.0
    assert paired_margin(2.0, 1) == 2.0


def test_withheld_clock_error_is_not_taken_for_a_sky():
    """A 600 s clock error withheld (noise seed 13): thermal drift
    and the multiple-scattering sky remove ~95 % of the excess alike. With two normal SEs
    the sky beat the drift by 2.12 jackknife SEs over six sweeps and was named; with the t
    margin (2.65) the verdict is a group holding both."""
    data = simulate_session("clock_offset", np.random.default_rng(13),
                            params=np.array([600.0]))["data"]
    others = tuple(c for c in DEFAULT_CANDIDATES if c != "clock_offset")
    rep = diagnose(data, others, seed=0)
    assert rep.verdict.effect == "group", rep.verdict.reason
    assert {"multiple_scattering", "thermal_drift"} <= set(rep.verdict.group)
    assert rep.thresholds["paired_se"] == 2.65
