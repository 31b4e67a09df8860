"""Injected error parameters of the three-pair polarization-opponent sensor.

Symbols follow Yang et al. (2014) [1]_, eqs. (2)-(3): channel ``i`` (1..3) has two
photodiodes behind polarizers nominally at ``a_i`` and ``a_i + 90`` deg; their mounting
errors are ``dtheta_{2i-1}`` and ``dtheta_{2i}``; ``f_i`` is the channel's transmittance
term, ``f_i = log10(t_{2i-1} / t_{2i})`` for photodiode-path transmittances ``t``; ``v_i`` is
the channel's additive output noise.

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from skysim.exceptions import InvalidParameterError
from skysim.validation import check_finite, check_in_range

__all__ = ["OpponentErrors"]


def _vec(name: str, values, n: int) -> tuple[float, ...]:
    arr = np.broadcast_to(check_finite(name, values), (n,))
    return tuple(float(x) for x in arr)


@dataclass(frozen=True)
class OpponentErrors:
    """Error parameters of one three-pair sensor (all zero: the ideal sensor).

    Parameters
    ----------
    misalignment_deg : 6 floats
        ``dtheta_1 .. dtheta_6`` [deg]: polarizer mounting errors, ordered as the paper
        (``dtheta_1, dtheta_2`` belong to channel U1, ...).
    transmittance : 3 floats
        ``f_1 .. f_3`` [log10 units]: transmittance imbalance of each channel's two paths.
    noise_V : float or 3 floats
        Standard deviation of the additive output noise ``v_i`` of each channel [V].
    turntable_error_deg : float
        Standard deviation of the turntable (heading reference) reading error [deg].
    """

    misalignment_deg: tuple = field(default=(0.0,) * 6)
    transmittance: tuple = field(default=(0.0,) * 3)
    noise_V: tuple = field(default=(0.0,) * 3)
    turntable_error_deg: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "misalignment_deg",
                           _vec("misalignment_deg", self.misalignment_deg, 6))
        object.__setattr__(self, "transmittance", _vec("transmittance", self.transmittance, 3))
        noise = _vec("noise_V", self.noise_V, 3)
        check_in_range("noise_V", noise, 0.0, np.inf)
        object.__setattr__(self, "noise_V", noise)
        check_in_range("turntable_error_deg", self.turntable_error_deg, 0.0, np.inf)

    @classmethod
    def draw(cls, rng: np.random.Generator, *, misalignment_max_deg: float,
             transmittance_sd: float, noise_range_V: tuple[float, float],
             turntable_error_deg: float = 0.0) -> "OpponentErrors":
        """Draw one sensor's errors.

        Misalignments ~ U(-max, max); each photodiode path transmittance ``t ~ N(1, sd)`` and
        ``f_i = log10(t_{2i-1}/t_{2i})``; each channel's noise level ~ U(noise_range_V).
        """
        mis = rng.uniform(-misalignment_max_deg, misalignment_max_deg, 6)
        t = 1.0 + transmittance_sd * rng.standard_normal(6)
        f = np.log10(t[0::2] / t[1::2])
        noise = rng.uniform(noise_range_V[0], noise_range_V[1], 3)
        return cls(tuple(mis), tuple(f), tuple(noise), turntable_error_deg)

    def to_dict(self) -> dict:
        return {"misalignment_deg": list(self.misalignment_deg),
                "transmittance": list(self.transmittance), "noise_V": list(self.noise_V),
                "turntable_error_deg": self.turntable_error_deg}

    @classmethod
    def from_dict(cls, d: dict, where: str = "sensor errors") -> "OpponentErrors":
        """Errors from a dict as written by :meth:`to_dict` (``turntable_error_deg`` optional).

        Raises
        ------
        InvalidParameterError
            If ``d`` is not a dict, misses a key, has an unknown key, or a value has the wrong
            length or is not a number (the message starts with ``where``).
        """
        required = ("misalignment_deg", "transmittance", "noise_V")
        sizes = {"misalignment_deg": 6, "transmittance": 3, "noise_V": 3}
        if not isinstance(d, dict):
            raise InvalidParameterError(f"{where}: expected a JSON object with keys "
                                        f"{', '.join(required)}; got a {type(d).__name__}")
        missing = [k for k in required if k not in d]
        unknown = sorted(set(d) - set(required) - {"turntable_error_deg"})
        if missing or unknown:
            what = "; ".join(x for x in (f"missing key(s) {missing}" if missing else "",
                                         f"unknown key(s) {unknown}" if unknown else "") if x)
            raise InvalidParameterError(f"{where}: {what}; valid: {', '.join(required)}, "
                                        "turntable_error_deg")
        for k, n in sizes.items():
            v = d[k]
            ok = (isinstance(v, (int, float)) and not isinstance(v, bool) and k == "noise_V") \
                or (isinstance(v, list) and len(v) == n and all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) for x in v))
            if not ok:
                raise InvalidParameterError(f"{where}: {k} must be a list of {n} numbers"
                                            f"{' (or one number)' if k == 'noise_V' else ''}; "
                                            f"got {v!r}")
        t = d.get("turntable_error_deg", 0.0)
        if not isinstance(t, (int, float)) or isinstance(t, bool):
            raise InvalidParameterError(f"{where}: turntable_error_deg must be a number; "
                                        f"got {t!r}")
        return cls(tuple(d["misalignment_deg"]), tuple(d["transmittance"]),
                   d["noise_V"] if isinstance(d["noise_V"], (int, float)) else tuple(d["noise_V"]),
                   float(t))
