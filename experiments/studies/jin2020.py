"""Attitude from skylight polarization + IMU with a dynamic gradient step (Jin et al. 2020).

``skysim reproduce jin2020`` (or ``skysim jin2020 --quick``): the experiment of Jin, Xie, Chu,
Wei & Wei, "Optimization method of navigation attitude based on skylight polarization
pattern", Aero Weaponry 27(1):39 (2020), simulated at Dalian University of Technology on
2018-05-25.

1. **Sun positions and the time reading.** The paper states the sun at 20.54 deg elevation /
   -100.89 deg azimuth at "17:20" and 12.98 / -106.62 deg at "18:00" (azimuth from south, west
   negative). We evaluate the ephemeris with the clock times read as Beijing time (UTC+8) and
   as local apparent solar time (LAST), and tabulate the discrepancy to the paper's angles.
2. **Static run** (~400 s, carrier at rest, starting at the paper's 17:20): gyro-only
   integration drifts with the gyro bias; the polarization + gravity gradient-descent filter
   (fixed step and dynamic step) holds the attitude.
3. **Dynamic run** (starting at 18:00): rotations about all three axes (yaw +-90 deg, pitch
   +-15 deg, roll +-20 deg; Euler-angle rates up to 14/8/14 deg/s, body rates up to ~17 deg/s);
   attitude error of the dynamic step vs the fixed step vs gyro-only integration.

Acceptance: over >= 20 seeds, the dynamic step's RMS attitude error in the
dynamic run is lower than the fixed step's (mean over seeds, and a one-sided paired sign test
at the 1 % level), and in the static run both beat gyro-only (every seed). The table also
gives the RMS over the second half of each run, after the convergence from the initial
alignment error: there the fixed step, which averages the sensor noise, is the better one.

Everything not stated in the paper is a documented choice in :class:`Scenario` (none tuned to
the outcome): the compound-eye sensor of :mod:`sensor.compound_eye` (zenith unit + eight at
60 deg), 100-count photodiode noise (about 0.1 deg of E-vector noise), a tactical MEMS IMU
(:class:`sensor.imu.ImuSpec` defaults), a 1-deg coarse initial alignment, and Madgwick's rule
for the fixed step's gain.

4. **Multiple-scattering sky** (static run): the readings are simulated under the
   multiple-scattering sky of :mod:`skysim.multiple` (optical thickness
   :attr:`Scenario.ms_taus`), whose E-vectors depart from "perpendicular to the sun" by
   degrees, and the dynamic-step filter runs with both error vectors: the Rayleigh form
   (E normal to the sun) and the measured-vs-predicted form with the same sky
   (:func:`calibration.attitude.model_references`). Reported per form: the mean yaw, pitch
   and roll error over the second half of the run (the bias) and the RMS total error.

Outputs in ``results/jin2020/``: ``sun_positions.csv``/``.md``, ``errors.csv`` (RMS per seed,
run and method), ``table.md``, ``summary.json``, ``timeseries_<run>.csv`` (+ JSON sidecar) of
seed 0, ``multiple_scattering.csv``/``.md``, and figures ``fig3_static.png``, ``fig4_dynamic.png``, ``fig5_errors.png``.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.exceptions import InvalidParameterError
from skysim.geometry import wrap_deg
from skysim.io import atomic_write_many, sidecar_path, write_json_atomic
from skysim.sun import Site

from experiments.plotting.figures import pyplot, save_png
from experiments.workflows.options import output_dir, positive_int
from experiments.workflows.options import seed as seed_type

__all__ = ["SITE", "DATE", "TZ", "PAPER_SUN", "Scenario", "SCENARIO", "QUICK",
           "azimuth_from_south", "sun_discrepancy_table", "run", "format_table",
           "register_reproduce", "register", "multiple_scattering_runs", "format_ms_table"]

SITE = Site(38.88, 121.53, 0.0, name="Dalian University of Technology")
MEMORY_PER_TRIAL_BYTES = 30_000_000
"""Peak memory per seed [bytes] with the full scenario: 4.1 MB measured with tracemalloc for
the quick one (180 s of runs, 2 vs 6 seeds), scaled to the full 600 s and doubled;
``skysim reproduce jin2020`` and ``skysim jin2020`` refuse --trials that would not fit."""
"""The paper's site (about 38.88 N, 121.53 E; height not stated, 0 m)."""
DATE = "2018-05-25"
TZ = "Asia/Shanghai"
PAPER_SUN = {"17:20": (20.54, -100.89), "18:00": (12.98, -106.62)}
"""Sun (elevation, azimuth from south, west negative) [deg] as stated in the paper."""


