"""The moonlit compass: heading error against lunar phase and Moon elevation for the
three-pair sensor (raw and with its dark-current calibration), the photodiode ring and the
polarization camera, each with its photon and dark-current noise at night illuminance.

``skysim reproduce moonlit-compass``:

- **Nights**: the waxing half of one lunation at Paranal in its winter, when the nights are
  long and the full Moon passes near the zenith (new Moon 2024-06-06 12:38 UTC, full Moon
  2024-06-22 01:08 UTC), from the ephemeris (:func:`skysim.moon.moon_position`).
  On every :attr:`Config.night_step_days`-th night, for each target Moon elevation the time
  of astronomical night (Sun below -18 deg) when the Moon is closest to it, kept when within
  :attr:`Config.elevation_tolerance_deg`. Thin crescents set in twilight, so the first nights
  after new Moon have no condition: no moonlit compass then (the summary says from which
  phase on there is one).
- **Sky** (:class:`skysim.night.MoonlitSky`): K&S scattered moonlight with the ROLO
  irradiance of that night's Moon, single-scattering Rayleigh pattern, over Paranal's V-band
  dark sky; V-band radiance turned into each sensor's unit by :mod:`sensor.night`.
- **Three-pair sensor** (zenith, :class:`sensor.photodiode.PhotodiodeChannels`): per trial a
  drawn sensor (as ``reproduce dark-current``: dark currents 20-100 pA, ~0.4-2 lx
  equivalent), calibrated at the integrating sphere at 1-1000 lx, then read at the zenith's
  lux equivalent and DoP for 36 headings; shot noise of photo- and dark current at
  :attr:`Config.bandwidth_Hz`, sampled at twice that and averaged over
  :attr:`Config.window_s`, log-amplifier output noise and 16-bit DAQ per sample. Headings:
  ``raw`` (the outputs through the 2014 equations, pair U1-U2, no calibration: what the
  sensor's own formula reads while the dark current pulls each ratio towards ``D_n / D_m``),
  ``dark-calibrated`` (the patent's dark-current calibration and
  :func:`calibration.dark_current.solve_combined`) and ``true-parameters`` (the same solve
  with the injected parameters: the floor of the dark-current model). At moonlight the
  intensity ``I`` of the dark-current solve is identified mainly by the mean over the channels
  of the photodiodes' dark-level mismatch (a zero-mean mismatch lies in the span of the
  polarization columns): sensors whose dark levels nearly match lose the angle too, so the
  errors mix a degree for some drawn sensors with tens of degrees for others (the table
  gives the median absolute error beside the RMS).
- **Ring** (:func:`sensor.compound_eye.ring_configuration`: 8 units at 45 deg elevation, 4
  photodiodes each): the same photodiodes with a linear transimpedance readout
  (:class:`sensor.night.NightPhotodiode`), averaged over the window, the dark level measured
  capped over the same window and subtracted; Stokes per unit, the Moon as the direction
  perpendicular to the units' E-vectors (:func:`calibration.installation.sun_vector_sensor`),
  heading from its azimuth. Random headings, level carrier.
- **Camera** (:class:`sensor.camera.PolarizationCamera`: the module's sensor defaults, a
  fisheye on a square sensor of IMX250MZR pixels, photoelectron rate from
  :func:`sensor.night.camera_photoelectron_rate`): exposure set for 0.6 of the full well on
  the 99th percentile of the sky, at most :attr:`Config.window_s`; the Moon's disk saturates;
  centred demosaicing, :func:`calibration.camera_heading.heading_from_image` with the Moon
  in the Sun's place. The simulated sensor is ``camera_px`` square, far smaller than the
  IMX250's 2448 x 2048: its heading noise is that of fewer pixels (``camera_pixels`` in the
  table; in the noise-limited regime the full sensor's is ``sqrt(n_sim / n_full)`` of it).

Heading errors: the three-pair sensor measures the polarization azimuth modulo 180 deg
(errors in [-90, 90), a guess has an RMS of 52 deg); ring and camera give the heading
modulo 360 deg (errors in [-180, 180), a guess has an RMS of 104 deg).

Outputs: ``conditions.csv``, ``table.csv`` / ``table.md`` (per sensor and condition: RMS,
mean and standard deviation of the heading error, failures), ``summary.json``,
``heading_vs_phase.png``, ``heading_vs_illuminance.png``.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.exceptions import InvalidParameterError
from skysim.io import atomic_write, write_json_atomic

from experiments.plotting.figures import pyplot, save_png

__all__ = ["Config", "DEFAULT_SEED", "QUICK", "SENSORS", "camera_errors", "format_summary",
           "format_table", "night_camera", "night_conditions",
           "register_reproduce", "ring_errors", "run", "three_pair_errors"]

DEFAULT_SEED = 20240622
"""Master seed (the full Moon of the lunation)."""

SENSORS = ("three-pair raw", "three-pair dark-calibrated", "three-pair true-parameters",
           "ring", "camera")
"""Rows of the table, in order."""

ASTRONOMICAL_NIGHT_DEG = -18.0


@dataclass(frozen=True)
class Config:
    """Settings (none tuned to the result).

    start, end : the waxing half of the lunation [UTC].
    step_min : time step of the ephemeris search [min].
    night_step_days : every n-th night.
    elevations_deg, elevation_tolerance_deg : target Moon elevations and the accepted miss.
    window_s : averaging window of the photodiodes and longest camera exposure [s] (the Moon
        moves 0.04 deg in 10 s).
    bandwidth_Hz : photodiode readout bandwidth (as ``reproduce dark-current``).
    headings : headings per three-pair trial (turntable-like, evenly spread).
    three_pair_trials, ring_trials, camera_trials : drawn sensors / headings / images per
        condition.
    camera_px : side of the simulated camera sensor [px].
    """

    start: str = "2024-06-06T12:00:00Z"
    end: str = "2024-06-22T12:00:00Z"
    step_min: float = 10.0
    night_step_days: int = 1
    elevations_deg: tuple = (15.0, 30.0, 45.0, 60.0, 75.0)
    elevation_tolerance_deg: float = 2.0
    window_s: float = 10.0
    bandwidth_Hz: float = 10.0
    headings: int = 36
    three_pair_trials: int = 10
    ring_trials: int = 24
    camera_trials: int = 6
    camera_px: int = 256


QUICK = Config(step_min=30.0, night_step_days=4, elevations_deg=(20.0, 45.0, 70.0),
               elevation_tolerance_deg=5.0, headings=12, three_pair_trials=2, ring_trials=6,
               camera_trials=2, camera_px=96)
"""The ``--quick`` settings: four nights, three elevations, few trials, small images."""


def _paranal():
    from .moonlit_sky import paranal as site
    return site()


# --------------------------------------------------------------------------- conditions
def night_conditions(cfg: Config = Config(), site=None) -> pd.DataFrame:
    """The (phase, Moon elevation) conditions of the lunation (module docstring).

    Returns one row per condition: ``time``, ``night`` (local date), ``moon_elevation_deg``,
    ``moon_azimuth_deg``, ``phase_angle_deg``, ``illuminated_fraction``,
    ``target_elevation_deg``, ``moon_irradiance_W_m2_nm`` (V band, above the atmosphere),
    ``moon_illuminance_lx`` (direct, horizontal), ``zenith_lux_eq`` (pi times the zenith's
    luminance) and ``zenith_dop``.

    Raises
    ------
    ValueError
        If no night of the span has the Moon up in astronomical night near a target
        elevation.
    """
    from sensor.night import lux_equivalent, moon_illuminance_lx
    from skysim.moon import moon_position
    from skysim.night import MoonlitSky, moon_band_irradiance
    from skysim.sun import sun_position

    site = site or _paranal()
    times = pd.date_range(cfg.start, cfg.end, freq=pd.Timedelta(minutes=cfg.step_min))
    sun = sun_position(times, site.latitude_deg, site.longitude_deg, site.altitude_m)
    dark = sun.elevation_deg.to_numpy() < ASTRONOMICAL_NIGHT_DEG
    moon = moon_position(times[dark], site.latitude_deg, site.longitude_deg, site.altitude_m)
    moon = moon[moon.elevation_deg.to_numpy() > 0.0]
    # the night's local date: solar time shifted by 12 h, so that no night straddles two
    night = (moon.index + pd.to_timedelta(site.longitude_deg / 15.0 - 12.0, unit="h")).floor("D")
    first = night.min() if len(night) else None
    rows = []
    for day in sorted(set(night)):
        if (day - first).days % cfg.night_step_days:
            continue
        m = moon[night == day]
        for target in cfg.elevations_deg:
            miss = np.abs(m.elevation_deg.to_numpy() - target)
            j = int(np.argmin(miss))
            if miss[j] <= cfg.elevation_tolerance_deg:
                rows.append((m.index[j], day.date().isoformat(), target))
    if not rows:
        raise InvalidParameterError(f"no time from {cfg.start} to {cfg.end} has the Moon within "
                         f"{cfg.elevation_tolerance_deg} deg of {list(cfg.elevations_deg)} deg "
                         "elevation in astronomical night; widen the span or the tolerance")
    t = pd.DatetimeIndex([r[0] for r in rows])
    pos = moon_position(t, site.latitude_deg, site.longitude_deg, site.altitude_m)
    e_moon, _ = moon_band_irradiance(pos, "V")
    el, az = pos.elevation_deg.to_numpy(), pos.azimuth_deg.to_numpy()
    zen = [MoonlitSky(e).field(90.0, 0.0, a, b) for e, a, b in zip(e_moon, el, az)]
    return pd.DataFrame({
        "time": t, "night": [r[1] for r in rows], "target_elevation_deg": [r[2] for r in rows],
        "moon_elevation_deg": el, "moon_azimuth_deg": az,
        "phase_angle_deg": pos.phase_angle_deg.to_numpy(),
        "illuminated_fraction": pos.illuminated_fraction.to_numpy(),
        "moon_irradiance_W_m2_nm": e_moon,
        "moon_illuminance_lx": moon_illuminance_lx(e_moon, el),
        "zenith_lux_eq": lux_equivalent(np.array([f.I for f in zen], float)),
        "zenith_dop": np.array([f.dop for f in zen], float)})


# --------------------------------------------------------------------------- three-pair
def _three_pair_trial(rng, cond: pd.DataFrame, cfg: Config, *, noise_free: bool = False):
    """Heading errors [deg] (C, J) of one drawn three-pair sensor per estimator."""
    from calibration.dark_current import ChannelModel, calibrate_dark_current, solve_combined
    from calibration.solve import heading_error_deg, solve_pair
    from sensor.daq import Daq
    from sensor.photodiode import PhotodiodeChannels
    from skysim.geometry import wrap_axial_deg

    from .dark_current import Config as DarkConfig, calibration_grid
    from sensor.yang2014 import ERROR_MODEL

    daq = Daq(ERROR_MODEL.daq_bits, ERROR_MODEL.daq_range_V)
    params = PhotodiodeChannels.draw(rng)
    noise = rng.uniform(*ERROR_MODEL.noise_range_V, 3)
    noise_total = np.sqrt(noise ** 2 + daq.lsb_V ** 2 / 12.0)
    dark_cfg = DarkConfig()
    I_c, phi_c, d_c = calibration_grid(dark_cfg)
    U_c, _ = params.sample(I_c, phi_c, d_c, rng, noise_V=noise, bandwidth_Hz=cfg.bandwidth_Hz,
                           daq=daq)
    cal_b = calibrate_dark_current(U_c, I_c, phi_c, d_c, noise_V=noise_total, daq=daq)

    n = max(1, int(round(2.0 * cfg.bandwidth_Hz * cfg.window_s)))  # Nyquist-rate samples
    heading = np.linspace(0.0, 360.0, cfg.headings, endpoint=False) + rng.uniform(0, 360)
    phi = wrap_axial_deg(heading[None, :] - cond.moon_azimuth_deg.to_numpy()[:, None])
    shape = phi.shape + (n,)
    E = np.broadcast_to(cond.zenith_lux_eq.to_numpy()[:, None, None], shape)
    d = np.broadcast_to(cond.zenith_dop.to_numpy()[:, None, None], shape)
    if noise_free:
        U = params.outputs(E[..., 0], phi, d[..., 0])
        noise_mean = noise_total * 1e-6
    else:
        U, _ = params.sample(E, np.broadcast_to(phi[..., None], shape), d, rng, noise_V=noise,
                             bandwidth_Hz=cfg.bandwidth_Hz, daq=daq)
        U = U.mean(axis=-2)
        noise_mean = noise_total / np.sqrt(n)
    phi_raw, _ = solve_pair(U, (1, 2))
    dark = solve_combined(U, cal_b.model, noise_mean)
    true = solve_combined(U, ChannelModel.from_photodiodes(params), noise_mean)
    return {"three-pair raw": heading_error_deg(phi_raw, phi),
            "three-pair dark-calibrated": heading_error_deg(dark.phi_deg, phi),
            "three-pair true-parameters": heading_error_deg(true.phi_deg, phi)}


def three_pair_errors(cond: pd.DataFrame, cfg: Config, rng: np.random.Generator, *,
                      noise_free: bool = False) -> dict:
    """Heading errors [deg] of the three-pair sensor per estimator: arrays (C, trials x
    headings) over the conditions ``cond`` (:func:`night_conditions`). ``noise_free``:
    no shot, output or DAQ noise in the night readings (the calibration keeps its noise)."""
    trials = [_three_pair_trial(rng, cond, cfg, noise_free=noise_free)
              for _ in range(cfg.three_pair_trials)]   # one drawn sensor per trial
    return {k: np.concatenate([t[k] for t in trials], axis=1) for k in trials[0]}


# --------------------------------------------------------------------------- ring
def ring_errors(cond: pd.DataFrame, cfg: Config, rng: np.random.Generator, *,
                photodiode=None, window_s: float | None = None) -> np.ndarray:
    """Heading errors [deg] (C, ring_trials) of the 8-unit ring (module docstring) at random
    headings, ``photodiode`` a :class:`sensor.night.NightPhotodiode` (default one)."""
    from calibration.installation import (UnitPolarization, e_vectors_sensor,
                                          polarization_from_photodiodes, sun_vector_sensor)
    from sensor.compound_eye import FOUR_ANGLES_DEG, body_attitude, ring_configuration
    from sensor.night import NightPhotodiode, lux_equivalent
    from skysim.geometry import direction_vector
    from skysim.night import MoonlitSky

    pdiode = photodiode or NightPhotodiode()
    window = cfg.window_s if window_s is None else window_s
    ring = ring_configuration(8, 45.0, FOUR_ANGLES_DEG)
    angles = np.asarray(FOUR_ANGLES_DEG)
    out = np.empty((len(cond), cfg.ring_trials))
    for c, row in enumerate(cond.itertuples()):  # one sky per condition
        yaw = rng.uniform(0.0, 360.0, cfg.ring_trials)
        moon_enu = np.broadcast_to(direction_vector(row.moon_elevation_deg,
                                                    row.moon_azimuth_deg), (yaw.size, 3))
        obs = ring.observe(MoonlitSky(row.moon_irradiance_W_m2_nm), body_attitude(yaw),
                           moon_enu)
        lux = lux_equivalent(obs.radiance)[..., None]
        current = pdiode.read_A(lux, obs.aop_unit_deg[..., None], obs.dop[..., None], angles,
                                window, rng)
        readings = current - pdiode.dark_level_A(window, rng, current.shape)
        aop, dop = polarization_from_photodiodes(readings, angles, "stokes")
        pol = UnitPolarization(aop, dop, np.isfinite(aop))
        moon_s, _ = sun_vector_sensor(e_vectors_sensor(pol, ring), np.abs(dop))
        body_az = np.degrees(np.arctan2(moon_s[:, 0], moon_s[:, 1]))
        heading = row.moon_azimuth_deg - body_az
        out[c] = (heading - yaw + 180.0) % 360.0 - 180.0
    return out


# --------------------------------------------------------------------------- camera
def night_camera(cfg: Config, **overrides):
    """The fisheye polarization camera of the study (module docstring)."""
    from sensor.camera import PolarizationCamera
    from sensor.night import MOON_RADIUS_DEG, camera_photoelectron_rate
    kwargs = {"photoelectrons_per_s": camera_photoelectron_rate(),
              "sun_radius_deg": MOON_RADIUS_DEG, **overrides}
    return PolarizationCamera.fisheye(cfg.camera_px, cfg.camera_px, **kwargs)


def camera_errors(cond: pd.DataFrame, cfg: Config, rng: np.random.Generator, cam=None,
                  *, noise_free: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Heading errors [deg] (C, camera_trials) of one image per trial (NaN where the image
    has too few usable samples) and the exposures [s]; ``noise_free``: the expected
    electrons digitised without shot or read noise."""
    from calibration.camera_heading import DEFAULT_DEMOSAIC, heading_from_image
    from calibration.exceptions import TooFewSamplesError
    from sensor.camera import camera_attitude, camera_stokes
    from skysim.night import MoonlitSky

    cam = cam or night_camera(cfg)
    err = np.full((len(cond), cfg.camera_trials), np.nan)
    expo = np.empty_like(err)
    for c, row in enumerate(cond.itertuples()):  # one sky per condition
        sky = MoonlitSky(row.moon_irradiance_W_m2_nm)
        for k, yaw in enumerate(rng.uniform(0.0, 360.0, cfg.camera_trials)):  # one image each
            scene = cam.scene(sky, camera_attitude(yaw), row.moon_elevation_deg,
                              row.moon_azimuth_deg)
            t = min(cam.auto_exposure_s(scene), cfg.window_s)
            expo[c, k] = t
            if noise_free:
                raw = cam.digitise(cam.expected_electrons(scene, t))
                raw[scene.sun] = cam.sensor.max_dn
            else:
                raw = cam.capture(scene, t, rng)
            st = camera_stokes(cam, raw, t, valid=scene.valid, method=DEFAULT_DEMOSAIC)
            try:
                h = heading_from_image(st, cam.lens, row.moon_elevation_deg,
                                       row.moon_azimuth_deg)
            except TooFewSamplesError:
                continue
            err[c, k] = (h.heading_deg - yaw + 180.0) % 360.0 - 180.0
    return err, expo


