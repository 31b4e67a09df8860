"""Aerosol sky: Rayleigh + aerosol multiple scattering over a Lambertian ground (sasktran2).

The clear molecular sky (:mod:`skysim.multiple`) is more polarized than the real one and its
neutral points lie closer to the sun and anti-sun. Aerosol scattering, strongly forward
peaked and weakly polarizing, lowers the degree of polarization and moves the neutral points
outwards (Coulson 1988 [1]_, ch. 5; measured: Kreuter, Emde & Blumthaler 2010 [2]_).

Model
-----
A plane-parallel atmosphere of Rayleigh scatterers (optical thickness from Bodhaine et al.
1999 at the wavelength and surface pressure, scale height :data:`RAYLEIGH_SCALE_HEIGHT_KM`)
and one aerosol type (:mod:`skysim.aerosol_types`: OPAC mixtures of log-normal components,
Mie optics by sasktran2) with an exponential extinction profile of the type's scale height,
over a Lambertian ground. The aerosol optical depth is given at 550 nm; at other wavelengths
it follows the Mie extinction of the type (its Angstrom behaviour). Solved by sasktran2
(exact single scatter with :data:`skysim.aerosol_types.N_MOMENTS` Greek moments,
discrete-ordinates multiple scatter with delta-M scaling), in the slab set-up of
:mod:`skysim.rt_sasktran` whose levels are equally spaced in total optical depth: the
profile enters as the aerosol fraction of the extinction at each level
(:func:`aerosol_fraction_levels`).

Speed
-----
The aerosol phase function is forward peaked: the singly scattered light falls by orders of
magnitude over the first degrees from the sun, which no table of a few tens of directions
follows. It is computed in closed form at every direction (:class:`SingleScatter`: the
engine's single scatter, line-of-sight weights per view angle times the phase matrix at the
exact scattering angle). What remains, light scattered at least twice, is smooth (the
engine's multiple scatter sees the phase function truncated to ``n_streams`` moments); the
engine is called once per (sun elevation; all AODs and albedos of a batch together) on a
grid of view zenith angles x relative azimuths, and that remainder is interpolated as
azimuthal Fourier modes (:class:`AerosolTable`). Grid and error: ``docs/physical_sky.md``,
tested in ``tests/test_aerosol.py`` and ``tests/test_tabled_skies.py``.

Units: ``I`` (and Q, U) are normalised to an incident solar flux ``pi`` per unit area normal
to the beam, direct beam excluded, as in :mod:`skysim.multiple`; Stokes basis and AoP as in
``docs/conventions.md``.

References
----------
.. [1] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak
   (1988).
.. [2] A. Kreuter, C. Emde, M. Blumthaler, "Measuring the influence of aerosols and albedo
   on sky polarization", Atmos. Res. 98:363-367 (2010),
   doi:10.1016/j.atmosres.2010.07.011.
.. [3] B. A. Bodhaine, N. B. Wood, E. G. Dutton, J. R. Slusser, J. Atmos. Oceanic Technol.
   16:1854-1861 (1999), doi:10.1175/1520-0426(1999)016<1854:ORODC>2.0.CO;2.
.. [4] T. Nakajima, M. Tanaka, "Algorithms for radiative intensity calculations in
   moderately thick atmospheres using a truncation approximation", J. Quant. Spectrosc.
   Radiat. Transfer 40:51-69 (1988), doi:10.1016/0022-4073(88)90031-3.
"""

from __future__ import annotations

import functools
from collections import OrderedDict

import numpy as np

from .aerosol_types import (N_MOMENTS, REFERENCE_WAVELENGTH_NM, AerosolType, aerosol_optics,
                            aerosol_type)
from .exceptions import InvalidParameterError
from .rt_sasktran import (DEFAULT_SETTINGS, EngineSettings, layered_stokes_cases, lru_take,
                          phase_f11_f12, rayleigh_depolarization_factor,
                          rayleigh_greek_coefficients)
from .sky import Sky
from .validation import check_finite, check_in_range

__all__ = ["AOD_RANGE", "AerosolSky", "AerosolTable", "AerosolType", "N_AZIMUTH", "N_ZENITH",
           "RAYLEIGH_SCALE_HEIGHT_KM", "SingleScatter", "aerosol_fraction_levels",
           "aerosol_single_scatter_cases", "aerosol_stokes_cases", "aerosol_tables_cases",
           "clear_tables_cache", "prefetch_tables", "table_grid"]

RAYLEIGH_SCALE_HEIGHT_KM = 8.0
"""Scale height of the molecular extinction [km] (US Standard Atmosphere 1976, lower
troposphere)."""

AOD_RANGE = (0.0, 2.0)
"""Aerosol optical depths at 550 nm accepted [1]."""