def azimuth_from_south(azimuth_deg):
    """The paper's azimuth [deg]: from south, west negative, in [-180, 180)
    (``180 - azimuth`` with the skysim azimuth clockwise from north)."""
    return wrap_deg(180.0 - np.asarray(azimuth_deg, float))


def _clock_time(hhmm: str, reading: str) -> pd.Timestamp:
    """Beijing clock time of the paper's time ``hhmm`` under a reading."""
    from skysim.sun import clock_time_from_apparent_solar_time
    h, m = (int(x) for x in hhmm.split(":"))
    if reading == "beijing":
        return pd.Timestamp(f"{DATE}T{hhmm}:00").tz_localize(TZ)
    if reading == "apparent_solar":
        return clock_time_from_apparent_solar_time(DATE, h + m / 60.0, SITE.longitude_deg, TZ,
                                                   SITE.latitude_deg)
    raise InvalidParameterError(f"unknown time reading {reading!r}; valid: 'beijing', 'apparent_solar'")


def sun_discrepancy_table() -> pd.DataFrame:
    """Ephemeris sun at the paper's two times under both readings, beside the paper's angles.

    Columns: ``paper_time``, ``reading`` ("beijing" or "apparent_solar"), ``clock_time``
    (Beijing), ``elevation_deg``, ``azimuth_south_deg``, ``paper_*``, ``d_elevation_deg``,
    ``d_azimuth_deg`` (ephemeris - paper) and ``time_offset_min`` (LAST - Beijing clock).
    """
    from skysim.sun import apparent_solar_time, sun_position
    rows = []
    for hhmm, (p_el, p_az) in PAPER_SUN.items():
        for reading in ("beijing", "apparent_solar"):
            t = _clock_time(hhmm, reading)
            sp = sun_position([t], SITE.latitude_deg, SITE.longitude_deg, SITE.altitude_m)
            last_h = apparent_solar_time([t], SITE.longitude_deg, SITE.latitude_deg).iloc[0]
            clock_h = t.hour + t.minute / 60 + (t.second + t.microsecond / 1e6) / 3600
            el = float(sp.elevation_deg.iloc[0])
            az = float(azimuth_from_south(sp.azimuth_deg.iloc[0]))
            rows.append({"paper_time": hhmm, "reading": reading,
                         "clock_time": t.isoformat(timespec="seconds"),
                         "elevation_deg": el, "azimuth_south_deg": az,
                         "paper_elevation_deg": p_el, "paper_azimuth_south_deg": p_az,
                         "d_elevation_deg": el - p_el, "d_azimuth_deg": az - p_az,
                         "time_offset_min": (last_h - clock_h) * 60.0})
    return pd.DataFrame(rows)


@dataclass(frozen=True)
class Scenario:
    """Experiment parameters (paper's where stated, else documented choices).

    reading : time reading of the paper's clock times ("apparent_solar": the one that
        reproduces the paper's sun angles, see the discrepancy table).
    static_time, dynamic_time : paper times at which the runs start.
    static_s, dynamic_s : run lengths [s] (the paper's static run is ~400 s).
    imu_rate_hz, polarization_every : 100 Hz IMU; polarization sensor and filter update at
        every 10th IMU sample (10 Hz).
    dmax : maximum DoP of the clear sky; noise_counts : photodiode noise [counts] at
        20,000 counts per unit radiance (~0.1 deg AoP noise at the zenith).
    initial_error_deg : 1-sigma per axis of the initial (coarse-alignment) attitude error,
        the same for every method.
    min_dop : units with a lower measured DoP are not used (near the sun).
    dynamic_amplitude_deg, dynamic_period_s : (yaw, pitch, roll) sinusoids of the dynamic run.
    ms_taus, ms_albedo : optical thicknesses and ground albedo of the multiple-scattering
        static runs (Rayleigh optical thickness 0.1 near 530 nm, 0.25 near 430 nm; black
        ground as in the Natraj tables' first case); ms_sun_step_deg : sun-elevation node
        step of that sky (one engine run per node, linear in between).
    """

    reading: str = "apparent_solar"
    static_time: str = "17:20"
    dynamic_time: str = "18:00"
    static_s: float = 400.0
    dynamic_s: float = 200.0
    static_attitude_deg: tuple = (30.0, 2.0, -1.5)
    imu_rate_hz: float = 100.0
    polarization_every: int = 10
    dmax: float = 0.7
    noise_counts: float = 100.0
    initial_error_deg: float = 1.0
    min_dop: float = 0.05
    dynamic_yaw0_deg: float = 30.0
    dynamic_amplitude_deg: tuple = (90.0, 15.0, 20.0)
    dynamic_period_s: tuple = (40.0, 12.0, 9.0)
    imu: dict = field(default_factory=dict)
    ms_taus: tuple = (0.1, 0.25)
    ms_albedo: float = 0.0
    ms_sun_step_deg: float = 1.0


