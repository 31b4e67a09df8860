"""Polarization camera: lens projection, mosaic signal chain, demosaicing (closed forms)."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sensor.camera import (FisheyeLens, MosaicSensor, PolarizationCamera, camera_attitude,
                           demosaic, local_meridian_aop)
from sensor.camera.mosaic import sky_stokes_camera
from skysim.exceptions import InvalidParameterError
from skysim.sky import RayleighSky


def random_rays(n: int, max_theta_deg: float, seed: int) -> np.ndarray:
    """``n`` unit camera-frame rays (n, 3), uniform in angle from the axis up to
    ``max_theta_deg`` and in image azimuth."""
    rng = np.random.default_rng(seed)
    theta = np.radians(rng.uniform(0.0, max_theta_deg, n))
    psi = rng.uniform(-np.pi, np.pi, n)
    return np.stack([np.sin(theta) * np.cos(psi), np.sin(theta) * np.sin(psi), np.cos(theta)],
                    -1)


@pytest.mark.parametrize("model", ["equidistant", "equisolid"])
def test_projection_round_trip(model):
    # directions -> pixels -> directions is exact up to float64 rounding: 1e-9 is ~1e6 ulp
    lens = FisheyeLens(focal_px=83.7, cx=63.2, cy=61.9, fov_deg=190.0, model=model)
    d = random_rays(5000, 95.0, seed=3)
    row, col = lens.project(d)
    back, valid = lens.back_project(row, col)
    assert valid.all()
    np.testing.assert_allclose(back, d, atol=1e-9, rtol=0)
    # and pixels -> directions -> pixels
    r2, c2 = lens.project(back)
    np.testing.assert_allclose(np.c_[r2, c2], np.c_[row, col], atol=1e-9, rtol=0)


def test_projection_closed_form_radius():
    # equidistant r = f theta, equisolid r = 2 f sin(theta/2): a ray at 60 deg from the axis
    for model, r in (("equidistant", 100 * np.pi / 3), ("equisolid", 200 * np.sin(np.pi / 6))):
        lens = FisheyeLens(100.0, 50.0, 40.0, 180.0, model)
        row, col = lens.project([np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3)])  # along +x
        assert col == pytest.approx(50.0 + r, abs=1e-12) and row == pytest.approx(40.0)
    lens = FisheyeLens(100.0, 50.0, 40.0, 120.0)
    assert np.isnan(lens.project([1.0, 0.0, 0.0])[0])  # 90 deg off axis, outside a 120 deg FOV


def test_image_top_is_heading_reference():
    # a level camera with yaw 90 (reference axis east): the image top sees the east horizon
    cam = PolarizationCamera.fisheye(64, 64)
    sc = cam.scene(RayleighSky(), camera_attitude(90.0), 30.0, 200.0)
    top = sc.valid[:8, 31] & sc.valid[:8, 32]
    # columns 31 and 32 lie half a pixel either side of the principal point (cx = 31.5)
    mid = 0.5 * (sc.view_azimuth_deg[:8, 31] + sc.view_azimuth_deg[:8, 32])
    np.testing.assert_allclose(mid[top], 90.0, atol=1e-9)
    assert np.all(np.abs(sc.view_azimuth_deg[:8, 31][top] - 90.0) < 1.5)


def test_uniform_polarized_scene_gives_malus_values():
    # ideal polarizers: a fully polarized flat field at angle chi gives I cos^2(chi - a) (Malus)
    cam = PolarizationCamera.fisheye(16, 16, read_noise_e=0.0, dark_current_e_s=0.0)
    chi = 30.0
    c, s = np.cos(np.radians(2 * chi)), np.sin(np.radians(2 * chi))
    e = cam.expected_electrons(cam.uniform_scene((1.0, c, s)), 1e-3)
    a = cam.sensor.nominal_angle_deg()
    malus = cam.photoelectrons_per_s * 1e-3 * np.cos(np.radians(chi - a)) ** 2
    inside = cam.pixel_directions[1]
    np.testing.assert_allclose(e[inside], malus[inside], rtol=1e-12)
    # extinction ratio ER: transmittance across the axis is 1/ER of that along it
    er = MosaicSensor(16, 16, extinction_ratio=50.0).analysis_vectors()
    t_par = er[..., 0] + er[..., 1] * np.cos(np.radians(2 * a)) + er[..., 2] * np.sin(
        np.radians(2 * a))
    t_perp = er[..., 0] - er[..., 1] * np.cos(np.radians(2 * a)) - er[..., 2] * np.sin(
        np.radians(2 * a))
    np.testing.assert_allclose(t_par / t_perp, 50.0, rtol=1e-12)


def test_noise_statistics_and_saturation():
    cam = PolarizationCamera.fisheye(64, 64, read_noise_e=5.0, adc_bits=16)
    scene = cam.uniform_scene((1.0, 0.0, 0.0))
    t = 0.01
    mean = cam.expected_electrons(scene, t)
    raws = np.stack([cam.capture(scene, t, np.random.default_rng(k)) for k in range(40)])
    inside = cam.pixel_directions[1]
    e = (raws.astype(float) - cam.sensor.black_level_dn) * cam.sensor.e_per_dn
    # variance = shot (mean) + read^2 + quantisation (e_per_dn^2 / 12); 40 frames x ~3000
    # pixels: the pooled variance ratio is known to ~0.5 %, 3 % leaves room for rounding
    var_pred = mean + 25.0 + cam.sensor.e_per_dn ** 2 / 12
    ratio = (e.var(axis=0, ddof=1)[inside] / var_pred[inside]).mean()
    assert ratio == pytest.approx(1.0, abs=0.03)
    assert (e.mean(0)[inside] / mean[inside]).mean() == pytest.approx(1.0, abs=2e-3)
    sat = cam.capture(scene, 10.0, np.random.default_rng(0))
    assert (sat[inside] == cam.sensor.max_dn).all() and sat.dtype == np.uint16


def test_sun_disk_saturates_and_horizon_is_masked():
    cam = PolarizationCamera.fisheye(128, 128)
    att = camera_attitude(0.0, pitch_deg=20.0)
    sc = cam.scene(RayleighSky(), att, 50.0, 10.0)
    assert sc.sun.sum() >= 1
    raw = cam.capture(sc, cam.auto_exposure_s(sc), np.random.default_rng(0))
    assert (raw[sc.sun] == cam.sensor.max_dn).all()
    d, inside = cam.pixel_directions
    el = np.degrees(np.arcsin(att.apply(d[inside])[:, 2]))
    assert (sc.valid[inside] == (el >= 0)).all() and (el < 0).any()


def _ideal_camera(n=128):
    return PolarizationCamera.fisheye(n, n, read_noise_e=0.0, dark_current_e_s=0.0)


def test_ideal_camera_stokes_equal_sky_within_demosaicing_bound():
    """Noise-free ideal camera, super-pixel demosaicing against the sky's Stokes at each
    super-pixel centre. The four pixels sample the field at offsets of half a pixel; with
    ideal polarizers (S0 = sum/2, S1 = d0 - d90, S2 = d45 - d135) each component's error is at
    most max_k(|dI_k| + |dP_k|), dI_k and dP_k the change of I and of (Q, U) from the centre
    to pixel k. Sun-disk blocks excluded (saturated)."""
    cam = _ideal_camera()
    att = camera_attitude(25.0, 3.0, -2.0)
    sky, sun = RayleighSky(), (35.0, 140.0)
    sc = cam.scene(sky, att, *sun)
    t = 1e-3
    raw = cam.expected_electrons(sc, t) / cam.sensor.e_per_dn
    st = demosaic(raw, cam.analysis_dn(t), valid=sc.valid & ~sc.sun, method="superpixel")
    ok = st.valid
    d, _ = cam.lens.back_project(st.row[ok], st.col[ok])
    _, s_c, *_ = sky_stokes_camera(sky, att, *sun, d, np.ones(len(d), bool))
    est = np.c_[st.S0[ok], st.S1[ok], st.S2[ok]]
    ref = s_c
    # bound from the scene's own pixel values in each block
    blocks = np.stack([sc.I, sc.Q, sc.U], -1).reshape(64, 2, 64, 2, 3).swapaxes(1, 2)
    blocks = blocks.reshape(64, 64, 4, 3)[ok]
    dif = blocks - ref[:, None, :]
    bound = (np.abs(dif[..., 0]) + np.hypot(dif[..., 1], dif[..., 2])).max(-1)
    assert (np.abs(est - ref) <= bound[:, None] + 1e-9).all()
    # the bound scales with a pixel's angular size (1.4 deg here): a few % of I
    assert np.median(bound) < 0.03 * np.median(ref[:, 0])
    # and in the local-meridian convention the AoP matches the sky's
    el, az, aop = local_meridian_aop(st, cam.lens, att)
    fld = sky.field(el[ok], az[ok], *sun)
    dolp = np.hypot(ref[:, 1], ref[:, 2]) / ref[:, 0]
    strong = dolp > 0.2  # away from the neutral points, where the AoP is well defined
    dif_aop = (aop[ok] - fld.aop_deg + 90) % 180 - 90
    assert np.abs(dif_aop[strong]).max() < 2.0  # within the bound's angle at DoP 0.2


def test_bilinear_exact_for_linear_fields():
    # the bilinear kernel reproduces a field linear in the pixel coordinates exactly away from
    # the border (the weights of each channel are symmetric about the pixel)
    cam = _ideal_camera(32)
    rows, cols = np.indices((32, 32), dtype=float)
    S = np.stack([2.0 + 0.01 * rows + 0.02 * cols, 0.3 - 0.004 * rows, 0.1 + 0.003 * cols], -1)
    a = cam.analysis_dn(1e-3)
    raw = np.einsum("hwk,hwk->hw", a, S)
    for method in ("bilinear", "centred", "superpixel"):
        st = demosaic(raw, a, method=method)
        inner = st.valid & (st.row > 1) & (st.row < 30) & (st.col > 1) & (st.col < 30)
        r, c = st.row[inner], st.col[inner]
        ref = np.c_[2.0 + 0.01 * r + 0.02 * c, 0.3 - 0.004 * r, 0.1 + 0.003 * c]
        if method == "bilinear":
            np.testing.assert_allclose(np.c_[st.S0[inner], st.S1[inner], st.S2[inner]], ref,
                                       atol=1e-9)
        if method == "centred":
            # weights (3/4, 1/4) per axis are symmetric about the centre: exact, up to the
            # float32 arithmetic of this method (measured 4e-7 on S0 ~ 2.5: ~3 ulp)
            np.testing.assert_allclose(np.c_[st.S0[inner], st.S1[inner], st.S2[inner]], ref,
                                       atol=2e-6)
        assert inner.sum() > 50


def test_demosaic_against_polanalyser():
    pa = pytest.importorskip("polanalyser")
    pytest.importorskip("cv2")
    rng = np.random.default_rng(5)
    raw = rng.integers(200, 4000, (32, 32)).astype(np.uint16)
    sensor = MosaicSensor(32, 32)  # layout [[90, 45], [135, 0]], polanalyser's
    a = 2.0 * sensor.analysis_vectors(ideal=True)  # d = A S with A = (1, cos 2a, sin 2a) / 2
    st = demosaic(raw, a / 2.0, method="bilinear")
    imgs = pa.demosaicing(raw, pa.COLOR_PolarMono)
    angles = np.deg2rad([0, 45, 90, 135])
    stokes = pa.calcStokes(imgs, angles) if hasattr(pa, "calcStokes") else None
    if stokes is None:
        pytest.skip("polanalyser without calcStokes")
    inner = (slice(2, -2), slice(2, -2))
    # polanalyser rounds the interpolated channels to the image's integer type: 1 DN
    np.testing.assert_allclose(st.S0[inner], stokes[..., 0][inner], atol=2.0)
    np.testing.assert_allclose(st.S1[inner], stokes[..., 1][inner], atol=2.0)
    np.testing.assert_allclose(st.S2[inner], stokes[..., 2][inner], atol=2.0)


def test_bad_inputs_raise():
    with pytest.raises(InvalidParameterError, match="even"):
        MosaicSensor(63, 64)
    with pytest.raises(InvalidParameterError, match="adc_bits"):
        MosaicSensor(64, 64, adc_bits=20)
    with pytest.raises(ValueError, match="equidistant"):
        FisheyeLens(10.0, 5.0, 5.0, model="pinhole")
    cam = _ideal_camera(16)
    with pytest.raises(ValueError, match="bilinear, centred, superpixel"):
        demosaic(np.zeros((16, 16)), cam.analysis_dn(1.0), method="vng")
    with pytest.raises(InvalidParameterError, match="analysis_dn"):
        demosaic(np.zeros((16, 16)), np.zeros((16, 16, 4)))
    with pytest.raises(InvalidParameterError, match="exposure_s"):
        cam.expected_electrons(cam.uniform_scene((1, 0, 0)), -1.0)
    assert isinstance(camera_attitude(10.0), Rotation)


def test_missing_tifffile_gives_install_hint(tmp_path, monkeypatch, capsys):
    import sys

    from experiments.cli.main import main
    monkeypatch.setitem(sys.modules, "tifffile", None)  # import fails as if not installed
    assert main(["camera", "--lat", "34", "--lon", "108", "--time", "2013-05-22T12:00+08:00",
                 "--width", "32", "--height", "32", "--out", str(tmp_path / "x.tiff")]) == 2
    err = capsys.readouterr().err
    assert "'camera'" in err and "pip install -e" in err
    assert not (tmp_path / "x.tiff").exists()


class _GenericRayleigh(RayleighSky):
    """The same sky through the generic :meth:`Sky.field` path of the camera."""


@pytest.mark.parametrize("dtype, atol", [("float64", 1e-12), ("float32", 1e-6)])
def test_rayleigh_dot_product_render_matches_generic_path(dtype, atol):
    # the Rayleigh sky from each pixel's camera-fixed frame (dot products, no angles) against
    # the generic path (view angles -> sky.field -> rotation into the camera frame) on a
    # tilted camera: float64 agree to rounding (measured 1e-13); float32 Stokes (|S| <= 1.5)
    # carry a few ulps, measured 2.5e-7
    cam = PolarizationCamera.fisheye(120, 100, fov_deg=190.0)
    att = camera_attitude(25.0, 13.0, -7.0)
    fast = cam.scene(RayleighSky(0.7, dtype=dtype), att, 35.0, 140.0)
    ref = cam.scene(_GenericRayleigh(0.7), att, 35.0, 140.0)
    assert fast.I.dtype == np.dtype(dtype)
    assert (fast.valid == ref.valid).all() and (fast.sun == ref.sun).all() and fast.sun.any()
    assert (~fast.valid).sum() > 1000  # the horizon of the tilted fisheye is in the image
    for a, b in ((fast.I, ref.I), (fast.Q, ref.Q), (fast.U, ref.U)):
        np.testing.assert_allclose(a, b, atol=atol, rtol=0)
    np.testing.assert_allclose(fast.view_elevation_deg, ref.view_elevation_deg, atol=1e-9)
    np.testing.assert_allclose(fast.view_azimuth_deg, ref.view_azimuth_deg, atol=1e-9)


def test_float32_render_error_bound():
    # every camera effect; float32 against float64 mean electrons: relative error <= 2e-6
    # (measured 9e-7, a few float32 ulps), i.e. <= 0.02 e- at the full well, a thousandth
    # of the shot noise there
    base = PolarizationCamera.fisheye(128, 96)
    sensor = replace(base.sensor.with_random_errors(
        np.random.default_rng(0), angle_std_deg=1.0, extinction_ratio=30.0,
        extinction_ratio_rel_std=0.2, gain_std=0.02), crosstalk=0.02)
    cam = PolarizationCamera(base.lens, sensor, base.photoelectrons_per_s,
                             1.5 * base.lens.focal_px)
    att = camera_attitude(25.0, 13.0, -7.0)
    e64, e32 = (cam.expected_electrons(cam.scene(RayleighSky(0.7, dtype=dt), att, 35.0, 140.0),
                                       0.02) for dt in ("float64", "float32"))
    assert e32.dtype == np.float32 and e64.dtype == np.float64
    np.testing.assert_allclose(e32, e64, rtol=2e-6, atol=0)


def test_crosstalk_conserves_energy_and_keeps_a_uniform_scene():
    c = 0.03
    ideal = PolarizationCamera.fisheye(64, 64, read_noise_e=0.0, dark_current_e_s=0.0)
    cam = PolarizationCamera(ideal.lens, replace(ideal.sensor, crosstalk=c))
    e = np.random.default_rng(4).uniform(0, 1e4, (64, 64))
    # energy conserving, borders included
    assert cam.sensor.apply_crosstalk(e).sum() == pytest.approx(e.sum(), rel=1e-12)
    np.testing.assert_allclose(cam.sensor.apply_crosstalk(np.full((64, 64), 7.0)), 7.0,
                               rtol=1e-12)
    # a uniform scene (filling the image circle) is unchanged wherever all four neighbours
    # see it; a uniform fully polarized one loses exactly 1 - 4c of its DoLP: every edge
    # neighbour's polarizer is at +-45 deg, whose cos 2(chi - a) terms cancel in pairs
    inside = cam.pixel_directions[1]
    core = inside.copy()
    for ax in (0, 1):
        for k in (1, -1):
            core &= np.roll(inside, k, axis=ax)
    core[[0, -1], :] = core[:, [0, -1]] = False  # a border pixel keeps its missing share
    unpol = cam.uniform_scene((1.0, 0.0, 0.0))
    np.testing.assert_allclose(cam.expected_electrons(unpol, 1e-3)[core],
                               ideal.expected_electrons(unpol, 1e-3)[core], rtol=1e-12)
    for chi in (0.0, 30.0, 100.0):
        x = np.radians(2 * chi)
        sc = cam.uniform_scene((1.0, np.cos(x), np.sin(x)))
        raw = cam.expected_electrons(sc, 1e-3) / cam.sensor.e_per_dn
        st = demosaic(raw, cam.analysis_dn(1e-3), valid=core, method="superpixel")
        assert st.valid.sum() > 400
        np.testing.assert_allclose(st.dolp[st.valid], 1.0 - 4.0 * c, rtol=1e-12)
        np.testing.assert_allclose(st.aop_camera_deg[st.valid], (chi + 90) % 180 - 90,
                                   atol=1e-9)
    with pytest.raises(InvalidParameterError, match="crosstalk"):
        MosaicSensor(8, 8, crosstalk=0.25)


def test_gaussian_shot_noise_limit_and_exact_poisson_below():
    from scipy import stats

    from sensor.camera.mosaic import POISSON_EXACT_BELOW_E
    # the documented bounds: sup |F_Poisson - F_approx| (continuity-corrected) from scipy's
    # exact Poisson law, the approximation lam + sqrt(lam) z + (z^2 - 1) / 6 inverted in
    # closed form, without read noise (the worst case)
    for lam, bound in ((POISSON_EXACT_BELOW_E, 4.4e-4), (1000.0, 1.2e-5)):
        k = np.arange(max(0, int(lam - 12 * lam ** 0.5)), int(lam + 12 * lam ** 0.5))
        x, g = (k + 0.5 - lam) / lam ** 0.5, 1.0 / (6.0 * lam ** 0.5)
        z = (-1.0 + np.sqrt(1.0 + 4.0 * g * (x + g))) / (2.0 * g)
        assert np.abs(stats.poisson.cdf(k, lam) - stats.norm.cdf(z)).max() <= bound
        # the plain normal limit misses by the Edgeworth skewness term 1/(6 sqrt(2 pi lam))
        plain = np.abs(stats.poisson.cdf(k, lam) - stats.norm.cdf(x)).max()
        assert plain == pytest.approx(1 / (6 * np.sqrt(2 * np.pi * lam)), rel=0.02)
    # both branches have the exact mean and variance (shot + read + quantisation); 200000
    # draws know the variance to 0.32 % (1 sigma): 1.5 % is 4.7 sigma
    cam = PolarizationCamera.fisheye(16, 16, read_noise_e=4.0, adc_bits=16)
    s = cam.sensor
    for mean in (10.0, 30.0, 300.0, 3000.0, 8000.0):
        raw = cam.noisy_frames(np.full(200_000, mean), np.random.default_rng(int(mean)))
        e = (raw.astype(float) - s.black_level_dn) * s.e_per_dn
        assert e.mean() == pytest.approx(mean, abs=5 * np.sqrt((mean + 16) / 2e5))
        assert e.var() == pytest.approx(mean + 16.0 + s.e_per_dn ** 2 / 12, rel=0.015)
        # and the third central moment is the Poisson law's, lam (read noise adds none);
        # its sampling error is ~sqrt(15 v^3 / n): 4 of those
        v = mean + 16.0
        assert np.mean((e - e.mean()) ** 3) == pytest.approx(mean, abs=4 * np.sqrt(15 * v ** 3
                                                                               / 2e5))
    # below the threshold the draw is Poisson itself: integer electrons without read noise
    exact = PolarizationCamera.fisheye(16, 16, read_noise_e=0.0, adc_bits=16,
                                       full_well_e=2.0 ** 16 - 1 - 1024)  # 1 e-/DN
    raw = exact.noisy_frames(np.full(50_000, 20.0), np.random.default_rng(1)).astype(float)
    counts = raw - exact.sensor.black_level_dn
    ref = stats.poisson.pmf(np.arange(60), 20.0) * counts.size
    obs = np.bincount(counts.astype(int), minlength=60)[:60]
    keep = ref > 20
    chi2 = np.sum((obs[keep] - ref[keep]) ** 2 / ref[keep])
    assert chi2 < stats.chi2.ppf(0.999, keep.sum() - 1)


@pytest.mark.parametrize("model", ["equidistant", "equisolid"])
def test_sun_disk_found_in_its_window(model):
    # the sun disk is searched in a box around the sun's image: the same pixels as the full-
    # frame test of the generic path, for random suns and attitudes (the sun near the edge of
    # a 190 deg field of view included), and a disk of several pixels
    rng = np.random.default_rng(0)
    cam = PolarizationCamera.fisheye(150, 120, model=model, fov_deg=190.0, sun_radius_deg=3.0)
    found = 0
    for _ in range(40):  # random configurations, each a whole image
        sun = (rng.uniform(-9.0, 90.0), rng.uniform(0.0, 360.0))
        att = camera_attitude(rng.uniform(0, 360), rng.uniform(-40, 40), rng.uniform(-40, 40))
        fast = cam.scene(RayleighSky(), att, *sun).sun
        assert (fast == cam.scene(_GenericRayleigh(), att, *sun).sun).all()
        found += int(fast.sum())
    assert found > 40 * 10


@pytest.mark.parametrize("model", ["equidistant", "equisolid"])
def test_polarization_axes_are_the_meridional_basis_turned_by_the_image_azimuth(model):
    # (e_0, e_90, -d) orthonormal and right-handed (angles right-handed about the light's
    # travel); e_0 = e_x = cos psi e_theta - sin psi e_psi and e_90 = -e_y = -(sin psi e_theta
    # + cos psi e_psi) with the basis of camera_basis; right of the centre (psi = 0) a small
    # step along e_0 moves the image point right only, above it (psi = -90 deg) a step along
    # e_90 moves it up only (1e-6 rad: the cross term is second order, < 1e-9 px)
    from sensor.camera import camera_basis
    lens = FisheyeLens(83.7, 63.2, 61.9, 190.0, model)
    rng = np.random.default_rng(9)
    row, col = rng.uniform(5, 120, 400), rng.uniform(5, 120, 400)
    e_0, e_90, d = lens.polarization_axes(row, col)
    ok = np.isfinite(d).all(-1)
    assert ok.sum() > 300
    e_0, e_90, d = e_0[ok], e_90[ok], d[ok]
    np.testing.assert_allclose(np.cross(e_0, e_90), -d, atol=1e-12)
    for u, v in ((e_0, e_90), (e_0, d), (e_90, d)):
        np.testing.assert_allclose(np.sum(u * v, -1), 0.0, atol=1e-12)
    _, psi, e_th, e_ps = camera_basis(d)
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    np.testing.assert_allclose(e_0, c * e_th - s * e_ps, atol=1e-12)
    np.testing.assert_allclose(e_90, -(s * e_th + c * e_ps), atol=1e-12)
    offsets = np.array([3.0, 20.0, 55.0])
    ex0, _, d0 = lens.polarization_axes(np.full(3, lens.cy), lens.cx + offsets)
    r1, c1 = lens.project(d0 + 1e-6 * ex0)
    assert (np.abs(r1 - lens.cy) < 1e-9).all() and (c1 > lens.cx + offsets).all()
    _, e90, d0 = lens.polarization_axes(lens.cy - offsets, np.full(3, lens.cx))
    r1, c1 = lens.project(d0 + 1e-6 * e90)
    assert (np.abs(c1 - lens.cx) < 1e-9).all() and (r1 < lens.cy - offsets).all()


@pytest.mark.parametrize("model", ["equidistant", "equisolid"])
def test_sky_pixels_are_those_above_the_horizon(model):
    # the blockwise horizon mask equals the one from the camera's per-pixel directions
    # (exact: the same rays; pixels within 1e-9 of the horizon would be ambiguous, none here)
    cam = PolarizationCamera.fisheye(150, 120, model=model, fov_deg=200.0)
    d, inside = cam.pixel_directions
    for pitch, roll in ((0.0, 0.0), (25.0, -10.0), (-5.0, 40.0)):
        att = camera_attitude(0.0, pitch, roll)
        sin_el = att.apply(np.nan_to_num(d).reshape(-1, 3))[:, 2].reshape(inside.shape)
        assert np.abs(sin_el[inside]).min() > 1e-9
        np.testing.assert_array_equal(cam.sky_pixels(att), inside & (sin_el >= 0))
