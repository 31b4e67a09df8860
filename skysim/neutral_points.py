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

**High sun.** Babinet and Brewster then lie a few degrees from the sun, near the zenith;
and Babinet passes the zenith once it is closer to it than the sun is. For suns above
:data:`DENSE_SCAN_ELEVATION_DEG` (or when the scan of the half meridians finds no point
beside the sun) the two are found on a dense scan of ``Q`` along the whole solar vertical
(:data:`DENSE_SCAN_STEP_DEG` steps, across the zenith; ``Q`` is continuous there since the
meridian basis turns by 180 deg), refined by Brent's method, on the same mode spline: the
engine's own rays within 11.5 deg of the zenith are wrong (its multiple-scatter source is
interpolated linearly in the view cosine there,
:data:`skysim.rt_sasktran.SOURCE_GRID_MU_STEP`), the spline is not
(:func:`skysim.multiple.mode_nodes_deg`). A Babinet point past the zenith is reported with
an elevation above 90 deg (measured along the solar vertical through the zenith:
``180 - e`` above the anti-solar horizon).

As the sun nears the zenith the two close in on it along the vertical (with the sun at the
zenith the sky is symmetric about it and they merge into it): tau 0.25, sun at 80, 86 and
89 deg: Babinet 2.9, 1.2 and 0.3 deg from the sun, Brewster 3.5, 1.4 and 0.3 deg. (The
engine's own rays, wrong within 11.5 deg of the zenith, make ``Q`` keep its sign along the
vertical above a sun at about 81.5 deg, as if the pair had left it.) Should the scan find
neither point, the pair is looked for off the vertical, as a mirror pair on either side
(both index +1/2, so the total index +1 about the sun is kept; Berry et al. [2]_ describe
such off-meridian pairs): the zero of ``(Q, U)`` of the mode spline beside the sun
(:func:`_off_meridian_pair`), reported with both elevations equal and the relative azimuth
``near_sun_azimuth_offset_deg`` (the pair at +-offset from the sun's azimuth).

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

from .validation import check_finite, check_in_range

__all__ = ["NeutralPoints", "neutral_points", "neutral_points_from_modes",
           "DENSE_SCAN_ELEVATION_DEG", "DENSE_SCAN_STEP_DEG", "NEUTRAL_DOP"]

DENSE_SCAN_ELEVATION_DEG = 60.0
"""Sun elevation [deg] above which Babinet and Brewster come from the dense meridian scan."""
DENSE_SCAN_STEP_DEG = 0.25
"""Step [deg] of the dense scan along the solar vertical (+-30 deg around the sun)."""
NEUTRAL_DOP = 1e-4
"""Largest DoLP accepted at an off-meridian zero of ``(Q, U)`` (the refined zero of the
spline; where the minimum stays above it, no pair is reported)."""


@dataclass(frozen=True)
class NeutralPoints:
    """Elevations [deg] of the three classical neutral points on the solar meridian.

    A point that lies below the horizon (not visible from the ground) is ``nan`` and its
    ``*_visible`` flag is False; a Babinet elevation above 90 deg lies past the zenith on the
    solar vertical (module docstring); distances are angular distances [deg] from the sun
    (Babinet, Brewster; signed along the vertical, great-circle for an off-meridian pair) or
    from the anti-solar point (Arago). ``near_sun_azimuth_offset_deg`` is 0 while Babinet and
    Brewster lie on the solar vertical and the pair's relative azimuth (+-) once a high sun
    has pushed them off it (module docstring).
    """

    sun_elevation_deg: float
    tau: float
    albedo: float
    babinet_elevation_deg: float
    brewster_elevation_deg: float
    arago_elevation_deg: float
    near_sun_azimuth_offset_deg: float = 0.0

    def _pair_distance(self) -> float:
        from .geometry import direction_vector
        d = (direction_vector(self.babinet_elevation_deg, self.near_sun_azimuth_offset_deg)
             @ direction_vector(self.sun_elevation_deg, 0.0))
        return float(np.degrees(np.arccos(np.clip(d, -1.0, 1.0))))

    @property
    def babinet_distance_deg(self) -> float:
        if self.near_sun_azimuth_offset_deg:
            return self._pair_distance()
        return self.babinet_elevation_deg - self.sun_elevation_deg

    @property
    def brewster_distance_deg(self) -> float:
        if self.near_sun_azimuth_offset_deg:
            return self._pair_distance()
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
        off = self.near_sun_azimuth_offset_deg
        for label, el, az in [("Babinet", self.babinet_elevation_deg,
                               (sun_azimuth_deg + off) % 360.0),
                              ("Brewster", self.brewster_elevation_deg,
                               (sun_azimuth_deg - off) % 360.0),
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
    """Babinet and Brewster elevations [deg] from a dense scan of Q along the solar vertical
    on the sky's Fourier-mode spline (module docstring, "High sun")."""
    from scipy.optimize import brentq
    modes = sky.modes(sun_elevation_deg)
    theta_sun = 90.0 - float(sun_elevation_deg)

    def q(x):
        # signed zenith angle x along the vertical: x > 0 towards the sun, x < 0 beyond the
        # zenith (the relative azimuth 180 deg)
        x = np.atleast_1d(np.asarray(x, float))
        return modes.evaluate(np.abs(x), np.where(x >= 0.0, 0.0, 180.0))[1]

    x = np.arange(theta_sun - 30.0, min(theta_sun + 30.0, 90.0) + 1e-9, DENSE_SCAN_STEP_DEG)
    values = q(x)
    idx = np.flatnonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)
    roots = np.array([brentq(lambda t: float(q(t)[0]), x[i], x[i + 1], xtol=1e-6)
                      for i in idx])
    above, below = roots[roots < theta_sun], roots[roots > theta_sun]
    babinet = 90.0 - float(above.max()) if above.size else np.nan
    brewster = 90.0 - float(below.min()) if below.size else np.nan
    return babinet, (brewster if brewster >= 0.0 else np.nan)


def _off_meridian_pair(sky, sun_elevation_deg: float, half_width_deg: float = 4.0,
                       step_deg: float = 0.25, azimuth_step_deg: float = 5.0):
    """``(elevation, relative azimuth)`` [deg] of the near-sun pair off the solar vertical, or
    ``(nan, nan)``: zero of ``(Q, U)`` of the sky's Fourier-mode spline, started from the
    DoLP minimum off the vertical on a grid of view zenith angles within ``half_width_deg``
    of the sun times relative azimuths 0-180 deg (one half: the pair is mirror symmetric)."""
    from scipy.optimize import minimize
    modes = sky.modes(sun_elevation_deg)
    theta_sun = 90.0 - float(sun_elevation_deg)
    th = np.arange(max(theta_sun - half_width_deg, step_deg), theta_sun + half_width_deg + 1e-9,
                   step_deg)
    ph = np.arange(0.0, 180.0 + 1e-9, azimuth_step_deg)
    T, P = np.meshgrid(th, ph, indexing="ij")
    I, Q, U = modes.evaluate(T, P)
    dop = np.hypot(Q, U) / I
    inner = (P > 0.0) & (P < 180.0) & (T > th[0]) & (T < th[-1])
    k = np.unravel_index(np.argmin(np.where(inner, dop, np.inf)), dop.shape)

    def f(v):
        i, q, u = modes.evaluate(v[0], v[1])
        return float((q ** 2 + u ** 2) / i ** 2)

    res = minimize(f, [T[k], P[k]], method="Nelder-Mead",
                   options={"xatol": 1e-5, "fatol": 1e-16, "maxiter": 2000})
    t, p = res.x
    if (np.sqrt(res.fun) > NEUTRAL_DOP or not th[0] < t < th[-1] or not 0.0 < p < 180.0):
        return np.nan, np.nan
    return 90.0 - float(t), float(p)


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
    check_finite("tau", tau)
    sky = MultipleScatteringSky(tau=tau, albedo=albedo, **sky_kwargs)
    n = neutral_points_from_modes(sky.modes(sun), sun, sky.tau, sky.albedo)
    if sun > DENSE_SCAN_ELEVATION_DEG or not (n.babinet_visible and n.brewster_visible):
        babinet, brewster = _dense_near_sun(sky, sun)
        n = replace(n, babinet_elevation_deg=babinet, brewster_elevation_deg=brewster)
        if not (n.babinet_visible or n.brewster_visible):
            el, off = _off_meridian_pair(sky, sun)
            n = replace(n, babinet_elevation_deg=el, brewster_elevation_deg=el,
                        near_sun_azimuth_offset_deg=0.0 if np.isnan(off) else off)
    return n
