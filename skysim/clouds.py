"""Overcast skies from radiative transfer: a liquid-water cloud layer in the Rayleigh slab.

The cloud is a homogeneous layer of spherical water droplets between a base and a top height,
inside the multiple-scattering Rayleigh atmosphere of :mod:`skysim.multiple`, solved by
sasktran2 (:func:`skysim.rt_sasktran.layered_particle_stokes_cases`). Its optical properties
come from the engine's own Lorenz-Mie code (``sasktran2.mie``) integrated over a gamma size
distribution (Hansen & Travis 1974, eq. (2.56) [1]_) with effective radius 10 um and
effective variance 0.1, a typical water cloud ([1]_, sect. 2.7), and the refractive index of
water of Hale & Querry (1973) [2]_. (sasktran2's tabulated water index and its ice-crystal
database are downloaded at run time, which a skysim installation cannot rely on; ice clouds
are therefore not offered: spheres are a poor model of ice crystals.)

The heights place the cloud in Rayleigh optical depth: the air below a height ``z`` holds
the fraction ``1 - exp(-z / H)`` of the column's molecules, with the molecular scale height
``H = 8.0 km`` [3]_; the engine's homogeneous slab puts the cloud at the same fractions.

Measured overcast skies keep the clear sky's angle-of-polarization pattern while their
degree of polarization stays below about 16 % (Hegedüs, Åkesson & Horváth 2007 [4]_);
``tests/test_clouds.py`` checks that the DoP falls with the cloud's optical thickness
(:data:`CLOUD_TAU_RANGE`) and the AoP pattern keeps to the clear sky's (Pomozi, Horváth &
Wehner 2001 [5]_).

The sky is the single scatter in closed form at every direction (the droplets' sharp
forward peak, the aureole: :func:`overcast_single_scatter`) plus the multiply scattered
light interpolated from engine rays (:func:`overcast_modes`).

References
----------
.. [1] J. E. Hansen, L. D. Travis, "Light scattering in planetary atmospheres", Space Sci.
   Rev. 16:527-610 (1974), doi:10.1007/BF00168069.
.. [2] G. M. Hale, M. R. Querry, "Optical constants of water in the 200-nm to 200-um
   wavelength region", Appl. Opt. 12:555-563 (1973), doi:10.1364/AO.12.000555, Table I.
.. [3] K. N. Liou, *An Introduction to Atmospheric Radiation*, 2nd ed., Academic Press
   (2002), sect. 3.3.1 (scale height of the molecular atmosphere, about 8 km).
.. [4] R. Hegedüs, S. Åkesson, G. Horváth, "Polarization patterns of thick clouds: overcast
   skies have distribution of the angle of polarization similar to that of clear skies",
   J. Opt. Soc. Am. A 24:2347-2356 (2007), doi:10.1364/JOSAA.24.002347.
.. [5] G. Pomozi, G. Horváth, R. Wehner, "How the clear-sky angle of polarization pattern
   continues underneath clouds", J. Exp. Biol. 204:2933-2942 (2001).
.. [6] T. Nakajima, M. Tanaka, "Algorithms for radiative intensity calculations in
   moderately thick atmospheres using a truncation approximation", J. Quant. Spectrosc.
   Radiat. Transfer 40:51-69 (1988), doi:10.1016/0022-4073(88)90031-3.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .disk_cache import finite_float_arrays, library_versions, load_entry, store_entry
from .exceptions import InvalidParameterError
from .multiple import MultipleScatteringSky, PoleSpline, _mu0, mode_nodes_deg, pole_orders
from .rt_sasktran import DEFAULT_SETTINGS, EngineSettings, ParticleLayer
from .validation import check_in_range

__all__ = [
    "CLOUD_TAU_RANGE",
    "MOLECULAR_SCALE_HEIGHT_M",
    "WATER_WAVELENGTH_RANGE_NM",
    "AzimuthModes",
    "CloudLayer",
    "CloudOptics",
    "CloudySky",
    "cloud_optics",
    "gamma_size_distribution",
    "molecular_fraction_below",
    "water_refractive_index",
]

MOLECULAR_SCALE_HEIGHT_M = 8000.0
"""Scale height of the molecular atmosphere [m] (Liou 2002, sect. 3.3.1 [3]_)."""

CLOUD_TAU_RANGE = (0.0, 20.0)
"""Cloud optical thicknesses accepted [1], thin cloud to stratocumulus: up to 20 the
transmitted flux agrees with the delta-Eddington within 2.3 % and, at 10 and 20, flux and
radiance with the asymptotic theory of thick layers within 1.2 % (``tests/test_clouds.py``;
the droplets' albedo capped at :data:`skysim.rt_sasktran.MAX_PARTICLE_SSA`)."""

# Hale & Querry (1973) [2]_, Table I: wavelength [nm], n, k of liquid water at 25 C
_HALE_QUERRY = np.array([
    [400.0, 1.339, 1.86e-9], [425.0, 1.338, 1.30e-9], [450.0, 1.337, 1.02e-9],
    [475.0, 1.336, 9.35e-10], [500.0, 1.335, 1.00e-9], [525.0, 1.334, 1.32e-9],
    [550.0, 1.333, 1.96e-9], [575.0, 1.333, 3.60e-9], [600.0, 1.332, 1.09e-8],
    [625.0, 1.332, 1.39e-8], [650.0, 1.331, 1.64e-8], [675.0, 1.331, 2.23e-8],
    [700.0, 1.331, 3.35e-8]])
WATER_WAVELENGTH_RANGE_NM = (400.0, 700.0)
"""Wavelengths [nm] of the tabulated refractive index of water (visible light)."""


def water_refractive_index(wavelength_nm) -> np.ndarray:
    """Complex refractive index ``n - i k`` of liquid water (sasktran2's sign of ``k``).

    Linear interpolation of Hale & Querry (1973), Table I [2]_ (1.333 - 1.96e-9 i at 550 nm).

    Parameters
    ----------
    wavelength_nm : array-like
        Wavelength [nm] in :data:`WATER_WAVELENGTH_RANGE_NM`.
    """
    lam = check_in_range("wavelength_nm", wavelength_nm, *WATER_WAVELENGTH_RANGE_NM,
                         hint="the cloud optics cover visible light, 400-700 nm")
    t = _HALE_QUERRY
    return np.interp(lam, t[:, 0], t[:, 1]) - 1j * np.interp(lam, t[:, 0], t[:, 2])


def gamma_size_distribution(effective_radius_um: float, effective_variance: float):
    """Gamma droplet size distribution of Hansen & Travis (1974), eq. (2.56) [1]_.

    ``n(r) ~ r^((1 - 3b)/b) exp(-r / (a b))`` with effective radius ``a`` and effective
    variance ``b``: a scipy gamma distribution of shape ``(1 - 2b)/b`` and scale ``a b``.

    Parameters
    ----------
    effective_radius_um : float
        Effective radius ``a`` [um], > 0.
    effective_variance : float
        Effective variance ``b`` [1], in (0, 0.5).

    Returns
    -------
    scipy.stats frozen distribution over radius [um].
    """
    from scipy.stats import gamma
    a = float(check_in_range("effective_radius_um", effective_radius_um, 0.0, 100.0,
                             low_open=True, hint="cloud droplets: 2-30 um"))
    b = float(check_in_range("effective_variance", effective_variance, 0.0, 0.5,
                             low_open=True, high_open=True, hint="water clouds: about 0.1"))
    return gamma(a=(1.0 - 2.0 * b) / b, scale=a * b)


@dataclass(frozen=True)
class CloudOptics:
    """Single-scattering properties of a droplet population at one wavelength.

    Attributes
    ----------
    greek : ndarray (4, L)
        Greek coefficients ``a1, a2, a3, b1`` (engine convention, ``a1[0] = 1``).
    single_scattering_albedo : float
    asymmetry_parameter : float
        ``g = a1[1] / 3``.
    angle_deg, p11, p12 : ndarray
        Scattering angles [deg] and phase-matrix elements (``p11`` normalised to mean 1 over
        the sphere; ``p12 / p11 > 0`` where the light is polarized perpendicular to the
        scattering plane).
    """

    greek: np.ndarray
    single_scattering_albedo: float
    asymmetry_parameter: float
    angle_deg: np.ndarray
    p11: np.ndarray
    p12: np.ndarray


@functools.lru_cache(maxsize=8)
def cloud_optics(wavelength_nm: float = 550.0, effective_radius_um: float = 10.0,
                 effective_variance: float = 0.1, n_moments: int = 1000) -> CloudOptics:
    """Mie optics of a water cloud from sasktran2's Lorenz-Mie code (~4 s; cached in the
    process and on disk, :data:`CLOUD_CACHE_KIND`).

    Parameters
    ----------
    wavelength_nm : float
        Wavelength [nm] in :data:`WATER_WAVELENGTH_RANGE_NM`.
    effective_radius_um, effective_variance : float
        Gamma size distribution (:func:`gamma_size_distribution`).
    n_moments : int
        Greek coefficients kept (1000 resolve the forward peak of 10-um droplets at 550 nm:
        the last ones are below 1e-4).
    """
    from .rt_sasktran import require_sasktran2
    require_sasktran2()
    params = {"format": _CLOUD_CACHE_FORMAT, "wavelength_nm": float(wavelength_nm),
              "effective_radius_um": float(effective_radius_um),
              "effective_variance": float(effective_variance), "n_moments": int(n_moments),
              **library_versions("sasktran2", "scipy")}
    hit = load_entry(CLOUD_CACHE_KIND, params, _CLOUD_ARRAYS)
    if hit is None or not _cloud_entry_usable(hit, int(n_moments)):
        hit = _integrate_cloud(wavelength_nm, effective_radius_um, effective_variance,
                               int(n_moments))
        store_entry(CLOUD_CACHE_KIND, params, hit)
    greek, ssa = hit["greek"], float(hit["single_scattering_albedo"])
    return CloudOptics(greek, min(ssa, 1.0), float(greek[0, 1] / 3.0), hit["angle_deg"],
                       hit["p11"], hit["p12"])


CLOUD_CACHE_KIND = "mie_cloud"
"""Subfolder of the on-disk cache (:mod:`skysim.disk_cache`) holding cloud optics: a later
process reads an entry back bit for bit instead of integrating again (~4 s); a missing,
corrupt or unreadable entry is computed and (re)written, an unwritable folder stores
nothing."""

_CLOUD_CACHE_FORMAT = 1
"""Version of an entry's content and of the integration set-up below: raise it when either
changes, so older entries are no longer found."""

_CLOUD_ARRAYS = ("greek", "single_scattering_albedo", "angle_deg", "p11", "p12")

_CLOUD_ANGLES = 1801
"""Scattering angles of the tabulated phase-matrix elements (0.1-deg steps)."""


def _cloud_entry_usable(entry: dict, n_moments: int) -> bool:
    """Whether a cache entry holds finite float64 optics of the expected shapes."""
    return finite_float_arrays(entry, {"greek": (4, n_moments), "single_scattering_albedo": (),
                                       "angle_deg": (_CLOUD_ANGLES,), "p11": (_CLOUD_ANGLES,),
                                       "p12": (_CLOUD_ANGLES,)})


def _integrate_cloud(wavelength_nm, effective_radius_um, effective_variance,
                     n_moments: int) -> dict:
    """The arrays of :data:`_CLOUD_ARRAYS` from sasktran2's Lorenz-Mie integration over the
    gamma size distribution."""
    from sasktran2.mie import LinearizedMie, integrate_mie
    dist = gamma_size_distribution(effective_radius_um, effective_variance)
    n = complex(water_refractive_index(wavelength_nm))
    lam_um = float(wavelength_nm) * 1e-3
    out = integrate_mie(LinearizedMie(), dist, lambda _: n, np.array([lam_um]),
                        num_angles=_CLOUD_ANGLES, num_quad=1024, compute_coeffs=True,
                        num_coeffs=n_moments)
    greek = np.stack([out[k].values[0] for k in ("lm_a1", "lm_a2", "lm_a3", "lm_b1")])
    return {"greek": np.asarray(greek, np.float64),
            "single_scattering_albedo": np.float64(out.xs_scattering.values[0]
                                                   / out.xs_total.values[0]),
            "angle_deg": np.asarray(out.angle.values, np.float64).copy(),
            "p11": np.asarray(out.p11.values[0], np.float64).copy(),
            "p12": np.asarray(out.p12.values[0], np.float64).copy()}


def molecular_fraction_below(height_m) -> np.ndarray:
    """Fraction of the molecular (Rayleigh) optical depth below ``height_m`` [m]:
    ``1 - exp(-z / H)`` with :data:`MOLECULAR_SCALE_HEIGHT_M` [3]_."""
    z = check_in_range("height_m", height_m, 0.0, 20000.0,
                       hint="cloud heights above the site in m (cirrus tops at most ~15 km)")
    return 1.0 - np.exp(-z / MOLECULAR_SCALE_HEIGHT_M)


@dataclass(frozen=True)
class CloudLayer:
    """A homogeneous liquid-water cloud layer.

    Parameters
    ----------
    tau : float
        Optical thickness [1] at ``wavelength_nm`` in :data:`CLOUD_TAU_RANGE` (thin cloud
        to stratocumulus; thicker stratus, up to 30 and more, is not verified).
    base_m, top_m : float
        Cloud base and top above the site [m], ``0 <= base < top <= 20000``.
    effective_radius_um, effective_variance : float
        Droplet size distribution (default: 10 um, 0.1 after Hansen & Travis 1974 [1]_).
    wavelength_nm : float
        Wavelength [nm] of the optics, in :data:`WATER_WAVELENGTH_RANGE_NM`.
    """

    tau: float
    base_m: float = 1000.0
    top_m: float = 2000.0
    effective_radius_um: float = 10.0
    effective_variance: float = 0.1
    wavelength_nm: float = 550.0

    def __post_init__(self):
        check_in_range("cloud tau", self.tau, *CLOUD_TAU_RANGE,
                       hint="cloud optical thickness (stratocumulus about 10-20); thicker clouds are not verified")
        if not 0.0 <= self.base_m < self.top_m <= 20000.0:
            raise InvalidParameterError(
                f"cloud base and top must satisfy 0 <= base < top <= 20000 m; got "
                f"base_m={self.base_m!r}, top_m={self.top_m!r}")
        gamma_size_distribution(self.effective_radius_um, self.effective_variance)
        water_refractive_index(self.wavelength_nm)

    def optics(self) -> CloudOptics:
        return cloud_optics(float(self.wavelength_nm), float(self.effective_radius_um),
                            float(self.effective_variance))

    def particle_layer(self) -> ParticleLayer:
        """The layer in the engine's terms (heights as molecular optical-depth fractions)."""
        o = self.optics()
        return ParticleLayer(float(molecular_fraction_below(self.base_m)),
                             float(molecular_fraction_below(self.top_m)),
                             o.single_scattering_albedo, o.greek)

    def to_dict(self) -> dict:
        return {"tau": float(self.tau), "base_m": float(self.base_m), "top_m": float(self.top_m),
                "phase": "liquid water droplets, Mie (sasktran2)",
                "size_distribution": "gamma (Hansen & Travis 1974, eq. 2.56)",
                "effective_radius_um": float(self.effective_radius_um),
                "effective_variance": float(self.effective_variance),
                "wavelength_nm": float(self.wavelength_nm)}


# --------------------------------------------------------------------------------------------
# Azimuthal modes of an overcast field
# --------------------------------------------------------------------------------------------

def fit_azimuths_deg(step_deg: float) -> np.ndarray:
    """Relative azimuths [deg] 0..180 at which the engine is called per zenith node."""
    n = int(round(180.0 / step_deg))
    if n < 4 or abs(n * step_deg - 180.0) > 1e-9:
        raise InvalidParameterError(f"azimuth_step_deg must divide 180 into >= 4 steps; got "
                                    f"{step_deg!r}. Default: 7.5.")
    return np.linspace(0.0, 180.0, n + 1)


@dataclass(frozen=True)
class AzimuthModes:
    """Cosine (I, Q) and sine (U) series in relative azimuth of a field that is symmetric
    about the solar meridian, interpolating engine values at equally spaced azimuths
    0..180 deg (trigonometric interpolation, the discrete cosine/sine transform), each mode
    interpolated in view zenith angle as :class:`skysim.multiple.FourierModes` does
    (:class:`skysim.multiple.PoleSpline`: divided by its power of ``sin(theta)`` at the zenith,
    a cubic spline even in ``theta``), on the nodes of :func:`skysim.multiple.mode_nodes_deg`.

    Attributes
    ----------
    theta_deg : ndarray (n,)
        View zenith angles of the engine rays [deg].
    coefficients : ndarray (3, M + 1, n)
        ``I_m, Q_m`` (cosine) and ``U_m`` (sine) for ``m = 0..M``.
    """

    theta_deg: np.ndarray
    coefficients: np.ndarray

    @classmethod
    def from_samples(cls, theta_deg, stokes) -> "AzimuthModes":
        """Modes from engine Stokes ``(n_zenith, M + 1, 3)`` at azimuths ``k 180 / M``."""
        stokes = np.asarray(stokes, float)
        M = stokes.shape[1] - 1
        m = np.arange(M + 1)
        phi = np.pi * m / M
        w = np.ones(M + 1)
        w[0] = w[-1] = 0.5          # trapezoid weights of the discrete transforms
        cos = np.cos(np.outer(m, phi)) * w      # (mode, azimuth)
        sin = np.sin(np.outer(m, phi)) * w
        scale = np.full(M + 1, 2.0 / M)
        scale[0] = scale[-1] = 1.0 / M
        c_iq = np.einsum("ka,tac->ctk", cos, stokes[..., :2]) * scale  # (2, theta, mode)
        sin_scale = np.full(M + 1, 2.0 / M)
        c_u = np.einsum("ka,ta->tk", sin, stokes[..., 2]) * sin_scale
        coeffs = np.stack([c_iq[0].T, c_iq[1].T, c_u.T])                # (3, mode, theta)
        return cls(np.asarray(theta_deg, float), coeffs)

    @functools.cached_property
    def _spline(self):
        m = np.arange(self.coefficients.shape[1])
        orders = np.stack([pole_orders(m, "I"), pole_orders(m, "Q"), pole_orders(m, "U")])
        return PoleSpline(self.theta_deg, self.coefficients, orders)

    def evaluate(self, theta_deg, phi_deg):
        """Return ``(I, Q, U)`` at view zenith ``theta_deg`` and relative azimuth ``phi_deg``
        [deg] (broadcast)."""
        theta, phi = np.broadcast_arrays(np.asarray(theta_deg, float),
                                         np.asarray(phi_deg, float))
        c = self._spline(theta.ravel())                                  # (3, mode, N)
        m = np.arange(c.shape[1])[:, None]
        p = np.radians(phi.ravel())[None, :]
        cos, sin = np.cos(m * p), np.sin(m * p)
        out = (np.sum(c[0] * cos, 0), np.sum(c[1] * cos, 0), np.sum(c[2] * sin, 0))
        return tuple(o.reshape(theta.shape) for o in out)


_OVERCAST_CACHE: dict = {}


def overcast_modes(tau: float, albedo: float, cloud: CloudLayer, mu0: float, *,
                   n_zenith: int = 25, azimuth_step_deg: float = 7.5,
                   depolarization_ratio: float = 0.0,
                   settings: EngineSettings = DEFAULT_SETTINGS) -> AzimuthModes:
    """Azimuth modes of the multiply scattered light below a Rayleigh slab with a cloud
    layer: the engine's total minus its own single scatter at the nodes (two engine calls,
    the second a single-scatter one of a few hundredths of a second; cached per arguments).

    The single scatter holds the droplets' forward peak (the aureole: ``P11`` falls by three
    decades over the first 10 deg), which no series of a few tens of azimuths and zenith
    nodes can follow (interpolated over 13 azimuths it gives I = 198 at 5 deg from the sun
    where the radiative transfer gives 1.1, and negative radiance 20 deg off the sun's
    azimuth); it is added back in closed form at every direction
    (:func:`overcast_single_scatter`). What is left has been scattered at least twice, through
    the engine's phase matrix truncated to ``settings.n_streams`` moments (delta-M), and
    varies over tens of degrees: the modes interpolate it (error measured in
    ``tests/test_clouds.py``).

    Parameters
    ----------
    tau, albedo : float
        Rayleigh optical thickness and ground albedo (as :class:`MultipleScatteringSky`).
    cloud : CloudLayer
    mu0 : float
        Cosine of the solar zenith angle, in (0, 1].
    n_zenith : int
        View zenith nodes (:func:`skysim.multiple.mode_nodes_deg`).
    azimuth_step_deg : float
        Spacing of the engine's relative azimuths [deg] (divides 180).
    """
    key = (float(tau), float(albedo), cloud, float(mu0), int(n_zenith), float(azimuth_step_deg),
           float(depolarization_ratio), settings)
    if key not in _OVERCAST_CACHE:
        from .rt_sasktran import MU_MAX, MU_MIN, layered_particle_stokes_cases
        mu = np.clip(np.cos(np.radians(mode_nodes_deg(int(n_zenith)))), MU_MIN, MU_MAX)
        az = fit_azimuths_deg(azimuth_step_deg)
        M, P = np.meshgrid(mu, az, indexing="ij")
        st = [layered_particle_stokes_cases(tau, albedo, [cloud.tau], cloud.particle_layer(),
                                            float(mu0), M.ravel(), P.ravel(),
                                            depolarization_ratio=depolarization_ratio,
                                            settings=settings, multiple_scatter=ms)[0]
              for ms in (True, False)]
        _OVERCAST_CACHE[key] = AzimuthModes.from_samples(np.degrees(np.arccos(mu)),
                                                         (st[0] - st[1]).reshape(M.shape + (3,)))
    return _OVERCAST_CACHE[key]


def overcast_single_scatter(tau: float, cloud: CloudLayer, view_elevation_deg,
                            view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg, *,
                            depolarization_ratio: float = 0.0,
                            settings: EngineSettings = DEFAULT_SETTINGS):
    """Singly scattered ``(I, Q, U)`` below the Rayleigh slab with its cloud layer, in closed
    form: the engine's single scatter at any direction, its forward peak (the aureole)
    included.

    The weights of :func:`skysim.slab_single_scatter.single_scatter_weights` on the
    engine's own levels (:func:`skysim.rt_sasktran.particle_layer_profile`), the droplets'
    Mie phase matrix (:func:`cloud_optics`, whole) and the Rayleigh one with depolarization
    (Hansen & Travis 1974, eq. (2.15) [1]_). As in the engine (its delta-M scaling with the
    single-scatter correction of Nakajima & Tanaka 1988 [6]_) the beam and the scattered
    light are attenuated by the droplets' extinction less the share ``f`` of their
    scattering in the truncated forward peak (:func:`skysim.rt_sasktran.delta_m_truncation`
    at ``settings.n_streams``): light scattered into the peak is counted as going on.

    Parameters
    ----------
    tau : float
        Rayleigh optical thickness of the slab.
    cloud : CloudLayer
    view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg : array-like
        Directions [deg], broadcast together; views and sun above the horizon.
    depolarization_ratio : float
        Molecular depolarization ratio.
    settings : EngineSettings
        The engine set-up whose levels and truncation are followed.

    Returns
    -------
    I, Q, U : ndarray
        In the unit of an incident solar flux ``pi``, local-meridian basis
        (``docs/conventions.md``), direct beam excluded.
    """
    from .rayleigh import meridian_components, scattering_angle_deg
    from .rt_sasktran import (MAX_PARTICLE_SSA, MU_MAX, MU_MIN, delta_m_truncation,
                              particle_layer_profile, rayleigh_depolarization_factor)
    from .slab_single_scatter import (perpendicular_stokes, phase_at_angle,
                                      single_scatter_weights)
    o = cloud.optics()
    w = min(o.single_scattering_albedo, MAX_PARTICLE_SSA)    # as the engine is given it
    z, k_r, k_p = particle_layer_profile(tau, [cloud.tau], cloud.particle_layer(), settings)
    scat = np.column_stack([k_r[:, 0], w * k_p[:, 0]])
    # the truncated forward peak stays in the beam: attenuation by the scaled extinction
    k_p = k_p * (1.0 - w * delta_m_truncation(o.greek, settings.n_streams)[1])
    vel, sel = np.asarray(view_elevation_deg, float), np.asarray(sun_elevation_deg, float)
    mu = np.clip(np.sin(np.radians(vel)), MU_MIN, MU_MAX)
    a_r, a_p = 0.25 * single_scatter_weights(z, scat, k_r[:, 0] + k_p[:, 0], mu,
                                             np.sin(np.radians(sel)))
    gam = scattering_angle_deg(vel, view_azimuth_deg, sel, sun_azimuth_deg)
    p11, p12 = phase_at_angle(o.angle_deg, o.p11, o.p12, gam)
    delta = rayleigh_depolarization_factor(depolarization_ratio)
    c2 = np.cos(np.radians(gam)) ** 2
    r11, r12 = delta * 0.75 * (1.0 + c2) + (1.0 - delta), delta * 0.75 * (1.0 - c2)
    a, b = meridian_components(vel, view_azimuth_deg, sel, sun_azimuth_deg)
    return perpendicular_stokes(a_r * r11 + a_p * p11, a_r * r12 + a_p * p12, a, b)


class CloudySky(MultipleScatteringSky):
    """Overcast sky: the multiple-scattering Rayleigh sky with a water-cloud layer.

    Parameters
    ----------
    cloud : CloudLayer
        The cloud (optical thickness, base and top, droplets).
    tau, albedo, wavelength_nm, pressure_hPa, latitude_deg, altitude_m, depolarization_ratio,
    sun_step_deg, settings
        As :class:`skysim.multiple.MultipleScatteringSky` (the clear atmosphere around the
        cloud; ``wavelength_nm`` also sets the cloud optics' wavelength when given).
    n_zenith : int
        View zenith nodes (default 25; with 17, 8.8 deg apart near the zenith, the radiance
        there errs by up to 3 % under a low sun).
    azimuth_step_deg : float
        Relative-azimuth spacing of the engine rays [deg] (default 7.5: 25 azimuths, modes up
        to m = 24). The multiply scattered light near the sun is peaked (scattered twice
        through the droplets' phase function cut to the engine's 32 moments): at 15 deg its
        series aliases into ripples of +-6 % over the whole almucantar of a low sun; at 7.5
        deg they are gone (Notes).

    Notes
    -----
    ``I`` has the normalisation of :class:`MultipleScatteringSky` (incident flux ``pi``,
    direct beam excluded; under a cloud of optical thickness ``tau_c`` the direct beam is
    attenuated by ``exp(-tau_c / mu0)`` and is left out).

    The field is the single scatter in closed form at every direction
    (:func:`overcast_single_scatter`: the droplets' aureole, however close to the sun) plus
    the multiply scattered light interpolated from the engine's rays (:func:`overcast_modes`);
    with ``sun_step_deg`` only the second is interpolated between sun nodes. Against exact
    engine runs off the nodes the radiance is within 1.2 % (RMS 0.05-0.25 %), the DoP within
    3.2e-3 and the AoP within 0.2 deg (cloud tau 0.25-2, suns 20-60 deg, views above 5 deg,
    including 3-20 deg from the sun; ``tests/test_clouds.py``, ``docs/clouds.md``). Two
    engine calls (some seconds) per sun elevation and cloud.
    """

    name = "cloudy"

    def __init__(self, cloud: CloudLayer, tau=None, albedo=0.0, wavelength_nm=None,
                 pressure_hPa=1013.25, *, latitude_deg=45.0, altitude_m=0.0,
                 depolarization_ratio=0.0, n_zenith: int = 25, azimuth_step_deg: float = 7.5,
                 sun_step_deg: float | None = None,
                 settings: EngineSettings = DEFAULT_SETTINGS):
        if not isinstance(cloud, CloudLayer):
            raise InvalidParameterError(f"cloud must be a CloudLayer; got {cloud!r}")
        super().__init__(tau, albedo, wavelength_nm, pressure_hPa, latitude_deg=latitude_deg,
                         altitude_m=altitude_m, depolarization_ratio=depolarization_ratio,
                         n_zenith=n_zenith, sun_step_deg=sun_step_deg, settings=settings)
        if wavelength_nm is not None and cloud.wavelength_nm != wavelength_nm:
            raise InvalidParameterError(
                f"the cloud's wavelength_nm={cloud.wavelength_nm!r} differs from the sky's "
                f"wavelength_nm={wavelength_nm!r}; give the cloud the same wavelength")
        fit_azimuths_deg(azimuth_step_deg)  # validates
        self.cloud = cloud
        self.azimuth_step_deg = float(azimuth_step_deg)

    def modes(self, sun_elevation_deg: float) -> AzimuthModes:
        """Azimuth modes of the multiply scattered light for one sun elevation [deg] (cached;
        :func:`overcast_modes`)."""
        return overcast_modes(self.tau, self.albedo, self.cloud, _mu0(sun_elevation_deg),
                              n_zenith=self.n_zenith, azimuth_step_deg=self.azimuth_step_deg,
                              depolarization_ratio=self.depolarization_ratio,
                              settings=self.settings)

    def _stokes(self, vel, vaz, sel, saz):
        multiple = super()._stokes(vel, vaz, sel, saz)      # interpolated (overcast_modes)
        single = overcast_single_scatter(self.tau, self.cloud, vel, vaz, sel, saz,
                                         depolarization_ratio=self.depolarization_ratio,
                                         settings=self.settings)
        return tuple(m + s for m, s in zip(multiple, single, strict=True))

    def describe(self) -> dict:
        out = super().describe()
        out.update(model=self.name, cloud=self.cloud.to_dict(),
                   azimuth_step_deg=self.azimuth_step_deg)
        return out
