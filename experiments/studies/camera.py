"""Polarization-camera commands: simulate a raw fisheye image, estimate the heading from one,
and the camera-compass reproduction (heading error vs sun elevation, exposure, extinction
ratio, calibration and sky model).

Commands: ``skysim camera`` (raw 16-bit TIFF or PNG + ``skysim.dofp/1`` sidecar, optional
DoLP/AoP figure), ``skysim camera-heading`` (heading from a raw image and its sidecar) and
``skysim reproduce camera``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from experiments.workflows.options import (DefaultsHelpFormatter, aware_time,
                                           data_file_and_sidecars, existing_file, float_in,
                                           int_at_least, int_in, output_file, positive_float,
                                           refuse_replacing_inputs, seed, with_sidecar)

__all__ = ["DEFAULT_SEED", "heading_trials", "run", "stokes_figure", "register",
           "register_reproduce"]

DEFAULT_SEED = 2016

SKY_DMAX = 0.75
"""d_max of the single-scattering sky of the reproduction (a clear day's maximum DoLP)."""

FAULTS = {"angle_std_deg": 1.0, "mosaic_rotation_deg": 2.0, "extinction_ratio": 30.0,
          "extinction_ratio_rel_std": 0.2, "gain_std": 0.03}
"""Per-pixel errors of the "real" camera of the reproduction (with vignetting, exit pupil at
1.5 focal lengths)."""

CAL_ANGLES_DEG = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)

# Peak memory per pixel [bytes] of the commands, checked before the work (SKYSIM_MEMORY_LIMIT_MB):
# the numpy peaks traced on 1024x1024 images (rayleigh 123, rayleigh with every error 138,
# berry 288, multiple 376; heading of a 2448x2048 image: centred 106, bilinear 281,
# superpixel below 155; a figure adds about 310 to the camera's and 40 to the heading's),
# rounded up by about 10 % for the interpreter's own share
CAMERA_BYTES_PER_PIXEL = {"rayleigh": 160, "berry": 320, "multiple": 420}
CAMERA_FIGURE_BYTES_PER_PIXEL = 340
CLOUDS_BYTES_PER_PIXEL = 300
"""Added by --clouds (traced on 512x512: rayleigh 300 -> 408, berry 241 -> 374; a cloudy
rayleigh sky leaves the float32 path for float64, hence more than the difference)."""
HEADING_BYTES_PER_PIXEL = {"centred": 130, "superpixel": 175, "bilinear": 320}
HEADING_FIGURE_BYTES_PER_PIXEL = 50
CAMERA_SECONDS_PER_PIXEL = {"rayleigh": 1.0e-6, "berry": 1.6e-6, "multiple": 1.0e-6}
CAMERA_FIGURE_SECONDS_PER_PIXEL = 2.4e-6
CAMERA_ENGINE_SECONDS = {"multiple": 10.0}
"""Time of ``skysim camera`` [s]: per pixel of the image (measured on a shared 2-core machine
from 64x64 to 1024x1024 and 2048x2048: rayleigh 0.5, berry 0.8, multiple 0.3 us; the figure
1.2 us; doubled) and, for the multiple-scattering sky, its engine runs (7.4 s measured at
64x64, rounded up)."""
MEMORY_PER_TRIAL_BYTES = 10_000
"""Memory of ``skysim reproduce camera`` per trial [bytes] (the images are made one at a
time): the full run's 60 conditions each keep a yaw (8 B) and two Python floats in lists
(about 64 B) per trial, 4.3 kB; rounded up for the table and its text."""


# --- shared helpers ---------------------------------------------------------------------

def _camera(size: int, *, faults: dict | None = None, rng=None, **sensor):
    from sensor.camera import PolarizationCamera
    cam = PolarizationCamera.fisheye(size, size, **sensor)
    if faults is None:
        return cam
    return PolarizationCamera(cam.lens, cam.sensor.with_random_errors(rng, **faults),
                              cam.photoelectrons_per_s, 1.5 * cam.lens.focal_px)


def _calibrate(cam, rng, n_frames: int = 8):
    from calibration.dofp_calibration import calibrate_dofp
    t = 0.6 * cam.sensor.full_well_e / cam.photoelectrons_per_s
    flats, dark = cam.calibration_frames(CAL_ANGLES_DEG, 1.0, t, n_frames, rng)
    return calibrate_dofp(flats, dark, CAL_ANGLES_DEG, saturation_dn=cam.sensor.max_dn), t