SCENARIO = Scenario()
QUICK = Scenario(static_s=120.0, dynamic_s=60.0)
"""Shorter runs for tests and ``--quick`` (same physics)."""

METHODS = ("dynamic", "fixed", "gyro")
SIGN_TEST_ALPHA = 0.01
"""Acceptance "dynamic below fixed across seeds": the mean over seeds of the per-seed RMS is
lower AND a one-sided paired sign test over the seeds rejects "no better than a coin flip" at
this level (with 20 seeds: at least 16 wins)."""
LABELS = {"dynamic": "dynamic step (line search)", "fixed": "fixed step (Madgwick β)",
          "gyro": "gyro only"}


def _imu_spec(sc: Scenario):
    from sensor.imu import AccelSpec, GyroSpec, ImuSpec
    g = GyroSpec(**sc.imu.get("gyro", {}))
    a = AccelSpec(**sc.imu.get("accel", {}))
    return ImuSpec(g, a, sc.imu_rate_hz)


def fixed_step_beta(sc: Scenario) -> float:
    """Madgwick's gain for the IMU's per-axis gyro error: bias, bias instability and white
    noise added in quadrature [deg/s] -> ``beta`` [1/s]."""
    from calibration.attitude import madgwick_beta
    spec = _imu_spec(sc)
    g = spec.gyro
    err = np.sqrt(g.bias_deg_s ** 2 + g.bias_instability_deg_s ** 2
                  + g.white_noise_deg_s(spec.sample_rate_hz) ** 2)
    return madgwick_beta(err)


def _simulate(kind: str, trials: int, rng, sc: Scenario) -> dict:
    """One run (static or dynamic) for all trials and all three methods."""
    from scipy.spatial.transform import Rotation

    from calibration.attitude import (
        attitude_error_deg,
        e_vectors_from_readings,
        estimate_attitude,
    )
    from sensor.compound_eye import PhotodiodeModel, patent_configuration
    from sensor.platform import dynamic_trajectory, sample_run
    from skysim.sky import RayleighSky

    if kind == "static":
        start, traj = _static_trajectory(sc)
    else:
        start = _clock_time(sc.dynamic_time, sc.reading)
        traj = dynamic_trajectory(start, sc.dynamic_s, sc.imu_rate_hz, sc.dynamic_yaw0_deg,
                                  amplitude_deg=sc.dynamic_amplitude_deg,
                                  period_s=sc.dynamic_period_s)
    sensor = patent_configuration(photodiode=PhotodiodeModel(noise_counts=sc.noise_counts))
    data = sample_run(traj, sensor, RayleighSky(sc.dmax), SITE, _imu_spec(sc), rng, trials,
                      sc.polarization_every)
    e_b, valid = e_vectors_from_readings(data.readings, sensor, sc.min_dop)
    truth = traj.attitude[data.pol_index]
    q0 = (truth[0] * Rotation.from_rotvec(
        rng.normal(0.0, np.radians(sc.initial_error_deg), (trials, 3)))).as_quat()
    beta = fixed_step_beta(sc)
    out = {"trajectory": traj, "truth": truth, "valid_fraction": float(valid.mean()),
           "start": start, "beta": beta, "estimates": {}, "errors": {}}
    for m in METHODS:
        est = estimate_attitude(data.gyro_deg_s, data.accel_mps2, e_b, data.sun_enu, q0,
                                sc.imu_rate_hz, sc.polarization_every, m, beta=beta,
                                valid=valid)
        out["estimates"][m] = est
        out["errors"][m] = attitude_error_deg(est, truth)
    return out


