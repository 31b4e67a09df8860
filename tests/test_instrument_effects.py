"""The ring's instrument candidates (``side_glare``, ``read_lag``): closed forms, reduction to
the base model at their null parameters, and recovery of their own effect planted in a
simulated ring by code that shares only the physics library with the fitter."""

import numpy as np
import pandas as pd
import pytest

from calibration.photodiode_diagnosis import diagnose_photodiodes, get_ring_effect
from calibration.photodiode_diagnosis.effects import lagged_yaw, sun_side
from calibration.photodiode_diagnosis.forward import Forward, SunTrack
from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes
from sensor.compound_eye import SkySample, body_attitude, ring_configuration
from sensor.photodiodes_io import PhotodiodeData
from skysim.sky import RayleighSky
from skysim.sun import Site, sun_vector

SITE = Site(39.258648, 8.440184, 0.0)
OFFSET_DEG = 35.0
"""True heading minus recorded yaw of the simulated sessions."""


def _stand_and_turn(seed=1, n_sweeps=6, start="2022-05-12T16:00:00+02:00", lag_s=0.0):
    """A ring (8 units x 0/45/90/135 at 45 deg elevation), sampled every 0.2 s: each sweep
    stands at five headings 90 deg apart (10 samples each) and turns between them at
    20.5 deg/s (22 samples; the real ring turns at 15-40 deg/s). ``lag_s``: the readings are
    those of the yaw recorded ``lag_s`` earlier (the record leads the converter)."""
    rng = np.random.default_rng(seed)
    t0 = pd.Timestamp(start)
    turn = np.linspace(0.0, 90.0, 23)[1:-1]
    one = np.concatenate([np.r_[np.full(10, 90.0 * k), 90.0 * k + turn] for k in range(4)]
                         + [np.full(10, 360.0)])
    yaw, times, sweep = [], [], []
    for s in range(n_sweeps):
        yaw.append(one + 20.0 * s)
        times += [t0 + pd.Timedelta(seconds=120 * s + 0.2 * j) for j in range(one.size)]
        sweep += [s] * one.size
    yaw, sweep = np.concatenate(yaw), np.array(sweep)
    t = (pd.DatetimeIndex(times) - t0).total_seconds().to_numpy()
    true_yaw = yaw.copy()
    if lag_s:
        # what the sensor really faced at each reading: the recorded yaw lag_s earlier,
        # within the sweep (np.interp holds the ends); the record keeps the recorded yaw
        for s in range(n_sweeps):
            m = sweep == s
            true_yaw[m] = np.interp(t[m] - lag_s, t[m], yaw[m])
    data = ring_configuration(8, 45.0).sample(
        RayleighSky(0.6), SITE, pd.DatetimeIndex(times), true_yaw + OFFSET_DEG, 0.0, 0.0,
        rng, include_truth=False, sweep=sweep)
    table = data.table.copy()
    table["yaw_deg"] = yaw
    return PhotodiodeData(table, data.sidecar)


def _sample(view_el, view_az):
    a = np.atleast_2d(np.asarray(view_el, float))
    return SkySample(np.ones_like(a), np.zeros_like(a), np.zeros_like(a),
                     np.zeros(a.shape + (3,)), a, np.atleast_2d(np.asarray(view_az, float)))


def test_sun_side_closed_form():
    """A unit looking north at 45 deg elevation: the sun due west (its left) gives +1, due
    east -1, anywhere in the north-south vertical plane 0; on a unit looking east, a sun in
    the north at the horizon is on its left: +1."""
    obs = _sample([[45.0, 45.0, 45.0, 45.0]], [[0.0, 0.0, 0.0, 90.0]])
    suns = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.6, 0.8]])
    s = np.array([sun_side(obs, np.repeat(sun[None], 1, 0))[0] for sun in suns])
    np.testing.assert_allclose(s[:, :3], [[1, 1, 1], [-1, -1, -1], [0, 0, 0]], atol=1e-12)
    north = sun_side(obs, np.array([[0.0, 1.0, 0.0]]))[0, 3]
    assert north == pytest.approx(1.0, abs=1e-12)
    # a sun on the unit's axis has no side
    axis = np.array([[0.0, np.sqrt(0.5), np.sqrt(0.5)]])
    assert sun_side(obs, axis)[0, 0] == 0.0