def _calibrated_inputs(cam, cal, t_cal, t):
    """Analysis vectors and dark frame of a calibration applied at exposure ``t``."""
    s = cam.sensor
    dark = cal.dark_dn + s.dark_current_e_s * (t - t_cal) / s.e_per_dn
    return cal.analysis_dn * (t / t_cal), dark


def stokes_figure(stokes, lens, attitude, path, title: str = ""):
    """DoLP, AoP in the image and AoP (local meridian) images of a Stokes image, as PNG,
    laid out as the sensor records it (row 0 at the top)."""
    from sensor.camera import local_meridian_aop

    from experiments.plotting.figures import pyplot, save_png
    plt = pyplot()
    _, _, aop_m = local_meridian_aop(stokes, lens, attitude)
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    panels = ((stokes.dolp, "DoLP", "viridis", (0, 1)),
              (stokes.aop_camera_deg, "AoP in the image, ccw from right [deg]", "twilight",
               (-90, 90)),
              (aop_m, "AoP, local meridian [deg]", "twilight", (-90, 90)))
    for ax, (img, label, cmap, (lo, hi)) in zip(axes, panels):
        im = ax.imshow(np.where(stokes.valid, img, np.nan), cmap=cmap, vmin=lo, vmax=hi,
                       interpolation="nearest")
        ax.set_title(label)
        ax.set_axis_off()
        fig.colorbar(im, ax=ax, fraction=0.046)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_png(fig, path)


# --- skysim camera ----------------------------------------------------------------------

def _make_sky(args):
    from skysim.sky import make_sky

    from experiments.workflows.cloud_options import with_clouds
    if args.sky == "multiple":
        return with_clouds(make_sky("multiple", tau=args.tau, albedo=args.albedo), args)
    if args.sky == "rayleigh" and args.clouds is None:
        # float32 throughout: within 2e-6 of float64 (docs/camera.md)
        return make_sky("rayleigh", dmax=args.dmax, dtype="float32")
    return with_clouds(make_sky(args.sky, dmax=args.dmax), args)


def _camera_command(args) -> int:
    from sensor.camera import PolarizationCamera, camera_attitude, camera_stokes
    from sensor.camera.files import require_image_codec, write_raw
    from skysim.resources import check_memory
    from skysim.sun import sun_position

    refuse_replacing_inputs(with_sidecar("--out", args.out) + [("--figure", args.figure)])
    require_image_codec(args.out)  # before the work, not after it
    check_memory(args.width * args.height * (CAMERA_BYTES_PER_PIXEL[args.sky]
                                             + (CLOUDS_BYTES_PER_PIXEL if args.clouds else 0)
                                             + (CAMERA_FIGURE_BYTES_PER_PIXEL if args.figure
                                                else 0)),
                 f"a {args.width}x{args.height} camera image ({args.sky} sky"
                 f"{', partly cloudy' if args.clouds else ''}"
                 f"{', with --figure' if args.figure else ''})",
                 "use a smaller --width/--height" + (" or leave out --figure" if args.figure
                                                     else ""))
    from experiments.workflows.progress import check_duration
    n_px = args.width * args.height
    check_duration(CAMERA_ENGINE_SECONDS.get(args.sky, 0.0) + n_px * (
        CAMERA_SECONDS_PER_PIXEL[args.sky] + (CAMERA_FIGURE_SECONDS_PER_PIXEL if args.figure
                                              else 0.0)),
        f"skysim camera: a {args.width}x{args.height} image", "a smaller --width/--height "
        "makes it shorter")
    sun = sun_position([args.time], args.lat, args.lon, args.alt).iloc[0]
    sun_el, sun_az = float(sun["elevation_deg"]), float(sun["azimuth_deg"])
    rng = np.random.default_rng(args.seed)
    cam = PolarizationCamera.fisheye(args.width, args.height, fov_deg=args.fov, model=args.lens,
                                     adc_bits=args.adc_bits, crosstalk=args.crosstalk)
    faults = {"angle_std_deg": args.angle_error_std, "mosaic_rotation_deg":
              args.mosaic_rotation, "extinction_ratio": args.extinction_ratio}
    if args.angle_error_std or args.mosaic_rotation or np.isfinite(args.extinction_ratio):
        cam = PolarizationCamera(cam.lens, cam.sensor.with_random_errors(rng, **faults),
                                 cam.photoelectrons_per_s, cam.exit_pupil_px)
    att = camera_attitude(args.yaw, args.pitch, args.roll)
    sky = _make_sky(args)
    scene = cam.scene(sky, att, sun_el, sun_az)
    exposure = args.exposure or cam.auto_exposure_s(scene)
    raw = cam.capture(scene, exposure, rng)
    from skysim import __version__
    doc = {"site": {"latitude_deg": args.lat, "longitude_deg": args.lon, "altitude_m": args.alt},
           "time": args.time.isoformat(),
           "attitude": {"yaw_deg": args.yaw, "pitch_deg": args.pitch, "roll_deg": args.roll,
                        "yaw_known": True},
           **cam.describe(), "exposure": {"exposure_s": exposure},
           "generator": {"package": "skysim", "version": __version__, "sky": sky.describe(),
                         "sun_elevation_deg": sun_el, "sun_azimuth_deg": sun_az,
                         "seed": args.seed}}
    write_raw(args.out, raw, doc)
    print(f"wrote {args.out} ({args.width}x{args.height}, {cam.sensor.adc_bits}-bit, exposure "
          f"{exposure * 1e3:.3f} ms, sun at {sun_el:.2f} deg elevation, {sun_az:.2f} deg "
          f"azimuth; {int((raw >= cam.sensor.max_dn).sum())} saturated pixels)")
    if args.figure:
        st = camera_stokes(cam, raw, exposure, valid=scene.valid)
        clouds = f", clouds {args.clouds[0]:g} at tau {args.clouds[1]:g}" if args.clouds else ""
        stokes_figure(st, cam.lens, att, args.figure, f"{args.sky} sky{clouds}, "
                      f"sun {sun_el:.1f} deg")
        print(f"wrote {args.figure}")
    return 0


