"""Aerosol sky (skysim.aerosol, skysim.aerosol_types): engine against Siewert (2000), Mie
optics against miepython, the molecular limit, the table and sun-step errors, the published
fall of the maximum DoP with AOD (Kreuter et al. 2010)."""

import numpy as np
import pytest

pytest.importorskip("sasktran2", reason="sasktran2 (extra skysim[rt]) not installed")

from skysim import aerosol
from skysim.aerosol import AerosolSky, aerosol_stokes_cases, prefetch_tables
from skysim.aerosol_types import PRESETS, aerosol_optics, aerosol_type
from skysim.exceptions import InvalidParameterError
from skysim.multiple import MultipleScatteringSky, bodhaine_optical_thickness
from skysim.rt_sasktran import EngineSettings, layered_stokes_cases, transmitted_stokes_cases
from skysim.sky import make_sky

PRESET, LAM, ALB = "continental_average", 450.0, 0.1


def _random_directions(n, seed=3):
    rng = np.random.default_rng(seed)
    return np.degrees(np.arcsin(rng.uniform(0.02, 1.0, n))), rng.uniform(-180.0, 180.0, n)


def _sun_distance(el, phi, sun_el):
    e, s, p = np.radians(el), np.radians(sun_el), np.radians(phi)
    return np.degrees(np.arccos(np.clip(np.sin(e) * np.sin(s)
                                        + np.cos(e) * np.cos(s) * np.cos(p), -1, 1)))


# ------------------------------------------------------------------ engine: Siewert (2000) IIA

@pytest.mark.parametrize("n_streams", [32])
def test_siewert2000_problem_IIA_downwelling(reference_dir, n_streams):
    """Downwelling I, Q, U at the bottom (tau = 1) of Siewert's aerosol slab from his Greek
    coefficients (mu0 = 0.6, omega = 0.973527, black ground).

    Conventions (``tests/siewert_reference.py``): alpha1 = row 2, alpha2 = row 1, alpha3 =
    row 6, beta1 = -row 3 (VLIDORT stores beta1 with Mishchenko's sign; sasktran2 has
    Hovenier's, the one whose Rayleigh beta1_2 is +sqrt(6)/2). Same flux normalisation (pi)
    as skysim; ``Q_table = Q``, ``U_table = -U``; relative azimuth 0 looks towards the sun.

    Tolerance: |dI/I| <= 5e-4 and |dQ|, |dU| <= 5e-5 (I is ~0.1-1) for view cosines 0.1-0.9.
    The engine is converged in streams (64 streams change nothing at 1e-5); what remains is
    the line-of-sight quadrature of 101 levels, 4e-4 at tau = 1 (docs/physical_sky.md);
    the tables have 6 significant digits. Not compared: mu = 0 (the tables give the limit
    mu -> 0+, the engine sees 1e-4, where I rises steeply: +2 %) and mu = 1 (the engine
    looks 0.08 deg off the zenith: +2e-3 in I).
    """
    import siewert_reference as ref
    folder = reference_dir / "siewert2000"
    rows = ref.greek_rows(folder)
    s = EngineSettings(n_streams=n_streams)
    g = np.zeros((s.n_streams, 4))
    n = rows[2].size
    g[:n, 0], g[:n, 1], g[:n, 2], g[:n, 3] = rows[2], rows[1], rows[6], -rows[3]
    mu, _ = ref.downwelling_bottom(2, folder)
    keep = (mu >= 0.1) & (mu <= 0.9)
    mu = mu[keep]
    phis = np.array([0.0, 90.0, 180.0])
    M, P = np.meshgrid(mu, phis, indexing="ij")
    st = layered_stokes_cases([ref.TAU], np.full((1, s.n_levels), ref.SSA),
                              np.broadcast_to(g, (1, s.n_levels) + g.shape), [0.0], ref.MU0,
                              M.ravel(), P.ravel(), settings=s)[0].reshape(M.shape + (3,))
    sign = {"I": 1.0, "Q": 1.0, "U": -1.0}
    checked = 0
    for (c, az), table in ref.TABLES.items():
        _, values = ref.downwelling_bottom(table, folder)
        model = sign[c] * st[:, int(np.flatnonzero(phis == az)[0]), "IQU".index(c)]
        if c == "I":
            np.testing.assert_allclose(model, values[keep], rtol=5e-4)
        else:
            np.testing.assert_allclose(model, values[keep], atol=5e-5)
        checked += 1
    assert checked == 7