# --------------------------------------------------------------------------- the study
def _stats(sensor: str, cond: pd.DataFrame, err: np.ndarray, extra=None) -> list[dict]:
    rows = []
    for c, row in enumerate(cond.itertuples()):
        e = err[c][np.isfinite(err[c])]
        rows.append({"sensor": sensor, "night": row.night,
                     "phase_angle_deg": row.phase_angle_deg,
                     "illuminated_fraction": row.illuminated_fraction,
                     "moon_elevation_deg": row.moon_elevation_deg,
                     "zenith_lux_eq": row.zenith_lux_eq, "zenith_dop": row.zenith_dop,
                     "n": int(e.size), "failures": int(err[c].size - e.size),
                     "rms_error_deg": float(np.sqrt(np.mean(e ** 2))) if e.size else np.nan,
                     "median_abs_error_deg": float(np.median(np.abs(e))) if e.size else np.nan,
                     "mean_error_deg": float(np.mean(e)) if e.size else np.nan,
                     "sd_error_deg": float(np.std(e, ddof=1)) if e.size > 1 else np.nan,
                     **({k: v[c] for k, v in extra.items()} if extra else {})})
    return rows


def run(*, quick: bool = False, trials: int | None = None, seed: int = DEFAULT_SEED,
        out=None, cfg: Config | None = None) -> dict:
    """The study of the module docstring; writes the outputs to ``out`` if given and returns
    ``{"conditions", "table", "summary"}``. ``trials`` scales every sensor's trials."""
    t0 = time.perf_counter()
    cfg = cfg or (QUICK if quick else Config())
    if trials:
        cfg = Config(**{**asdict(cfg), "three_pair_trials": trials, "ring_trials": trials,
                        "camera_trials": trials})
    seeds = np.random.SeedSequence(seed).spawn(3)
    cond = night_conditions(cfg)
    rows = []
    timing = {}
    t = time.perf_counter()
    for name, err in three_pair_errors(cond, cfg, np.random.default_rng(seeds[0])).items():
        rows += _stats(name, cond, err)
    timing["three_pair_s"] = time.perf_counter() - t
    t = time.perf_counter()
    rows += _stats("ring", cond, ring_errors(cond, cfg, np.random.default_rng(seeds[1])))
    timing["ring_s"] = time.perf_counter() - t
    t = time.perf_counter()
    cam = night_camera(cfg)
    err, expo = camera_errors(cond, cfg, np.random.default_rng(seeds[2]), cam)
    n_pix = int(cam.sky_pixels(_level()).sum())
    rows += _stats("camera", cond, err, {"exposure_s": np.nanmean(expo, axis=1),
                                         "camera_pixels": np.full(len(cond), n_pix)})
    timing["camera_s"] = time.perf_counter() - t
    table = pd.DataFrame(rows)
    summary = _summary(cond, table, cfg, seed, timing, time.perf_counter() - t0)
    result = {"conditions": cond, "table": table, "summary": summary}
    if out is not None:
        _write(Path(out), result)
    return result


