"""skysim's polarization camera against pyskylumos's camera chain on the same scene.

pyskylumos (https://pypi.org/project/pyskylumos/) needs Python >= 3.12; skysim's suite may run
on an older Python, where ``tests/peer/test_pyskylumos.py`` skips. Run the comparison in an
environment that has both (skysim's source on the path and numpy, scipy, pyskylumos installed)::

    python3.12 -m venv /tmp/pysky && /tmp/pysky/bin/pip install pyskylumos scipy
    PYTHONPATH=. /tmp/pysky/bin/python tests/peer/compare_pyskylumos.py

What is compared (see docs/camera.md, "Peer comparison: pyskylumos"):

1. Lens: pyskylumos's ``equi_angle`` / ``equi_solid_angle`` pixel directions against skysim's
   equidistant / equisolid lens of the same focal length in pixels. pyskylumos's upward chart
   puts north at the image's right and east at its top (azimuth counter-clockwise in the
   image): a camera looking up with its top towards east, i.e. skysim's camera at yaw 90 deg,
   pixel for pixel, with the same sense of angles (counter-clockwise in the displayed image).
2. Sky: pyskylumos's ``RAYLEIGH`` DoP and AoP at those directions against skysim's
   ``RayleighSky(1.0)`` for the same sun (given explicitly to both). Radiance: pyskylumos
   scales by a CIE standard-sky luminance distribution, skysim's single-scattering sky by the
   Rayleigh phase function; compared as a ratio only.
3. Camera chain, noise free: both mosaics fed the same per-pixel radiance, DoP and AoP (the
   pyskylumos sky, pixel for pixel), ideal polarizers and polarizers of
   the same diattenuation (pyskylumos's ``extinction_ratio`` eps multiplies the DoP;
   skysim's extinction ratio ER gives eps = (ER - 1) / (ER + 1)), 12-bit ADC at the same
   counts per radiance; super-pixel DoLP and AoP compared.
4. Noise: pyskylumos draws multiplicative Gaussian noise (standard deviation proportional
   to the signal, ``1 / SNR``); skysim photon shot noise plus read noise (standard deviation
   ``sqrt(e + read^2)``): the standard deviations of flat fields at two levels.
"""

from __future__ import annotations

import numpy as np

N = 128
SUN = (35.0, 140.0)  # elevation, azimuth [deg]
BITS = 12


def _sky_coords(location, time, el_deg, az_deg):
    from astropy.coordinates import AltAz, SkyCoord
    from astropy.units import deg
    return SkyCoord(alt=el_deg * deg, az=az_deg * deg,
                    frame=AltAz(obstime=time, location=location))


def _engine(lens: str, f_px: float, extinction: float = 1.0, snr: float = 1e12, seed=0):
    from pyskylumos.engine import Engine
    return Engine(sensor_pixel_pitch_micrometers=3.45, lens_conjugation_type=lens,
                  number_pixels_vertical=N, number_pixels_horizontal=N,
                  lens_focal_length_micrometers=3.45 * f_px, polarizer_tolerance_radians=0.0,
                  extinction_ratio=extinction, auto_exposure_saturation_fraction=1.0,
                  adc_resolution_bits=BITS, multiplicative_noise_snr=snr,
                  wire_grid_orientations_slicing=_mosaic(), random_seed=seed)


def _mosaic():
    """skysim's default layout [[90, 45], [135, 0]] as pyskylumos's slicing patterns."""
    from pyskylumos.sensor.SlicingPattern import SlicingPattern
    return {90: SlicingPattern(0, 0, 2), 45: SlicingPattern(0, 1, 2),
            135: SlicingPattern(1, 0, 2), 0: SlicingPattern(1, 1, 2)}