# ------------------------------------------------------------------ Mie optics vs miepython

@pytest.mark.slow
def test_mie_moments_against_miepython():
    """Greek moments alpha1_l, beta1_l (l <= 32, those of the multiple scatter), the
    single-scattering albedo and the extinction per particle of the continental_clean preset
    at 550 nm against miepython (an independent Mie code), integrated here over the same
    size distributions (log-normal, truncated at twice the 0.99999 number quantile like the
    engine's integration, renormalised) on our own quadrature: 200 Gauss nodes in ln r,
    1000 in cos(angle).

    Tolerances: alpha1_l within 2e-3 relative, beta1_l within 5e-3 absolute (|beta1| up to
    0.18), ssa within 5e-4, extinction within 1e-3 relative. They bound our quadrature's own
    error: doubling the radius nodes changes alpha1_l by up to 1.3e-3 and beta1_l by 2e-3.
    beta1 is projected on P^l_02(x) = sqrt((l-2)!/(l+2)!) P_l^2(x), the normalisation in
    which the Rayleigh matrix has beta1_2 = +sqrt(6)/2 (skysim.rt_sasktran), and with
    P12 = |S1|^2 - |S2|^2 (> 0 for polarization perpendicular to the scattering plane).
    """
    miepython = pytest.importorskip("miepython", reason="miepython (extra test) not installed")
    from numpy.polynomial.legendre import Legendre, leggauss
    from scipy.special import gammaln, lpmv
    from scipy.stats import norm

    lam, n_l = 550.0, 33
    t = PRESETS["continental_clean"]
    x, wx = leggauss(1000)
    ext = sca = 0.0
    p11, p12 = np.zeros_like(x), np.zeros_like(x)
    u, wu = leggauss(200)
    for comp, number in t.components:
        ls = np.log(comp.sigma)
        zmax = norm.ppf(0.99999) + np.log(2.0) / ls
        z, wz = (u + 1) / 2 * (zmax + 8) - 8, wu * (zmax + 8) / 2
        w = number * norm.pdf(z) * wz / np.sum(norm.pdf(z) * wz)
        for r, wi in zip(comp.mode_radius_um * 1e3 * np.exp(ls * z), w):
            size = 2 * np.pi * r / lam
            qext, qsca, _, _ = miepython.efficiencies_mx(comp.refractive_index, size)
            s1, s2 = miepython.S1_S2(comp.refractive_index, size, x, norm="one")
            ext += wi * qext * np.pi * r * r
            sca += wi * qsca * np.pi * r * r
            p11 += wi * qsca * np.pi * r * r * (abs(s1) ** 2 + abs(s2) ** 2)
            p12 += wi * qsca * np.pi * r * r * (abs(s1) ** 2 - abs(s2) ** 2)
    c = 2.0 / np.sum(wx * p11)
    ell = np.arange(n_l)
    a1 = (2 * ell + 1) / 2 * np.array([np.sum(Legendre.basis(k)(x) * p11 * c * wx) for k in ell])
    p02 = np.array([np.exp(0.5 * (gammaln(k - 1) - gammaln(k + 3))) * lpmv(2, k, x)
                    if k >= 2 else 0 * x for k in ell])
    b1 = (2 * ell + 1) / 2 * np.sum(p02 * p12 * c * wx, axis=1)
    o = aerosol_optics(t, lam)
    np.testing.assert_allclose(o.greek[:n_l, 0], a1, rtol=2e-3)
    np.testing.assert_allclose(o.greek[:n_l, 3], b1, atol=5e-3)
    assert abs(o.ssa - sca / ext) < 5e-4
    per_particle_nm2 = o.extinction / 1e6 / sum(n for _, n in t.components) * 1e18
    assert abs(per_particle_nm2 / (ext / sum(n for _, n in t.components)) - 1) < 1e-3


