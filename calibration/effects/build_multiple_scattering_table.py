"""Build the zenith table of the ``multiple_scattering`` effect (run once, result committed).

``python -m calibration.effects.build_multiple_scattering_table [--out PATH] [--quick]``

Physics used to keep the table small
------------------------------------
For a plane-parallel atmosphere over a Lambertian ground of albedo ``A`` the diffuse field
seen from the ground depends on ``A`` exactly as (Chandrasekhar 1950 [1]_, ch. IX, sec. 72,
"the principle of reduction" of the planetary problem to the standard problem; Coulson, Dave
& Sekera 1960 [2]_, introduction; Natraj et al. 2009 [3]_, eq. (10))::

    X(A) = X_0 + A / (1 - A s) * X_1,        X = I, Q, U,

where ``X_0`` is the field over a black ground, ``s`` the spherical albedo of the atmosphere
(the fraction of isotropic, unpolarized light from below that it reflects back down) and
``X_1`` the field produced by a unit Lambertian source at the ground (the ground-reflected
light scattered back down). ``s`` depends on ``tau`` only. Three engine runs at albedos
``0, a_1, a_2`` therefore fix ``X_0``, ``X_1`` and ``s`` for every ``A``: with
``D_k = I(a_k) - I_0``, ``a_k / D_k = (1 - a_k s) / I_1`` is linear in ``a_k``. Since ``s``
does not depend on the sun, the third albedo is run at one sun elevation per ``tau`` only
(:data:`S_REFERENCE_ELEVATION_DEG`); every other node needs two runs (``A = 0`` and ``a_2``),
and ``X_1 = (X(a_2) - X_0) (1 - a_2 s) / a_2``. (A 4 x 5 trial grid with all three albedos
at every node gave ``s`` equal over sun elevations to 1e-10.)
At the zenith the ground term is azimuthally symmetric, so ``Q_1 = U_1 = 0`` (checked here:
the engine returns ``|Q_1| / I_1 < 1e-6``); the ground only dilutes the zenith DoP.

Engine set-up
-------------
sasktran2 exactly as :func:`skysim.rt_sasktran.transmitted_stokes` (the set-up validated
against the Natraj et al. 2009 tables, ``docs/physical_sky.md``): exact single scatter plus
discrete-ordinates multiple scatter, 32 streams, 101 levels in a 10 km homogeneous slab on a
1e9 m planet (spherical geometry), pure Rayleigh phase matrix (depolarization ratio 0, as in
the tables), view cosine ``1 - 1e-6`` (0.08 deg off the zenith, the engine's limit) towards
the sun's azimuth. One engine call per sun elevation covers every ``(tau, albedo)`` pair as a
separate "wavelength" (optical properties per wavelength, same geometry); tested equal to
single calls.

Grid: ``tau`` log-spaced 0.02..1 (the effect's bounds), sun elevation 1..90 deg denser at a
low sun (the slant optical path ``tau / mu0`` grows fastest there); build albedos 0, 0.4,
0.8. A validation set of off-grid ``(tau, sun elevation, albedo)`` points is computed
directly and the largest interpolation error in zenith DoP is stored with the table.
About 10 min on one loaded core of the development machine (0.5-3 s per
``(tau, albedo, sun elevation)`` case depending on the load; 9 x 10 nodes, 189 cases, plus
16 validation cases).

References
----------
.. [1] S. Chandrasekhar, *Radiative Transfer*, Oxford (1950; Dover 1960), sec. 72.
.. [2] K. L. Coulson, J. V. Dave, Z. Sekera, *Tables Related to Radiation Emerging from a
   Planetary Atmosphere with Rayleigh Scattering*, Univ. California Press (1960).
.. [3] V. Natraj, K.-F. Li, Y. L. Yung, ApJ 691:1909-1920 (2009),
   doi:10.1088/0004-637X/691/2/1909.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from skysim.exceptions import InvalidParameterError
from skysim.io import atomic_write
from skysim.rt_sasktran import (
    DEFAULT_SETTINGS,
    MU_MAX,
    EngineSettings,
    transmitted_stokes_cases,
)

__all__ = ["BUILD_ALBEDOS", "SUN_ELEVATIONS_DEG", "S_REFERENCE_ELEVATION_DEG", "TABLE_PATH",
           "TABLE_SCHEMA", "TAUS",
           "albedo_reduction", "build_table", "main", "zenith_stokes"]

TABLE_SCHEMA = "skysim.multiple_scattering_zenith/1"
TABLE_PATH = Path(__file__).with_name("multiple_scattering_table.npz")

TAUS = np.geomspace(0.02, 1.0, 9)
"""Optical-thickness nodes [1]: log-spaced over the effect's bounds (ratio 1.63)."""

