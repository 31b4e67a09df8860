"""Error-sensitivity sweeps of the three-pair sensor: Monte-Carlo statistics and SALib indices.

``skysim sweep CONFIG.toml [--backend local|dask] [--scheduler ADDRESS] [--out DIR]``

Each *trial* is one sensor with its own error parameters (configuration:
:mod:`experiments.workflows.sweep_config`) doing one turntable sweep of ``stops`` stops evenly
over the polarization azimuth ``phi`` in [-90, 90) under a fixed sun. Per trial and channel pair the
sweep records the heading error of the ideal solve (eqs. 5-9 of Yang et al. 2014 [1]_, "raw")
and, after a Gauss-Newton LSM calibration on the even stops (eqs. 10-14, with the DoP scale
fitted), of the compensated solve on the odd (held-out) stops; "3 sigma" is 3 x RMS about
zero (bias included), as in ``docs/conventions.md``.

Forward model, vectorised over trials and stops:

- Sky: any model of :func:`skysim.sky.make_sky`, sun at azimuth 0 (only relative azimuths
  matter) and elevation ``sun_elevation_deg``. The sensor sees the sky along its boresight;
  ``dmax`` scales the model's DoP.
- Tilt: the turntable axis is tilted by ``tilt_deg`` towards ``tilt_azimuth_deg``; the sensor
  frame is the level frame rotated by that tilt (Rodrigues' formula [3]_), the E-vector of the
  boresight's sky point is projected onto the tilted sensor axes.
- Channels: eqs. (2)-(3) of [1]_ generalised with a dark current ``delta`` (relative to the
  mean photocurrent of each photodiode):
  ``U_i = g (log10((1 + d cos 2x_1 + delta) / (1 - d cos 2x_2 + delta)) + f_i) + v_i``; with
  ``delta = 0`` this is the paper's equation. Then 16-bit DAQ quantisation.
- Reference heading: the turntable reading (true heading + ``turntable_error_deg`` noise)
  minus the sun azimuth, as a level sensor would see it.

Randomness: trials are grouped in blocks of :data:`BLOCK_TRIALS`; block ``b`` draws from
``numpy.random.SeedSequence(seed, spawn_key=(b,))`` (the ``b``-th child of
``SeedSequence(seed).spawn``), so results are identical for any chunking and backend. SALib
designs (Sobol, Morris) use common random numbers: one noise realisation for all trials, so
that the model the estimators see is a deterministic function of the parameters.

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424.
.. [2] A. Saltelli et al., "Variance based sensitivity analysis of model output. Design and
   estimator for the total sensitivity index", Comput. Phys. Commun. 181:259 (2010),
   doi:10.1016/j.cpc.2009.09.018; M. D. Morris, Technometrics 33(2):161 (1991),
   doi:10.1080/00401706.1991.10484804 (both through SALib).
.. [3] O. Rodrigues, J. Math. Pures Appl. 5:380 (1840); any rotation text, e.g. J. Diebel,
   "Representing attitude", Stanford (2006), eq. 96.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skysim.exceptions import InvalidParameterError, SkysimError

from experiments.plotting.figures import pyplot, save_png
from experiments.workflows.options import (existing_file, output_dir, positive_int,
                                           refuse_replacing_inputs)
from .sweep_config import GROUPS, PARAMETERS, SweepConfig, SweepConfigError, load_config

__all__ = ["BLOCK_TRIALS", "SweepMemoryError", "SweepStateError", "block_seed", "design",
           "simulate_trials", "evaluate_trials", "ephemeris_sun_elevation", "ChunkPlan",
           "ChunkTask", "check_sweep_memory", "expected_trials", "plan_chunks", "run_chunk",
           "run_sweep", "sensitivity_indices", "summary_table", "register"]

BLOCK_TRIALS = 64
"""Trials per random-number block (the unit of seeding; chunks are whole blocks)."""

BYTES_PER_TRIAL_STOP = 1000
"""Memory of one trial per turntable stop [bytes] for chunk sizing, about twice the measured
marginal peak (tracemalloc, 256 vs 1,024 trials x 182 stops with three calibrated pairs:
~450 B per trial and stop, Gauss-Newton Jacobians and their step-halving copies dominating);
``tests/test_sweep.py`` checks a budget-sized chunk's peak stays inside the budget."""


class SweepMemoryError(SweepConfigError):
    """Not even one block of trials fits the memory budget; raise ``memory_mb`` or lower
    ``stops``."""


class SweepStateError(SkysimError, RuntimeError):
    """The output folder holds a different sweep (its configuration digest differs)."""


def block_seed(seed: int, block: int) -> np.random.SeedSequence:
    """Seed of trial block ``block``: the ``block``-th child of ``SeedSequence(seed).spawn``."""
    return np.random.SeedSequence(seed, spawn_key=(block,))


# --------------------------------------------------------------------------- design


def _members(cfg: SweepConfig) -> list[tuple[str, object]]:
    return [(m, p) for p in cfg.factors for m in p.members]


def salib_problem(cfg: SweepConfig) -> dict:
    """SALib problem of the varying parameters (groups as configured)."""
    mem = _members(cfg)
    problem = {"num_vars": len(mem), "names": [m for m, _ in mem],
               "bounds": [p.salib_bounds()[0] for _, p in mem],
               "dists": [p.salib_bounds()[1] for _, p in mem]}
    if any(len(p.members) > 1 for p in cfg.factors):
        problem["groups"] = [p.name for _, p in mem]
    return problem


