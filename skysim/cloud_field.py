"""Broken clouds on the sky dome: a seeded, spatially correlated cloud field that drifts with
the wind.

Geometry
--------
The clouds form one thin layer at the height ``base_m`` above the site, a spherical shell of
radius ``R + h`` about the Earth's centre (``R`` the mean Earth radius [1]_). A view ray of
elevation ``e`` meets it after the slant distance

``l = sqrt(R^2 sin^2 e + 2 R h + h^2) - R sin e``

at the arc distance ``s = (R + h) atan2(l cos e, R + l sin e)`` from the point above the site,
where the ray's zenith angle has the cosine ``mu = (l + R sin e) / (R + h)`` (plane geometry
of the triangle Earth's centre - site - layer point; for ``R -> inf``: ``s = h cot e`` and
``mu = sin e``). The point's horizontal coordinates on the layer are ``s (sin az, cos az)``
(east, north). A layer and not a dome: the clouds near the horizon are farther away and look
smaller (perspective), and a wind moves them across the sky as real clouds move, fast overhead
and slowly near the horizon.

Field
-----
A stationary, isotropic Gaussian random field ``g`` of unit variance on the layer, with the
Matérn correlation ([2]_, sect. 2.7)

``C(r) = 2^(1 - nu) / Gamma(nu) (r / L)^nu K_nu(r / L)``,

whose spectral density on the plane is proportional to ``(L^-2 + |k|^2)^-(nu + 1)``. It is
drawn as a sum of ``n_modes`` random Fourier modes (the spectral representation of
Shinozuka & Deodatis [3]_; random features [4]_):
``g(x) = sqrt(2 / N) sum_j cos(k_j . x + phi_j)`` with ``phi_j`` uniform and
``k_j = z_j / (L sqrt(w_j))``, ``z_j`` standard normal in 2-D and ``w_j`` chi-squared with
``2 nu`` degrees of freedom (a Gaussian scale mixture whose marginal is that spectral
density), so that ``E[g(x) g(y)] = C(|x - y|)`` exactly. The default smoothness
``nu = 1/3`` gives the ``k^(-5/3)`` one-dimensional spectrum measured in cloud liquid water
along aircraft tracks over scales of 0.1-100 km (Cahalan & Snider 1989 [5]_).

``correlation_deg`` is the correlation angular scale seen at the zenith: the angle from the
zenith at which the field's correlation with the zenith point falls to ``1/e``. It sets
``L = s(90 - correlation_deg) / rho_nu`` with ``C(rho_nu L) = 1/e``.

Cover and thickness
-------------------
The cloud is where ``g`` exceeds the threshold ``t``: the ``(1 - cover)`` quantile of ``g`` at
the time 0 over :data:`QUANTILE_GRID` cells of equal solid angle (equal steps in
``sin(elevation)`` and in azimuth), so the clouds cover exactly the fraction ``cover`` of
those cells, i.e. of the dome's solid angle to within one cell (1 / 18432). Its vertical
optical thickness at 550 nm is ``tau`` everywhere in the cloud (``thickness="uniform"``:
every cloud of the same thickness) or ``tau (g - t) / <g - t>`` (``"excess"``: thicker in the
cores, thinning to 0 at the edges; ``<.>`` the mean over the cloudy cells, so the mean over
the cover is ``tau``; at cover 1 the threshold lies half a value spacing below the grid's
lowest value).

Drift
-----
A wind of ``wind_speed_m_s`` from the azimuth ``wind_from_deg`` (the meteorological
convention: the direction it blows from) moves the layer rigidly: the field at the time
``t`` [s] is the field at 0 shifted by ``v t`` downwind. Overhead it moves
``v / h`` rad/s (:attr:`CloudField.zenith_angular_speed_deg_s`: 0.6 deg/s for 10 m/s at
1 km). The cover is exact at the time 0; as the clouds drift it fluctuates about it (new
clouds come over the horizon, others leave).

References
----------
.. [1] H. Moritz, "Geodetic Reference System 1980", J. Geodesy 74:128-133 (2000),
   doi:10.1007/s001900050278 (mean radius R1 = 6371008.8 m).
.. [2] M. L. Stein, *Interpolation of Spatial Data: Some Theory for Kriging*, Springer (1999),
   sect. 2.7 (the Matérn class and its spectral density).
.. [3] M. Shinozuka, G. Deodatis, "Simulation of stochastic processes by spectral
   representation", Appl. Mech. Rev. 44(4):191-204 (1991), doi:10.1115/1.3119501.
.. [4] A. Rahimi, B. Recht, "Random features for large-scale kernel machines", Advances in
   Neural Information Processing Systems 20 (2007).
.. [5] R. F. Cahalan, J. B. Snider, "Marine stratocumulus structure", Remote Sens. Environ.
   28:95-107 (1989).
"""

