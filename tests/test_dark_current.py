"""Dark-current solve and multi-parameter calibration (calibration/dark_current.py)."""

import numpy as np
import pytest

from calibration.dark_current import (MSE_FACTOR, ChannelModel,
                                      DarkCurrentNotIdentifiableError,
                                      IntensityNotIdentifiableError, TooFewChannelsError,
                                      _solution_jacobian, calibrate_dark_current, output_model,
                                      solve_combined, solve_opponent, solve_photodiodes)
from calibration.solve import heading_error_deg
from skysim.exceptions import InvalidParameterError
from sensor.daq import Daq
from sensor.photodiode import (BelowDarkLevelError, PhotodiodeChannels, SaturatedReadingError,
                               photodiode_signal)

LEVELS = np.array([1.0, 2.0, 5.0, 10.0, 30.0, 100.0, 1000.0])


def _grid(levels=LEVELS):
    phis = np.linspace(-90, 90, 36, endpoint=False)
    return [a.ravel() for a in np.meshgrid(levels, phis, [0.3, 0.7], indexing="ij")]


def test_noise_free_solve_inverts_the_channel_model():
    """x = A^-1 b recovers injected I, phi, d from noise-free outputs (round trip; 1e-6
    relative is the conditioning of A at 1000 lx times double rounding)."""
    p = PhotodiodeChannels.draw(np.random.default_rng(2))
    I, phi, d = _grid()
    sol = solve_opponent(p.outputs(I, phi, d), ChannelModel.from_photodiodes(p))
    np.testing.assert_allclose(sol.intensity_lx, I, rtol=1e-6)
    np.testing.assert_allclose(np.mod(sol.phi_deg - phi + 90, 180) - 90, 0, atol=1e-7)
    np.testing.assert_allclose(sol.dop, d, atol=1e-9)


def test_output_model_matches_photodiode_model():
    """The identifiable parametrisation reproduces the full photodiode model (1e-12 V:
    rounding)."""
    p = PhotodiodeChannels.draw(np.random.default_rng(5))
    I, phi, d = _grid()
    np.testing.assert_allclose(output_model(I, phi, d, ChannelModel.from_photodiodes(p)),
                               p.outputs(I, phi, d), atol=1e-12)


def test_analytic_jacobians_against_finite_differences():
    p = PhotodiodeChannels.draw(np.random.default_rng(6))
    model = ChannelModel.from_photodiodes(p)
    I, phi, d = [a[::20] for a in _grid(LEVELS[:5])]
    U = p.outputs(I, phi, d)
    q, jac = _solution_jacobian(U, model)
    _, Jout = output_model(I, phi, d, model, jacobian=True)
    th = model.to_vector()
    for j in range(8):  # channel 1; other channels share the code path
        h = 1e-6 * max(1.0, abs(th[j]))
        t2 = th.copy()
        t2[j] += h
        m2 = ChannelModel.from_vector(t2)
        q2, _ = _solution_jacobian(U, m2)
        for i in range(3):
            diff = q2[i] - q[i]
            if i == 1:  # phi is axial: a step across -90/90 deg is a small change
                diff = np.mod(diff + 90.0, 180.0) - 90.0
            fd = diff / h
            # forward difference: error ~ h * second derivative; 1e-4 relative of the scale
            np.testing.assert_allclose(jac[:, i, 0, j], fd, rtol=1e-3,
                                       atol=1e-4 * np.abs(fd).max() + 1e-9)
        fd_out = (output_model(I, phi, d, m2) - output_model(I, phi, d, model)) / h
        np.testing.assert_allclose(Jout[:, 0, j], fd_out[:, 0], rtol=1e-4, atol=1e-8)


def test_photodiode_level_solve_round_trip():
    pol = np.array([0.0, 45.0, 90.0, 135.0])
    I, aop, d = 20.0, np.array([-60.0, 10.0, 80.0]), 0.4
    S = photodiode_signal(I, aop[:, None], d, pol, responsivity=5e-11, dark=3e-11,
                          extinction_efficiency=0.99)
    sol = solve_photodiodes(S, pol, responsivity=5e-11, dark=3e-11, extinction_efficiency=0.99)
    np.testing.assert_allclose(sol.intensity_lx, I, rtol=1e-9)
    np.testing.assert_allclose(sol.phi_deg, aop, atol=1e-8)
    np.testing.assert_allclose(sol.dop, d, atol=1e-10)
    with pytest.raises(BelowDarkLevelError):
        solve_photodiodes(np.full((1, 4), 1e-11), pol, dark=3e-11)


