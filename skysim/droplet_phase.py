"""The phase matrix of the cloud droplets at 550 nm, and the share of their scattering in the
diffraction peak: what the cloud's own light (:mod:`skysim.cloud_light`) and the forward lobe
split from it (:mod:`skysim.forward_lobe`) are built on.

References
----------
.. [1] H. C. van de Hulst, *Light Scattering by Small Particles*, Wiley (1957), sect. 8.22
   (diffraction carries half the extinction of a large sphere).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["DIFFRACTION_SHARE", "PHASE_FILE", "DropletPhase", "droplet_phase"]

PHASE_FILE = Path(__file__).with_name("data") / "water_cloud_phase_550nm.csv"
"""The droplets' phase matrix (builder ``skysim/data/build_water_cloud_phase.py``)."""

DIFFRACTION_SHARE = 0.5
"""Share of the droplets' scattering in their diffraction peak (van de Hulst [1]_,
sect. 8.22): the forward lobe is whole out to the angle that holds it
(:mod:`skysim.forward_lobe`), and the beam that carries the single scatter's polarization
keeps it (:mod:`skysim.cloud_light`)."""


@dataclass(frozen=True)
class DropletPhase:
    """Phase matrix of the cloud droplets at 550 nm.

    Attributes
    ----------
    angle_deg, p11, p12 : ndarray
        Scattering angles [deg] (every 0.1 deg), ``p11`` (mean 1 over the sphere) and ``p12``
        (positive: polarized perpendicular to the scattering plane).
    single_scattering_albedo, asymmetry_parameter : float
    """

    angle_deg: np.ndarray
    p11: np.ndarray
    p12: np.ndarray
    single_scattering_albedo: float
    asymmetry_parameter: float

    def legendre_moment(self, degree: int) -> float:
        """``chi_l = <P_l(cos Theta)>`` over the phase function (``chi_1 = g``)."""
        from scipy.special import eval_legendre
        t = np.radians(self.angle_deg)
        w = self.p11 * np.sin(t)
        return float(np.trapezoid(w * eval_legendre(int(degree), np.cos(t)), t)
                     / np.trapezoid(w, t))


@functools.lru_cache(maxsize=1)
def droplet_phase() -> DropletPhase:
    """The phase matrix of the default water cloud (:data:`PHASE_FILE`; effective radius
    10 um, effective variance 0.1, 550 nm, as :class:`skysim.clouds.CloudLayer`)."""
    lines = PHASE_FILE.read_text().splitlines()
    meta = {k.strip("# "): float(v) for k, v in (ln.split("=") for ln in lines
                                                  if ln.startswith("#") and "=" in ln)}
    rows = [ln for ln in lines if ln and not ln.startswith("#")][1:]   # after the header
    a, p11, p12 = np.array([r.split(",") for r in rows], dtype=float).T
    return DropletPhase(a, p11, p12, meta["single_scattering_albedo"],
                        meta["asymmetry_parameter"])
