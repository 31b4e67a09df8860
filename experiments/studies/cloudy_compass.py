"""The cloudy compass: heading error against cloud cover and cloud optical thickness for the
three-pair sensor, the photodiode ring and the polarization camera, each with the heading
methods skysim has, under the partly cloudy sky of :mod:`skysim.partly_cloudy`.

``skysim reproduce cloudy-compass``:

- **Sky**: the multiple-scattering Rayleigh sky at 550 nm (:class:`skysim.multiple.
  MultipleScatteringSky`, molecular optical thickness of Bodhaine et al. 1999, ground albedo
  0.1) behind broken clouds (:class:`skysim.cloud_field.CloudField`: base 1000 m, correlation
  scale 10 deg overhead, the same optical thickness in every cloud), the sun at
  :attr:`Config.sun_elevation_deg`.
- **Trials**: one cloud field per optical thickness (the same Gaussian field at every cover,
  so the covers differ only in how much of it is cloud: paired comparisons), sampled at
  trial ``k`` at the time ``k`` hours with a wind of 100 m/s: every trial sees a patch of
  sky 360 km downwind of the last, independent of it (the dome reaches 113 km at the
  horizon). A sampling device, not weather: the clouds are frozen during a trial. Each trial
  has its own random heading.
- **Three-pair sensor** (zenith, the 2014 equations, :func:`sensor.opponent.opponent_output`
  on the sky's zenith DoP and AoP): ideal channels, output noise 0.4 mV (the middle of
  the error model of ``reproduce yang2014``), 16-bit DAQ. Methods: ``U1-U2`` (the paper's
  pair, every reading), ``U1-U2, DoP >= 0.05`` (readings whose solved DoP is below 0.05 give
  no heading: the sensor knows when it is under a thick cloud). The polarization azimuth is
  known modulo 180 deg: errors in [-90, 90).
- **Ring** (:func:`sensor.compound_eye.ring_configuration`: 8 units at 45 deg, 4
  photodiodes each, Gaussian read noise 3 counts, a 16-bit ADC whose full scale is a radiance
  of 1.09 in the flux-pi unit: a thick sunlit cloud stays in range, the aureole near the sun
  saturates; a unit with a saturated photodiode is left out). Stokes per unit, the sun as the
  direction most nearly perpendicular to the units' E-vectors
  (:func:`calibration.installation.sun_vector_sensor`), weighted by DoP (``DoP-weighted``),
  all units alike (``equal weights``), or only units with DoP >= 0.05 (``DoP >= 0.05``).
  Heading modulo 360 deg.
- **Camera** (:class:`sensor.camera.PolarizationCamera`, fisheye on a
  :attr:`Config.camera_px` square sensor, exposure for 0.6 of the full well on the 99th
  percentile of the sky, centred demosaicing): :func:`calibration.camera_heading.
  heading_from_image` with Cauchy's robust loss (``robust``) or plain least squares
  (``least squares``), both on the pixels of DoLP >= 0.05.

The table gives per sensor and method, cover and optical thickness: the number of headings,
the failures (no heading), the median absolute and the RMS heading error [deg].
``--trials N`` sets the camera images per cover and thickness and scales the other sensors'
trials in proportion.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from skysim.io import atomic_write, write_json_atomic

from experiments.plotting.figures import pyplot, save_png

__all__ = ["Config", "DEFAULT_SEED", "QUICK", "METHODS", "camera_errors", "clear_sky",
           "cloud_fields", "format_table", "register_reproduce", "ring_errors", "run",
           "three_pair_errors"]

DEFAULT_SEED = 20010904
"""Master seed (the publication date of Pomozi et al. 2001)."""

METHODS = {"three-pair": ("U1-U2", "U1-U2, DoP >= 0.05"),
           "ring": ("DoP-weighted", "equal weights", "DoP >= 0.05"),
           "camera": ("robust", "least squares")}
"""Heading methods per sensor, in table order."""

MIN_DOP = 0.05
"""DoP below which a reading or unit gives no heading in the gated methods (the zenith unit
threshold of :func:`calibration.installation.unit_polarization`)."""

TRIAL_SPACING_S = 3600.0
TRIAL_WIND_M_S = 100.0
"""Trials are 360 km apart on the cloud layer (module docstring)."""


@dataclass(frozen=True)
class Config:
    """Settings (none tuned to the result).

    covers : cloud covers [1].
    taus : cloud optical thicknesses at 550 nm [1] (thin: 2; stratocumulus: 10).
    sun_elevation_deg, sun_azimuth_deg : the sun [deg].
    three_pair_trials, ring_trials, camera_trials : headings per cover and thickness.
    camera_px : side of the simulated camera sensor [px].
    noise_V : three-pair output noise [V, 1 sigma].
    ring_counts_per_radiance : ring ADC counts for a radiance of 1 (flux-pi unit).
    ring_noise_counts : ring read noise [counts, 1 sigma].
    """

    covers: tuple = (0.0, 0.25, 0.5, 0.75, 0.9)
    taus: tuple = (2.0, 10.0)
    sun_elevation_deg: float = 40.0
    sun_azimuth_deg: float = 135.0
    three_pair_trials: int = 400
    ring_trials: int = 200
    camera_trials: int = 8
    camera_px: int = 128
    noise_V: float = 0.4e-3
    ring_counts_per_radiance: float = 60_000.0
    ring_noise_counts: float = 3.0


QUICK = Config(covers=(0.0, 0.5, 0.9), taus=(10.0,), three_pair_trials=100, ring_trials=40,
               camera_trials=2, camera_px=64)
"""The ``--quick`` settings: three covers, one thickness, few trials, small images."""


# --------------------------------------------------------------------------- the sky
def clear_sky():
    """The clear sky of the study (module docstring)."""
    from skysim.multiple import MultipleScatteringSky
    return MultipleScatteringSky(wavelength_nm=550.0, albedo=0.1)


def cloud_fields(cfg: Config, seed: int) -> dict:
    """``{(cover, tau): CloudField}``: one Gaussian field per optical thickness, thresholded
    at every cover (module docstring)."""
    from skysim.cloud_field import CloudField
    seeds = np.random.SeedSequence(seed).spawn(len(cfg.taus))
    return {(c, t): CloudField(c, t, seeds[i], wind_speed_m_s=TRIAL_WIND_M_S,
                               wind_from_deg=270.0)
            for i, t in enumerate(cfg.taus) for c in cfg.covers}


def _sky(clear, field, n: int):
    from skysim.partly_cloudy import PartlyCloudySky
    return PartlyCloudySky(clear, field, np.arange(n) * TRIAL_SPACING_S)


def _heading_error(est_deg, true_deg, period: float = 360.0) -> np.ndarray:
    h = 0.5 * period
    return (np.asarray(est_deg) - np.asarray(true_deg) + h) % period - h


# --------------------------------------------------------------------------- three-pair
def three_pair_errors(clear, field, cfg: Config, rng: np.random.Generator) -> dict:
    """Heading errors [deg] (three_pair_trials,) per method, NaN where a method gives none,
    and the zenith DoP of each trial."""
    from calibration.solve import solve_pair
    from sensor.daq import Daq
    from sensor.opponent import CHANNEL_ANGLES_DEG, opponent_output
    from skysim.geometry import wrap_axial_deg
    n = cfg.three_pair_trials
    sky = _sky(clear, field, n)
    heading = rng.uniform(0.0, 360.0, n)
    el, az = np.full(n, cfg.sun_elevation_deg), np.full(n, cfg.sun_azimuth_deg)
    f = sky.field(90.0, heading, el, az)     # the zenith seen with the sensor's meridian
    # phi: heading minus the azimuth perpendicular to the zenith E-vector (sensor.opponent)
    e = f.e_vector
    e_az = np.degrees(np.arctan2(e[..., 0], e[..., 1]))
    phi = wrap_axial_deg(heading - e_az - 90.0)
    u = opponent_output(phi[:, None], f.dop[:, None], CHANNEL_ANGLES_DEG, 0.0, 0.0, 0.0)
    u = u + cfg.noise_V * rng.standard_normal(u.shape)
    u, _ = Daq(16, 10.0).acquire(u)
    phi_est, dop_est = solve_pair(u, (1, 2))
    true_phi = wrap_axial_deg(heading - cfg.sun_azimuth_deg)
    err = _heading_error(phi_est, true_phi, 180.0)
    return {"U1-U2": err, "U1-U2, DoP >= 0.05": np.where(dop_est >= MIN_DOP, err, np.nan),
            "_dop": f.dop}


# --------------------------------------------------------------------------- ring
def ring_errors(clear, field, cfg: Config, rng: np.random.Generator) -> dict:
    """Heading errors [deg] (ring_trials,) per method, NaN where a method gives none."""
    from calibration.installation import (UnitPolarization, e_vectors_sensor,
                                          polarization_from_photodiodes, sun_vector_sensor)
    from sensor.compound_eye import FOUR_ANGLES_DEG, body_attitude, ring_configuration
    from skysim.geometry import direction_vector
    n = cfg.ring_trials
    ring = ring_configuration(8, 45.0, FOUR_ANGLES_DEG)
    angles = np.asarray(FOUR_ANGLES_DEG)
    yaw = rng.uniform(0.0, 360.0, n)
    sun = np.broadcast_to(direction_vector(cfg.sun_elevation_deg, cfg.sun_azimuth_deg), (n, 3))
    obs = ring.observe(_sky(clear, field, n), body_attitude(yaw), sun)
    chi = np.radians(obs.aop_unit_deg[..., None] - angles)
    mean = cfg.ring_counts_per_radiance * obs.radiance[..., None] * (
        1.0 + obs.dop[..., None] * np.cos(2.0 * chi))
    full = 2.0 ** 16 - 1.0
    counts = np.clip(np.round(mean + cfg.ring_noise_counts * rng.standard_normal(mean.shape)),
                     0.0, full)
    usable = np.all(counts < full, axis=-1)                     # no saturated photodiode
    aop, dop = polarization_from_photodiodes(counts, angles, "stokes")
    out = {}
    for method, weights in (("DoP-weighted", np.abs(dop)), ("equal weights", np.ones_like(dop)),
                            ("DoP >= 0.05", (np.abs(dop) >= MIN_DOP).astype(float))):
        w = np.where(usable, weights, 0.0)
        pol = UnitPolarization(np.where(w > 0, aop, np.nan), dop, w > 0)
        sun_s, _ = sun_vector_sensor(e_vectors_sensor(pol, ring), w)
        body_az = np.degrees(np.arctan2(sun_s[:, 0], sun_s[:, 1]))
        err = _heading_error(cfg.sun_azimuth_deg - body_az, yaw)
        out[method] = np.where(np.sum(w > 0, axis=1) >= 2, err, np.nan)
    return out


# --------------------------------------------------------------------------- camera
def camera_errors(clear, field, cfg: Config, rng: np.random.Generator, cam=None) -> dict:
    """Heading errors [deg] (camera_trials,) per method of one image per trial, NaN where the
    image has too few usable pixels."""
    from calibration.camera_heading import DEFAULT_DEMOSAIC, heading_from_image
    from calibration.exceptions import TooFewSamplesError
    from sensor.camera import PolarizationCamera, camera_attitude, camera_stokes
    cam = cam or PolarizationCamera.fisheye(cfg.camera_px, cfg.camera_px)
    sky = _sky(clear, field, 1)
    out = {m: np.full(cfg.camera_trials, np.nan) for m in METHODS["camera"]}
    for k, yaw in enumerate(rng.uniform(0.0, 360.0, cfg.camera_trials)):  # one image each
        scene = cam.scene(sky.at(k * TRIAL_SPACING_S), camera_attitude(yaw),
                          cfg.sun_elevation_deg, cfg.sun_azimuth_deg)
        t = cam.auto_exposure_s(scene)
        st = camera_stokes(cam, cam.capture(scene, t, rng), t, valid=scene.valid,
                           method=DEFAULT_DEMOSAIC)
        for method, loss in zip(METHODS["camera"], ("cauchy", "linear")):
            try:
                h = heading_from_image(st, cam.lens, cfg.sun_elevation_deg,
                                       cfg.sun_azimuth_deg, min_dolp=MIN_DOP, loss=loss)
            except TooFewSamplesError:
                continue
            out[method][k] = _heading_error(h.heading_deg, yaw)
    return out


# --------------------------------------------------------------------------- the study
def _rows(sensor: str, cover: float, tau: float, errors: dict) -> list[dict]:
    rows = []
    for method in METHODS[sensor]:
        e = errors[method]
        ok = e[np.isfinite(e)]
        rows.append({"sensor": sensor, "method": method, "cover": cover, "tau": tau,
                     "n": int(e.size), "failures": int(e.size - ok.size),
                     "median_abs_error_deg": float(np.median(np.abs(ok))) if ok.size else np.nan,
                     "rms_error_deg": float(np.sqrt(np.mean(ok ** 2))) if ok.size else np.nan,
                     "p90_abs_error_deg": float(np.percentile(np.abs(ok), 90))
                     if ok.size else np.nan})
    return rows


def run(*, quick: bool = False, trials: int | None = None, seed: int = DEFAULT_SEED,
        out=None, cfg: Config | None = None) -> dict:
    """The study of the module docstring; writes the outputs to ``out`` if given and returns
    ``{"table", "summary"}``. ``trials``: camera images per cover and thickness, the other
    sensors' trials scaled in proportion (the camera takes most of the time)."""
    t0 = time.perf_counter()
    cfg = cfg or (QUICK if quick else Config())
    if trials:
        k = trials / cfg.camera_trials
        cfg = replace(cfg, three_pair_trials=max(1, round(cfg.three_pair_trials * k)),
                      ring_trials=max(1, round(cfg.ring_trials * k)), camera_trials=trials)
    clear = clear_sky()
    fields = cloud_fields(cfg, seed)
    rngs = dict(zip(("three-pair", "ring", "camera"),
                    (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))))
    rows, zenith_dop, timing = [], {}, dict.fromkeys(METHODS, 0.0)
    for (cover, tau), field in fields.items():
        for sensor, fn in (("three-pair", three_pair_errors), ("ring", ring_errors),
                           ("camera", camera_errors)):
            t = time.perf_counter()
            errors = fn(clear, field, cfg, rngs[sensor])
            timing[sensor] += time.perf_counter() - t
            rows += _rows(sensor, cover, tau, errors)
            if sensor == "three-pair":
                zenith_dop[(cover, tau)] = float(np.median(errors["_dop"]))
    table = pd.DataFrame(rows)
    table["zenith_dop_median"] = [zenith_dop[(c, t)] for c, t in zip(table.cover, table.tau)]
    summary = _summary(table, cfg, seed, timing, time.perf_counter() - t0)
    result = {"table": table, "summary": summary}
    if out is not None:
        _write(Path(out), result, cfg, clear, fields)
    return result


