"""Adapter to the sasktran2 radiative-transfer engine: the diffuse sky of a Rayleigh slab.

The physical problem is the one of the Coulson-Dave-Sekera tables [1]_ [2]_: a homogeneous,
conservative Rayleigh-scattering slab of optical thickness ``tau`` over a Lambertian ground of
albedo ``A``, lit by unpolarized sunlight of flux ``pi`` per unit area normal to the beam
(``F = 1``); we want the diffuse Stokes vector transmitted to a ground observer looking up.

sasktran2 [3]_ solves it only with a particular set-up (checked against the tables, see
``docs/physical_sky.md``), which this module fixes so that a caller cannot get it wrong:

- its plane-parallel and pseudo-spherical modes compute upwelling radiance only, so the slab is
  put in **spherical** geometry on a very large planet. The ratio planet radius / slab height
  must be large (curvature of the solar path, error ~ H / (R mu0^2)) but not so large that the
  ray-shell intersections lose precision: with R = 1e9 m and a 1000 m slab (R/H = 1e6) the
  radiance shows noise of several 1e-3 from one view angle to the next at mu0 = 0.1; with
  R/H = 1e5 (R = 1e9 m, H = 1e4 m) it is smooth;
- **exact single scatter plus discrete-ordinates multiple scatter**;
- enough levels: the error of the line-of-sight quadrature falls from 1.4e-3 (51 levels) to
  4e-4 (101) to 2e-4 (201) at tau = 1, mu0 = 0.1; 101 levels are used;
- enough streams: 16 streams leave a -2e-3 to -3.6e-3 bias of I in thin slabs (tau = 0.02);
  32 streams bring it below 1e-3;
- view cosines are kept inside [1e-4, 1 - 1e-6]: exactly mu = 1 gives wrong Q, U away from the
  solar meridian, and mu = 0 returns zeros.

Stokes convention of the output: the skysim one (``docs/conventions.md``): reference direction
the local meridian (towards the zenith), ``Q > 0`` when the E-vector lies along the meridian,
``U > 0`` when it is turned from the meridian towards increasing azimuth, relative azimuth
``phi`` = view azimuth minus sun azimuth (clockwise). sasktran2's default basis for an
upward-looking observer has the same ``Q`` but the opposite ``U`` at a given ``phi`` (its
azimuth runs the other way), so ``U`` is negated here; ``tests/test_multiple.py`` checks the
result against the closed-form single-scattering sky of :mod:`skysim.rayleigh`. The
Coulson/Natraj tables (``Q = I_r - I_l``) relate as ``Q_table = -Q``, ``U_table = +U``.

References
----------
.. [1] K. L. Coulson, J. V. Dave, Z. Sekera, *Tables Related to Radiation Emerging from a
   Planetary Atmosphere with Rayleigh Scattering*, Univ. California Press (1960).
.. [2] V. Natraj, K.-F. Li, Y. L. Yung, "Rayleigh scattering in planetary atmospheres:
   corrected tables through accurate computation of X and Y functions", ApJ 691:1909 (2009),
   doi:10.1088/0004-637X/691/2/1909.
.. [3] D. J. Zawada, L. A. Rieger, A. E. Bourassa, D. A. Degenstein, "SASKTRAN2: a fast
   differentiable radiative transfer model", sasktran2 on PyPI (2023-).
.. [4] J. W. Hovenier, C. V. M. van der Mee, "Fundamental relationships relevant to the
   transfer of polarized light in a scattering atmosphere", A&A 128:1 (1983); Rayleigh
   expansion coefficients with depolarization: J. E. Hansen, L. D. Travis, Space Sci. Rev.
   16:527 (1974), eq. (2.15), doi:10.1007/BF00168069.
.. [5] W. J. Wiscombe, "The delta-M method: rapid yet accurate radiative flux calculations
   for strongly asymmetric phase functions", J. Atmos. Sci. 34:1408-1422 (1977),
   doi:10.1175/1520-0469(1977)034<1408:TDMRYA>2.0.CO;2.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .exceptions import InvalidParameterError, MissingDependencyError, SkysimWarning
from .validation import check_in_range

__all__ = [
    "DEFAULT_SETTINGS",
    "MU_MAX",
    "MU_MIN",
    "SOURCE_GRID_MU_STEP",
    "EngineSettings",
    "SasktranUnavailableError",
    "TABLE_TAU_RANGE",
    "TauBeyondTablesWarning",
    "TauOutsideVerifiedRangeError",
    "VERIFIED_TAU_RANGE",
    "ParticleLayer",
    "check_verified_tau",
    "MAX_PARTICLE_SSA",
    "delta_m_truncation",
    "layered_particle_stokes_cases",
    "particle_layer_profile",
    "layered_stokes_cases",
    "lru_take",
    "phase_f11_f12",
    "rayleigh_greek_coefficients",
    "tau_check",
    "rayleigh_depolarization_factor",
    "require_sasktran2",
    "transmitted_stokes",
    "transmitted_stokes_cases",
]

MU_MIN = 1.0e-4
"""Smallest view cosine passed to the engine (mu = 0 returns zeros): 0.006 deg above the horizon."""

MU_MAX = 1.0 - 1.0e-6
"""Largest view cosine passed to the engine (exactly mu = 1 gives wrong Q, U): 0.08 deg off zenith."""

SOURCE_GRID_MU_STEP = 0.02
"""Spacing of the view cosines (1, 0.98, 0.96, ...) at which the engine evaluates its
discrete-ordinates multiple-scatter source in this (spherical) set-up; between them the
source's azimuthal Fourier modes are interpolated linearly in the cosine. That is exact at
the nodes and close between them, except next to the zenith: a mode ``m >= 1`` of the
source vanishes as ``sin^m`` of the zenith angle (``sin`` for ``m = 1``: not a linear
function of the cosine), so for ``1 > mu > 0.98`` (11.5 deg around the zenith) the engine's
``m = 1`` multiple scatter falls linearly in the angle instead of staying proportional to
its sine: for a Rayleigh slab of tau 0.5, sun at 30 deg zenith, the ``m = 1`` multiple
scatter at 5 deg from the zenith is less than half of what it should be, 0.7 % of I.
Measured from the engine's own rays (the kinks of ``I_1 / sin(theta)`` at mu = 0.98 and
0.96, whatever the number of streams); the tables of :mod:`skysim.multiple`,
:mod:`skysim.clouds` and :mod:`skysim.aerosol` sample the engine near the zenith only at
these cosines (:func:`skysim.multiple.mode_nodes_deg`,
:func:`skysim.aerosol.table_grid`)."""


TABLE_TAU_RANGE = (1.0e-3, 1.0)
"""Optical thicknesses at which this engine set-up is checked against references: 0.02-1
against the Natraj et al. (2009) tables (DoLP to 1e-3, I to 1.4e-3; tests/test_multiple.py),
down to 1e-3 against the closed-form single-scattering limit."""

VERIFIED_TAU_RANGE = (1.0e-3, 3.0)
"""Optical thicknesses the engine accepts: :data:`TABLE_TAU_RANGE`, and beyond it up to 3
where the set-up is checked by convergence only (against 401 levels and 64 streams, sun
cosines 0.1-1: I within 2e-3, DoLP within 4e-4 at tau = 3; the quadrature error grows as
tau, 5e-3 at tau = 5 and 1.7e-2 at tau = 10, and the set-up fails silently further out: a
radiance plateau near 2e-3 for tau = 1e3-1e4, I = 4e-25 at tau = 1e6)."""


class TauOutsideVerifiedRangeError(InvalidParameterError):
    """The optical thickness lies outside :data:`VERIFIED_TAU_RANGE`, where the engine set-up
    is not verified (and is known to return wrong radiances for very thick slabs)."""


class TauBeyondTablesWarning(SkysimWarning):
    """The optical thickness lies beyond the published tables (above 1): the engine set-up is
    checked there by convergence only (:data:`VERIFIED_TAU_RANGE`)."""


def check_verified_tau(name: str, tau) -> np.ndarray:
    """Return ``tau`` as a float array; raise :class:`TauOutsideVerifiedRangeError` outside
    :data:`VERIFIED_TAU_RANGE` (and ``InvalidParameterError`` for tau <= 0 or not finite)."""
    t = check_in_range(name, tau, 0.0, np.inf, low_open=True,
                       hint="optical thickness > 0 (tau = 0 has no diffuse sky)")
    lo, hi = VERIFIED_TAU_RANGE
    bad = (t < lo) | (t > hi)
    if bad.any():
        raise TauOutsideVerifiedRangeError(
            f"{name}={float(np.asarray(t).ravel()[np.flatnonzero(bad.ravel())[0]])!r} lies "
            f"outside [{lo:g}, {hi:g}], the range in which the multiple-scattering engine "
            "set-up is verified (tables for 0.02-1, the single-scattering limit below, "
            "convergence up to 3); a Rayleigh atmosphere at sea level has tau 0.0086 at 1000 "
            "nm and 1 at 314 nm")
    return t


def tau_check(tau: float) -> str:
    """How the engine set-up is checked at ``tau``: ``"tables"`` (:data:`TABLE_TAU_RANGE`)
    or ``"convergence"`` (beyond the tables, inside :data:`VERIFIED_TAU_RANGE`)."""
    return "tables" if TABLE_TAU_RANGE[0] <= tau <= TABLE_TAU_RANGE[1] else "convergence"


class SasktranUnavailableError(MissingDependencyError):
    """The optional radiative-transfer engine sasktran2 is not installed.

    Fix: install the ``rt`` extra from the skysim checkout,
    ``python -m pip install -e '.[rt]'`` (the message gives the exact command).
    """


@dataclass(frozen=True)
class EngineSettings:
    """Numerical set-up of the sasktran2 run (see the module docstring for why each value).

    Attributes
    ----------
    n_streams : int
        Discrete-ordinates streams over the full sphere (even, >= 4).
    n_levels : int
        Altitude levels of the slab (>= 51: fewer make the line-of-sight quadrature err by
        more than 1e-3; 2 levels overestimate I by 10-21 %).
    slab_height_m : float
        Geometric thickness of the homogeneous slab [m].
    planet_radius_m : float
        Radius of the (nearly flat) planet [m]; ``planet_radius_m / slab_height_m`` must lie in
        [1e4, 1e6] (curvature error below, round-off noise above).
    """

    n_streams: int = 32
    n_levels: int = 101
    slab_height_m: float = 1.0e4
    planet_radius_m: float = 1.0e9

    def __post_init__(self):
        if self.n_streams < 4 or self.n_streams % 2:
            raise InvalidParameterError(
                f"n_streams must be an even number >= 4; got {self.n_streams}. Use 32 (default).")
        if self.n_levels < 51:
            raise InvalidParameterError(
                f"n_levels must be >= 51 (fewer levels bias the radiance by > 1e-3); got "
                f"{self.n_levels}. Use 101 (default).")
        ratio = self.planet_radius_m / self.slab_height_m
        if not 1e4 <= ratio <= 1e6:
            raise InvalidParameterError(
                f"planet_radius_m / slab_height_m must lie in [1e4, 1e6]; got {ratio:.3g}. "
                "Use the defaults (1e9 m, 1e4 m).")

    def to_dict(self) -> dict:
        return asdict(self)


DEFAULT_SETTINGS = EngineSettings()


def lru_take(cache, keys, max_size: int) -> list:
    """The values of ``keys`` in the ordered dict ``cache`` (all present), marked as used
    most recently; then the least recently used entries beyond ``max_size`` are dropped.
    The per-process cache of engine results (Fourier modes, aerosol tables)."""
    for key in keys:
        cache.move_to_end(key)
    out = [cache[k] for k in keys]
    while len(cache) > max_size:
        cache.popitem(last=False)
    return out


def require_sasktran2():
    """Import and return :mod:`sasktran2`, or raise :class:`SasktranUnavailableError`."""
    try:
        import sasktran2
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        from .extras import missing_extra_message
        raise SasktranUnavailableError(
            missing_extra_message("sasktran2", "the multiple-scattering sky (radiative-transfer "
                                  "engine)"), name="sasktran2") from exc
    return sasktran2


def rayleigh_depolarization_factor(depolarization_ratio) -> float:
    """Rayleigh phase-matrix factor ``Delta = (1 - rho) / (1 + rho / 2)``.

    Hansen & Travis (1974), eq. (2.15) [4]_: with molecular anisotropy the Rayleigh phase matrix
    is ``Delta`` times the pure Rayleigh matrix plus ``(1 - Delta)`` times isotropic
    unpolarizing scattering, so the single-scattering maximum DoP is ``(1 - rho)/(1 + rho)``.

    Parameters
    ----------
    depolarization_ratio : float
        ``rho`` in [0, 0.5); air: ~0.028 (Bodhaine et al. 1999), the tables: 0.
    """
    rho = float(check_in_range("depolarization_ratio", depolarization_ratio, 0.0, 0.5,
                               high_open=True, hint="air has ~0.028; the tables use 0"))
    return (1.0 - rho) / (1.0 + rho / 2.0)


def transmitted_stokes(tau: float, albedo: float, mu0: float, mu, phi_deg, *,
                       depolarization_ratio: float = 0.0,
                       settings: EngineSettings = DEFAULT_SETTINGS):
    """Diffuse Stokes ``(I, Q, U)`` seen from the ground, one engine call for all directions.

    Parameters
    ----------
    tau : float
        Optical thickness of the slab, >= 0 (0 returns zeros: no diffuse sky).
    albedo : float
        Lambertian ground albedo in [0, 1].
    mu0 : float
        Cosine of the solar zenith angle, in (0, 1].
    mu : array-like
        Cosine of the view zenith angle (looking up), in [0, 1]; clipped into
        [:data:`MU_MIN`, :data:`MU_MAX`] before the engine call (see module docstring).
    phi_deg : array-like
        Relative azimuth [deg]: view azimuth minus sun azimuth, clockwise; 0 looks towards the
        sun's azimuth. Broadcast with ``mu``.
    depolarization_ratio : float
        Molecular depolarization ratio rho (0 for the tables).
    settings : EngineSettings

    Returns
    -------
    I, Q, U : ndarray
        Stokes parameters normalised to an incident solar flux ``pi`` per unit area normal to
        the beam (the tables' normalisation: ``I`` is radiance / (F) with ``pi F`` the flux),
        direct beam excluded, in the skysim basis (module docstring).
    """
    tau = float(check_in_range("tau", tau, 0.0, np.inf, hint="optical thickness is >= 0"))
    albedo = float(check_in_range("albedo", albedo, 0.0, 1.0))
    mu0 = float(check_in_range("mu0", mu0, 0.0, 1.0, low_open=True,
                               hint="the sun must be above the horizon"))
    mu = check_in_range("mu", mu, 0.0, 1.0, hint="the diffuse sky is seen looking up")
    mu, phi = np.broadcast_arrays(mu, np.asarray(phi_deg, dtype=float))
    if tau == 0.0:
        z = np.zeros(mu.shape)
        return z, z.copy(), z.copy()
    stokes = transmitted_stokes_cases([tau], [albedo], mu0, mu.ravel(), phi.ravel(),
                                      depolarization_ratio=depolarization_ratio,
                                      settings=settings)[0]
    shape = mu.shape
    return stokes[:, 0].reshape(shape), stokes[:, 1].reshape(shape), stokes[:, 2].reshape(shape)


def _check_geometry(mu0, mu, phi_deg):
    """Validated sun cosine (float) and broadcast 1-d view cosines and relative azimuths."""
    mu0 = float(check_in_range("mu0", mu0, 0.0, 1.0, low_open=True,
                               hint="the sun must be above the horizon"))
    mu, phi = np.broadcast_arrays(np.atleast_1d(check_in_range("mu", mu, 0.0, 1.0)),
                                  np.atleast_1d(np.asarray(phi_deg, dtype=float)))
    return mu0, mu, phi


def _engine_setup(sk, settings: EngineSettings, mu0: float, mu, phi, altitudes):
    """Config (exact single scatter, discrete-ordinates multiple scatter, 3 Stokes), the
    large-planet spherical geometry on ``altitudes`` [m] and the upward rays of the set-up in
    the module docstring."""
    cfg = sk.Config()
    cfg.num_stokes = 3
    cfg.single_scatter_source = sk.SingleScatterSource.Exact
    cfg.multiple_scatter_source = sk.MultipleScatterSource.DiscreteOrdinates
    cfg.num_streams = settings.n_streams
    geometry = sk.Geometry1D(mu0, 0.0, settings.planet_radius_m, altitudes,
                             sk.InterpolationMethod.LinearInterpolation,
                             sk.GeometryType.Spherical)
    viewing = sk.ViewingGeometry()
    for m, p in zip(np.clip(np.ravel(mu), MU_MIN, MU_MAX), np.radians(np.ravel(phi))):
        viewing.add_ray(sk.SolarAnglesObserverLocation(mu0, float(p), float(m), 0.0))
    return cfg, geometry, viewing


def _stokes_of(sk, cfg, geometry, viewing, atmosphere) -> np.ndarray:
    """Run the engine; Stokes ``(cases, rays, 3)`` in the skysim basis, incident flux pi."""
    radiance = sk.Engine(cfg, geometry, viewing).calculate_radiance(atmosphere)
    stokes = np.pi * np.asarray(radiance.radiance.values, dtype=float)  # (m, n, 3): I, Q, U
    stokes[..., 2] *= -1.0  # sasktran2's U has the opposite sense to skysim's (module docstring)
    return stokes


def transmitted_stokes_cases(taus, albedos, mu0: float, mu, phi_deg, *,
                             depolarization_ratio: float = 0.0,
                             settings: EngineSettings = DEFAULT_SETTINGS) -> np.ndarray:
    """Diffuse Stokes for many ``(tau, albedo)`` cases at one sun, in one engine call.

    Each case is one "wavelength" of the engine (the optical properties are per wavelength);
    the set-up, normalisation and basis are those of :func:`transmitted_stokes`, which is the
    single-case form of this function.

    Parameters
    ----------
    taus, albedos : array-like (m,)
        Optical thickness (> 0) and Lambertian albedo in [0, 1] of each case.
    mu0 : float
        Cosine of the solar zenith angle, in (0, 1].
    mu, phi_deg : array-like (n,)
        View cosines and relative azimuths [deg], as :func:`transmitted_stokes`.

    Returns
    -------
    ndarray (m, n, 3)
        ``I, Q, U`` of each case and direction (skysim basis, incident flux ``pi``).

    Raises
    ------
    TauOutsideVerifiedRangeError
        For a tau outside :data:`VERIFIED_TAU_RANGE`.
    """
    taus, albedos = np.broadcast_arrays(np.atleast_1d(np.asarray(taus, float)),
                                        np.atleast_1d(np.asarray(albedos, float)))
    check_verified_tau("taus", taus)
    check_in_range("albedos", albedos, 0.0, 1.0)
    mu0, mu, phi = _check_geometry(mu0, mu, phi_deg)
    delta = rayleigh_depolarization_factor(depolarization_ratio)
    greek = rayleigh_greek_coefficients(delta, max(16, settings.n_streams))
    return layered_stokes_cases(taus, np.ones((taus.size, settings.n_levels)),
                                np.broadcast_to(greek, (taus.size, settings.n_levels)
                                                + greek.shape),
                                albedos, mu0, mu, phi, settings=settings)


def rayleigh_greek_coefficients(delta: float, n_moments: int) -> np.ndarray:
    """Generalised-spherical-function expansion of the Rayleigh phase matrix ([4]_).

    Non-zero coefficients: ``alpha1_0 = 1``, ``alpha1_2 = Delta/2``, ``alpha2_2 = 3 Delta``,
    ``beta1_2 = sqrt(6) Delta / 2`` (``alpha3 = 0``; ``alpha4`` only acts on V).

    Returns
    -------
    ndarray (n_moments, 4)
        Columns ``alpha1, alpha2, alpha3, beta1`` (sasktran2's order and sign convention).
    """
    g = np.zeros((int(n_moments), 4))
    g[0, 0] = 1.0
    g[2, 0] = delta / 2.0
    g[2, 1] = 3.0 * delta
    g[2, 3] = np.sqrt(6.0) * delta / 2.0
    return g


def phase_f11_f12(greek, cos_scattering) -> tuple[np.ndarray, np.ndarray]:
    """Phase-matrix elements ``F11`` and ``F12`` from Greek coefficients, at scattering-angle
    cosines.

    ``F11 = sum_l alpha1_l P_l(x)`` and ``F12 = sum_l beta1_l P^l_02(x)`` (Hovenier & van
    der Mee 1983 [4]_; de Rooij & van der Stap 1984, A&A 131:237), ``P_l`` the Legendre
    polynomials and ``P^l_02`` the generalised spherical functions, by their three-term
    recurrences: ``(l + 1) P_{l+1} = (2l + 1) x P_l - l P_{l-1}`` and
    ``sqrt((l+1)^2 - 4) P^{l+1}_02 = (2l + 1) x P^l_02 - sqrt(l^2 - 4) P^{l-1}_02`` from
    ``P^2_02 = (sqrt(6) / 4)(1 - x^2)``. In the engine's convention (``alpha1_0 = 1``:
    ``F11`` averages to 1 over the sphere) ``F12 > 0`` is light polarized perpendicular to
    the scattering plane (Rayleigh: ``F12 = (3/4) Delta sin^2``,
    :func:`rayleigh_greek_coefficients`).

    Parameters
    ----------
    greek : array-like (n_moments, 4)
        ``alpha1, alpha2, alpha3, beta1`` (only ``alpha1`` and ``beta1`` enter).
    cos_scattering : array-like
        Cosines of the scattering angle, in [-1, 1].

    Returns
    -------
    F11, F12 : ndarray, the shape of ``cos_scattering``.
    """
    g = np.asarray(greek, float)
    x = np.clip(np.asarray(cos_scattering, float), -1.0, 1.0)
    a1, b1 = g[:, 0], g[:, 3]
    p_prev, p = np.ones_like(x), x.copy()
    f11 = a1[0] * p_prev + (a1[1] * p if a1.size > 1 else 0.0)
    for l in range(1, a1.size - 1):
        p_prev, p = p, ((2 * l + 1) * x * p - l * p_prev) / (l + 1)
        f11 += a1[l + 1] * p
    f12 = np.zeros_like(x)
    if b1.size > 2:
        q_prev, q = np.zeros_like(x), (np.sqrt(6.0) / 4.0) * (1.0 - x * x)
        f12 += b1[2] * q
        for l in range(2, b1.size - 1):
            q_prev, q = q, (((2 * l + 1) * x * q - np.sqrt(l * l - 4.0) * q_prev)
                            / np.sqrt((l + 1.0) ** 2 - 4.0))
            f12 += b1[l + 1] * q
    return f11, f12


def layered_stokes_cases(taus, ssa, greek, albedos, mu0: float, mu, phi_deg, *,
                         settings: EngineSettings = DEFAULT_SETTINGS,
                         delta_m: bool = False, multiple_scatter: bool = True) -> np.ndarray:
    """Diffuse Stokes of slabs whose scattering properties vary with optical depth, several
    cases (one engine "wavelength" each) at one sun in one engine call.

    The slab is the homogeneous one of :func:`transmitted_stokes` in *total* extinction:
    its ``settings.n_levels`` levels are equally spaced in optical depth (``taus / (n - 1)``
    per layer, the set-up checked against the tables), level 0 at the ground. In a
    plane-parallel atmosphere only the optical-depth coordinate matters, so any vertical
    profile enters through the single-scattering albedo and phase matrix given per level.

    Parameters
    ----------
    taus : array-like (m,)
        Total optical thickness of each case, in :data:`VERIFIED_TAU_RANGE`.
    ssa : array-like (m, n_levels)
        Single-scattering albedo per case and level (level 0 at the ground), in [0, 1].
    greek : array-like (m, n_levels, n_moments, 4)
        Greek coefficients ``alpha1, alpha2, alpha3, beta1`` per moment ``l`` (sasktran2's
        convention, ``alpha1_0 = 1``; :func:`rayleigh_greek_coefficients` is an example).
        ``n_moments`` (>= ``settings.n_streams``) moments are used by the exact single
        scatter; the discrete-ordinates multiple scatter uses the first ``n_streams``.
    albedos : array-like (m,)
        Lambertian ground albedo of each case, in [0, 1].
    mu0, mu, phi_deg
        As :func:`transmitted_stokes_cases`.
    settings : EngineSettings
    delta_m : bool
        Delta-M scaling of the multiple-scatter phase matrices to ``n_streams`` moments
        (Wiscombe 1977, J. Atmos. Sci. 34:1408,
        doi:10.1175/1520-0469(1977)034<1408:TDMRYA>2.0.CO;2), for forward-peaked (aerosol)
        phase functions.
    multiple_scatter : bool
        False: the engine's exact single scatter alone (no multiple-scatter source).

    Returns
    -------
    ndarray (m, n, 3)
        ``I, Q, U`` (skysim basis, incident flux ``pi``, direct beam excluded).
    """
    taus = np.atleast_1d(np.asarray(taus, float))
    check_verified_tau("taus", taus)
    albedos = np.broadcast_to(np.asarray(albedos, float), taus.shape)
    check_in_range("albedos", albedos, 0.0, 1.0)
    ssa = check_in_range("ssa", ssa, 0.0, 1.0)
    greek = np.asarray(greek, dtype=float)
    m, n_levels = taus.size, settings.n_levels
    if ssa.shape != (m, n_levels) or greek.shape[:2] != (m, n_levels) or greek.shape[3] != 4:
        raise InvalidParameterError(
            f"ssa must have shape ({m}, {n_levels}) and greek ({m}, {n_levels}, n_moments, 4) "
            f"for {m} case(s) and settings.n_levels = {n_levels}; got {ssa.shape} and "
            f"{greek.shape}")
    n_moments = greek.shape[2]
    if n_moments < settings.n_streams:
        raise InvalidParameterError(f"greek has {n_moments} moments; at least n_streams = "
                                    f"{settings.n_streams} are needed")
    mu0, mu, phi = _check_geometry(mu0, mu, phi_deg)
    sk = require_sasktran2()
    altitudes = np.linspace(0.0, settings.slab_height_m, n_levels)
    cfg, geometry, viewing = _engine_setup(sk, settings, mu0, mu, phi, altitudes)
    if not multiple_scatter:
        cfg.multiple_scatter_source = sk.MultipleScatterSource.NoSource
    cfg.num_singlescatter_moments = n_moments
    cfg.delta_m_scaling = bool(delta_m)
    atmosphere = sk.Atmosphere(geometry, cfg, numwavel=m, calculate_derivatives=False)
    atmosphere.storage.total_extinction[:] = taus[None, :] / settings.slab_height_m
    atmosphere.storage.ssa[:] = ssa.T
    view = sk.polarization.LegendreStorageView(atmosphere.storage.leg_coeff, 3)
    for k, target in enumerate((view.a1, view.a2, view.a3, view.b1)):
        target[:] = np.transpose(greek[..., k], (2, 1, 0))  # (moment, level, case)
    atmosphere.surface.albedo[:] = albedos
    return _stokes_of(sk, cfg, geometry, viewing, atmosphere)


# --------------------------------------------------------------------------------------------
# A particle layer (cloud) inside the Rayleigh slab
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ParticleLayer:
    """Optical properties of a homogeneous particle layer for the engine.

    Attributes
    ----------
    base_fraction, top_fraction : float
        Bottom and top of the layer as fractions of the Rayleigh optical thickness below them
        (0 at the ground, 1 at the top of the atmosphere), ``0 <= base < top <= 1``: the slab
        is homogeneous in Rayleigh extinction, so a fraction places the layer in optical depth.
    single_scattering_albedo : float
        Single-scattering albedo of the particles, in (0, 1].
    greek : ndarray (4, L)
        Greek (generalised-spherical-function) coefficients ``a1, a2, a3, b1`` of the
        particles' phase matrix, ``a1[0] = 1`` (Hovenier & van der Mee 1983 [4]_), in the
        engine's convention (as ``sasktran2.mie.integrate_mie`` returns them).
    """

    base_fraction: float
    top_fraction: float
    single_scattering_albedo: float
    greek: np.ndarray

    def __post_init__(self):
        if not 0.0 <= self.base_fraction < self.top_fraction <= 1.0:
            raise InvalidParameterError(
                f"the particle layer must satisfy 0 <= base < top <= 1 (fractions of the "
                f"Rayleigh optical depth); got base={self.base_fraction!r}, "
                f"top={self.top_fraction!r}")
        check_in_range("single_scattering_albedo", self.single_scattering_albedo, 0.0, 1.0,
                       low_open=True)
        g = np.asarray(self.greek, float)
        if g.ndim != 2 or g.shape[0] != 4 or abs(g[0, 0] - 1.0) > 1e-3:
            raise InvalidParameterError(
                f"greek must have shape (4, L) with a1[0] = 1; got shape {g.shape}")


MAX_PARTICLE_SSA = 1.0 - 1e-4
"""Largest single-scattering albedo given to the engine for a particle layer. Water droplets
scatter almost conservatively (``1 - w`` about 5e-7 at 550 nm); at such albedos the
discrete-ordinates solution of a droplet layer, whose delta-M-truncated phase function keeps
an eigenvalue ``k^2 ~ 3 (1 - w)(1 - g')`` within the engine's round-off of zero, breaks down:
with ``1 - w = 1e-5`` the transmittance is 0.88 instead of 0.84 at cloud optical thickness
2, 1.08 at 5, 11 at 10 and negative at 20 (16 or 32 streams alike;
in the engine's scalar mode "an homogeneous solution was found to be imaginary"), while a
Henyey-Greenstein layer of the same scaled asymmetry parameter stays sound. With
``1 - w = 1e-4`` it is stable, within 0.2 % of 32 streams with 16, and absorbs 0.05 % of
the transmitted flux at optical thickness 2 and 0.6 % at 20 (linear in ``1 - w`` between
1e-4 and 1e-3: 0.3335, 0.3252, 0.3162 at 1e-4, 5e-4, 1e-3); ``tests/test_clouds.py``."""


_LEBEDEV_SIZES = (6, 14, 26, 38, 50, 74, 86, 110, 146, 170, 194, 230, 266, 302, 350, 434, 590,
                  770, 974, 1202, 1454, 1730, 2030, 2354, 2702, 3074, 3470, 3890)
"""Quadrature sizes the engine's successive orders accept (its incoming and outgoing rules)."""


def delta_m_truncation(greek, n_streams: int):
    """Delta-M truncation of a phase matrix's Greek coefficients (Wiscombe 1977 [5]_).

    The forward peak beyond the first ``n_streams`` moments is cut off as a fraction
    ``f = a1[n_streams] / (2 n_streams + 1)`` of the scattering, which the caller counts as
    unscattered (``tau' = (1 - w f) tau``, ``w' = w (1 - f) / (1 - w f)``); the kept moments
    become ``(a_l - f (2l + 1)) / (1 - f)`` for ``a1, a2, a3`` and ``b1 / (1 - f)``, the
    vector form of Hovenier & van der Mee [4]_ used by sasktran2's own manual constituent.

    Parameters
    ----------
    greek : ndarray (4, L)
        ``a1, a2, a3, b1``.
    n_streams : int
        Moments kept (``L > n_streams``; otherwise nothing is truncated and ``f = 0``).

    Returns
    -------
    greek_truncated : ndarray (4, min(L, n_streams))
    f : float
        Truncated fraction of the scattering.
    """
    g = np.asarray(greek, float)
    n = int(n_streams)
    if g.shape[1] <= n:
        return g.copy(), 0.0
    f = float(g[0, n] / (2 * n + 1))
    out = g[:, :n].copy()
    two_l1 = 2.0 * np.arange(n) + 1.0
    out[:3] = (out[:3] - f * two_l1) / (1.0 - f)
    out[3] = out[3] / (1.0 - f)
    return out, f


def particle_layer_profile(tau: float, particle_taus, layer: ParticleLayer,
                           settings: EngineSettings = DEFAULT_SETTINGS,
                           max_layer_tau: float | None = None):
    """The engine's altitude levels and extinction profiles of a Rayleigh slab holding a
    particle layer (:func:`layered_particle_stokes_cases`).

    The slab's ``settings.n_levels`` equally spaced levels plus levels through the layer;
    the particle extinction is constant on the levels inside the layer and zero outside, so
    under the engine's linear interpolation between levels it ramps up over the level
    interval below the base and down over the one above the top, and is scaled so that the
    layer's optical thickness (trapezoid rule: exact for linear interpolation) is the case's.
    ``max_layer_tau`` [1], if given: at least as many levels inside the layer as keep each
    level interval there at most that optical thickness in the thickest case, and the two
    edge ramps as narrow as those intervals (by default they span a slab interval each, and
    hold up to 0.9 of a cloud of optical thickness 20 with 101 levels).

    Returns
    -------
    altitudes : ndarray (n,)
        Levels [m], increasing from 0 to ``settings.slab_height_m``.
    k_r : ndarray (n, 1)
        Rayleigh extinction [1/m].
    k_p : ndarray (n, m)
        Particle extinction [1/m] of each case.
    """
    ptau = np.atleast_1d(np.asarray(particle_taus, float))
    H = settings.slab_height_m
    base, top = layer.base_fraction * H, layer.top_fraction * H
    n_inside = max(11, settings.n_levels // 5)
    if max_layer_tau is not None:
        check_in_range("max_layer_tau", max_layer_tau, 0.0, np.inf, low_open=True)
        n_inside = max(n_inside, int(np.ceil(float(ptau.max(initial=0.0)) / max_layer_tau)) + 1)
    inside = np.linspace(base, top, n_inside)
    if max_layer_tau is not None:
        # the edge ramps as thin as the intervals inside
        step = (top - base) / (n_inside - 1)
        inside = np.concatenate([inside, np.clip([base - step, top + step], 0.0, H)])
    altitudes = np.unique(np.concatenate([np.linspace(0.0, H, settings.n_levels), inside]))
    in_layer = ((altitudes >= base) & (altitudes <= top)).astype(float)
    # optical thickness of a unit-extinction profile under linear interpolation (trapezoid)
    unit_tau = float(np.sum(0.5 * (in_layer[1:] + in_layer[:-1]) * np.diff(altitudes)))
    k_r = np.full((altitudes.size, 1), float(tau) / H)
    k_p = in_layer[:, None] * (ptau[None, :] / unit_tau)                    # (levels, cases)
    return altitudes, k_r, k_p


def layered_particle_stokes_cases(tau: float, albedo: float, particle_taus,
                                  layer: ParticleLayer, mu0: float, mu, phi_deg, *,
                                  depolarization_ratio: float = 0.0,
                                  settings: EngineSettings = DEFAULT_SETTINGS,
                                  multiple_scatter: bool = True,
                                  successive_orders: bool = False,
                                  successive_orders_directions: int = 110,
                                  max_layer_tau: float | None = None) -> np.ndarray:
    """Diffuse Stokes below a Rayleigh slab holding a particle layer, one engine call for
    several particle optical thicknesses (each case one "wavelength" of the engine).

    The slab and its set-up are those of :func:`transmitted_stokes_cases`; between
    ``layer.base_fraction`` and ``layer.top_fraction`` of its height the particles add
    extinction (scaled so that the layer's optical thickness is exactly the case's, under
    the engine's linear interpolation between levels) and their phase matrix, mixed with the
    Rayleigh one in proportion to the scattering extinction of each. The engine's delta-M
    scaling (:func:`delta_m_truncation`, Wiscombe 1977 [5]_) cuts the forward peak of large
    particles to ``settings.n_streams`` moments for the multiple scatter; the single scatter
    uses the whole expansion. The particles' single-scattering albedo is capped at
    :data:`MAX_PARTICLE_SSA` (the engine's solution of a conservative droplet layer is
    unstable). Verified for droplet layers up to an optical thickness of 20
    (``tests/test_clouds.py``: transmitted flux against the delta-Eddington and the
    asymptotic theory of thick layers, radiance against DISORT within 3.4 % at cloud optical
    thickness 1-20).

    Parameters
    ----------
    tau, albedo : float
        Rayleigh optical thickness (in :data:`VERIFIED_TAU_RANGE`) and Lambertian albedo.
    particle_taus : array-like (m,)
        Optical thickness of the particle layer of each case, >= 0.
    layer : ParticleLayer
    mu0, mu, phi_deg, depolarization_ratio, settings
        As :func:`transmitted_stokes_cases`.
    multiple_scatter : bool
        False: the engine's single scatter alone (its exact single-scatter source with the
        whole phase expansion; no multiple-scatter source).
    successive_orders : bool
        True: the multiple scatter from the engine's successive orders of scattering instead
        of its discrete ordinates (a different solver of the same atmosphere, for checks;
        some ten times slower). Under a water cloud it converges only for a phase matrix
        truncated beforehand (:func:`delta_m_truncation`; with the engine's own delta-M
        scaling its first order keeps the whole forward peak, which its directions alias:
        the radiance grows 1.2-1.9 times from 230 to 434 directions) and with 434 or more
        directions (434 to 590 change the radiance by up to 2.2 %, the DoP by 7e-3; 590
        take 11 GB of memory). Even then its DoP is up to 0.011 low in the clear Rayleigh
        sky of optical thickness 1 against the tables of Natraj et al. (2009) (0.1 at the
        zenith), and under clouds of optical thickness 10-20 its radiance depends on how
        the cloud's edges are resolved (from 13 % below to 10 % above the discrete
        ordinates, which agree with DISORT within 2 %; ``docs/clouds.md``).
    successive_orders_directions : int
        Directions of the successive orders' incoming and outgoing quadratures (one of the
        engine's Lebedev sizes: 110, 230, 434, 590, ...); the cost grows about as its 1.5th
        power.
    max_layer_tau : float, optional
        Largest optical thickness of a level interval inside the particle layer
        (:func:`particle_layer_profile`); the discrete ordinates do not need it (they solve
        each homogeneous interval exactly), the successive orders do.

    Returns
    -------
    ndarray (m, n, 3)
        ``I, Q, U`` (skysim basis, incident flux ``pi``, direct beam excluded).
    """
    check_verified_tau("tau", tau)
    if successive_orders and int(successive_orders_directions) not in _LEBEDEV_SIZES:
        raise InvalidParameterError(
            f"successive_orders_directions={successive_orders_directions!r} is not one of the "
            f"engine's quadrature sizes {_LEBEDEV_SIZES}")
    ptau = np.atleast_1d(check_in_range("particle_taus", particle_taus, 0.0, np.inf,
                                        hint="optical thickness is >= 0"))
    check_in_range("albedo", albedo, 0.0, 1.0)
    mu0, mu, phi = _check_geometry(mu0, mu, phi_deg)
    delta = rayleigh_depolarization_factor(depolarization_ratio)
    greek = np.asarray(layer.greek, float)
    n_moments = max(greek.shape[1], settings.n_streams + 1)
    w_p = min(float(layer.single_scattering_albedo), MAX_PARTICLE_SSA)
    sk = require_sasktran2()
    altitudes, k_r, k_p = particle_layer_profile(tau, ptau, layer, settings, max_layer_tau)
    cfg, geometry, viewing = _engine_setup(sk, settings, mu0, mu, phi, altitudes)
    if not multiple_scatter:
        cfg.multiple_scatter_source = sk.MultipleScatterSource.NoSource
    elif successive_orders:
        cfg.multiple_scatter_source = sk.MultipleScatterSource.SuccessiveOrders
        cfg.init_successive_orders_with_discrete_ordinates = False
        cfg.num_successive_orders_incoming = int(successive_orders_directions)
        cfg.num_successive_orders_outgoing = int(successive_orders_directions)
    cfg.delta_m_scaling = True
    cfg.num_singlescatter_moments = n_moments
    atmosphere = sk.Atmosphere(geometry, cfg, numwavel=ptau.size, calculate_derivatives=False)
    atmosphere.storage.total_extinction[:] = k_r + k_p
    scat = k_r + w_p * k_p
    atmosphere.storage.ssa[:] = scat / (k_r + k_p)
    share = (w_p * k_p / scat)[None]                                          # (1, lev, case)
    rayleigh = rayleigh_greek_coefficients(delta, cfg.num_singlescatter_moments).T
    particle = np.zeros_like(rayleigh)
    particle[:, :greek.shape[1]] = greek
    view = sk.polarization.LegendreStorageView(atmosphere.storage.leg_coeff, 3)
    for k, target in enumerate((view.a1, view.a2, view.a3, view.b1)):
        target[:] = ((1.0 - share) * rayleigh[k][:, None, None]
                     + share * particle[k][:, None, None])
    atmosphere.surface.albedo[:] = float(albedo)
    return _stokes_of(sk, cfg, geometry, viewing, atmosphere)
