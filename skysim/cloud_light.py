"""Sunlight through a water cloud: the cloud's own radiance and polarization, and how much of
the light behind it comes through.

A cloud column of vertical optical thickness ``tau`` (conservative scattering: the droplets'
single-scattering albedo at 550 nm is 1 - 5e-7) lit by the sun at ``mu0 = sin(elevation)``
is treated as a plane-parallel layer of its own (the independent pixel approximation of
Cahalan et al. [1]_). Below it, looking up at a zenith-angle cosine ``mu``, in the unit of
:mod:`skysim.multiple` (incident solar flux ``pi`` per unit area normal to the beam):

- **Single scattering** by the droplets ([2]_, sect. 3). A droplet much larger than the
  wavelength (size parameter 114 here) puts half of the light it scatters into its narrow
  diffraction lobe (the extinction paradox, van de Hulst [3]_, sect. 8.22; in the droplets'
  phase function half of the scattering lies within 6.7 deg of the forward direction,
  tested). Light scattered into the lobe keeps going with the beam, so the beam weakens as
  ``exp(-tau'/mu0)``, ``tau' = (1 - f) tau``, ``f = 1/2`` (:data:`DIFFRACTION_SHARE`; the
  scaling of Joseph et al. [4]_ with the lobe as the truncated part), and
  ``I_1 = P11(Theta) s``, ``(Q_1, U_1) = P12(Theta) s (cos 2chi, sin 2chi)`` with
  ``s = w h' / (4 (1 - f))`` (:func:`single_scatter_factor`),
  ``h' = mu0 (exp(-tau'/mu0) - exp(-tau'/mu)) / (mu0 - mu)``
  (:func:`skysim.rayleigh.slab_transmission`; ``tau P11 / (4 mu)`` for a thin cloud),
  ``Theta`` the scattering angle and ``chi`` the AoP of the direction perpendicular to the
  scattering plane. ``P11`` and ``P12`` are the Mie phase matrix of the default droplets of
  :mod:`skysim.clouds` (:func:`droplet_phase`, a table built with sasktran2's Mie code and
  checked against miepython). ``P12 > 0`` polarizes perpendicular to the scattering plane,
  as the clear sky; at 20-70 deg from the sun ``P12 < 0``: the 90-deg turned AoP of some
  clouds seen by Pust & Shaw [5]_. This part holds the cloud's aureole and its polarization.
- **Multiple scattering**, unpolarized (:func:`diffuse_radiance`): the two-stream
  source-function method of Toon et al. [6]_ on the delta-Eddington solution for
  conservative scattering (Joseph et al. [4]_; its flux is eq. (24) of Meador & Weaver [7]_,
  :func:`two_stream_transmittance`).
- **Light behind the cloud** (the sky above it, or the sunbeam for the air below it) comes
  through as a pattern: in the small-angle approximation of multiple forward scattering a
  cloud of slant optical thickness ``tau / mu`` multiplies the ``l``-th angular harmonic of
  the radiance passing through by ``exp(-(1 - chi_l) tau / mu)`` (Zege, Ivanov & Katsev
  [8]_, ch. 2), ``chi_l`` the phase function's Legendre moments. The Rayleigh polarization
  pattern of the sky, and the pattern a sunbeam imprints on the air it lights, are of degree
  ``l = 2``: :func:`pattern_transmission`, ``chi_2 = 0.794`` for these droplets.

Checked against the radiative transfer of :class:`skysim.clouds.CloudySky` under overcast
(``tests/test_partly_cloudy.py``; ``docs/clouds.md`` gives the numbers).

References
----------
.. [1] R. F. Cahalan, W. Ridgway, W. J. Wiscombe, T. L. Bell, J. B. Snider, "The albedo of
   fractal stratocumulus clouds", J. Atmos. Sci. 51:2434-2455 (1994),
   doi:10.1175/1520-0469(1994)051<2434:TAOFSC>2.0.CO;2.
.. [2] J. E. Hansen, L. D. Travis, "Light scattering in planetary atmospheres", Space Sci.
   Rev. 16:527-610 (1974), doi:10.1007/BF00168069.
.. [3] H. C. van de Hulst, *Light Scattering by Small Particles*, Wiley (1957; Dover 1981),
   sect. 8.22 (the extinction paradox: diffraction takes half of the extinction).
.. [4] J. H. Joseph, W. J. Wiscombe, J. A. Weinman, "The delta-Eddington approximation for
   radiative flux transfer", J. Atmos. Sci. 33:2452-2459 (1976),
   doi:10.1175/1520-0469(1976)033<2452:TDEAFR>2.0.CO;2.
.. [5] N. J. Pust, J. A. Shaw, "Digital all-sky polarization imaging of partly cloudy
   skies", Appl. Opt. 47(34):H190-H198 (2008), doi:10.1364/AO.47.00H190.
.. [6] O. B. Toon, C. P. McKay, T. P. Ackerman, K. Santhanam, "Rapid calculation of radiative
   heating rates and photodissociation rates in inhomogeneous multiple scattering
   atmospheres", J. Geophys. Res. 94(D13):16287-16301 (1989), doi:10.1029/JD094iD13p16287.
.. [7] W. E. Meador, W. R. Weaver, "Two-stream approximations to radiative transfer in
   planetary atmospheres: a unified description of existing methods and a new improvement",
   J. Atmos. Sci. 37:630-643 (1980), doi:10.1175/1520-0469(1980)037<0630:TSATRT>2.0.CO;2.
.. [8] E. P. Zege, A. P. Ivanov, I. L. Katsev, *Image Transfer Through a Scattering Medium*,
   Springer (1991), ch. 2 (small-angle approximation: transfer of the angular harmonics).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .rayleigh import slab_transmission
from .slab_single_scatter import perpendicular_stokes
from .validation import check_in_range

__all__ = ["DIFFRACTION_SHARE", "PHASE_FILE", "DropletPhase", "cloud_stokes",
           "diffuse_radiance", "droplet_phase", "pattern_transmission",
           "single_scatter_factor", "two_stream_transmittance"]

PHASE_FILE = Path(__file__).with_name("data") / "water_cloud_phase_550nm.csv"
"""The droplets' phase matrix (builder ``skysim/data/build_water_cloud_phase.py``)."""