def _heading_command(args) -> int:
    from calibration.camera_heading import heading_from_image
    from sensor.camera import camera_attitude, camera_stokes
    from sensor.camera.files import camera_from_sidecar, check_sidecar, read_raw
    from skysim.io import find_sidecar
    from skysim.resources import check_memory
    from skysim.sun import sun_position

    refuse_replacing_inputs([("--figure", args.figure)],
                            [("image", p) for p in data_file_and_sidecars(args.image)])
    raw, doc = read_raw(args.image, flip=args.flip, rotate_deg=args.rotate)
    check_sidecar(doc, find_sidecar(Path(args.image)))
    check_memory(raw.size * (HEADING_BYTES_PER_PIXEL[args.method]
                             + (HEADING_FIGURE_BYTES_PER_PIXEL if args.figure else 0)),
                 f"the heading of a {raw.shape[1]}x{raw.shape[0]} image ({args.method} "
                 "demosaicing)", "use --method centred or superpixel, or leave out --figure"
                 if args.method == "bilinear" else "leave out --figure or crop the image")
    cam = camera_from_sidecar(doc)
    site, att = doc["site"], doc["attitude"]
    sun = sun_position([aware_time(doc["time"])], site["latitude_deg"], site["longitude_deg"],
                       site.get("altitude_m", 0.0)).iloc[0]
    sun_el, sun_az = float(sun["elevation_deg"]), float(sun["azimuth_deg"])
    # pixels that can see the sky: in the image circle and above the horizon for this tilt
    # (the heading does not change the horizon of a camera whose tilt is known)
    pitch, roll = att.get("pitch_deg", 0.0), att.get("roll_deg", 0.0)
    valid = cam.sky_pixels(camera_attitude(0.0, pitch, roll))
    st = camera_stokes(cam, raw, doc["exposure"]["exposure_s"], valid=valid, method=args.method)
    h = heading_from_image(st, cam.lens, sun_el, sun_az, pitch_deg=pitch, roll_deg=roll,
                           min_dolp=args.min_dolp)
    print(f"heading {h.heading_deg:.3f} deg ± {h.sigma_deg:.3f} (1σ, noise) from {h.n_used} "
          f"samples ({h.n_rejected} down-weighted as outliers); sun {sun_el:.2f} deg elevation")
    if att.get("yaw_known", False):
        err = (h.heading_deg - att["yaw_deg"] + 180.0) % 360.0 - 180.0
        print(f"recorded yaw {att['yaw_deg']:.3f} deg: error {err:+.3f} deg")
    if h.ambiguity_ratio < 2.0:
        print("warning: sun near the horizon, the heading 180 deg away fits almost as well "
              f"(cost ratio {h.ambiguity_ratio:.2f})")
    if args.figure:
        stokes_figure(st, cam.lens, camera_attitude(h.heading_deg, pitch, roll), args.figure)
        print(f"wrote {args.figure}")
    return 0


