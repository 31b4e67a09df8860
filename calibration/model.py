"""Analytic derivatives of the opponent-channel equation used by the estimators.

For ``U = g (log10(1 + d cos 2x1) - log10(1 - d cos 2x2) + f)`` with
``x1 = phi + a + e1`` and ``x2 = phi + a + e2`` (eq. 2 of Yang et al. 2014), the partial
derivatives (eq. 12 of the paper, per degree for the angles) are::

    dU/de1  = -(g / ln10) 2 d sin 2x1 / (1 + d cos 2x1) * pi/180
    dU/de2  = -(g / ln10) 2 d sin 2x2 / (1 - d cos 2x2) * pi/180
    dU/dphi = dU/de1 + dU/de2
    dU/dd   =  (g / ln10) (cos 2x1 / (1 + d cos 2x1) + cos 2x2 / (1 - d cos 2x2))
    dU/df   =  g
"""

from __future__ import annotations

import numpy as np

from sensor.opponent import opponent_output

__all__ = ["channel_jacobian"]

_DEG = np.pi / 180.0


def channel_jacobian(phi_deg, dop, angle_deg, e1_deg, e2_deg, f, gain,
                     wrt=("phi", "dop", "e1", "e2", "f")):
    """Channel output [V] and the requested partial derivatives (broadcast arrays).

    Returns
    -------
    value : ndarray
    jac : dict name -> ndarray (angles per degree, ``dop`` per unit DoP, ``f`` per unit)
    """
    value = opponent_output(phi_deg, dop, angle_deg, e1_deg, e2_deg, f, gain)
    x1 = np.radians(2.0 * (phi_deg + angle_deg + e1_deg))
    x2 = np.radians(2.0 * (phi_deg + angle_deg + e2_deg))
    c1, s1, c2, s2 = np.cos(x1), np.sin(x1), np.cos(x2), np.sin(x2)
    k = gain / np.log(10.0)
    n1 = 1.0 + dop * c1
    n2 = 1.0 - dop * c2
    jac = {}
    de1 = -k * 2.0 * dop * s1 / n1 * _DEG
    de2 = -k * 2.0 * dop * s2 / n2 * _DEG
    if "e1" in wrt:
        jac["e1"] = de1
    if "e2" in wrt:
        jac["e2"] = de2
    if "phi" in wrt:
        jac["phi"] = de1 + de2
    if "dop" in wrt:
        jac["dop"] = k * (c1 / n1 + c2 / n2)
    if "f" in wrt:
        jac["f"] = np.broadcast_to(gain, np.shape(value))
    return value, jac
