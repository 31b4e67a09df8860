"""Photodiode-level channel model (sensor/photodiode.py): reduction to the 2014 equation,
Malus's law closed forms, extinction ratio, dark current, shot noise, bad input."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sensor.daq import Daq
from sensor.errors import OpponentErrors
from sensor.opponent import channel_outputs
from sensor.photodiode import (BelowDarkLevelError, InvalidIntensityError, PhotodiodeChannels,
                               SaturatedReadingError, check_above_dark, check_not_saturated,
                               extinction_factors, opponent_log_ratio, photodiode_signal,
                               shot_noise, three_pair_outputs, three_pair_signals)
from skysim.exceptions import InvalidParameterError

# Two evaluations of the same real number by different sequences of double operations
# (log10(a/b) vs log10(a'/b') + log10(K_n/K_m)) differ by a few ulp of values of order 1:
# 1e-13 V is 100x that and 1e9 times below the 0.3 mV LSB of the DAQ.
ROUNDING_V = 1e-13


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), log_intensity=st.floats(-3, 6))
def test_reduces_exactly_to_three_pair_equation(seed, log_intensity):
    """D = 0, ideal polarizers, gain 0.5, V_OSO = 0: eq. 2 of Yang 2014 with
    f_k = log10(K_n / K_m), at any intensity (the 2014 model has no intensity term)."""
    rng = np.random.default_rng(seed)
    phi, dop = rng.uniform(-90, 90, 200), rng.uniform(0.01, 0.99, 200)
    err = OpponentErrors.draw(rng, misalignment_max_deg=2.0, transmittance_sd=0.05,
                              noise_range_V=(0.0, 0.0))
    params = PhotodiodeChannels.from_opponent_errors(err)
    u = params.outputs(10.0 ** log_intensity, phi, dop)
    u_2014 = channel_outputs(phi, dop, err.misalignment_deg, err.transmittance)
    np.testing.assert_allclose(u, u_2014, rtol=0, atol=ROUNDING_V)
    # the same through the plain function interface
    resp = np.stack([10.0 ** np.asarray(err.transmittance), np.ones(3)], axis=-1).ravel()
    u_fn = three_pair_outputs(10.0 ** log_intensity, phi, dop,
                              mounting_error_deg=err.misalignment_deg, responsivity=resp)
    np.testing.assert_allclose(u_fn, u_2014, rtol=0, atol=ROUNDING_V)


def test_malus_closed_forms():
    """Ideal polarizer: S = K I (1 + d cos 2(chi - p)); unpolarized light gives K I at every
    angle, fully polarized light K I (1 + cos 2 delta) = 2 K I cos^2 delta (Malus)."""
    delta = np.linspace(-90, 90, 37)
    s = photodiode_signal(3.0, delta, 0.999999999, 0.0, responsivity=2.0)
    np.testing.assert_allclose(s, 2 * 2.0 * 3.0 * np.cos(np.radians(delta)) ** 2,
                               rtol=0, atol=1e-8)
    np.testing.assert_allclose(photodiode_signal(3.0, delta, 0.0, 0.0, responsivity=2.0), 6.0)


def test_extinction_ratio_against_principal_transmittances():
    """T1, T2 principal transmittances: S/I = (T1 + T2)/2 + (T1 - T2)/2 d cos 2delta,
    Hecht sect. 8.3, in the normalisation where an ideal polarizer gives 1 + d cos 2delta
    (factor 2 of the unpolarized half absorbed in K)."""
    t1, ratio = 0.88, 5e-3
    k, eta = extinction_factors(ratio, t1)
    t2 = ratio * t1
    delta, d = np.linspace(-90, 90, 19), 0.6
    s = photodiode_signal(1.0, delta, d, 0.0, extinction_intensity=k,
                          extinction_efficiency=eta)
    expected = (t1 + t2) + (t1 - t2) * d * np.cos(np.radians(2 * delta))
    np.testing.assert_allclose(s, expected, rtol=1e-14)
    # crossed fully polarized light leaks T2 (x2 for the normalisation above)
    np.testing.assert_allclose(photodiode_signal(1.0, 90.0, 1 - 1e-12, 0.0,
                                                 extinction_intensity=k,
                                                 extinction_efficiency=eta), 2 * t2, rtol=1e-9)


def test_dark_current_is_additive_and_pulls_ratio_to_dark_ratio():
    s0 = photodiode_signal(5.0, 10.0, 0.5, 30.0, responsivity=1e-10)
    s1 = photodiode_signal(5.0, 10.0, 0.5, 30.0, responsivity=1e-10, dark=7e-11)
    assert s1 - s0 == pytest.approx(7e-11, rel=1e-12)
    # vanishing light: U -> Ka log10(D_n / D_m) + V_OSO
    p = PhotodiodeChannels(dark_A=(1e-10, 2e-10, 3e-10, 1e-10, 1e-10, 4e-10),
                           offset_V=(0.01, 0.0, -0.01))
    u = p.outputs(1e-9, 30.0, 0.7)
    d = np.reshape(p.dark_A, (3, 2))
    np.testing.assert_allclose(u, 0.5 * np.log10(d[:, 0] / d[:, 1]) + np.array([0.01, 0, -0.01]),
                               atol=1e-9)


def test_log_ratio_gain_offset():
    assert opponent_log_ratio(100.0, 1.0, gain=0.4, offset_V=0.02) == pytest.approx(0.82)


def test_broadcasting_shapes():
    s = three_pair_signals(np.ones((4, 1)), np.zeros((1, 5)), 0.5)
    assert s.shape == (4, 5, 3, 2)
    assert PhotodiodeChannels().outputs(np.ones(7), 0.0, 0.5).shape == (7, 3)


def test_shot_noise_variance():
    """var = 2 q I B: 1 nA over 10 Hz gives 5.66e-15 A rms; 20,000 draws estimate the sd
    to 0.5 % (1 sigma), checked within 3 %."""
    rng = np.random.default_rng(3)
    n = shot_noise(np.full(20_000, 1e-9), 10.0, rng)
    assert np.std(n) == pytest.approx(np.sqrt(2 * 1.602176634e-19 * 1e-9 * 10), rel=0.03)


def test_sample_noise_is_the_requested_output_noise():
    """Bright light (shot noise ~1e-6 V) and no quantisation: sd(U) = noise_V within 3 %."""
    rng = np.random.default_rng(4)
    p = PhotodiodeChannels()
    u, sat = p.sample(np.full(20_000, 1e4), 0.0, 0.5, rng, noise_V=1e-3, daq=Daq(bits=None))
    assert not sat.any()
    np.testing.assert_allclose(u.std(axis=0), 1e-3, rtol=0.03)


@pytest.mark.parametrize("bad", [0.0, -1.0])
def test_rejects_zero_or_negative_intensity(bad):
    with pytest.raises(InvalidIntensityError, match="intensity must be > 0"):
        photodiode_signal([1.0, bad], 0.0, 0.5, 0.0)


def test_rejects_bad_parameters():
    with pytest.raises(InvalidParameterError, match="dop"):
        photodiode_signal(1.0, 0.0, 1.0, 0.0)
    with pytest.raises(InvalidParameterError, match="dark"):
        photodiode_signal(1.0, 0.0, 0.5, 0.0, dark=-1e-12)
    with pytest.raises(InvalidIntensityError, match="signal_b"):
        opponent_log_ratio(1.0, 0.0)
    with pytest.raises(InvalidParameterError, match="extinction_ratio"):
        extinction_factors(1.0)


def test_rejects_saturated_and_below_dark_readings():
    daq = Daq(16, 10.0)
    with pytest.raises(SaturatedReadingError, match="rail"):
        check_not_saturated([0.1, 10.0 - daq.lsb_V], daq)
    check_not_saturated([0.1, 9.0], daq)
    with pytest.raises(BelowDarkLevelError, match="dark level"):
        check_above_dark([2e-10, 4e-11], [5e-11, 5e-11])