def aerosol_fraction_levels(tau_rayleigh: float, tau_aerosol, scale_height_km: float,
                            n_levels: int,
                            rayleigh_scale_height_km: float = RAYLEIGH_SCALE_HEIGHT_KM):
    """Aerosol share of the extinction at levels equally spaced in total optical depth.

    With exponential extinction profiles ``k_x(z) = (tau_x / H_x) exp(-z / H_x)`` of the
    molecules (R) and the aerosol (A), the optical depth above height ``z`` is
    ``C(z) = tau_R exp(-z/H_R) + tau_A exp(-z/H_A)``. Level ``k`` (0 at the ground) lies at
    ``C(z_k) = (tau_R + tau_A) (1 - k / (n - 1))``, and its aerosol share is
    ``k_A / (k_A + k_R)`` at ``z_k`` (the top level: the limit ``z -> inf``).

    Parameters
    ----------
    tau_rayleigh : float
        Molecular optical thickness (> 0).
    tau_aerosol : array-like (m,)
        Aerosol optical thickness at the wavelength, >= 0.
    scale_height_km, rayleigh_scale_height_km : float
        Scale heights [km] of the aerosol and the molecular extinction.
    n_levels : int

    Returns
    -------
    ndarray (m, n_levels)
        Aerosol fraction of the extinction in [0, 1].
    """
    from scipy.special import expit
    tau_a = np.atleast_1d(np.asarray(tau_aerosol, dtype=float))
    h_a, h_r = float(scale_height_km), float(rayleigh_scale_height_km)
    z = np.concatenate([[0.0], np.geomspace(1e-4, 60.0 * max(h_a, h_r), 4000)])  # [km]
    k = np.arange(int(n_levels)) / (int(n_levels) - 1)
    out = np.empty((tau_a.size, int(n_levels)))
    for i, ta in enumerate(tau_a):  # a few AOD cases per engine call
        if ta == 0.0:
            out[i] = 0.0
            continue
        column = tau_rayleigh * np.exp(-z / h_r) + ta * np.exp(-z / h_a)
        zk = np.interp((tau_rayleigh + ta) * (1.0 - k), column[::-1], z[::-1])
        log_ratio = np.log(ta * h_r / (tau_rayleigh * h_a)) + zk * (1.0 / h_r - 1.0 / h_a)
        out[i] = expit(log_ratio)
        out[i, -1] = float(h_a > h_r) if h_a != h_r else expit(log_ratio[-1])
    return out


def _slab_optics(aods_550, preset, wavelength_nm: float, pressure_hPa: float,
                 depolarization_ratio: float, settings: EngineSettings, n_moments: int):
    """The slab of :func:`aerosol_stokes_cases` per case: total optical thickness ``(m,)``,
    Rayleigh and aerosol scattering per unit extinction at the levels ``(m, n_levels)``
    (level 0 at the ground), and the Greek coefficients ``(n_moments, 4)`` of the molecules
    and of the aerosol."""
    from .molecular import bodhaine_optical_thickness
    aods = np.atleast_1d(check_in_range("aods_550", aods_550, *AOD_RANGE,
                                        hint="aerosol optical depth at 550 nm"))
    t = aerosol_type(preset)
    tau_r = float(bodhaine_optical_thickness(wavelength_nm, pressure_hPa))
    optics = aerosol_optics(t, wavelength_nm, n_moments)
    ref = aerosol_optics(t, REFERENCE_WAVELENGTH_NM, n_moments)
    tau_a = aods * optics.extinction / ref.extinction
    f = aerosol_fraction_levels(tau_r, tau_a, t.scale_height_km, settings.n_levels)
    g_r = rayleigh_greek_coefficients(rayleigh_depolarization_factor(depolarization_ratio),
                                      n_moments)
    return tau_r + tau_a, 1.0 - f, f * optics.ssa, g_r, optics.greek


