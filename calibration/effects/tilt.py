"""Sensor not level: an installation tilt that turns with the turntable.

A sensor tilted by ``beta`` towards the direction ``gamma`` of its own frame (0 = along its
reference axis ``x``, 90 = along ``y``, ``x`` turned 90 deg clockwise seen from above) looks at
the sky point ``z_s = cos(beta) z + sin(beta) (cos(gamma) x + sin(gamma) y)`` instead of the
zenith; as the turntable turns, that point circles the zenith. The sensor frame is the level
frame rotated by ``beta`` about ``n = z x t`` (``t`` the horizontal tilt direction, Rodrigues'
formula), so ``x_s = R x``, ``y_s = R y``. The light from ``z_s`` has the sky model's E-vector
``E`` (perpendicular to ``z_s``, so it lies in the sensor's polarizer plane) and DoP; its angle
in the sensor frame ``alpha = atan2(E . y_s, E . x_s)`` gives ``phi = wrap(-alpha - 90)``, the
definition that for a level sensor reduces to ``wrap(heading - E azimuth - 90)``
(``docs/conventions.md``). Parameters are the tilt components ``(beta cos gamma, beta sin
gamma)`` [deg], smooth through zero tilt (the base model).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from skysim.geometry import elevation_azimuth, wrap_axial_deg
from skysim.sky import RayleighSky

from . import Effect, unit_vector_frame

__all__ = ["EFFECT", "Tilt", "tilted_frame", "tilted_polarization"]

_SHAPE_SKY = RayleighSky(dmax=1.0)


def tilted_frame(heading_deg, tilt_x_deg: float, tilt_y_deg: float):
    """Sensor axes ``(x_s, y_s, z_s)`` in ENU, each (n, 3), for a tilt in the sensor frame."""
    x, y, z = unit_vector_frame(heading_deg)
    beta = np.radians(np.hypot(tilt_x_deg, tilt_y_deg))
    if beta == 0.0:
        return x, y, z
    gamma = np.arctan2(tilt_y_deg, tilt_x_deg)
    t = np.cos(gamma) * x + np.sin(gamma) * y
    n = np.cross(z, t)
    c, s = np.cos(beta), np.sin(beta)

    def rot(v):
        return v * c + np.cross(n, v) * s + n * np.sum(n * v, axis=-1, keepdims=True) * (1 - c)

    return rot(x), rot(y), rot(z)


def tilted_polarization(heading_deg, sun_el_deg, sun_az_deg, tilt_x_deg, tilt_y_deg,
                        sky=_SHAPE_SKY):
    """``(phi_deg, dop)`` seen by a tilted zenith sensor (module docstring)."""
    xs, ys, zs = tilted_frame(heading_deg, tilt_x_deg, tilt_y_deg)
    el, az = elevation_azimuth(zs)
    # a fit may probe times past sunset (clock terms); evaluate the sky at the horizon there
    fld = sky.field(np.minimum(el, 90.0), az, np.maximum(sun_el_deg, 1e-6), sun_az_deg)
    e = fld.e_vector
    alpha = np.degrees(np.arctan2(np.sum(e * ys, axis=-1), np.sum(e * xs, axis=-1)))
    return wrap_axial_deg(-alpha - 90.0), fld.dop


class Tilt(Effect):
    """Tilt components [deg] along the sensor's reference axis and across it."""

    name = "tilt"
    parameter_names = ("tilt_x_deg", "tilt_y_deg")
    units = ("deg", "deg")
    bounds = np.tile([-10.0, 10.0], (2, 1))
    prior_mean = np.zeros(2)
    prior_sd = np.full(2, 3.0)
    fd_step = np.full(2, 1e-3)
    stage = "geometry"
    null = np.zeros(2)
    generation_range: ClassVar[dict] = {"beta_deg": "U(0.3, 3)", "gamma_deg": "U(0, 360)"}

    def starts(self):
        return [np.array([0.3, 0.0]), np.array([0.0, 0.3])]

    def draw(self, rng):
        beta, gamma = rng.uniform(0.3, 3.0), rng.uniform(0.0, 2 * np.pi)
        return np.array([beta * np.cos(gamma), beta * np.sin(gamma)])

    def polarization(self, ctx, p, heading_deg, sun_el_deg, sun_az_deg):
        return tilted_polarization(heading_deg, sun_el_deg, sun_az_deg, float(p[0]), float(p[1]))


EFFECT = Tilt()