def _static_trajectory(sc: Scenario):
    from sensor.platform import static_trajectory
    start = _clock_time(sc.static_time, sc.reading)
    return start, static_trajectory(start, sc.static_s, sc.imu_rate_hz, *sc.static_attitude_deg)


ERROR_FORMS = ("perpendicular", "model")
"""Error vectors of the multiple-scattering runs: ``perpendicular`` (E normal to the sun,
the Rayleigh form) and ``model`` (measured vs the sky's predicted E-vector)."""


def multiple_scattering_runs(trials: int, rng, sc: Scenario) -> pd.DataFrame:
    """Static run under the multiple-scattering sky, dynamic step, both error vectors.

    One row per (tau, form): mean over seeds of the per-seed mean yaw/pitch/roll error over
    the second half of the run (the bias, [deg]), of the per-seed RMS total error over the
    whole run and its second half [deg]; ``aop_departure_*_deg``: the angle in each unit's
    focal plane between the sky's E-vector and the Rayleigh one, normal to the sun (noise
    free, median and maximum over units and samples with DoP >= min_dop).
    """
    from scipy.spatial.transform import Rotation

    from calibration.attitude import attitude_error_deg, e_vectors_from_readings, estimate_attitude
    from sensor.compound_eye import PhotodiodeModel, patent_configuration
    from sensor.platform import sample_run, sun_vector
    from skysim.multiple import MultipleScatteringSky

    from skysim.geometry import elevation_azimuth
    from skysim.sky import RayleighSky

    start, traj = _static_trajectory(sc)
    rows = []
    for tau in sc.ms_taus:
        sky = MultipleScatteringSky(tau=tau, albedo=sc.ms_albedo,
                                    sun_step_deg=sc.ms_sun_step_deg)
        # equal signal-to-noise: the zenith unit reads the same counts under this sky as under
        # the Rayleigh sky of the main runs (the multiple-scattering I is in flux units)
        sun_el, sun_az = elevation_azimuth(sun_vector([traj.times[0]], SITE)[0])
        gain = float(RayleighSky(sc.dmax).field(90.0, 0.0, sun_el, sun_az).I[0]
                     / sky.field(90.0, 0.0, sun_el, sun_az).I[0])
        sensor = patent_configuration(photodiode=PhotodiodeModel(
            counts_per_radiance=PhotodiodeModel.counts_per_radiance * gain,
            noise_counts=sc.noise_counts))
        data = sample_run(traj, sensor, sky, SITE, _imu_spec(sc), rng, trials,
                          sc.polarization_every)
        e_b, valid = e_vectors_from_readings(data.readings, sensor, sc.min_dop)
        truth = traj.attitude[data.pol_index]
        obs = sensor.observe(sky, truth, data.sun_enu)
        R_b = truth.as_matrix()
        s_b = np.einsum("kji,kj->ki", R_b, data.sun_enu)               # sun in the body frame
        e_rayleigh = np.cross(sensor.view_directions_sensor()[None], s_b[:, None, :])
        e_rayleigh /= np.linalg.norm(e_rayleigh, axis=-1, keepdims=True)
        dep = np.degrees(np.arccos(np.clip(np.abs(np.einsum(
            "kmi,kmi->km", obs.e_vector_sensor, e_rayleigh)), 0.0, 1.0)))
        dep = dep[obs.dop >= sc.min_dop]
        q0 = (truth[0] * Rotation.from_rotvec(
            rng.normal(0.0, np.radians(sc.initial_error_deg), (trials, 3)))).as_quat()
        for form in ERROR_FORMS:
            kw = {} if form == "perpendicular" else {
                "sky": sky, "view_axes_b": sensor.view_directions_sensor()}
            est = estimate_attitude(data.gyro_deg_s, data.accel_mps2, e_b, data.sun_enu, q0,
                                    sc.imu_rate_hz, sc.polarization_every, "dynamic",
                                    valid=valid, **kw)
            err = attitude_error_deg(est, truth)
            half = err["total"].shape[1] // 2
            rows.append({"tau": tau, "albedo": sc.ms_albedo, "form": form,
                         "aop_departure_median_deg": float(np.median(dep)),
                         "aop_departure_max_deg": float(dep.max()),
                         **{f"{k}_bias_deg": float(np.mean(np.mean(err[k][:, half:], axis=1)))
                            for k in ("yaw", "pitch", "roll")},
                         "total_rms_deg": float(np.mean(_rms(err["total"]))),
                         "total_rms_second_half_deg": float(np.mean(_rms(err["total"][:, half:])))})
    return pd.DataFrame(rows)


