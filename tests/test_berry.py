"""Berry, Dennis & Lee (2004) singularity sky: Rayleigh limit, singularities, index 1/2."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skysim import rayleigh
from skysim.berry import BerrySky, berry_polarization, singularities, stereographic
from skysim.exceptions import InvalidParameterError
from skysim.geometry import wrap_axial_deg
from skysim.sky import make_sky


@settings(max_examples=60, deadline=None)
@given(el=st.floats(0, 90), az=st.floats(0, 360), sel=st.floats(0.5, 89.5),
       saz=st.floats(0, 360), dmax=st.floats(0.1, 1.0))
def test_delta_zero_is_the_rayleigh_sky(el, az, sel, saz, dmax):
    """[1]: with coincident singularities |w| = sin^2 g, so the DoP dmax |w|/(2 - |w|) is the
    Rayleigh dmax sin^2 g/(1 + cos^2 g) (2 - sin^2 g = 1 + cos^2 g) and the AoP is the closed
    form of skysim.rayleigh (checks the stereographic frame and the AoP reference and sense).
    Tolerance 1e-12 in DoP: an algebraic identity, evaluated in float64 (measured 2e-15);
    1e-6 deg in AoP (arg and arctan2 of the two closed forms near g = 1 deg)."""
    g = rayleigh.scattering_angle_deg(el, az, sel, saz)
    dop, aop = berry_polarization(el, az, sel, saz, 0.0, dmax)
    assert dop == pytest.approx(float(rayleigh.degree_of_polarization(g, dmax)), abs=1e-12)
    if 1.0 < g < 179.0:  # the AoP is undefined at the sun and anti-sun
        ref = rayleigh.angle_of_polarization_deg(el, az, sel, saz)
        assert abs(float(wrap_axial_deg(aop - ref))) < 1e-6


@settings(max_examples=40, deadline=None)
@given(sel=st.floats(-10.0, 89.0), saz=st.floats(0, 360), dmax=st.floats(0.1, 1.0),
       delta=st.floats(1e-4, 0.3))
def test_small_delta_tends_to_the_rayleigh_dop(sel, saz, dmax, delta):
    """Limit delta -> 0 of the DoP over the whole sky (upper hemisphere, 1 deg grid): the
    two pairs split symmetrically about the sun and the anti-sun, so the first-order change
    cancels and |DoP(delta) - dmax sin^2 g/(1 + cos^2 g)| <= dmax delta^2 (delta in rad;
    the measured maximum is 0.50 dmax delta^2 for every sun elevation)."""
    el, az = np.meshgrid(np.linspace(0.0, 90.0, 91), np.linspace(0.0, 359.0, 360))
    g = rayleigh.scattering_angle_deg(el, az, sel, saz)
    dop, _ = berry_polarization(el, az, sel, saz, delta, dmax)
    err = np.max(np.abs(dop - rayleigh.degree_of_polarization(g, dmax)))
    assert err <= dmax * np.radians(delta) ** 2


def _singular_directions(sel, saz, delta):
    """(elevation, azimuth) [deg] of Babinet, Brewster, Arago and the fourth point: Babinet
    and Brewster delta/2 above and below the sun on its vertical (Babinet continues over the
    zenith to the opposite azimuth), Arago and the fourth point their antipodes."""
    bab_el, bab_az = sel + delta / 2, saz
    if bab_el > 90.0:
        bab_el, bab_az = 180.0 - bab_el, saz + 180.0
    bre_el = sel - delta / 2
    return np.array([(bab_el, bab_az), (bre_el, saz), (-bre_el, saz + 180.0),
                     (-bab_el, bab_az + 180.0)])


@settings(max_examples=60, deadline=None)
@given(sel=st.floats(-10.0, 89.0), saz=st.floats(0, 360), delta=st.floats(1.0, 89.0),
       dmax=st.floats(0.1, 1.0))
def test_zero_dop_at_the_four_singularities(sel, saz, delta, dmax):
    """[1]: the DoP vanishes at Babinet, Brewster, Arago and the fourth point, wherever the
    sun and whatever delta, and not at the sun (for delta >= 1 deg). Tolerance 1e-9: the
    directions pass through degrees, tan and exp (1e-14 rad) and |w| grows linearly away
    from a zero."""
    pts = _singular_directions(sel, saz, delta)
    if abs(pts[0, 0]) > 89.999:  # Babinet at the zenith: the fourth point at the nadir
        return
    dop, _ = berry_polarization(pts[:, 0], pts[:, 1], sel, saz, delta, dmax)
    np.testing.assert_allclose(dop, 0.0, atol=1e-9)
    sun_dop, _ = berry_polarization(sel, saz, sel, saz, delta, dmax)
    assert sun_dop > 0.0


def test_singularities_where_placed():
    """The stereographic positions of the four points are the directions delta/2 above and
    below the sun and their antipodes (sun at 10 deg: Brewster below the horizon)."""
    sel, saz, delta = 10.0, 120.0, 40.0
    s = singularities(sel, saz, delta)
    assert np.isclose(s["arago"], stereographic(10.0, saz + 180.0))
    assert np.isclose(s["brewster"], stereographic(-10.0, saz))
    assert np.isclose(s["fourth"], stereographic(-30.0, saz + 180.0))


def test_singularities_have_index_one_half():
    """[1]: each neutral point is an index +1/2 singularity: the AoP turns by +-180 deg
    (not 360 as around the Rayleigh sun) on a small loop around it."""
    sel, saz, delta = 30.0, 0.0, 40.0
    t = np.linspace(0, 2 * np.pi, 721)
    el = 50.0 + 2.0 * np.sin(t)
    az = np.degrees(2.0 * np.cos(t) / np.cos(np.radians(el)))
    # AoP relative to a fixed (north-pointing) axis near the point: meridian basis rotates
    # negligibly on this loop (az within a few degrees)
    _, aop = berry_polarization(el, az, sel, saz, delta)
    turn = np.sum(wrap_axial_deg(np.diff(aop)))
    assert abs(abs(turn) - 180.0) < 5.0
    _, aop0 = berry_polarization(el, az, 50.0, 0.0, 0.0)  # Rayleigh: sun inside the loop
    assert abs(abs(np.sum(wrap_axial_deg(np.diff(aop0)))) - 360.0) < 5.0


def test_berry_sky_interface_and_bad_input():
    sky = make_sky("berry", delta_deg=30.0, dmax=0.7)
    assert isinstance(sky, BerrySky)
    f = sky.field(np.array([30.0, 60.0]), np.array([0.0, 200.0]), 20.0, 90.0)
    assert np.all((f.dop >= 0) & (f.dop <= 0.7))
    assert sky.describe() == {"model": "berry", "delta_deg": 30.0, "dmax": 0.7,
                              "dop": "dmax |w| / (2 - |w|)",
                              "I": "relative single-scattering radiance (3/4)(1 + cos^2 g)"}
    with pytest.raises(InvalidParameterError, match="delta_deg"):
        BerrySky(delta_deg=-1.0)
    with pytest.raises(InvalidParameterError, match="dmax"):
        BerrySky(dmax=1.5)


def test_zenith_e_vector_perpendicular_to_solar_meridian():
    sky = BerrySky(40.0)
    f = sky.field(90.0, np.array([0.0, 45.0, 300.0]), 25.0, 70.0)
    sun_h = np.array([np.sin(np.radians(70.0)), np.cos(np.radians(70.0)), 0.0])
    np.testing.assert_allclose(f.e_vector @ sun_h, 0.0, atol=1e-9)


def test_cli_sky_berry(tmp_path):
    from experiments.cli.main import main
    out, png = tmp_path / "berry.parquet", tmp_path / "berry.png"
    assert main(["sky", "--model", "berry", "--delta-deg", "30", "--dmax", "0.8",
                 "--sun-elevation", "20", "--sun-azimuth", "90", "--grid-step", "10",
                 "--out", str(out), "--plot", str(png)]) == 0
    import pandas as pd
    t = pd.read_parquet(out)
    assert len(t) == 10 * 36 and t.dop.max() <= 0.8 + 1e-12 and png.stat().st_size > 10_000


def test_continuous_when_babinet_crosses_the_zenith():
    """Sun higher than 90 - delta/2: the fourth point passes through the nadir (infinity);
    the pattern must stay continuous (no 90 deg AoP jump, no NaN)."""
    el, az = np.array([60.0, 30.0, 10.0]), np.array([10.0, 200.0, 100.0])
    below = berry_polarization(el, az, 69.999, 0.0, 40.0)
    at = berry_polarization(el, az, 70.0, 0.0, 40.0)
    above = berry_polarization(el, az, 70.001, 0.0, 40.0)
    for a, b in [(below, at), (at, above)]:
        np.testing.assert_allclose(a[0], b[0], atol=1e-4)
        np.testing.assert_allclose(wrap_axial_deg(a[1] - b[1]), 0.0, atol=0.01)
    assert singularities(70.0, 0.0, 40.0)["fourth"] == np.inf


def test_dop_reaches_dmax_where_w_is_one():
    """|w| = 1 at 90 deg from a sun at the zenith (delta = 0: |w| = sin^2 90 deg), where
    |w|/(2 - |w|) = 1 gives dmax; |w| = 1/2 at 45 deg gives (1/2)/(3/2) = 1/3, the Rayleigh
    sin^2 45/(1 + cos^2 45). Closed forms, 1e-9 (sun 1e-9 deg off the zenith)."""
    d, _ = berry_polarization(np.array([0.0, 45.0]), 0.0, 90.0 - 1e-9, 0.0, 0.0, 0.8)
    np.testing.assert_allclose(d, [0.8, 0.8 / 3.0], atol=1e-9)


def test_berry_in_twilight_keeps_the_zenith_e_vector():
    """Sun 5 deg below the horizon: the zenith E-vector stays perpendicular to the solar
    meridian (the singularities sit symmetrically on it), as in daylight."""
    import numpy as np
    from skysim.berry import BerrySky
    from skysim.geometry import direction_vector
    f = BerrySky().field(90.0, 0.0, -5.0, 120.0)
    assert abs(float(f.e_vector.reshape(-1, 3)[0] @ direction_vector(0.0, 120.0))) < 1e-9


def test_e_vector_turns_at_the_neutral_points_on_the_solar_vertical():
    """On the solar vertical the pattern is mirror-symmetric, so the E-vector is parallel or
    perpendicular to it; each index-1/2 point on it swaps the two [1]: parallel (AoP 0)
    between Brewster and Babinet around the sun, perpendicular (AoP -90) above Babinet,
    below Brewster and all along the anti-solar half above Arago, as in the Rayleigh sky
    (delta = 0) everywhere. Sun at 30 deg, delta 40: Babinet at 50, Brewster at 10, Arago at
    -10 deg on the anti-solar side. Exact by symmetry (1e-9 deg)."""
    el = np.array([70.0, 45.0, 30.0, 15.0, 0.0, 0.0, 30.0, 60.0])
    az = np.array([100.0] * 5 + [280.0] * 3)
    _, aop = berry_polarization(el, az, 30.0, 100.0, 40.0)
    np.testing.assert_allclose(aop, [-90, 0, 0, 0, -90, -90, -90, -90], atol=1e-9)
    _, aop0 = berry_polarization(el, az, 30.0, 100.0, 0.0)
    np.testing.assert_allclose(np.delete(aop0, 2), -90.0, atol=1e-9)   # the sun itself: undefined


@settings(max_examples=40, deadline=None)
@given(sel=st.floats(-10.0, 60.0), saz=st.floats(0, 360), delta=st.floats(0.5, 59.0))
def test_w_equals_the_published_product_form(sel, saz, delta):
    """berry_w writes the antipodal factors in a form that stays finite at the nadir; where
    Babinet is below the zenith (sun under 90 - delta/2, as drawn here) it must equal the
    published product, -4 prod(zeta - zeta_k) / ((1 + |zeta|^2)^2 |zeta_Bab - zeta_4|
    |zeta_Bre - zeta_Ara|) with zeta_Ara = -1/conj(zeta_Bre), zeta_4 = -1/conj(zeta_Bab)
    (the form of the public implementations, e.g. OpenSky's Simu_Berry). Tolerance 1e-12
    (|w| <= 1; rounding of the two algebraically equal forms, measured 1e-15)."""
    from skysim.berry import berry_w
    el, az = np.meshgrid(np.linspace(-30.0, 90.0, 25), np.linspace(0.0, 350.0, 36))
    zeta = stereographic(el, az)
    u = np.exp(1j * np.radians(90.0 - saz))
    bab = np.tan(np.radians(90.0 - sel - delta / 2) / 2) * u
    bre = np.tan(np.radians(90.0 - sel + delta / 2) / 2) * u
    ara, fourth = -1 / np.conj(bre), -1 / np.conj(bab)
    published = (-4 * (zeta - bab) * (zeta - bre) * (zeta - ara) * (zeta - fourth)
                 / ((1 + np.abs(zeta) ** 2) ** 2 * np.abs(bab - fourth) * np.abs(bre - ara)))
    np.testing.assert_allclose(berry_w(zeta, sel, saz, delta), published, rtol=0, atol=1e-12)