# ------------------------------------------------------------------ molecular limit

def test_zero_aod_is_the_molecular_sky():
    """AOD -> 0: the engine input is the Rayleigh slab of skysim.multiple exactly (1e-9),
    and the interpolated aerosol sky equals MultipleScatteringSky at the same Rayleigh tau
    and depolarization within 2e-3 in I/I and DoP (both interpolate the same engine field,
    each within 1.4e-3 of it: docs/physical_sky.md)."""
    tau = float(bodhaine_optical_thickness(LAM))
    mu0 = np.sin(np.radians(30.0))
    el, phi = _random_directions(50)
    a = aerosol_stokes_cases([0.0], [ALB], mu0, np.sin(np.radians(el)), phi, preset=PRESET,
                             wavelength_nm=LAM, depolarization_ratio=0.03)[0]
    m = transmitted_stokes_cases([tau], [ALB], mu0, np.sin(np.radians(el)), phi,
                                 depolarization_ratio=0.03)[0]
    np.testing.assert_allclose(a, m, rtol=1e-9, atol=1e-12)
    el, phi = _random_directions(400, seed=5)
    fa = AerosolSky(PRESET, 0.0, ALB, LAM, depolarization_ratio=0.03).field(el, phi, 30.0, 0.0)
    fm = MultipleScatteringSky(tau=tau, albedo=ALB, depolarization_ratio=0.03).field(
        el, phi, 30.0, 0.0)
    assert np.max(np.abs(fa.I / fm.I - 1)) < 2e-3
    assert np.max(np.abs(fa.dop - fm.dop)) < 2e-3


# ------------------------------------------------------------------ table and sun-step errors

@pytest.mark.parametrize("preset", ["continental_average", "desert"])
def test_single_scatter_is_the_engines(preset):
    """The closed-form single scatter (line-of-sight weights times the phase matrix at the
    exact scattering angle) against the engine's exact single scatter, sun at 40 deg zenith,
    rays from the zenith to 5 deg elevation, from 0.004 deg to 1 deg off the sun (the top of
    the forward peak) and at oblique azimuths, AOD 0.05 and 0.5. Measured: I within 2.7e-4
    relative, Q/I 1.2e-4, U/I 2.1e-4 (largest at 5 deg elevation). Tolerances 5e-4 and 3e-4:
    the engine's line-of-sight quadrature over its 101 levels against the closed form. The
    desert aerosol has the sharpest forward peak of the presets."""
    mu0 = np.cos(np.radians(40.0))
    mu = np.array([0.999999, 0.98, 0.9, 0.8, 0.78, 0.766, 0.76, 0.74, 0.7, 0.5, 0.3, 0.1,
                   0.0872])
    M, P = np.meshgrid(mu, [0.0, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 45.0, 90.0, 135.0, 180.0],
                       indexing="ij")
    kw = dict(preset=preset, wavelength_nm=550.0, depolarization_ratio=0.03)
    engine = aerosol_stokes_cases([0.05, 0.5], [0.0], mu0, M.ravel(), P.ravel(),
                                  multiple_scatter=False, **kw)
    ours = aerosol.aerosol_single_scatter_cases([0.05, 0.5], mu0, **kw)
    for e, s in zip(engine, ours):
        got = s.stokes(np.degrees(np.arccos(M.ravel())), P.ravel()).T
        assert np.max(np.abs(got[:, 0] / e[:, 0] - 1)) < 5e-4
        assert np.max(np.abs(got[:, 1:] - e[:, 1:]) / e[:, :1]) < 3e-4