def register(sub) -> None:
    from experiments.workflows.cloud_options import add_cloud_options
    p = sub.add_parser("camera", help="simulate a raw fisheye polarization-camera image "
                       "(16-bit TIFF or PNG + sidecar)", formatter_class=DefaultsHelpFormatter,
                       description="Image the sky with a division-of-focal-plane polarization "
                                   "camera (2x2 micro-polarizer mosaic behind a fisheye lens) "
                                   "and write the raw mosaic with a skysim.dofp/1 sidecar.")
    p.add_argument("--lat", type=float_in(-90, 90), required=True, help="latitude [deg, north +]")
    p.add_argument("--lon", type=float_in(-180, 180), required=True,
                   help="longitude [deg, east +]")
    p.add_argument("--alt", type=float_in(-500, 9000, unit="m"), default=0.0,
                   help="altitude [m]")
    p.add_argument("--time", type=aware_time, required=True,
                   help="exposure time, ISO 8601 with UTC offset")
    p.add_argument("--out", type=output_file(".tif", ".tiff", ".png"), required=True,
                   help="raw image, 16-bit TIFF (.tif, .tiff) or PNG (.png); the sidecar is "
                        "<name>.json")
    p.add_argument("--yaw", type=float_in(unit="deg"), default=0.0,
                   help="heading of the image top [deg]")
    p.add_argument("--pitch", type=float_in(unit="deg"), default=0.0,
                   help="camera pitch [deg]")
    p.add_argument("--roll", type=float_in(unit="deg"), default=0.0,
                   help="camera roll [deg]")
    p.add_argument("--width", type=int_at_least(2), default=512, help="pixels (even)")
    p.add_argument("--height", type=int_at_least(2), default=512, help="pixels (even)")
    p.add_argument("--lens", choices=("equidistant", "equisolid"), default="equidistant",
                   help="fisheye projection: equidistant (r = f theta) or equisolid "
                        "(r = 2 f sin(theta / 2))")
    p.add_argument("--fov", type=float_in(0, 360, low_open=True, high_open=True), default=180.0,
                   help="field of view [deg]")
    p.add_argument("--exposure", type=positive_float, default=None,
                   help="exposure [s] (default: the 99th percentile of the sky at 60%% of "
                        "the full well)")
    p.add_argument("--adc-bits", type=int_in(8, 16), default=12, help="ADC bits, 8-16")
    p.add_argument("--extinction-ratio", type=float_in(1, low_open=True), default=np.inf,
                   help="polarizer extinction ratio")
    p.add_argument("--crosstalk", type=float_in(0, 0.25, high_open=True), default=0.0,
                   help="share of each of its four edge neighbours' photoelectrons a pixel "
                        "receives (it keeps 1 - 4x its own)")
    p.add_argument("--angle-error-std", type=float_in(0), default=0.0,
                   help="per-pixel polarizer angle error, standard deviation [deg]")
    p.add_argument("--mosaic-rotation", type=float_in(unit="deg"), default=0.0,
                   help="rotation of the whole polarizer array [deg]")
    p.add_argument("--sky", choices=("rayleigh", "multiple", "berry"), default="rayleigh",
                   help="sky model: single-scattering Rayleigh, multiple scattering (sasktran2) "
                        "or the Berry neutral-point sky")
    p.add_argument("--dmax", type=float_in(0, 1, low_open=True), default=SKY_DMAX,
                   help="rayleigh/berry: maximum degree of polarization (skysim sky: 1)")
    p.add_argument("--tau", type=positive_float, default=0.1,
                   help="multiple: Rayleigh optical thickness")
    p.add_argument("--albedo", type=float_in(0, 1), default=0.1, help="multiple: ground albedo")
    add_cloud_options(p)
    p.add_argument("--seed", type=seed, default=0, help="random seed of the noise")
    p.add_argument("--figure", type=output_file(".png"), default=None,
                   help="also write DoLP/AoP images (.png)")
    p.set_defaults(func=_camera_command)

    h = sub.add_parser("camera-heading", help="heading from one raw polarization-camera image",
                       formatter_class=DefaultsHelpFormatter,
                       description="Estimate the camera's heading from the AoP pattern of one "
                                   "raw image (E-vector perpendicular to the sun), using the "
                                   "site, time and tilt of its skysim.dofp/1 sidecar.")
    h.add_argument("image", type=existing_file,
                   help="raw image (.tif, .tiff, .png) with its sidecar")
    # literals: sensor.camera.files.FLIPS and ROTATIONS_DEG (tested equal)
    h.add_argument("--flip", choices=("none", "horizontal", "vertical"), default="none",
                   help="the camera's readout flips the image (horizontal: left to right, "
                        "vertical: top to bottom); undone before --rotate is")
    h.add_argument("--rotate", type=int, choices=(0, 90, 180, 270), default=0,
                   help="the camera's readout rotates the image by this many degrees "
                        "counter-clockwise as displayed (after its flip); undone first")
    # literals: the command line does not import the camera (tested equal to
    # sensor.camera.DEMOSAIC_METHODS and calibration.camera_heading.DEFAULT_DEMOSAIC)
    h.add_argument("--method", choices=("bilinear", "centred", "superpixel"), default="centred",
                   help="demosaicing (centred: half resolution, channels met at each "
                        "super-pixel centre)")
    h.add_argument("--min-dolp", type=float_in(0, 1, high_open=True), default=0.05,
                   help="samples of lower DoLP are left out")
    h.add_argument("--figure", type=output_file(".png"), default=None,
                   help="also write DoLP/AoP images (.png)")
    h.set_defaults(func=_heading_command)


