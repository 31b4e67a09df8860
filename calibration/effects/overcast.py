"""Overcast: a uniform cloud layer over the whole sky, seen by a zenith-pointing sensor.

The base model takes the zenith light as single-scattered skylight: E-vector perpendicular to
the solar meridian, DoP ``d_max sin^2 g / (1 + cos^2 g)`` (``g`` the solar zenith angle). Under
a cloud layer of optical thickness ``tau`` (550 nm) the zenith light is the sky of
:class:`skysim.partly_cloudy.PartlyCloudySky` at cover 1 (:mod:`skysim.cloud_light`, checked
against the radiative transfer of an overcast layer in ``docs/clouds.md``): the clear sky's
light scattered below the cloud and passed through it, attenuated, keeps its E-vector
(Pomozi, Horváth & Wehner 2001 [1]_), and the droplets add their own light, bright and weakly
polarized by their phase matrix. At the zenith, which lies in the solar meridian, every part
is polarized either perpendicular or parallel to the meridian (no ``U`` in the meridian frame,
by symmetry); the droplets' single scattering at scattering angles near 90-150 deg is polarized
parallel to it, so a thin cloud under a high sun can turn the zenith E-vector by 90 deg (the
cloudy-compass reproduction shows the same turn in the radiative transfer). The effect returns
``phi`` turned by 90 deg where the zenith's net polarization is parallel to the meridian, and
the DoP shape ``|Q| / I`` in the meridian frame.

Limits: the output stage's DoP scale ``s`` multiplies this shape, so it scales the cloud's own
polarization with the clear sky's (on the ring, whose diagnosis can apply it to the clear sky
alone, the two are kept apart); a sun below 0.5 deg elevation gives the clear shape (the cloud
is lit by the sunbeam only, and the base model's twilight sky holds there).

References
----------
.. [1] G. Pomozi, G. Horváth, R. Wehner, "How the clear-sky angle of polarization pattern
   continues underneath clouds", J. Exp. Biol. 204:2933-2942 (2001).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from skysim.geometry import wrap_axial_deg

from . import Effect, zenith_rayleigh

__all__ = ["EFFECT", "Overcast", "zenith_signed_dop"]

MIN_SUN_ELEVATION_DEG = 0.5
"""Below this sun elevation [deg] the zenith keeps the clear sky's light (module doc)."""


def zenith_signed_dop(tau: float, sun_elevation_deg) -> np.ndarray:
    """Zenith DoP [1] under a uniform overcast of optical thickness ``tau``, signed: positive
    when the E-vector is perpendicular to the solar meridian (as in the clear sky), negative
    when parallel. ``tau = 0`` gives the single-scattering shape ``sin^2 g / (1 + cos^2 g)``.
    Suns below :data:`MIN_SUN_ELEVATION_DEG` give the clear shape."""
    from skysim.cloud_field import CloudField
    from skysim.partly_cloudy import PartlyCloudySky
    from skysim.sky import RayleighSky
    el = np.asarray(sun_elevation_deg, float)
    flat = el.ravel()
    # the base model's own zenith shape where there is no cloud light
    out = zenith_rayleigh(np.zeros_like(flat), flat, np.zeros_like(flat))[1].astype(float)
    lit = flat >= MIN_SUN_ELEVATION_DEG
    if tau == 0.0 or not lit.any():
        return out.reshape(el.shape)
    clear = RayleighSky(1.0)
    s, n = flat[lit], int(lit.sum())
    sky = PartlyCloudySky(clear, CloudField(1.0, float(tau), 0, n_modes=16))
    f = sky.field(np.full(n, 90.0), np.zeros(n), s, np.zeros(n))
    ref = clear.field(np.full(n, 90.0), np.zeros(n), s, np.zeros(n))
    x = np.radians(2.0 * ref.aop_deg)
    out[lit] = (f.Q * np.cos(x) + f.U * np.sin(x)) / f.I
    return out.reshape(el.shape)


class Overcast(Effect):
    """Optical thickness ``cloud_tau`` of a uniform cloud layer over the zenith sensor."""

    name = "overcast"
    parameter_names = ("cloud_tau",)
    units = ("1",)
    bounds = np.array([[0.0, 10.0]])
    prior_mean = np.array([1.0])
    prior_sd = np.array([5.0])
    fd_step = np.array([1e-3])
    stage = "geometry"
    null = np.array([0.0])
    generation_range: ClassVar[dict] = {
        "cloud_tau": "U(0.3, 3) (thin to moderate layer cloud: cirrostratus to thin stratus)"}

    def starts(self):
        return [np.array([t]) for t in (0.3, 1.0, 3.0)]

    def draw(self, rng):
        return np.array([rng.uniform(0.3, 3.0)])

    def polarization(self, ctx, p, heading_deg, sun_el_deg, sun_az_deg):
        tau = float(self.clip(p)[0])
        d = zenith_signed_dop(tau, sun_el_deg)
        phi = wrap_axial_deg(np.asarray(heading_deg) - sun_az_deg + np.where(d < 0, 90.0, 0.0))
        return phi, np.abs(d)


EFFECT = Overcast()
