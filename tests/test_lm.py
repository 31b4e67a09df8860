"""The prior-weighted Levenberg-Marquardt core reaches the maximum a-posteriori solution.

- A linear model with a Gaussian prior has the exact MAP solution
  ``(X^T X / s^2 + P)^-1 (X^T y / s^2 + P mu)`` and posterior covariance
  ``(X^T X / s^2 + P)^-1`` (``P = diag(1 / sd^2)``); the fit reaches both, with either
  damping schedule and a dense or sparse Jacobian, and its profiled covariance is the free
  block of the joint inverse.
- A box bound that cuts off the unconstrained optimum of a linear model: the optimum is on
  the bound, the other parameters at their MAP with it fixed there (closed form).
- A nonlinear (exponential decay) fit agrees with :func:`scipy.optimize.least_squares` on the
  same objective, the prior entered as extra residuals.
- A trial the model rejects (``InvalidParameterError``) is retried with more damping.
"""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import least_squares

from calibration.diagnosis.lm import MARQUARDT, TRUST_REGION, levenberg_marquardt
from skysim.exceptions import InvalidParameterError

SIGMA = 0.1
RESOLUTION = 1e-6
"""Where the fit can stop, in posterior SDs from the optimum: ``d`` SDs off raise the cost by
``d^2``, which a cost of 20-40 resolves in double precision (1.1e-16 relative) only for ``d``
above ``sqrt(40 * 1.1e-16) ~ 7e-8``; the fit stops where a step lowers the cost by less than
that. 1e-6 leaves a margin of ten over it."""


def _linear(seed=0, m=40, p=4):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(m, p))
    truth = rng.normal(size=p)
    y = X @ truth + 0.7 * SIGMA * rng.normal(size=m)   # noise below SIGMA
    mu = np.zeros(p)
    sd = np.r_[0.5, 2.0, np.inf, 1.0][:p]
    return X, y, mu, sd


def _linear_fns(X, y, sparse=False):
    def residual(t):
        return X @ t - y, None

    def jacobian(t, r, state, columns):
        J = X[:, columns]
        return sp.csc_matrix(J) if sparse else J
    return residual, jacobian


def _map(X, y, mu, sd, sigma=SIGMA):
    P = np.diag(np.where(np.isfinite(sd), 1.0 / sd ** 2, 0.0))
    A = X.T @ X / sigma ** 2 + P
    return np.linalg.solve(A, X.T @ y / sigma ** 2 + P @ mu), np.linalg.inv(A)


@pytest.mark.parametrize("damping", [MARQUARDT, TRUST_REGION], ids=["marquardt", "trust"])
@pytest.mark.parametrize("sparse", [False, True], ids=["dense", "sparse"])
def test_linear_map_and_covariance(damping, sparse):
    X, y, mu, sd = _linear()
    residual, jacobian = _linear_fns(X, y, sparse)
    fit = levenberg_marquardt(residual, jacobian, np.full(4, 3.0), mu, sd, sigma=SIGMA,
                              tol=1e-15, damping=damping, covariance=True)
    want, cov = _map(X, y, mu, sd)
    assert fit.converged
    se = np.sqrt(np.diag(cov))
    np.testing.assert_allclose((fit.theta - want) / se, 0.0, atol=RESOLUTION)
    r = X @ want - y
    dof = X.shape[0] - X.shape[1]
    assert np.sum(r ** 2) / SIGMA ** 2 / dof < 1.0   # noise below SIGMA: no widening
    np.testing.assert_allclose(fit.covariance, cov, rtol=1e-9)
    prior = np.where(np.isfinite(sd), ((want - mu) / sd) ** 2, 0.0).sum()
    assert fit.cost == pytest.approx(np.sum(r ** 2) / SIGMA ** 2 + prior, rel=1e-12)
    assert fit.rms == pytest.approx(np.sqrt(np.mean(r ** 2)), rel=1e-9)