def _level():
    from sensor.camera import camera_attitude
    return camera_attitude(0.0)


def _summary(cond, table, cfg, seed, timing, elapsed) -> dict:
    from sensor.night import LUX_PER_V_IRRADIANCE, camera_photoelectron_rate
    best = {}
    for sensor, g in table.groupby("sensor", sort=False):
        g = g.sort_values("phase_angle_deg")
        full = g.iloc[0]
        best[sensor] = {
            "rms_error_deg_median": float(np.nanmedian(g.rms_error_deg)),
            "median_abs_error_deg_median": float(np.nanmedian(g.median_abs_error_deg)),
            "rms_error_deg_fullest_moon": float(full.rms_error_deg),
            "rms_error_deg_thinnest_moon": float(g.iloc[-1].rms_error_deg),
            "failures": int(g.failures.sum())}
    return {"schema": "skysim.moonlit_compass/1", "seed": seed, "config": asdict(cfg),
            "site": _paranal().to_dict(), "band": "V",
            "lux_per_V_irradiance": LUX_PER_V_IRRADIANCE,
            "camera_photoelectrons_per_s_per_radiance": camera_photoelectron_rate(),
            "conditions": int(len(cond)),
            "phase_angle_deg_range": [float(cond.phase_angle_deg.min()),
                                      float(cond.phase_angle_deg.max())],
            "first_night_with_moonlit_compass": str(cond.night.min()),
            "zenith_lux_eq_range": [float(cond.zenith_lux_eq.min()),
                                    float(cond.zenith_lux_eq.max())],
            "moon_illuminance_lx_max": float(cond.moon_illuminance_lx.max()),
            "sensors": best, "timing_s": timing, "elapsed_s": elapsed}


