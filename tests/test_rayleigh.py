"""Single-scattering Rayleigh sky: closed-form limits and geometric invariants."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skysim import rayleigh
from skysim.exceptions import InvalidParameterError, SunBelowHorizonError
from skysim.geometry import direction_vector, elevation_azimuth, wrap_axial_deg
from skysim.sky import RayleighSky, make_sky

elevations = st.floats(0.5, 89.5)
azimuths = st.floats(0.0, 359.99)


def test_dop_closed_form_limits():
    """d = d_max sin^2 g/(1+cos^2 g) (Yang et al. 2014 eq. 1): 0 at g = 0 and 180 deg,
    d_max at 90 deg, and (sin^2 60)/(1+cos^2 60) = 0.75/1.25 = 0.6 of d_max at 60 deg."""
    d = rayleigh.degree_of_polarization([0.0, 180.0, 90.0, 60.0], dmax=0.7)
    np.testing.assert_allclose(d, [0.0, 0.0, 0.7, 0.42], atol=1e-15)


def test_dop_zero_at_sun_and_dmax_at_90_from_it():
    sky = RayleighSky(dmax=0.8)
    f = sky.field([30.0, 60.0], [120.0, 300.0], 30.0, 120.0)   # at the sun; 90 deg from it
    np.testing.assert_allclose(f.dop, [0.0, 0.8], atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(sun_el=elevations, sun_az=azimuths, view_az=azimuths)
def test_zenith_e_vector_perpendicular_to_solar_meridian(sun_el, sun_az, view_az):
    """DESIGN.md invariant: at the zenith the E-vector is perpendicular to the solar meridian,
    whatever meridian (view azimuth) the AoP is referred to."""
    f = RayleighSky().field(90.0, view_az, sun_el, sun_az)
    e = f.e_vector
    sun_horizontal = direction_vector(0.0, sun_az)
    assert abs(np.dot(e, sun_horizontal)) < 1e-9
    assert abs(e[2]) < 1e-9


@settings(max_examples=200, deadline=None)
@given(v_el=elevations, v_az=azimuths, s_el=elevations, s_az=azimuths)
def test_e_vector_perpendicular_to_view_and_sun(v_el, v_az, s_el, s_az):
    e = rayleigh.e_vector(v_el, v_az, s_el, s_az)
    if np.isnan(e).any():  # view parallel to the sun: undefined, DoP 0
        return
    assert abs(np.dot(e, direction_vector(v_el, v_az))) < 1e-9
    assert abs(np.dot(e, direction_vector(s_el, s_az))) < 1e-9


@settings(max_examples=200, deadline=None)
@given(v_el=elevations, v_az=azimuths, s_el=elevations, s_az=azimuths)
def test_stokes_consistent_with_dop_and_aop(v_el, v_az, s_el, s_az):
    f = RayleighSky(dmax=0.75).field(v_el, v_az, s_el, s_az)
    gamma = rayleigh.scattering_angle_deg(v_el, v_az, s_el, s_az)
    assert f.dop == pytest.approx(rayleigh.degree_of_polarization(gamma, 0.75), abs=1e-12)
    if f.dop > 1e-6:
        aop = rayleigh.angle_of_polarization_deg(v_el, v_az, s_el, s_az)
        assert abs(wrap_axial_deg(f.aop_deg - aop)) < 1e-6


def test_aop_reference_and_sense():
    """Closed-form cases of the documented convention (AoP from the local meridian):
    - in the solar vertical plane the E-vector is horizontal: AoP = -90 (== +90);
    - sun on the horizon (el -> 0), view on the horizon 90 deg from it: the scattering plane
      is horizontal, E is vertical, along the meridian: AoP = 0;
    - sense: view north at 45 deg, sun east at 45 deg: E ~ v x s = (1, 1, -1)/sqrt3, whose
      components on e_el = (0, -1, 1)/sqrt2 and e_az = (1, 0, 0) give
      atan2(1/sqrt3, -sqrt(2/3)) = 144.74 deg -> -35.26 deg."""
    aop = rayleigh.angle_of_polarization_deg([40.0, 40.0], [200.0, 20.0], 30.0, 200.0)
    np.testing.assert_allclose(aop, [-90.0, -90.0], atol=1e-9)
    assert rayleigh.angle_of_polarization_deg(1.0, 90.0, 1e-6, 0.0) == pytest.approx(0.0, abs=1e-4)
    expected = wrap_axial_deg(np.degrees(np.arctan2(1 / np.sqrt(3), -np.sqrt(2 / 3))))
    assert rayleigh.angle_of_polarization_deg(45.0, 0.0, 45.0, 90.0) == pytest.approx(expected)
    assert expected == pytest.approx(-35.264, abs=1e-3)


def test_broadcasting_over_shapes():
    el = np.linspace(1, 89, 12).reshape(3, 4)
    f = RayleighSky(0.7).field(el[..., None], np.array([0.0, 90.0]), 25.0, 270.0)
    assert f.dop.shape == (3, 4, 2) and f.e_vector.shape == (3, 4, 2, 3)


def test_geometry_round_trip():
    rng = np.random.default_rng(0)
    el, az = rng.uniform(-89, 89, 100), rng.uniform(0, 360, 100)
    el2, az2 = elevation_azimuth(direction_vector(el, az))
    np.testing.assert_allclose(el2, el, atol=1e-10)
    np.testing.assert_allclose(az2, az, atol=1e-9)


def test_bad_input():
    with pytest.raises(SunBelowHorizonError, match="-12.0"):
        RayleighSky().field(90.0, 0.0, -12.0, 100.0)
    with pytest.raises(InvalidParameterError, match="view_elevation_deg"):
        RayleighSky().field(-5.0, 0.0, 20.0, 100.0)
    with pytest.raises(InvalidParameterError, match="dmax"):
        RayleighSky(dmax=1.2)
    with pytest.raises(InvalidParameterError, match="dmax"):
        RayleighSky(dmax=0.0)
    with pytest.raises(InvalidParameterError, match="nan"):
        RayleighSky().field(np.nan, 0.0, 20.0, 100.0)
    with pytest.raises(ValueError, match="valid: aerosol, berry, multiple, rayleigh"):
        make_sky("mie")


def test_twilight_sky_keeps_the_rayleigh_pattern():
    """Sun 6 deg below the horizon (civil twilight): the single-scattering closed forms still
    hold (DoP = d_max at 90 deg from the sun, the zenith E-vector perpendicular to the solar
    meridian), and the model refuses a sun below -10 deg."""
    f = RayleighSky(dmax=0.8).field(84.0, 0.0, -6.0, 0.0)      # 90 deg from the sun
    np.testing.assert_allclose(f.dop, 0.8, atol=1e-12)
    z = RayleighSky().field(90.0, 0.0, -6.0, 275.0)
    np.testing.assert_allclose(np.abs(z.e_vector @ direction_vector(0.0, 275.0)), 0.0,
                               atol=1e-12)
    with pytest.raises(SunBelowHorizonError, match="twilight"):
        RayleighSky().field(90.0, 0.0, -10.5, 0.0)

def _vector_reference(v_el, v_az, s_el, s_az, dmax):
    """The field from ENU vectors and the cross product, independent of the meridian-component
    formulas: gamma = angle(v, s), DoP by eq. 1 of Yang et al. 2014, E = v x s projected on the
    local basis (geometry.local_basis)."""
    from skysim.geometry import angle_between_deg, local_basis
    v, e_el, e_az = local_basis(v_el, v_az)
    s = np.broadcast_to(direction_vector(s_el, s_az), v.shape)
    gamma = angle_between_deg(v, s)
    e = np.cross(v, s)
    chi = np.degrees(np.arctan2(np.sum(e * e_az, axis=-1), np.sum(e * e_el, axis=-1)))
    dop = rayleigh.degree_of_polarization(gamma, dmax)
    intensity = rayleigh.relative_radiance(gamma)
    q = intensity * dop * np.cos(np.radians(2 * chi))
    u = intensity * dop * np.sin(np.radians(2 * chi))
    return intensity, q, u, dop, wrap_axial_deg(chi), gamma


def _field_cases(n=200_000, seed=11):
    rng = np.random.default_rng(seed)
    v_el, v_az = rng.uniform(0, 90, n), rng.uniform(-360, 720, n)
    s_el, s_az = rng.uniform(0.01, 89.99, n), rng.uniform(0, 360, n)
    # zenith, horizon, the solar meridian (both sides), 90 deg away, and the sun itself
    v_el[:6], v_az[:6] = [90.0, 0.0, 40.0, 40.0, 0.0, 30.0], [17.0, 95.0, 200.0, 20.0, 5.0, 120.0]
    s_el[:6], s_az[:6] = [30.0, 0.001, 30.0, 30.0, 45.0, 30.0], [17.0, 5.0, 200.0, 200.0, 95.0,
                                                                   120.0]
    return v_el, v_az, s_el, s_az


def test_meridian_component_field_equals_vector_formulation():
    """The field from (a, b) agrees with the cross-product formulation to 1e-12 in I, Q, U and
    DoP and to 1e-9 deg in AoP (axially; AoP compared where DoP > 1e-6, nearer the sun both
    are rounding noise). Both are exact formulas; the tolerance is float64 rounding."""
    v_el, v_az, s_el, s_az = _field_cases()
    f = rayleigh.polarization_field(v_el, v_az, s_el, s_az, 0.7)
    ref = _vector_reference(v_el, v_az, s_el, s_az, 0.7)
    for key, r in zip(("I", "Q", "U", "dop"), ref):
        np.testing.assert_allclose(f[key], r, rtol=0, atol=1e-12, err_msg=key)
    defined = ref[3] > 1e-6
    assert np.all(np.abs(wrap_axial_deg(f["aop_deg"] - ref[4]))[defined] < 1e-9)
    assert np.all((f["aop_deg"] >= -90.0) & (f["aop_deg"] < 90.0))
    assert f["aop_deg"][5] == 0.0 and f["dop"][5] == 0.0  # at the sun: 0, not NaN
    np.testing.assert_allclose(f["aop_deg"][2:4], [-90.0, -90.0], atol=1e-9)  # solar meridian


def test_float32_path_within_its_stated_bound():
    """float32: |dDoP| <= FLOAT32_DOP_ERROR everywhere; |dAoP| <= FLOAT32_AOP_ERROR_DEG beyond
    FLOAT32_MIN_SCATTERING_ANGLE_DEG from the sun and anti-sun, on 200,000 random directions
    and suns (plus the special cases) against the float64 vector formulation."""
    v_el, v_az, s_el, s_az = _field_cases(seed=12)
    f32 = rayleigh.polarization_field(v_el, v_az, s_el, s_az, 0.7, np.float32)
    assert f32["dop"].dtype == np.float32 and f32["aop_deg"].dtype == np.float32
    _, _, _, dop, aop, gamma = _vector_reference(v_el, v_az, s_el, s_az, 0.7)
    assert np.max(np.abs(f32["dop"] - dop)) <= rayleigh.FLOAT32_DOP_ERROR
    margin = rayleigh.FLOAT32_MIN_SCATTERING_ANGLE_DEG
    far = (gamma >= margin) & (gamma <= 180.0 - margin)
    assert far.mean() > 0.99
    d_aop = np.abs(wrap_axial_deg(f32["aop_deg"].astype(float) - aop))[far]
    assert d_aop.max() <= rayleigh.FLOAT32_AOP_ERROR_DEG


def test_float32_sky_and_dtype_choice():
    f = RayleighSky(0.7, dtype="float32").field([10.0, 50.0], [0.0, 90.0], 30.0, 180.0)
    assert f.I.dtype == np.float32 and f.dop.dtype == np.float32
    assert RayleighSky(0.7, dtype="float32").describe()["dtype"] == "float32"
    with pytest.raises(ValueError, match="float64, float32"):
        RayleighSky(0.7, dtype="float16")
    with pytest.raises(ValueError, match="float64, float32"):
        RayleighSky(0.7, dtype="double-ish")


def test_separate_grid_and_sun_axes_equal_full_broadcast():
    """A (1, N) grid against (T, 1) suns (the sun's vector path) gives the numbers of the
    broadcast inputs (one tangent of the azimuth difference) to float64 rounding."""
    rng = np.random.default_rng(3)
    el, az = rng.uniform(0, 90, 50), rng.uniform(0, 360, 50)
    sel, saz = rng.uniform(1, 80, 7), rng.uniform(0, 360, 7)
    sky = RayleighSky(0.6)
    f = sky.field(el[None, :], az[None, :], sel[:, None], saz[:, None])
    full = [np.broadcast_to(x, (7, 50)).copy() for x in (el[None], az[None], sel[:, None],
                                                          saz[:, None])]
    g = sky.field(*full)
    for name in ("I", "Q", "U", "dop", "aop_deg"):
        np.testing.assert_allclose(getattr(f, name), getattr(g, name), rtol=0, atol=1e-12)
    assert f.view_elevation_deg.shape == (7, 50)


def test_cos_sin_from_half_angle_tangent():
    """cos/sin from t = tan(x/2) agree with np.cos/np.sin to 4.5e-16 (2 ulp of 1) in float64,
    at every angle including the multiples of 90 deg, and keep 0-d inputs 0-d."""
    from skysim.geometry import cos_sin_deg
    x = np.concatenate([np.arange(-720.0, 721.0, 45.0),
                        np.random.default_rng(0).uniform(-720, 720, 100_000)])
    c, s = cos_sin_deg(x)
    assert np.max(np.abs(c - np.cos(np.radians(x)))) <= 4.5e-16
    assert np.max(np.abs(s - np.sin(np.radians(x)))) <= 4.5e-16
    c0, s0 = cos_sin_deg(60.0)
    assert c0.shape == () and c0 == pytest.approx(0.5, abs=1e-16)


def test_stokes_from_sun_projections_matches_meridian_field():
    # in the local meridian basis (e_el, e_az) (right-handed about the ray) the dot-product
    # form equals polarization_field (itself tested against the vector formulation)
    from skysim.geometry import direction_vector, local_basis
    rng = np.random.default_rng(8)
    el, az = rng.uniform(0, 90, 2000), rng.uniform(0, 360, 2000)
    sun_el, sun_az = 27.0, 211.0
    v, e_el, e_az = local_basis(el, az)
    np.testing.assert_allclose(np.cross(e_el, e_az), v, atol=1e-15)
    s = direction_vector(sun_el, sun_az)
    i, q, u = rayleigh.stokes_from_sun_projections(e_el @ s, e_az @ s, 0.7)
    ref = rayleigh.polarization_field(el, az, sun_el, sun_az, 0.7)
    for a, b in ((i, ref["I"]), (q, ref["Q"]), (u, ref["U"])):
        np.testing.assert_allclose(a, b, atol=1e-14)