def _summary(table, cfg, seed, timing, elapsed) -> dict:
    worst = max(cfg.covers)
    per = {}
    for (sensor, method), g in table.groupby(["sensor", "method"], sort=False):
        per[f"{sensor} {method}"] = {
            f"tau {t:g}": {f"cover {c:g}": {"median_abs_error_deg": r.median_abs_error_deg,
                                            "rms_error_deg": r.rms_error_deg,
                                            "failures": int(r.failures), "n": int(r.n)}
                           for c, r in zip(h.cover, h.itertuples())}
            for t, h in g.groupby("tau")}
    return {"schema": "skysim.cloudy_compass/1", "seed": seed, "config": asdict(cfg),
            "sky": clear_sky().describe(), "most_cloudy_cover": worst,
            "trial_spacing_km": TRIAL_SPACING_S * TRIAL_WIND_M_S / 1000.0,
            "methods": per, "timing_s": timing, "elapsed_s": elapsed}


def format_table(table: pd.DataFrame, value: str = "median_abs_error_deg") -> str:
    """Markdown: ``value`` per sensor and method (rows) and cover and thickness (columns);
    failures (headings not given) in brackets."""
    keys = sorted(set(zip(table.tau, table.cover)))
    head = " | ".join(f"τ {t:g}, cover {c:g}" for t, c in keys)
    lines = [f"| sensor | method | {head} |", "|---|---|" + "---|" * len(keys)]
    for (sensor, method), g in table.groupby(["sensor", "method"], sort=False):
        cells = []
        for t, c in keys:
            r = g[(g.tau == t) & (g.cover == c)].iloc[0]
            fail = f" ({r.failures}/{r.n} none)" if r.failures else ""
            cells.append(f"{r[value]:.3g}{fail}")
        lines.append(f"| {sensor} | {method} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _write(out: Path, result: dict, cfg: Config, clear, fields) -> None:
    out.mkdir(parents=True, exist_ok=True)
    table = result["table"]
    atomic_write(out / "table.csv", lambda p: table.to_csv(p, index=False, float_format="%.6g"))
    text = ("# Cloudy compass\n\nHeading error [deg] by sensor and method against cloud cover "
            f"and optical thickness τ (550 nm), sun at {cfg.sun_elevation_deg:g}° elevation; in "
            "brackets the trials that gave no heading.\n\n## Median absolute error [deg]\n\n"
            + format_table(table) + "\n\n## RMS error [deg]\n\n"
            + format_table(table, "rms_error_deg") + "\n")
    atomic_write(out / "table.md", lambda p: p.write_text(text))
    write_json_atomic(out / "summary.json", result["summary"])
    _plot(table, out)
    _example(out, cfg, clear, fields)


SENSOR_TITLES = {"three-pair": "three-pair sensor at the zenith",
                 "ring": "ring of 8 photodiode units", "camera": "fisheye polarization camera"}
METHOD_LABELS = {"U1-U2": "units 1 and 2, every reading", "U1-U2, DoP >= 0.05":
                 "units 1 and 2, DoP ≥ 0.05", "DoP-weighted": "units weighted by DoP",
                 "equal weights": "units weighted equally",
                 "DoP >= 0.05": "units of DoP ≥ 0.05 only", "robust": "robust fit (Cauchy)",
                 "least squares": "least squares"}
"""What the figure calls the sensors and the methods of :data:`METHODS`."""


def _plot(table: pd.DataFrame, out: Path) -> None:
    """Median heading error against cover, one panel per sensor: the line style is the
    method (legend in the panel), the colour the clouds' optical thickness (one legend for
    the figure)."""
    from matplotlib.lines import Line2D
    plt = pyplot()
    sensors = list(METHODS)
    fig, axes = plt.subplots(1, len(sensors), figsize=(4.2 * len(sensors), 4.4), sharey=True,
                             constrained_layout=True)
    styles = ["-", "--", ":"]
    taus = sorted(table.tau.unique())
    cmap = plt.get_cmap("viridis")
    colours = {tau: cmap(j / max(1, len(taus) - 1) * 0.8) for j, tau in enumerate(taus)}
    for ax, sensor in zip(axes, sensors):
        for i, method in enumerate(METHODS[sensor]):
            for tau in taus:
                g = table[(table.sensor == sensor) & (table.method == method)
                          & (table.tau == tau)].sort_values("cover")
                ax.semilogy(g.cover, g.median_abs_error_deg, linestyle=styles[i % 3],
                            marker="o", ms=3, color=colours[tau])
        ax.set(title=SENSOR_TITLES[sensor], xlabel="cloud cover [fraction of the sky]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend([Line2D([], [], color="0.2", linestyle=styles[i % 3])
                   for i in range(len(METHODS[sensor]))],
                  [METHOD_LABELS[m] for m in METHODS[sensor]], fontsize=7.5,
                  loc="upper left", handlelength=3.5, title="method", title_fontsize=7.5)
    axes[0].set_ylabel("median absolute heading error [deg]")
    lo, hi = axes[0].get_ylim()
    axes[0].set_ylim(lo, hi * (hi / lo) ** 0.3)  # room for the method legends above the lines
    fig.legend([Line2D([], [], color=colours[tau], marker="o", ms=3) for tau in taus],
               [f"{tau:g}" for tau in taus], title="cloud optical thickness", loc="outside "
               "lower center", ncol=len(taus), fontsize=8, title_fontsize=8)
    save_png(fig, out / "heading_vs_cover.png")