# --- skysim reproduce camera ------------------------------------------------------------

SUN_AZIMUTH_DEG = 135.0


def heading_trials(cam, sky, sun_elevation_deg: float, yaws_deg, rng, *, fill: float = 0.6,
                   calibration=None, method: str = "centred"):
    """Heading errors and reported standard errors [deg] of one image per yaw [deg] (each
    trial is a whole image, vectorised over its pixels). ``calibration``: ``(cal, t_cal)``
    from the flat-field calibration, else the nominal camera model. ``method``: demosaicing
    (default :data:`calibration.camera_heading.DEFAULT_DEMOSAIC`)."""
    from calibration.camera_heading import heading_from_image
    from sensor.camera import camera_attitude, camera_stokes
    errors, sigmas = [], []
    for yaw in yaws_deg:  # one image per trial
        scene = cam.scene(sky, camera_attitude(yaw), sun_elevation_deg, SUN_AZIMUTH_DEG)
        t = fill / 0.6 * cam.auto_exposure_s(scene)
        raw = cam.capture(scene, t, rng)
        extra = {}
        if calibration is not None:
            extra = dict(zip(("analysis_dn", "dark_dn"), _calibrated_inputs(cam, *calibration,
                                                                            t)))
        st = camera_stokes(cam, raw, t, valid=scene.valid, method=method, **extra)
        h = heading_from_image(st, cam.lens, sun_elevation_deg, SUN_AZIMUTH_DEG)
        errors.append((h.heading_deg - yaw + 180.0) % 360.0 - 180.0)
        sigmas.append(h.sigma_deg)
    return np.array(errors), np.array(sigmas)


def _row(study, sky_name, camera, sun_el, fill, er, errors, sigmas, crosstalk=0.0):
    return {"study": study, "sky": sky_name, "camera": camera, "sun_elevation_deg": sun_el,
            "fill": fill, "extinction_ratio": er, "crosstalk": crosstalk, "trials": len(errors),
            "rms_error_deg": float(np.sqrt(np.mean(errors ** 2))),
            "mean_error_deg": float(np.mean(errors)),
            "max_abs_error_deg": float(np.max(np.abs(errors))),
            "mean_sigma_deg": float(np.mean(sigmas))}


