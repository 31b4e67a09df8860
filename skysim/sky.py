"""The ``Sky`` interface every sky model implements, and model selection by name.

A sensor never depends on one sky model: it asks a :class:`Sky` for the Stokes vector
arriving from given view directions for a given sun, and derives DoP, AoP and the E-vector
from it through :class:`SkyField`.

Models (select with :func:`make_sky`):

- ``"rayleigh"``: single scattering with a free d_max (:mod:`skysim.rayleigh`).
- ``"multiple"``: plane-parallel multiple-scattering Rayleigh atmosphere over a Lambertian
  ground (optional extra ``skysim[rt]``).
- ``"berry"``: the analytic neutral-point singularity model of Berry, Dennis & Lee (2004).
- ``"aerosol"``: molecules and an aerosol type (OPAC presets, Mie optics) over a Lambertian
  ground, multiple scattering (optional extra ``skysim[rt]``).

Broken clouds go in front of any of them: :class:`skysim.partly_cloudy.PartlyCloudySky`
(which needs the model's radiance unit, :meth:`Sky.flux_pi_scale`).
"""

from __future__ import annotations

import abc
import functools
import importlib
from dataclasses import dataclass

import numpy as np

from . import rayleigh
from .exceptions import BroadcastError, InvalidParameterError, UnsupportedOperationError
from .geometry import e_vector_from_aop, wrap_axial_deg
from .validation import (
    TWILIGHT_LIMIT_DEG,
    check_dop,
    check_finite,
    check_in_range,
    check_sun_above_horizon,
)

__all__ = ["SkyField", "Sky", "RayleighSky", "make_sky", "SKY_MODELS"]


@dataclass(frozen=True)
class SkyField:
    """Stokes parameters of the light from a set of view directions.

    Attributes
    ----------
    view_elevation_deg, view_azimuth_deg : ndarray
        View directions [deg] (broadcast to the field's shape).
    I, Q, U : ndarray
        Stokes parameters in the local-meridian basis (Q > 0: E-vector along the meridian).
        The unit of ``I`` is model specific and stated by the model.
    """

    view_elevation_deg: np.ndarray
    view_azimuth_deg: np.ndarray
    I: np.ndarray
    Q: np.ndarray
    U: np.ndarray

    @classmethod
    def with_polarization(cls, view_elevation_deg, view_azimuth_deg, I, Q, U, dop,
                          aop_deg) -> "SkyField":
        """A field whose model already knows DoP and AoP [deg] (not derived again from Q, U)."""
        f = cls(view_elevation_deg, view_azimuth_deg, I, Q, U)
        f.__dict__.update(dop=dop, aop_deg=aop_deg)  # fills the cached properties
        return f

    @functools.cached_property
    def dop(self) -> np.ndarray:
        """Degree of linear polarization sqrt(Q^2 + U^2) / I."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.hypot(self.Q, self.U) / self.I

    @functools.cached_property
    def aop_deg(self) -> np.ndarray:
        """Angle of polarization [deg, in [-90, 90)] from the local meridian towards +azimuth."""
        return wrap_axial_deg(0.5 * np.degrees(np.arctan2(self.U, self.Q)))

    @property
    def e_vector(self) -> np.ndarray:
        """Unit E-vector in ENU, shape ``(..., 3)`` (sign arbitrary: it is an axis)."""
        return e_vector_from_aop(self.view_elevation_deg, self.view_azimuth_deg, self.aop_deg)


class Sky(abc.ABC):
    """A clear-sky polarization model.

    Subclasses implement :meth:`_stokes`; :meth:`field` validates the input and broadcasts.
    """

    name: str = "abstract"
    min_sun_elevation_deg: float = 0.0
    """Lowest sun elevation [deg] the model holds for (0: a sunlit atmosphere is needed)."""

    def field(self, view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
              sun_azimuth_deg) -> SkyField:
        """Stokes field for view directions and sun positions (all in degrees, broadcast).

        Raises
        ------
        SunBelowHorizonError
            If any sun elevation is <= :attr:`min_sun_elevation_deg` (0 deg, or -10 deg for
            the single-scattering models, which hold in twilight).
        InvalidParameterError
            If a view direction is below the horizon or an input is not finite.
        BroadcastError
            If the inputs' shapes do not broadcast against each other.
        """
        check_sun_above_horizon(sun_elevation_deg, self.min_sun_elevation_deg)
        check_in_range("view_elevation_deg", view_elevation_deg, 0.0, 90.0,
                       hint="ground-based sky models only look up")
        check_finite("view_azimuth_deg", view_azimuth_deg)
        check_finite("sun_azimuth_deg", sun_azimuth_deg)
        args = tuple(np.asarray(a, dtype=float) for a in (
            view_elevation_deg, view_azimuth_deg, sun_elevation_deg, sun_azimuth_deg))
        try:
            np.broadcast_shapes(*(a.shape for a in args))
        except ValueError:
            raise BroadcastError(
                "view_elevation_deg, view_azimuth_deg, sun_elevation_deg and sun_azimuth_deg "
                f"of shapes {', '.join(str(a.shape) for a in args)} do not broadcast against "
                "each other; give arrays of one shape, or shapes such as (1, N) and (T, 1)") \
                from None
        return self._make_field(*args)

    def _make_field(self, vel, vaz, sel, saz) -> SkyField:
        """Field for validated, not yet broadcast inputs: broadcast and call :meth:`_stokes`.

        A model that can work on the inputs as given (e.g. trigonometry on a ``(1, N)`` grid
        and ``(T, 1)`` suns separately) or that knows DoP and AoP in closed form overrides
        this.
        """
        vel, vaz, sel, saz = np.broadcast_arrays(vel, vaz, sel, saz)
        I, Q, U = self._stokes(vel, vaz, sel, saz)
        return SkyField(vel, vaz, I, Q, U)

    @abc.abstractmethod
    def _stokes(self, view_elevation_deg, view_azimuth_deg, sun_elevation_deg,
                sun_azimuth_deg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return broadcast ``(I, Q, U)`` arrays for already validated inputs."""

    def flux_pi_scale(self, view_elevation_deg, sun_elevation_deg) -> np.ndarray:
        """This model's ``I`` for a radiance of 1 in the unit of an incident solar flux ``pi``
        per unit area normal to the beam (the unit of :mod:`skysim.multiple`), at view and
        sun elevations [deg] (broadcast): how light computed in that absolute unit, such as a
        cloud's (:mod:`skysim.partly_cloudy`), joins this sky.

        Raises
        ------
        UnsupportedOperationError
            For a model whose ``I`` has no stated absolute unit.
        """
        raise UnsupportedOperationError(f"sky model {self.name!r} does not state the unit of its "
                                        "radiance, so no cloud light can be added to it")

    def describe(self) -> dict:
        """Model name and parameters, for sidecars."""
        return {"model": self.name}