def test_phase_elements_against_closed_forms():
    """``F11``, ``F12`` from Greek coefficients: the Rayleigh ones in closed form
    ((3/4)(1 + cos^2) and (3/4) sin^2 for Delta = 1; 1e-12), and the tabulated aerosol phase
    function (linear between angles 0.01 deg apart) within 1e-4 of its series in the desert
    aerosol's forward peak (0-3 deg)."""
    from skysim.rt_sasktran import phase_f11_f12, rayleigh_greek_coefficients
    x = np.cos(np.radians(np.linspace(0.0, 180.0, 181)))
    f11, f12 = phase_f11_f12(rayleigh_greek_coefficients(1.0, 8), x)
    np.testing.assert_allclose(f11, 0.75 * (1 + x * x), atol=1e-12)
    np.testing.assert_allclose(f12, 0.75 * (1 - x * x), atol=1e-12)
    optics = aerosol_optics(aerosol_type("desert"), 550.0, 512)
    angle = np.random.default_rng(2).uniform(0.0, 3.0, 200)
    table = aerosol._aerosol_phase(aerosol_type("desert"), 550.0, 512)
    series = phase_f11_f12(optics.greek, np.cos(np.radians(angle)))
    for got, want in zip(table(angle), series):
        assert np.max(np.abs(got - want) / series[0]) < 1e-4


@pytest.mark.slow
def test_sun_step_interpolation_error_and_engine_calls(monkeypatch):
    """``sun_step_deg = 1``: many suns within 29-31 deg cost one engine call per sun node (3),
    not per sun. At the middle of a step (against the exact table at 29.5 deg), everywhere
    including within 8 deg of the sun: the multiply scattered light and the single scatter's
    line-of-sight weights interpolated linearly in sun elevation, the phase function at each
    sample's own scattering angle, err by <= 1.5e-4 in I/I and 3.5e-5 in DoP (measured;
    tolerances 5e-4 and 2e-4: the error grows as the step squared, these allow a step
    1.8 times longer)."""
    aerosol.clear_tables_cache()   # engine calls are counted: none may come from the cache
    calls = []
    real = aerosol.aerosol_stokes_cases
    # multiple-scatter engine calls (the single scatter is computed in closed form)
    monkeypatch.setattr(aerosol, "aerosol_stokes_cases",
                        lambda *a, **k: (k.get("multiple_scatter", True) and calls.append(a[2]))
                        or real(*a, **k))
    sky = AerosolSky(PRESET, 0.2, ALB, LAM, sun_step_deg=1.0)
    el, phi = _random_directions(2000, seed=9)
    rng = np.random.default_rng(1)
    el[:100] = 29.5 + rng.uniform(-6.0, 6.0, 100)       # around the sun
    phi[:100] = rng.uniform(-8.0, 8.0, 100)
    suns = rng.uniform(29.0, 31.0, el.size)
    suns[:400] = 29.5
    f = sky.field(el, phi, suns, 0.0)
    assert len(calls) == 3                     # nodes 29, 30, 31
    exact = AerosolSky(PRESET, 0.2, ALB, LAM).field(el[:400], phi[:400], 29.5, 0.0)
    assert np.min(_sun_distance(el[:100], phi[:100], 29.5)) < 1.5
    assert np.max(np.abs(f.I[:400] / exact.I - 1)) < 5e-4
    assert np.max(np.abs(f.dop[:400] - exact.dop)) < 2e-4