def run(*, quick: bool = False, trials: int | None = None, seed: int = DEFAULT_SEED,
        out: Path = Path("results/camera")) -> dict:
    """The camera-compass study; writes ``table.md``, ``table.csv``, ``summary.json`` and
    figures under ``out`` and returns ``{"table": DataFrame, "summary": dict}``."""
    import pandas as pd

    from skysim.multiple import MultipleScatteringSky
    from skysim.sky import RayleighSky

    from calibration.camera_heading import DEFAULT_DEMOSAIC

    start = time.perf_counter()
    size = 128 if quick else 256
    trials = trials or (3 if quick else 10)
    elevations = (10.0, 40.0, 70.0) if quick else (5.0, 15.0, 30.0, 45.0, 60.0, 75.0)
    rng = np.random.default_rng(seed)
    skies = {"rayleigh": RayleighSky(SKY_DMAX),
             "multiple": MultipleScatteringSky(tau=0.1, albedo=0.1)}
    ideal = _camera(size)
    faulty = _camera(size, faults=FAULTS, rng=rng)
    cal = _calibrate(faulty, rng)
    cameras = {"ideal": (ideal, None), "uncalibrated": (faulty, None),
               "calibrated": (faulty, cal)}
    rows = []
    for sky_name, sky in skies.items():
        for cam_name, (cam, c) in cameras.items():
            for el in elevations:
                e, s = heading_trials(cam, sky, el, rng.uniform(0, 360, trials), rng,
                                      calibration=c)
                rows.append(_row("sun elevation", sky_name, cam_name, el, 0.6, np.inf, e, s))
    fills = (0.02, 0.1, 0.6) if quick else (0.01, 0.03, 0.1, 0.3, 0.6, 0.95)
    for fill in fills:
        e, s = heading_trials(ideal, skies["rayleigh"], 40.0, rng.uniform(0, 360, trials), rng,
                              fill=fill)
        rows.append(_row("exposure", "rayleigh", "ideal", 40.0, fill, np.inf, e, s))
    ratios = (5.0, 30.0, np.inf) if quick else (3.0, 10.0, 30.0, 100.0, np.inf)
    for er in ratios:
        faults = {"extinction_ratio": er, "extinction_ratio_rel_std": 0.2}
        cam = _camera(size, faults=faults, rng=rng)
        for cam_name, c in (("uncalibrated", None), ("calibrated", _calibrate(cam, rng))):
            e, s = heading_trials(cam, skies["rayleigh"], 40.0, rng.uniform(0, 360, trials),
                                  rng, calibration=c)
            rows.append(_row("extinction ratio", "rayleigh", cam_name, 40.0, 0.6, er, e, s))
    # crosstalk: ideal polarizers (it lowers the DoLP by 1 - 4c, not the AoP), and the faulty
    # camera calibrated (a flat field measures each pixel's analysis vector with the
    # neighbours' share in it)
    for c in ((0.01, 0.03) if quick else (0.005, 0.01, 0.02, 0.04)):
        for cam_name, cam in (("ideal", _camera(size, crosstalk=c)),
                              ("calibrated", _camera(size, faults=FAULTS, rng=rng,
                                                     crosstalk=c))):
            cal = _calibrate(cam, rng) if cam_name == "calibrated" else None
            e, s = heading_trials(cam, skies["rayleigh"], 40.0, rng.uniform(0, 360, trials),
                                  rng, calibration=cal)
            rows.append(_row("crosstalk", "rayleigh", cam_name, 40.0, 0.6, np.inf, e, s, c))
    table = pd.DataFrame(rows)
    summary = {"image_px": size, "trials_per_condition": trials, "seed": seed,
               "demosaicing": DEFAULT_DEMOSAIC, "sun_azimuth_deg": SUN_AZIMUTH_DEG,
               "rayleigh_dmax": SKY_DMAX, "multiple": skies["multiple"].describe(),
               "faulty_camera": FAULTS, "calibration_angles_deg": list(CAL_ANGLES_DEG),
               "elapsed_s": time.perf_counter() - start}
    _write_outputs(Path(out), table, summary, skies, ideal, size)
    summary["elapsed_s"] = time.perf_counter() - start
    return {"table": table, "summary": summary}


