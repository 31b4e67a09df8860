"""Multiple-scattering polarized sky: a Rayleigh slab over a Lambertian ground.

The model is the plane-parallel problem of the Coulson-Dave-Sekera tables [1]_ [2]_: a
homogeneous, conservative Rayleigh atmosphere of optical thickness ``tau`` (given, or derived
from wavelength and surface pressure after Bodhaine et al. 1999 [3]_) over a Lambertian ground
of albedo ``A``. The radiative transfer is solved by sasktran2 (:mod:`skysim.rt_sasktran`,
optional extra ``rt``: ``python -m pip install -e '.[rt]'`` in the checkout).

Speed by physics
----------------
For Rayleigh scattering of unpolarized sunlight the diffuse Stokes vector depends on the
relative azimuth ``phi`` only through ``cos(m phi)`` (I, Q) and ``sin(m phi)`` (U) with
``m <= 2`` (Chandrasekhar 1950, ch. X, eqs. (64)-(66) [4]_; the Lambertian ground adds to
``m = 0`` only). :func:`fourier_modes` therefore calls the engine once per
(tau, albedo, sun zenith) on ``n_zenith`` view zenith angles x 5 azimuths (one call for
several (tau, albedo) at one sun: :func:`fourier_modes_cases`), fits the five mode
functions ``I_m, Q_m (m = 0, 1, 2)`` and ``U_m (m = 1, 2)`` per zenith angle (the residual of
that fit measures how well the engine obeys ``m <= 2``), and interpolates them in view zenith
angle (:class:`PoleSpline`: each mode divided by its known power of ``sin(theta)`` at the
zenith, a cubic spline even in ``theta``). Near the zenith the nodes are the view cosines at
which the engine's multiple-scatter source is exact (1, 0.98, 0.96:
:data:`skysim.rt_sasktran.SOURCE_GRID_MU_STEP`, :func:`mode_nodes_deg`); the engine's own
rays in between are wrong there and are not used. The interpolation error (tested in
``tests/test_multiple.py`` and ``tests/test_zenith_region.py``; stated in
``docs/physical_sky.md``) is below 1e-3 in DoLP and in I/I for the default 25 nodes.

Units: ``I`` (and Q, U) are normalised to an incident solar flux of ``pi`` per unit area normal
to the beam, as in the tables; the direct solar beam is not included.

References
----------
.. [1] K. L. Coulson, J. V. Dave, Z. Sekera, *Tables Related to Radiation Emerging from a
   Planetary Atmosphere with Rayleigh Scattering*, Univ. California Press (1960).
.. [2] V. Natraj, K.-F. Li, Y. L. Yung, ApJ 691:1909 (2009), doi:10.1088/0004-637X/691/2/1909.
.. [3] B. A. Bodhaine, N. B. Wood, E. G. Dutton, J. R. Slusser, "On Rayleigh optical depth
   calculations", J. Atmos. Oceanic Technol. 16:1854-1861 (1999),
   doi:10.1175/1520-0426(1999)016<1854:ORODC>2.0.CO;2.
.. [4] S. Chandrasekhar, *Radiative Transfer*, Oxford (1950; Dover 1960), ch. X.
.. [5] J. W. Hovenier, C. V. M. van der Mee, H. Domke, *Transfer of Polarized Light in
   Planetary Atmospheres: Basic Concepts and Practical Methods*, Kluwer (2004), ch. 2 and 4
   (Fourier decomposition of the Stokes vector and of the reflection and transmission
   matrices in the meridian-plane basis).
.. [6] J. F. de Haan, P. B. Bosma, J. W. Hovenier, "The adding method for multiple
   scattering calculations of polarized light", A&A 183:371-391 (1987).
"""

from __future__ import annotations

import functools
import warnings
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from .exceptions import InvalidParameterError
from .molecular import (WAVELENGTH_RANGE_NM,  # noqa: F401 (re-exported)
                        bodhaine_depolarization_ratio, bodhaine_optical_thickness,
                        bodhaine_optical_thickness_fit)
from .rt_sasktran import (DEFAULT_SETTINGS, EngineSettings, TauBeyondTablesWarning,
                          check_verified_tau, lru_take, tau_check)
from .sky import Sky
from .validation import check_finite, check_in_range

