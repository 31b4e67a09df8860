"""Light scattered again and again through the cloud droplets' forward lobe: the small-angle
approximation, and the split of the phase function that it needs.

Three quarters of what a 10-um droplet scatters stays within 27 deg of the forward direction
(half within 6.7 deg, its diffraction peak: van de Hulst 1957 [1]_, sect. 8.22). Light that
is scattered several times through this lobe keeps going roughly with the sunbeam and
spreads around the sun by tens of degrees; a two-stream (delta-Eddington) treatment counts
it as unscattered and shows it nowhere. Here the phase function is split,
``P = f P_F + (1 - f) P_W``, into a forward lobe ``f P_F = s(Theta) P`` and a wide part,
with the taper ``s = 1`` out to the angle holding :data:`skysim.droplet_phase.DIFFRACTION_SHARE`
of the scattering (the diffraction peak), ``cos^2`` down to 0 at :data:`LOBE_EDGE_DEG` (the
small-angle approximation's ``sin Theta ~ Theta`` holds there within 5 %).

- **The lobe** in the small-angle approximation (Zege, Ivanov & Katsev 1991 [2]_, ch. 2;
  the same transfer of angular harmonics as :func:`skysim.cloud_light.pattern_transmission`):
  the sunbeam after a slant lobe optical thickness ``x = f tau / mu0`` carries, at an angle
  ``Theta`` from the sun, the radiance (incident flux ``pi``)
  ``L = (1/4) sum_l (2l + 1) P_l(cos Theta) [exp(-x (1 - chi_l)) - exp(-x) (1 + x chi_l)]``
  of the light scattered two or more times through the lobe (``chi_l`` the lobe's Legendre
  moments), dimmed by the wide part, ``exp(-(1 - f) tau / mu0)``: :func:`lobe_multiple_radiance`.
- **The wide part** scatters the beam (lobe-scattered light included: a delta-function
  scaling with the lobe as its forward peak, Potter 1970 [3]_, Joseph et al. 1976 [4]_),
  with the scaled optical thickness ``(1 - f) tau`` and asymmetry parameter ``g_W = (g - f
  g_F) / (1 - f)``.

References
----------
.. [1] H. C. van de Hulst, *Light Scattering by Small Particles*, Wiley (1957; Dover 1981),
   sect. 8.22.
.. [2] E. P. Zege, A. P. Ivanov, I. L. Katsev, *Image Transfer Through a Scattering Medium*,
   Springer (1991), ch. 2 (small-angle approximation: transfer of the angular harmonics).
.. [3] J. F. Potter, "The delta function approximation in radiative transfer theory",
   J. Atmos. Sci. 27:943-949 (1970).
.. [4] J. H. Joseph, W. J. Wiscombe, J. A. Weinman, "The delta-Eddington approximation for
   radiative flux transfer", J. Atmos. Sci. 33:2452-2459 (1976),
   doi:10.1175/1520-0469(1976)033<2452:TDEAFR>2.0.CO;2.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .droplet_phase import DIFFRACTION_SHARE, droplet_phase

__all__ = ["LOBE_EDGE_DEG", "ForwardLobe", "forward_lobe", "lobe_multiple_radiance"]

LOBE_EDGE_DEG = 30.0
"""Outer edge of the forward lobe [deg]: ``sin Theta / Theta >= 0.95`` out to it, the
small-angle approximation's own condition."""

N_MOMENTS = 1000
"""Legendre moments of the lobe kept (its diffraction peak is about 0.5 deg wide)."""

_X_GRID = np.geomspace(1e-3, 1e3, 121)   # slant lobe optical thickness of the table


@dataclass(frozen=True)
class ForwardLobe:
    """The droplets' phase function split into a forward lobe and a wide part.

    Attributes
    ----------
    angle_deg : ndarray
        Scattering angles [deg] of the phase table (every 0.1 deg).
    taper : ndarray
        ``s(Theta)``, the lobe's share of the phase function at each angle.
    share : float
        ``f``, the lobe's share of the scattering.
    wide_asymmetry : float
        ``g_W``, the asymmetry parameter of the wide part.
    table : ndarray (n_angles, n_x)
        ``L / (1 - exp(-x) (1 + x))`` (module docstring, without the dimming by the wide
        part) at :data:`_X_GRID`: the shape of the multiply lobe-scattered light.
    """

    angle_deg: np.ndarray
    taper: np.ndarray
    share: float
    wide_asymmetry: float
    table: np.ndarray

    def taper_at(self, scattering_angle_deg) -> np.ndarray:
        """``s`` at the given scattering angles [deg]."""
        return np.interp(scattering_angle_deg, self.angle_deg, self.taper)