def format_table(table) -> str:
    """Markdown table of the study."""
    cols = ["study", "sky", "camera", "sun_elevation_deg", "fill", "extinction_ratio",
            "crosstalk", "trials", "rms_error_deg", "mean_error_deg", "mean_sigma_deg"]
    head = ("| study | sky | camera | sun el [deg] | fill | ER | crosstalk | trials | "
            "RMS error [deg] | mean error [deg] | mean 1σ [deg] |")
    lines = [head, "|" + "---|" * len(cols)]
    for r in table[cols].itertuples(index=False):
        lines.append(f"| {r.study} | {r.sky} | {r.camera} | {r.sun_elevation_deg:.0f} | "
                     f"{r.fill:.2f} | {r.extinction_ratio:g} | {r.crosstalk:g} | {r.trials} | "
                     f"{r.rms_error_deg:.4f} | {r.mean_error_deg:+.4f} | "
                     f"{r.mean_sigma_deg:.4f} |")
    return "\n".join(lines)


def _write_outputs(out: Path, table, summary, skies, cam, size) -> None:
    from sensor.camera import camera_attitude, camera_stokes
    from skysim.io import atomic_write, write_json_atomic

    from experiments.plotting.figures import pyplot, save_png
    out.mkdir(parents=True, exist_ok=True)
    (out / "figures").mkdir(exist_ok=True)
    atomic_write(out / "table.csv", lambda tmp: table.to_csv(tmp, index=False))
    md = ("Heading error of a fisheye polarization camera, one image per trial "
          f"({size}x{size} px, {summary['demosaicing']} demosaicing, sun azimuth "
          f"{SUN_AZIMUTH_DEG:g} deg, random yaw).\n\n" + format_table(table) + "\n")
    atomic_write(out / "table.md", lambda tmp: tmp.write_text(md))
    write_json_atomic(out / "summary.json", summary)
    plt = pyplot()
    el = table[table.study == "sun elevation"]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for (sky, camera), g in el.groupby(["sky", "camera"]):
        ax.semilogy(g.sun_elevation_deg, g.rms_error_deg, "o-" if sky == "rayleigh" else "s--",
                    label=f"{camera}, {sky} sky")
    ax.set_xlabel("sun elevation [deg]")
    ax.set_ylabel("heading RMS error [deg]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    save_png(fig, out / "figures" / "heading_vs_sun_elevation.png")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    ex = table[table.study == "exposure"]
    a1.loglog(ex.fill, ex.rms_error_deg, "o-", label="RMS error")
    a1.loglog(ex.fill, ex.mean_sigma_deg, "k:", label="mean reported 1σ")
    a1.set_xlabel("exposure: 99th percentile of the sky / full well")
    a1.set_ylabel("heading error [deg]")
    a1.legend(fontsize=8)
    er = table[table.study == "extinction ratio"]
    for camera, g in er.groupby("camera"):
        x = np.where(np.isfinite(g.extinction_ratio), g.extinction_ratio, 1e3)
        a2.loglog(x, g.rms_error_deg, "o-", label=camera)
    a2.set_xlabel("extinction ratio (1000 = ideal polarizer)")
    a2.set_ylabel("heading RMS error [deg]")
    a2.legend(fontsize=8)
    for a in (a1, a2):
        a.grid(alpha=0.3, which="both")
    fig.tight_layout()
    save_png(fig, out / "figures" / "heading_vs_exposure_and_extinction.png")
    rng = np.random.default_rng(0)
    for name, sky in skies.items():
        att = camera_attitude(0.0)
        scene = cam.scene(sky, att, 40.0, SUN_AZIMUTH_DEG)
        t = cam.auto_exposure_s(scene)
        st = camera_stokes(cam, cam.capture(scene, t, rng), t, valid=scene.valid)
        stokes_figure(st, cam.lens, att, out / "figures" / f"dolp_aop_{name}.png",
                      f"{name} sky, sun at 40 deg elevation, image top north")


def _reproduce(args) -> int:
    out = Path(args.out or "results/camera")
    result = run(quick=args.quick, trials=args.trials, seed=args.seed, out=out)
    s = result["summary"]
    print(f"Polarization-camera compass — {s['image_px']} px images, "
          f"{s['trials_per_condition']} trials per condition, seed {s['seed']}")
    print(format_table(result["table"]))
    print(f"{s['elapsed_s']:.1f} s; wrote {out}/table.md, table.csv, summary.json, figures")
    return 0


def register_reproduce(targets: dict) -> None:
    targets["camera"] = _reproduce