def aerosol_stokes_cases(aods_550, albedos, mu0: float, mu, phi_deg, *, preset,
                         wavelength_nm: float, pressure_hPa: float = 1013.25,
                         depolarization_ratio: float = 0.0,
                         settings: EngineSettings = DEFAULT_SETTINGS,
                         n_moments: int = N_MOMENTS,
                         multiple_scatter: bool = True) -> np.ndarray:
    """Diffuse Stokes of the Rayleigh + aerosol sky for several (AOD, albedo) cases at one
    sun, in one engine call.

    Parameters
    ----------
    aods_550 : array-like (m,)
        Aerosol optical depth at 550 nm of each case, in :data:`AOD_RANGE`.
    albedos : array-like (m,) or float
        Lambertian ground albedo, in [0, 1].
    mu0 : float
        Cosine of the solar zenith angle, in (0, 1].
    mu, phi_deg : array-like (n,)
        View cosines (looking up) and relative azimuths [deg] (view minus sun, clockwise).
    preset : str or AerosolType
        Aerosol type (:data:`skysim.aerosol_types.PRESETS`).
    wavelength_nm : float
        Wavelength [nm], 250-1000 (Rayleigh optical thickness from Bodhaine et al. [3]_).
    pressure_hPa : float
        Surface pressure [hPa].
    depolarization_ratio : float
        Molecular depolarization ratio.
    settings : EngineSettings
    n_moments : int
        Greek moments of the exact single scatter.
    multiple_scatter : bool
        False: the engine's exact single scatter alone.

    Returns
    -------
    ndarray (m, n, 3)
        ``I, Q, U`` (skysim basis, incident flux ``pi``, direct beam excluded).
    """
    taus, scat_r, scat_a, g_r, g_a = _slab_optics(aods_550, preset, wavelength_nm,
                                                  pressure_hPa, depolarization_ratio,
                                                  settings, n_moments)
    albedos = np.broadcast_to(check_in_range("albedos", albedos, 0.0, 1.0), taus.shape)
    ssa = scat_r + scat_a
    greek = (scat_r[..., None, None] * g_r + scat_a[..., None, None] * g_a) \
        / ssa[..., None, None]
    return layered_stokes_cases(taus, ssa, greek, albedos, mu0, mu, phi_deg,
                                settings=settings, delta_m=True,
                                multiple_scatter=multiple_scatter)


# --------------------------------------------------------------------------------------------
# The single scatter in closed form (the aureole's forward peak, exact at every direction)
# --------------------------------------------------------------------------------------------

class _AerosolPhase:
    """``F11``, ``F12`` of an aerosol type on a grid of scattering angles
    :data:`PHASE_STEP_DEG` apart (from its Greek coefficients), interpolated linearly."""

    def __init__(self, greek):
        self.angle_deg = np.linspace(0.0, 180.0, int(round(180.0 / PHASE_STEP_DEG)) + 1)
        self.f11, self.f12 = phase_f11_f12(greek, np.cos(np.radians(self.angle_deg)))

    def __call__(self, scattering_deg):
        x = np.clip(np.asarray(scattering_deg, float) / PHASE_STEP_DEG, 0.0,
                    self.angle_deg.size - 1.0)
        i = np.minimum(x.astype(np.intp), self.angle_deg.size - 2)
        w = x - i
        return ((1.0 - w) * self.f11[i] + w * self.f11[i + 1],
                (1.0 - w) * self.f12[i] + w * self.f12[i + 1])


PHASE_STEP_DEG = 0.01
"""Scattering-angle step [deg] of the tabulated aerosol phase function (linear interpolation
between; the 512-moment expansion resolves about 0.35 deg, so the interpolation errs by
< 1e-4 of F11 in the forward peak of the coarsest preset, desert: tested)."""


@functools.lru_cache(maxsize=32)
def _aerosol_phase(preset: AerosolType, wavelength_nm: float, n_moments: int) -> _AerosolPhase:
    return _AerosolPhase(aerosol_optics(preset, wavelength_nm, n_moments).greek)


