"""The real sky's DoP profile in the photodiode diagnosis: geometry read from the angle of
polarization (the DoP profiled out), and the candidates that explain the profile.

A sky whose DoP profile differs from single scattering while its AoP is the Rayleigh pattern
(as the real sky's is away from the neutral points) must not move the fitted unit pointing:
a fit of the full model with free pointing trades the DoP misfit for a false elevation, the
two-stage fit does not.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from calibration.photodiode_diagnosis import instrument_from_photodiodes
from calibration.photodiode_diagnosis.effects import get_ring_effect
from calibration.photodiode_diagnosis.fit import fit, fit_pinned
from calibration.photodiode_diagnosis.forward import Forward, SunTrack
from calibration.photodiode_diagnosis.run import orient, solar_noon_s
from sensor.compound_eye import ring_configuration
from sensor.photodiodes_io import PhotodiodeData
from skysim import rayleigh
from skysim.sky import RayleighSky, Sky
from skysim.sun import Site

SITE = Site(39.258648, 8.440184, 0.0)


class FlatDopSky(Sky):
    """Rayleigh AoP, DoP ``dmax * sqrt(p_R)``: more polarized near the sun and flatter than
    single scattering (at 30 deg from the sun 0.6 * 0.35 = 0.21 where Rayleigh gives 0.07),
    as the measured sky is."""

    name = "flat"

    def _stokes(self, vel, vaz, sel, saz):
        g = rayleigh.scattering_angle_deg(vel, vaz, sel, saz)
        I, Q, U = RayleighSky(1.0)._stokes(vel, vaz, sel, saz)
        p = np.hypot(Q, U) / I
        k = 0.6 * np.sqrt(p) / np.maximum(p, 1e-12)
        return rayleigh.relative_radiance(g), Q / I * k * rayleigh.relative_radiance(g), \
            U / I * k * rayleigh.relative_radiance(g)


def flat_sky_session(n_sweeps=3, per_sweep=120, start="2022-05-12T10:00:00+02:00", seed=4):
    rng = np.random.default_rng(seed)
    sensor = ring_configuration(8, 45.0)
    t0 = pd.Timestamp(start)
    times = pd.DatetimeIndex([t0 + pd.Timedelta(seconds=60 * s + 0.1 * k)
                              for s in range(n_sweeps) for k in range(per_sweep)])
    yaw = np.tile(np.linspace(0.0, 360.0, per_sweep, endpoint=False), n_sweeps)
    data = sensor.sample(FlatDopSky(), SITE, times, yaw, 0.0, 0.0, rng,
                         yaw_reference="relative", yaw_offset_deg=35.0, include_truth=False,
                         sweep=np.repeat(np.arange(n_sweeps), per_sweep))
    t = data.table.drop(columns=["pitch_deg", "roll_deg"])
    return PhotodiodeData(t, dict(data.sidecar))


@pytest.fixture(scope="module")
def flat():
    return instrument_from_photodiodes(flat_sky_session())


def _start(fwd):
    L = fwd.layout
    th = np.zeros(L.size)
    th[L.scale] = 0.6
    return orient(fwd, th)[1]


def test_aop_fit_is_blind_to_the_dop_profile(flat):
    """At the true geometry the DoP-free model reproduces readings of a sky with another DoP
    profile to the counts' rounding (relative 5e-4, as the base model does for its own sky),
    while the single-scattering DoP model misses them by percents."""
    fwd = Forward(flat)
    L = fwd.layout
    th = np.zeros(L.size)
    th[L.scale] = 0.6
    th[L.heading] = 35.0
    full = np.sqrt(np.mean(fwd.residual(th)[fwd.usable] ** 2))
    fwd.dop_free = True
    free = np.sqrt(np.mean(fwd.residual(th)[fwd.usable] ** 2))
    assert free < 5e-4
    assert full > 20 * free


def test_pointing_pinned_by_the_aop_not_the_dop_profile(flat):
    """Fitted with free pointing on the full model, the units' elevations take up the DoP
    misfit (several degrees off the true 45); fitted by :func:`fit_pinned`, they stay within
    0.5 deg (the pointing is read from the AoP; with 2,900 samples of 1e-4 quantisation
    noise its posterior SD is ~0.05 deg, the bound allows the AoP fit's 12 iterations)."""
    fwd = Forward(flat)
    L = fwd.layout
    th = _start(fwd)
    plain = fit(fwd, th, sigma=0.01, max_iter=25)
    pinned, aop = fit_pinned(fwd, th, sigma=0.01, max_iter=25)
    el_plain = plain.theta[L.pointing][:L.n_units]
    el_pinned = pinned.theta[L.pointing][:L.n_units]
    assert np.max(np.abs(el_plain)) > 2.0
    assert np.max(np.abs(el_pinned)) < 0.5
    np.testing.assert_array_equal(pinned.theta[L.pointing], aop.theta[L.pointing])


def test_neutral_points_candidate_reduces_to_base_at_null(flat):
    """Separation 0: the Berry sky with the ``|w| / (2 - |w|)`` mapping is the Rayleigh sky
    (2 - sin^2 g = 1 + cos^2 g), so the candidate's residuals equal the base's to rounding."""
    e = get_ring_effect("neutral_points")
    sun = SunTrack(flat.site, flat.t_s.min(), flat.t_s.max(), margin_s=0.0)
    base, ext = Forward(flat, sun=sun), Forward(flat, e, sun=sun)
    th = np.zeros(ext.layout.size)
    th[ext.layout.scale] = 0.6
    th[ext.layout.heading] = 35.0
    np.testing.assert_allclose(ext.residual(th), base.residual(th[:base.layout.size]),
                               atol=1e-9)


def test_solar_noon_matches_pvlib():
    """Culmination time against pvlib's SPA transit (NREL SPA, Reda & Andreas 2004) within
    30 s: the two ephemerides agree to ~0.01 deg, the sun's elevation is flat at noon, and
    the parabola refines the 60-s grid to a few seconds."""
    pvlib = pytest.importorskip("pvlib")
    t = pd.Timestamp("2022-05-12T09:00:00Z")
    sun = SunTrack(SITE, t.value / 1e9, t.value / 1e9, margin_s=15 * 3600.0)
    noon = solar_noon_s(sun, t.value / 1e9)
    tr = pvlib.solarposition.sun_rise_set_transit_spa(
        pd.DatetimeIndex([t.floor("D")]), SITE.latitude_deg, SITE.longitude_deg)
    ref = tr["transit"].iloc[0].tz_convert("UTC").value / 1e9
    assert abs(noon - ref) < 30.0


def test_aerosol_candidate_at_a_node_is_the_aerosol_sky():
    """At one of its AOD nodes the candidate's interpolated sky is the node's
    :class:`skysim.aerosol.AerosolSky` itself (weights 1 and 0: to rounding, 1e-12), and it
    is asked for by name, not run by default (its engine runs take minutes)."""
    pytest.importorskip("sasktran2")
    from calibration.photodiode_diagnosis.effects import RING_EFFECT_NAMES, GridAerosolSky
    assert "aerosol" not in RING_EFFECT_NAMES
    e = get_ring_effect("aerosol")
    rng = np.random.default_rng(2)
    el, az = rng.uniform(30, 60, 50), rng.uniform(0, 360, 50)
    sun = np.full(50, 35.0)
    grid = GridAerosolSky(None)
    f = grid.at(0.1).field(el, az, sun, 120.0)
    ref = grid.skies[1].field(el, az, sun, 120.0)
    assert grid.AOD_NODES[1] == 0.1
    np.testing.assert_allclose(f.I, ref.I, rtol=1e-12)
    np.testing.assert_allclose(f.dop, ref.dop, rtol=1e-12, atol=1e-15)
    assert e.k == 1 and e.parameter_names == ("aod_550",)