__all__ = [
    "FIT_AZIMUTHS_DEG",
    "WAVELENGTH_RANGE_NM",
    "FourierModes",
    "MultipleScatteringSky",
    "PoleSpline",
    "bodhaine_depolarization_ratio",
    "bodhaine_optical_thickness",
    "bodhaine_optical_thickness_fit",
    "clear_modes_cache",
    "fourier_modes",
    "fourier_modes_cases",
    "interval_stokes",
    "SNAP_MU_MIN",
    "mix_modes",
    "mode_nodes_deg",
    "pole_orders",
    "prefetch_modes",
    "session_sun_nodes",
    "sun_bracket",
    "zenith_nodes_deg",
]

FIT_AZIMUTHS_DEG = np.array([0.0, 45.0, 90.0, 135.0, 180.0])
"""Relative azimuths [deg] at which the engine is called per zenith node (5 > 3 unknowns)."""

# --------------------------------------------------------------------------------------------
# Fourier modes of the transmitted field
# --------------------------------------------------------------------------------------------

def zenith_nodes_deg(n_zenith: int) -> np.ndarray:
    """View zenith nodes [deg] in [0, 90], denser towards the horizon.

    ``theta_k = 90 sin(pi k / (2 (n - 1)))``: the transmitted field changes fastest near the
    horizon (the slant optical path ``tau / mu`` saturates there).
    """
    if int(n_zenith) < 8:
        raise InvalidParameterError(f"n_zenith must be >= 8; got {n_zenith}. Default: 25.")
    k = np.arange(int(n_zenith))
    return 90.0 * np.sin(0.5 * np.pi * k / (int(n_zenith) - 1))


SNAP_MU_MIN = 0.1
"""Nodes of :func:`zenith_nodes_deg` with a view cosine at least this are moved to the
nearest view cosine at which the engine's multiple-scatter source is exact
(:func:`mode_nodes_deg`); closer to the horizon the nodes are left where they are (their
sine spacing follows the radiance's steep rise there, and the source's interpolation error is
below 1e-4 of I)."""


def mode_nodes_deg(n_zenith: int) -> np.ndarray:
    """View zenith nodes [deg] of the Fourier-mode tables.

    The engine's multiple-scatter source is exact at view cosines ``1 - 0.02 k``
    (:data:`skysim.rt_sasktran.SOURCE_GRID_MU_STEP`) and interpolated linearly in the cosine
    between them, which is wrong between the zenith and ``mu = 0.98`` (11.5 deg) and errs by up
    to about 1e-3 of I between the next few. So the nodes are: the zenith (0, traced at
    :data:`skysim.rt_sasktran.MU_MAX`), the cosines 0.98 and 0.96 (11.48, 16.26 deg), the
    nodes of :func:`zenith_nodes_deg` beyond them moved to the nearest exact cosine down to
    :data:`SNAP_MU_MIN`, and the remaining ones near the horizon as they are. The engine's
    rays between the zenith and 11.48 deg are not used; :class:`PoleSpline` bridges them.
    """
    from .rt_sasktran import SOURCE_GRID_MU_STEP as step
    mu = np.cos(np.radians(zenith_nodes_deg(n_zenith)))
    snapped = np.round(mu / step) * step
    mu = np.where(mu >= SNAP_MU_MIN, snapped, mu)
    mu = np.unique(np.concatenate([[1.0, 1.0 - step, 1.0 - 2.0 * step],
                                   mu[mu < 1.0 - 2.5 * step]]))[::-1]
    return np.degrees(np.arccos(np.clip(mu, 0.0, 1.0)))


def pole_orders(m, stokes: str) -> np.ndarray:
    """Power of ``sin(theta)`` with which the azimuthal Fourier mode ``m`` of a Stokes
    parameter (``"I"``, or ``"Q"``/``"U"`` in the local meridian basis) vanishes at the
    zenith: ``m`` for I, ``|m - 2|`` for Q and U.

    Near the zenith the field is smooth in the Cartesian direction coordinates
    ``(x, y) = theta (cos phi, sin phi)``, so a mode ``m`` of I behaves as ``theta^m``; Q and U
    refer to the meridian, which turns with ``phi``: ``Q + iU`` is the Cartesian-frame
    ``Q_c + i U_c`` (smooth) times ``exp(-2 i phi)``, so its modes behave as
    ``theta^|m -+ 2|`` (the Fourier decomposition in the meridian-plane basis [5]_ [6]_). At the
    zenith itself only ``I_0`` and ``Q_2``, ``U_2`` (the zenith's linear polarization seen in
    the turning basis) survive, as the engine's zenith rays show.
    """
    m = np.abs(np.asarray(m, int))
    return m if stokes == "I" else np.abs(m - 2)


