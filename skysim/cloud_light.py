"""Sunlight through a water cloud: the cloud's own radiance and polarization, and how much of
the light behind it comes through.

A cloud column of vertical optical thickness ``tau`` (conservative scattering: the droplets'
single-scattering albedo at 550 nm is 1 - 5e-7) lit by the sun at ``mu0 = sin(elevation)``
is treated as a plane-parallel layer of its own (the independent pixel approximation of
Cahalan et al. [1]_). Below it, looking up at a zenith-angle cosine ``mu``, in the unit of
:mod:`skysim.multiple` (incident solar flux ``pi`` per unit area normal to the beam):

- **The forward lobe**: three quarters of what these droplets scatter stays within 27 deg
  of the forward direction, half within 6.7 deg (their diffraction peak: the extinction
  paradox, van de Hulst [3]_, sect. 8.22; tested). The phase function is split into that
  lobe, ``f = 0.64`` of the scattering (the diffraction peak, tapering off by 30 deg), and a
  wide part (:mod:`skysim.forward_lobe`).
- **Single scattering** by the droplets ([2]_, sect. 3), ``I_1 = P11(Theta) s``,
  ``(Q_1, U_1) = P12(Theta) s_p (cos 2chi, sin 2chi)``, ``Theta`` the scattering angle and
  ``chi`` the AoP of the direction perpendicular to the scattering plane. Through the wide
  part, the beam weakens only by what the wide part takes from it (the lobe's light keeps
  going with it, the delta-function scaling of Potter and of Joseph et al. [4]_):
  ``s = w h' / (4 (1 - f))`` (:func:`single_scatter_factor`),
  ``h' = mu0 (exp(-tau'/mu0) - exp(-tau'/mu)) / (mu0 - mu)``, ``tau' = (1 - f) tau``
  (:func:`skysim.rayleigh.slab_transmission`; ``tau P11 / (4 mu)`` for a thin cloud);
  through the lobe, by every scattering, ``s = w h(tau) / 4``; in between, weighted by the
  lobe's taper. The polarized part ``s_p`` counts, for the wide part, only the beam still
  within the diffraction peak (``f = 1/2`` in ``s``: light the lobe has turned by tens of
  degrees is scattered in planes spread around the sun, and its polarization cancels).
  ``P11`` and ``P12`` are the Mie phase matrix of the default droplets of
  :mod:`skysim.clouds` (:func:`droplet_phase`, a table built with sasktran2's Mie code and
  checked against miepython). ``P12 > 0`` polarizes perpendicular to the scattering plane,
  as the clear sky; at 20-70 deg from the sun ``P12 < 0``: the 90-deg turned AoP of some
  clouds seen by Pust & Shaw [5]_.
- **Multiple scattering through the lobe**, unpolarized: the small-angle approximation of
  Zege, Ivanov & Katsev [8]_ (:func:`skysim.forward_lobe.lobe_multiple_radiance`), the
  bright, wide aureole of a thin cloud.
- **Multiple scattering through the wide part**, unpolarized (:func:`diffuse_radiance`):
  the two-stream source-function method of Toon et al. [6]_ on the Eddington solution for
  conservative scattering, delta-scaled with the lobe as the peak ([4]_; its flux is
  eq. (24) of Meador & Weaver [7]_, :func:`two_stream_transmittance` for the
  delta-Eddington scaling).
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
import numpy as np

from .droplet_phase import DIFFRACTION_SHARE, PHASE_FILE, DropletPhase, droplet_phase
from .forward_lobe import forward_lobe, lobe_multiple_radiance
from .rayleigh import slab_transmission
from .slab_single_scatter import perpendicular_stokes
from .validation import check_in_range

__all__ = ["DIFFRACTION_SHARE", "PHASE_FILE", "DropletPhase", "cloud_stokes",
           "diffuse_radiance", "droplet_phase", "pattern_transmission",
           "single_scatter_factor", "two_stream_transmittance"]

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


def single_scatter_factor(tau, mu, mu0, share: float | None = None) -> np.ndarray:
    """``s = w h' / (4 (1 - f))`` (module docstring): the light the droplets' wide part
    scatters once out of a beam that keeps the share ``f`` of their scattering (default:
    the forward lobe's, :func:`skysim.forward_lobe.forward_lobe`) is ``P11 s``
    (broadcast)."""
    f = forward_lobe().share if share is None else float(share)
    w = droplet_phase().single_scattering_albedo
    return 0.25 * w / (1.0 - f) * slab_transmission((1.0 - f) * np.asarray(tau, float), mu,
                                                    mu0)


def diffuse_radiance(tau, mu, mu0) -> np.ndarray:
    """Multiply scattered radiance leaving the cloud base along ``mu`` [flux-``pi`` unit] of
    light scattered at least once through the droplets' wide part, unpolarized: the
    two-stream source-function method ([6]_) on the Eddington solution for conservative
    scattering, delta-scaled with the forward lobe as the peak (Potter 1970, Joseph et al.
    [4]_; :mod:`skysim.forward_lobe`).

    With ``tau' = (1 - f) tau`` and ``g'`` the wide part's asymmetry parameter
    (:func:`skysim.forward_lobe.forward_lobe`), ``a = 3 mu0 / 4`` (``F0 = pi``) the
    diffuse field is ``I(t, mu) = I0(t) + mu I1(t)`` with ``I1 = a e^(-t/mu0) + C1``,
    ``I0 = C0 + (1 - g') C1 t - a mu0 e^(-t/mu0)``; no diffuse light entering at the top and
    none coming up from a black ground (Marshak's conditions) give
    ``C1 = -a (mu0 (1 - e') + 2/3 (1 + e')) / (4/3 + (1 - g') tau')`` (``e' = e^(-tau'/mu0)``)
    and ``C0 = a mu0 + 2a/3 + 2 C1 / 3`` (with ``f = g^2``, ``g' = g / (1 + g)`` its flux is
    the delta-Eddington :func:`two_stream_transmittance`). The diffuse field scattered once
    more, the source ``I0(t) - g' mu I1(t)``, integrated along the ray to the base:

    ``I_m = (C0 - g' mu C1) E + (1 - g') C1 (tau' - mu E) - a (mu0 + g' mu) h'``,
    ``E = 1 - e^(-tau'/mu)``, ``h' = slab_transmission(tau', mu, mu0)``.

    Of second order in a thin cloud; in a thick one it tends to the Eddington law of
    darkening ``~ (2 + 3 mu)``. Broadcast; ``mu, mu0`` in (0, 1].
    """
    lobe = forward_lobe()
    tau, mu, mu0 = np.broadcast_arrays(*(np.asarray(x, float) for x in (tau, mu, mu0)))
    gp = lobe.wide_asymmetry
    ts = (1.0 - lobe.share) * tau
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
    lobe = forward_lobe().taper_at(theta)
    # once scattered: through the wide part out of the beam that keeps its lobe light, or
    # through the lobe out of the beam itself (every scattering removes from it)
    lobe_once = lobe * 0.25 * ph.single_scattering_albedo * slab_transmission(tau, mu, mu0)
    once = (1.0 - lobe) * single_scatter_factor(tau, mu, mu0) + lobe_once
    # polarized: only out of the beam still within its diffraction peak of the sun; light
    # turned by the lobe's wider angles comes from all around the sun, and its scattering
    # planes, hence its polarization, spread out
    polarized = (1.0 - lobe) * single_scatter_factor(tau, mu, mu0, DIFFRACTION_SHARE) + lobe_once
    return perpendicular_stokes(once * p11 + lobe_multiple_radiance(tau, mu0, theta)
                                + diffuse_radiance(tau, mu, mu0), polarized * p12, a, b)