def format_table(table: pd.DataFrame, value: str = "rms_error_deg") -> str:
    """Markdown: ``value`` (a column of the table, e.g. the RMS heading error [deg]) per
    condition (rows) and sensor (columns)."""
    wide = table.pivot_table(index=["night", "phase_angle_deg", "moon_elevation_deg",
                                    "zenith_lux_eq", "zenith_dop"], columns="sensor",
                             values=value, sort=False)
    cols = [s for s in SENSORS if s in wide.columns]
    lines = ["| night | phase angle [deg] | Moon elevation [deg] | zenith lux eq. [lx] "
             "| zenith DoP | " + " | ".join(cols) + " |",
             "|---|---|---|---|---|" + "---|" * len(cols)]
    for key, r in wide.iterrows():
        night, phase, el, lux, dop = key
        lines.append(f"| {night} | {phase:.1f} | {el:.1f} | {lux:.2e} | {dop:.2f} | "
                     + " | ".join(f"{r[c]:.3g}" for c in cols) + " |")
    return "\n".join(lines)


def _write(out: Path, result: dict):
    out.mkdir(parents=True, exist_ok=True)
    cond = result["conditions"].assign(
        time=result["conditions"].time.dt.strftime("%Y-%m-%dT%H:%M:%SZ"))
    for name, df in (("conditions", cond), ("table", result["table"])):
        atomic_write(out / f"{name}.csv", lambda p, df=df: df.to_csv(p, index=False,
                                                                     float_format="%.6g"))
    atomic_write(out / "table.md", lambda p: p.write_text(
        "# Moonlit compass\n\n## RMS heading error [deg]\n\n" + format_table(result["table"])
        + "\n\n## Median absolute heading error [deg]\n\n"
        + format_table(result["table"], "median_abs_error_deg") + "\n"))
    write_json_atomic(out / "summary.json", result["summary"])
    _plot(result, out)