def format_ms_table(ms: pd.DataFrame) -> str:
    """The multiple-scattering rows as markdown."""
    lines = [("| τ | error vector | AoP departure from E ⟂ sun, median / max [deg] | yaw bias [deg] "
              "| pitch bias [deg] | roll bias [deg] | total RMS [deg] | total RMS, 2nd half "
              "[deg] |"), "|---|---|---|---|---|---|---|---|"]
    names = {"perpendicular": "E ⟂ sun (Rayleigh form)", "model": "measured vs predicted"}
    for r in ms.itertuples():
        lines.append(f"| {r.tau:g} | {names[r.form]} | {r.aop_departure_median_deg:.2f} / "
                     f"{r.aop_departure_max_deg:.1f} | {r.yaw_bias_deg:+.4f} | "
                     f"{r.pitch_bias_deg:+.4f} | {r.roll_bias_deg:+.4f} | "
                     f"{r.total_rms_deg:.4f} | {r.total_rms_second_half_deg:.4f} |")
    return "\n".join(lines)


def _rms(x, axis=-1):
    return np.sqrt(np.mean(np.square(x), axis=axis))


def run(trials: int = 20, seed: int = 2020, out=None, scenario: Scenario = SCENARIO,
        figures: bool = True, multiple_scattering: bool | None = None) -> dict:
    """Both runs for ``trials`` seeds (and the multiple-scattering static runs: None runs them
    when the ``rt`` extra, sasktran2, is installed); returns tables and a summary, writes
    them to ``out``."""
    if multiple_scattering is None:
        import importlib.util
        multiple_scattering = importlib.util.find_spec("sasktran2") is not None
    t0 = time.perf_counter()
    seq = np.random.SeedSequence(seed)
    children = seq.spawn(3)
    runs = {kind: _simulate(kind, trials, np.random.default_rng(child), scenario)
            for kind, child in zip(("static", "dynamic"), children[:2])}
    ms = (multiple_scattering_runs(trials, np.random.default_rng(children[2]), scenario)
          if multiple_scattering else None)
    rows = []
    for kind, r in runs.items():
        for m in METHODS:
            err = r["errors"][m]
            for s in range(trials):
                half = err["total"].shape[1] // 2
                rows.append({"run": kind, "method": m, "seed_index": s,
                             **{f"{k}_rms_deg": float(_rms(v[s])) for k, v in err.items()},
                             "total_rms_second_half_deg": float(_rms(err["total"][s, half:]))})
    errors = pd.DataFrame(rows)
    table = (errors.groupby(["run", "method"], sort=False)
             [["total_rms_deg", "yaw_rms_deg", "pitch_rms_deg", "roll_rms_deg",
               "total_rms_second_half_deg"]].mean()
             .reset_index())
    summary = _summary(errors, runs, trials, seed, scenario, time.perf_counter() - t0)
    if ms is not None:
        summary["multiple_scattering"] = ms.to_dict(orient="records")
    sun = sun_discrepancy_table()
    result = {"sun": sun, "errors": errors, "table": table, "summary": summary, "runs": runs,
              "multiple_scattering": ms}
    if out is not None:
        _write(Path(out), result, figures, seed, scenario)
    return result