DIFFRACTION_SHARE = 0.5
"""Share ``f`` of the droplets' scattering in their diffraction lobe (van de Hulst [3]_,
sect. 8.22), which keeps going with the beam (module docstring)."""


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


@functools.lru_cache(maxsize=1)
def _pattern_extinction() -> float:
    return 1.0 - droplet_phase().legendre_moment(2)


def pattern_transmission(tau, mu) -> np.ndarray:
    """Share of a degree-2 angular pattern (a polarization pattern) that passes a cloud of
    vertical optical thickness ``tau`` along ``mu``: ``exp(-(1 - chi_2) tau / mu)`` (module
    docstring, [8]_). Broadcast; ``mu > 0``."""
    return np.exp(-_pattern_extinction() * np.asarray(tau, float) / np.asarray(mu, float))


def two_stream_transmittance(tau, mu0, g: float | None = None) -> np.ndarray:
    """Total (direct + diffuse) transmittance [1] of a conservative layer over a black
    surface, delta-Eddington two-stream ([7]_ eq. (24), [4]_).

    ``T = 1 - (G tau' + (c3 - G mu0)(1 - exp(-tau'/mu0))) / (1 + G tau')`` with
    ``G = 3 (1 - g') / 4``, ``c3 = (2 - 3 g' mu0) / 4``, ``tau' = (1 - g^2) tau``,
    ``g' = g / (1 + g)``; ``g`` defaults to the droplets' asymmetry parameter.
    """
    g = droplet_phase().asymmetry_parameter if g is None else float(g)
    tau, mu0 = (np.asarray(a, float) for a in (tau, mu0))
    gp = g / (1.0 + g)
    ts = (1.0 - g * g) * tau
    g1 = 0.75 * (1.0 - gp)
    g3 = 0.25 * (2.0 - 3.0 * gp * mu0)
    r = (g1 * ts + (g3 - g1 * mu0) * -np.expm1(-ts / mu0)) / (1.0 + g1 * ts)
    return 1.0 - r