class SingleScatter:
    """The singly scattered light of one aerosol table (one sun), at any direction.

    ``I = (1/4) sum_x A_x(mu) F11_x(Theta)`` over the molecules and the aerosol (``x``), and
    the polarized radiance likewise with ``F12`` (> 0: perpendicular to the scattering plane),
    rotated to the local meridian (:func:`skysim.slab_single_scatter.perpendicular_stokes`).
    The line-of-sight weights ``A_x`` (:func:`skysim.slab_single_scatter.single_scatter_weights`
    on the engine's levels, tabulated in view zenith angle :data:`SINGLE_ZENITH_STEP_DEG` apart)
    depend on the view cosine only; the phase-matrix elements (the Rayleigh ones from their
    three moments, the aerosol's tabulated :data:`PHASE_STEP_DEG` apart from its Greek
    moments, :func:`skysim.rt_sasktran.phase_f11_f12`) are taken at the exact scattering
    angle ``Theta``. As in the engine's exact single scatter with delta-M scaling (the TMS
    method of Nakajima & Tanaka 1988 [4]_), the beam and the scattered light are attenuated
    by the extinction less the truncated forward peak (the share ``a1[n_streams] /
    (2 n_streams + 1)`` of each level's scattering, which the engine counts as going on),
    while the source keeps the whole phase function: with the true extinction the desert sky
    comes out 7 % low at 5 deg elevation. The result is the engine's single scatter within
    2.7e-4 in I and 2.1e-4 in Q/I, U/I (``tests/test_aerosol.py``), the forward peak
    included, which no table of a few tens of azimuths and zenith nodes follows.

    Parameters
    ----------
    sun_zenith_deg : float
        Solar zenith angle [deg].
    weights : ndarray (2, n)
        ``A_Rayleigh``, ``A_aerosol`` at :func:`single_zenith_grid_deg`.
    greek_rayleigh : ndarray (n_moments, 4)
    phase : callable
        Scattering angle [deg] -> aerosol ``(F11, F12)``.
    """

    def __init__(self, sun_zenith_deg: float, weights, greek_rayleigh, phase):
        self.sun_zenith_deg = float(sun_zenith_deg)
        self.weights = np.asarray(weights, float)
        self.greek_rayleigh = np.asarray(greek_rayleigh, float)[:3]
        self.phase = phase

    def weights_at(self, theta_deg) -> np.ndarray:
        """``(A_Rayleigh, A_aerosol)`` at view zenith angles [deg], shape ``(2,) + shape``."""
        x = np.clip(np.asarray(theta_deg, float) / SINGLE_ZENITH_STEP_DEG, 0.0,
                    self.weights.shape[1] - 1.0)
        i = np.minimum(x.astype(np.intp), self.weights.shape[1] - 2)
        w = x - i
        return (1.0 - w) * self.weights[:, i] + w * self.weights[:, i + 1]

    def stokes(self, theta_deg, phi_deg, sun_zenith_deg=None, weights=None) -> np.ndarray:
        """``(I, Q, U)`` ``(3,) + shape`` at view zenith ``theta_deg`` and relative azimuth
        ``phi_deg`` [deg]; ``sun_zenith_deg`` and ``weights`` (default: this table's sun and
        :meth:`weights_at`) for a sun between tables."""
        from .rayleigh import meridian_components
        from .slab_single_scatter import perpendicular_stokes
        theta, phi = np.broadcast_arrays(np.asarray(theta_deg, float),
                                         np.asarray(phi_deg, float))
        sz = self.sun_zenith_deg if sun_zenith_deg is None else sun_zenith_deg
        sz = np.broadcast_to(np.asarray(sz, float), theta.shape)
        wts = self.weights_at(theta) if weights is None else weights
        a, b = meridian_components(90.0 - theta, phi, 90.0 - sz, 0.0)
        t, s = np.radians(theta), np.radians(sz)
        cos_g = np.cos(t) * np.cos(s) + np.sin(t) * np.sin(s) * np.cos(np.radians(phi))
        f11_r, f12_r = phase_f11_f12(self.greek_rayleigh, cos_g)
        f11_a, f12_a = self.phase(np.degrees(np.arccos(np.clip(cos_g, -1.0, 1.0))))
        return np.stack(perpendicular_stokes(0.25 * (wts[0] * f11_r + wts[1] * f11_a),
                                             0.25 * (wts[0] * f12_r + wts[1] * f12_a), a, b))


SINGLE_ZENITH_STEP_DEG = 0.05
"""View-zenith step [deg] of a table's single-scatter weights (smooth in the view angle:
linear interpolation errs by < 1e-6 of them)."""


def single_zenith_grid_deg() -> np.ndarray:
    """View zenith angles [deg] of the single-scatter weights, 0-90."""
    return np.linspace(0.0, 90.0, int(round(90.0 / SINGLE_ZENITH_STEP_DEG)) + 1)


def aerosol_single_scatter_cases(aods_550, mu0: float, *, preset, wavelength_nm: float,
                                 pressure_hPa: float = 1013.25,
                                 depolarization_ratio: float = 0.0,
                                 settings: EngineSettings = DEFAULT_SETTINGS,
                                 n_moments: int = N_MOMENTS) -> list:
    """:class:`SingleScatter` of the slab of :func:`aerosol_stokes_cases` for several AODs
    at one sun (no engine call; the albedo does not enter the single scatter).

    Parameters are those of :func:`aerosol_stokes_cases`. Returns a list, one per AOD.
    """
    from .rt_sasktran import MU_MAX, MU_MIN
    t = aerosol_type(preset)
    taus, scat_r, scat_a, g_r, g_a = _slab_optics(aods_550, t, wavelength_nm, pressure_hPa,
                                                  depolarization_ratio, settings, n_moments)
    from .slab_single_scatter import single_scatter_weights
    n = settings.n_streams
    # the engine's delta-M truncation at each level: the share a1[n] / (2n + 1) of the
    # level's scattering in the forward peak stays in the attenuated beam
    truncated = (scat_r * g_r[n, 0] + scat_a * g_a[n, 0]) / (2 * n + 1)
    altitudes = np.linspace(0.0, settings.slab_height_m, settings.n_levels)
    k = taus[:, None] / settings.slab_height_m                      # extinction [1/m]
    mu = np.clip(np.cos(np.radians(single_zenith_grid_deg())), MU_MIN, MU_MAX)
    phase = _aerosol_phase(t, float(wavelength_nm), int(n_moments))
    sz = float(np.degrees(np.arccos(mu0)))
    return [SingleScatter(sz, single_scatter_weights(
        altitudes, np.column_stack([kc * scat_r[c], kc * scat_a[c]]),
        kc * (1.0 - truncated[c]), mu, float(mu0)), g_r, phase)
        for c, kc in enumerate(k[:, 0])]