def test_lagged_yaw_is_the_record_earlier_within_each_sweep():
    t = np.r_[np.arange(10.0), 100.0 + np.arange(10.0)]
    sweep = np.repeat([0, 1], 10)
    yaw = np.r_[20.0 * np.arange(10.0), 500.0 - 30.0 * np.arange(10.0)]
    out = lagged_yaw(t, yaw, sweep, 0.5)
    # linear within each sweep: shifted by rate x lag; the first sample holds its sweep's start
    np.testing.assert_allclose(out[1:10], yaw[1:10] - 10.0, atol=1e-12)
    np.testing.assert_allclose(out[11:], yaw[11:] + 15.0, atol=1e-12)
    assert out[0] == yaw[0] and out[10] == yaw[10]
    back = lagged_yaw(t, yaw, sweep, -0.5)
    assert back[9] == yaw[9] and back[19] == yaw[19]          # the ends hold forward too
    np.testing.assert_array_equal(lagged_yaw(t, yaw, sweep, 0.0), yaw)


@pytest.fixture(scope="module")
def standing_ring():
    return _stand_and_turn()


@pytest.mark.parametrize("name", ["side_glare", "read_lag"])
def test_candidate_is_the_base_model_at_its_null(standing_ring, name):
    inst = instrument_from_photodiodes(standing_ring)
    e = get_ring_effect(name)
    e.bind(inst)
    sun = SunTrack(inst.site, inst.t_s.min(), inst.t_s.max(), margin_s=15 * 3600.0)
    base, ext = Forward(inst, sun=sun), Forward(inst, e, sun=sun)
    th = np.zeros(ext.layout.size)
    th[ext.layout.scale] = 0.6
    th[ext.layout.heading] = OFFSET_DEG
    th[ext.layout.effect] = e.null
    np.testing.assert_allclose(ext.residual(th), base.residual(th[:base.layout.size]),
                               atol=1e-12)


def test_side_glare_without_side_is_stray_light(standing_ring):
    """As much light from either side (L = R = S) is the stray light to rounding; the two
    strengths are the stray light's one with a side fraction b, S (1 + b s), for
    L = S (1 + b) and R = S (1 - b) (|b| <= 1), and light from one side only is the other
    strength at its null."""
    inst = instrument_from_photodiodes(standing_ring)
    glare, stray = get_ring_effect("side_glare"), get_ring_effect("stray_light")
    glare.bind(inst)
    stray.bind(inst)
    P = len(inst.columns)
    rng = np.random.default_rng(2)
    S, scale = rng.uniform(0.0, 0.2, P), 12.0
    sun, _ = sun_vector(pd.to_datetime(inst.t_s, unit="s", utc=True), inst.site)
    obs = ring_configuration(8, 45.0).observe(
        RayleighSky(0.6), body_attitude(inst.yaw_deg + OFFSET_DEG), sun)
    a = glare.additive(np.r_[S, S, scale], obs, sun, inst.pd_unit)
    b = stray.additive(np.r_[S, scale], obs, sun, inst.pd_unit)
    np.testing.assert_allclose(a, b, rtol=1e-14)
    side = sun_side(obs, sun)[:, inst.pd_unit]
    frac = rng.uniform(-1.0, 1.0, P)
    mixed = glare.additive(np.r_[S * (1.0 + frac), S * (1.0 - frac), scale], obs, sun,
                           inst.pd_unit)
    np.testing.assert_allclose(mixed, b * (1.0 + frac * side), rtol=1e-12, atol=1e-15)
    # from the left only: doubled with the sun square to the left, gone to the right
    left = glare.additive(np.r_[2.0 * S, np.zeros(P), scale], obs, sun, inst.pd_unit)
    np.testing.assert_allclose(left, b * (1.0 + side), rtol=1e-12, atol=1e-15)
    assert np.all(left >= 0.0)
    assert glare.null[:2 * P] == glare.lower[:2 * P] == (0.0,) * (2 * P)


