"""Reference formulas written out as printed, shared by the tests and the benchmarks."""

import numpy as np

from sensor.opponent import CHANNEL_ANGLES_DEG, GAIN


def pair_by_cramer(U, pair, gain=GAIN):
    """Eqs. (5)-(9) of Yang et al. 2014 for one pair, as printed: invert both channels
    (p = tanh(U ln10 / 2g)), Cramer's rule for C = d cos 2phi and S = d sin 2phi, then
    phi = atan2(S, C) / 2 wrapped to [-90, 90) and d = hypot(C, S)."""
    i, j = pair[0] - 1, pair[1] - 1
    p_i = np.tanh(U[..., i] * np.log(10.0) / (2.0 * gain))
    p_j = np.tanh(U[..., j] * np.log(10.0) / (2.0 * gain))
    ai, aj = np.radians(2.0 * CHANNEL_ANGLES_DEG[[i, j]])
    det = np.sin(ai - aj)
    c = (p_j * np.sin(ai) - p_i * np.sin(aj)) / det
    s = (p_j * np.cos(ai) - p_i * np.cos(aj)) / det
    phi = np.mod(0.5 * np.degrees(np.arctan2(s, c)) + 90.0, 180.0) - 90.0
    return phi, np.hypot(c, s)