from __future__ import annotations

import functools

import numpy as np

from .exceptions import BroadcastError, InvalidParameterError
from .validation import check_finite, check_in_range

__all__ = ["EARTH_RADIUS_M", "QUANTILE_GRID", "THICKNESS_PROFILES", "CloudField",
           "air_below", "equal_area_grid", "layer_intersection",
           "matern_correlation", "matern_efold_ratio", "time_offsets_s"]

EARTH_RADIUS_M = 6_371_008.8
"""Mean radius of the Earth [m] (GRS80 mean radius R1, Moritz 2000 [1]_)."""

QUANTILE_GRID = (96, 192)
"""Cells in ``sin(elevation)`` and in azimuth of the equal-solid-angle grid on which the
cover is made exact (18432 cells, one cell = 5.4e-5 of the dome)."""

THICKNESS_PROFILES = ("uniform", "excess")
"""How the optical thickness varies within the clouds (module docstring)."""

_BLOCK = 4096
"""Points per block of the mode sums: the (points x modes) phases of a block stay within a
few MB (a whole camera frame at once would need hundreds)."""


def layer_intersection(elevation_deg, height_m):
    """Where view rays meet a cloud layer (module docstring, Geometry).

    Parameters
    ----------
    elevation_deg : array-like
        View elevation [deg], in [0, 90].
    height_m : float or array-like
        Height of the layer above the site [m], > 0 (broadcast).

    Returns
    -------
    distance_m : ndarray
        Arc distance [m] along the layer from the point above the site.
    mu : ndarray
        Cosine of the ray's zenith angle at the layer [1].
    """
    e = np.radians(check_in_range("elevation_deg", elevation_deg, 0.0, 90.0))
    h = np.asarray(height_m, dtype=float)
    R = EARTH_RADIUS_M
    se = np.sin(e)
    root = np.sqrt(R * R * se * se + 2.0 * R * h + h * h)
    # l = root - R sin e, written without the cancellation at high elevations
    slant = (2.0 * R * h + h * h) / (root + R * se)
    distance = (R + h) * np.arctan2(slant * np.cos(e), R + slant * se)
    return distance, root / (R + h)


@functools.lru_cache(maxsize=32)
def _air_mass_table(height_m: float):
    """Relative air masses ``(below the layer, whole path)`` of rays at the elevations
    :data:`_AIR_MASS_ELEVATIONS` (curved rays through an exponential atmosphere)."""
    from .clouds import MOLECULAR_SCALE_HEIGHT_M as H
    R = EARTH_RADIUS_M
    e = np.radians(_AIR_MASS_ELEVATIONS)[:, None]
    r_layer = R + height_m
    s_below = np.sqrt(r_layer ** 2 - (R * np.cos(e[:, 0])) ** 2) - R * np.sin(e[:, 0])
    grid = np.concatenate([[0.0], np.geomspace(1.0, 3e6, 800)])[None, :]      # [m]
    z = np.sqrt(R * R + grid * grid + 2.0 * R * grid * np.sin(e)) - R
    n = np.exp(-z / H) / H
    cum = np.concatenate([np.zeros((e.size, 1)),
                          np.cumsum(0.5 * (n[:, 1:] + n[:, :-1]) * np.diff(grid), axis=1)],
                         axis=1)
    below = np.array([np.interp(sb, grid[0], c) for sb, c in zip(s_below, cum)])
    return below, cum[:, -1]


_AIR_MASS_ELEVATIONS = np.concatenate([np.arange(0.0, 10.0, 0.1), np.arange(10.0, 90.01, 0.5)])