def _plant_side_glare(data: PhotodiodeData, S, b, scale_deg):
    """Add ``S_p exp(-psi / scale) (1 + b_p s)`` session-median units of unpolarized light to
    every photodiode: the sun's distance ``psi`` and side ``s`` from each unit's true axis
    (heading = recorded yaw + OFFSET_DEG, unit azimuths 0, 45, ... clockwise from the
    heading, 45 deg elevation), written out here apart from the fitter's geometry."""
    table = data.table.copy()
    cols = [c for c in table.columns if c.startswith("u")]
    level = float(np.median(table[cols].to_numpy(float)))
    times = pd.DatetimeIndex(pd.to_datetime(table["time"]))
    sun, _ = sun_vector(times, SITE)
    heading = np.radians(table["yaw_deg"].to_numpy(float) + OFFSET_DEG)
    for j, col in enumerate(cols):
        unit = int(col[1:col.index("_")])
        az = heading + np.radians(45.0 * unit)
        el = np.radians(45.0)
        axis = np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el),
                         np.full_like(az, np.sin(el))], axis=1)
        cos_psi = np.clip(np.sum(axis * sun, axis=1), -1.0, 1.0)
        psi = np.degrees(np.arccos(cos_psi))
        # the left of a unit facing azimuth az: the horizontal direction az - 90 deg
        left = np.stack([np.sin(az - np.pi / 2), np.cos(az - np.pi / 2), np.zeros_like(az)], 1)
        side = np.sum(left * sun, axis=1) / np.sqrt(1.0 - cos_psi ** 2)
        table[col] = np.round(table[col] + level * S[j] * np.exp(-psi / scale_deg)
                              * (1.0 + b[j] * side))
    return PhotodiodeData(table, data.sidecar)


@pytest.mark.slow
def test_side_glare_named_over_stray_light_and_recovered():
    """Glare on a quarter of the photodiodes, each lit from one side (b = +-0.8), falling off
    over 12 deg from the sun, on a ring whose units' pointing is calibrated (as with
    ``--pointing-from``: read from the angle of polarization with the glare unmodelled, the
    pointing takes up part of it and holds the candidate short of its optimum). Named over
    side-blind stray light and the aureole by the paired rule; the fall-off recovered
    within 10 % and, on every lit photodiode the fault screen keeps, its side fraction
    (L - R) / (L + R) within 0.3 of the planted +-0.8 (a fraction from the wrong side would
    be 1.6 off)."""
    base = _stand_and_turn(seed=5)
    P = 32
    rng = np.random.default_rng(8)
    lit = rng.choice(P, 8, replace=False)
    S, b = np.zeros(P), np.zeros(P)
    S[lit] = rng.uniform(0.04, 0.10, lit.size)
    b[lit] = rng.choice([-0.8, 0.8], lit.size)
    data = _plant_side_glare(base, S, b, 12.0)
    # the aureole too: side glare is named alone only over what it can stand in for
    doc = diagnose_photodiodes(data, ("side_glare", "stray_light", "aureole"), n_folds=3,
                               pointing=np.zeros(16))
    v = doc["verdict"]
    assert v["effect"] == "side_glare", v["reason"]
    assert abs(v["params"]["scale_deg"]["value"] / 12.0 - 1.0) < 0.10
    cols = [c for c in data.table.columns if c.startswith("u")]
    # the screen drops photodiodes whose readings the glare takes off Malus's law, and units
    # left with too few: their glare is not fitted
    gone = {f["channel"] for f in doc["faults"]}
    kept = [j for j in lit if cols[j] not in gone and cols[j].split("_")[0] not in gone]
    assert len(kept) >= 4, doc["faults"]
    L = np.array([v["params"][f"L_{cols[j]}"]["value"] for j in kept])
    R = np.array([v["params"][f"R_{cols[j]}"]["value"] for j in kept])
    np.testing.assert_array_less(np.abs((L - R) / (L + R) - b[kept]), 0.3)


def test_aerosol_candidate_takes_the_instruments_band(standing_ring):
    """The aerosol candidate's sky is at the band the sidecar gives (a UV instrument at
    350 nm), and at the default 500 nm without one."""
    from calibration.photodiode_diagnosis.effects import GridAerosolSky
    side = dict(standing_ring.sidecar, schema="skysim.photodiodes/2",
                band={"wavelength_nm": 350.0, "fwhm_nm": 20.0})
    e = get_ring_effect("aerosol")
    e.bind(instrument_from_photodiodes(PhotodiodeData(standing_ring.table, side)))
    assert e.wavelength_nm == 350.0
    e.bind(instrument_from_photodiodes(standing_ring))
    assert e.wavelength_nm == 500.0
    grid = GridAerosolSky(2.0, wavelength_nm=350.0)
    assert all(s.wavelength_nm == 350.0 for s in grid.skies)


def test_side_glare_starts_fit_its_parameter_list(standing_ring):
    e = get_ring_effect("side_glare")
    e.bind(instrument_from_photodiodes(standing_ring))
    assert all(s.shape == (len(e.parameter_names),) for s in e.starts(None))
    assert e.k == 2 * 32 + 1
