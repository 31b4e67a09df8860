"""Heading solve (eqs. 5-9) and Gauss-Newton LSM compensation (eqs. 10-14)."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration import (ConvergenceError, RankDeficientError, TooFewSamplesError, fit_pair,
                         heading_error_deg, solve_pair, solve_pair_compensated)
from calibration.lsq import fit_pairs
from calibration.pipeline import calibrate_measurement
from calibration.solve import PAIRS
from sensor.daq import Daq
from sensor.errors import OpponentErrors
from sensor.opponent import OpponentSensor, channel_outputs
from skysim.sky import RayleighSky
from written_out import pair_by_cramer  # tests/written_out.py

ERR = OpponentErrors(misalignment_deg=(0.6, -0.4, 0.9, 0.2, -0.7, 0.3),
                     transmittance=(0.012, -0.008, 0.02))
PAIR_PARAMS = {(1, 2): ([0, 1, 2, 3], [0, 1]), (1, 3): ([0, 1, 4, 5], [0, 2]),
               (2, 3): ([2, 3, 4, 5], [1, 2])}


def _truth(pair):
    mi, fi = PAIR_PARAMS[pair]
    return np.array(ERR.misalignment_deg)[mi], np.array(ERR.transmittance)[fi]


@settings(max_examples=300, deadline=None)
@given(phi=st.floats(-90.0, 89.999), d=st.floats(0.05, 0.95), pair=st.sampled_from(PAIRS))
def test_ideal_forward_inverse_returns_heading(phi, d, pair):
    """Forward (eqs. 2-3, no errors) then inverse (eqs. 5-9): heading to 1e-9 deg, d to 1e-12;
    phi covers [-90, 90): the 90-degree ambiguity of atan is resolved by d > 0."""
    u = channel_outputs(phi, d)
    phi_hat, d_hat = solve_pair(u, pair)
    assert abs(heading_error_deg(phi_hat, phi)) < 1e-9
    assert d_hat == pytest.approx(d, abs=1e-12)


@settings(max_examples=200, deadline=None)
@given(phi=st.floats(-90.0, 89.999), d=st.floats(0.1, 0.9), pair=st.sampled_from(PAIRS))
def test_compensated_forward_inverse_with_known_errors(phi, d, pair):
    """With known errors and no noise, the compensated inverse returns the heading to 1e-9."""
    u = channel_outputs(phi, d, ERR.misalignment_deg, ERR.transmittance)
    mis, f = _truth(pair)
    phi_hat, d_hat = solve_pair_compensated(u, pair, mis, f)
    assert abs(heading_error_deg(phi_hat, phi)) < 1e-9
    assert d_hat == pytest.approx(d, abs=1e-10)


def test_solve_output_range_covers_half_circle():
    phi = np.linspace(-90, 89.9, 1000)
    phi_hat, _ = solve_pair(channel_outputs(phi, 0.5), (2, 3))
    assert phi_hat.min() >= -90 and phi_hat.max() < 90
    np.testing.assert_allclose(phi_hat, phi, atol=1e-9)


def _sweep(n=181, d=0.5, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    phi = np.linspace(-90, 90, n, endpoint=False)
    u = channel_outputs(phi, d, ERR.misalignment_deg, ERR.transmittance)
    return phi, u + noise * rng.standard_normal(u.shape)


@pytest.mark.parametrize("pair", PAIRS)
def test_lsm_recovers_parameters_noise_free(pair):
    """Round trip: noise-free sweep -> exact parameters (1e-7 deg, 1e-9 in f)."""
    phi, u = _sweep()
    cal = fit_pair(phi, u, pair, 0.5)
    mis, f = _truth(pair)
    np.testing.assert_allclose(cal.misalignment_deg, mis, atol=1e-7)
    np.testing.assert_allclose(cal.transmittance, f, atol=1e-9)
    assert cal.converged and cal.iterations < 15


def test_lsm_with_dop_scale_and_noise_within_standard_errors():
    """With 0.5 mV noise the estimates lie within 4 standard errors of the truth, and over
    40 noise realisations the z-scores have unit spread (0.7..1.3: the sample SD of 40 draws
    has a relative SE of 11 %, so this band is ~3 SE wide): the covariance is honest."""
    mis, f = _truth((1, 3))
    z = []
    for seed in range(40):
        phi, u = _sweep(noise=5e-4, seed=seed, d=0.7 * 0.6)
        cal = fit_pair(phi, u, (1, 3), 0.6, fit_dop_scale=True)
        est = np.r_[cal.misalignment_deg, cal.transmittance, cal.dop_scale]
        z.append((est - np.r_[mis, f, 0.7]) / cal.standard_errors)
    z = np.array(z)
    assert np.abs(z).max() < 4.5
    assert 0.7 < z.std() < 1.3


def test_lsm_compensation_reduces_heading_error():
    phi, u = _sweep(noise=3e-4, seed=3)
    raw = heading_error_deg(solve_pair(u, (1, 2))[0], phi)
    cal = fit_pair(phi, u, (1, 2), 0.5)
    comp = heading_error_deg(cal.solve(u)[0], phi)
    assert np.abs(raw).max() > 0.5          # errors of ~1 deg before compensation
    assert 3 * comp.std() < 0.2             # noise level after: 0.3 mV ~ 0.04 deg per channel


def test_lsm_bad_input():
    phi, u = _sweep(n=5)
    with pytest.raises(TooFewSamplesError, match="5 samples for 6 parameters"):
        fit_pair(phi, u, (1, 2), 0.5)
    with pytest.raises(TooFewSamplesError, match="7 parameters"):
        fit_pair(np.r_[phi, 0.0], np.vstack([u, u[:1]]), (1, 2), 0.5, fit_dop_scale=True)
    same = np.full(20, 10.0)
    with pytest.raises(RankDeficientError, match="not observable"):
        fit_pair(same, channel_outputs(same, 0.5), (1, 2), 0.5)
    phi, u = _sweep(noise=1e-3)
    with pytest.raises(ConvergenceError, match="last step") as info:
        fit_pair(phi, u, (1, 2), 0.5, max_iter=1)
    assert info.value.last_step > 0
    with pytest.raises(ValueError, match="pair"):
        fit_pair(phi, u, (1, 1), 0.5)
    with pytest.raises(ValueError, match="nan"):
        fit_pair(np.r_[np.nan, phi[1:]], u, (1, 2), 0.5)


def test_calibrate_measurement_table(xian):
    """End to end on a simulated table: the fitted d_max and mounting errors match the
    injected ones (within 5 SE), and the compensated 3 sigma is at the noise level."""
    rng = np.random.default_rng(5)
    err = OpponentErrors(ERR.misalignment_deg, ERR.transmittance, noise_V=3e-4)
    times = pd.date_range("2013-05-22T17:10:00+08:00", periods=181, freq="3333ms")
    headings = 275.5 - 90 + np.arange(181.0)
    m = OpponentSensor(err, daq=Daq(16)).sample(RayleighSky(0.7), xian, times, headings, rng)
    res = calibrate_measurement(m)
    for pair, cal in res.pairs.items():
        mis, _ = _truth(pair)
        se = cal.standard_errors
        assert np.all(np.abs(cal.misalignment_deg - mis) < 5 * se[:4])
        assert abs(cal.dop_scale - 0.7) < 5 * se[6]
    rows = res.summary_rows()
    assert all(r["compensated_3sigma_deg"] < 0.25 < r["raw_max_abs_deg"] for r in rows)


def test_batched_lsm_equals_single_fits_and_recovers_each_sensor():
    """fit_pairs over a batch of sensors (different errors, noise, d_max) gives, element by
    element, the same estimate as fit_pair (1e-9: same algorithm, only vectorised) and the
    batched compensated solve the same headings (1e-9 deg)."""
    rng = np.random.default_rng(3)
    trials, n = 5, 91
    phi = np.linspace(-90, 90, n, endpoint=False)
    mis = rng.uniform(-1, 1, (trials, 6))
    f = 0.01 * rng.standard_normal((trials, 3))
    dmax = rng.uniform(0.5, 0.8, trials)
    shape = 0.9 + 0.1 * np.cos(np.radians(phi))        # any DoP shape; its scale is fitted
    u = channel_outputs(phi, dmax[:, None] * shape, mis[:, None, :], f[:, None, :])
    u = u + 3e-4 * rng.standard_normal(u.shape)
    batch = fit_pairs(phi[None].repeat(trials, 0), u, (1, 3), shape, fit_dop_scale=True)
    assert batch.misalignment_deg.shape == (trials, 4) and batch.converged.all()
    phi_b, _ = batch.solve(u)
    for k in range(trials):
        single = fit_pair(phi, u[k], (1, 3), shape, fit_dop_scale=True)
        np.testing.assert_allclose(batch.misalignment_deg[k], single.misalignment_deg, atol=1e-9)
        np.testing.assert_allclose(batch.transmittance[k], single.transmittance, atol=1e-11)
        assert batch.dop_scale[k] == pytest.approx(single.dop_scale, abs=1e-11)
        np.testing.assert_allclose(phi_b[k], single.solve(u[k])[0], atol=1e-9)
        # and each sensor's own injected errors come back (noise 0.3 mV -> ~0.05 deg)
        np.testing.assert_allclose(batch.misalignment_deg[k], mis[k, [0, 1, 4, 5]], atol=0.1)
        assert batch.dop_scale[k] == pytest.approx(dmax[k], abs=0.01)


def test_batched_lsm_flags_or_names_the_failing_element():
    """A degenerate element (all samples at one heading) raises naming its batch index, or
    is flagged with on_failure='flag' while the others are still estimated."""
    phi, u = _sweep(n=60)
    phis = np.stack([phi, np.full_like(phi, 10.0)])
    us = np.stack([u, channel_outputs(phis[1], 0.5)])
    with pytest.raises(RankDeficientError, match=r"batch element \(1,\)"):
        fit_pairs(phis, us, (1, 2), 0.5)
    res = fit_pairs(phis, us, (1, 2), 0.5, on_failure="flag")
    assert res.converged.tolist() == [True, False]
    np.testing.assert_allclose(res.misalignment_deg[0], _truth((1, 2))[0], atol=1e-7)
    with pytest.raises(ValueError, match="on_failure"):
        fit_pairs(phis, us, (1, 2), 0.5, on_failure="ignore")


def test_solve_pairs_equals_each_pair_written_out():
    """All pairs at once, in cache-sized blocks (more than one block here), equal the per-pair
    formulas to 1e-12 deg / 1e-12 in d, with phi in [-90, 90) (+90 -> -90)."""
    from calibration.solve import SOLVE_BLOCK, solve_pairs
    rng = np.random.default_rng(4)
    n = 2 * SOLVE_BLOCK + 17
    phi = rng.uniform(-90, 90, n)
    phi[:3] = [-90.0, 0.0, 45.0]
    u = channel_outputs(phi, rng.uniform(0.05, 0.95, n))
    got_phi, got_d = solve_pairs(u)
    assert got_phi.shape == (n, 3) and got_d.shape == (n, 3)
    for k, pair in enumerate(PAIRS):
        ref_phi, ref_d = pair_by_cramer(u, pair)
        assert np.max(np.abs(heading_error_deg(got_phi[:, k], ref_phi))) < 1e-12
        np.testing.assert_allclose(got_d[:, k], ref_d, rtol=0, atol=1e-12)
    assert np.all((got_phi >= -90.0) & (got_phi < 90.0))
    np.testing.assert_array_equal(solve_pair(u, (2, 3))[0], got_phi[:, 2])


def test_solve_pairs_boundary_and_signed_zeros_stay_in_range():
    """phi is in [-90, 90) from the sign of zero alone: headings at exactly +-90 deg and
    outputs that are +0 or -0 (every sign pattern, alone and beside a nonzero channel) never
    give +90; where the pair's d > 0 they equal the per-pair formulas (axially, 1e-12 deg), and
    a pair whose two outputs are zero gives d = 0 exactly."""
    from calibration.solve import solve_pairs
    signs = np.array([[a, b, c] for a in (1, -1) for b in (1, -1) for c in (1, -1)], float)
    zeros = 0.0 * signs                                          # +0 / -0 in every pattern
    one_lit = zeros.copy()
    one_lit[:, 0] = 0.3                                          # U1 nonzero, U2 = U3 = +-0
    u = np.concatenate([channel_outputs(np.array([-90.0, 90.0, 0.0, -45.0]), 0.6),
                        zeros, one_lit, one_lit[:, [1, 0, 2]], one_lit[:, [1, 2, 0]]])
    phi, d = solve_pairs(u)
    assert np.all((phi >= -90.0) & (phi < 90.0)) and np.all(np.isfinite(phi))
    for k, pair in enumerate(PAIRS):
        ref_phi, ref_d = pair_by_cramer(u, pair)
        dark = np.all(u[:, [pair[0] - 1, pair[1] - 1]] == 0.0, axis=1)
        assert dark.sum() == 16                  # the eight all-zero rows and eight more
        np.testing.assert_array_equal(d[dark, k], 0.0)
        lit = ~dark
        assert np.max(np.abs(heading_error_deg(phi[lit, k], ref_phi[lit]))) < 1e-12
        np.testing.assert_allclose(d[:, k], ref_d, rtol=0, atol=1e-15)
    # a pair given in either order is the same linear system
    rev_phi, rev_d = solve_pairs(u, tuple(pair[::-1] for pair in PAIRS))
    np.testing.assert_allclose(rev_phi, phi, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rev_d, d, rtol=0, atol=1e-15)


def test_solve_pairs_shapes_and_bad_input():
    from calibration.solve import solve_pairs
    u = channel_outputs(np.linspace(-80, 80, 12).reshape(3, 4), 0.5)
    phi, d = solve_pairs(u, ((1, 2), (2, 3)))
    assert phi.shape == (3, 4, 2) and d.shape == (3, 4, 2)
    assert solve_pair(u[0, 0], (1, 3))[0].shape == ()
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        solve_pairs(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="two different channels"):
        solve_pairs(u, ((1, 1),))