class PoleSpline:
    """Cubic-spline interpolation in view zenith angle of azimuthal Fourier modes, exact in
    its behaviour through the zenith.

    A mode ``f`` vanishing as ``sin^p(theta)`` at the zenith (:func:`pole_orders`) is
    interpolated as ``g = f / sin^q(theta)`` (``q = p`` up to 2, above that 1 or 2 with the
    parity of ``p``), times ``sin^q(theta)``. ``g`` is even in ``theta`` (a path through the
    zenith continues at ``phi + 180 deg`` with the meridian basis turned by 180 deg, which
    leaves Q and U unchanged, so ``f(-theta) = (-1)^m f(theta)`` and ``p = m`` mod 2), so the
    spline runs over the nodes mirrored to ``-theta``. Its value at the zenith is the node's
    where ``p = 0``, zero where ``p > q``, and free (no zenith node) where ``p = q > 0``. A
    spline of ``f`` itself (or one linear in ``mu``) would give a mode ``m = 1`` the wrong
    shape between the zenith and the next node: linear in ``mu`` it is ``theta^2`` instead of
    ``theta``. References: Hovenier, van der Mee & Domke (2004) [5]_; de Haan et al.
    (1987) [6]_.

    Parameters
    ----------
    theta_deg : array-like (n,)
        Nodes [deg] in [0, 90], increasing; a node below 1 deg is the zenith's (the engine
        traces it at :data:`skysim.rt_sasktran.MU_MAX`).
    values : array-like (..., n)
        Modes at the nodes.
    orders : array-like (...)
        Their powers ``p`` (:func:`pole_orders`), one per mode.
    """

    POLE_NODE_DEG = 1.0

    def __init__(self, theta_deg, values, orders):
        from scipy.interpolate import CubicSpline
        th = np.asarray(theta_deg, float)
        v = np.asarray(values, float)
        self._shape = v.shape[:-1]
        v = v.reshape(-1, th.size)
        p = np.broadcast_to(np.asarray(orders, int), self._shape).ravel()
        self._q = np.where(p <= 2, p, 2 - p % 2)
        pole = th < self.POLE_NODE_DEG
        if pole.sum() != 1 or not pole[0]:
            raise InvalidParameterError(
                f"the first node (and only it) must be the zenith's, below "
                f"{self.POLE_NODE_DEG} deg; got nodes starting {th[:3].tolist()}")
        off = th[1:]
        g = v[:, 1:] / np.sin(np.radians(off))[None, :] ** self._q[:, None]
        g = np.concatenate([g[:, ::-1], g], axis=1)
        x = np.concatenate([-off[::-1], off])
        anchored = (p == 0) | (p > self._q)
        self._anchored = anchored
        self._splines = []
        if anchored.any():
            at_pole = np.where(p[anchored] == 0, v[anchored, 0], 0.0)
            k = off.size
            y = np.concatenate([g[anchored, :k], at_pole[:, None], g[anchored, k:]], axis=1)
            self._splines.append((anchored, CubicSpline(np.concatenate([x[:k], [0.0], x[k:]]),
                                                         y, axis=1)))
        if (~anchored).any():
            self._splines.append((~anchored, CubicSpline(x, g[~anchored], axis=1)))

    def __call__(self, theta_deg) -> np.ndarray:
        """Modes at view zenith angles ``theta_deg`` [deg] (1-d, in [0, 90]): ``(..., N)``."""
        t = np.ravel(np.asarray(theta_deg, float))
        out = np.empty((self._q.size, t.size))
        for rows, spline in self._splines:
            out[rows] = spline(t)
        out *= np.sin(np.radians(t))[None, :] ** self._q[:, None]
        return out.reshape(self._shape + (t.size,))


