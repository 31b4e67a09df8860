"""Single scattering of a layered slab (skysim.slab_single_scatter): closed-form limits and an
independent quadrature."""

import numpy as np
import pytest

from skysim.exceptions import InvalidParameterError
from skysim.rayleigh import slab_transmission
from skysim.slab_single_scatter import (perpendicular_stokes, phase_at_angle,
                                        single_scatter_weights)


def test_homogeneous_slab_is_the_classical_closed_form():
    # One homogeneous layer: A = mu0 (e^-T/mu0 - e^-T/mu) / (mu0 - mu) (Hansen & Travis 1974,
    # sect. 3; skysim.rayleigh.slab_transmission), for every constituent in proportion to its
    # share of the extinction; mu = mu0 included (the removable singularity). Both sides are
    # closed forms: 1e-12 is round-off
    z = np.linspace(0.0, 1000.0, 5)
    ke = np.full(z.size, 2e-3)                       # T = 2
    ks = np.column_stack([0.25 * ke, 0.7 * ke])
    mu = np.array([0.05, 0.3, 0.5, 0.5000001, 0.9, 1.0])
    A = single_scatter_weights(z, ks, ke, mu, 0.5)
    h = slab_transmission(2.0, mu, 0.5)
    np.testing.assert_allclose(A[0], 0.25 * h, rtol=1e-12)
    np.testing.assert_allclose(A[1], 0.7 * h, rtol=1e-12)


def test_layer_with_ramps_matches_a_brute_force_quadrature():
    # A cloud layer with linear ramps at its edges inside a uniform Rayleigh slab (the
    # engine's profile): against the trapezoid rule on 400001 points of the same
    # piecewise-linear profile (its error ~ (dz)^2 f'' / 12: below 1e-6 relative here), 1e-5
    z = np.array([0.0, 900.0, 1000.0, 1100.0, 1500.0, 2000.0, 2100.0, 10000.0])
    k_r = np.full(z.size, 1e-5)
    k_p = np.array([0, 0, 0, 2e-3, 2e-3, 2e-3, 0, 0.0])
    ks = np.column_stack([k_r, 0.99 * k_p])
    mu, mu0 = np.array([0.08, 0.3, 0.64, 1.0]), 0.4
    A = single_scatter_weights(z, ks, k_r + k_p, mu, mu0)
    zz = np.linspace(0.0, z[-1], 400001)
    kk = np.interp(zz, z, k_r + k_p)
    t = np.concatenate([[0.0], np.cumsum(0.5 * (kk[1:] + kk[:-1]) * np.diff(zz))])
    t = t[-1] - t                                    # optical depth from the top
    T = t[0]
    for j, k in enumerate((np.interp(zz, z, ks[:, 0]), np.interp(zz, z, ks[:, 1]))):
        ref = np.trapezoid(k * np.exp(-t / mu0 - (T - t) / mu[:, None]), zz, axis=1) / mu
        np.testing.assert_allclose(A[j], ref, rtol=1e-5)


def test_grazing_view_does_not_overflow():
    # mu -> 0: exp(-c t) alone overflows; the weights are factored at the run's larger end.
    # Grazing limit: only the lowest optical depth ~ mu is seen, lit through the whole slab,
    # A -> exp(-T / mu0) (T = 1 here), to first order in mu / mu0 = 2e-4
    z = np.array([0.0, 5000.0, 10000.0])
    ke = np.full(3, 1e-4)
    A = single_scatter_weights(z, ke[:, None], ke, 1e-4, 0.5)
    assert np.isfinite(A).all()
    assert A[0] == pytest.approx(np.exp(-2.0), rel=1e-3)


def test_phase_interpolation_is_exact_on_the_table_and_log_linear_between():
    a = np.array([0.0, 1.0, 2.0])
    p11, p12 = np.array([100.0, 10.0, 1.0]), np.array([10.0, -1.0, 0.5])
    q11, q12 = phase_at_angle(a, p11, p12, [0.0, 0.5, 2.0])
    np.testing.assert_allclose(q11, [100.0, np.sqrt(1000.0), 1.0])
    np.testing.assert_allclose(q12 / q11, [0.1, 0.5 * (0.1 - 0.1), 0.5], atol=1e-15)


def test_perpendicular_stokes_has_the_given_degree_and_no_plane_on_the_sun_line():
    a, b = np.array([0.6, 0.0, 0.0]), np.array([0.0, 0.8, 0.0])
    I, Q, U = perpendicular_stokes(np.ones(3), np.array([0.5, -0.5, 0.5]), a, b)
    np.testing.assert_allclose(np.hypot(Q, U), [0.5, 0.5, 0.0])
    assert Q[0] > 0 and Q[1] > 0      # E along a (perpendicular), and parallel to the plane


def test_bad_levels_raise():
    with pytest.raises(InvalidParameterError, match="altitudes"):
        single_scatter_weights([0.0, 0.0], np.ones((2, 1)), np.ones(2), 0.5, 0.5)
    with pytest.raises(InvalidParameterError, match="mu"):
        single_scatter_weights([0.0, 1.0], np.ones((2, 1)), np.ones(2), 0.0, 0.5)