SENSOR_TITLES = {"three-pair raw": "three-pair sensor, uncalibrated",
                 "three-pair dark-calibrated": "three-pair, dark current calibrated",
                 "three-pair true-parameters": "three-pair, true sensor parameters",
                 "ring": "ring of 8 photodiode units", "camera": "polarization camera"}
"""What the figures call the rows of :data:`SENSORS`."""


def _plot(result: dict, out: Path):
    """RMS heading error against the Moon's phase, one panel per sensor on a 2 x 3 grid
    whose sixth cell holds the legend (the Moon's elevation); and against the night's
    illuminance, all sensors on one axis."""
    plt = pyplot()
    table = result["table"]
    sensors = [s for s in SENSORS if s in set(table.sensor)]
    ncols = min(3, len(sensors) + 1)
    nrows = -(-(len(sensors) + 1) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.9 * ncols, 3.3 * nrows), sharey=True,
                             squeeze=False, constrained_layout=True)
    cmap = plt.get_cmap("viridis")
    targets = sorted(result["conditions"].target_elevation_deg.unique())
    flat = axes.ravel()
    for ax, sensor in zip(flat, sensors):
        g = table[table.sensor == sensor].merge(
            result["conditions"][["night", "moon_elevation_deg", "target_elevation_deg"]],
            on=["night", "moon_elevation_deg"])
        for i, target in enumerate(targets):
            h = g[g.target_elevation_deg == target].sort_values("phase_angle_deg")
            ax.semilogy(h.phase_angle_deg, h.rms_error_deg, "o-", ms=3,
                        color=cmap(i / max(1, len(targets) - 1)),
                        label=f"about {target:g}°")
        ax.invert_xaxis()
        ax.set(title=SENSOR_TITLES.get(sensor, sensor),
               xlabel="Moon's phase angle [deg] (new → full)")
        ax.grid(True, which="both", alpha=0.3)
    for row in axes:
        row[0].set_ylabel("RMS heading error [deg]")
    handles, labels = flat[0].get_legend_handles_labels()
    for ax in flat[len(sensors):]:
        ax.set_axis_off()
    flat[len(sensors)].legend(handles, labels, title="Moon's elevation", loc="center",
                              fontsize=9, title_fontsize=9)
    save_png(fig, out / "heading_vs_phase.png")

    fig, ax = plt.subplots(figsize=(6, 5.0), constrained_layout=True)
    for sensor in sensors:
        g = table[table.sensor == sensor].sort_values("zenith_lux_eq")
        ax.loglog(g.zenith_lux_eq, g.rms_error_deg, "o", ms=4,
                  label=SENSOR_TITLES.get(sensor, sensor))
    ax.set(xlabel="zenith lux equivalent π L [lx]", ylabel="RMS heading error [deg]",
           title="heading error vs night illuminance")
    ax.grid(True, which="both", alpha=0.3)
    fig.legend(loc="outside lower center", ncol=2, fontsize=8)  # beside the points, not on them
    save_png(fig, out / "heading_vs_illuminance.png")