def test_covariance_widened_by_excess_residuals():
    """With residuals ten times ``sigma``, the covariance is the information's inverse
    times the reduced chi-square (``max(1, chi2 / dof)``)."""
    X, y, mu, sd = _linear(seed=1)
    sigma = SIGMA / 10.0
    residual, jacobian = _linear_fns(X, y)
    fit = levenberg_marquardt(residual, jacobian, np.zeros(4), mu, sd, sigma=sigma, tol=1e-15,
                              covariance=True)
    want, cov = _map(X, y, mu, sd, sigma)
    chi2 = np.sum((X @ want - y) ** 2) / sigma ** 2 / (X.shape[0] - X.shape[1])
    assert chi2 > 20.0
    np.testing.assert_allclose(fit.covariance, cov * chi2, rtol=1e-9)


def test_held_and_profiled_parameters():
    """A held parameter stays at its start and takes no prior; the profiled covariance is the
    free parameters' block of the joint information's inverse."""
    X, y, mu, sd = _linear(seed=2)
    residual, jacobian = _linear_fns(X, y)
    free = np.array([True, True, False, True])
    start = np.array([0.0, 0.0, 0.7, 0.0])
    fit = levenberg_marquardt(residual, jacobian, start, mu, sd, free=free, sigma=SIGMA,
                              tol=1e-15, covariance=True, profiled=~free)
    f = np.flatnonzero(free)
    # the free parameters' MAP with the held one fixed: a linear model in the other three
    want, cond = _map(X[:, f], y - X[:, 2] * 0.7, mu[f], sd[f])
    assert fit.theta[2] == 0.7
    np.testing.assert_allclose((fit.theta[f] - want) / np.sqrt(np.diag(cond)), 0.0,
                               atol=RESOLUTION)
    P = np.diag(np.where(np.isfinite(sd), 1.0 / sd ** 2, 0.0))
    joint = np.linalg.inv(X.T @ X / SIGMA ** 2 + P)
    # widened by the reduced chi-square of the fit (the held value is not the best one)
    chi2 = np.sum((X @ fit.theta - y) ** 2) / SIGMA ** 2 / (X.shape[0] - f.size)
    np.testing.assert_allclose(fit.covariance, joint[np.ix_(f, f)] * max(chi2, 1.0),
                               rtol=1e-9)
    # profiling widens: the held parameter (no prior) trades with the free ones
    assert np.all(np.diag(fit.covariance) > np.diag(cond))


def test_bound_cutting_off_the_optimum():
    """The unconstrained optimum of parameter 0 is above its upper bound: the fit ends on the
    bound, the others at their MAP given it there."""
    X, y, mu, sd = _linear(seed=3)
    unbounded, _ = _map(X, y, mu, sd)
    upper = np.full(4, np.inf)
    upper[0] = unbounded[0] - 0.3
    residual, jacobian = _linear_fns(X, y)
    fit = levenberg_marquardt(residual, jacobian, np.zeros(4), mu, sd, upper=upper,
                              sigma=SIGMA, tol=1e-15)
    rest, cond = _map(X[:, 1:], y - X[:, 0] * upper[0], mu[1:], sd[1:])
    assert fit.converged
    assert fit.theta[0] == upper[0]
    np.testing.assert_allclose((fit.theta[1:] - rest) / np.sqrt(np.diag(cond)), 0.0,
                               atol=RESOLUTION)


def _decay():
    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 5.0, 60)
    y = 2.0 * np.exp(-0.8 * t) + 0.3 + SIGMA * rng.normal(size=t.size)
    mu = np.array([1.0, 1.0, 0.0])
    sd = np.array([1.0, 0.5, np.inf])

    def model(th):
        return th[0] * np.exp(-th[1] * t) + th[2]

    def jac(th):
        e = np.exp(-th[1] * t)
        return np.column_stack([e, -th[0] * t * e, np.ones_like(t)])
    return t, y, mu, sd, model, jac