def design(cfg: SweepConfig):
    """Trial count and, for SALib methods, the design matrix.

    Returns
    -------
    n_trials : int
    X : ndarray (n_trials, D) or None
        Values of the varying parameters (columns ``salib_problem(cfg)["names"]``), repeated
        for each sun-elevation condition; None for ``montecarlo`` (drawn per block).
    conditions : ndarray (n_trials,) or None
        Sun elevation [deg] of each trial's condition.
    """
    if cfg.method == "montecarlo":
        return cfg.trials, None, None
    problem = salib_problem(cfg)
    if cfg.method == "sobol":
        from SALib.sample import sobol
        X = sobol.sample(problem, cfg.base_samples, calc_second_order=False, seed=cfg.seed)
    else:
        from SALib.sample import morris
        X = morris.sample(problem, cfg.base_samples, num_levels=cfg.morris_levels,
                          seed=cfg.seed)
    conds = np.asarray(cfg.conditions or [np.nan])
    return (len(X) * conds.size, np.tile(X, (conds.size, 1)),
            np.repeat(conds, len(X)))


def trial_parameters(cfg: SweepConfig, n: int, rng: np.random.Generator, X=None,
                     conditions=None) -> dict:
    """Every parameter of :data:`PARAMETERS` for ``n`` trials, arrays of shape (n,).

    Varying parameters come from ``X`` (SALib design rows) or, for Monte-Carlo, are drawn
    from ``rng`` in configuration order; fixed and unconfigured ones take their value.
    """
    out = {k: np.full(n, v) for k, v in PARAMETERS.items()}
    col = 0
    for p in cfg.parameters:
        for m in p.members:
            if p.fixed:
                out[m] = np.full(n, p.args[0])
            elif X is not None:
                out[m] = np.asarray(X[:, col], dtype=float)
                col += 1
            elif p.dist == "uniform":
                out[m] = rng.uniform(p.args[0], p.args[1], n)
            else:
                out[m] = p.args[0] + p.args[1] * rng.standard_normal(n)
    if conditions is not None and np.isfinite(conditions).all():
        out["sun_elevation_deg"] = np.asarray(conditions, dtype=float)
    return out


def ephemeris_sun_elevation(cfg: SweepConfig, params: dict) -> np.ndarray:
    """Sun elevation [deg] of each trial from its site and date, in one array call of
    :func:`skysim.sun.sun_position` (geometric, NREL SPA).

    The trial's UTC time is 1 January of ``cfg.year`` + ``floor(day_of_year) - 1`` days +
    ``local_time_h - longitude_deg / 15`` hours (``day_of_year`` picks the date, its fraction
    is ignored; ``local_time_h`` is local mean solar time).

    Raises
    ------
    SweepConfigError
        If the sun is not above the horizon (or is at the zenith) for some trial: the
        message gives the first such trial's site and date and how many there are.
    """
    import pandas as pd

    from skysim.sun import sun_position
    lat, lon = params["latitude_deg"], params["longitude_deg"]
    hours = (24.0 * (np.floor(params["day_of_year"]) - 1.0) + params["local_time_h"]
             - lon / 15.0)
    times = pd.Timestamp(f"{cfg.year}-01-01T00:00Z") + pd.to_timedelta(hours * 3600.0, "s")
    el = sun_position(pd.DatetimeIndex(times), lat, lon).elevation_deg.to_numpy()
    bad = np.flatnonzero(~((el > 0.0) & (el < 90.0)))
    if bad.size:
        k = bad[0]
        raise SweepConfigError(
            f"{bad.size} of {el.size} trials have the sun at {el[k]:.2f} deg, outside (0, 90) "
            f"(first: latitude_deg {lat[k]:.3f}, longitude_deg {lon[k]:.3f}, day_of_year "
            f"{params['day_of_year'][k]:.2f}, local_time_h {params['local_time_h'][k]:.2f}); "
            "narrow the latitude, date or local-time ranges to daytime")
    return el


# --------------------------------------------------------------------------- physics


def tilted_axes(heading_deg, tilt_deg, tilt_azimuth_deg):
    """Forward and right axes of a sensor on a tilted turntable, ENU, shape (T, n, 3).

    The level axes at heading ``h`` are ``f0 = (sin h, cos h, 0)`` and ``r0 = (cos h, -sin h,
    0)``; the tilt rotates them by ``tau`` about the horizontal axis ``k = (-cos a, sin a, 0)``
    that takes the zenith to the boresight (elevation ``90 - tau``, azimuth ``a``): the
    rotation vector ``tau k`` (scipy's ``Rotation.from_rotvec``).

    Parameters
    ----------
    heading_deg : (n,) [deg]
    tilt_deg, tilt_azimuth_deg : (T,) [deg]
    """
    from scipy.spatial.transform import Rotation
    h = np.radians(np.asarray(heading_deg, float))
    tau = np.radians(np.atleast_1d(np.asarray(tilt_deg, float)))
    a = np.radians(np.atleast_1d(np.asarray(tilt_azimuth_deg, float)))
    zero = np.zeros_like(h)
    f0 = np.stack([np.sin(h), np.cos(h), zero], axis=-1)                  # (n, 3)
    r0 = np.stack([np.cos(h), -np.sin(h), zero], axis=-1)
    k = np.stack([-np.cos(a), np.sin(a), np.zeros_like(a)], axis=-1)      # (T, 3)
    R = Rotation.from_rotvec(tau[:, None] * k).as_matrix()                # (T, 3, 3)
    return np.einsum("tij,nj->tni", R, f0), np.einsum("tij,nj->tni", R, r0)