@pytest.mark.slow
def test_prefetch_several_aods_in_one_call(monkeypatch):
    """prefetch_tables computes all AOD nodes at a sun in one engine call; the skies then
    evaluate from the cache, identical to tables computed one AOD at a time (each AOD is an
    independent engine 'wavelength')."""
    calls = []
    real = aerosol.aerosol_stokes_cases
    monkeypatch.setattr(aerosol, "aerosol_stokes_cases",
                        lambda *a, **k: (k.get("multiple_scatter", True)
                                         and calls.append(len(a[0]))) or real(*a, **k))
    aods = [0.05, 0.5]
    sky = AerosolSky(PRESET, 0.05, ALB, LAM)
    prefetch_tables(aods, [20.0], sky=sky)
    el, phi = _random_directions(20)
    fields = [AerosolSky(PRESET, a, ALB, LAM).field(el, phi, 20.0, 0.0) for a in aods]
    assert calls == [2]
    aerosol.clear_tables_cache()
    alone = AerosolSky(PRESET, 0.5, ALB, LAM).field(el, phi, 20.0, 0.0)
    np.testing.assert_allclose(alone.I, fields[1].I, rtol=1e-12)


# ------------------------------------------------------------------ physics

@pytest.mark.slow
def test_max_dop_falls_with_aod_kreuter2010():
    """Kreuter, Emde & Blumthaler (2010), Atmos. Res. 98:363, measured the sky's maximum DoP
    at 450 nm fall from about 0.7 to 0.4 as the AOD rose from 0.05 to 0.5. The model
    (continental average, albedo 0.1, sun at 30 deg): strictly falling, 0.6-0.8 at AOD 0.05
    and 0.3-0.5 at 0.5 (their points scatter by about +-0.05 and depend on sun and ground)."""
    aods = [0.05, 0.1, 0.2, 0.5]
    sky = AerosolSky(PRESET, aods[0], ALB, LAM)
    prefetch_tables(aods, [30.0], sky=sky)
    el, az = np.meshgrid(np.arange(0.0, 90.1, 1.0), np.arange(0.0, 360.0, 2.0))
    dmax = [AerosolSky(PRESET, a, ALB, LAM).field(el, az, 30.0, 0.0).dop.max() for a in aods]
    assert np.all(np.diff(dmax) < 0)
    assert 0.6 < dmax[0] < 0.8 and 0.3 < dmax[-1] < 0.5


def test_zenith_e_vector_perpendicular_to_solar_meridian():
    """docs/conventions.md invariant: at the zenith the E-vector is perpendicular to the
    solar meridian (AoP 90 deg from the meridian of the sun's azimuth), within 0.5 deg."""
    f = AerosolSky(PRESET, 0.2, ALB, LAM).field(90.0, [0.0, 180.0], 30.0, 0.0)
    assert np.all(np.abs(np.abs(f.aop_deg) - 90.0) < 0.5)


def test_describe_and_make_sky():
    sky = make_sky("aerosol", preset="maritime_clean", aod_550=0.1, wavelength_nm=550.0)
    d = sky.describe()
    assert d["model"] == "aerosol" and d["aerosol"]["name"] == "maritime_clean"
    assert d["aod"] == pytest.approx(0.1)
    assert 0.9 < d["aerosol_ssa"] <= 1.0


@pytest.mark.parametrize("kwargs, match", [
    ({"preset": "volcanic"}, "unknown aerosol preset 'volcanic'"),
    ({"aod_550": -0.1}, "aod_550"),
    ({"aod_550": 3.0}, "aod_550"),
    ({"albedo": 1.5}, "albedo"),
    ({"wavelength_nm": 1200.0}, "wavelength_nm"),
    ({"sun_step_deg": 0.0}, "sun_step_deg"),
])
def test_bad_input_names_the_value(kwargs, match):
    with pytest.raises(ValueError, match=match):
        AerosolSky(**kwargs)


def test_aerosol_type_rejects_bad_components():
    with pytest.raises(InvalidParameterError, match="number density"):
        aerosol.AerosolType("x", ((aerosol_type("urban").components[0][0], -1.0),), 2.0)
