"""A partly cloudy sky: broken clouds (:mod:`skysim.cloud_field`) in front of any clear sky.

Along a view direction whose ray meets a cloud of vertical optical thickness ``tau`` at the
zenith-angle cosine ``mu`` (:func:`skysim.cloud_field.layer_intersection`), the Stokes vector
``S`` is the sum of three parts (each cloud column a plane-parallel layer of its own: the
independent pixel approximation, as :mod:`skysim.cloud_light`):

1. **The air below the cloud base** scatters the sunlight as in the clear sky: ``f_b S_clear``,
   with ``f_b`` its share of the ray's light (:func:`skysim.cloud_field.air_below`:
   ``1 - exp(-h / H)`` overhead, more towards the horizon, where the ray stays low) and
   ``S_clear`` the clear sky's own Stokes, so its E-vector
   continues the clear-sky pattern under the cloud (Pomozi, Horváth & Wehner 2001 [1]_; Pust
   & Shaw 2008 [2]_ saw this light set the AoP of most clouds). Where a cloud stands between
   that air and the sun the air is shaded: it is lit by the sunlight that cloud lets through,
   of which the part that still draws the sun's pattern is
   ``T_sun = pattern_transmission(tau_sun, mu0)`` (:func:`skysim.cloud_light.pattern_transmission`),
   ``tau_sun`` the cloud on the sun's line from the midpoint of the ray below the layer.
2. **The clear sky behind the cloud** (the air above it), ``(1 - f_b) S_clear``, of which
   ``T = pattern_transmission(tau, mu)`` comes through: a thin cloud lets the sky's pattern
   through, a thick one hides it.
3. **The cloud's own light**, the sunlight it transmits diffusely, bright and weakly
   polarized (:func:`skysim.cloud_light.cloud_stokes`: the droplets' single scattering,
   polarized by their phase matrix, plus unpolarized multiple scattering through their
   forward lobe and through the rest of their phase function), dimmed by the
   air below on its way, ``t_b = exp(-tau_R m_b)`` (:func:`skysim.cloud_field.air_below`):
   clouds near the horizon fade into the haze.

So ``S = S_clear (1 - f_b (1 - T_sun) - (1 - f_b)(1 - T)) + k t_b S_cloud``, where ``k`` turns
the cloud's light (in the unit of an incident solar flux ``pi``) into the clear sky's unit
(:meth:`skysim.sky.Sky.flux_pi_scale`). Clear directions have ``T = 1``; with no cloud
anywhere (cover 0 or ``tau`` 0) the factor is exactly 1 and the clear sky comes back
unchanged.

Left out: reflections between ground and cloud base, the air lit by the clouds' diffuse
light and the air above lit by their tops, the attenuation of the sunbeam by the air above
the cloud, the light of cloud sides (a thin layer has none), and the multiply scattered
light's weak polarization. Against the radiative transfer of an overcast layer
(:class:`skysim.clouds.CloudySky`, cloud optical thickness 1-20, suns 30 and 50 deg) the
median radiance agrees within 6 % and single directions within 0.65-1.42 times under
thin clouds (1-5), 0.82-1.18 at 10 and 0.91-1.01 at 20; the DoP within 0.02 RMS from
optical thickness 5-10 on, 0.04-0.05 RMS under thinner clouds (``docs/clouds.md``).

References
----------
.. [1] G. Pomozi, G. Horváth, R. Wehner, "How the clear-sky angle of polarization pattern
   continues underneath clouds: full-sky measurements and implications for animal
   orientation", J. Exp. Biol. 204:2933-2942 (2001).
.. [2] N. J. Pust, J. A. Shaw, "Digital all-sky polarization imaging of partly cloudy
   skies", Appl. Opt. 47(34):H190-H198 (2008), doi:10.1364/AO.47.00H190.
"""

from __future__ import annotations

import numpy as np

from . import rayleigh
from .cloud_field import CloudField, air_below, layer_intersection, time_offsets_s
from .cloud_light import cloud_stokes, pattern_transmission
from .exceptions import InvalidParameterError
from .sky import Sky, SkyField
from .validation import check_finite

__all__ = ["PartlyCloudySky"]