def _example(out: Path, cfg: Config, clear, fields) -> None:
    """DoP, AoP and radiance of the sky at the middle cover and the thickest clouds."""
    from skysim.partly_cloudy import PartlyCloudySky

    from skysim.geometry import sky_grid
    from experiments.plotting.polar_maps import plot_polar_maps
    cover = sorted(cfg.covers)[len(cfg.covers) // 2]
    tau = max(cfg.taus)
    sky = PartlyCloudySky(clear, fields[(cover, tau)])
    el, az = sky_grid(1.5)
    f = sky.field(el, az, cfg.sun_elevation_deg, cfg.sun_azimuth_deg)
    sun = (cfg.sun_elevation_deg, cfg.sun_azimuth_deg)
    plot_polar_maps(el, az, {"DoP": (f.dop, "viridis", (0, 1)),
                             "AoP [deg]": (f.aop_deg, "twilight", (-90, 90)),
                             "log10 I (flux pi)": (np.log10(f.I), "magma", None)},
                    out / "example_sky.png", sun=sun,
                    title=f"multiple-scattering sky at 550 nm behind clouds of cover {cover:g} "
                          f"and optical thickness {tau:g}; sun at {sun[0]:g} deg elevation")


# --------------------------------------------------------------------------- command line
def format_summary(table: pd.DataFrame) -> str:
    lines = []
    worst = table.cover.max()
    for (sensor, method), g in table.groupby(["sensor", "method"], sort=False):
        clear = g[g.cover == 0.0].median_abs_error_deg.median()
        cells = ", ".join(f"τ {r.tau:g}: {r.median_abs_error_deg:.3g} deg"
                          + (f" ({r.failures}/{r.n} none)" if r.failures else "")
                          for r in g[g.cover == worst].itertuples())
        lines.append(f"{sensor + ' ' + method:34s} median |error| clear {clear:.3g} deg; "
                     f"cover {worst:g}: {cells}")
    return "\n".join(lines)


def register_reproduce(targets: dict) -> None:
    from experiments.workflows.progress import reproduction
    targets["cloudy-compass"] = reproduction(
        "cloudy-compass", "Cloudy compass — heading error vs cloud cover and optical thickness",
        run, lambda result: format_summary(result["table"]),
        ("table.md", "table.csv", "summary.json", "heading_vs_cover.png", "example_sky.png"))
