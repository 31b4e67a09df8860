"""Band-integrated skies (skysim.spectral) against a fine-wavelength sum, closed-form limits
and bad input."""

import numpy as np
import pytest
from scipy.integrate import trapezoid

from skysim.exceptions import InvalidParameterError
from skysim.molecular import bodhaine_depolarization_ratio, bodhaine_optical_thickness
from skysim.rayleigh import scattering_angle_deg, slab_transmission
from skysim.sky import RayleighSky, Sky
from skysim.spectral import (BESSELL_BANDS, SpectralResponse, band_sky, blackbody_spectrum,
                             get_response)


class ThinRayleighSlab(Sky):
    """Single scattering below a molecular slab at one wavelength, in the unit of an incident
    flux pi: ``I = P11 h / 4``, polarized ``-P12 h / 4`` perpendicular to the scattering plane,
    with the depolarized Rayleigh phase matrix (Hansen & Travis 1974, eq. 2.15) and the slab
    factor ``h`` of :func:`skysim.rayleigh.slab_transmission`; tau and the depolarization
    ratio from Bodhaine et al. (1999). A closed-form sky that changes with wavelength."""

    name = "thin rayleigh slab"

    def __init__(self, wavelength_nm):
        self.tau = float(bodhaine_optical_thickness(wavelength_nm))
        rho = float(bodhaine_depolarization_ratio(wavelength_nm))
        self.gamma = rho / (2.0 - rho)

    def _stokes(self, vel, vaz, sel, saz):
        g = self.gamma
        c2 = np.cos(np.radians(scattering_angle_deg(vel, vaz, sel, saz))) ** 2
        p11 = 3.0 / (4.0 * (1.0 + 2.0 * g)) * ((1.0 + 3.0 * g) + (1.0 - g) * c2)
        p12 = -3.0 / (4.0 * (1.0 + 2.0 * g)) * (1.0 - g) * (1.0 - c2)
        h = slab_transmission(self.tau, np.sin(np.radians(vel)), np.sin(np.radians(sel)))
        aop = RayleighSky().field(vel, vaz, sel, saz).aop_deg
        pol = -p12 * h / 4.0
        return (p11 * h / 4.0, pol * np.cos(np.radians(2 * aop)),
                pol * np.sin(np.radians(2 * aop)))

    def flux_pi_scale(self, view_elevation_deg, sun_elevation_deg):
        return np.ones(np.broadcast_shapes(np.shape(view_elevation_deg),
                                           np.shape(sun_elevation_deg)))


EL, AZ = np.meshgrid(np.arange(5.0, 90.1, 5.0), np.arange(0.0, 360.0, 15.0))
SUN = (30.0, 120.0)


def _fine_sum(response, step_nm=0.25):
    """Eq. [1] of skysim.spectral by the trapezoid rule on a fine grid, one sky per step."""
    lam = np.arange(response.wavelength_nm[0], response.wavelength_nm[-1] + 1e-9, step_nm)
    w = np.interp(lam, response.wavelength_nm, response.response) * blackbody_spectrum(lam)
    s = np.array([[getattr(f, k) for k in "IQU"] for f in (
        ThinRayleighSlab(x).field(EL, AZ, *SUN) for x in lam)])        # (m, 3, ...)
    return trapezoid(w[:, None, None, None] * s, lam, axis=0) / trapezoid(w, lam)


@pytest.mark.parametrize("band", ["B", "V", "R"])
def test_band_sky_matches_a_fine_wavelength_sum(band):
    """Eight Chebyshev nodes (the default) against 0.25-nm steps over the band (about 1,000
    skies). Tolerances: 1e-4 relative in I and in the polarized radiance, 1e-5 in DoP. The
    error is the polynomial interpolation's in the wavenumber; measured 2.3e-5 in I and 1.2e-7
    in DoP for B (at 5 deg elevation, where the slant optical path at the band's blue edge
    reaches 14), 1e-7 for V; it falls tenfold per two nodes (3e-4 with six). The fine sum's
    own error (trapezoid at 0.25 nm against 0.125 nm) is below 1e-8."""
    response = get_response(band)
    ref = _fine_sum(response)
    f = band_sky(ThinRayleighSlab, response).field(EL, AZ, *SUN)
    np.testing.assert_allclose(f.I, ref[0], rtol=1e-4)
    np.testing.assert_allclose(np.hypot(f.Q, f.U), np.hypot(ref[1], ref[2]), rtol=1e-4)
    np.testing.assert_allclose(f.dop, np.hypot(ref[1], ref[2]) / ref[0], atol=1e-5)
    # a broad band differs from its central wavelength by far more than the tolerance
    mono = ThinRayleighSlab(BESSELL_BANDS[band][0]).field(EL, AZ, *SUN)
    assert np.max(np.abs(mono.I / ref[0] - 1.0)) > 20 * 1e-4


def test_narrow_band_is_the_monochromatic_sky():
    # a 0.2 nm wide band at 500 nm: tau changes by 0.16 % across it, the band mean by 1e-5
    narrow = SpectralResponse.gaussian(500.0, 0.2)
    f = band_sky(ThinRayleighSlab, narrow, n_nodes=3).field(EL, AZ, *SUN)
    mono = ThinRayleighSlab(500.0).field(EL, AZ, *SUN)
    np.testing.assert_allclose(f.I, mono.I, rtol=2e-5)
    np.testing.assert_allclose(f.dop, mono.dop, atol=1e-7)


