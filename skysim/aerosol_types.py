"""Aerosol types and their Mie optics: log-normal components mixed by number (OPAC).

An aerosol type is an external mixture of spherical components, each a log-normal number
size distribution ``dN/dln r = N / (sqrt(2 pi) ln sigma) exp(-(ln r - ln r_mod)^2 /
(2 ln^2 sigma))`` with mode (median) radius ``r_mod`` and geometric standard deviation
``sigma`` ([1]_, eq. (1)), truncated at twice its 0.99999 number quantile (the engine's
integration range), and a complex refractive index ``m = n - i k``. The Mie
integration over each distribution (cross-sections and the Greek coefficients of the
scattering matrix) is sasktran2's own (``sasktran2.mie``, [2]_); this module mixes the
components by number:

- extinction and scattering per unit volume ``beta = sum_i N_i C_i``;
- Greek coefficients weighted by the scattering of each component,
  ``alpha_l = sum_i N_i C_sca,i alpha_l,i / sum_i N_i C_sca,i`` ([3]_, eq. (2.56)).

The optics of each component (one Mie integration, up to a few seconds for coarse modes)
are cached in the process and on disk (:mod:`skysim.disk_cache`, subfolder ``mie/`` of
``$SKYSIM_CACHE_DIR``, else ``$XDG_CACHE_HOME/skysim``, else ``~/.cache/skysim``), one
``.npz`` per entry keyed by the SHA-256 of every field of the component, the wavelength, the
number of moments and the sasktran2 and scipy versions: a later process reads the result
back bit for bit. A corrupt entry is recomputed and overwritten; a cache folder that cannot
be written only means nothing is stored; deleting the folder is always safe.

Presets (:data:`PRESETS`) are OPAC's mixtures [1]_ (Table 4: number densities per component;
Table 1: the components' ``r_mod`` and ``sigma`` for dry particles; refractive indices of
the dry components at 550 nm from the OPAC data files). Stated simplifications: particles
are dry (0 % relative humidity: OPAC's water-soluble and sea-salt particles grow with
humidity, e.g. at 80 % the published mixtures scatter more and more forward), the
refractive index is held at its 550 nm value at every wavelength (the Angstrom exponent
then follows from the size distribution alone), and the vertical profile is one exponential
with OPAC's aerosol scale height for the type (OPAC adds free-tropospheric and
stratospheric layers above the boundary layer).

References
----------
.. [1] M. Hess, P. Koepke, I. Schult, "Optical Properties of Aerosols and Clouds: The
   Software Package OPAC", Bull. Amer. Meteor. Soc. 79:831-844 (1998),
   doi:10.1175/1520-0477(1998)079<0831:OPOAAC>2.0.CO;2.
.. [2] D. J. Zawada et al., SASKTRAN2, ``sasktran2.mie.distribution.integrate_mie_cpp``
   (sasktran2 on PyPI).
.. [3] J. E. Hansen, L. D. Travis, "Light scattering in planetary atmospheres", Space Sci.
   Rev. 16:527-610 (1974), doi:10.1007/BF00168069.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np

from .disk_cache import finite_float_arrays, library_versions, load_entry, store_entry
from .exceptions import InvalidParameterError
from .validation import check_in_range

__all__ = ["AerosolComponent", "AerosolType", "AerosolOptics", "COMPONENTS", "PRESETS",
           "N_MOMENTS", "REFERENCE_WAVELENGTH_NM", "aerosol_optics", "aerosol_type"]

REFERENCE_WAVELENGTH_NM = 550.0
"""Wavelength [nm] at which the aerosol optical depth is given (``aod_550``)."""

N_MOMENTS = 512
"""Greek-coefficient moments kept per aerosol (exact single scatter; see docs/physical_sky.md
for the convergence that sets it)."""


@dataclass(frozen=True)
class AerosolComponent:
    """One log-normal component.

    Attributes
    ----------
    name : str
        OPAC's short name (``WASO``, ``INSO``, ...).
    mode_radius_um : float
        Mode (median) radius of the number distribution [um].
    sigma : float
        Geometric standard deviation (> 1).
    refractive_index : complex
        ``n - i k`` (sasktran2's sign: negative imaginary part absorbs).
    """

    name: str
    mode_radius_um: float
    sigma: float
    refractive_index: complex

    def __post_init__(self):
        check_in_range("mode_radius_um", self.mode_radius_um, 1e-4, 20.0,
                       hint="aerosol mode radii lie between 1e-4 and 20 um")
        check_in_range("sigma", self.sigma, 1.0, 4.0, low_open=True,
                       hint="geometric standard deviation of a log-normal, e.g. 2.0")
        m = complex(self.refractive_index)
        if not (1.0 < m.real < 3.0 and m.imag <= 0.0):
            raise InvalidParameterError(
                f"refractive_index={m!r}: give n - ik with 1 < n < 3 and k >= 0, e.g. 1.53-0.006j")


COMPONENTS = {
    "WASO": AerosolComponent("WASO", 0.0212, 2.24, 1.53 - 0.006j),   # water-soluble
    "INSO": AerosolComponent("INSO", 0.471, 2.51, 1.53 - 0.008j),    # insoluble (dust-like)
    "SOOT": AerosolComponent("SOOT", 0.0118, 2.00, 1.75 - 0.44j),    # soot
    "SSAM": AerosolComponent("SSAM", 0.209, 2.03, 1.50 - 1e-8j),     # sea salt, accumulation
    "SSCM": AerosolComponent("SSCM", 1.75, 2.03, 1.50 - 1e-8j),      # sea salt, coarse
    "MINM": AerosolComponent("MINM", 0.07, 1.95, 1.53 - 0.0055j),    # mineral, nucleation
    "MIAM": AerosolComponent("MIAM", 0.39, 2.00, 1.53 - 0.0055j),    # mineral, accumulation
    "MICM": AerosolComponent("MICM", 1.90, 2.15, 1.53 - 0.0055j),    # mineral, coarse
}
"""OPAC components, dry ([1]_, Table 1; refractive index at 550 nm)."""


@dataclass(frozen=True)
class AerosolType:
    """An external mixture of components.

    Attributes
    ----------
    name : str
    components : tuple of (AerosolComponent, float)
        Each component with its number density [1/cm^3] (only ratios matter: the optical
        depth is set by ``aod_550``).
    scale_height_km : float
        Exponential scale height of the aerosol extinction [km].
    source : str
        Where the numbers come from.
    """

    name: str
    components: tuple
    scale_height_km: float
    source: str = "user"

    def __post_init__(self):
        if not self.components:
            raise InvalidParameterError("an aerosol type needs at least one component")
        for comp, n in self.components:
            if not isinstance(comp, AerosolComponent) or not (np.isfinite(n) and n > 0):
                raise InvalidParameterError(
                    f"components must be (AerosolComponent, number density > 0) pairs; got "
                    f"({comp!r}, {n!r})")
        check_in_range("scale_height_km", self.scale_height_km, 0.1, 100.0,
                       hint="aerosol scale heights are 1-8 km (OPAC)")

    def describe(self) -> dict:
        return {"name": self.name, "scale_height_km": self.scale_height_km,
                "source": self.source,
                "components": [{"name": c.name, "mode_radius_um": c.mode_radius_um,
                                "sigma": c.sigma,
                                "refractive_index": [c.refractive_index.real,
                                                     c.refractive_index.imag],
                                "number_density_cm3": n} for c, n in self.components]}


_OPAC = "OPAC (Hess, Koepke & Schult 1998, Table 4), dry components"


def _preset(name, h_km, **numbers):
    return AerosolType(name, tuple((COMPONENTS[k], float(v)) for k, v in numbers.items()),
                       h_km, _OPAC)


PRESETS = {
    "continental_clean": _preset("continental_clean", 8.0, WASO=2600.0, INSO=0.15),
    "continental_average": _preset("continental_average", 8.0, WASO=7000.0, INSO=0.4,
                                   SOOT=8300.0),
    "urban": _preset("urban", 8.0, WASO=28000.0, INSO=1.5, SOOT=130000.0),
    "maritime_clean": _preset("maritime_clean", 1.0, WASO=1500.0, SSAM=20.0, SSCM=3.2e-3),
    "desert": _preset("desert", 2.0, WASO=2000.0, MINM=269.5, MIAM=30.5, MICM=0.142),
}
"""OPAC aerosol types ([1]_, Table 4: number densities [1/cm^3] and scale heights [km])."""


def aerosol_type(preset) -> AerosolType:
    """The :class:`AerosolType` named ``preset`` (a key of :data:`PRESETS`), or ``preset``
    itself when it already is one.

    Raises
    ------
    InvalidParameterError
        For an unknown name (the message lists the presets).
    """
    if isinstance(preset, AerosolType):
        return preset
    if preset not in PRESETS:
        raise InvalidParameterError(
            f"unknown aerosol preset {preset!r}; valid: {', '.join(PRESETS)}")
    return PRESETS[preset]


@dataclass(frozen=True)
class AerosolOptics:
    """Bulk optics of an aerosol type at one wavelength.

    Attributes
    ----------
    wavelength_nm : float
    extinction : float
        Extinction per unit volume for the type's number densities [1/m] (only ratios
        between wavelengths matter).
    ssa : float
        Single-scattering albedo.
    greek : ndarray (n_moments, 4)
        ``alpha1, alpha2, alpha3, beta1`` of the scattering matrix (sasktran2's convention,
        ``alpha1_0 = 1``; ``alpha1_1 / 3`` is the asymmetry parameter).
    """

    wavelength_nm: float
    extinction: float
    ssa: float
    greek: np.ndarray

    @property
    def asymmetry(self) -> float:
        """Asymmetry parameter ``g = alpha1_1 / 3``."""
        return float(self.greek[1, 0] / 3.0)


MIE_CACHE_KIND = "mie"
"""Subfolder of the on-disk cache (:mod:`skysim.disk_cache`) holding the component optics."""

_MIE_CACHE_FORMAT = 1
"""Version of what an entry holds and how it is computed here (the distribution set-up below):
raise it when either changes, so older entries are no longer found."""

_MIE_ARRAYS = ("extinction", "scattering", "greek")


def _field_json(value):
    """A component field as exact JSON: complex -> [re, im], real numbers -> float."""
    if isinstance(value, (complex, np.complexfloating)):
        return [float(value.real), float(value.imag)]
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        return float(value)
    return value if isinstance(value, str) else repr(value)


def _mie_cache_params(comp: AerosolComponent, wavelength_nm: float, n_moments: int,
                      sasktran2) -> dict:
    """Everything the optics of one component depend on: every field of the component, the
    wavelength, the moment count and the versions of the code that integrates."""
    versions = library_versions("sasktran2", "scipy")
    if versions["sasktran2"] == "unknown":  # pragma: no cover - an unpackaged sasktran2 build
        versions["sasktran2"] = str(getattr(sasktran2, "__version__", "unknown"))
    return {"format": _MIE_CACHE_FORMAT,
            "component": {f.name: _field_json(getattr(comp, f.name)) for f in fields(comp)},
            "wavelength_nm": float(wavelength_nm), "n_moments": int(n_moments), **versions}


def _integrate_component(comp: AerosolComponent, wavelength_nm: float, n_moments: int):
    """Mie cross-sections [m^2 per particle] and Greek coefficients of one component from
    sasktran2's size-distribution integration ([2]_)."""
    from scipy.stats import lognorm
    from sasktran2.mie.distribution import integrate_mie_cpp
    dist = lognorm(np.log(comp.sigma), scale=comp.mode_radius_um * 1e3)  # radii in [nm]
    m = complex(comp.refractive_index)
    ds = integrate_mie_cpp([dist], lambda _w: m, np.array([float(wavelength_nm)]),
                           num_coeffs=int(n_moments))
    ext = float(ds.xs_total.values[0, 0])           # [m^2] per particle
    sca = float(ds.xs_scattering.values[0, 0])
    greek = np.stack([ds[f"lm_{k}"].values[0, 0] for k in ("a1", "a2", "a3", "b1")], axis=1)
    return ext, sca, np.asarray(greek, dtype=float)


