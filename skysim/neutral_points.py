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

**High sun.** Babinet and Brewster then lie a few degrees from the sun, near the zenith,
where the spline's nodes are ~6 deg apart; and Babinet passes the zenith once it is closer
to it than the sun is. For suns above :data:`DENSE_SCAN_ELEVATION_DEG` (or when the spline
finds no point beside the sun) the two are found on a dense engine scan of ``Q`` along the
solar vertical (:data:`DENSE_SCAN_STEP_DEG` steps, across the zenith; ``Q`` is continuous
there since the meridian basis turns by 180 deg), refined by Brent's method on a cubic
spline of the scan. Within ~6 deg of the zenith the two points merge with the sun (``Q`` keeps
its sign, with a DoLP minimum below the engine's accuracy, :data:`MERGED_DOP`, beside the sun):
both are then reported at that minimum. A Babinet point past the zenith is reported with an elevation above
90 deg (measured along the solar vertical through the zenith: ``180 - e`` above the
anti-solar horizon).

References
----------
.. [1] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak
   (1988), ch. 5 (neutral points).
.. [2] M. V. Berry, M. R. Dennis, R. L. Lee Jr, "Polarization singularities in the clear sky",
   New J. Phys. 6:162 (2004), doi:10.1088/1367-2630/6/1/162.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from .exceptions import InvalidParameterError
from .validation import check_in_range

__all__ = ["NeutralPoints", "neutral_points", "neutral_points_from_modes",
           "DENSE_SCAN_ELEVATION_DEG", "DENSE_SCAN_STEP_DEG", "MERGED_DOP"]

DENSE_SCAN_ELEVATION_DEG = 60.0
"""Sun elevation [deg] above which Babinet and Brewster come from the dense meridian scan."""
DENSE_SCAN_STEP_DEG = 0.25
"""Step [deg] of the dense scan along the solar vertical (+-30 deg around the sun)."""
MERGED_DOP = 1e-3
"""DoLP below which the near-sun minimum counts as a neutral point when ``Q`` has no sign
change beside the sun (the engine set-up is verified to ~1e-3 in DoLP): Babinet and Brewster
have then merged with the sun (sun within ~6 deg of the zenith) and are both reported at
that minimum."""


@dataclass(frozen=True)
class NeutralPoints:
    """Elevations [deg] of the three classical neutral points on the solar meridian.

    A point that lies below the horizon (not visible from the ground) is ``nan`` and its
    ``*_visible`` flag is False; a Babinet elevation above 90 deg lies past the zenith on the
    solar vertical (module docstring); distances are angular distances [deg] from the sun (Babinet,
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
                out[label] = ((float(el), float(az)) if el <= 90.0
                              else (float(180.0 - el), float(anti)))
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


def _dense_near_sun(sky, sun_elevation_deg: float) -> tuple[float, float]:
    """Babinet and Brewster elevations [deg] from a dense engine scan of Q along the solar
    vertical (module docstring, "High sun")."""
    from scipy.interpolate import CubicSpline
    from scipy.optimize import brentq

    from .rt_sasktran import MU_MAX, MU_MIN, transmitted_stokes
    theta_sun = 90.0 - float(sun_elevation_deg)
    # signed zenith angle x along the vertical: x > 0 towards the sun, x < 0 beyond the zenith
    x = np.arange(theta_sun - 30.0, min(theta_sun + 30.0, 90.0) + 1e-9, DENSE_SCAN_STEP_DEG)
    mu = np.clip(np.cos(np.radians(np.abs(x))), MU_MIN, MU_MAX)
    x = np.sign(x) * np.degrees(np.arccos(mu))          # the angles the engine traces
    phi = np.where(x >= 0.0, 0.0, 180.0)
    I, Q, _ = transmitted_stokes(sky.tau, sky.albedo, float(np.sin(np.radians(sun_elevation_deg))),
                                 mu, phi, depolarization_ratio=sky.depolarization_ratio,
                                 settings=sky.settings)
    x, keep = np.unique(x, return_index=True)
    q = CubicSpline(x, Q[keep])
    idx = np.flatnonzero(np.sign(Q[keep][:-1]) * np.sign(Q[keep][1:]) < 0)
    roots = np.array([brentq(q, x[i], x[i + 1], xtol=1e-6) for i in idx])
    above, below = roots[roots < theta_sun], roots[roots > theta_sun]
    if not (above.size and below.size):
        # no sign change beside the sun: the two points have merged with the sun to within
        # the engine's verified DoLP accuracy; report both at the DoP minimum near the sun
        dop = np.abs(Q[keep]) / I[keep]
        near = np.abs(x - theta_sun) <= 10.0
        k = np.flatnonzero(near)[np.argmin(dop[near])]
        if dop[k] <= MERGED_DOP:
            return 90.0 - float(x[k]), 90.0 - float(x[k])
    babinet = 90.0 - float(above.max()) if above.size else np.nan
    brewster = 90.0 - float(below.min()) if below.size else np.nan
    return babinet, (brewster if brewster >= 0.0 else np.nan)


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
        Above :data:`DENSE_SCAN_ELEVATION_DEG` one more engine call (the dense scan).
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
    n = neutral_points_from_modes(sky.modes(sun), sun, sky.tau, sky.albedo)
    if sun > DENSE_SCAN_ELEVATION_DEG or not (n.babinet_visible and n.brewster_visible):
        babinet, brewster = _dense_near_sun(sky, sun)
        n = replace(n, babinet_elevation_deg=babinet, brewster_elevation_deg=brewster)
    return n