@dataclass(frozen=True)
class FourierModes:
    """Azimuthal Fourier modes of the diffuse Stokes field for one (tau, albedo, mu0).

    ``I = sum_m I_m(theta) cos(m phi)``, ``Q = sum_m Q_m(theta) cos(m phi)`` (m = 0, 1, 2),
    ``U = sum_m U_m(theta) sin(m phi)`` (m = 1, 2), with ``theta`` the view zenith angle and
    ``phi`` the relative azimuth (view minus sun, clockwise), in the skysim Stokes basis.

    Attributes
    ----------
    theta_deg : ndarray (n,)
        View zenith angles of the engine rays [deg] (:func:`mode_nodes_deg`).
    coefficients : ndarray (8, n)
        Rows ``I_0, I_1, I_2, Q_0, Q_1, Q_2, U_1, U_2`` at ``theta_deg``.
    fit_residual : float
        Largest residual of the ``m <= 2`` least-squares fit over all nodes, relative to I.
    """

    theta_deg: np.ndarray
    coefficients: np.ndarray
    fit_residual: float

    ORDERS = np.concatenate([pole_orders([0, 1, 2], "I"), pole_orders([0, 1, 2], "Q"),
                             pole_orders([1, 2], "U")])
    """Powers of ``sin(theta)`` of the rows at the zenith (:func:`pole_orders`)."""

    @functools.cached_property
    def _spline(self):
        return PoleSpline(self.theta_deg, self.coefficients, self.ORDERS)

    def evaluate(self, theta_deg, phi_deg):
        """Return ``(I, Q, U)`` at view zenith ``theta_deg`` [deg] and azimuth ``phi_deg`` [deg]."""
        theta, phi = np.broadcast_arrays(np.asarray(theta_deg, float), np.asarray(phi_deg, float))
        c = self._spline(theta.ravel()).reshape((8,) + theta.shape)
        p = np.radians(phi)
        c1, c2, s1, s2 = np.cos(p), np.cos(2 * p), np.sin(p), np.sin(2 * p)
        return (c[0] + c[1] * c1 + c[2] * c2, c[3] + c[4] * c1 + c[5] * c2,
                c[6] * s1 + c[7] * s2)


def fourier_modes(tau: float, albedo: float, mu0: float, *, n_zenith: int = 25,
                  depolarization_ratio: float = 0.0,
                  settings: EngineSettings = DEFAULT_SETTINGS) -> FourierModes:
    """Fourier modes of the diffuse field from one engine call (cached per arguments).

    Parameters
    ----------
    tau, albedo : float
        Optical thickness (in :data:`skysim.rt_sasktran.VERIFIED_TAU_RANGE`) and Lambertian
        ground albedo in [0, 1].
    mu0 : float
        Cosine of the solar zenith angle, in (0, 1].
    n_zenith : int
        Number of view zenith nodes of :func:`zenith_nodes_deg`, the basis of
        :func:`mode_nodes_deg` (25 gives 25 nodes); the engine traces 5 rays per node.
    depolarization_ratio : float
        Molecular depolarization ratio (0 in the tables).
    settings : EngineSettings
    """
    return fourier_modes_cases([tau], [albedo], mu0, n_zenith=n_zenith,
                               depolarization_ratio=depolarization_ratio, settings=settings)[0]


MODES_CACHE_SIZE = 512
"""Fourier-mode sets kept per process (least recently used dropped first)."""
_MODES_CACHE: OrderedDict = OrderedDict()


def clear_modes_cache() -> None:
    """Forget every cached Fourier-mode set (the next sky evaluation calls the engine)."""
    _MODES_CACHE.clear()


def fourier_modes_cases(taus, albedos, mu0: float, *, n_zenith: int = 25,
                        depolarization_ratio: float = 0.0,
                        settings: EngineSettings = DEFAULT_SETTINGS) -> list:
    """Fourier modes for several ``(tau, albedo)`` at one sun: those not cached yet come from
    one engine call together (each case is one "wavelength" of the engine, computed
    independently, so the modes equal those of :func:`fourier_modes` case by case; the call's
    set-up is shared, about 0.5 s of a single case's 1.3 s on one core).

    Parameters
    ----------
    taus, albedos : sequences of float, same length
        Optical thicknesses and albedos of the cases.
    mu0, n_zenith, depolarization_ratio, settings
        As :func:`fourier_modes`.

    Returns
    -------
    list of FourierModes, one per case.
    """
    keys = [(float(t), float(a), float(mu0), int(n_zenith), float(depolarization_ratio),
             settings) for t, a in zip(taus, albedos, strict=True)]
    missing = list(dict.fromkeys(k for k in keys if k not in _MODES_CACHE))
    if missing:
        from .rt_sasktran import MU_MAX, MU_MIN, transmitted_stokes_cases
        nodes = mode_nodes_deg(int(n_zenith))
        mu = np.clip(np.cos(np.radians(nodes)), MU_MIN, MU_MAX)
        theta = np.degrees(np.arccos(mu))  # the angles the engine actually traces
        M, P = np.meshgrid(mu, FIT_AZIMUTHS_DEG, indexing="ij")
        stokes = transmitted_stokes_cases([k[0] for k in missing], [k[1] for k in missing],
                                          float(mu0), M.ravel(), P.ravel(),
                                          depolarization_ratio=float(depolarization_ratio),
                                          settings=settings)
        for key, st in zip(missing, stokes):
            I, Q, U = (st[:, c].reshape(M.shape) for c in range(3))
            _MODES_CACHE[key] = _fit_modes(theta, I, Q, U)
    return lru_take(_MODES_CACHE, keys, MODES_CACHE_SIZE)