def _usable(entry: dict, n_moments: int) -> bool:
    """Whether a cache entry holds finite float64 optics of the expected shapes."""
    return finite_float_arrays(entry, {"extinction": (), "scattering": (),
                                       "greek": (int(n_moments), 4)})


@functools.lru_cache(maxsize=64)
def _component_optics(comp: AerosolComponent, wavelength_nm: float, n_moments: int):
    """``(extinction [m^2], scattering [m^2], greek (n_moments, 4))`` of one component.

    Cached per process (this LRU cache) and across processes on disk
    (:mod:`skysim.disk_cache`, subfolder ``mie/``): an entry computed before on this machine
    is read back bit for bit; a missing, corrupt or unreadable one is computed and
    (re)written; an unwritable cache folder only means nothing is stored.
    """
    from .rt_sasktran import require_sasktran2
    sasktran2 = require_sasktran2()
    params = _mie_cache_params(comp, wavelength_nm, n_moments, sasktran2)
    hit = load_entry(MIE_CACHE_KIND, params, _MIE_ARRAYS)
    if hit is not None and _usable(hit, n_moments):
        return float(hit["extinction"]), float(hit["scattering"]), hit["greek"]
    ext, sca, greek = _integrate_component(comp, wavelength_nm, n_moments)
    store_entry(MIE_CACHE_KIND, params, {"extinction": np.float64(ext),
                                         "scattering": np.float64(sca), "greek": greek})
    return ext, sca, greek


def aerosol_optics(preset, wavelength_nm: float, n_moments: int = N_MOMENTS) -> AerosolOptics:
    """Extinction, single-scattering albedo and Greek coefficients of an aerosol type.

    Parameters
    ----------
    preset : str or AerosolType
        A key of :data:`PRESETS` or a user type.
    wavelength_nm : float
        Wavelength [nm], 250-2500.
    n_moments : int
        Greek-coefficient moments (>= 16).

    Returns
    -------
    AerosolOptics
        Cached per component, wavelength and ``n_moments`` (a coarse mode takes seconds),
        in this process and on disk for later processes (module notes).
    """
    t = aerosol_type(preset)
    lam = float(check_in_range("wavelength_nm", wavelength_nm, 250.0, 2500.0))
    if int(n_moments) < 16:
        raise InvalidParameterError(f"n_moments must be >= 16; got {n_moments}")
    ext = sca = 0.0
    greek = np.zeros((int(n_moments), 4))
    for comp, number in t.components:
        e, s, g = _component_optics(comp, lam, int(n_moments))
        n = number * 1e6                                    # [1/m^3]
        ext += n * e
        sca += n * s
        greek += n * s * g
    return AerosolOptics(lam, ext, sca / ext, greek / sca)