def opponent_outputs(phi_deg, dop, dtheta_deg, f, dark_rel, gain: float):
    """Channel outputs with dark current [V], shape (T, n, 3): the photodiode model of
    :func:`sensor.photodiode.three_pair_outputs` for one sensor per trial.

    Unit incident intensity, photodiode responsivities ``(10^f_i, 1)`` per channel (so the
    transmittance term is ``f_i`` of eqs. (2)-(3) of [1]_) and a dark level ``delta`` on every
    photodiode, relative to a photodiode's mean photocurrent: ``U_i = g log10((10^f_i (1 + d
    cos 2(phi + a_i + dth_{2i-1})) + delta) / (1 - d cos 2(phi + a_i + dth_{2i}) + delta))``.
    ``delta = 0`` gives the paper's equation.

    Parameters
    ----------
    phi_deg : (T, n) [deg]
    dop : (T, 1) or (T, n)
    dtheta_deg : (T, 6) [deg]
    f : (T, 3) [log10 units]
    dark_rel : (T,)
    gain : [V/decade]
    """
    from sensor.photodiode import three_pair_outputs
    T = np.shape(dtheta_deg)[0]
    responsivity = np.stack([10.0 ** np.asarray(f), np.ones((T, 3))], axis=-1).reshape(T, 1, 6)
    dark = np.broadcast_to(np.asarray(dark_rel, float)[:, None, None], (T, 1, 6))
    return three_pair_outputs(1.0, phi_deg, dop, gain=gain,
                              mounting_error_deg=np.asarray(dtheta_deg)[:, None, :],
                              responsivity=responsivity, dark=dark)


def simulate_trials(params: dict, stops: int, sky, daq, noise, table_noise, gain: float):
    """Simulate one sweep per trial.

    Parameters
    ----------
    params : dict of (T,) arrays (every name of :data:`PARAMETERS`)
    stops : int
    sky : skysim.sky.Sky
    daq : sensor.daq.Daq
    noise : (T, stops, 3) standard normal draws (channel noise)
    table_noise : (T, stops) standard normal draws (turntable reading)
    gain : float [V/decade]

    Returns
    -------
    dict with ``phi_level`` (T, stops) the heading-equivalent phi of a perfect level sensor
    [deg], ``phi_ref`` (T, stops) the reference from the turntable reading [deg], ``U``
    (T, stops, 3) [V] and ``dop_shape`` (T,) the level zenith DoP of the sky model.
    """
    from skysim.geometry import wrap_axial_deg
    heading = -90.0 + 180.0 * np.arange(stops) / stops          # relative to the sun [deg]
    sun_el = params["sun_elevation_deg"]
    tilt, tilt_az = params["tilt_deg"], params["tilt_azimuth_deg"]
    level = sky.field(90.0, 0.0, sun_el, 0.0)
    e0 = level.e_vector
    e_az0 = np.degrees(np.arctan2(e0[..., 0], e0[..., 1]))
    phi_level = wrap_axial_deg(heading[None, :] - e_az0[:, None] - 90.0)
    seen = sky.field(90.0 - tilt, tilt_az, sun_el, 0.0)
    e = seen.e_vector[:, None, :]
    fwd, right = tilted_axes(heading, tilt, tilt_az)
    chi_cw = np.degrees(np.arctan2(np.sum(e * right, -1), np.sum(e * fwd, -1)))
    phi_seen = wrap_axial_deg(-chi_cw - 90.0)
    dop = (params["dmax"] * seen.dop)[:, None]
    dtheta = np.stack([params[f"dtheta{k}_deg"] for k in range(1, 7)], axis=-1)
    f = np.stack([params[f"f{k}"] for k in range(1, 4)], axis=-1)
    U = opponent_outputs(phi_seen, dop, dtheta, f, params["dark_current_rel"], gain)
    U = daq.acquire(U + params["noise_V"][:, None, None] * noise)[0]
    phi_ref = wrap_axial_deg(phi_level + params["turntable_error_deg"][:, None] * table_noise)
    return {"phi_level": phi_level, "phi_ref": phi_ref, "U": U, "dop_shape": level.dop}


def _three_sigma(err, axis=-1):
    return 3.0 * np.sqrt(np.mean(np.square(err), axis=axis))


def evaluate_trials(sim: dict, pairs, calibrate: bool = True, gain: float = 0.5) -> dict:
    """Heading errors per trial and pair: raw and LSM-compensated, on the odd stops.

    Returns a dict of (T,) columns: ``raw_3sigma_deg_p12``, ``raw_max_abs_deg_p12`` and, with
    ``calibrate``, ``compensated_3sigma_deg_p12``, ``compensated_max_abs_deg_p12``,
    ``converged_p12``, ``dop_scale_p12`` (same for the other pairs).
    """
    from calibration.exceptions import ConvergenceError
    from calibration.lsq import fit_pairs
    from calibration.solve import heading_error_deg, solve_pair
    U, phi_level, phi_ref = sim["U"], sim["phi_level"], sim["phi_ref"]
    fit = np.arange(U.shape[1]) % 2 == 0
    out = {}
    for label in pairs:
        pair = (int(label[0]), int(label[-1]))
        tag = f"p{pair[0]}{pair[1]}"
        raw = heading_error_deg(solve_pair(U[:, ~fit], pair, gain)[0], phi_level[:, ~fit])
        out[f"raw_3sigma_deg_{tag}"] = _three_sigma(raw)
        out[f"raw_max_abs_deg_{tag}"] = np.max(np.abs(raw), axis=-1)
        if not calibrate:
            continue
        cal = fit_pairs(phi_ref[:, fit], U[:, fit], pair, sim["dop_shape"][:, None],
                        fit_dop_scale=True, gain=gain, on_failure="flag")
        try:
            comp_phi = cal.solve(U[:, ~fit])[0]
            solved = np.ones(len(U), bool)
        except ConvergenceError:
            comp_phi, solved = _solve_flagged(cal, U[:, ~fit])
        comp = heading_error_deg(comp_phi, phi_level[:, ~fit])
        out[f"compensated_3sigma_deg_{tag}"] = _three_sigma(comp)
        out[f"compensated_max_abs_deg_{tag}"] = np.max(np.abs(comp), axis=-1)
        out[f"converged_{tag}"] = np.asarray(cal.converged) & solved
        out[f"dop_scale_{tag}"] = np.asarray(cal.dop_scale)
    return out