def _fit_modes(theta, I, Q, U) -> FourierModes:
    """Least-squares ``m <= 2`` modes of engine Stokes ``(n_zenith, 5)`` at
    :data:`FIT_AZIMUTHS_DEG`."""
    p = np.radians(FIT_AZIMUTHS_DEG)
    cos_basis = np.stack([np.ones_like(p), np.cos(p), np.cos(2 * p)], axis=1)  # (5, 3)
    sin_basis = np.stack([np.sin(p), np.sin(2 * p)], axis=1)                   # (5, 2)
    ci, *_ = np.linalg.lstsq(cos_basis, I.T, rcond=None)
    cq, *_ = np.linalg.lstsq(cos_basis, Q.T, rcond=None)
    cu, *_ = np.linalg.lstsq(sin_basis, U.T, rcond=None)
    resid = max(np.max(np.abs(cos_basis @ ci - I.T) / I.T),
                np.max(np.abs(cos_basis @ cq - Q.T) / I.T),
                np.max(np.abs(sin_basis @ cu - U.T) / I.T))
    coeffs = np.concatenate([ci, cq, cu], axis=0)
    return FourierModes(theta, coeffs, float(resid))


def prefetch_modes(skies, sun_elevation_deg) -> None:
    """Compute, in one engine call per sun node, the Fourier modes that several
    :class:`MultipleScatteringSky` objects differing only in ``(tau, albedo)`` will need at
    these sun elevations [deg] (later evaluations are cache hits).

    Raises
    ------
    InvalidParameterError
        If the skies differ in anything but ``tau`` and ``albedo``.
    """
    skies = list(skies)
    first = skies[0]
    def shared(s):
        return (s.n_zenith, s.depolarization_ratio, s.settings, s.sun_step_deg,
                s.sun_node_origin_deg)

    if any(shared(s) != shared(first) for s in skies):
        raise InvalidParameterError(
            "prefetch_modes needs skies that differ only in tau and albedo")
    nodes = first.sun_node_set(sun_elevation_deg)
    for el in sorted(nodes):
        fourier_modes_cases([s.tau for s in skies], [s.albedo for s in skies], _mu0(el),
                            n_zenith=first.n_zenith,
                            depolarization_ratio=first.depolarization_ratio,
                            settings=first.settings)


def mix_modes(modes, weights) -> FourierModes:
    """The weighted sum of Fourier-mode sets on the same zenith nodes (the diffuse field is
    linear in them, so a sky interpolated between engine runs is one mode set evaluated once
    instead of one evaluation per run)."""
    modes = list(modes)
    theta = modes[0].theta_deg
    if any(m.theta_deg.shape != theta.shape or np.any(m.theta_deg != theta) for m in modes):
        raise InvalidParameterError("mix_modes needs mode sets on the same zenith nodes")
    c = sum(float(w) * m.coefficients for m, w in zip(modes, weights, strict=True))
    return FourierModes(theta, c, max(m.fit_residual for m in modes))


LOW_SUN_STEPS = 8
LOW_SUN_RATIO = 1.125
LOWEST_NODE_DEG = 0.01
"""Sun nodes near the horizon (:func:`sun_bracket`): below about ``LOW_SUN_STEPS`` steps the
nodes are geometric (``top / 1.125^k``, spacing about 1/8 of the elevation), because the field
bends faster as the sun nears the horizon: with uniform 1-deg nodes the AoP misses by up to
0.8 deg at a 1.5-deg sun, with these by 0.03 deg (measured, tau 0.1; tested). Suns below
``LOWEST_NODE_DEG`` are computed exactly."""