# --------------------------------------------------------------------------- command line
def format_summary(summary: dict) -> str:
    lines = [f"{summary['conditions']} conditions, phase angle "
             f"{summary['phase_angle_deg_range'][0]:.0f}-{summary['phase_angle_deg_range'][1]:.0f}"
             f" deg, zenith {summary['zenith_lux_eq_range'][0]:.1e}-"
             f"{summary['zenith_lux_eq_range'][1]:.1e} lx equivalent; direct moonlight up to "
             f"{summary['moon_illuminance_lx_max']:.2f} lx"]
    for sensor, s in summary["sensors"].items():
        lines.append(f"{sensor:28s} RMS heading error: median {s['rms_error_deg_median']:.3g}"
                     f" deg, fullest Moon {s['rms_error_deg_fullest_moon']:.3g} deg, thinnest "
                     f"{s['rms_error_deg_thinnest_moon']:.3g} deg")
    return "\n".join(lines)


def register_reproduce(targets: dict) -> None:
    from experiments.workflows.progress import reproduction
    targets["moonlit-compass"] = reproduction(
        "moonlit-compass", "Moonlit compass — heading error vs lunar phase and Moon elevation",
        run, lambda result: format_summary(result["summary"]),
        ("table.md", "table.csv", "conditions.csv", "summary.json", "heading_vs_phase.png",
         "heading_vs_illuminance.png"))