def _solve_flagged(cal, U):
    """Compensated solve when some trial's Newton iteration diverges: bisect the batch so
    the diverging trials are found in O(log T) vectorised solves; theirs become NaN and are
    flagged (``converged = False``), never silently replaced."""
    from calibration.exceptions import ConvergenceError
    from calibration.solve import solve_pair_compensated
    phi = np.full(U.shape[:2], np.nan)
    ok = np.ones(len(U), bool)
    stack = [np.arange(len(U))]
    while stack:
        idx = stack.pop()
        try:
            phi[idx] = solve_pair_compensated(U[idx], cal.pair, cal.misalignment_deg[idx],
                                              cal.transmittance[idx], cal.gain)[0]
        except ConvergenceError:
            if idx.size == 1:
                ok[idx] = False
            else:
                stack += [idx[: idx.size // 2], idx[idx.size // 2:]]
    return phi, ok


# --------------------------------------------------------------------------- chunks


@dataclass(frozen=True)
class ChunkTask:
    """One chunk: trials ``[start, stop)`` (whole seed blocks) and where to write them."""

    cfg: SweepConfig
    index: int
    start: int
    stop: int
    path: str
    digest: str
    X: np.ndarray | None = None
    conditions: np.ndarray | None = None


def chunk_trials(cfg: SweepConfig) -> int:
    """Trials per chunk: ``cfg.chunk_trials`` or the memory budget, in whole seed blocks.

    Raises
    ------
    SweepMemoryError
        If one block of :data:`BLOCK_TRIALS` trials exceeds ``cfg.memory_mb``.
    """
    per_trial = BYTES_PER_TRIAL_STOP * cfg.stops
    if cfg.chunk_trials is not None:
        wanted = cfg.chunk_trials
    else:
        wanted = int(cfg.memory_mb * 1e6 // per_trial)
    if BLOCK_TRIALS * per_trial > cfg.memory_mb * 1e6:
        raise SweepMemoryError(
            f"one block of {BLOCK_TRIALS} trials x {cfg.stops} stops needs about "
            f"{BLOCK_TRIALS * per_trial / 1e6:.0f} MB, more than [execution] memory_mb = "
            f"{cfg.memory_mb:g}; raise memory_mb or lower [sweep] stops")
    blocks = max(1, min(wanted, int(cfg.memory_mb * 1e6 // per_trial)) // BLOCK_TRIALS)
    return blocks * BLOCK_TRIALS


class ChunkPlan(Sequence):
    """The chunks of a sweep as a lazy sequence: task ``k`` is made when it is asked for, so
    planning takes constant time and memory whatever the number of trials."""

    def __init__(self, cfg: SweepConfig, out: Path, digest: str, n_trials: int, X=None,
                 conditions=None):
        self.cfg, self.out, self.digest, self.n_trials = cfg, Path(out), digest, n_trials
        self.X, self.conditions = X, conditions
        self.size = chunk_trials(cfg)

    def __len__(self) -> int:
        return -(-self.n_trials // self.size)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        if k < 0:
            k += len(self)
        if not 0 <= k < len(self):
            raise IndexError(f"chunk {k} of {len(self)}")
        start = k * self.size
        stop = min(start + self.size, self.n_trials)
        return ChunkTask(self.cfg, k, start, stop,
                         str(self.out / "chunks" / f"chunk-{k:06d}.parquet"), self.digest,
                         None if self.X is None else self.X[start:stop],
                         None if self.conditions is None else self.conditions[start:stop])


def plan_chunks(cfg: SweepConfig, out: Path, digest: str, n_trials: int, X=None,
                conditions=None) -> ChunkPlan:
    """Split the sweep into memory-bounded chunks of whole seed blocks (a lazy sequence of
    :class:`ChunkTask`)."""
    return ChunkPlan(cfg, out, digest, n_trials, X, conditions)


ANALYSIS_BYTES_PER_VALUE = 24
"""Memory of one analysed value of one trial [bytes]: the float64 read from
``trials.parquet`` (8 B), Arrow's buffer while converting and pandas' copies in the grouped
statistics (2 x 8 B)."""


def expected_trials(cfg: SweepConfig) -> int:
    """Number of trials :func:`design` makes, without making it: Monte-Carlo ``trials``;
    Sobol (first and total order) ``N (G + 2)``, Morris ``N (G + 1)`` per sun-elevation
    condition, G the number of varying factors (groups count once) [2]_."""
    if cfg.method == "montecarlo":
        return cfg.trials
    g = len(cfg.factors)
    per = cfg.base_samples * (g + 2 if cfg.method == "sobol" else g + 1)
    return per * max(1, len(cfg.conditions))


def check_sweep_memory(cfg: SweepConfig, workers: int = 1) -> None:
    """Refuse a sweep whose design or analysis would not fit in memory (the chunks stream,
    but the summary and indices hold the analysed columns of every trial), or whose chunks,
    ``workers`` at a time on this machine, would not.

    Raises
    ------
    MemoryLimitError
        With the estimate and the limit.
    """
    from skysim.resources import check_memory
    n = expected_trials(cfg)
    size = min(chunk_trials(cfg), n)
    check_memory(workers * size * cfg.stops * BYTES_PER_TRIAL_STOP,
                 f"{workers} chunk(s) of {size} trials x {cfg.stops} stops at a time",
                 "lower [execution] memory_mb or chunk_trials, or --workers")
    values = len(analysis_columns(cfg)) + (2 * len(salib_problem(cfg)["names"])
                                           if cfg.method != "montecarlo" else 0)
    check_memory(n * values * ANALYSIS_BYTES_PER_VALUE,
                 f"the analysis of {n} trials ({values} values each)",
                 "lower [sweep] trials or [sensitivity] base_samples")


_META_KEY = b"skysim.sweep"


def run_chunk(task: ChunkTask) -> dict:
    """Simulate, evaluate and atomically write one chunk (Parquet, one row per trial)."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    from sensor.daq import Daq
    from sensor.opponent import GAIN
    from skysim.io import atomic_write
    from skysim.sky import make_sky

    t0 = time.perf_counter()
    cfg = task.cfg
    parts, noise, tnoise, blocks = [], [], [], []
    for b in range(task.start // BLOCK_TRIALS, math.ceil(task.stop / BLOCK_TRIALS)):
        lo, hi = b * BLOCK_TRIALS, min((b + 1) * BLOCK_TRIALS, task.stop)
        rng = np.random.default_rng(block_seed(cfg.seed, b))
        sl = slice(lo - task.start, hi - task.start)
        parts.append(trial_parameters(
            cfg, hi - lo, rng, None if task.X is None else task.X[sl],
            None if task.conditions is None else task.conditions[sl]))
        noise.append(rng.standard_normal((hi - lo, cfg.stops, 3)))
        tnoise.append(rng.standard_normal((hi - lo, cfg.stops)))
        blocks.append(np.full(hi - lo, b))
    params = {k: np.concatenate([p[k] for p in parts]) for k in PARAMETERS}
    if cfg.uses_ephemeris:
        params["sun_elevation_deg"] = ephemeris_sun_elevation(cfg, params)
    noise, tnoise = np.concatenate(noise), np.concatenate(tnoise)
    if cfg.method != "montecarlo":  # common random numbers: a deterministic model for SALib
        noise, tnoise = common_noise(cfg, task.stop - task.start)
    sky = make_sky(**cfg.sky)
    sim = simulate_trials(params, cfg.stops, sky, Daq(cfg.daq_bits, cfg.daq_range_V),
                          noise, tnoise, GAIN)
    outputs = evaluate_trials(sim, cfg.pairs, cfg.calibrate, GAIN)
    cols = {"trial": np.arange(task.start, task.stop), "block": np.concatenate(blocks),
            "condition_sun_elevation_deg": (np.full(task.stop - task.start, np.nan)
                                            if task.conditions is None else task.conditions)}
    table = pa.Table.from_pandas(pd.DataFrame({**cols, **params, **outputs}),
                                 preserve_index=False)
    meta = {"digest": task.digest, "chunk": task.index, "start": task.start, "stop": task.stop}
    table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                           _META_KEY: json.dumps(meta).encode()})
    atomic_write(task.path, lambda p: pq.write_table(table, p))
    return {"index": task.index, "path": task.path, "rows": task.stop - task.start,
            "elapsed_s": time.perf_counter() - t0}


def common_noise(cfg: SweepConfig, n: int):
    """One noise realisation shared by every trial of a SALib design (common random
    numbers), from ``SeedSequence([seed, 1])``: Sobol and Morris estimators assume a
    deterministic model, so trials differ only in their parameters; the noise *level*
    ``noise_V`` (and ``turntable_error_deg``) scales this realisation."""
    rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 1]))
    v = rng.standard_normal((1, cfg.stops, 3))
    t = rng.standard_normal((1, cfg.stops))
    return np.broadcast_to(v, (n, cfg.stops, 3)), np.broadcast_to(t, (n, cfg.stops))


def chunk_status(task: ChunkTask) -> str | None:
    """None if the chunk file is present and complete; otherwise why it must be computed
    (``"missing"`` or a description of the corruption or mismatch)."""
    import pyarrow.parquet as pq
    path = Path(task.path)
    if not path.exists():
        return "missing"
    try:
        md = pq.read_metadata(path)
        meta = json.loads((md.metadata or {}).get(_META_KEY, b"{}"))
        trials = pq.read_table(path, columns=["trial"]).column("trial").to_numpy()
    except Exception as exc:  # pyarrow raises several types for a truncated/garbled file
        return f"unreadable ({type(exc).__name__}: {exc})"
    want = {"digest": task.digest, "start": task.start, "stop": task.stop}
    got = {k: meta.get(k) for k in want}
    if got != want:
        return f"written by another sweep or chunking ({got} != {want})"
    if not np.array_equal(trials, np.arange(task.start, task.stop)):
        return f"incomplete ({trials.size} of {task.stop - task.start} trials)"
    return None


# --------------------------------------------------------------------------- analysis


def _pair_tags(cfg: SweepConfig) -> list[str]:
    return [f"p{p[0]}{p[-1]}" for p in cfg.pairs]


def output_columns(cfg: SweepConfig) -> list[str]:
    """Analysed outputs: raw and (with calibration) compensated 3 sigma per pair."""
    kinds = ["raw", "compensated"] if cfg.calibrate else ["raw"]
    return [f"{k}_3sigma_deg_{t}" for t in _pair_tags(cfg) for k in kinds]


def _elevation_groups(trials, binned: bool = True):
    """(label [deg], index) per sun-elevation group: the SALib design's conditions, else
    (``binned``) 10-deg bins of a varying sun elevation, else one group at the median."""
    cond = trials["condition_sun_elevation_deg"]
    if cond.notna().all():
        return [(float(c), g.index) for c, g in trials.groupby(cond, sort=True)]
    el = trials["sun_elevation_deg"]
    if el.nunique() == 1 or not binned:
        return [(float(el.median()), trials.index)]
    centre = np.floor(el / 10.0) * 10.0 + 5.0
    return [(float(c), g.index) for c, g in trials.groupby(centre, sort=True)]


def summary_table(trials, cfg: SweepConfig):
    """Monte-Carlo statistics per sun-elevation group and pair (long format DataFrame)."""
    import pandas as pd
    rows = []
    for label, idx in _elevation_groups(trials):
        sub = trials.loc[idx]
        for tag in _pair_tags(cfg):
            row = {"sun_elevation_deg": label, "pair": f"{tag[1]}-{tag[2]}", "trials": len(sub)}
            for kind in (["raw", "compensated"] if cfg.calibrate else ["raw"]):
                y = sub[f"{kind}_3sigma_deg_{tag}"]
                row.update({f"{kind}_3sigma_median_deg": y.median(),
                            f"{kind}_3sigma_p05_deg": y.quantile(0.05),
                            f"{kind}_3sigma_p95_deg": y.quantile(0.95)})
            if cfg.calibrate:
                row["converged_fraction"] = float(sub[f"converged_{tag}"].mean())
            rows.append(row)
    return pd.DataFrame(rows)


def sensitivity_indices(trials, cfg: SweepConfig):
    """Sobol (S1, ST) or Morris (mu*, sigma) indices by SALib, per sun-elevation group and
    output; None for Monte-Carlo sweeps. Outputs with non-converged trials are skipped (and
    listed in the ``skipped`` attribute of the returned frame)."""
    import pandas as pd
    if cfg.method == "montecarlo":
        return None
    problem = salib_problem(cfg)
    rows, skipped = [], []
    for label, idx in _elevation_groups(trials, binned=False):
        sub = trials.loc[idx]
        for out in output_columns(cfg):
            Y = sub[out].to_numpy(float)
            if not np.isfinite(Y).all():
                skipped.append(f"{out} at {label:g} deg: {int((~np.isfinite(Y)).sum())} trials "
                               "without a converged compensation")
                continue
            if cfg.method == "sobol":
                from SALib.analyze import sobol
                si = sobol.analyze(problem, Y, calc_second_order=False, seed=cfg.seed)
                names = list(dict.fromkeys(problem.get("groups", problem["names"])))
                stats = {"S1": si["S1"], "S1_conf": si["S1_conf"], "ST": si["ST"],
                         "ST_conf": si["ST_conf"]}
            else:
                from SALib.analyze import morris
                X = sub[problem["names"]].to_numpy(float)
                si = morris.analyze(problem, X, Y, num_levels=cfg.morris_levels, seed=cfg.seed)
                names = list(si["names"])
                stats = {k: np.asarray(si[k]) for k in ("mu", "mu_star", "sigma",
                                                          "mu_star_conf")}
            for k, name in enumerate(names):
                rows.append({"sun_elevation_deg": label, "output": out, "factor": name,
                             **{s: float(v[k]) for s, v in stats.items()}})
    frame = pd.DataFrame(rows)
    frame.attrs["skipped"] = skipped
    return frame


def dominant_factors(indices, cfg: SweepConfig) -> list[dict]:
    """The factor with the largest total index (Sobol ST, Morris mu*) per group and output."""
    if indices is None or indices.empty:
        return []
    key = "ST" if cfg.method == "sobol" else "mu_star"
    best = indices.loc[indices.groupby(["sun_elevation_deg", "output"])[key].idxmax()]
    return [{"sun_elevation_deg": r.sun_elevation_deg, "output": r.output, "factor": r.factor,
             key: getattr(r, key)} for r in best.itertuples()]


# --------------------------------------------------------------------------- figures


def _finish(fig, ax, path, xlabel: str, ylabel: str, **legend) -> None:
    """Log y axis, labels, legend; save as PNG and close."""
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(**legend)
    fig.tight_layout()
    save_png(fig, path)


def plot_indices(indices, cfg: SweepConfig, path) -> None:
    """Bar charts of the sensitivity indices: one panel per output kind and sun elevation."""
    plt = pyplot()
    key, conf = ("ST", "ST_conf") if cfg.method == "sobol" else ("mu_star", "mu_star_conf")
    groups = sorted(indices.sun_elevation_deg.unique())
    varied = any(p.name == "sun_elevation_deg" and not p.fixed for p in cfg.parameters)

    def sun_label(el: float) -> str:
        if varied and not cfg.conditions:  # one design over the sun elevation as a factor
            return "sun elevation a factor of the design"
        return f"sun elevation {el:g}°"
    kinds = sorted(indices.output.str.split("_").str[0].unique())
    fig, axes = plt.subplots(len(kinds), len(groups), squeeze=False,
                             figsize=(4.2 * len(groups), 3.4 * len(kinds)))
    for r, kind in enumerate(kinds):
        for c, el in enumerate(groups):
            ax = axes[r, c]
            sub = indices[(indices.sun_elevation_deg == el) & indices.output.str.startswith(kind)]
            outs = sorted(sub.output.unique())
            factors = list(dict.fromkeys(sub.factor))
            width = 0.8 / max(len(outs), 1)
            for k, out in enumerate(outs):
                s = sub[sub.output == out].set_index("factor").loc[factors]
                ax.bar(np.arange(len(factors)) + k * width, s[key], width, yerr=s[conf],
                       label=f"pair {out[-2]}-{out[-1]}")
                if cfg.method == "sobol":
                    ax.scatter(np.arange(len(factors)) + k * width, s["S1"], color="k",
                               marker="_", s=60, zorder=3)
            ax.set_xticks(np.arange(len(factors)) + 0.4 - width / 2, factors, rotation=45,
                          ha="right", fontsize=7)
            ax.set_title(f"{kind} 3σ, {sun_label(el)}", fontsize=9)
            ax.set_ylabel("Sobol ST (bar), S1 (—)" if cfg.method == "sobol"
                          else "Morris μ* [deg]")
            ax.legend(fontsize=7)
    fig.tight_layout()
    save_png(fig, path)


def plot_error_vs_elevation(summary, path) -> None:
    """Median and 5-95 % band of raw and compensated 3 sigma against sun elevation."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for pair, g in summary.groupby("pair"):
        for kind, style in (("raw", "--"), ("compensated", "-")):
            if f"{kind}_3sigma_median_deg" not in g:
                continue
            line, = ax.plot(g.sun_elevation_deg, g[f"{kind}_3sigma_median_deg"], style,
                            marker="o", label=f"{kind}, pair {pair}")
            ax.fill_between(g.sun_elevation_deg, g[f"{kind}_3sigma_p05_deg"],
                            g[f"{kind}_3sigma_p95_deg"], color=line.get_color(), alpha=0.12)
    _finish(fig, ax, path, "sun elevation [deg]",
            "heading error 3σ [deg] (median, 5–95 %)", fontsize=7, ncol=2)


PLOT_MAX_POINTS = 20_000
"""Scatter plots show the first trials only (Monte-Carlo trials are exchangeable)."""


def plot_error_vs_noise(trials, cfg: SweepConfig, path) -> None:
    """Heading error 3 sigma against channel noise (first :data:`PLOT_MAX_POINTS` trials),
    first pair."""
    plt = pyplot()
    tag = _pair_tags(cfg)[0]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    trials = trials.iloc[:PLOT_MAX_POINTS]
    noise_mV = trials.noise_V * 1e3
    for kind, colour in (("raw", "tab:orange"), ("compensated", "tab:blue")):
        col = f"{kind}_3sigma_deg_{tag}"
        if col in trials:
            ax.scatter(noise_mV, trials[col], s=3, alpha=0.3, color=colour,
                       label=f"{kind}, pair {tag[1]}-{tag[2]}")
    _finish(fig, ax, path, "channel noise σ [mV]", "heading error 3σ [deg]",
            fontsize=8, markerscale=4)


# --------------------------------------------------------------------------- driver


def markdown_table(frame) -> str:
    """A DataFrame as a Markdown table (floats to 4 significant digits)."""
    def cell(v):
        return f"{v:.4g}" if isinstance(v, float) else str(v)
    lines = ["| " + " | ".join(map(str, frame.columns)) + " |",
             "|" + "---|" * len(frame.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |"
              for row in frame.itertuples(index=False)]
    return "\n".join(lines)


def concatenate_chunks(tasks, path) -> None:
    """Stream the chunk files into one Parquet file, one chunk in memory at a time."""
    import pyarrow.parquet as pq
    writer = None
    try:
        for t in tasks:
            table = pq.read_table(t.path)
            meta = {k: v for k, v in (table.schema.metadata or {}).items() if k != _META_KEY}
            table = table.replace_schema_metadata(meta)
            if writer is None:
                writer = pq.ParquetWriter(path, table.schema)
            writer.write_table(table)
    finally:
        if writer is not None:
            writer.close()


def analysis_columns(cfg: SweepConfig) -> list[str]:
    """Columns the summary, indices and figures need (a sweep larger than memory keeps only
    these in memory, about a third of ``trials.parquet``)."""
    tags = _pair_tags(cfg)
    extra = [f"converged_{t}" for t in tags] if cfg.calibrate else []
    factors = [m for m, _ in _members(cfg)]
    return list(dict.fromkeys(["trial", "condition_sun_elevation_deg", "sun_elevation_deg",
                               "noise_V", *factors, *output_columns(cfg), *extra]))


def _remove_temporaries(folder: Path) -> None:
    """Remove the temporary files of chunks whose worker was stopped mid-write (a finished
    chunk is renamed into place atomically, so these are never results)."""
    for tmp in Path(folder).glob(".tmp-*"):
        tmp.unlink(missing_ok=True)


def _check_state(out: Path, cfg: SweepConfig, digest: str) -> None:
    """Refuse an ``out`` holding results of another sweep; a ``sweep.json`` without any chunk
    (a run that failed before computing) is no result and is replaced."""
    manifest = out / "sweep.json"
    has_results = any((out / "chunks").glob("chunk-*.parquet")) or (out / "trials.parquet").exists()
    if manifest.is_file() and has_results:
        try:
            old = json.loads(manifest.read_text()).get("digest")
        except (json.JSONDecodeError, UnicodeDecodeError, AttributeError):
            old = None
        if old is not None and old != digest:
            raise SweepStateError(
                f"{out} holds chunks of a different sweep (configuration digest {old[:12]} != "
                f"{digest[:12]}); give another --out or delete {out}")


def run_sweep(cfg: SweepConfig, out, *, backend: str = "local", scheduler: str | None = None,
              workers: int | None = None, progress: bool = True, figures: bool = True,
              log=print) -> dict:
    """Run (or resume) a sweep into ``out``; return the trial table, summary and indices.

    Writes ``out/chunks/chunk-*.parquet`` (one per chunk, atomically; present complete chunks
    are skipped, corrupted ones recomputed), then ``trials.parquet`` (one row per trial),
    ``summary.csv``/``summary.md``, ``indices.csv`` (Sobol/Morris), ``sweep.json`` (config,
    digest, seed, timings) and figures.

    Raises
    ------
    SweepStateError
        If ``out`` holds a sweep with another configuration.
    SweepMemoryError
        If one seed block does not fit the memory budget.
    """
    import pandas as pd

    from skysim.io import atomic_write, write_json_atomic

    from .sweep_backends import run_tasks
    from skysim.io import check_output_dir
    from skysim.sky import make_sky
    t0 = time.perf_counter()
    out = check_output_dir(out)
    digest = cfg.digest()
    _check_state(out, cfg, digest)
    sky = dict(cfg.sky)
    try:  # a bad sky fails here, before any state is written, not in the first worker
        make_sky(sky.pop("model"), **sky)
    except InvalidParameterError as exc:
        raise SweepConfigError(f"[sky] {exc}") from None
    from .sweep_backends import default_workers
    local = backend == "local" or not scheduler   # a remote cluster has its own memory
    check_sweep_memory(cfg, (workers or default_workers()) if local else 1)
    n_trials, X, conditions = design(cfg)
    if cfg.uses_ephemeris and X is not None:  # a SALib design: every sun checked up front
        ephemeris_sun_elevation(cfg, trial_parameters(cfg, n_trials, None, X, conditions))
    tasks = plan_chunks(cfg, out, digest, n_trials, X, conditions)
    todo = []
    for task in tasks:
        why = chunk_status(task)
        if why is not None:
            if why != "missing":
                log(f"chunk {task.index}: {why}; recomputing")
            todo.append(task)
    _remove_temporaries(out / "chunks")   # of chunks a killed run cut short
    manifest = {"schema": "skysim.sweep/1", "digest": digest, "config": cfg.to_dict(),
                "n_trials": n_trials, "chunk_trials": chunk_trials(cfg), "chunks": len(tasks)}
    (out / "chunks").mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "sweep.json", {**manifest, "status": "running"})
    log(f"sweep {cfg.name!r}: {n_trials} trials in {len(tasks)} chunks "
        f"({len(tasks) - len(todo)} already done), backend {backend}")
    t_run = time.perf_counter()
    try:
        reports = run_tasks(run_chunk, todo, backend=backend, scheduler=scheduler,
                            workers=workers, progress=progress, desc=cfg.name)
    except KeyboardInterrupt:
        _remove_temporaries(out / "chunks")
        log(f"interrupted: finished chunks are kept in {out / 'chunks'}; rerun the same "
            "command to resume")
        raise
    except BaseException:
        _remove_temporaries(out / "chunks")
        raise
    compute_s = time.perf_counter() - t_run
    atomic_write(out / "trials.parquet", lambda p: concatenate_chunks(tasks, p))
    trials = pd.read_parquet(out / "trials.parquet", columns=analysis_columns(cfg))
    summary = summary_table(trials, cfg)
    atomic_write(out / "summary.csv", lambda p: summary.to_csv(p, index=False,
                                                               float_format="%.5g"))
    atomic_write(out / "summary.md", lambda p: p.write_text(
        f"# Sweep {cfg.name}: heading error 3σ [deg]\n\n"
        + markdown_table(summary) + "\n"))
    indices = sensitivity_indices(trials, cfg)
    if indices is not None:
        atomic_write(out / "indices.csv", lambda p: indices.to_csv(p, index=False,
                                                                   float_format="%.5g"))
    if figures:
        if indices is not None and not indices.empty:
            plot_indices(indices, cfg, out / "indices.png")
        plot_error_vs_elevation(summary, out / "error_vs_sun_elevation.png")
        plot_error_vs_noise(trials, cfg, out / "error_vs_noise.png")
    info = {**manifest, "status": "complete", "seed": cfg.seed, "backend": backend,
            "chunks_computed": len(reports), "chunks_reused": len(tasks) - len(todo),
            "compute_s": compute_s, "elapsed_s": time.perf_counter() - t0,
            "dominant_factors": dominant_factors(indices, cfg),
            "indices_skipped": [] if indices is None else indices.attrs["skipped"]}
    write_json_atomic(out / "sweep.json", info)
    return {"trials": trials, "summary": summary, "indices": indices, "info": info}


SWEEP_FILES = ("sweep.json", "trials.parquet", "summary.csv", "summary.md", "indices.csv",
               "indices.png", "error_vs_sun_elevation.png", "error_vs_noise.png")
"""The files a sweep writes into its output folder (besides ``chunks/``)."""


def _sweep_command(args) -> int:
    import pandas as pd
    cfg = load_config(args.config)
    out = Path(args.out or f"results/sweep_{cfg.name}")
    refuse_replacing_inputs([("--out", out / name) for name in SWEEP_FILES],
                            [("config", args.config)])
    res = run_sweep(cfg, out, backend=args.backend, scheduler=args.scheduler,
                    workers=args.workers, progress=not args.no_progress,
                    figures=not args.no_figures)
    pd.set_option("display.width", 200)
    print(res["summary"].to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    if res["info"]["dominant_factors"]:
        dom = pd.DataFrame(res["info"]["dominant_factors"])
        print("\ndominant factor (largest total index) per sun elevation [deg] and output:")
        print(dom.pivot(index="sun_elevation_deg", columns="output", values="factor")
              .to_string())
    for s in res["info"]["indices_skipped"]:
        print(f"indices skipped: {s}")
    info = res["info"]
    print(f"{info['n_trials']} trials, {info['chunks_computed']} chunks computed, "
          f"{info['chunks_reused']} reused, {info['elapsed_s']:.1f} s; wrote {out}")
    return 0


def register(sub) -> None:
    p = sub.add_parser("sweep", help="error-sensitivity sweep (Monte-Carlo, Sobol, Morris)",
                       description="Run a sweep configured in TOML (see docs/sweeps.md); "
                                   "interrupted sweeps resume from their chunks.")
    p.add_argument("config", type=existing_file, help="sweep configuration (.toml)")
    p.add_argument("--backend", choices=("local", "dask"), default="local",
                   help="local processes, or dask.distributed (extra 'sweep')")
    p.add_argument("--scheduler", help="dask scheduler address (default: a LocalCluster)")
    p.add_argument("--workers", type=positive_int, help="processes / LocalCluster workers "
                                                        "(default: usable cores)")
    p.add_argument("--out", type=output_dir,
                   help="output folder (default: results/sweep_<name>)")
    p.add_argument("--no-figures", action="store_true", help="write no figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_sweep_command)