class RayleighSky(Sky):
    """Single-scattering Rayleigh sky with maximum degree of polarization ``dmax``.

    ``I`` is the relative radiance (3/4)(1 + cos^2 g) (mean 1 over the sphere).

    Parameters
    ----------
    dmax : float
        Maximum degree of polarization, in (0, 1].
    dtype : {"float64", "float32"}
        Arithmetic of the field. ``"float32"`` is about 3x faster and half the memory, with
        errors against float64 within :data:`skysim.rayleigh.FLOAT32_DOP_ERROR` (DoP) and
        :data:`skysim.rayleigh.FLOAT32_AOP_ERROR_DEG` (AoP, beyond
        :data:`skysim.rayleigh.FLOAT32_MIN_SCATTERING_ANGLE_DEG` from the sun and anti-sun).
    """

    name = "rayleigh"
    min_sun_elevation_deg = TWILIGHT_LIMIT_DEG
    DTYPES = ("float64", "float32")

    def __init__(self, dmax: float = 1.0, dtype: str = "float64"):
        if dmax != 1.0:
            check_dop("dmax", dmax)
        try:
            self.dtype = np.dtype(dtype)
        except TypeError:
            self.dtype = None
        if self.dtype is None or self.dtype.name not in self.DTYPES:
            raise InvalidParameterError(
                f"dtype must be one of {', '.join(self.DTYPES)}; got {dtype!r}")
        self.dmax = float(dmax)

    def _stokes(self, vel, vaz, sel, saz):
        f = rayleigh.polarization_field(vel, vaz, sel, saz, self.dmax, self.dtype)
        return f["I"], f["Q"], f["U"]

    def _make_field(self, vel, vaz, sel, saz) -> SkyField:
        f = rayleigh.polarization_field(vel, vaz, sel, saz, self.dmax, self.dtype)
        vel, vaz = (np.broadcast_to(x, f["I"].shape) for x in (vel, vaz))
        return SkyField.with_polarization(vel, vaz, f["I"], f["Q"], f["U"], f["dop"],
                                          f["aop_deg"])

    def flux_pi_scale(self, view_elevation_deg, sun_elevation_deg) -> np.ndarray:
        """The relative radiance against the flux-``pi`` unit: that of a thin Rayleigh slab
        of the molecular optical thickness at 550 nm (:func:`skysim.rayleigh.flux_pi_scale`)."""
        return rayleigh.flux_pi_scale(view_elevation_deg, sun_elevation_deg)

    def describe(self) -> dict:
        out = {"model": self.name, "dmax": self.dmax}
        if self.dtype != np.float64:
            out["dtype"] = str(self.dtype)
        return out


SKY_MODELS = {
    "rayleigh": "skysim.sky:RayleighSky",
    "multiple": "skysim.multiple:MultipleScatteringSky",
    "berry": "skysim.berry:BerrySky",
    "aerosol": "skysim.aerosol:AerosolSky",
}
"""Registered sky models: name -> 'module:Class' (imported lazily)."""


def make_sky(model: str = "rayleigh", **params) -> Sky:
    """Build a sky model by name, e.g. ``make_sky("rayleigh", dmax=0.7)``.

    Raises
    ------
    InvalidParameterError
        For an unknown model name (the message lists the valid ones), or a parameter the
        model does not take (the message lists the ones it takes).
    """
    import inspect
    if model not in SKY_MODELS:
        raise InvalidParameterError(
            f"unknown sky model {model!r}; valid: {', '.join(sorted(SKY_MODELS))}")
    module_name, cls_name = SKY_MODELS[model].split(":")
    cls = getattr(importlib.import_module(module_name), cls_name)
    takes = [n for n, p in inspect.signature(cls).parameters.items()
             if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    unknown = sorted(set(params) - set(takes))
    if unknown:
        raise InvalidParameterError(f"sky model {model!r} has no parameter(s) {unknown}; it "
                                    f"takes {', '.join(takes)}")
    return cls(**params)
