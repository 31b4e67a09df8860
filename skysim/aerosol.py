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
The aerosol phase function is forward peaked, so the azimuthal Fourier series of the field
does not stop at ``m = 2`` as for Rayleigh scattering. The engine is called once per (sun
elevation; all AODs and albedos of a batch together) on a grid of view zenith angles x
relative azimuths (:class:`AerosolTable`), and the field is interpolated on that grid
(cubic in both angles, mirror-symmetric about the solar meridian, continued through the
zenith). Grid and error: ``docs/physical_sky.md``, tested in ``tests/test_aerosol.py``.

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
"""

from __future__ import annotations

import functools
from collections import OrderedDict

import numpy as np

from .aerosol_types import (N_MOMENTS, REFERENCE_WAVELENGTH_NM, AerosolType, aerosol_optics,
                            aerosol_type)
from .exceptions import InvalidParameterError
from .rt_sasktran import (DEFAULT_SETTINGS, EngineSettings, layered_stokes_cases, lru_take,
                          rayleigh_depolarization_factor, rayleigh_greek_coefficients)
from .sky import Sky
from .validation import check_finite, check_in_range

__all__ = ["AOD_RANGE", "AerosolSky", "AerosolTable", "AerosolType", "N_AZIMUTH", "N_ZENITH",
           "RAYLEIGH_SCALE_HEIGHT_KM", "aerosol_fraction_levels", "aerosol_stokes_cases",
           "aerosol_tables_cases", "clear_tables_cache", "prefetch_tables", "table_grid",
           "zenith_cap_repaired"]

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
    from .molecular import bodhaine_optical_thickness
    aods = np.atleast_1d(check_in_range("aods_550", aods_550, *AOD_RANGE,
                                        hint="aerosol optical depth at 550 nm"))
    albedos = np.broadcast_to(check_in_range("albedos", albedos, 0.0, 1.0), aods.shape)
    t = aerosol_type(preset)
    tau_r = float(bodhaine_optical_thickness(wavelength_nm, pressure_hPa))
    optics = aerosol_optics(t, wavelength_nm, n_moments)
    ref = aerosol_optics(t, REFERENCE_WAVELENGTH_NM, n_moments)
    tau_a = aods * optics.extinction / ref.extinction
    f = aerosol_fraction_levels(tau_r, tau_a, t.scale_height_km, settings.n_levels)
    scat_r, scat_a = 1.0 - f, f * optics.ssa                    # (m, levels)
    ssa = scat_r + scat_a
    g_r = rayleigh_greek_coefficients(rayleigh_depolarization_factor(depolarization_ratio),
                                      n_moments)
    greek = (scat_r[..., None, None] * g_r + scat_a[..., None, None] * optics.greek) \
        / ssa[..., None, None]
    return layered_stokes_cases(tau_r + tau_a, ssa, greek, albedos, mu0, mu, phi_deg,
                                settings=settings, delta_m=True,
                                multiple_scatter=multiple_scatter)


# --------------------------------------------------------------------------------------------
# Tables: the field on a (view zenith x relative azimuth) grid, cubic B-spline interpolation
# --------------------------------------------------------------------------------------------

N_ZENITH = 25
"""View zenith nodes of a table (:func:`skysim.multiple.zenith_nodes_deg`: sine spaced)."""
N_AZIMUTH = 37
"""Relative-azimuth nodes of a table, 0-180 deg (5 deg apart)."""
REFINE = 4
"""The cubic B-spline of a table is sampled this many times finer per grid step and then
interpolated bilinearly (differs from the spline by <= 8.5e-4 in I/I beyond 20 deg from the
sun and <= 6e-4 in DoP everywhere, at 20 000 random directions, suns at 10 and 35 deg;
docs/physical_sky.md)."""
_PAD = 3            # ghost nodes on each side of the grid (symmetry or extrapolation)
_PARITY = np.array([1.0, 1.0, -1.0])  # I, Q even and U odd in the relative azimuth


class AerosolTable:
    """Diffuse Stokes field for one (aerosol, AOD, albedo, wavelength, sun) on a grid.

    The grid is uniform in the index ``k`` of the sine-spaced zenith nodes
    ``theta_k = 90 sin(pi k / (2 (n - 1)))`` [deg] and in the relative azimuth
    ``phi`` in [0, 180] deg, so a cubic B-spline on a uniform grid
    (:func:`scipy.ndimage.map_coordinates`) interpolates it. The grid is extended before the
    spline is fitted: past ``phi = 0`` and ``180`` by the mirror symmetry about the solar
    meridian (I, Q even, U odd), past the zenith by continuing along the great circle
    (``f(-theta, phi) = s f(theta, 180 - phi)``, ``s = +1`` for I, Q and ``-1`` for U; the
    meridian basis turns by 180 deg, which leaves Q and U unchanged), and past the horizon
    by quadratic extrapolation. The spline interpolates ``ln I``, ``Q/I`` and ``U/I`` (same
    parities), smooth also in the aureole; for speed it is sampled :data:`REFINE` times finer
    once and evaluated bilinearly on that grid.

    Parameters
    ----------
    stokes : ndarray (n_zenith, n_azimuth, 3)
        ``I, Q, U`` at the nodes (skysim basis).
    """

    def __init__(self, stokes: np.ndarray):
        from scipy import ndimage
        st = np.asarray(stokes, dtype=float)
        self.n_zenith, self.n_azimuth = st.shape[:2]
        self.azimuth_step_deg = 180.0 / (self.n_azimuth - 1)
        p = _PAD
        # log I, Q/I, U/I: smooth where I has the aureole's steep peak (a spline of I itself
        # rings there, down to I ~ 0 a degree from the sun)
        v = np.stack([np.log(st[..., 0]), st[..., 1] / st[..., 0], st[..., 2] / st[..., 0]])
        left = _PARITY[:, None, None] * v[:, :, p:0:-1]                   # phi < 0
        right = _PARITY[:, None, None] * v[:, :, -2:-2 - p:-1]            # phi > 180
        v = np.concatenate([left, v, right], axis=2)
        through = _PARITY[:, None, None] * v[:, p:0:-1, ::-1]             # theta < 0
        last = v[:, -3:]
        beyond = np.stack([last[:, 2] * (1 + j) * (2 + j) / 2 - last[:, 1] * j * (2 + j)
                           + last[:, 0] * j * (1 + j) / 2 for j in range(1, p + 1)], axis=1)
        v = np.concatenate([through, v, beyond], axis=1)
        self.stokes = st
        self._coefficients = [ndimage.spline_filter(c, order=3, mode="nearest") for c in v]

    @functools.cached_property
    def _fine(self) -> np.ndarray:
        """The spline sampled on a grid :data:`REFINE` times finer in both indices,
        ``(rows, columns, 3)``: evaluation is then bilinear (4 taps instead of 16)."""
        from scipy import ndimage
        k = np.arange((self.n_zenith - 1) * REFINE + 1) / REFINE + _PAD
        j = np.arange((self.n_azimuth - 1) * REFINE + 1) / REFINE + _PAD
        K, J = np.meshgrid(k, j, indexing="ij")
        return np.stack([ndimage.map_coordinates(c, [K, J], order=3, prefilter=False,
                                                 mode="nearest")
                         for c in self._coefficients], axis=-1)

    def evaluate(self, theta_deg, phi_deg):
        """``(I, Q, U)`` at view zenith angles ``theta_deg`` in [0, 90] and relative azimuths
        ``phi_deg`` [deg] (any real value; broadcast)."""
        theta, phi = np.broadcast_arrays(np.asarray(theta_deg, float),
                                         np.asarray(phi_deg, float))
        rel = (phi.ravel() + 180.0) % 360.0 - 180.0
        fine = self._fine
        rows, cols = fine.shape[:2]
        x = (2.0 * (self.n_zenith - 1) * REFINE / np.pi) * np.arcsin(
            np.clip(theta.ravel() / 90.0, 0.0, 1.0))
        y = np.abs(rel) * (REFINE / self.azimuth_step_deg)
        i0 = np.minimum(x.astype(np.intp), rows - 2)
        j0 = np.minimum(y.astype(np.intp), cols - 2)
        fx, fy = (x - i0)[:, None], (y - j0)[:, None]
        flat = fine.reshape(-1, 3)
        top = i0 * cols + j0
        v = ((1.0 - fx) * ((1.0 - fy) * flat[top] + fy * flat[top + 1])
             + fx * ((1.0 - fy) * flat[top + cols] + fy * flat[top + cols + 1]))
        i = np.exp(v[:, 0])
        q, u = i * v[:, 1], i * np.where(rel < 0.0, -v[:, 2], v[:, 2])
        return tuple(o.reshape(theta.shape) for o in (i, q, u))


def table_grid(n_zenith: int = N_ZENITH, n_azimuth: int = N_AZIMUTH):
    """View zenith [deg] and relative azimuth [deg] nodes of a table, as ``(n_zenith,
    n_azimuth)`` arrays."""
    from .multiple import zenith_nodes_deg
    if int(n_azimuth) < 5:
        raise InvalidParameterError(f"n_azimuth must be >= 5; got {n_azimuth}. Default: "
                                    f"{N_AZIMUTH}.")
    return np.meshgrid(zenith_nodes_deg(int(n_zenith)), np.linspace(0.0, 180.0, int(n_azimuth)),
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
        from .rt_sasktran import SOURCE_GRID_MU_STEP
        theta, phi = table_grid(n_zenith, n_azimuth)
        cap = 1.0 - SOURCE_GRID_MU_STEP * np.arange(1, 3)
        mu = np.concatenate([np.cos(np.radians(theta.ravel())), np.repeat(cap, phi.shape[1])])
        az = np.concatenate([phi.ravel(), np.tile(phi[0], cap.size)])
        total, single = (aerosol_stokes_cases(
            [k[0] for k in missing], [k[1] for k in missing], float(mu0), mu, az, preset=t,
            wavelength_nm=wavelength_nm, pressure_hPa=pressure_hPa,
            depolarization_ratio=depolarization_ratio, settings=settings,
            n_moments=n_moments, multiple_scatter=ms) for ms in (True, False))
        shape = (theta.shape[0] + cap.size,) + theta.shape[1:] + (3,)
        for key, st, ss in zip(missing, total, single):
            _TABLES[key] = AerosolTable(zenith_cap_repaired(
                np.concatenate([theta[:, 0], np.degrees(np.arccos(cap))]), phi[0],
                st.reshape(shape), ss.reshape(shape))[:theta.shape[0]])
    return lru_take(_TABLES, keys, TABLES_CACHE_SIZE)


def zenith_cap_repaired(theta_deg, phi_deg, total, single) -> np.ndarray:
    """Engine Stokes on a (view zenith x relative azimuth) grid with the multiply scattered
    light of the rows near the zenith replaced by its interpolation from the rows where the
    engine's multiple-scatter source is exact.

    Between the zenith and the view cosine 0.98 (11.5 deg) the engine interpolates its
    multiple-scatter source linearly in the cosine, which gives its azimuthal modes the wrong
    shape (:data:`skysim.rt_sasktran.SOURCE_GRID_MU_STEP`); at the zenith and at the cosines
    0.98, 0.96 it is exact, and the single scatter is exact everywhere (the aerosol's forward
    peak included). So the multiple scatter (``total - single``) of the rows within 16.8 deg
    of the zenith (other than the zenith's) is taken from its azimuthal Fourier modes
    (:class:`skysim.clouds.AzimuthModes`, cosine/sine series over the grid's azimuths)
    interpolated in zenith angle by :class:`skysim.multiple.PoleSpline` over the zenith row,
    the rows at the cosines 0.98 and 0.96 and the rows beyond, and the single scatter is added
    back. Cost: the single-scatter engine call adds about a fifth to a table's (measured 0.9 s
    against 4.6 s of CPU, 999 rays).

    Parameters
    ----------
    theta_deg : ndarray (n,)
        View zenith angles [deg] of the rows (the first the zenith's, below 1 deg), among
        them the cosines 0.98 and 0.96 (any order after the first).
    phi_deg : ndarray (k,)
        Relative azimuths [deg], equally spaced from 0 to 180.
    total, single : ndarray (n, k, 3)
        The engine's ``I, Q, U`` with and without its multiple-scatter source.

    Returns
    -------
    ndarray (n, k, 3)
        ``total`` with the rows within 16.8 deg of the zenith repaired.
    """
    from .clouds import AzimuthModes
    from .rt_sasktran import SOURCE_GRID_MU_STEP
    th = np.asarray(theta_deg, float)
    mu = np.cos(np.radians(th))
    exact = np.isclose(mu, 1.0 - SOURCE_GRID_MU_STEP, atol=1e-9) | np.isclose(
        mu, 1.0 - 2.0 * SOURCE_GRID_MU_STEP, atol=1e-9)
    cap_edge = np.degrees(np.arccos(1.0 - 2.0 * SOURCE_GRID_MU_STEP)) + 0.5
    bad = (th > 1.0) & (th < cap_edge) & ~exact
    use = np.flatnonzero(~bad)
    use = use[np.argsort(th[use])]
    multiple = np.asarray(total, float) - np.asarray(single, float)
    modes = AzimuthModes.from_samples(th[use], multiple[use])
    out = np.array(total, dtype=float)
    rows = np.flatnonzero(bad)
    if rows.size:
        fixed = np.stack(modes.evaluate(th[rows][:, None], np.asarray(phi_deg, float)[None, :]),
                         axis=-1)
        out[rows] = np.asarray(single, float)[rows] + fixed
    return out


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
        Table grid (:class:`AerosolTable`); the engine traces ``n_zenith * n_azimuth`` rays.
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
        out = np.zeros((3,) + vel.shape)
        nodes, inverse = np.unique(np.concatenate([lo.ravel(), hi.ravel()]),
                                   return_inverse=True)
        i_lo, i_hi = inverse[:lo.size].reshape(lo.shape), inverse[lo.size:].reshape(hi.shape)
        for k, node in enumerate(nodes):  # one table per sun node (cached engine call)
            weight = np.where(i_lo == k, 1.0 - w, 0.0) + np.where(i_hi == k, w, 0.0)
            use = weight > 0.0
            if use.any():
                st = self.table(node).evaluate(theta[use], phi[use])
                out[:, use] += weight[use] * np.asarray(st)
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