SUN_ELEVATIONS_DEG = np.array([1.0, 3.0, 6.0, 10.0, 16.0, 24.0, 34.0, 47.0, 65.0, 90.0])
"""Sun-elevation nodes [deg], denser at a low sun."""

S_REFERENCE_ELEVATION_DEG = 47.0
"""Sun elevation [deg] of the third-albedo runs that fix ``s`` (independent of the sun)."""

BUILD_ALBEDOS = (0.0, 0.4, 0.8)
"""Ground albedos of the three runs that fix ``X_0``, ``X_1`` and ``s``."""


def zenith_stokes(taus, albedos, sun_elevation_deg: float,
                  settings: EngineSettings = DEFAULT_SETTINGS) -> np.ndarray:
    """Diffuse zenith Stokes ``(I, Q, U)`` for many ``(tau, albedo)`` pairs, one engine call.

    Same physics, set-up, normalisation (incident flux ``pi``) and Stokes basis as
    :func:`skysim.rt_sasktran.transmitted_stokes` at ``mu = MU_MAX``, ``phi = 0``; each pair is
    one "wavelength" of the engine.

    Parameters
    ----------
    taus, albedos : array-like (m,)
        Optical thickness (> 0) and Lambertian albedo in [0, 1] of each case.
    sun_elevation_deg : float
        Sun elevation [deg], in (0, 90].

    Returns
    -------
    ndarray (m, 3)
        ``I, Q, U`` of each case.
    """
    if not 0.0 < sun_elevation_deg <= 90.0:
        raise InvalidParameterError(
            f"sun_elevation_deg must lie in (0, 90]; got {sun_elevation_deg}")
    mu0 = float(np.sin(np.radians(sun_elevation_deg)))
    return transmitted_stokes_cases(taus, albedos, mu0, [MU_MAX], [0.0],
                                    depolarization_ratio=0.0, settings=settings)[:, 0, :]


def albedo_reduction(x0, xa, xb, a=BUILD_ALBEDOS[1], b=BUILD_ALBEDOS[2]):
    """``(I_1, Q_1, s)`` from the zenith Stokes at albedos 0, ``a`` and ``b``.

    ``X(A) = X_0 + A X_1 / (1 - A s)`` (module docstring): with ``D = I(A) - I_0``,
    ``A / D = 1 / I_1 - A s / I_1`` is linear in ``A``; two albedos give ``1 / I_1`` and
    ``s / I_1``, then ``Q_1 = (Q(b) - Q_0) (1 - b s) / b``.

    Parameters
    ----------
    x0, xa, xb : ndarray (..., 3)
        ``I, Q, U`` at albedos 0, ``a``, ``b``.
    """
    ya = a / (xa[..., 0] - x0[..., 0])
    yb = b / (xb[..., 0] - x0[..., 0])
    c1 = (ya - yb) / (b - a)          # s / I_1
    c0 = ya + c1 * a                  # 1 / I_1
    s = c1 / c0
    i1 = 1.0 / c0
    q1 = (xb[..., 1] - x0[..., 1]) * (1.0 - b * s) / b
    return i1, q1, s