def test_calibration_recovers_injected_parameters_within_3_sigma():
    """Round trip with noise: every identifiable parameter within 3 (predicted) sigma of its
    injected value (the 100-trial z statistics are in `skysim reproduce dark-current`)."""
    rng = np.random.default_rng(11)
    p = PhotodiodeChannels.draw(rng)
    noise = np.array([3e-4, 4e-4, 5e-4])
    I, phi, d = _grid()
    daq = Daq()
    U, _ = p.sample(I, phi, d, rng, noise_V=noise, daq=daq)
    cal = calibrate_dark_current(U, I, phi, d, noise_V=np.hypot(noise, daq.lsb_V / 12 ** 0.5),
                                 daq=daq)
    z = (cal.model.to_vector() - ChannelModel.from_photodiodes(p).to_vector()) / \
        cal.standard_errors
    assert np.all(np.abs(z) < 3.0), dict(zip(cal.parameter_names, np.round(z, 2)))
    assert 0.7 < cal.chi2_reduced < 1.4      # noise model right: chi2/dof ~ 1 +- 3 sqrt(2/m)


def test_single_intensity_level_is_not_identifiable():
    rng = np.random.default_rng(1)
    p = PhotodiodeChannels.draw(rng)
    I, phi, d = _grid(np.array([10.0]))
    U, _ = p.sample(I, phi, d, rng)
    with pytest.raises(DarkCurrentNotIdentifiableError, match="single intensity level"):
        calibrate_dark_current(U, I, phi, d)


def test_bad_input():
    model = ChannelModel.nominal()
    with pytest.raises(TooFewChannelsError):
        solve_opponent(np.zeros((4, 2)), model)
    with pytest.raises(IntensityNotIdentifiableError):
        solve_opponent(np.zeros((4, 3)), ChannelModel.nominal(dark_lx=0.0))
    with pytest.raises(SaturatedReadingError):
        solve_opponent(np.array([[0.1, 10.0, 0.0]]), model, daq=Daq())
    I, phi, d = _grid()
    with pytest.raises(ValueError, match="intensity must be > 0"):
        calibrate_dark_current(np.zeros((I.size, 3)), -I, phi, d)


def test_combined_solve_noise_free_equals_dark_model():
    """Noise-free outputs: 1/I is resolved everywhere, and the combined solve inverts the
    channel model like x = A^-1 b (same equations, reparametrised in u = 1/I; tolerances of
    test_noise_free_solve_inverts_the_channel_model: conditioning at 1000 lx)."""
    p = PhotodiodeChannels.draw(np.random.default_rng(2))
    model = ChannelModel.from_photodiodes(p)
    I, phi, d = _grid()
    U = p.outputs(I, phi, d)
    comb = solve_combined(U, model, 1e-9)
    assert comb.dark_model.all()
    np.testing.assert_allclose(comb.intensity_lx, I, rtol=1e-6)
    np.testing.assert_allclose(heading_error_deg(comb.phi_deg, phi), 0, atol=1e-7)
    np.testing.assert_allclose(comb.dop, d, atol=1e-9)
    np.testing.assert_allclose(comb.dark_to_signal, np.mean(model.dark_lx) / I, rtol=1e-6)


def test_bright_arm_ignores_dark_levels_exactly():
    """With 1/I = 0 the dark levels drop out of A (p, q) = -A_0: a sensor without dark
    current is solved exactly whatever dark levels the model carries (round trip)."""
    drawn = PhotodiodeChannels.draw(np.random.default_rng(4))
    p = drawn.with_(dark_A=(0.0,) * 6)
    model = ChannelModel.from_photodiodes(p)
    model = ChannelModel(model.alpha_deg, model.eta, ChannelModel.from_photodiodes(drawn).dark_lx,
                         model.gain_V, model.offset_V)
    I, phi, d = _grid()
    sol = solve_combined(p.outputs(I, phi, d), model, 4e-4, mse_factor=np.inf)
    assert not sol.dark_model.any() and np.isinf(sol.intensity_lx).all()
    np.testing.assert_allclose(heading_error_deg(sol.phi_deg, phi), 0, atol=1e-9)
    np.testing.assert_allclose(sol.dop, d, atol=1e-11)


def _noisy(lux, n, seed=8):
    rng = np.random.default_rng(seed)
    p = PhotodiodeChannels.draw(rng)
    noise = np.array([3e-4, 4e-4, 5e-4])
    phi = rng.uniform(-90, 90, n)
    U = p.outputs(np.full(n, lux), phi, 0.6) + noise * rng.standard_normal((n, 3))
    return U, phi, ChannelModel.from_photodiodes(p), noise


def test_inverse_intensity_sd_matches_monte_carlo():
    """The sd of u = 1/I propagated from the output noise matches the scatter of u_hat over
    4000 noisy repeats of one direction at 10 lx (sd estimate: 1.1 % relative sampling error;
    linearisation error at 10 lx < 1 %; 5 % tolerance = 3 x sampling + linearisation)."""
    rng = np.random.default_rng(3)
    p = PhotodiodeChannels.draw(rng)
    model = ChannelModel.from_photodiodes(p)
    noise = np.array([3e-4, 4e-4, 5e-4])
    U = p.outputs(np.full(4000, 10.0), 20.0, 0.6) + noise * rng.standard_normal((4000, 3))
    sol = solve_combined(U, model, noise, mse_factor=0.0)
    delta = np.mean(model.dark_lx)
    np.testing.assert_allclose(np.std(sol.dark_to_signal), np.median(sol.dark_to_signal_sd),
                               rtol=0.05)
    np.testing.assert_allclose(np.mean(sol.dark_to_signal), delta / 10.0, rtol=0.01)