# --------------------------------------------------------------------------------------------
# Tables: the multiply scattered light as azimuthal Fourier modes, the single scatter exact
# --------------------------------------------------------------------------------------------

N_ZENITH = 25
"""Basis of the view zenith nodes of a table (:func:`skysim.multiple.mode_nodes_deg`: 24
nodes, at the view cosines where the engine's multiple-scatter source is exact)."""
N_AZIMUTH = 37
"""Relative-azimuth nodes of a table, 0-180 deg (5 deg apart)."""
FINE_ZENITH_STEP_DEG = 0.5
FINE_AZIMUTH_STEP_DEG = 1.25
"""The multiply scattered light of a table is sampled once on a grid of these steps [deg]
(view zenith x relative azimuth) and evaluated bilinearly there (within 1e-4 of the modes
in I/I: ``tests/test_aerosol.py``)."""


class AerosolTable:
    """Diffuse Stokes field for one (aerosol, AOD, albedo, wavelength, sun).

    The singly scattered light (:class:`SingleScatter`) is computed in closed form at every
    direction; it holds the aerosol's forward peak. The rest, light scattered at least twice
    (through the engine's phase function truncated to ``n_streams`` moments, so it varies
    over several degrees even beside the sun), is the engine's total minus that single
    scatter at the nodes: view zenith angles where the engine's multiple-scatter source is
    exact (:func:`skysim.multiple.mode_nodes_deg`) x equally spaced relative azimuths
    0-180 deg. It is expanded in azimuth (cosine series for I, Q, sine series for U:
    :class:`skysim.clouds.AzimuthModes`) and each mode interpolated in view zenith angle by
    :class:`skysim.multiple.PoleSpline` (exact in its behaviour through the zenith); for
    speed it is sampled once on a grid :data:`FINE_ZENITH_STEP_DEG` x
    :data:`FINE_AZIMUTH_STEP_DEG` and evaluated bilinearly.

    Parameters
    ----------
    theta_deg : ndarray (n,)
        View zenith angles [deg] of the engine rays (the first the zenith's, below 1 deg).
    phi_deg : ndarray (k,)
        Relative azimuths [deg], equally spaced from 0 to 180.
    multiple : ndarray (n, k, 3)
        ``I, Q, U`` of the multiply scattered light at the nodes (skysim basis).
    single : SingleScatter
    """

    def __init__(self, theta_deg, phi_deg, multiple, single: SingleScatter):
        from .clouds import AzimuthModes
        self.theta_deg = np.asarray(theta_deg, float)
        self.phi_deg = np.asarray(phi_deg, float)
        self.modes = AzimuthModes.from_samples(self.theta_deg, multiple)
        self.single = single

    @functools.cached_property
    def _fine(self) -> np.ndarray:
        """The modes sampled on the fine grid, ``(rows, columns, 3)`` float32 (bilinear
        evaluation: 4 taps)."""
        th = np.linspace(0.0, 90.0, int(round(90.0 / FINE_ZENITH_STEP_DEG)) + 1)
        ph = np.linspace(0.0, 180.0, int(round(180.0 / FINE_AZIMUTH_STEP_DEG)) + 1)
        T, P = np.meshgrid(th, ph, indexing="ij")
        return np.stack(self.modes.evaluate(T, P), axis=-1).astype(np.float32)

    def multiple_scatter(self, theta_deg, phi_deg) -> np.ndarray:
        """``(I, Q, U)`` ``(3,) + shape`` of the multiply scattered light at view zenith
        angles in [0, 90] and relative azimuths (any real value) [deg] (broadcast)."""
        theta, phi = np.broadcast_arrays(np.asarray(theta_deg, float),
                                         np.asarray(phi_deg, float))
        rel = (phi.ravel() + 180.0) % 360.0 - 180.0
        fine = self._fine
        rows, cols = fine.shape[:2]
        x = np.clip(theta.ravel(), 0.0, 90.0) / FINE_ZENITH_STEP_DEG
        y = np.abs(rel) / FINE_AZIMUTH_STEP_DEG
        i0 = np.minimum(x.astype(np.intp), rows - 2)
        j0 = np.minimum(y.astype(np.intp), cols - 2)
        fx, fy = (x - i0)[:, None], (y - j0)[:, None]
        flat = fine.reshape(-1, 3)
        top = i0 * cols + j0
        v = ((1.0 - fx) * ((1.0 - fy) * flat[top] + fy * flat[top + 1])
             + fx * ((1.0 - fy) * flat[top + cols] + fy * flat[top + cols + 1]))
        v[:, 2] = np.where(rel < 0.0, -v[:, 2], v[:, 2])
        return v.T.reshape((3,) + theta.shape)

    def evaluate(self, theta_deg, phi_deg):
        """``(I, Q, U)`` at view zenith angles ``theta_deg`` in [0, 90] and relative azimuths
        ``phi_deg`` [deg] (any real value; broadcast)."""
        out = self.multiple_scatter(theta_deg, phi_deg) + self.single.stokes(theta_deg,
                                                                             phi_deg)
        return out[0], out[1], out[2]


