"""Neutral points of the multiple-scattering sky: Arago, Babinet and Brewster.

In single Rayleigh scattering the degree of polarization vanishes only at the sun and the
anti-sun. Multiple scattering (and ground reflection) adds light polarized parallel to the
scattering plane, which cancels the Rayleigh polarization at points on the solar meridian
[1]_ [2]_:

- **Babinet**: above the sun,
- **Brewster**: below the sun (above the horizon only when the sun is high enough),
- **Arago**: above the anti-solar point (visible when the sun is low).

By the mirror symmetry of a plane-parallel sky about the solar meridian, ``U = 0`` there and
the polarization is ``Q`` alone (skysim basis: Q > 0 means E along the meridian, i.e. parallel
to the scattering plane, "negative" polarization). The neutral points are the zeros of
``Q`` on the two half-meridians, found with Brent's method on the Fourier-mode spline of
:mod:`skysim.multiple` (``Q(theta, 0) = Q_0 + Q_1 + Q_2`` towards the sun,
``Q(theta, 180) = Q_0 - Q_1 + Q_2`` away from it).

References
----------
.. [1] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak
   (1988), ch. 5 (neutral points).
.. [2] M. V. Berry, M. R. Dennis, R. L. Lee Jr, "Polarization singularities in the clear sky",
   New J. Phys. 6:162 (2004), doi:10.1088/1367-2630/6/1/162.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .exceptions import InvalidParameterError
from .validation import check_in_range

__all__ = ["NeutralPoints", "neutral_points", "neutral_points_from_modes"]


@dataclass(frozen=True)
class NeutralPoints:
    """Elevations [deg] of the three classical neutral points on the solar meridian.

    A point that lies below the horizon (not visible from the ground) is ``nan`` and its
    ``*_visible`` flag is False; distances are angular distances [deg] from the sun (Babinet,
    Brewster) or from the anti-solar point (Arago).
    """

    sun_elevation_deg: float
    tau: float
    albedo: float
    babinet_elevation_deg: float
    brewster_elevation_deg: float
    arago_elevation_deg: float

    @property
    def babinet_distance_deg(self) -> float:
        return self.babinet_elevation_deg - self.sun_elevation_deg

    @property
    def brewster_distance_deg(self) -> float:
        return self.sun_elevation_deg - self.brewster_elevation_deg

    @property
    def arago_distance_deg(self) -> float:
        return self.arago_elevation_deg + self.sun_elevation_deg

    @property
    def babinet_visible(self) -> bool:
        return bool(np.isfinite(self.babinet_elevation_deg))

    @property
    def brewster_visible(self) -> bool:
        return bool(np.isfinite(self.brewster_elevation_deg))

    @property
    def arago_visible(self) -> bool:
        return bool(np.isfinite(self.arago_elevation_deg))

    def to_dict(self) -> dict:
        d = asdict(self)
        d.update(babinet_distance_deg=self.babinet_distance_deg,
                 brewster_distance_deg=self.brewster_distance_deg,
                 arago_distance_deg=self.arago_distance_deg)
        return d

    def marks(self, sun_azimuth_deg: float) -> dict:
        """``{label: (elevation_deg, azimuth_deg)}`` of the visible points (for plots)."""
        out = {}
        anti = (sun_azimuth_deg + 180.0) % 360.0
        for label, el, az in [("Babinet", self.babinet_elevation_deg, sun_azimuth_deg),
                              ("Brewster", self.brewster_elevation_deg, sun_azimuth_deg),
                              ("Arago", self.arago_elevation_deg, anti)]:
            if np.isfinite(el):
                out[label] = (float(el), float(az))
        return out


def _zeros_on_half_meridian(modes, sign: float, step_deg: float = 0.05) -> np.ndarray:
    """Elevations [deg] where Q changes sign along phi = 0 (sign=+1) or 180 (sign=-1)."""
    from scipy.optimize import brentq

    def q(theta):
        c = modes._spline(np.atleast_1d(theta))
        return c[3] + sign * c[4] + c[5]

    theta = np.arange(0.0, 90.0 + step_deg / 2, step_deg)
    values = q(theta)
    idx = np.flatnonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)
    roots = [brentq(lambda t: float(q(t)[0]), theta[i], theta[i + 1], xtol=1e-6) for i in idx]
    return 90.0 - np.asarray(roots, dtype=float)


def neutral_points_from_modes(modes, sun_elevation_deg: float, tau: float = np.nan,
                              albedo: float = np.nan) -> NeutralPoints:
    """Locate the neutral points from cached :class:`skysim.multiple.FourierModes`."""
    sun = float(sun_elevation_deg)
    toward = _zeros_on_half_meridian(modes, +1.0)
    away = _zeros_on_half_meridian(modes, -1.0)
    above = toward[toward > sun]
    below = toward[toward < sun]
    # the zero nearest to the sun on each side; Arago: the lowest zero on the anti-solar side
    babinet = float(above.min()) if above.size else np.nan
    brewster = float(below.max()) if below.size else np.nan
    arago = float(away.min()) if away.size else np.nan
    return NeutralPoints(sun, float(tau), float(albedo), babinet, brewster, arago)


def neutral_points(sun_elevation_deg: float, tau: float, albedo: float = 0.0,
                   **sky_kwargs) -> NeutralPoints:
    """Arago, Babinet and Brewster points of the multiple-scattering sky.

    Parameters
    ----------
    sun_elevation_deg : float
        Sun elevation [deg] in (0, 89.5] (at the zenith the solar meridian is undefined).
    tau, albedo : float
        Rayleigh optical thickness and Lambertian ground albedo.
    **sky_kwargs
        Passed to :class:`skysim.multiple.MultipleScatteringSky` (e.g. ``n_zenith``).

    Returns
    -------
    NeutralPoints
        One engine call per (sun elevation, tau, albedo), cached.
    """
    from .multiple import MultipleScatteringSky

    sun = float(check_in_range("sun_elevation_deg", sun_elevation_deg, 0.0, 89.5,
                               low_open=True,
                               hint="the solar meridian is undefined with the sun at the zenith"))
    if not np.isfinite(tau):
        raise InvalidParameterError(f"tau must be finite; got {tau!r}")
    sky = MultipleScatteringSky(tau=tau, albedo=albedo, **sky_kwargs)
    return neutral_points_from_modes(sky.modes(sun), sun, sky.tau, sky.albedo)