def _summary(errors: pd.DataFrame, runs, trials, seed, sc: Scenario, elapsed) -> dict:
    def per_seed(kind, m):
        return errors[(errors.run == kind) & (errors.method == m)].total_rms_deg.to_numpy()
    from scipy.stats import binomtest
    dyn_d, dyn_f = per_seed("dynamic", "dynamic"), per_seed("dynamic", "fixed")
    st = {m: per_seed("static", m) for m in METHODS}
    wins = int(np.sum(dyn_d < dyn_f))
    p_sign = float(binomtest(wins, trials, 0.5, alternative="greater").pvalue)
    checks = {
        "dynamic_run_dynamic_below_fixed_mean": bool(dyn_d.mean() < dyn_f.mean()),
        "dynamic_run_dynamic_below_fixed_sign_test": bool(p_sign < SIGN_TEST_ALPHA),
        "static_run_dynamic_below_gyro_all_seeds": bool(np.all(st["dynamic"] < st["gyro"])),
        "static_run_fixed_below_gyro_all_seeds": bool(np.all(st["fixed"] < st["gyro"])),
        "enough_seeds": bool(trials >= 20),
    }
    counts = {"dynamic_run_seeds_dynamic_below_fixed": wins, "sign_test_p": p_sign,
              "static_run_seeds_dynamic_below_gyro": int(np.sum(st["dynamic"] < st["gyro"])),
              "static_run_seeds_fixed_below_gyro": int(np.sum(st["fixed"] < st["gyro"]))}
    half = {kind: {m: float(errors[(errors.run == kind) & (errors.method == m)]
                            .total_rms_second_half_deg.mean()) for m in METHODS} for kind in runs}
    final = {kind: {m: float(_rms(r["errors"][m]["total"][:, -1], axis=0)) for m in METHODS}
             for kind, r in runs.items()}
    return {"source": "Jin, Xie, Chu, Wei & Wei, 'Optimization method of navigation attitude "
                      "based on skylight polarization pattern', Aero Weaponry 27(1):39 (2020)",
            "trials": trials, "seed": seed, "site": SITE.to_dict(), "date": DATE,
            "scenario": asdict(sc), "imu": _imu_spec(sc).to_dict(),
            "fixed_step_beta_per_s": runs["static"]["beta"],
            "start_times": {k: r["start"].isoformat() for k, r in runs.items()},
            "valid_unit_fraction": {k: r["valid_fraction"] for k, r in runs.items()},
            "mean_rms_total_deg": {kind: {m: float(errors[(errors.run == kind)
                                                          & (errors.method == m)]
                                                   .total_rms_deg.mean()) for m in METHODS}
                                   for kind in runs},
            "final_error_rms_deg": final, "mean_rms_second_half_deg": half,
            "acceptance": checks, "acceptance_counts": counts,
            "accepted": bool(all(checks.values())),
            "elapsed_s": elapsed}


def format_table(table: pd.DataFrame) -> str:
    """Mean over seeds of the per-seed RMS attitude errors, as a markdown table.

    The last column excludes the first half of each run (the convergence from the initial
    alignment error), so it compares the methods once they track."""
    lines = [("| run | method | total [deg] | yaw [deg] | pitch [deg] | roll [deg] | "
              "total, 2nd half of run [deg] |"), "|---|---|---|---|---|---|---|"]
    for r in table.itertuples():
        lines.append(f"| {r.run} | {LABELS[r.method]} | {r.total_rms_deg:.4f} | "
                     f"{r.yaw_rms_deg:.4f} | {r.pitch_rms_deg:.4f} | {r.roll_rms_deg:.4f} | "
                     f"{r.total_rms_second_half_deg:.4f} |")
    return "\n".join(lines)


def format_sun_table(sun: pd.DataFrame) -> str:
    """The sun-position discrepancy table as markdown."""
    lines = [("| paper time | reading | Beijing clock | elevation [deg] | azimuth from S [deg] | "
              "paper el / az | Δel | Δaz | LAST − clock [min] |"),
             "|---|---|---|---|---|---|---|---|---|"]
    for r in sun.itertuples():
        lines.append(f"| {r.paper_time} | {r.reading} | {r.clock_time[11:19]} | "
                     f"{r.elevation_deg:.3f} | {r.azimuth_south_deg:.3f} | "
                     f"{r.paper_elevation_deg} / {r.paper_azimuth_south_deg} | "
                     f"{r.d_elevation_deg:+.3f} | {r.d_azimuth_deg:+.3f} | "
                     f"{r.time_offset_min:+.2f} |")
    return "\n".join(lines)