def table_grid(n_zenith: int = N_ZENITH, n_azimuth: int = N_AZIMUTH):
    """View zenith [deg] and relative azimuth [deg] of a table's engine rays, as
    ``(n_nodes, n_azimuth)`` arrays: :func:`skysim.multiple.mode_nodes_deg` (the zenith and
    the horizon at the angles the engine traces, :data:`skysim.rt_sasktran.MU_MAX` and
    ``MU_MIN``) x ``n_azimuth`` azimuths 0-180 deg."""
    from .multiple import mode_nodes_deg
    from .rt_sasktran import MU_MAX, MU_MIN
    if int(n_azimuth) < 5:
        raise InvalidParameterError(f"n_azimuth must be >= 5; got {n_azimuth}. Default: "
                                    f"{N_AZIMUTH}.")
    mu = np.clip(np.cos(np.radians(mode_nodes_deg(int(n_zenith)))), MU_MIN, MU_MAX)
    return np.meshgrid(np.degrees(np.arccos(mu)), np.linspace(0.0, 180.0, int(n_azimuth)),
                       indexing="ij")


TABLES_CACHE_SIZE = 512
"""Aerosol tables kept per process (least recently used dropped first)."""
_TABLES: OrderedDict = OrderedDict()


def clear_tables_cache() -> None:
    """Forget every cached aerosol table (the next evaluation calls the engine)."""
    _TABLES.clear()


def aerosol_tables_cases(aods_550, albedos, mu0: float, *, preset, wavelength_nm: float,
                         pressure_hPa: float = 1013.25, depolarization_ratio: float = 0.0,
                         n_zenith: int = N_ZENITH, n_azimuth: int = N_AZIMUTH,
                         settings: EngineSettings = DEFAULT_SETTINGS,
                         n_moments: int = N_MOMENTS) -> list:
    """Tables for several (AOD, albedo) cases at one sun; those not cached yet come from one
    engine call together (:func:`aerosol_stokes_cases`; each case is an independent engine
    "wavelength", so the tables equal those computed one by one).

    Parameters are those of :func:`aerosol_stokes_cases`; ``n_zenith`` x ``n_azimuth`` is the
    grid (:func:`table_grid`). Returns a list of :class:`AerosolTable`, one per case.
    """
    aods = np.atleast_1d(np.asarray(aods_550, dtype=float))
    albedos = np.broadcast_to(np.asarray(albedos, dtype=float), aods.shape)
    t = aerosol_type(preset)
    shared = (t, float(wavelength_nm), float(pressure_hPa), float(depolarization_ratio),
              float(mu0), int(n_zenith), int(n_azimuth), settings, int(n_moments))
    keys = [(float(a), float(b)) + shared for a, b in zip(aods, albedos)]
    missing = list(dict.fromkeys(k for k in keys if k not in _TABLES))
    if missing:
        theta, phi = table_grid(n_zenith, n_azimuth)
        kw = dict(preset=t, wavelength_nm=wavelength_nm, pressure_hPa=pressure_hPa,
                  depolarization_ratio=depolarization_ratio, settings=settings,
                  n_moments=n_moments)
        total = aerosol_stokes_cases([k[0] for k in missing], [k[1] for k in missing],
                                     float(mu0), np.cos(np.radians(theta.ravel())),
                                     phi.ravel(), **kw)
        singles = aerosol_single_scatter_cases([k[0] for k in missing], float(mu0), **kw)
        for key, st, ss in zip(missing, total, singles):
            multiple = st.reshape(theta.shape + (3,)) - np.moveaxis(ss.stokes(theta, phi), 0, -1)
            _TABLES[key] = AerosolTable(theta[:, 0], phi[0], multiple, ss)
    return lru_take(_TABLES, keys, TABLES_CACHE_SIZE)

# --------------------------------------------------------------------------------------------
# The Sky object
# --------------------------------------------------------------------------------------------

