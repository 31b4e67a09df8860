"""Skies seen through a sensor's spectral response: band integration.

Real photodiodes and cameras are not monochromatic: a sensor behind a filter of spectral
response ``R(lambda)`` sees the Stokes vector ::

    S_band = int R(lambda) E(lambda) S(lambda) dlambda / int R(lambda) E(lambda) dlambda   [1]

with ``S(lambda) = (I, Q, U)`` the sky at wavelength ``lambda`` in the unit of an incident
flux ``pi`` (:meth:`skysim.sky.Sky.flux_pi_scale`) and ``E`` the spectral irradiance of the
source (the Sun). ``S_band`` is then again in the unit of an incident flux ``pi``, now the
band's, so the DoP and AoP of a band-integrated sky come from its integrated Stokes vector,
never from averaging DoP or AoP.

Quadrature by physics: the sky varies slowly and smoothly with wavelength, while a filter's
response may have steep edges. The molecular optical thickness goes as ``lambda^-4`` (an
aerosol's as a lower power), which across a broad band (B: 300-570 nm) changes twelvefold and
which no low-degree polynomial in ``lambda`` follows; in the wavenumber ``nu = 1 / lambda``
it *is* a polynomial (of degree 4, times the slowly varying King factor). So ``S`` is
interpolated by the polynomial in ``nu`` through its values at ``n`` Chebyshev nodes of the
band in ``nu`` (first kind: no Runge oscillation, Trefethen 2013 [2]_, ch. 8), and the weight
``R E`` is integrated exactly against each Lagrange basis polynomial on the response's own
fine grid (product integration, Davis & Rabinowitz 1984 [3]_, sect. 2.5): ``n`` sky
evaluations (each a radiative-transfer run for the multiple-scattering skies), an error set
by how well a degree ``n - 1`` polynomial in ``nu`` follows the sky across the band, not by
the response's shape, and a wavelength-independent sky reproduced exactly.

Source spectrum: the Sun as a black body at its nominal effective temperature, 5772 K (IAU
2015 Resolution B3 [4]_), unless given. Within one band only its slope matters; the black
body follows the measured solar spectrum's slope to within a few per cent per 100 nm
outside the strongest Fraunhofer lines (Gueymard 2004 [5]_, fig. 1).

Named bands: Johnson-Cousins U, B, V, R, I as Gaussian responses with Bessell's effective
wavelengths and widths (Bessell 2005 [1]_, Table 1, FWHM); a Gaussian is an approximation of
the tabulated filter curves, good for the smooth skies here; a measured curve should be given
as a table when it is at hand.

References
----------
.. [1] M. S. Bessell, "Standard photometric systems", Annu. Rev. Astron. Astrophys.
   43:293-336 (2005), doi:10.1146/annurev.astro.41.082801.100251, Table 1.
.. [2] L. N. Trefethen, *Approximation Theory and Approximation Practice*, SIAM (2013),
   ch. 8.
.. [3] P. J. Davis and P. Rabinowitz, *Methods of Numerical Integration*, 2nd ed., Academic
   Press (1984), sect. 2.5 (product integration).
.. [4] A. Prsa et al., "Nominal values for selected solar and planetary quantities: IAU 2015
   Resolution B3", Astron. J. 152:41 (2016), doi:10.3847/0004-6256/152/2/41.
.. [5] C. A. Gueymard, "The sun's total and spectral irradiance for solar energy
   applications and solar radiation models", Solar Energy 76:423-453 (2004),
   doi:10.1016/j.solener.2003.08.039.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .exceptions import InvalidParameterError
from .sky import Sky
from .validation import check_finite

__all__ = ["BESSELL_BANDS", "SOLAR_EFFECTIVE_TEMPERATURE_K", "BandSky", "SpectralResponse",
           "band_sky", "blackbody_spectrum", "get_response"]

SOLAR_EFFECTIVE_TEMPERATURE_K = 5772.0
"""Nominal effective temperature of the Sun [K] (IAU 2015 Resolution B3 [4]_)."""

BESSELL_BANDS = {"U": (366.0, 65.0), "B": (438.0, 89.0), "V": (545.0, 84.0),
                 "R": (641.0, 158.0), "I": (798.0, 154.0)}
"""Johnson-Cousins bands: effective wavelength and FWHM [nm] (Bessell 2005 [1]_, Table 1)."""

_H, _C, _K = 6.62607015e-34, 2.99792458e8, 1.380649e-23   # SI 2019 exact constants


def blackbody_spectrum(wavelength_nm, temperature_K: float = SOLAR_EFFECTIVE_TEMPERATURE_K):
    """Planck's spectral radiance shape ``lambda^-5 / (exp(hc / lambda k T) - 1)``, scaled to
    1 at its largest value over ``wavelength_nm`` (only the shape enters eq. [1])."""
    lam = np.asarray(wavelength_nm, float) * 1e-9
    b = lam ** -5 / np.expm1(_H * _C / (lam * _K * float(temperature_K)))
    return b / np.max(b)


@dataclass(frozen=True)
class SpectralResponse:
    """A sensor's relative spectral response, tabulated.

    Attributes
    ----------
    wavelength_nm : ndarray (m,)
        Strictly increasing [nm].
    response : ndarray (m,)
        Relative response, >= 0, not all 0 (any scale: photons or energy, as the sensor is
        calibrated; linear between the table's points).
    name : str
    """

    wavelength_nm: np.ndarray
    response: np.ndarray
    name: str = "custom"

    def __post_init__(self):
        lam = check_finite("wavelength_nm", np.asarray(self.wavelength_nm, float))
        r = check_finite("response", np.asarray(self.response, float))
        if lam.ndim != 1 or r.shape != lam.shape or lam.size < 2:
            raise InvalidParameterError(
                f"a spectral response needs two or more (wavelength, response) pairs of equal "
                f"length; got {lam.size} wavelengths and {r.size} responses")
        if np.any(np.diff(lam) <= 0):
            i = int(np.flatnonzero(np.diff(lam) <= 0)[0])
            raise InvalidParameterError(
                f"wavelength_nm must increase strictly; {lam[i + 1]:g} nm follows {lam[i]:g} nm")
        if np.any(r < 0) or not np.any(r > 0):
            raise InvalidParameterError(
                "response must be >= 0 and not all 0; got values from "
                f"{r.min():g} to {r.max():g}")
        object.__setattr__(self, "wavelength_nm", lam)
        object.__setattr__(self, "response", r)

    @classmethod
    def gaussian(cls, center_nm: float, fwhm_nm: float, name: str | None = None,
                 n: int = 201) -> "SpectralResponse":
        """A Gaussian response of given centre and FWHM [nm], tabulated over +-1.5 FWHM
        (the response there is 2e-3 of its peak)."""
        c, w = float(center_nm), float(fwhm_nm)
        if not (np.isfinite(c) and np.isfinite(w) and w > 0 and c - 1.5 * w > 0):
            raise InvalidParameterError(
                f"a Gaussian response needs a positive FWHM and a band above 0 nm; got centre "
                f"{center_nm!r} nm, FWHM {fwhm_nm!r} nm")
        lam = np.linspace(c - 1.5 * w, c + 1.5 * w, int(n))
        sigma = w / (2.0 * np.sqrt(2.0 * np.log(2.0)))
        return cls(lam, np.exp(-0.5 * ((lam - c) / sigma) ** 2),
                   name or f"gaussian {c:g}/{w:g} nm")

    @classmethod
    def from_csv(cls, path) -> "SpectralResponse":
        """A response from a CSV file with columns ``wavelength_nm`` and ``response``."""
        import pandas as pd
        path = Path(path)
        try:
            table = pd.read_csv(path)
        except (OSError, ValueError) as exc:
            raise InvalidParameterError(f"{path}: cannot read a spectral response: {exc}") \
                from None
        missing = {"wavelength_nm", "response"} - set(table.columns)
        if missing:
            raise InvalidParameterError(
                f"{path}: a spectral response needs the columns wavelength_nm and response; "
                f"missing {', '.join(sorted(missing))}")
        try:
            return cls(table.wavelength_nm.to_numpy(float), table.response.to_numpy(float),
                       path.name)
        except (InvalidParameterError, ValueError) as exc:
            raise InvalidParameterError(f"{path}: {exc}") from None

    def weights(self, n_nodes: int = 8, source: Callable | None = None):
        """Chebyshev nodes [nm] of the band and their product-integration weights (eq. [1]).

        Parameters
        ----------
        n_nodes : int
            Number of wavelengths at which the sky is evaluated (>= 1).
        source : callable, optional
            Source spectral irradiance shape ``E(wavelength_nm)``; default the solar black
            body (:func:`blackbody_spectrum`).

        Returns
        -------
        nodes_nm : ndarray (n,)
        weights : ndarray (n,)
            Summing to 1: ``S_band = sum_i w_i S(nodes_i)``.
        """
        n = int(n_nodes)
        if n < 1:
            raise InvalidParameterError(f"n_nodes must be >= 1; got {n_nodes!r}")
        from scipy.interpolate import BarycentricInterpolator
        lo, hi = self.wavelength_nm[0], self.wavelength_nm[-1]
        # the response's grid refined to resolve its edges and the basis polynomials
        grid = np.union1d(self.wavelength_nm, np.linspace(lo, hi, 2001))
        e = blackbody_spectrum(grid) if source is None else np.asarray(source(grid), float)
        wr = np.interp(grid, self.wavelength_nm, self.response) * e
        nu_lo, nu_hi = 1.0 / hi, 1.0 / lo
        k = np.arange(n)
        nu = 0.5 * (nu_lo + nu_hi) - 0.5 * (nu_hi - nu_lo) * np.cos((2 * k + 1) * np.pi
                                                                    / (2 * n))
        # Lagrange basis polynomials in nu on the grid: the interpolant of each unit vector
        basis = BarycentricInterpolator(nu, np.eye(n), axis=0)(1.0 / grid).T     # (n, grid)
        from scipy.integrate import trapezoid
        w = trapezoid(basis * wr, grid, axis=1)
        return 1.0 / nu, w / trapezoid(wr, grid)


def get_response(band_or_response) -> SpectralResponse:
    """A :class:`SpectralResponse` from itself, a band name (:data:`BESSELL_BANDS`) or the path
    of a CSV table (:meth:`SpectralResponse.from_csv`)."""
    if isinstance(band_or_response, SpectralResponse):
        return band_or_response
    if isinstance(band_or_response, str) and band_or_response in BESSELL_BANDS:
        c, w = BESSELL_BANDS[band_or_response]
        return SpectralResponse.gaussian(c, w, name=band_or_response)
    if isinstance(band_or_response, (str, Path)) and Path(band_or_response).suffix == ".csv":
        return SpectralResponse.from_csv(band_or_response)
    raise InvalidParameterError(
        f"unknown spectral band {band_or_response!r}; give one of "
        f"{', '.join(BESSELL_BANDS)}, a CSV file (wavelength_nm, response) or a "
        "SpectralResponse")


class BandSky(Sky):
    """The sky through a spectral response: a weighted sum of monochromatic skies (eq. [1]).

    ``I``, ``Q``, ``U`` are in the unit of an incident flux ``pi`` (each monochromatic sky's
    radiance divided by its :meth:`~skysim.sky.Sky.flux_pi_scale`).

    Parameters
    ----------
    skies : sequence of Sky
        The sky at each node wavelength.
    weights : array (n,)
        Product-integration weights (:meth:`SpectralResponse.weights`), summing to 1.
    description : dict, optional
        Recorded by :meth:`describe` (the response, the nodes).
    """

    name = "band"

    def __init__(self, skies, weights, description: dict | None = None):
        self.skies = tuple(skies)
        self.weights = np.asarray(weights, float)
        if len(self.skies) != self.weights.size or not self.skies:
            raise InvalidParameterError(
                f"a band sky needs one weight per sky; got {len(self.skies)} skies and "
                f"{self.weights.size} weights")
        self.min_sun_elevation_deg = max(s.min_sun_elevation_deg for s in self.skies)
        self._description = dict(description or {})

    def _stokes(self, vel, vaz, sel, saz):
        total = 0.0
        for sky, w in zip(self.skies, self.weights):
            f = sky.field(vel, vaz, sel, saz)
            total = total + np.stack([f.I, f.Q, f.U]) * (w / sky.flux_pi_scale(vel, sel))
        return total[0], total[1], total[2]

    def flux_pi_scale(self, view_elevation_deg, sun_elevation_deg) -> np.ndarray:
        """1: ``I`` is in the unit of an incident flux ``pi`` in the band."""
        return np.ones(np.broadcast_shapes(np.shape(view_elevation_deg),
                                           np.shape(sun_elevation_deg)))

    def describe(self) -> dict:
        return {"model": self.name, **self._description,
                "weights": [float(w) for w in self.weights],
                "skies": [s.describe() for s in self.skies]}


def band_sky(sky_at: Callable[[float], Sky], band, n_nodes: int = 8,
             source: Callable | None = None) -> BandSky:
    """The sky of a spectral band, from a function giving the sky at one wavelength.

    Parameters
    ----------
    sky_at : callable
        ``sky_at(wavelength_nm) -> Sky``, e.g. ``lambda lam: MultipleScatteringSky(
        wavelength_nm=lam, albedo=0.1)``.
    band : str, path or SpectralResponse
        A band name (:data:`BESSELL_BANDS`), a CSV response table or a response
        (:func:`get_response`).
    n_nodes : int
        Wavelengths at which ``sky_at`` is called (default 8: for a molecular slab across the
        broad B band, 300-570 nm, the error in I is 2e-5 relative at 5 deg elevation, where
        the slant optical path at the band's blue edge reaches 14, and 1e-7 in V; it falls
        about tenfold per two nodes; ``tests/test_spectral.py``).
    source : callable, optional
        Source spectrum shape (default the solar black body).

    Returns
    -------
    BandSky
    """
    response = get_response(band)
    nodes, weights = response.weights(n_nodes, source)
    return BandSky([sky_at(float(lam)) for lam in nodes], weights,
                   {"band": response.name, "nodes_nm": [float(x) for x in nodes],
                    "source": "solar black body 5772 K" if source is None else "given"})