def _timeseries(r: dict) -> pd.DataFrame:
    """Seed 0: true and estimated attitude at the update samples."""
    from sensor.compound_eye import attitude_angles
    y, p, ro = attitude_angles(r["truth"])
    y = wrap_deg(y)
    cols = {"t_s": r["estimates"]["gyro"].t_s, "true_yaw_deg": y, "true_pitch_deg": p,
            "true_roll_deg": ro}
    for m, est in r["estimates"].items():
        ey, ep, er = (a[0] for a in est.angles_deg())
        ey = wrap_deg(ey)
        cols.update({f"{m}_yaw_deg": ey, f"{m}_pitch_deg": ep, f"{m}_roll_deg": er,
                     f"{m}_error_deg": r["errors"][m]["total"][0]})
    return pd.DataFrame(cols)


def _write(out: Path, result: dict, figures: bool, seed: int, sc: Scenario) -> None:
    from skysim import __version__
    out.mkdir(parents=True, exist_ok=True)
    sun, errors = result["sun"], result["errors"]
    atomic_write_many([
        (out / "sun_positions.csv", lambda tmp: sun.to_csv(tmp, index=False)),
        (out / "sun_positions.md", lambda tmp: tmp.write_text(format_sun_table(sun) + "\n")),
        (out / "errors.csv", lambda tmp: errors.to_csv(tmp, index=False)),
        (out / "table.md", lambda tmp: tmp.write_text(format_table(result["table"]) + "\n"))])
    ms = result.get("multiple_scattering")
    if ms is not None:
        atomic_write_many([
            (out / "multiple_scattering.csv", lambda tmp: ms.to_csv(tmp, index=False)),
            (out / "multiple_scattering.md",
             lambda tmp: tmp.write_text(format_ms_table(ms) + "\n"))])
    write_json_atomic(out / "summary.json", result["summary"])
    for kind, r in result["runs"].items():
        ts = _timeseries(r)
        sidecar = {"schema": "skysim.jin2020.timeseries/1", "run": kind, "seed": seed,
                   "seed_index": 0, "site": SITE.to_dict(), "start": r["start"].isoformat(),
                   "columns": ("t_s [s] since start; *_deg attitude [deg] (yaw clockwise from "
                               "north in [-180, 180), pitch nose up, roll right side down); "
                               "*_error_deg total attitude error angle [deg]"),
                   "generator": {"package": "skysim", "version": __version__,
                                 "scenario": asdict(sc)}}
        csv = out / f"timeseries_{kind}.csv"
        atomic_write_many([(csv, lambda tmp, ts=ts: ts.to_csv(tmp, index=False)),
                           (sidecar_path(csv), lambda tmp, s=sidecar: tmp.write_text(
                               json.dumps(s, indent=2) + "\n"))])
    if figures:
        plot_attitude(result["runs"]["static"], out / "fig3_static.png", "Static run")
        plot_attitude(result["runs"]["dynamic"], out / "fig4_dynamic.png", "Dynamic run")
        plot_errors(result["runs"], out / "fig5_errors.png")


def plot_attitude(r: dict, path: Path, title: str) -> None:
    """Yaw, pitch and roll over time (seed 0), like Figs. 3-4: the truth and the three
    estimators on the left (they overlie each other at this scale), each estimator's error
    (estimate minus truth, yaw wrapped to [-180, 180)) on the right, where they separate."""
    plt = pyplot()
    ts = _timeseries(r)
    fig, axes = plt.subplots(3, 2, figsize=(12, 7.5), sharex=True, layout="constrained")
    styles = dict(zip(METHODS, ("-", "--", ":")))
    for (ax, err_ax), ang in zip(axes, ("yaw", "pitch", "roll")):
        ax.plot(ts.t_s, ts[f"true_{ang}_deg"], color="0.6", lw=4, label="true")
        for m in METHODS:
            est = ts[f"{m}_{ang}_deg"]
            ax.plot(ts.t_s, est, styles[m], lw=1, label=LABELS[m])
            diff = est - ts[f"true_{ang}_deg"]
            if ang == "yaw":
                diff = (diff + 180.0) % 360.0 - 180.0
            err_ax.plot(ts.t_s, diff, styles[m], lw=1)
        err_ax.axhline(0.0, color="0.6", lw=1)
        ax.set_ylabel(f"{ang} [deg]")
        err_ax.set_ylabel(f"{ang} error [deg]")
    for ax in axes[-1]:
        ax.set_xlabel("time since start [s]")
    axes[0, 0].set_title("attitude")
    axes[0, 1].set_title("estimate minus truth")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize=9)
    fig.suptitle(f"{title}: attitude, seed 0 ({r['start']:%Y-%m-%d %H:%M:%S %Z})")
    save_png(fig, path, dpi=110)