class PartlyCloudySky(Sky):
    """Broken clouds in front of a clear sky (see the module docstring).

    Parameters
    ----------
    clear : Sky
        The clear sky (any model that states its radiance unit through
        :meth:`~skysim.sky.Sky.flux_pi_scale`: rayleigh, multiple, aerosol, berry, moonlit).
    clouds : CloudField
        The cloud field (cover, thickness, scale, height, wind, seed).
    time_s : float or array-like
        Time since the cloud field's time 0 [s]: a scalar (one snapshot), or one value per sun
        position of the evaluations that follow (:meth:`at_times`).

    Notes
    -----
    The unit of ``I`` is the clear sky's. The sun must be above the horizon (the clouds are
    lit by the sunbeam).
    """

    name = "partly-cloudy"

    def __init__(self, clear: Sky, clouds: CloudField, time_s=0.0):
        if not isinstance(clear, Sky):
            raise InvalidParameterError(f"clear must be a Sky; got {clear!r}")
        if isinstance(clear, PartlyCloudySky):
            raise InvalidParameterError("clear must be a clear sky, not a PartlyCloudySky: "
                                        "give its .clear")
        if not isinstance(clouds, CloudField):
            raise InvalidParameterError(f"clouds must be a CloudField; got {clouds!r}")
        self.clear, self.clouds = clear, clouds
        self.time_s = check_finite("time_s", time_s)
        self.min_sun_elevation_deg = max(float(clear.min_sun_elevation_deg), 0.0)

    def at(self, time_s) -> "PartlyCloudySky":
        """The same clouds at another time [s] (scalar, or one per sun position)."""
        return PartlyCloudySky(self.clear, self.clouds, time_s)

    def at_times(self, times, epoch=None) -> "PartlyCloudySky":
        """The sky at sample ``times`` (timezone-aware), one per sun position of the
        evaluations that follow; the cloud field is as drawn at ``epoch`` (timezone-aware;
        default the first of ``times``).

        Raises
        ------
        NaiveDatetimeError
            If a time or the epoch has no timezone.
        """
        import pandas as pd

        from .sun import as_utc_index
        idx = as_utc_index(times)
        t0 = idx[0] if epoch is None else as_utc_index([epoch])[0]
        return self.at(np.asarray((idx - t0) / pd.Timedelta(seconds=1), dtype=float))

    def flux_pi_scale(self, view_elevation_deg, sun_elevation_deg) -> np.ndarray:
        return self.clear.flux_pi_scale(view_elevation_deg, sun_elevation_deg)

    def _make_field(self, vel, vaz, sel, saz) -> SkyField:
        clear = self.clear.field(vel, vaz, sel, saz)
        shape = np.shape(clear.I)
        t = time_offsets_s(self.time_s, np.shape(sel))
        vel, vaz, sel, saz, t = (np.broadcast_to(a, shape).ravel() for a in (
            vel, vaz, sel, saz, t))
        c = self.clouds
        x, y, mu = c.layer_points(vel, vaz, t)
        tau = c.optical_thickness_at(x, y)
        mu0 = np.sin(np.radians(sel))
        # the sun's line from the midpoint of the ray below the layer: half the view's layer
        # distance, then as far towards the sun as a layer at half the height
        s_view, _ = layer_intersection(vel, c.base_m)
        s_sun, _ = layer_intersection(sel, 0.5 * c.base_m)
        av, asun = np.radians(vaz), np.radians(saz)
        xs = 0.5 * s_view * np.sin(av) + s_sun * np.sin(asun) - c._wind[0] * t
        ys = 0.5 * s_view * np.cos(av) + s_sun * np.cos(asun) - c._wind[1] * t
        tau_sun = c.optical_thickness_at(xs, ys)
        fb, t_air = air_below(vel, c.base_m)
        keep = 1.0 - (fb * (1.0 - pattern_transmission(tau_sun, mu0))
                      + (1.0 - fb) * (1.0 - pattern_transmission(tau, mu)))
        I, Q, U = (np.asarray(a, float).ravel() * keep for a in (clear.I, clear.Q, clear.U))
        cloudy = tau > 0.0
        if cloudy.any():
            v, s, a, z = vel[cloudy], sel[cloudy], vaz[cloudy], saz[cloudy]
            pa, pb = rayleigh.meridian_components(v, a, s, z)
            ve, se = np.radians(v), np.radians(s)
            cos_scat = np.sin(ve) * np.sin(se) + np.cos(ve) * np.cos(se) * np.cos(
                np.radians(a - z))
            ic, qc, uc = cloud_stokes(tau[cloudy], mu[cloudy], mu0[cloudy], cos_scat, pa, pb)
            k = np.broadcast_to(self.clear.flux_pi_scale(v, s), ic.shape) * t_air[cloudy]
            I[cloudy] += k * ic
            Q[cloudy] += k * qc
            U[cloudy] += k * uc
        vel, vaz = (a.reshape(shape) for a in (vel, vaz))
        return SkyField(vel, vaz, I.reshape(shape), Q.reshape(shape), U.reshape(shape))

    def _stokes(self, vel, vaz, sel, saz):
        f = self._make_field(vel, vaz, sel, saz)
        return f.I, f.Q, f.U

    def describe(self) -> dict:
        t = self.time_s
        return {"model": self.name, "clear": self.clear.describe(),
                "clouds": self.clouds.describe(),
                "time_s": float(t) if t.ndim == 0 else "one per sun position",
                "air_below_cloud": "share of the ray's molecular scattering below the base",
                "cloud_light": "single scattering (Mie phase matrix) + unpolarized multiple "
                               "scattering: forward lobe (small-angle approximation) and "
                               "wide part (delta-scaled Eddington, source function)"}