@pytest.mark.parametrize("lux", [1e4, 3.0])
def test_pooled_combined_is_never_worse_than_either_arm(lux):
    """Heading RMS of the pooled combined solve <= 1.03 x the better arm (dark model, or
    1/I = 0) on the same 3000 samples: paired RMS ratios of one data set, sampling error
    ~1/sqrt(2 x 3000) = 1.3 %, so 3 % is ~2.3 sigma above the no-loss value 1."""
    U, phi, model, noise = _noisy(lux, 3000)

    def rms(sol):
        return np.sqrt(np.mean(heading_error_deg(sol.phi_deg, phi) ** 2))

    b = rms(solve_combined(U, model, noise, mse_factor=0.0))
    b0 = rms(solve_combined(U, model, noise, mse_factor=np.inf))
    cw = solve_combined(U, model, noise, pool_axis=0)
    assert rms(cw) <= 1.03 * min(b, b0), (rms(cw), b, b0)
    assert cw.dark_model.all() == (lux < 100)       # pooled decision: dark model in dim light
    assert cw.dark_to_signal.shape == (3000,)


def test_per_sample_decision_rate_in_bright_light():
    """At 1e4 lx u = 1/I is ~0.05 of its sd: u_hat ~ N(u, sd) and the dark model is chosen
    where u_hat > sqrt(2) sd, i.e. with probability 1 - Phi(sqrt(2) - u/sd) ~ 0.08; the
    observed share over 3000 samples must lie within 3 binomial sigma (0.015)."""
    from scipy.stats import norm
    U, _, model, noise = _noisy(1e4, 3000)
    sol = solve_combined(U, model, noise)
    nc = np.median(np.mean(model.dark_lx) / 1e4 / sol.dark_to_signal_sd)
    p = 1 - norm.cdf(np.sqrt(MSE_FACTOR) - nc)
    assert abs(sol.dark_model.mean() - p) < 3 * np.sqrt(p * (1 - p) / 3000), (
        sol.dark_model.mean(), p)


def test_combined_bad_input():
    U = np.zeros((4, 3))
    m = ChannelModel.nominal()
    m = ChannelModel(m.alpha_deg, m.eta, [[1.0, 2.0]] * 3, m.gain_V, m.offset_V)
    with pytest.raises(InvalidParameterError, match="noise_V"):
        solve_combined(U, m, 0.0)
    with pytest.raises(InvalidParameterError, match="mse_factor"):
        solve_combined(U, m, 1e-3, mse_factor=-1.0)
    with pytest.raises(IntensityNotIdentifiableError, match="equal within every channel"):
        solve_combined(U, ChannelModel.nominal(dark_lx=1.0), 1e-3)
    with pytest.raises(TooFewChannelsError):
        solve_combined(np.zeros((4, 2)), m, 1e-3)


def test_cli_quick(tmp_path):
    import warnings

    from experiments.studies.dark_current import DEFAULT_SEED, run
    from sensor.illuminance import WATER_TYPES, DepthBeyondValidationWarning
    assert DEFAULT_SEED == 20210401
    with warnings.catch_warnings():  # the run marks those depths itself (dop_validated)
        warnings.simplefilter("error", DepthBeyondValidationWarning)
        r = run(trials=2, out=tmp_path, progress=False, figures=True)
    for name in ("by_level.csv", "summary.json", "error_vs_illuminance.png", "by_depth.csv",
                 "underwater.csv", "underwater_heading_vs_depth.png"):
        assert (tmp_path / name).exists(), name
    w = r["by_depth"]
    # surface: the polarized skylight gives a sub-degree heading; at the deepest level of
    # every water type (1 lx, and the in-water DoP 0.07-0.12 instead of the sky's 0.48:
    # heading noise ~ 1/(I d)) the heading error is at least five times larger (observed
    # 9-16x over 100 trials); the DoP never falls below the in-water single-scattering value
    for _, g in w.groupby("water"):
        assert g.heading_3sigma_cw_deg.iloc[0] < 1.0
        assert g.heading_3sigma_cw_deg.iloc[-1] > 5 * g.heading_3sigma_cw_deg.iloc[0]
        assert g.dop.min() > 0.05
    # rows deeper than the DoP model's validated depth (Lerner et al. 2011: 5 m in clear
    # water, none in coastal and turbid water) are marked, the rest not, in both tables
    for t in (w, r["underwater"]):
        bound = t.water.map(lambda n: WATER_TYPES[n].polarization_validated_depth_m)
        assert (t.dop_validated == (t.depth_m <= bound)).all()
    assert w[w.water == "clear_ocean"].dop_validated.sum() >= 2   # the surface and 5 m
    t = r["by_level"]
    low = t[t.illuminance_lx <= 2.2]
    # at ~1-2 lx the dark current dominates: the 2014 model's heading error is many times
    # that of the dark-current model (observed factors 28-59 over 8 trials)
    assert (low.reduction_b_vs_a_best > 5).all()