def plot_errors(runs: dict, path: Path) -> None:
    """Attitude error vs time, RMS over seeds, per method and run (like Fig. 5)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, (kind, r) in zip(axes, runs.items()):
        for m in METHODS:
            est = r["estimates"][m]
            ax.semilogy(est.t_s, _rms(r["errors"][m]["total"], axis=0), label=LABELS[m])
        ax.set(xlabel="time since start [s]", ylabel="attitude error, RMS over seeds [deg]",
               title=f"{kind} run ({r['errors']['gyro']['total'].shape[0]} seeds)")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    save_png(fig, path, dpi=110)


def _main(trials: int, seed: int, out, quick: bool) -> int:
    from skysim.resources import check_memory
    check_memory(trials * MEMORY_PER_TRIAL_BYTES, f"{trials} seeds of jin2020",
                 "use fewer --trials")
    sc = QUICK if quick else SCENARIO
    out = Path(out or "results/jin2020")
    result = run(trials=trials, seed=seed, out=out, scenario=sc)
    s = result["summary"]
    print(f"Jin et al. 2020 — Dalian {DATE}; {trials} seeds, seed {seed}; static "
          f"{sc.static_s:g} s, dynamic {sc.dynamic_s:g} s; IMU {sc.imu_rate_hz:g} Hz, updates "
          f"{sc.imu_rate_hz / sc.polarization_every:g} Hz")
    print("\nSun: the paper's clock times read as Beijing time vs local apparent solar time")
    print(format_sun_table(result["sun"]))
    print("\nRMS attitude error, mean over seeds")
    print(format_table(result["table"]))
    print("\nacceptance: " + ", ".join(f"{k}={v}" for k, v in s["acceptance"].items()))
    c = s["acceptance_counts"]
    print("dynamic run: dynamic step below fixed step in "
          f"{c['dynamic_run_seeds_dynamic_below_fixed']}/{trials} seeds (sign test p = "
          f"{c['sign_test_p']:.2g}); static run: below gyro-only "
          f"in {c['static_run_seeds_dynamic_below_gyro']} (dynamic) and "
          f"{c['static_run_seeds_fixed_below_gyro']} (fixed) of {trials}")
    if result["multiple_scattering"] is not None:
        print("\nStatic run under the multiple-scattering sky (dynamic step), mean over seeds")
        print(format_ms_table(result["multiple_scattering"]))
    print(f"accepted: {s['accepted']}; {s['elapsed_s']:.1f} s; wrote {out}/")
    return 0


def _reproduce(args) -> int:
    return _main(args.trials or 20, args.seed, args.out, getattr(args, "quick", False))


def register_reproduce(targets: dict) -> None:
    targets["jin2020"] = _reproduce


def register(subparsers) -> None:
    p = subparsers.add_parser("jin2020", help="Jin et al. 2020 attitude filter (with --quick)",
                              description="Same as 'skysim reproduce jin2020', plus --quick.")
    p.add_argument("--trials", type=positive_int, default=20,
                   help="number of seeds, >= 1 (default 20, the acceptance needs >= 20); "
                        "about 3.5 s each")
    p.add_argument("--seed", type=seed_type, default=2020,
                   help="master random seed, >= 0 (default 2020)")
    p.add_argument("--out", type=output_dir, default=None,
                   help="output folder (default: results/jin2020)")
    p.add_argument("--quick", action="store_true", help="shorter runs (120 s static, 60 s dynamic)")
    p.set_defaults(func=_command)


def _command(args) -> int:
    """``skysim jin2020``: its expected duration checked against a day's budget first (as
    ``skysim reproduce`` does)."""
    from experiments.workflows.progress import check_duration, expected_reproduction_seconds
    check_duration(expected_reproduction_seconds("jin2020", args.quick, args.trials),
                   f"skysim jin2020 with --trials {args.trials}", "fewer --trials or --quick "
                   "make it shorter")
    return _main(args.trials, args.seed, args.out, args.quick)