def sun_bracket(sun_elevation_deg, step_deg, origin_deg: float = 0.0):
    """Sun nodes ``(lower, upper)`` [deg] around every sun elevation, for interpolating a sky
    linearly in the sun's elevation between engine runs.

    Nodes are ``origin_deg + k step_deg`` down to ``top``, the first of them at or above
    ``LOW_SUN_STEPS step_deg``, and geometric below it (``top / LOW_SUN_RATIO^k``).

    Parameters
    ----------
    sun_elevation_deg : array_like
        Sun elevations [deg].
    step_deg : float or None
        Node spacing [deg]; None: every sun is computed exactly.
    origin_deg : float
        A node [deg] (a session's own sun, so that a session at one sun is exact).

    Returns
    -------
    lower, upper : ndarray
        The neighbouring nodes [deg]; NaN where the sky is computed at the sun itself (no
        step, a sun on a node, or one below :data:`LOWEST_NODE_DEG`).
    """
    sel = np.asarray(sun_elevation_deg, float)
    nan = np.full(sel.shape, np.nan)
    if step_deg is None:
        return nan, nan
    step, origin = float(step_deg), float(origin_deg)
    lo = origin + np.floor((sel - origin) / step) * step
    hi = np.minimum(lo + step, 90.0)
    top = origin + np.ceil((LOW_SUN_STEPS * step - origin) / step) * step
    low = sel < top
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.floor(np.log(top / np.where(low & (sel > 0), sel, top)) / np.log(LOW_SUN_RATIO))
    lo = np.where(low, top * LOW_SUN_RATIO ** -(k + 1), lo)
    hi = np.where(low, top * LOW_SUN_RATIO ** -k, hi)
    exact = (lo == sel) | (sel < LOWEST_NODE_DEG) | (lo < LOWEST_NODE_DEG)
    return np.where(exact, nan, lo), np.where(exact, nan, hi)


MAX_SESSION_STEP_DEG = 3.0
"""Widest sun-node step [deg] :func:`session_sun_nodes` chooses. Linear interpolation over 3
deg (above the geometric low-sun nodes) errs by at most 2e-3 in I/I, 1.5e-3 in DoLP, 2.5e-3
in the polarized radiance ``|dQ, dU| / I`` and 0.2 deg in AoP where the DoP exceeds 0.1
(measured at mid-interval suns of 25-82 deg, tau 0.02-1, albedo 0-0.6: at most 1.6e-3,
1.4e-3, 2.2e-3 and 0.18 deg; the error grows as the step squared; tested in
``tests/test_multiple.py``), four times below a real photodiode instrument's relative noise
(about 1e-2)."""


def session_sun_nodes(sun_elevation_deg, max_step_deg: float = MAX_SESSION_STEP_DEG):
    """Sun-node step and origin [deg] (for :func:`sun_bracket`) that cover a session's suns
    with as few engine runs as the stated error allows: one node (exact) when the sun stands
    still, two nodes (the session's lowest sun and one step above, at least 1 deg, at most
    ``max_step_deg``) when it moves; a time shift (a clock fit) adds nodes a step apart.

    Returns
    -------
    step_deg, origin_deg : float
    """
    el = np.asarray(sun_elevation_deg, float).ravel()
    lo, span = float(np.min(el)), float(np.ptp(el))
    if span <= 1.0:
        return 1.0, lo
    return span / np.ceil(span / float(max_step_deg)), lo


def interval_stokes(theta_deg, phi_deg, sun_elevation_deg, lower, upper, modes_at):
    """``(I, Q, U)`` (3, n) at view zenith ``theta_deg`` and relative azimuth ``phi_deg``
    [deg] for suns at ``sun_elevation_deg`` [deg], interpolated linearly between the sun
    nodes ``lower`` and ``upper`` (:func:`sun_bracket`; NaN: the sun itself). ``modes_at(el)``
    gives the :class:`FourierModes` at a sun elevation. One vectorised pass per distinct node
    interval (a session whose sun moves a few degrees has one or two)."""
    theta, phi, sel = (np.ravel(np.asarray(a, float)) for a in (theta_deg, phi_deg,
                                                                 sun_elevation_deg))
    lo, hi = np.ravel(lower), np.ravel(upper)
    out = np.empty((3, sel.size))
    keys, inverse = np.unique(np.where(np.isnan(lo), sel, lo), return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(keys.size + 1))
    for k in range(keys.size):
        group = order[bounds[k]:bounds[k + 1]]
        exact = np.isnan(lo[group])
        m = group[exact]      # at this sun itself (a node, or computed exactly)
        if m.size:
            out[:, m] = modes_at(keys[k]).evaluate(theta[m], phi[m])
        m = group[~exact]     # between this node and the next
        if m.size:
            a, b = lo[m[0]], hi[m[0]]
            f = (sel[m] - a) / (b - a)
            out[:, m] = ((1.0 - f) * np.stack(modes_at(a).evaluate(theta[m], phi[m]))
                         + f * np.stack(modes_at(b).evaluate(theta[m], phi[m])))
    return out