@pytest.mark.parametrize("damping", [MARQUARDT, TRUST_REGION], ids=["marquardt", "trust"])
def test_exponential_against_scipy(damping):
    t, y, mu, sd, model, jac = _decay()
    fit = levenberg_marquardt(lambda th: (model(th) - y, None),
                              lambda th, r, s, c: jac(th)[:, c], np.array([1.0, 2.0, 0.0]),
                              mu, sd, sigma=SIGMA, tol=1e-15, damping=damping,
                              covariance=True)
    w = np.isfinite(sd)

    def stacked(th):
        return np.r_[(model(th) - y) / SIGMA, (th[w] - mu[w]) / sd[w]]

    ref = least_squares(stacked, np.array([1.0, 2.0, 0.0]), method="lm", xtol=1e-15,
                        ftol=1e-15, gtol=1e-15)
    assert fit.converged and ref.success
    # both minimise the same objective to where its decrease is below 1e-15 of it; the
    # parameters are then within ~sqrt(1e-15 * cost) / curvature of the optimum, 1e-6 of the
    # posterior SD at most: 1e-6 bounds the difference of two such solutions
    se = np.sqrt(np.diag(fit.covariance))
    np.testing.assert_allclose((fit.theta - ref.x) / se, 0.0, atol=1e-6)
    assert fit.cost == pytest.approx(2.0 * ref.cost, rel=1e-12)
    # covariance: the Gauss-Newton inverse of the stacked Jacobian, widened by the reduced
    # chi-square; the two Jacobians (analytic here, differences in scipy's "lm") differ by
    # scipy's difference error, ~sqrt(1.1e-16) = 1e-8 relative (3.6e-8 measured): 1e-6
    Js = ref.jac
    chi2 = np.sum((model(ref.x) - y) ** 2) / SIGMA ** 2 / (t.size - 3)
    np.testing.assert_allclose(fit.covariance, np.linalg.inv(Js.T @ Js) * max(chi2, 1.0),
                               rtol=1e-6)


def test_rejected_trial_is_damped():
    """The model rejects parameters above 3; the undamped step from 0.5 lands at 4.25, so
    the fit must retry with more damping to reach the root 2."""
    def residual(th):
        if th[0] > 3.0:
            raise InvalidParameterError(f"theta {th[0]} above 3")
        return np.array([th[0] ** 2 - 4.0]), None

    fit = levenberg_marquardt(residual, lambda th, r, s, c: np.array([[2.0 * th[0]]]),
                              np.array([0.5]), np.zeros(1), np.array([np.inf]), tol=1e-15)
    assert fit.converged
    assert fit.theta[0] == pytest.approx(2.0, rel=1e-12)


def test_iteration_limit_and_start_cost():
    t, y, mu, sd, model, jac = _decay()
    fns = (lambda th: (model(th) - y, None), lambda th, r, s, c: jac(th)[:, c])
    start = np.array([1.0, 2.0, 0.0])
    zero = levenberg_marquardt(*fns, start, mu, sd, sigma=SIGMA, max_iter=0)
    r = model(start) - y
    assert zero.n_iter == 0 and not zero.converged
    assert zero.cost == pytest.approx(np.sum(r ** 2) / SIGMA ** 2
                                      + np.sum(((start - mu)[:2] / sd[:2]) ** 2), rel=1e-12)
    one = levenberg_marquardt(*fns, start, mu, sd, sigma=SIGMA, max_iter=1)
    assert one.n_iter == 1 and not one.converged and one.cost < zero.cost


@pytest.mark.parametrize("kwargs,message", [
    ({"prior_sd": [1.0, 0.0, 1.0, 1.0]}, "prior_sd 0.0 of parameter 1"),
    ({"prior_mean": [0.0, 0.0]}, "prior_mean has 2 values for 4 parameters"),
    ({"lower": [0.0, 2.0, 0.0, 0.0], "upper": [1.0, 1.0, 1.0, 1.0]},
     "upper bound 1.0 of parameter 1 is below its lower bound 2.0"),
    ({"sigma": -0.1}, "sigma -0.1"),
])
def test_bad_input_named(kwargs, message):
    X, y, mu, sd = _linear()
    args = {"prior_mean": mu, "prior_sd": sd, **kwargs}
    residual, jacobian = _linear_fns(X, y)
    with pytest.raises(InvalidParameterError, match=message):
        levenberg_marquardt(residual, jacobian, np.zeros(4), **args)