def single_scatter_factor(tau, mu, mu0) -> np.ndarray:
    """``s = w h' / (4 (1 - f))`` (module docstring): the droplets' singly scattered light is
    ``I_1 = P11 s`` and polarized ``P12 s`` perpendicular to the scattering plane
    (broadcast)."""
    f = DIFFRACTION_SHARE
    w = droplet_phase().single_scattering_albedo
    return 0.25 * w / (1.0 - f) * slab_transmission((1.0 - f) * np.asarray(tau, float), mu,
                                                    mu0)


def diffuse_radiance(tau, mu, mu0) -> np.ndarray:
    """Multiply scattered radiance leaving the cloud base along ``mu`` [flux-``pi`` unit],
    unpolarized: the two-stream source-function method ([6]_) on the delta-Eddington
    solution for conservative scattering ([4]_).

    With ``tau' = (1 - g^2) tau``, ``g' = g / (1 + g)``, ``a = 3 mu0 / 4`` (``F0 = pi``) the
    diffuse field is ``I(t, mu) = I0(t) + mu I1(t)`` with ``I1 = a e^(-t/mu0) + C1``,
    ``I0 = C0 + (1 - g') C1 t - a mu0 e^(-t/mu0)``; no diffuse light entering at the top and
    none coming up from a black ground (Marshak's conditions) give
    ``C1 = -a (mu0 (1 - e') + 2/3 (1 + e')) / (4/3 + (1 - g') tau')`` (``e' = e^(-tau'/mu0)``)
    and ``C0 = a mu0 + 2a/3 + 2 C1 / 3`` (its transmitted flux is
    :func:`two_stream_transmittance`, tested). The diffuse field scattered once more, the
    source ``I0(t) - g' mu I1(t)``, integrated along the ray to the base:

    ``I_m = (C0 - g' mu C1) E + (1 - g') C1 (tau' - mu E) - a (mu0 + g' mu) h'``,
    ``E = 1 - e^(-tau'/mu)``, ``h' = slab_transmission(tau', mu, mu0)``.

    Of second order in a thin cloud; in a thick one it tends to the Eddington law of
    darkening ``~ (2 + 3 mu)``. Broadcast; ``mu, mu0`` in (0, 1].
    """
    g = droplet_phase().asymmetry_parameter
    tau, mu, mu0 = np.broadcast_arrays(*(np.asarray(x, float) for x in (tau, mu, mu0)))
    gp = g / (1.0 + g)
    ts = (1.0 - g * g) * tau
    a = 0.75 * mu0
    e = np.exp(-ts / mu0)
    c1 = -a * (mu0 * (1.0 - e) + 2.0 / 3.0 * (1.0 + e)) / (4.0 / 3.0 + (1.0 - gp) * ts)
    c0 = a * mu0 + 2.0 * a / 3.0 + 2.0 * c1 / 3.0
    big_e = -np.expm1(-ts / mu)
    return ((c0 - gp * mu * c1) * big_e + (1.0 - gp) * c1 * (ts - mu * big_e)
            - a * (mu0 + gp * mu) * slab_transmission(ts, mu, mu0))


def cloud_stokes(tau, mu, mu0, cos_scattering, a, b):
    """The cloud's own light ``(I, Q, U)`` in the unit of an incident solar flux ``pi``, in
    the local-meridian basis (module docstring).

    Parameters
    ----------
    tau : array-like
        Vertical optical thickness of the cloud column [1], >= 0.
    mu : array-like
        Cosine of the view's zenith angle at the cloud, in (0, 1].
    mu0 : array-like
        Sine of the sun's elevation, in (0, 1].
    cos_scattering : array-like
        Cosine of the scattering angle (view direction . sun direction).
    a, b : array-like
        Components of the E-vector perpendicular to the scattering plane on the local
        meridian basis (:func:`skysim.rayleigh.meridian_components`: ``a^2 + b^2 =
        sin^2 Theta``).
    """
    tau = check_in_range("cloud tau", tau, 0.0, np.inf)
    ph = droplet_phase()
    theta = np.degrees(np.arccos(np.clip(cos_scattering, -1.0, 1.0)))
    p11 = np.interp(theta, ph.angle_deg, ph.p11)
    p12 = np.interp(theta, ph.angle_deg, ph.p12)
    s = single_scatter_factor(tau, mu, mu0)
    return perpendicular_stokes(s * p11 + diffuse_radiance(tau, mu, mu0), s * p12, a, b)
