"""Multiple scattering through the droplets' forward lobe (skysim.forward_lobe): Poisson
statistics of the scattering number and the composition of Legendre moments."""

import numpy as np
import pytest

from skysim.cloud_light import DIFFRACTION_SHARE, droplet_phase
from skysim.forward_lobe import LOBE_EDGE_DEG, forward_lobe, lobe_multiple_radiance

_THETA = np.concatenate([np.linspace(0.0, 2.0, 401)[:-1], np.linspace(2.0, 30.0, 561)[:-1],
                         np.linspace(30.0, 180.0, 301)])


def _moments(L):
    """``int L dOmega`` and ``int L cos(Theta) dOmega`` over the sphere (trapezoid, fine
    near the sun)."""
    t = np.radians(_THETA)
    w = 2.0 * np.pi * np.sin(t)
    return np.trapezoid(L * w, t), np.trapezoid(L * np.cos(t) * w, t)


@pytest.mark.parametrize("tau", [0.1, 1.0, 5.0])
def test_lobe_light_is_the_beam_scattered_twice_or_more(tau):
    # In the small-angle approximation the lobe only turns light: what it has scattered two
    # or more times carries the share 1 - e^-x (1 + x) of the beam (Poisson, x = f tau /
    # mu0), dimmed by the wide part, e^-((1 - f) tau / mu0); in the flux-pi unit its
    # radiance integrates to pi times that. Its mean cosine is that of the n-fold
    # convolutions, sum over n >= 2 of the Poisson weights times g_F^n (the Legendre
    # moments of a convolution multiply), with g_F the lobe's own mean cosine from the phase
    # table. Tolerance 2e-3 (measured 4e-4 and 7e-5): the quadrature of the 0.5-deg-wide
    # peak and the table's bilinear interpolation in the slant thickness (121 nodes over
    # six decades)
    lobe, mu0 = forward_lobe(), 0.6
    L = lobe_multiple_radiance(tau, mu0, _THETA)
    power, first = _moments(L)
    f = lobe.share
    x = f * tau / mu0
    dim = np.exp(-(1.0 - f) * tau / mu0)
    share = 1.0 - np.exp(-x) * (1.0 + x)
    assert power == pytest.approx(np.pi * dim * share, rel=2e-3)
    ph = droplet_phase()
    t = np.radians(ph.angle_deg)
    w = ph.p11 * np.sin(t) * lobe.taper
    g_f = np.trapezoid(w * np.cos(t), t) / np.trapezoid(w, t)
    mean_cos = (np.exp(-x * (1.0 - g_f)) - np.exp(-x) * (1.0 + x * g_f)) / share
    assert first / power == pytest.approx(mean_cos, rel=2e-3)


def test_the_lobe_is_the_diffraction_peak_and_tapers_off_by_its_edge():
    # Fully in the lobe out to the angle holding DIFFRACTION_SHARE of the scattering (van de
    # Hulst 1957 sect. 8.22), nothing beyond LOBE_EDGE_DEG; its share lies between the two
    # (what lies within the edge: 0.78)
    lobe = forward_lobe()
    ph = droplet_phase()
    t = np.radians(ph.angle_deg)
    w = ph.p11 * np.sin(t) * np.gradient(t)
    inner = np.interp(DIFFRACTION_SHARE, np.cumsum(w) / w.sum(), ph.angle_deg)
    assert np.all(lobe.taper_at(np.linspace(0.0, inner - 0.1, 20)) == 1.0)
    assert np.all(lobe.taper_at(np.linspace(LOBE_EDGE_DEG, 180.0, 20)) == 0.0)
    within = w[ph.angle_deg <= LOBE_EDGE_DEG].sum() / w.sum()
    assert DIFFRACTION_SHARE < lobe.share < within
    g = ph.asymmetry_parameter
    g_lobe = np.sum(w * lobe.taper * np.cos(t)) / np.sum(w * lobe.taper)
    assert lobe.share * g_lobe + (1.0 - lobe.share) * lobe.wide_asymmetry == pytest.approx(
        g, abs=1e-3)


def test_lobe_light_stays_near_the_sun():
    # Light turned n times by a lobe no wider than 30 deg: beyond 60 deg below 1e-4 of its
    # value at the sun for up to five lobe scatterings on average (the Legendre series'
    # ringing, damped by the Lanczos factors, would show there)
    for tau in (0.1, 1.0, 5.0):
        L = lobe_multiple_radiance(tau, 0.6, np.array([0.0, 60.0, 90.0, 135.0, 180.0]))
        assert np.all(L[1:] < 1e-4 * L[0]) and np.all(L >= 0.0)