def compare(lens_model: str = "equidistant") -> dict:
    """Run the comparison; returns the differences (see the module doc) as a flat dict."""
    from astropy.coordinates import EarthLocation
    from astropy.time import Time
    from astropy.units import m

    from sensor.camera import MosaicSensor, PolarizationCamera, Scene, camera_attitude, demosaic
    from skysim.geometry import direction_vector
    from skysim.sky import RayleighSky

    out = {}
    cam = PolarizationCamera.fisheye(N, N, model=lens_model, fov_deg=180.0)
    f_px = cam.lens.focal_px
    lens_name = {"equidistant": "equi_angle", "equisolid": "equi_solid_angle"}[lens_model]
    engine = _engine(lens_name, f_px)
    az_p, alt_p = engine.get_initial_azimuth_altitude()

    # 1. lens: pyskylumos pixel (r, c) sees what skysim's camera at yaw 90 sees at (r, c)
    att = camera_attitude(90.0)
    d_c, inside = cam.pixel_directions
    d_n = att.apply(np.nan_to_num(d_c).reshape(-1, 3)).reshape(N, N, 3)
    d_p = direction_vector(alt_p, az_p)
    out["lens_max_angle_deg"] = float(np.degrees(np.arccos(np.clip(
        np.sum(d_p * d_n, -1)[inside], -1, 1))).max())

    # 2. sky at pyskylumos's directions, sun given explicitly
    loc = EarthLocation(lat=34.0, lon=108.0, height=0.0 * m)
    time = Time(["2024-06-01T04:00:00"])
    sun = _sky_coords(loc, time[0], *SUN)
    (dop_p, aop_p, rad_p, *_), _ = engine.simulate_sky_polarization(
        "RAYLEIGH", loc, time, 12, alt_p, az_p, sun_position=sun)
    dop_p, aop_p, rad_p = dop_p[0], aop_p[0], rad_p[0]
    sc = cam.scene(RayleighSky(1.0), att, *SUN)
    I_s, Q_s, U_s = sc.I, sc.Q, sc.U
    up = sc.valid & np.isfinite(dop_p)
    dop_s = np.hypot(Q_s, U_s) / np.where(up, I_s, 1.0)
    chi_s = 0.5 * np.arctan2(U_s, Q_s)
    polarized = up & (dop_s > 0.05)
    out["sky_dop_max_diff"] = float(np.abs(dop_p - dop_s)[up].max())
    dchi = (np.degrees(aop_p - chi_s) + 90.0) % 180.0 - 90.0
    out["sky_aop_max_diff_deg"] = float(np.abs(dchi[polarized]).max())
    ratio = rad_p[up] / I_s[up]
    out["radiance_ratio_range"] = (float(ratio.min() / np.median(ratio)),
                                   float(ratio.max() / np.median(ratio)))

    # 3. the chains on identical inputs: pyskylumos's sky, noise free
    mask = np.isfinite(dop_p) & np.isfinite(aop_p) & np.isfinite(rad_p) & up
    dop_in = np.where(mask, dop_p, np.nan)
    aop_in = np.where(mask, aop_p, np.nan)
    rad_in = np.where(mask, rad_p, np.nan)
    for eps in (1.0, 0.9):
        eng = _engine(lens_name, f_px, extinction=eps)
        res = eng.simulate_measurement(dop_in[None], aop_in[None], rad_in[None])
        dolp_p, aop_m = res["dop"][0], res["aop"][0]
        er = np.inf if eps == 1.0 else (1 + eps) / (1 - eps)
        sensor = MosaicSensor(N, N, full_well_e=2 ** BITS - 1,
                              read_noise_e=0.0, dark_current_e_s=0.0, adc_bits=BITS,
                              black_level_dn=0, extinction_ratio=er)
        ours = PolarizationCamera(cam.lens, sensor)
        m_s = mask
        i_s = np.where(m_s, rad_in, 0.0)
        p_s = np.where(m_s, dop_in, 0.0)
        chi = np.where(m_s, aop_in, 0.0)
        scene = Scene(i_s, i_s * p_s * np.cos(2 * chi), i_s * p_s * np.sin(2 * chi), m_s,
                      np.zeros_like(m_s))
        # the same counts per radiance as pyskylumos's auto exposure (brightest pixel at full
        # scale), skysim's (1 + 1/ER) mean transmission folded in
        k = (2 ** BITS - 1) / np.nanmax(0.5 * rad_in * (1 + eps * dop_in))
        t = k / ours.photoelectrons_per_s / (1.0 + (0.0 if eps == 1.0 else 1.0 / er))
        raw = ours.digitise(ours.expected_electrons(scene, t))
        # pyskylumos's raw counts from its own micro-polarizer and chip (the engine returns
        # only DoLP and AoP): floor against skysim's rounding, so at most 1 count apart
        from pyskylumos.sensor.MicroPolarizer import MicroPolarizer
        from pyskylumos.sensor.SensorChip import SensorChip
        iop = MicroPolarizer(extinction_ratio=eps, polarizer_tolerance_radians=0.0,
                             wire_grid_orientations_slicing=_mosaic()).get_intensity_on_pixel(
            dop_in[None], aop_in[None], rad_in[None])
        counts = SensorChip(auto_exposure_saturation_fraction=1.0, adc_resolution_bits=BITS,
                            multiplicative_noise_snr=1e12).get_bits_intensity(iop)[0]
        st = demosaic(raw, ours.analysis_dn(t, ideal=True), valid=m_s, method="superpixel")
        dolp_s = st.dolp
        aop_s = np.radians(st.aop_camera_deg)
        both = st.valid & np.isfinite(dolp_p)
        tag = "ideal" if eps == 1.0 else f"eps{eps:g}"
        # skysim demosaics with the nominal (ideal) analysis: its DoLP is eps times the scene's
        out[f"chain_{tag}_dolp_max_diff"] = float(np.abs(dolp_p - dolp_s)[both].max())
        strong = both & (dolp_p > 0.1)
        da = (np.degrees(aop_m - aop_s) + 90.0) % 180.0 - 90.0
        out[f"chain_{tag}_aop_max_diff_deg"] = float(np.abs(da[strong]).max())
        out[f"chain_{tag}_samples"] = int(both.sum())
        out[f"chain_{tag}_raw_max_diff_counts"] = float(np.abs(counts - raw)[mask].max())

    # 4. noise: flat unpolarized fields at two levels, standard deviation in counts
    from pyskylumos.sensor.SensorChip import SensorChip
    rng = np.random.default_rng(1)
    ours = PolarizationCamera.fisheye(N, N, full_well_e=2 ** BITS - 1, black_level_dn=0,
                                      adc_bits=BITS, read_noise_e=2.3, dark_current_e_s=0.0)
    for level in (0.1, 0.5):
        chip = SensorChip(auto_exposure_saturation_fraction=1.0, adc_resolution_bits=BITS,
                          multiplicative_noise_snr=100.0, random_seed=3)
        field = np.full((1, N, N), level)
        field[0, 0, 0] = 1.0  # pyskylumos's auto exposure puts the brightest at full scale
        raw_p = chip.get_bits_intensity(field)[0].ravel()[1:]
        raw_s = ours.noisy_frames(np.full(N * N, level * (2 ** BITS - 1)), rng).astype(float)
        out[f"noise_std_counts_at_{level:g}"] = (float(raw_p.std()), float(raw_s.std()))
    return out


def main() -> int:
    for lens in ("equidistant", "equisolid"):
        print(f"[{lens} lens, {N}x{N} px, sun at {SUN[0]:g} deg elevation, {SUN[1]:g} deg "
              "azimuth]")
        for key, value in compare(lens).items():
            print(f"  {key:<34s} {value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
