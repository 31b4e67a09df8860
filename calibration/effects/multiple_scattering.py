"""Multiple scattering: the zenith DoP of a real Rayleigh atmosphere over a ground.

The base model takes the zenith DoP as ``d_max`` times the single-scattering shape
``sin^2 g / (1 + cos^2 g)``. In a plane-parallel Rayleigh atmosphere of optical thickness
``tau`` over a Lambertian ground of albedo ``A``, multiply scattered light (and light reflected
by the ground) is less polarized and depolarizes the sky unevenly: the DoP at the zenith falls
faster towards a low sun, and the neutral points (Arago, Babinet, Brewster) appear
(Coulson 1988 [1]_ ch. 6; tables of Natraj et al. 2009 [2]_). The effect replaces the shape by
the zenith DoP of the multiple-scattering sky of :mod:`skysim.multiple`, keeping the
free scale ``s`` for aerosol depolarization. By the symmetry of a plane-parallel atmosphere the
zenith E-vector stays perpendicular to the solar meridian, so ``phi`` is unchanged.

Speed: a precomputed zenith table
---------------------------------
The radiative-transfer engine costs ~1 s per run, and a fit probes dozens of ``(tau, A)``
pairs, so the effect reads a table built once by
:mod:`calibration.effects.build_multiple_scattering_table` (sasktran2, the set-up of
:mod:`skysim.rt_sasktran`) and shipped next to this module (``multiple_scattering_table.npz``,
loaded with :mod:`importlib.resources`; no engine is needed at run time). Two pieces of
physics keep it small:

- the albedo enters exactly through Chandrasekhar's reduction of the planetary problem
  ([3]_ sec. 72; [2]_ eq. (10)): ``X(A) = X_0 + A / (1 - A s) X_1`` for ``X = I, Q`` with
  ``s`` the spherical albedo of the atmosphere, so the table holds ``I_0, Q_0, I_1, Q_1``
  per ``(tau, sun elevation)`` and ``s`` per ``tau`` (``s`` does not depend on the sun:
  equal over sun elevations to 1e-10 in a trial build);
- the zenith field is smooth in ``tau`` and sun elevation: the DoP at ``A = 0``,
  ``q = Q_0 / I_0``, and the ground ratios ``I_1 / I_0``, ``Q_1 / I_0`` are interpolated by
  bicubic (not-a-knot) splines in ``(ln tau, sun elevation)`` on a 9 x 10 grid (``tau`` 0.02..1, sun
  1..90 deg), ``s`` by a cubic spline in ``ln tau``. The zenith DoP is then

  ``|q + g Q_1/I_0| / (1 + g I_1/I_0)``, ``g = A / (1 - A s)``.

The interpolation error against direct engine runs at off-grid points is stored in the table
(``meta``) and tested (``tests/test_effects.py``). Sun elevations outside the table's range
(below 1 deg: the diagnosis excludes those samples) are clamped to it; ``tau`` and ``A`` are
held inside :attr:`MultipleScattering.bounds` by the fit.

References
----------
.. [1] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak
   (1988).
.. [2] V. Natraj, K.-F. Li, Y. L. Yung, ApJ 691:1909-1920 (2009),
   doi:10.1088/0004-637X/691/2/1909.
.. [3] S. Chandrasekhar, *Radiative Transfer*, Oxford (1950; Dover 1960), sec. 72.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from typing import ClassVar

import numpy as np

from skysim.geometry import wrap_axial_deg

from ..diagnosis.errors import EffectUnavailableError
from . import Effect

__all__ = ["EFFECT", "TABLE_NAME", "EffectUnavailableError", "MultipleScattering",
           "ZenithTable", "load_table", "zenith_dop"]

TABLE_NAME = "multiple_scattering_table.npz"
"""Package-data file of :mod:`calibration.effects` holding the zenith table."""


@lru_cache(maxsize=8)
def _design_matrix(el_bytes: bytes, knots_bytes: bytes):
    """Cubic B-spline basis (sparse, n x n_nodes) at the sun elevations of a data set: a fit
    evaluates the same elevations for every (tau, A), so the basis is built once."""
    from scipy.interpolate import BSpline
    el = np.frombuffer(el_bytes)
    return BSpline.design_matrix(el, np.frombuffer(knots_bytes), 3).tocsr()


@dataclass(frozen=True)
class ZenithTable:
    """Interpolant of the diffuse zenith field over ``(tau, sun elevation)`` (module docstring).

    The bicubic interpolating spline (not-a-knot in both directions) is held as a cubic spline
    in ``ln tau`` whose values are the B-spline coefficients in sun elevation of
    ``(Q_0 / I_0, I_1 / I_0, Q_1 / I_0)``: at one ``tau`` the DoP of ``n`` samples is then a
    sparse ``(n x 10) @ (10 x 3)`` product.

    Attributes
    ----------
    tau, sun_elevation_deg : ndarray
        Grid nodes [1], [deg].
    coef : BSpline
        Over ``ln tau``; values (n_el, 3) B-spline coefficients in sun elevation.
    knots : ndarray
        Knots of the sun-elevation B-splines [deg].
    s : CubicSpline
        Spherical albedo of the atmosphere over ``ln tau``.
    meta : dict
        Build record (engine set-up, validation errors).
    """

    tau: np.ndarray
    sun_elevation_deg: np.ndarray
    coef: object
    knots: np.ndarray
    s: object
    meta: dict

    @classmethod
    def from_arrays(cls, a) -> ZenithTable:
        """Interpolant from the table arrays (``tau``, ``sun_elevation_deg``, ``I0``, ``Q0``,
        ``I1``, ``Q1``, ``s``, optional ``meta`` JSON text or dict)."""
        from scipy.interpolate import CubicSpline, make_interp_spline
        x = np.log(np.asarray(a["tau"], float))
        y = np.asarray(a["sun_elevation_deg"], float)
        i0 = np.asarray(a["I0"], float)
        z = np.stack([np.asarray(a["Q0"]) / i0, np.asarray(a["I1"]) / i0,
                      np.asarray(a["Q1"]) / i0], axis=-1)            # (n_tau, n_el, 3)
        along_el = make_interp_spline(y, z, k=3, axis=1)
        coef = make_interp_spline(x, along_el.c, k=3, axis=1)  # c: (n_el, n_tau, 3)
        meta = a.get("meta", {}) if isinstance(a, dict) else a["meta"]
        meta = json.loads(str(meta)) if not isinstance(meta, dict) else meta
        return cls(np.exp(x), y, coef, np.asarray(along_el.t, float),
                   CubicSpline(x, np.asarray(a["s"], float)), meta)

    def dop(self, sun_elevation_deg, tau: float, albedo: float) -> np.ndarray:
        """Zenith DoP [1] at sun elevations [deg] for one optical thickness and ground albedo:
        ``|q + g p| / (1 + g r)`` with ``g = A / (1 - A s(tau))``."""
        el = np.asarray(sun_elevation_deg, float)
        flat = np.ascontiguousarray(np.clip(el.ravel(), self.sun_elevation_deg[0],
                                            self.sun_elevation_deg[-1]))
        lt = float(np.clip(np.log(tau), np.log(self.tau[0]), np.log(self.tau[-1])))
        g = float(albedo) / (1.0 - float(albedo) * float(self.s(lt)))
        q, r, p = (_design_matrix(flat.tobytes(), self.knots.tobytes()) @ self.coef(lt)).T
        return (np.abs(q + g * p) / (1.0 + g * r)).reshape(el.shape)


@lru_cache(maxsize=1)
def load_table() -> ZenithTable:
    """The committed zenith table (:data:`TABLE_NAME`), loaded once.

    Raises
    ------
    EffectUnavailableError
        When the file is missing (rebuild it with
        ``python -m calibration.effects.build_multiple_scattering_table``).
    """
    ref = resources.files(__package__).joinpath(TABLE_NAME)
    if not ref.is_file():
        raise EffectUnavailableError(
            f"effect 'multiple_scattering' needs its zenith table {TABLE_NAME} in "
            f"{__package__}; build it with `python -m "
            f"{__package__}.build_multiple_scattering_table` (needs sasktran2, skysim[rt])")
    with ref.open("rb") as fh, np.load(fh) as z:
        return ZenithTable.from_arrays({k: z[k] for k in z.files})


def zenith_dop(sun_elevation_deg, tau: float, albedo: float) -> np.ndarray:
    """Zenith DoP of the multiple-scattering sky at the given sun elevations [deg]
    (:meth:`ZenithTable.dop` of :func:`load_table`)."""
    return load_table().dop(sun_elevation_deg, tau, albedo)


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
    generation_range: ClassVar[dict] = {
        "tau": "U(0.05, 0.4) (Rayleigh optical thickness 700..400 nm)",
        "albedo": "U(0, 0.4)"}

    def available(self):
        try:
            load_table()
        except EffectUnavailableError as exc:
            return str(exc)
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