def build_table(taus=TAUS, sun_elevations_deg=SUN_ELEVATIONS_DEG, n_validation: int = 4,
                seed: int = 20261123, progress: bool = True) -> dict:
    """Run the engine on the grid and on an off-grid validation set; return the arrays.

    Returns
    -------
    dict
        ``tau`` (nt,), ``sun_elevation_deg`` (ne,), ``I0, Q0, I1, Q1`` (nt, ne), ``s`` (nt,),
        the
        validation set ``val_tau, val_sun_elevation_deg, val_albedo, val_I, val_Q`` (n_val,)
        computed directly by the engine, plus ``meta`` (JSON text).
    """
    taus = np.asarray(taus, float)
    els = np.asarray(sun_elevations_deg, float)
    t0 = time.perf_counter()
    cases_tau = np.repeat(taus, len(BUILD_ALBEDOS))
    cases_alb = np.tile(BUILD_ALBEDOS, taus.size)
    x_ref = zenith_stokes(cases_tau, cases_alb, S_REFERENCE_ELEVATION_DEG).reshape(
        taus.size, -1, 3)
    _, _, s = albedo_reduction(x_ref[:, 0], x_ref[:, 1], x_ref[:, 2])
    a2 = BUILD_ALBEDOS[2]
    out = np.empty((taus.size, els.size, 2, 3))
    for j, el in enumerate(els):  # one engine call per sun elevation (loop over the grid)
        out[:, j] = zenith_stokes(np.repeat(taus, 2), np.tile([0.0, a2], taus.size),
                                  el).reshape(taus.size, 2, 3)
        if progress:
            print(f"sun elevation {el:5.1f} deg done ({time.perf_counter() - t0:.0f} s)",
                  flush=True)
    g = (1.0 - a2 * s[:, None]) / a2
    i1 = (out[:, :, 1, 0] - out[:, :, 0, 0]) * g
    q1 = (out[:, :, 1, 1] - out[:, :, 0, 1]) * g
    # off-grid validation: log-uniform tau, sun elevation uniform between grid nodes
    rng = np.random.default_rng(seed)
    val_el = rng.uniform(els[0], els[-1], n_validation)
    val = []
    for el in val_el:  # one engine call per validation sun elevation
        vt = np.exp(rng.uniform(np.log(taus[0]), np.log(taus[-1]), n_validation))
        va = rng.uniform(0.0, 0.95, n_validation)
        st = zenith_stokes(vt, va, el)
        val.append(np.column_stack([vt, np.full(n_validation, el), va, st[:, 0], st[:, 1]]))
    val = np.concatenate(val)
    elapsed = time.perf_counter() - t0
    meta = {"schema": TABLE_SCHEMA,
            "engine": "sasktran2", "engine_settings": DEFAULT_SETTINGS.to_dict(),
            "view": "zenith (mu = 1 - 1e-6), towards the sun azimuth",
            "depolarization_ratio": 0.0, "build_albedos": list(BUILD_ALBEDOS),
            "normalisation": "incident solar flux pi per unit area normal to the beam; "
                             "diffuse only; skysim Stokes basis (Q < 0: E-vector "
                             "perpendicular to the solar meridian)",
            "albedo_formula": "X(A) = X0 + A/(1 - A s) X1 (Chandrasekhar 1950 sec. 72)",
            "s_reference_sun_elevation_deg": S_REFERENCE_ELEVATION_DEG,
            "validation_seed": seed, "build_seconds": round(elapsed, 1),
            "builder": "python -m calibration.effects.build_multiple_scattering_table"}
    return {"tau": taus, "sun_elevation_deg": els, "I0": out[:, :, 0, 0],
            "Q0": out[:, :, 0, 1], "I1": i1, "Q1": q1, "s": s,
            "val_tau": val[:, 0], "val_sun_elevation_deg": val[:, 1], "val_albedo": val[:, 2],
            "val_I": val[:, 3], "val_Q": val[:, 4], "meta": meta}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=str(TABLE_PATH), help="output .npz")
    p.add_argument("--quick", action="store_true",
                   help="coarse 4 x 5 grid (smoke test; not for the committed table)")
    args = p.parse_args(argv)
    kw = {"taus": TAUS[::4], "sun_elevations_deg": SUN_ELEVATIONS_DEG[::3],
          "n_validation": 2} if args.quick else {}
    table = build_table(**kw)
    # stated interpolation error: evaluate the effect's interpolant built from this table
    from .multiple_scattering import ZenithTable
    zt = ZenithTable.from_arrays(table)
    dop_direct = np.abs(table["val_Q"]) / table["val_I"]
    dop_table = np.array([zt.dop(el, tau, alb) for el, tau, alb in zip(
        table["val_sun_elevation_deg"], table["val_tau"], table["val_albedo"])])
    err = dop_table - dop_direct
    table["meta"].update(max_abs_dop_error_validation=float(np.max(np.abs(err))),
                         rms_dop_error_validation=float(np.sqrt(np.mean(err**2))),
                         max_q1_over_i1=float(np.max(np.abs(table["Q1"] / table["I1"]))))
    meta_text = json.dumps(table["meta"], indent=1)
    arrays = {k: v for k, v in table.items() if k != "meta"}

    def write(path):
        with open(path, "wb") as fh:
            np.savez_compressed(fh, meta=np.array(meta_text), **arrays)

    atomic_write(Path(args.out), write)
    print(meta_text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
