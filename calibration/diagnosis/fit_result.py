"""The result of a diagnosis fit (base model plus at most one effect), for every instrument."""

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
