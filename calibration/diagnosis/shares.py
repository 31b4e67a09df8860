"""How a held-out gap divides over slices of the data, and the RMS a slice of white noise
stays below: formulas on numbers alone (``docs/diagnosis.md``, "Where"), shared by the
diagnosis (:mod:`.core`) and the readers of earlier reports (:mod:`.legacy`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["partition_shares", "slice_limit"]


def slice_limit(floor: float, dof, margin: float) -> np.ndarray:
    """RMS white noise at ``floor`` stays below in 99 % of slices with ``dof`` degrees of
    freedom, times ``1 + margin`` (:mod:`.core` docstring, step 6)."""
    from scipy.stats import chi2
    dof = np.maximum(np.asarray(dof, float), 1.0)
    return floor * (1 + margin) * np.sqrt(chi2.ppf(0.99, dof) / dof)


def partition_shares(n, rms_, floor: float) -> np.ndarray:
    """Shares of the slices of one dimension (:mod:`.core` docstring, step 6).

    Parameters
    ----------
    n : array (s,)
        Values per slice.
    rms_ : array (s,)
        RMS per slice [unit of ``floor``].
    floor : float

    Returns
    -------
    ndarray (s,)
        ``max(ss - n f^2, 0) / sum(max(ss - n f^2, 0))`` with ``ss = n rms^2``, or
        ``ss / sum(ss)`` where no slice exceeds the floor; they add to 1.
    """
    n = np.asarray(n, float)
    ss = n * np.square(np.asarray(rms_, float))
    excess = np.maximum(ss - n * floor ** 2, 0.0)
    if excess.sum() > 0:
        return excess / excess.sum()
    return ss / max(float(ss.sum()), 1e-300)
