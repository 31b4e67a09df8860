"""Multiple scattering: the zenith DoP of a real Rayleigh atmosphere over a ground.

The base model takes the zenith DoP as ``d_max`` times the single-scattering shape
``sin^2 g / (1 + cos^2 g)``. In a plane-parallel Rayleigh atmosphere of optical thickness
``tau`` over a Lambertian ground of albedo ``A``, multiply scattered light (and light reflected
by the ground) is less polarized and depolarizes the sky unevenly: the DoP at the zenith falls
faster towards a low sun, and the neutral points (Arago, Babinet, Brewster) appear
(Coulson 1988 [1]_ ch. 6; tables of Natraj et al. 2009 [2]_). The effect replaces the shape by
the zenith DoP of :func:`skysim.sky.make_sky` ``("multiple", tau=..., albedo=...)`` (issue 3,
:mod:`skysim.multiple`), keeping the free scale ``s`` for aerosol depolarization. By the
symmetry of a plane-parallel atmosphere the zenith E-vector stays perpendicular to the solar
meridian, so ``phi`` is unchanged. The engine runs at sun-elevation nodes 5 deg apart over
the data's range (cubic spline between, cached per ``(tau, albedo)``).

Cost: each node is one radiative-transfer run (sasktran2: ~1 s on an idle core, 20-30 s on
the loaded 2-core development machine), and a fit probes a few dozen ``(tau, albedo)``
pairs, so this candidate is orders of magnitude slower than the others; the command line
leaves it out unless asked for (``--effects``).

References
----------
.. [1] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak
   (1988).
.. [2] V. Natraj, K.-F. Li, Y. L. Yung, ApJ 691:1909-1920 (2009),
   doi:10.1088/0004-637X/691/2/1909.
"""

from __future__ import annotations

from functools import lru_cache
from typing import ClassVar

import numpy as np

from skysim.geometry import wrap_axial_deg

from . import Effect

__all__ = ["EFFECT", "EffectUnavailableError", "MultipleScattering", "zenith_dop"]

NODE_STEP_DEG = 5.0
"""Spacing [deg] of the sun-elevation nodes at which the engine is called (cubic spline
between them: the zenith DoP is smooth in sun elevation, interpolation error ~h^4)."""


class EffectUnavailableError(RuntimeError):
    """The physics an effect needs is not installed or not built yet (says what to add)."""


@lru_cache(maxsize=4096)
def _zenith_dop_node(tau: float, albedo: float, sun_elevation_deg: float) -> float:
    try:
        from skysim.sky import make_sky
        sky = make_sky("multiple", tau=tau, albedo=albedo)
        return float(sky.field(90.0, 0.0, sun_elevation_deg, 180.0).dop)
    except (ImportError, AttributeError) as exc:
        raise EffectUnavailableError(
            "effect 'multiple_scattering' needs the multiple-scattering sky "
            "make_sky('multiple', tau=..., albedo=...) of skysim.multiple (issue 3) and its "
            f"radiative-transfer engine, which are not available here ({exc}); leave it out "
            "with --effects or install skysim[rt]") from exc


def zenith_dop(sun_elevation_deg, tau: float, albedo: float) -> np.ndarray:
    """Zenith DoP of the multiple-scattering sky at the given sun elevations [deg].

    The engine runs at sun-elevation nodes every :data:`NODE_STEP_DEG` covering the requested
    elevations (each node cached per ``(tau, albedo)``); a cubic spline interpolates between.
    """
    from scipy.interpolate import CubicSpline
    el = np.asarray(sun_elevation_deg, dtype=float)
    lo = max(NODE_STEP_DEG * (np.floor(el.min() / NODE_STEP_DEG) - 1), 1.0)
    hi = min(NODE_STEP_DEG * (np.ceil(el.max() / NODE_STEP_DEG) + 1), 90.0)
    nodes = np.unique(np.r_[np.arange(lo, hi, NODE_STEP_DEG), hi])
    key = (round(float(tau), 5), round(float(albedo), 5))
    values = np.array([_zenith_dop_node(*key, float(x)) for x in nodes])
    if nodes.size < 2:
        return np.full(el.shape, values[0])
    return CubicSpline(nodes, values)(el)


class MultipleScattering(Effect):
    """Optical thickness ``tau`` and ground albedo ``A`` of the multiple-scattering sky."""

    name = "multiple_scattering"
    parameter_names = ("tau", "albedo")
    units = ("1", "1")
    bounds = np.array([[0.02, 1.0], [0.0, 0.95]])
    prior_mean = np.array([0.15, 0.15])
    prior_sd = np.array([0.5, 0.5])
    fd_step = np.array([2e-3, 5e-3])
    stage = "geometry"
    null = np.array([np.nan, np.nan])  # no parameter value gives single scattering
    generation_range: ClassVar[dict] = {"tau": "U(0.05, 0.4) (Rayleigh optical thickness 700..400 nm)",
                        "albedo": "U(0, 0.4)"}

    def available(self):
        import importlib.util
        for module in ("skysim.multiple", "sasktran2"):
            if importlib.util.find_spec(module) is None:
                return (f"effect 'multiple_scattering' needs {module} (the multiple-scattering "
                        "sky of issue 3 and its engine, extra skysim[rt]); leave it out with "
                        "--effects or install it")
        return None

    def starts(self):
        return [np.array([0.1, 0.1]), np.array([0.3, 0.3])]

    def draw(self, rng):
        return np.array([rng.uniform(0.05, 0.4), rng.uniform(0.0, 0.4)])

    def polarization(self, ctx, p, heading_deg, sun_el_deg, sun_az_deg):
        tau, albedo = self.clip(p)
        phi = wrap_axial_deg(np.asarray(heading_deg) - sun_az_deg)
        return phi, zenith_dop(sun_el_deg, tau, albedo)


EFFECT = MultipleScattering()
