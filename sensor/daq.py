"""Data acquisition: quantisation and clipping of analog voltages.

The default matches the Advantech USB-4716 used by Yang et al. (2014): 16-bit converter on a
bipolar +/-10 V range, so one LSB is 20 V / 2^16 = 0.305 mV and the quantisation noise has a
standard deviation of LSB/sqrt(12) = 88 uV.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["Daq"]


@dataclass(frozen=True)
class Daq:
    """An ideal mid-tread ADC.

    Parameters
    ----------
    bits : int or None
        Resolution, 1..32; None disables quantisation (and clipping).
    range_V : float
        Full scale is [-range_V, +range_V) [V], > 0.

    Raises
    ------
    InvalidParameterError
        For bits that are not a whole number 1..32 (e.g. ``"sixteen"``) or a range that is
        not a positive number.
    """

    bits: int | None = 16
    range_V: float = 10.0

    def __post_init__(self):
        from skysim.exceptions import InvalidParameterError
        b = self.bits
        if b is not None and (isinstance(b, bool) or not isinstance(b, (int, np.integer))
                              or not 1 <= b <= 32):
            raise InvalidParameterError(f"DAQ bits must be a whole number 1..32 (or None for "
                                        f"no quantisation); got {b!r}")
        r = self.range_V
        if isinstance(r, bool) or not isinstance(r, (int, float, np.floating)) \
                or not np.isfinite(r) or r <= 0:
            raise InvalidParameterError(f"DAQ range_V must be a positive number of volts; "
                                        f"got {r!r}")

    @property
    def lsb_V(self) -> float:
        """Size of one code [V] (0 when quantisation is disabled)."""
        return 0.0 if self.bits is None else 2.0 * self.range_V / 2 ** self.bits

    def acquire(self, volts) -> tuple[np.ndarray, np.ndarray]:
        """Quantise and clip voltages [V]; return ``(codes_as_volts, saturated_mask)``."""
        v = np.asarray(volts, dtype=float)
        if self.bits is None:
            return v, np.zeros(v.shape, dtype=bool)
        lsb = self.lsb_V
        lo, hi = -self.range_V, self.range_V - lsb
        saturated = (v < lo) | (v > hi)
        return np.clip(np.round(v / lsb) * lsb, lo, hi), saturated

    def to_dict(self) -> dict:
        return asdict(self)