def air_below(elevation_deg, height_m: float, tau: float = 0.0973):
    """The air between the site and a layer at ``height_m`` [m] along view rays.

    With ``m_b`` and ``m`` the ray's relative air masses below the layer and in all (number
    density ``exp(-z / H)``, ``H`` = :data:`skysim.clouds.MOLECULAR_SCALE_HEIGHT_M`, along
    the curved ray; ``m`` tends to ``sqrt(pi R / (2 H))`` at the horizon, tested) and
    ``tau`` the molecular optical thickness (default: 550 nm at sea level, Bodhaine et al.
    1999):

    Returns
    -------
    fraction : ndarray
        Share of the clear sky's light along the ray that this air scatters,
        ``(1 - exp(-tau m_b)) / (1 - exp(-tau m))``: about ``1 - exp(-h / H)`` overhead
        (:func:`skysim.clouds.molecular_fraction_below`), growing towards 1 at the horizon,
        where the ray stays low.
    transmission : ndarray
        ``exp(-tau m_b)``: what reaches the site of light from the layer.
    """
    below, total = _air_mass_table(float(height_m))
    el = np.asarray(elevation_deg, float)
    mb = np.interp(el, _AIR_MASS_ELEVATIONS, below)
    m = np.interp(el, _AIR_MASS_ELEVATIONS, total)
    return np.expm1(-tau * mb) / np.expm1(-tau * m), np.exp(-tau * mb)


def matern_correlation(r_over_L, smoothness: float) -> np.ndarray:
    """Matérn correlation ``2^(1-nu)/Gamma(nu) x^nu K_nu(x)`` at ``x = r / L`` ([2]_,
    sect. 2.7); 1 at 0."""
    from scipy.special import gamma, kv
    x = np.asarray(r_over_L, dtype=float)
    nu = float(smoothness)
    with np.errstate(invalid="ignore", over="ignore"):
        c = 2.0 ** (1.0 - nu) / gamma(nu) * x ** nu * kv(nu, x)
    return np.where(x > 0, c, 1.0)


@functools.lru_cache(maxsize=16)
def matern_efold_ratio(smoothness: float) -> float:
    """``rho`` with ``matern_correlation(rho, nu) = 1/e`` (1 for ``nu = 1/2``)."""
    from scipy.optimize import brentq
    return float(brentq(lambda x: matern_correlation(x, smoothness) - np.exp(-1.0),
                        1e-6, 50.0, xtol=1e-12))


def equal_area_grid(n_sin: int, n_azimuth: int):
    """Cell centres ``(elevation_deg, azimuth_deg)`` [deg] of ``n_sin x n_azimuth`` cells of
    equal solid angle on the dome (equal steps in ``sin(elevation)`` and in azimuth),
    flattened."""
    s = (np.arange(n_sin) + 0.5) / n_sin
    az = (np.arange(n_azimuth) + 0.5) * 360.0 / n_azimuth
    E, A = np.meshgrid(np.degrees(np.arcsin(s)), az, indexing="ij")
    return E.ravel(), A.ravel()


def _rng(rng) -> tuple[np.random.Generator, object]:
    """A Generator and what to record of it (the seed, or 'generator')."""
    if isinstance(rng, np.random.Generator):
        return rng, "generator"
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) and rng >= 0:
        return np.random.default_rng(int(rng)), int(rng)
    if isinstance(rng, np.random.SeedSequence):
        return np.random.default_rng(rng), {"entropy": str(rng.entropy),
                                            "spawn_key": list(rng.spawn_key)}
    raise InvalidParameterError(f"rng must be a numpy Generator, a SeedSequence or a seed (an "
                                f"integer >= 0); got {rng!r}")


