"""The result of a diagnosis fit (base model plus at most one effect), for every instrument.

References
----------
.. [1] G. A. F. Seber, C. J. Wild, *Nonlinear Regression*, Wiley (1989), sect. 2.1.2
   (asymptotic covariance of the least-squares estimate, ``s^2 (J^T J)^-1`` with
   ``s^2 = S(theta) / (n - p)``).
.. [2] H. White, "A heteroskedasticity-consistent covariance matrix estimator and a direct
   test for heteroskedasticity", Econometrica 48(4):817-838 (1980), doi:10.2307/1912934.
.. [3] K.-Y. Liang, S. L. Zeger, "Longitudinal data analysis using generalized linear
   models", Biometrika 73(1):13-22 (1986), doi:10.1093/biomet/73.1.13 (the cluster form).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FitResult"]


@dataclass
class FitResult:
    """A least-squares (MAP) fit: parameters, cost, convergence and covariance.

    Attributes
    ----------
    theta : ndarray (p,)
        All fitted parameters (base model, then the effect's, in the instrument's layout).
    cost : float
        Final cost (sum of squared weighted residuals and prior terms).
    rms : float or None
        RMS of the data residuals at the solution [unit of the data].
    n_iter : int
        Iterations taken.
    converged : bool
        False when the iteration limit was reached (the caller reports it).
    covariance : ndarray or None
        Posterior covariance of the free parameters (of all of ``theta`` when ``free`` is
        None), scaled by the reduced chi-square where it exceeds 1.
    free : ndarray (p,) bool or None
        Parameters that were fitted (None: all).
    effect : slice or None
        Where the effect's parameters sit in ``theta`` (None: a base-model fit).
    """

    theta: np.ndarray
    cost: float
    rms: float | None
    n_iter: int
    converged: bool
    covariance: np.ndarray | None = None
    free: np.ndarray | None = None
    effect: slice | None = None

    @classmethod
    def from_least_squares(cls, result, n_independent: int, effect: slice | None = None,
                           group_size: int | None = None) -> FitResult:
        """A fit of :func:`scipy.optimize.least_squares` (unweighted residuals) with its
        covariance from the Jacobian ``J`` at the optimum.

        Without ``group_size``: the Gauss-Newton covariance ``s^2 (J^T J)^+``, ``s^2 =
        sum(r^2) / (n_independent - p)`` the residual variance ([1]_ sect. 2.1.2). With it:
        the sandwich ``(J^T J)^+ (sum_g J_g^T r_g r_g^T J_g) (J^T J)^+ n / (n - p)`` over groups
        of ``group_size`` consecutive residuals ([2]_ eq. (3), in the cluster form of [3]_),
        which holds when the noise variance differs between groups (shot noise of brighter
        and darker pixels) and residuals within a group are correlated.

        Parameters
        ----------
        result : scipy.optimize.OptimizeResult
            With ``x``, ``fun``, ``jac``, ``cost``, ``nfev`` and ``success``.
        n_independent : int
            Independent residual values ``n``: ``len(result.fun)`` unless the residuals obey
            linear constraints (channels normalised by their mean sum to zero: one fewer per
            group).
        effect : slice, optional
            Where the effect's parameters sit in ``x``.
        group_size : int, optional
            Residuals per group (``len(result.fun)`` a multiple of it).
        """
        x = np.asarray(result.x, float)
        r = np.asarray(result.fun, float)
        J = np.asarray(result.jac, float)
        n = max(int(n_independent) - x.size, 1)
        s2 = float(r @ r) / n
        A = np.linalg.pinv(J.T @ J)
        if group_size is None:
            cov = A * s2
        else:
            g = (J * r[:, None]).reshape(-1, int(group_size), x.size).sum(axis=1)
            cov = A @ (g.T @ g) @ A * (int(n_independent) / n)
        return cls(x.copy(), float(result.cost), float(np.sqrt(s2)), int(result.nfev),
                   bool(result.success), cov, None, effect)

    def sd(self, index: int) -> float | None:
        """Posterior standard deviation of parameter ``index`` (None without a covariance or
        for a parameter held fixed)."""
        if self.covariance is None or (self.free is not None and not self.free[index]):
            return None
        pos = index if self.free is None else int(np.sum(self.free[:index]))
        return float(np.sqrt(max(self.covariance[pos, pos], 0.0)))

    @property
    def params(self) -> np.ndarray:
        """The effect's parameters (empty for a base-model fit)."""
        return self.theta[self.effect] if self.effect is not None else np.zeros(0)

    @property
    def base(self) -> np.ndarray:
        """The base model's parameters (those before the effect's)."""
        return self.theta[:self.effect.start] if self.effect is not None else self.theta

    def parameters(self, index: slice, names, units=None) -> dict:
        """``name -> {"value", "se", "unit"}`` of the parameters at ``index`` of ``theta``."""
        idx = range(*index.indices(self.theta.size))
        units = units if units is not None else [None] * len(idx)
        out = {}
        for i, n, u in zip(idx, names, units):
            sd = self.sd(i)
            out[n] = {"value": float(self.theta[i]), "se": float("nan") if sd is None else sd}
            if u is not None:
                out[n]["unit"] = u
        return out