def test_wavelength_independent_sky_is_unchanged():
    """The Rayleigh sky has no wavelength: the band sky is it in the unit of a flux pi."""
    sky = RayleighSky(0.7)
    f = band_sky(lambda lam: sky, "V").field(EL, AZ, *SUN)
    ref = sky.field(EL, AZ, *SUN)
    scale = sky.flux_pi_scale(EL, SUN[0])
    np.testing.assert_allclose(f.I, ref.I / scale, rtol=1e-12)
    np.testing.assert_allclose(f.dop, ref.dop, atol=1e-12)
    np.testing.assert_allclose(f.aop_deg, ref.aop_deg, atol=1e-9)


def test_weights_integrate_polynomials_exactly():
    """Product integration is exact for a sky that is a polynomial of degree < n in the
    wavenumber 1 / lambda."""
    resp = SpectralResponse(np.array([400.0, 420.0, 470.0, 500.0]),
                            np.array([0.0, 1.0, 0.6, 0.0]))      # a filter with sharp edges
    nodes, w = resp.weights(5)
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    poly = np.array([3.0, -2.0, 0.5, 1.0, -0.7])                  # degree 4 in x
    x = lambda lam: 450.0 / lam                                  # noqa: E731
    lam = np.union1d(resp.wavelength_nm, np.linspace(400.0, 500.0, 2001))
    wr = np.interp(lam, resp.wavelength_nm, resp.response) * blackbody_spectrum(lam)
    exact = trapezoid(wr * np.polyval(poly, x(lam)), lam) / trapezoid(wr, lam)
    assert np.dot(w, np.polyval(poly, x(nodes))) == pytest.approx(exact, rel=1e-10)


def test_band_sky_describes_itself():
    d = band_sky(ThinRayleighSlab, "B", n_nodes=4).describe()
    assert d["model"] == "band" and d["band"] == "B" and len(d["nodes_nm"]) == 4
    assert sum(d["weights"]) == pytest.approx(1.0)


@pytest.mark.parametrize("make, match", [
    (lambda: SpectralResponse([500.0, 490.0], [1.0, 1.0]), "490 nm follows 500 nm"),
    (lambda: SpectralResponse([400.0, 500.0], [1.0, -0.1]), "response must be >= 0"),
    (lambda: SpectralResponse([400.0, 500.0], [0.0, 0.0]), "not all 0"),
    (lambda: SpectralResponse([400.0, np.nan], [1.0, 1.0]), "wavelength_nm"),
    (lambda: SpectralResponse.gaussian(500.0, -3.0), "positive FWHM"),
    (lambda: get_response("Z"), "unknown spectral band 'Z'"),
    (lambda: get_response("B").weights(0), "n_nodes must be >= 1"),
])
def test_bad_responses_are_refused(make, match):
    with pytest.raises(InvalidParameterError, match=match):
        make()


def test_response_from_csv(tmp_path):
    good = tmp_path / "filter.csv"
    good.write_text("wavelength_nm,response\n400,0\n450,1\n500,0\n")
    assert get_response(str(good)).name == "filter.csv"
    bad = tmp_path / "bad.csv"
    bad.write_text("lambda,r\n400,0\n")
    with pytest.raises(InvalidParameterError, match="bad.csv.*missing response, wavelength_nm"):
        get_response(bad)


# --------------------------------------------------------------------------- command line

@pytest.mark.slow
def test_sky_command_through_a_response(tmp_path, capsys):
    """``skysim sky --model multiple --response V`` writes the band sky of the Python API,
    its nodes and weights in the sidecar (8 engine runs, about 7 s of processor time, up to
    two minutes on a loaded machine)."""
    pytest.importorskip("sasktran2", reason="the multiple-scattering sky needs sasktran2")
    import json

    import pandas as pd

    from experiments.cli.main import main
    from skysim.multiple import MultipleScatteringSky
    out = tmp_path / "v.csv"
    assert main(["sky", "--model", "multiple", "--response", "V", "--albedo", "0.1",
                 "--sun-elevation", "30", "--sun-azimuth", "120", "--grid-step", "30",
                 "--out", str(out)]) == 0
    table = pd.read_csv(out)
    side = json.loads((tmp_path / "v.csv.json").read_text())
    assert side["sky"]["model"] == "band" and side["sky"]["band"] == "V"
    assert len(side["sky"]["nodes_nm"]) == 8
    ref = band_sky(lambda lam: MultipleScatteringSky(wavelength_nm=lam, albedo=0.1), "V").field(
        table.elevation_deg.to_numpy(), table.azimuth_deg.to_numpy(), 30.0, 120.0)
    np.testing.assert_allclose(table.I, ref.I, rtol=1e-12)
    np.testing.assert_allclose(table.dop, ref.dop, atol=1e-12)


@pytest.mark.parametrize("extra, needles", [
    (["--model", "multiple", "--response", "B", "--tau", "0.1"], ["--response B", "--tau"]),
    (["--model", "multiple", "--response", "Z"], ["unknown spectral band 'Z'"]),
    (["--model", "rayleigh", "--response", "B"], ["--response", "--model multiple or aerosol"]),
])
def test_sky_command_refuses_bad_responses(extra, needles, capsys):
    from test_cli_errors import _run_cli
    res = _run_cli(["sky", "--sun-elevation", "30", "--sun-azimuth", "10", *extra], capsys)
    assert res.code == 2 and res.clean and res.names(*needles), res.err