def _second_and_higher(x):
    """``1 - exp(-x) (1 + x)``: the share of a beam scattered at least twice (Poisson)."""
    return -np.expm1(-x) - x * np.exp(-x)


@functools.lru_cache(maxsize=1)
def forward_lobe() -> ForwardLobe:
    """The split of :func:`skysim.droplet_phase.droplet_phase` (cached; about 0.5 s)."""
    ph = droplet_phase()
    a = ph.angle_deg
    t = np.radians(a)
    w = ph.p11 * np.sin(t) * np.gradient(t)                 # scattering per angle bin
    inner = float(np.interp(DIFFRACTION_SHARE, np.cumsum(w) / np.sum(w), a))
    taper = np.where(a <= inner, 1.0, np.where(
        a >= LOBE_EDGE_DEG, 0.0,
        np.cos(0.5 * np.pi * (a - inner) / (LOBE_EDGE_DEG - inner)) ** 2))
    lobe = w * taper
    share = float(np.sum(lobe) / np.sum(w))
    legendre = np.polynomial.legendre.legvander(np.cos(t), N_MOMENTS)   # (angles, l)
    chi = lobe @ legendre / np.sum(lobe)
    g_lobe = float(chi[1])
    g_wide = (ph.asymmetry_parameter - share * g_lobe) / (1.0 - share)
    x = _X_GRID[None, :]
    terms = np.exp(-x * (1.0 - chi[:, None])) - np.exp(-x) * (1.0 + x * chi[:, None])
    l = np.arange(N_MOMENTS + 1)
    # Lanczos sigma factors damp the truncated series' ringing (Gibbs) far from the sun,
    # at the cost of smoothing over about 180 / N_MOMENTS deg; what rings below zero is 0
    sigma = np.sinc(l / (N_MOMENTS + 1.0))
    table = np.maximum(legendre @ (((2.0 * l + 1.0) * sigma)[:, None] * terms), 0.0)
    table /= _second_and_higher(x)
    return ForwardLobe(a, taper, share, float(g_wide), table)


def lobe_multiple_radiance(tau, mu0, scattering_angle_deg) -> np.ndarray:
    """Radiance [flux-``pi`` unit] of sunlight scattered two or more times through the
    droplets' forward lobe, below a cloud of vertical optical thickness ``tau`` lit at
    ``mu0``, at ``scattering_angle_deg`` [deg] from the sun (module docstring; unpolarized;
    bilinear in the angle and the logarithm of the slant lobe optical thickness on the
    precomputed table). Broadcast; ``mu0`` in (0, 1]."""
    lobe = forward_lobe()
    tau, mu0, theta = np.broadcast_arrays(*(np.asarray(v, float) for v in (
        tau, mu0, scattering_angle_deg)))
    x = lobe.share * tau / mu0
    step = lobe.angle_deg[1] - lobe.angle_deg[0]
    fi = np.clip(theta / step, 0.0, lobe.angle_deg.size - 1.000001)
    i = fi.astype(int)
    u = fi - i
    lx = np.log(_X_GRID)
    fj = np.clip((np.log(np.maximum(x, _X_GRID[0])) - lx[0]) / (lx[1] - lx[0]), 0.0,
                 lx.size - 1.000001)
    j = fj.astype(int)
    v = fj - j
    T = lobe.table
    shape = ((1 - u) * (1 - v) * T[i, j] + u * (1 - v) * T[i + 1, j]
             + (1 - u) * v * T[i, j + 1] + u * v * T[i + 1, j + 1])
    with np.errstate(under="ignore"):
        dim = np.exp(-(1.0 - lobe.share) * tau / mu0)
    return 0.25 * dim * _second_and_higher(x) * shape