class CloudField:
    """A seeded field of broken clouds on one layer (see the module docstring).

    Parameters
    ----------
    cover : float
        Fraction of the dome's solid angle covered by cloud at the time 0, in [0, 1].
    tau : float
        Vertical optical thickness of the clouds at 550 nm [1], in [0, 100] (the mean over the
        cover for ``thickness="excess"``).
    rng : numpy.random.Generator, SeedSequence or int
        Source of the field's random modes (a seed is recorded by :meth:`describe`).
    correlation_deg : float
        Correlation angular scale at the zenith [deg], in (0, 60]: the angle from the zenith
        at which the field's correlation with the zenith point is 1/e.
    base_m : float
        Height of the cloud layer above the site [m], in [50, 15000].
    thickness : {"uniform", "excess"}
        Optical thickness within the clouds (module docstring).
    smoothness : float
        Matérn smoothness ``nu``, in [0.05, 5] (default 1/3: the -5/3 spectrum of [5]_).
    wind_speed_m_s : float
        Wind speed at the cloud layer [m/s], in [0, 100].
    wind_from_deg : float
        Azimuth the wind blows from [deg, clockwise from north].
    n_modes : int
        Random Fourier modes, >= 16 (the cost of an evaluation grows with them).

    Raises
    ------
    InvalidParameterError
        For a value outside its range (the message names it).
    """

    def __init__(self, cover: float, tau: float, rng=0, *, correlation_deg: float = 10.0,
                 base_m: float = 1000.0, thickness: str = "uniform",
                 smoothness: float = 1.0 / 3.0, wind_speed_m_s: float = 0.0,
                 wind_from_deg: float = 270.0, n_modes: int = 256):
        self.cover = float(check_in_range("cover", cover, 0.0, 1.0,
                                          hint="the fraction of the sky covered by cloud"))
        self.tau = float(check_in_range("cloud tau", tau, 0.0, 100.0,
                                        hint="vertical optical thickness at 550 nm: thin "
                                             "cirrus < 1, cumulus 5-30, thick stratus up to "
                                             "~100"))
        self.correlation_deg = float(check_in_range(
            "correlation_deg", correlation_deg, 0.0, 60.0, low_open=True,
            hint="the cloud scale seen at the zenith in degrees (a few to a few tens)"))
        self.base_m = float(check_in_range("base_m", base_m, 50.0, 15000.0,
                                           hint="cloud base above the site in m"))
        if thickness not in THICKNESS_PROFILES:
            raise InvalidParameterError(f"thickness must be one of "
                                        f"{', '.join(THICKNESS_PROFILES)}; got {thickness!r}")
        self.thickness = thickness
        self.smoothness = float(check_in_range("smoothness", smoothness, 0.05, 5.0))
        self.wind_speed_m_s = float(check_in_range("wind_speed_m_s", wind_speed_m_s, 0.0,
                                                   100.0, hint="wind speed in m/s"))
        self.wind_from_deg = float(check_finite("wind_from_deg", wind_from_deg))
        if isinstance(n_modes, bool) or not isinstance(n_modes, (int, np.integer)) \
                or n_modes < 16:
            raise InvalidParameterError(f"n_modes must be an integer >= 16; got {n_modes!r}")
        self.n_modes = int(n_modes)
        gen, self.seed = _rng(rng)
        r_efold, _ = layer_intersection(90.0 - self.correlation_deg, self.base_m)
        self.length_m = float(r_efold) / matern_efold_ratio(self.smoothness)
        z = gen.standard_normal((self.n_modes, 2))
        w = gen.chisquare(2.0 * self.smoothness, self.n_modes)
        self._k = z / (self.length_m * np.sqrt(w))[:, None]        # [rad/m], (N, 2)
        self._phase = gen.uniform(0.0, 2.0 * np.pi, self.n_modes)
        to = np.radians(self.wind_from_deg + 180.0)
        self._wind = self.wind_speed_m_s * np.array([np.sin(to), np.cos(to)])  # [m/s] E, N

    # ------------------------------------------------------------------ the Gaussian field
    def _gaussian_at(self, x, y) -> np.ndarray:
        """``g`` at layer coordinates ``x`` (east), ``y`` (north) [m] (same shape)."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        xy = np.stack([x.ravel(), y.ravel()], axis=-1)
        out = np.empty(xy.shape[0])
        amp = np.sqrt(2.0 / self.n_modes)
        for s in range(0, xy.shape[0], _BLOCK):   # blocks of points, not single points
            ph = xy[s:s + _BLOCK] @ self._k.T
            ph += self._phase
            out[s:s + _BLOCK] = np.cos(ph, out=ph).sum(axis=1) * amp
        return out.reshape(x.shape)

    def layer_points(self, elevation_deg, azimuth_deg, time_s=0.0):
        """Layer coordinates of view rays, moved back by the drift to the time 0.

        Returns
        -------
        x, y : ndarray
            East and north coordinates [m] of the field at the time 0 that the rays see at
            ``time_s``.
        mu : ndarray
            Cosine of the rays' zenith angle at the layer.
        """
        el, az, t = np.broadcast_arrays(*(np.asarray(a, float) for a in (
            elevation_deg, azimuth_deg, time_s)))
        s, mu = layer_intersection(el, self.base_m)
        a = np.radians(az)
        return s * np.sin(a) - self._wind[0] * t, s * np.cos(a) - self._wind[1] * t, mu

    def gaussian(self, elevation_deg, azimuth_deg, time_s=0.0) -> np.ndarray:
        """The unit-variance Gaussian field ``g`` seen along view directions [deg] at
        ``time_s`` [s] after the time 0 (broadcast)."""
        check_finite("time_s", time_s)
        x, y, _ = self.layer_points(elevation_deg, azimuth_deg, time_s)
        return self._gaussian_at(x, y)

    # ------------------------------------------------------------------ cover and thickness
    @functools.cached_property
    def _threshold(self) -> tuple[float, float]:
        """Threshold ``t`` and the mean excess ``<g - t>`` over the cloudy cells of the
        quantile grid."""
        if self.cover == 0.0:
            return np.inf, 1.0
        if self.overcast:
            return -np.inf, 1.0
        g = np.sort(self.gaussian(*equal_area_grid(*QUANTILE_GRID)))
        n_cloud = int(round(self.cover * g.size))
        if n_cloud >= g.size:   # overcast: below the lowest value, halfway to a spacing
            t = g[0] - 0.5 * (g[1] - g[0]) if self.thickness == "excess" else -np.inf
        else:
            t = 0.5 * (g[-n_cloud - 1] + g[-n_cloud]) if n_cloud else np.inf
        excess = float(np.mean(g[g > t] - t)) if n_cloud and np.isfinite(t) else 1.0
        return float(t), excess

    @property
    def threshold(self) -> float:
        """The value of ``g`` above which a direction is cloudy (+inf: no cloud)."""
        return self._threshold[0]

    @property
    def overcast(self) -> bool:
        """True for a uniform overcast (cover 1, uniform thickness): the same optical
        thickness in every direction, so the Gaussian field need not be evaluated."""
        return self.cover == 1.0 and self.thickness == "uniform"

    def optical_thickness_at(self, x, y) -> np.ndarray:
        """Vertical optical thickness [1] at layer coordinates ``x`` (east), ``y`` (north)
        [m] of the field at the time 0 (:meth:`layer_points`)."""
        if self.overcast:
            return np.full(np.broadcast_shapes(np.shape(x), np.shape(y)), self.tau)
        return self.optical_thickness_of(self._gaussian_at(x, y))

    def optical_thickness_of(self, g) -> np.ndarray:
        """Vertical optical thickness [1] where the Gaussian field has the values ``g``."""
        t, excess = self._threshold
        g = np.asarray(g, float)
        if self.thickness == "uniform":
            return np.where(g > t, self.tau, 0.0)
        return np.where(g > t, self.tau * (g - t) / excess, 0.0)

    def optical_thickness(self, elevation_deg, azimuth_deg, time_s=0.0) -> np.ndarray:
        """Vertical optical thickness [1] of the cloud seen along view directions [deg] at
        ``time_s`` [s] (0 in the clear)."""
        return self.optical_thickness_of(self.gaussian(elevation_deg, azimuth_deg, time_s))

    def cloudy(self, elevation_deg, azimuth_deg, time_s=0.0) -> np.ndarray:
        """Whether the view directions [deg] see a cloud at ``time_s`` [s]."""
        return self.gaussian(elevation_deg, azimuth_deg, time_s) > self.threshold

    # ------------------------------------------------------------------ drift
    @property
    def zenith_angular_speed_deg_s(self) -> float:
        """Angular speed of the clouds overhead [deg/s]: ``v / h``."""
        return float(np.degrees(self.wind_speed_m_s / self.base_m))

    def describe(self) -> dict:
        """Parameters and seed, for sidecars."""
        return {"cover": self.cover, "tau": self.tau, "tau_wavelength_nm": 550.0,
                "correlation_deg": self.correlation_deg, "base_m": self.base_m,
                "thickness": self.thickness, "smoothness": self.smoothness,
                "wind_speed_m_s": self.wind_speed_m_s, "wind_from_deg": self.wind_from_deg,
                "n_modes": self.n_modes, "seed": self.seed,
                "field": "Matern Gaussian random field on a cloud layer, random Fourier modes",
                "cover_grid": list(QUANTILE_GRID)}


def time_offsets_s(time_s, sun_shape) -> np.ndarray:
    """Times [s] aligned with the sun arrays of a field evaluation: a scalar as it is, an
    array with one value per sun position reshaped to ``sun_shape``.

    Raises
    ------
    BroadcastError
        If the array has neither one element nor one per sun position.
    """
    t = check_finite("time_s", time_s)
    if t.ndim == 0 or t.size == 1:
        return t.reshape(())
    n = int(np.prod(sun_shape))
    if t.size != n:
        raise BroadcastError(f"time_s has {t.size} values but the sky is evaluated for {n} "
                             "sun positions; give one time per sun position or a scalar")
    return t.reshape(sun_shape)