class AerosolSky(Sky):
    """Multiple-scattering sky of molecules and aerosol over a Lambertian ground (sasktran2).

    Parameters
    ----------
    preset : str or AerosolType
        Aerosol type: a key of :data:`skysim.aerosol_types.PRESETS` (``continental_clean``,
        ``continental_average``, ``urban``, ``maritime_clean``, ``desert``) or a user
        :class:`~skysim.aerosol_types.AerosolType` (size distributions, refractive indices,
        scale height).
    aod_550 : float
        Aerosol optical depth at 550 nm, in :data:`AOD_RANGE` (0: the molecular sky).
    albedo : float
        Lambertian ground albedo in [0, 1].
    wavelength_nm : float
        Wavelength [nm], 250-1000. The molecular optical thickness follows from Bodhaine
        et al. (1999) at ``pressure_hPa``; the AOD from the type's Mie extinction.
    pressure_hPa : float
        Surface pressure [hPa].
    depolarization_ratio : float or "bodhaine"
        Molecular depolarization ratio; ``"bodhaine"`` (default): ~0.028 from Bodhaine et
        al. (1999) at ``wavelength_nm``.
    sun_step_deg : float, optional
        For many sun positions: tables only at sun elevations that are multiples of this
        step [deg] (from ``sun_node_origin_deg``; geometric near the horizon:
        :func:`skysim.multiple.sun_bracket`), the Stokes vector interpolated linearly between
        the two neighbouring nodes. None: one engine call per distinct sun elevation. Error:
        ``docs/physical_sky.md`` (tested).
    sun_node_origin_deg : float
        One of the sun nodes [deg] (default 0).
    n_zenith, n_azimuth : int
        Table grid (:func:`table_grid`: the view zenith nodes of
        :func:`skysim.multiple.mode_nodes_deg` for ``n_zenith``, 24 for the default 25, times
        ``n_azimuth`` azimuths 0-180 deg); the engine traces one ray per node.
    settings : EngineSettings
        Numerical set-up of sasktran2.
    n_moments : int
        Greek moments of the exact single scatter.

    Notes
    -----
    ``I`` is normalised to an incident solar flux ``pi`` per unit area normal to the beam,
    the direct beam excluded; Stokes basis and AoP as ``docs/conventions.md``. One engine
    call per table (sun elevation node; several AODs/albedos at one sun share a call:
    :func:`prefetch_tables`), cached per process.
    """

    name = "aerosol"

    def __init__(self, preset="continental_average", aod_550: float = 0.1, albedo: float = 0.0,
                 wavelength_nm: float = 550.0, *, pressure_hPa: float = 1013.25,
                 depolarization_ratio="bodhaine", sun_step_deg: float | None = None,
                 sun_node_origin_deg: float = 0.0,
                 n_zenith: int = N_ZENITH, n_azimuth: int = N_AZIMUTH,
                 settings: EngineSettings = DEFAULT_SETTINGS, n_moments: int = N_MOMENTS):
        from .molecular import _check_wavelength, bodhaine_depolarization_ratio
        from .rt_sasktran import require_sasktran2
        self.aerosol = aerosol_type(preset)
        self.aod_550 = float(check_in_range("aod_550", aod_550, *AOD_RANGE,
                                            hint="aerosol optical depth at 550 nm"))
        self.albedo = float(check_in_range("albedo", albedo, 0.0, 1.0,
                                           hint="Lambertian ground albedo is a fraction"))
        self.wavelength_nm = float(_check_wavelength(wavelength_nm))
        self.pressure_hPa = float(check_in_range("pressure_hPa", pressure_hPa, 0.0, 1100.0,
                                                 low_open=True))
        if isinstance(depolarization_ratio, str):
            if depolarization_ratio != "bodhaine":
                raise InvalidParameterError(f"depolarization_ratio={depolarization_ratio!r}: "
                                            "give a number or 'bodhaine'")
            depolarization_ratio = float(bodhaine_depolarization_ratio(self.wavelength_nm))
        rayleigh_depolarization_factor(depolarization_ratio)  # validates
        self.depolarization_ratio = float(depolarization_ratio)
        self.sun_step_deg = None if sun_step_deg is None else float(
            check_in_range("sun_step_deg", sun_step_deg, 0.0, 10.0, low_open=True,
                           hint="a few degrees at most (None: exact per sun elevation)"))
        self.sun_node_origin_deg = float(check_finite("sun_node_origin_deg",
                                                      sun_node_origin_deg))
        table_grid(n_zenith, n_azimuth)  # validates
        self.n_zenith, self.n_azimuth = int(n_zenith), int(n_azimuth)
        self.settings = settings
        self.n_moments = int(n_moments)
        require_sasktran2()  # fail here, with the install command, not at the first map

    def _shared(self) -> dict:
        return dict(preset=self.aerosol, wavelength_nm=self.wavelength_nm,
                    pressure_hPa=self.pressure_hPa,
                    depolarization_ratio=self.depolarization_ratio, n_zenith=self.n_zenith,
                    n_azimuth=self.n_azimuth, settings=self.settings, n_moments=self.n_moments)

    def table(self, sun_elevation_deg: float) -> AerosolTable:
        """The table for one sun elevation [deg] (cached)."""
        return aerosol_tables_cases([self.aod_550], [self.albedo], _mu0(sun_elevation_deg),
                                    **self._shared())[0]

    def sun_nodes_deg(self, sun_elevation_deg) -> tuple:
        """Sun elevations [deg] whose tables give the sky at this one: itself (exact), or the
        two neighbouring sun nodes."""
        lo, hi, _ = self._sun_interval(np.atleast_1d(float(sun_elevation_deg)))
        return (float(lo[0]),) if lo[0] == hi[0] else (float(lo[0]), float(hi[0]))

    def _sun_interval(self, sun_elevation_deg):
        """Lower and upper sun nodes [deg] and the weight of the upper one, elementwise
        (:func:`skysim.multiple.sun_bracket`): the sun itself, weight 0, where it is exact."""
        from .multiple import sun_bracket
        el = np.asarray(sun_elevation_deg, dtype=float)
        lo, hi = sun_bracket(el, self.sun_step_deg, self.sun_node_origin_deg)
        exact = np.isnan(lo)
        lo, hi = np.where(exact, el, lo), np.where(exact, el, hi)
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(exact, 0.0, (el - lo) / (hi - lo))
        return lo, hi, w

    def _stokes(self, vel, vaz, sel, saz):
        theta, phi = 90.0 - vel, vaz - saz
        lo, hi, w = self._sun_interval(sel)
        multiple = np.zeros((3,) + vel.shape)
        weights = np.zeros((2,) + vel.shape)
        nodes, inverse = np.unique(np.concatenate([lo.ravel(), hi.ravel()]),
                                   return_inverse=True)
        i_lo, i_hi = inverse[:lo.size].reshape(lo.shape), inverse[lo.size:].reshape(hi.shape)
        for k, node in enumerate(nodes):  # one table per sun node (cached engine call)
            weight = np.where(i_lo == k, 1.0 - w, 0.0) + np.where(i_hi == k, w, 0.0)
            use = weight > 0.0
            if use.any():
                table = self.table(node)
                multiple[:, use] += weight[use] * table.multiple_scatter(theta[use], phi[use])
                weights[:, use] += weight[use] * table.single.weights_at(theta[use])
        # the single scatter at each sample's own sun: its line-of-sight weights (smooth in
        # the sun's elevation) interpolated between the sun nodes, the phase function (the
        # aureole's sharp peak) at the exact scattering angle
        out = multiple + table.single.stokes(theta, phi, 90.0 - sel, weights)
        return out[0], out[1], out[2]

    def flux_pi_scale(self, view_elevation_deg, sun_elevation_deg) -> np.ndarray:
        """1: ``I`` is in the unit of an incident solar flux ``pi``."""
        return np.ones(np.broadcast_shapes(np.shape(view_elevation_deg),
                                           np.shape(sun_elevation_deg)))

    def describe(self) -> dict:
        optics = aerosol_optics(self.aerosol, self.wavelength_nm, self.n_moments)
        ref = aerosol_optics(self.aerosol, REFERENCE_WAVELENGTH_NM, self.n_moments)
        from .molecular import bodhaine_optical_thickness
        return {"model": self.name, "aerosol": self.aerosol.describe(),
                "aod_550": self.aod_550,
                "aod": self.aod_550 * optics.extinction / ref.extinction,
                "aerosol_ssa": optics.ssa, "aerosol_asymmetry": optics.asymmetry,
                "rayleigh_tau": float(bodhaine_optical_thickness(self.wavelength_nm,
                                                                 self.pressure_hPa)),
                "rayleigh_scale_height_km": RAYLEIGH_SCALE_HEIGHT_KM,
                "albedo": self.albedo, "wavelength_nm": self.wavelength_nm,
                "pressure_hPa": self.pressure_hPa,
                "depolarization_ratio": self.depolarization_ratio,
                "sun_step_deg": self.sun_step_deg,
                "sun_node_origin_deg": self.sun_node_origin_deg, "n_zenith": self.n_zenith,
                "n_azimuth": self.n_azimuth, "n_moments": self.n_moments,
                "engine": "sasktran2", "engine_settings": self.settings.to_dict(),
                "I_normalisation": "incident solar flux pi per unit area normal to the beam "
                                   "(F = 1); diffuse sky only, direct beam excluded"}


def _mu0(sun_elevation_deg) -> float:
    return float(np.sin(np.radians(sun_elevation_deg)))


def prefetch_tables(aods_550, sun_elevation_deg, *, albedos=None, sky: AerosolSky) -> None:
    """Compute, in one engine call per sun node, the tables that skies like ``sky`` but with
    each of ``aods_550`` (and ``albedos``, default the sky's) need at these sun elevations
    [deg] (with ``sky.sun_step_deg``: the nodes around them). Later evaluations of such skies
    are cache hits; a fit of the AOD interpolating between AOD nodes calls this once.
    """
    aods = np.atleast_1d(np.asarray(aods_550, dtype=float))
    alb = np.full(aods.shape, sky.albedo) if albedos is None else \
        np.broadcast_to(np.asarray(albedos, float), aods.shape)
    lo, hi, _ = sky._sun_interval(np.unique(np.asarray(sun_elevation_deg, float)))
    for node in np.unique(np.concatenate([lo, hi])):
        aerosol_tables_cases(aods, alb, _mu0(node), **sky._shared())
