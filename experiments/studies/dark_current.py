"""Dark current and weak light: the 2014 model against the dark-current model.

Monte-Carlo over simulated sensors (:meth:`sensor.photodiode.PhotodiodeChannels.draw`: mounting
errors, responsivity spread, dark currents 20-100 pA (~0.4-2 lx equivalent), film-polarizer
extinction ratios, log-amplifier gain and offset errors; channel noise U(0.25, 0.55) mV as in
:data:`sensor.yang2014.ERROR_MODEL`; photocurrent shot noise; 16-bit DAQ). Per trial:

- calibration set (integrating sphere [1]_): intensity levels :attr:`Config.cal_levels_lx`,
  36 reference polarization angles over [-90, 90) and DoP 0.3 and 0.7 at each level;
- (a) the 2014 model [2]_: Gauss-Newton LSM (:func:`calibration.lsq.fit_pair`, DoP scale
  fitted) on the brightest level, the daylight practice of [2]_; heading from each pair;
- (b) the dark-current model: :func:`calibration.dark_current.calibrate_dark_current` on all
  levels, heading/DoP/intensity from :func:`calibration.dark_current.solve_opponent`;
- evaluation sweep: illuminance from 1e4 lx down to 1 lx, 90 held-out polarization azimuths
  (offset by 1 deg from the calibration angles), sky DoP :attr:`Config.dop`.

- (b0) the calibrated dark-current model with ``1/I = 0`` (dark current neglected, three
  channels, weighted least squares: the bright-light arm);
- (c) the combined solve :func:`calibration.dark_current.solve_combined`, per sample: (b) where
  the estimated dark-to-signal ratio exceeds sqrt(2) times its standard error, else (b0);
  (cw) the same with ``1/I`` pooled over the 90 samples of one illuminance level (one
  turntable sweep under a constant sky);
- underwater scenario: a clear Rayleigh sky (:attr:`Config.sky_dmax`, sun at
  :attr:`Config.sun_elevation_deg`) seen at the zenith from depths where the Beer-Lambert
  illuminance falls from the surface value to ~1 lx, in the water types of
  :data:`sensor.illuminance.WATER_TYPES` (:func:`sensor.illuminance.underwater_light`:
  Fresnel transmission, ``K_d`` of Jerlov's Table XXVII at 480 nm, the transmitted sky's
  polarization mixed with the in-water single scattering of the refracted sun). That DoP
  model is validated only down to
  :attr:`sensor.illuminance.WaterType.polarization_validated_depth_m` (5 m in clear water,
  the surface in coastal and turbid water; Lerner et al. 2011); deeper it keeps the in-water
  single-scattering DoP although the zenith DoP of the asymptotic light field tends to zero
  (Mobley 1994, sect. 9.3). Those depths are kept, for the light level, but marked
  (``dop_validated`` false in ``underwater.csv`` and ``by_depth.csv``, shaded in the figure):
  their DoP is an upper bound and their heading errors are lower bounds.

Reported: heading-error 3 sigma (3 x RMS about zero) and DoP RMS error vs illuminance for (a)
(pair 1-2 and the best pair per trial and level), (b), (b0), (c), (cw); per level the median
over trials of the paired ratio (c)/(b), (c)/(b0), (cw)/(b), (cw)/(b0) with a bootstrap 95 %
interval (the combined solve is "worse than an arm beyond noise" where the interval lies
above 1); recovered vs injected parameters with z-scores; the illuminance below which (a)
fails and the factor by which (b) recovers; heading error vs depth under water.

References
----------
.. [1] J. Yang, Y. You, P. Hu, X. Liu, L. Guo, "Underwater polarization sensor
   multi-parameter optimization calibration method considering dark current", Chinese patent
   application (2021).
.. [2] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from calibration.dark_current import (ChannelModel, calibrate_dark_current, solve_combined,
                                      solve_opponent)
from calibration.lsq import fit_pair
from calibration.solve import PAIRS, heading_error_deg
from sensor.daq import Daq
from sensor.illuminance import WATER_TYPES, DepthBeyondValidationWarning, underwater_light
from sensor.photodiode import PhotodiodeChannels
from sensor.yang2014 import ERROR_MODEL
from skysim.sky import RayleighSky
from skysim import __version__
from skysim.io import atomic_write, write_json_atomic


__all__ = ["Config", "DEFAULT_SEED", "calibration_grid", "run", "register_reproduce",
           "format_summary", "underwater_conditions"]

DEFAULT_SEED = 20210401
MEMORY_PER_TRIAL_BYTES = 600_000
"""Peak memory per trial [bytes]: the bootstrap of the paired ratios holds (2000 resamples x
trials x 13 levels) float64 and numpy's median copy, 432 kB per trial measured with
tracemalloc (100 vs 400 trials), plus the per-trial tables; ``skysim reproduce`` refuses
--trials that would not fit."""
"""Master seed of ``skysim reproduce dark-current`` (the patent's year and month)."""


@dataclass(frozen=True)
class Config:
    """Experiment settings (all magnitudes fixed before looking at results).

    cal_levels_lx : integrating-sphere levels spanning the dark level (~1 lx) up to daylight
        laboratory levels.
    cal_dops : two reference DoPs, so polarization efficiency and dark level separate.
    sweep_lx : evaluation illuminances, 1e4 lx (overcast daylight) down to 1 lx (deep dusk;
        in the underwater scenario 8-470 m of water, depending on the water type).
    dop : zenith DoP of the evaluated sky (a clear dusk sky).
    noise_range_V : channel output noise, as in sensor.yang2014.ERROR_MODEL.
    bandwidth_Hz : readout bandwidth for the shot noise.
    sun_elevation_deg, sky_dmax : the underwater scenario's clear sky (Rayleigh, d_max 0.8:
        zenith DoP 0.48 at 30 deg sun elevation).
    water_types : names in sensor.illuminance.WATER_TYPES.
    depth_illuminance_lx : zenith lux equivalents under water that fix depths
        ``z = ln(E(0-)/E) / K_d`` of each water type (surface down to 1 lx) ...
    depth_transmitted_fractions : ... and the transmitted skylight's shares
        ``exp(-kappa_p z)`` that fix more depths (the transition from the sky's to the
        in-water polarization); depths beyond the last illuminance are dropped.
    wavelength_nm : wavelength of ``K_d`` (the blue band of the sensor).
    """

    cal_levels_lx: tuple = (1.0, 2.0, 5.0, 10.0, 30.0, 100.0, 1000.0)
    cal_angles: int = 36
    cal_dops: tuple = (0.3, 0.7)
    sweep_lx: tuple = tuple(np.round(10.0 ** np.linspace(4.0, 0.0, 13), 3))
    eval_angles: int = 90
    dop: float = 0.6
    noise_range_V: tuple = ERROR_MODEL.noise_range_V
    bandwidth_Hz: float = 10.0
    daq_bits: int = ERROR_MODEL.daq_bits
    daq_range_V: float = ERROR_MODEL.daq_range_V
    sun_elevation_deg: float = 30.0
    sky_dmax: float = 0.8
    water_types: tuple = ("clear_ocean", "coastal", "turbid")
    depth_illuminance_lx: tuple = (1e4, 1e3, 1e2, 30.0, 10.0, 3.0, 1.0)
    depth_transmitted_fractions: tuple = (0.5, 0.2, 0.05)
    wavelength_nm: float = 480.0


def _three_sigma(err, axis=-1):
    return 3.0 * np.sqrt(np.mean(np.square(err), axis=axis))


def calibration_grid(cfg: Config):
    """The calibration conditions of ``cfg``: illuminance [lx], E-vector angle [deg] and DoP,
    every combination of its levels, ``cal_angles`` angles over 180 deg and DoPs, flattened."""
    phis = np.linspace(-90.0, 90.0, cfg.cal_angles, endpoint=False)
    I, phi, d = np.meshgrid(np.asarray(cfg.cal_levels_lx), phis, np.asarray(cfg.cal_dops),
                            indexing="ij")
    return I.ravel(), phi.ravel(), d.ravel()


def underwater_conditions(cfg: Config) -> pd.DataFrame:
    """Depth, zenith lux equivalent and DoP of the underwater scenario (one row per water type
    and depth; :func:`sensor.illuminance.underwater_light`); ``dop_validated`` is false deeper
    than the water type's validated depth of the DoP model, where the DoP is an upper bound
    (the model's warning is replaced by that column)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DepthBeyondValidationWarning)
        return _underwater_conditions(cfg)


def _underwater_conditions(cfg: Config) -> pd.DataFrame:
    sky = RayleighSky(cfg.sky_dmax)
    rows = []
    for name in cfg.water_types:
        w = WATER_TYPES[name]
        kd = float(w.diffuse_attenuation_per_m(cfg.wavelength_nm))
        e0 = underwater_light(sky, 0.0, 0.0, cfg.sun_elevation_deg, 0.0, 0.0, name,
                              wavelength_nm=cfg.wavelength_nm)
        target = np.asarray(cfg.depth_illuminance_lx)
        z_e = np.log(e0.illuminance_lx / target[target < e0.illuminance_lx]) / kd
        z_f = -np.log(np.asarray(cfg.depth_transmitted_fractions)) / w.polarization_decay_per_m
        z = np.unique(np.concatenate([[0.0, w.polarization_validated_depth_m], z_e, z_f]))
        z = z[z <= z_e.max() * (1 + 1e-9)]
        light = underwater_light(sky, 0.0, 0.0, cfg.sun_elevation_deg, 0.0, z, name,
                                 wavelength_nm=cfg.wavelength_nm)
        rows += [{"water": name, "depth_m": zi, "illuminance_lx": ei, "dop": di,
                  "dop_validated": bool(zi <= w.polarization_validated_depth_m)}
                 for zi, ei, di in zip(z, light.illuminance_lx, light.dop)]
    return pd.DataFrame(rows)


def _solve_all(U, phi_true, dop_true, cal_a, cal_b, noise_total):
    """Heading 3 sigma and DoP RMS over the last axis for every arm; dict of arrays."""
    sol = solve_opponent(U, cal_b.model)
    comb = solve_combined(U, cal_b.model, noise_total)
    pooled = solve_combined(U, cal_b.model, noise_total, pool_axis=-1)
    bright = solve_combined(U, cal_b.model, noise_total, mse_factor=np.inf)
    out = {}
    for name, s in (("b", sol), ("c", comb), ("cw", pooled), ("b0", bright)):
        out[f"heading_3sigma_{name}_deg"] = _three_sigma(heading_error_deg(s.phi_deg, phi_true))
        out[f"dop_rms_{name}"] = np.sqrt(np.mean((s.dop - dop_true) ** 2, axis=-1))
    out["dark_model_fraction_c"] = np.mean(comb.dark_model, axis=-1)
    out["dark_model_fraction_cw"] = np.mean(pooled.dark_model, axis=-1)
    heading_a = {}
    for pair, cal in cal_a.items():
        phi_a, d_a = cal.solve(U)
        name = f"a{pair[0]}{pair[1]}"
        heading_a[name] = _three_sigma(heading_error_deg(phi_a, phi_true))
        out[f"dop_rms_{name}"] = np.sqrt(np.mean((d_a / cal.dop_scale - dop_true) ** 2,
                                                 axis=-1))
    out["heading_3sigma_a12_deg"] = heading_a["a12"]
    out["heading_3sigma_a_best_deg"] = np.min(np.stack(list(heading_a.values())), axis=0)
    return out, sol, heading_a


def _trial(k: int, seed_seq, cfg: Config, daq: Daq, water: pd.DataFrame):
    """One simulated sensor: calibrate (a) and (b), evaluate the sweep and the underwater
    scenario. Returns rows."""
    rng = np.random.default_rng(seed_seq)
    params = PhotodiodeChannels.draw(rng)
    noise = rng.uniform(*cfg.noise_range_V, 3)
    noise_total = np.sqrt(noise ** 2 + daq.lsb_V ** 2 / 12.0)   # + quantisation
    I_c, phi_c, d_c = calibration_grid(cfg)
    U_c, _ = params.sample(I_c, phi_c, d_c, rng, noise_V=noise, bandwidth_Hz=cfg.bandwidth_Hz,
                           daq=daq)
    cal_b = calibrate_dark_current(U_c, I_c, phi_c, d_c, noise_V=noise_total, daq=daq)
    bright = I_c == max(cfg.cal_levels_lx)
    cal_a = {pair: fit_pair(phi_c[bright], U_c[bright], pair, d_c[bright], fit_dop_scale=True)
             for pair in PAIRS}

    E = np.asarray(cfg.sweep_lx)[:, None]
    phi_e = np.linspace(-89.0, 91.0, cfg.eval_angles, endpoint=False)[None, :]
    phi_e = np.broadcast_to(phi_e, (E.size, phi_e.size))
    U_e, _ = params.sample(np.broadcast_to(E, phi_e.shape), phi_e, cfg.dop, rng, noise_V=noise,
                           bandwidth_Hz=cfg.bandwidth_Hz, daq=daq)
    res, sol, heading_a = _solve_all(U_e, phi_e, cfg.dop, cal_a, cal_b, noise_total)
    res["intensity_rel_err_b_median"] = np.median(np.abs(sol.intensity_lx / E - 1.0), axis=-1)
    best = min(heading_a, key=lambda n: heading_a[n][0])
    res["dop_rms_a_daylight_best_pair"] = res[f"dop_rms_{best}"]
    cols = [c for c in res if not c.startswith("dop_rms_a") or c in ("dop_rms_a12",
                                                                   "dop_rms_a_daylight_best_pair")]
    sweep_rows = [{"trial": k, "illuminance_lx": float(E[i, 0]),
                   **{c: float(res[c][i]) for c in cols}} for i in range(E.shape[0])]
    # underwater: zenith view at the depths of `water`, same sensor and calibrations
    phi_w = np.broadcast_to(phi_e[:1], (len(water), phi_e.shape[1]))
    E_w = water.illuminance_lx.to_numpy()[:, None]
    d_w = water.dop.to_numpy()[:, None]
    U_w, _ = params.sample(np.broadcast_to(E_w, phi_w.shape), phi_w,
                           np.broadcast_to(d_w, phi_w.shape), rng, noise_V=noise,
                           bandwidth_Hz=cfg.bandwidth_Hz, daq=daq)
    res_w, _, _ = _solve_all(U_w, phi_w, d_w, cal_a, cal_b, noise_total)
    water_rows = [{"trial": k, "water": water.water.iloc[i], "depth_m": water.depth_m.iloc[i],
                   "illuminance_lx": water.illuminance_lx.iloc[i], "dop": water.dop.iloc[i],
                   "dop_validated": bool(water.dop_validated.iloc[i]),
                   **{c: float(res_w[c][i]) for c in res_w if c.startswith("heading")}}
                  for i in range(len(water))]
    truth = ChannelModel.from_photodiodes(params).to_vector()
    est, se = cal_b.model.to_vector(), cal_b.standard_errors
    param_rows = [{"trial": k, "parameter": name, "injected": truth[j], "recovered": est[j],
                   "standard_error": se[j], "z": (est[j] - truth[j]) / se[j]}
                  for j, name in enumerate(cal_b.parameter_names)]
    return sweep_rows, param_rows, water_rows


def run(trials: int = 100, seed: int = DEFAULT_SEED, out=None, cfg: Config = Config(),
        progress: bool = True, figures: bool = True) -> dict:
    """Run the Monte-Carlo; write tables and figures to ``out`` if given."""
    t0 = time.perf_counter()
    with _single_threaded_blas():
        result = _run(trials, seed, cfg, progress, t0)
    if out is not None:
        _write(Path(out), result, figures)
    return result


def _single_threaded_blas():
    """One BLAS thread during the Monte-Carlo, if threadpoolctl is installed: the calibration
    is many small SVDs, which multithreaded OpenBLAS slows down by ~100x on a loaded machine
    (measured: 1512 x 24 SVD 0.57 s vs 1.1 ms single-threaded on the 2-core CI machine)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def _run(trials, seed, cfg, progress, t0) -> dict:
    from tqdm import tqdm

    daq = Daq(cfg.daq_bits, cfg.daq_range_V)
    seeds = np.random.SeedSequence(seed).spawn(trials)
    water = underwater_conditions(cfg)
    sweep, params, under = [], [], []
    for k in tqdm(range(trials), desc="dark-current trials", disable=not progress,
                  unit="trial"):
        s, p, w = _trial(k, seeds[k], cfg, daq, water)
        sweep += s
        params += p
        under += w
    sweep = pd.DataFrame(sweep)
    params = pd.DataFrame(params)
    under = pd.DataFrame(under)
    by_level = _by_level(sweep, np.random.default_rng(seeds[0].spawn(1)[0]))
    by_depth = (under.drop(columns="dop_validated")
                .groupby(["water", "depth_m"], sort=False).median(numeric_only=True)
                .drop(columns="trial").reset_index()
                .merge(water[["water", "depth_m", "dop_validated"]], on=["water", "depth_m"]))
    param_table = _parameter_table(params)
    summary = _summary(by_level, param_table, params, trials, seed, cfg,
                       time.perf_counter() - t0)
    result = {"sweep": sweep, "parameters": params, "by_level": by_level,
              "parameter_table": param_table, "underwater": under, "by_depth": by_depth,
              "summary": summary}
    return result


COMBINED_VS_ARMS = (("c", "b"), ("c", "b0"), ("cw", "b"), ("cw", "b0"))
"""Paired ratios (combined / arm) of the heading 3 sigma reported per level."""


def _by_level(sweep: pd.DataFrame, rng: np.random.Generator, n_boot: int = 2000
              ) -> pd.DataFrame:
    """Medians over trials per level; paired ratios combined/arm with bootstrap 95 % CI."""
    g = sweep.groupby("illuminance_lx", sort=False)
    t = g.median(numeric_only=True).drop(columns="trial")
    t.columns = [f"{c}_median" for c in t.columns]
    t["reduction_b_vs_a_best"] = (t["heading_3sigma_a_best_deg_median"]
                                  / t["heading_3sigma_b_deg_median"])
    levels = t.index.to_numpy()
    n_trials = sweep.trial.nunique()
    idx = rng.integers(0, n_trials, (n_boot, n_trials))       # trials resampled, all levels
    for comb, arm in COMBINED_VS_ARMS:
        wide = sweep.pivot(index="trial", columns="illuminance_lx")
        ratio = (wide[f"heading_3sigma_{comb}_deg"] / wide[f"heading_3sigma_{arm}_deg"]
                 )[levels].to_numpy()                          # (trials, levels)
        boot = np.median(ratio[idx], axis=1)                   # (n_boot, levels)
        t[f"ratio_{comb}_{arm}_median"] = np.median(ratio, axis=0)
        t[f"ratio_{comb}_{arm}_lo95"] = np.quantile(boot, 0.025, axis=0)
        t[f"ratio_{comb}_{arm}_hi95"] = np.quantile(boot, 0.975, axis=0)
    return t.reset_index()


def _parameter_table(params: pd.DataFrame) -> pd.DataFrame:
    """Recovered vs injected per parameter: bias, spread, mean predicted se, z statistics."""
    params = params.assign(error=params.recovered - params.injected,
                           parameter_kind=params.parameter.str.split(".").str[1])
    g = params.groupby("parameter", sort=False)
    return pd.DataFrame({
        "injected_mean": g.injected.mean(), "recovered_mean": g.recovered.mean(),
        "error_mean": g.error.mean(), "error_sd": g.error.std(),
        "standard_error_mean": g.standard_error.mean(),
        "z_mean": g.z.mean(), "z_sd": g.z.std(),
        "fraction_within_3sigma": g.z.apply(lambda z: float(np.mean(np.abs(z) < 3.0))),
    }).reset_index()


def _summary(by_level, param_table, params, trials, seed, cfg, elapsed) -> dict:
    day = by_level.iloc[0]
    a = by_level["heading_3sigma_a_best_deg_median"].to_numpy()
    E = by_level["illuminance_lx"].to_numpy()
    # (a) fails where its heading 3 sigma exceeds twice its daylight value
    fails = a > 2.0 * day["heading_3sigma_a_best_deg_median"]
    fail_below = float(E[np.argmax(fails)]) if fails.any() else None
    dark = params[params.parameter.str.contains("dark_")]
    low = by_level[by_level.illuminance_lx < 100.0]
    red = low["reduction_b_vs_a_best"]
    combined = {}
    for comb, arm in COMBINED_VS_ARMS:
        lo = by_level[f"ratio_{comb}_{arm}_lo95"].to_numpy()
        worse = lo > 1.0
        combined[f"{comb}_vs_{arm}"] = {
            "max_median_ratio": float(by_level[f"ratio_{comb}_{arm}_median"].max()),
            "worse_beyond_noise_at_lx": E[worse].astype(float).tolist()}
    return {
        "trials": trials, "seed": seed, "config": asdict(cfg),
        "package_version": __version__,
        "daylight_heading_3sigma_deg": {"a_best": float(day["heading_3sigma_a_best_deg_median"]),
                                        "b": float(day["heading_3sigma_b_deg_median"])},
        "a_fails_below_lx": fail_below,
        "a_fail_criterion": "median heading 3 sigma > 2 x its value at 1e4 lx",
        "reduction_below_100lx": {"min": float(red.min()), "median": float(red.median()),
                                  "at_lx": dict(zip(low.illuminance_lx.astype(float).tolist(),
                                                    red.astype(float).tolist()))},
        "dark_current_fraction_within_3sigma": float(np.mean(np.abs(dark.z) < 3.0)),
        "dark_current_z_mean": float(dark.z.mean()), "dark_current_z_sd": float(dark.z.std()),
        "all_parameters_fraction_within_3sigma": float(np.mean(np.abs(params.z) < 3.0)),
        "combined_vs_arms": combined,
        "combined_criterion": "dark-current model where 1/I_hat > sqrt(2) sd(1/I_hat) "
                              "(Toro-Vizcarrondo & Wallace MSE criterion), else 1/I = 0",
        "acceptance": {
            "dark_currents_within_3sigma (>= 99 % of |z| < 3 expected ~99.7 %)":
                bool(np.mean(np.abs(dark.z) < 3.0) >= 0.99),
            "heading_3sigma_halved_below_100lx": bool(red.min() >= 2.0),
            "windowed_combined_never_worse_than_b_or_b0_beyond_noise":
                not (combined["cw_vs_b"]["worse_beyond_noise_at_lx"]
                     or combined["cw_vs_b0"]["worse_beyond_noise_at_lx"])},
        "elapsed_s": elapsed,
    }


def format_summary(result: dict) -> str:
    """Markdown table of the sweep (medians over trials) and the key findings."""
    t = result["by_level"]
    s = result["summary"]
    lines = ["| illuminance [lx] | (a) 3σ pair 1-2 [deg] | (a) 3σ best pair [deg] | "
             "(b) 3σ [deg] | (a)/(b) | (b0) 3σ [deg] | (c) 3σ [deg] | (cw) 3σ [deg] "
             "| (c)/(b) | (c)/(b0) | (cw)/(b) | (cw)/(b0) | (c) dark-model share "
             "| (a) DoP rms | (b) DoP rms | (cw) DoP rms | (b) |I/E-1| |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def ratio(r, c, a):
        d = r._asdict()
        return (f"{d[f'ratio_{c}_{a}_median']:.2f} [{d[f'ratio_{c}_{a}_lo95']:.2f}, "
                f"{d[f'ratio_{c}_{a}_hi95']:.2f}]")

    for r in t.itertuples():
        lines.append(
            f"| {r.illuminance_lx:g} | {r.heading_3sigma_a12_deg_median:.3f} "
            f"| {r.heading_3sigma_a_best_deg_median:.3f} | {r.heading_3sigma_b_deg_median:.3f} "
            f"| {r.reduction_b_vs_a_best:.1f} | {r.heading_3sigma_b0_deg_median:.3f} "
            f"| {r.heading_3sigma_c_deg_median:.3f} | {r.heading_3sigma_cw_deg_median:.3f} "
            + "".join(f"| {ratio(r, c, a)} " for c, a in COMBINED_VS_ARMS)
            + f"| {r.dark_model_fraction_c_median:.2f} | {r.dop_rms_a12_median:.4f} "
            f"| {r.dop_rms_b_median:.4f} | {r.dop_rms_cw_median:.4f} "
            f"| {r.intensity_rel_err_b_median_median:.3f} |")
    fb = s["a_fails_below_lx"]
    lines += ["", f"(a) fails below {fb:g} lx ({s['a_fail_criterion']})" if fb is not None
              else "(a) does not fail in the swept range",
              f"below 100 lx (b) reduces the heading 3σ of (a) by a factor "
              f"{s['reduction_below_100lx']['min']:.1f} (min) .. "
              f"{max(s['reduction_below_100lx']['at_lx'].values()):.1f} (max)",
              f"dark-equivalent illuminances within 3σ of injected: "
              f"{100 * s['dark_current_fraction_within_3sigma']:.1f} % of "
              f"{s['trials'] * 6} (z mean {s['dark_current_z_mean']:+.2f}, "
              f"sd {s['dark_current_z_sd']:.2f})",
              "combined solve (c per sample, cw pooled per level) worse than an arm beyond "
              "noise (bootstrap 95 % interval of the median paired ratio above 1) at: "
              + "; ".join(f"{k}: {v['worse_beyond_noise_at_lx'] or 'nowhere'}"
                          for k, v in s["combined_vs_arms"].items())]
    if "by_depth" in result:
        lines += ["", "Under water (zenith view, sun elevation "
                  f"{s['config']['sun_elevation_deg']:g} deg; medians over trials). DoP "
                  "marked * : deeper than the DoP model is validated (5 m in clear water, "
                  "the surface in coastal and turbid water; Lerner et al. 2011), an upper "
                  "bound, so the heading errors of that row are lower bounds:", "",
                  "| water | depth [m] | lux equivalent [lx] | DoP | (a) best pair 3σ [deg] "
                  "| (b) 3σ [deg] | (c) 3σ [deg] | (cw) 3σ [deg] |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in result["by_depth"].itertuples():
            mark = "" if r.dop_validated else " *"
            lines.append(f"| {r.water} | {r.depth_m:.1f} | {r.illuminance_lx:.3g} "
                         f"| {r.dop:.3g}{mark} | {r.heading_3sigma_a_best_deg:.3g} "
                         f"| {r.heading_3sigma_b_deg:.3g} | {r.heading_3sigma_c_deg:.3g} "
                         f"| {r.heading_3sigma_cw_deg:.3g} |")
    return "\n".join(lines)


def _write(out: Path, result: dict, figures: bool):
    out.mkdir(parents=True, exist_ok=True)
    for name in ("sweep", "parameters", "by_level", "parameter_table", "underwater",
                 "by_depth"):
        df = result[name]
        atomic_write(out / f"{name}.csv", lambda p, df=df: df.to_csv(p, index=False,
                                                                     float_format="%.6g"))
    atomic_write(out / "summary.md", lambda p: p.write_text(
        "# Dark current and weak light\n\n" + format_summary(result) + "\n"))
    write_json_atomic(out / "summary.json", {**result["summary"], "schema":
                                             "skysim.dark_current/1"})
    if figures:
        _plot(result, out)


LABELS = {
    "a": "2014 model (LSM on the brightest level)",
    "b": "dark-current model",
    "b0": "dark-current model, dark current neglected",
    "c": "combined, chosen per sample",
    "cw": "combined, chosen per sweep (pooled 1/I)",
}
"""Figure legend of each estimator (the module docstring's (a), (b), (b0), (c), (cw))."""


def _plot(result: dict, out: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = result["by_level"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    E = t.illuminance_lx
    ax1.loglog(E, t.heading_3sigma_a12_deg_median, "s--", label=f"{LABELS['a']}, pair 1-2")
    ax1.loglog(E, t.heading_3sigma_a_best_deg_median, "o-", label=f"{LABELS['a']}, best pair")
    ax1.loglog(E, t.heading_3sigma_b_deg_median, "^-", label=LABELS["b"])
    ax1.loglog(E, t.heading_3sigma_b0_deg_median, "x:", label=LABELS["b0"])
    ax1.loglog(E, t.heading_3sigma_c_deg_median, "v-", label=LABELS["c"])
    ax1.loglog(E, t.heading_3sigma_cw_deg_median, "D-", label=LABELS["cw"])
    ax1.set(xlabel="illuminance [lx]", ylabel="heading error 3σ [deg] (median of trials)")
    ax2.loglog(E, t.dop_rms_a12_median, "s--", label=f"{LABELS['a']}, pair 1-2")
    ax2.loglog(E, t.dop_rms_b_median, "^-", label=LABELS["b"])
    ax2.set(xlabel="illuminance [lx]", ylabel="DoP RMS error")
    for ax in (ax1, ax2):
        ax.invert_xaxis()
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    atomic_write(out / "error_vs_illuminance.png", lambda p: fig.savefig(p, dpi=120,
                                                                         format="png"))
    plt.close(fig)

    p = result["parameters"]
    dark = p[p.parameter.str.contains("dark_")]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    ax1.errorbar(dark.injected, dark.recovered, yerr=3 * dark.standard_error, fmt=".", ms=3,
                 alpha=0.5)
    lim = [0, float(dark.injected.max()) * 1.1]
    ax1.plot(lim, lim, "k-", lw=0.8)
    ax1.set(xlabel="injected D/(K k) [lx]", ylabel="recovered ± 3σ [lx]")
    ax2.hist(dark.z, bins=30, density=True, alpha=0.7)
    zz = np.linspace(-4, 4, 200)
    ax2.plot(zz, np.exp(-zz ** 2 / 2) / np.sqrt(2 * np.pi), "k-", lw=1)
    ax2.set(xlabel="z = (recovered - injected) / se", ylabel="density")
    atomic_write(out / "dark_current_recovery.png", lambda q: fig.savefig(q, dpi=120,
                                                                          format="png"))
    plt.close(fig)

    w = result["by_depth"]
    fig, axes = plt.subplots(1, len(w.water.unique()), figsize=(12, 4), constrained_layout=True,
                             squeeze=False)
    for ax, (name, g) in zip(axes[0], w.groupby("water", sort=False)):
        bound = WATER_TYPES[name].polarization_validated_depth_m
        ax.axvspan(bound, g.depth_m.max(), color="0.88", zorder=0,
                   label="DoP model not validated (clear water below 5 m, other water below "
                         "the surface): heading errors there are lower bounds")
        ax.set_xscale("symlog", linthresh=1.0)
        for col, style, label in (("a_best", "o-", f"{LABELS['a']}, best pair"),
                                  ("b", "^-", LABELS["b"]), ("cw", "D-", LABELS["cw"])):
            ax.semilogy(g.depth_m, g[f"heading_3sigma_{col}_deg"], style, label=label)
        ax2 = ax.twinx()
        ax2.semilogy(g.depth_m, g.illuminance_lx, "k:", lw=0.8)
        ax2.set_ylabel("lux equivalent [lx] (dotted)")
        valid = f"to {bound:g} m" if bound > 0 else "at the surface only"
        ax.set(title=f"{name.replace('_', ' ')}: DoP validated {valid}", xlabel="depth [m] (linear below 1)",
               ylabel="heading error 3σ [deg]")
        ax.grid(True, which="both", alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=8)
    atomic_write(out / "underwater_heading_vs_depth.png", lambda q: fig.savefig(q, dpi=120,
                                                                                format="png"))
    plt.close(fig)


def _reproduce(args) -> int:
    trials = args.trials or (20 if getattr(args, "quick", False) else 100)
    out = Path(args.out or "results/dark_current")
    result = run(trials=trials, seed=args.seed if args.seed is not None else DEFAULT_SEED,
                 out=out)
    print(f"Dark current and weak light — {trials} Monte-Carlo trials")
    print(format_summary(result))
    print(f"{result['summary']['elapsed_s']:.1f} s; wrote {out}/by_level.csv, "
          "parameter_table.csv, sweep.csv, parameters.csv, underwater.csv, by_depth.csv, "
          "summary.json, summary.md, figures")
    return 0


def register_reproduce(targets: dict) -> None:
    targets["dark-current"] = _reproduce