def _mu0(sun_elevation_deg) -> float:
    return float(np.sin(np.radians(sun_elevation_deg)))


# --------------------------------------------------------------------------------------------
# The Sky object
# --------------------------------------------------------------------------------------------

class MultipleScatteringSky(Sky):
    """Multiple-scattering Rayleigh sky over a Lambertian ground (sasktran2 engine).

    Parameters
    ----------
    tau : float, optional
        Rayleigh optical thickness in :data:`skysim.rt_sasktran.VERIFIED_TAU_RANGE` (1e-3 to
        3; outside it :class:`~skysim.rt_sasktran.TauOutsideVerifiedRangeError`). Above 1
        (beyond the published tables, checked by convergence only) a
        :class:`~skysim.rt_sasktran.TauBeyondTablesWarning`, and ``describe()["tau_check"]``
        says ``"convergence"`` instead of ``"tables"``.
        Give either ``tau`` or ``wavelength_nm``.
    albedo : float
        Lambertian ground albedo in [0, 1].
    wavelength_nm : float, optional
        Wavelength [nm] in :data:`WAVELENGTH_RANGE_NM`: ``tau`` then follows from
        :func:`bodhaine_optical_thickness` at ``pressure_hPa``, ``latitude_deg``, ``altitude_m``
        (at sea level tau exceeds 1 below 314 nm; 2.7 at 250 nm).
    pressure_hPa : float
        Surface pressure [hPa] (only with ``wavelength_nm``).
    latitude_deg, altitude_m : float
        Site latitude [deg] and altitude [m] for gravity (only with ``wavelength_nm``).
    depolarization_ratio : float or "bodhaine"
        Molecular depolarization ratio; 0 (default) as in the Coulson/Natraj tables; "bodhaine"
        uses :func:`bodhaine_depolarization_ratio` at ``wavelength_nm``.
    n_zenith : int
        Zenith nodes of the Fourier-mode interpolation, as :func:`mode_nodes_deg` (default
        25: 24 nodes).
    sun_step_deg : float, optional
        For many sun positions (time series): compute the modes only at sun elevations
        ``sun_node_origin_deg + k sun_step_deg`` and interpolate the Stokes vector linearly
        between the two neighbouring nodes; near the horizon the nodes close in geometrically
        (:func:`sun_bracket`, :data:`LOW_SUN_STEPS`). The evaluation is vectorised over all samples of a node
        interval, so a time series costs a few engine calls and passes, not one per sample.
        None (default): one engine call per distinct sun elevation, no interpolation. The
        error of a 1 deg step is stated and tested in ``tests/test_multiple.py``.
    sun_node_origin_deg : float
        One of the sun nodes [deg] (default 0; :func:`session_sun_nodes` puts it at a
        session's own sun).
    settings : EngineSettings
        Numerical set-up of sasktran2 (defaults validated against the tables).

    Notes
    -----
    ``I`` is normalised to an incident solar flux ``pi`` per unit area normal to the beam
    (the tables' normalisation), the direct beam excluded. Stokes basis and AoP follow
    ``docs/conventions.md``. One engine call (about 1 s) per distinct sun elevation; the
    modes are cached per (tau, albedo, sun zenith), so later maps for the same sun are
    interpolations only.
    """

    name = "multiple"

    def __init__(self, tau=None, albedo=0.0, wavelength_nm=None, pressure_hPa=1013.25, *,
                 latitude_deg=45.0, altitude_m=0.0, depolarization_ratio=0.0,
                 n_zenith: int = 25, sun_step_deg: float | None = None,
                 sun_node_origin_deg: float = 0.0,
                 settings: EngineSettings = DEFAULT_SETTINGS):
        if (tau is None) == (wavelength_nm is None):
            raise InvalidParameterError(
                "give exactly one of tau (optical thickness) or wavelength_nm (tau then "
                f"follows from Bodhaine et al. 1999); got tau={tau!r}, "
                f"wavelength_nm={wavelength_nm!r}")
        if tau is None:
            tau = float(bodhaine_optical_thickness(wavelength_nm, pressure_hPa, latitude_deg,
                                                   altitude_m))
        self.tau = float(check_verified_tau("tau", tau))
        if tau_check(self.tau) == "convergence":
            warnings.warn("an optical thickness above 1 lies beyond the published tables: the "
                          "multiple-scattering sky is checked there by convergence only "
                          "(radiance within 2e-3 at tau = 3); describe() records it",
                          TauBeyondTablesWarning, stacklevel=2)
        self.albedo = float(check_in_range("albedo", albedo, 0.0, 1.0,
                                           hint="Lambertian ground albedo is a fraction"))
        self.wavelength_nm = None if wavelength_nm is None else float(wavelength_nm)
        self.pressure_hPa = float(pressure_hPa)
        if isinstance(depolarization_ratio, str):
            if depolarization_ratio != "bodhaine" or wavelength_nm is None:
                raise InvalidParameterError(
                    f"depolarization_ratio={depolarization_ratio!r}: give a number, or "
                    "'bodhaine' together with wavelength_nm")
            depolarization_ratio = float(bodhaine_depolarization_ratio(wavelength_nm))
        self.depolarization_ratio = float(depolarization_ratio)
        zenith_nodes_deg(n_zenith)  # validates
        self.n_zenith = int(n_zenith)
        self.sun_step_deg = None if sun_step_deg is None else float(
            check_in_range("sun_step_deg", sun_step_deg, 0.0, 10.0, low_open=True,
                           hint="a few degrees at most (None: exact per sun elevation)"))
        self.sun_node_origin_deg = float(check_finite("sun_node_origin_deg",
                                                      sun_node_origin_deg))
        self.settings = settings

    def modes(self, sun_elevation_deg: float) -> FourierModes:
        """Fourier modes for one sun elevation [deg] (cached)."""
        return fourier_modes(self.tau, self.albedo, _mu0(sun_elevation_deg),
                             n_zenith=self.n_zenith,
                             depolarization_ratio=self.depolarization_ratio,
                             settings=self.settings)

    def _stokes(self, vel, vaz, sel, saz):
        lo, hi = self._bracket(sel)
        out = interval_stokes(90.0 - vel, vaz - saz, sel, lo, hi, self.modes)
        I, Q, U = (c.reshape(vel.shape) for c in out)
        return I, Q, U

    def _bracket(self, sun_elevation_deg):
        """Sun nodes around every sun elevation (:func:`sun_bracket`)."""
        return sun_bracket(sun_elevation_deg, self.sun_step_deg, self.sun_node_origin_deg)

    def sun_nodes_deg(self, sun_elevation_deg: float) -> tuple:
        """Sun elevations [deg] whose modes give the sky at this one: itself (exact), or the
        two neighbouring nodes (multiples of ``sun_step_deg``, geometric near the horizon)."""
        lo, hi = self._bracket(float(sun_elevation_deg))
        if np.isnan(lo):
            return (float(sun_elevation_deg),)
        return (float(lo), float(hi))

    def sun_node_set(self, sun_elevation_deg) -> list:
        """Every sun elevation [deg] whose modes the sky at these suns needs, sorted."""
        sel = np.asarray(sun_elevation_deg, float).ravel()
        lo, hi = self._bracket(sel)
        exact = np.isnan(lo)
        return sorted(set(np.unique(sel[exact]).tolist()) | set(np.unique(lo[~exact]).tolist())
                      | set(np.unique(hi[~exact]).tolist()))

    def flux_pi_scale(self, view_elevation_deg, sun_elevation_deg) -> np.ndarray:
        """1: ``I`` is in the unit of an incident solar flux ``pi``."""
        return np.ones(np.broadcast_shapes(np.shape(view_elevation_deg),
                                           np.shape(sun_elevation_deg)))

    def describe(self) -> dict:
        return {"model": self.name, "tau": self.tau, "tau_check": tau_check(self.tau),
                "albedo": self.albedo,
                "wavelength_nm": self.wavelength_nm,
                "pressure_hPa": self.pressure_hPa if self.wavelength_nm else None,
                "depolarization_ratio": self.depolarization_ratio,
                "n_zenith": self.n_zenith, "sun_step_deg": self.sun_step_deg,
                "sun_node_origin_deg": self.sun_node_origin_deg, "engine": "sasktran2",
                "engine_settings": self.settings.to_dict(),
                "I_normalisation": "incident solar flux pi per unit area normal to the beam "
                                   "(F = 1); diffuse sky only, direct beam excluded"}
