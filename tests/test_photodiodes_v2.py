"""Schema "skysim.photodiodes/2": any photodiode compass (crossed pairs, rotating analysers,
fractional angles, readings kinds, clock uncertainty and band), the conversion of first-version
files, a round-trip property, a bad-input battery, the zenith compass's 180-deg ambiguity and
the forward model of a rotating analyser against the zenith's closed form."""

import copy
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.photodiode_diagnosis.forward import Forward
from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes
from sensor.photodiodes_io import (PHOTODIODES_SCHEMA, PHOTODIODES_SCHEMA_V1, PhotodiodeData,
                                   PhotodiodeFormatError, SidecarMismatchError,
                                   heading_ambiguity_deg, heading_error_deg, migrate_sidecar,
                                   read_photodiodes, write_photodiodes)
from skysim import SkysimError
from skysim.exceptions import InvalidParameterError, UnsupportedOperationError
from skysim.io import sidecar_path
from skysim.sun import sun_position

FIXTURE = Path(__file__).resolve().parent / "fixtures" / "rotating_analyser"
SITE = {"latitude_deg": 39.258648, "longitude_deg": 8.440184, "altitude_m": 0.0}


def _side(**over):
    side = {"schema": PHOTODIODES_SCHEMA, "site": dict(SITE), "yaw_reference": "north",
            "yaw_sense": "clockwise", "readings": "raw", "reading_unit": "counts",
            "adc_full_scale": 4095, "saturation_value": 4095,
            "units": [{"azimuth_deg": 0.0, "elevation_deg": 90.0, "photodiodes": [0.0, 90.0],
                       "columns": ["pd_a", "pd_b"],
                       "analyser": {"kind": "rotating", "angle_column": "gear_deg"}}]}
    side.update(over)
    return side


def _table(n=12, seed=0):
    rng = np.random.default_rng(seed)
    return pd.DataFrame({"time": pd.date_range("2022-06-21T10:00+02:00", periods=n, freq="40ms"),
                         "yaw_deg": 0.0, "gear_deg": np.arange(n) * 3.6,
                         "pd_a": rng.uniform(100, 4000, n), "pd_b": rng.uniform(100, 4000, n)})


# ------------------------------------------------------------------ the fixture
def test_rotating_analyser_fixture_loads_with_every_new_field():
    """The simulated rotating-analyser session (tests/fixtures/rotating_analyser): a zenith
    crossed pair on a gear, normalised per revolution, converted from its authors' layout."""
    d = read_photodiodes(FIXTURE / "rotating_analyser.csv")
    assert d.sidecar["schema"] == PHOTODIODES_SCHEMA and d.migrated_from is None
    assert d.readings_kind == "normalised" and d.reading_unit == "relative"
    assert d.rotating_units == [0] and d.columns == ["pd_a", "pd_b"]
    assert d.time_uncertainty_s == 30.0 and d.band_wavelength_nm == 365.0
    assert d.heading_ambiguity_deg == 180.0
    assert {u["quantity"] for u in d.unrecoverable} == {
        "dop_scale", "dark_offset", "radiance", "heading_beyond_180_deg"}
    assert d.extra_columns == ["revolution"]
    # normalised readings reach 0 once per revolution: not flagged as a dropped conversion
    assert d.flags.summary()["zero"] == 0 and (d.readings == 0).sum() >= 18
    authors = pd.read_csv(FIXTURE / "authors_layout.csv")
    np.testing.assert_array_equal(d.polarizer_angles_deg[:, 0],
                                  np.mod(authors["gear_deg"], 180.0))
    np.testing.assert_allclose(np.mod(d.polarizer_angles_deg[:, 1] - d.polarizer_angles_deg[:, 0],
                                      180.0), 90.0, atol=1e-9)
    inst = instrument_from_photodiodes(d)
    assert inst.heading_ambiguity_deg == 180.0 and inst.time_uncertainty_s == 30.0
    assert inst.readings_kind == "normalised" and inst.pd_angle_row_deg.shape == (1800, 2)
    assert inst.n_sweeps == 6 and inst.source["readings_kind"] == "normalised"
    sub = inst.subset(np.arange(300, 600))
    np.testing.assert_array_equal(sub.pd_angle_row_deg, inst.pd_angle_row_deg[300:600])
    fwd = Forward(inst)
    held = fwd.held_by_readings()
    assert held[fwd.layout.off].all() and held[fwd.layout.scale] and held.sum() == 3
    np.testing.assert_array_equal(sub.analyser_cycle, inst.analyser_cycle[300:600])
    assert fwd.usable.all()          # a crossed pair's two readings are enough per sample


def test_fixture_conversion_is_reproducible(tmp_path):
    """The committed file is what the committed converter makes of the authors' layout."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("make_rotating_analyser",
                                                  FIXTURE / "make_rotating_analyser.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = mod.convert_authors_layout(FIXTURE / "authors_layout.csv", tmp_path / "x.csv")
    assert out.read_bytes() == (FIXTURE / "rotating_analyser.csv").read_bytes()
    assert json.loads(sidecar_path(out).read_text()) == json.loads(
        (FIXTURE / "rotating_analyser.csv.json").read_text())


def test_rate_and_phase_give_the_angle_column():
    """A gear at a constant rate described by rate, phase and epoch gives the same per-row
    angles as its encoder column (the fixture's gear turns at 90 deg/s from 0 at the start)."""
    d = read_photodiodes(FIXTURE / "rotating_analyser.csv")
    side = copy.deepcopy(d.sidecar)
    side["units"][0]["analyser"] = {"kind": "rotating", "rate_deg_per_s": 90.0,
                                    "phase_deg": 0.0, "epoch": "2022-06-21T10:00:00+02:00"}
    by_rate = PhotodiodeData(d.table.drop(columns=["gear_deg"]), side)
    # the encoder column is rounded to 0.01 deg
    np.testing.assert_allclose(np.mod(by_rate.polarizer_angles_deg - d.polarizer_angles_deg
                                      + 90.0, 180.0) - 90.0, 0.0, atol=0.0051)
    # without an epoch the first sample's time is the epoch, and it is written out
    del side["units"][0]["analyser"]["epoch"]
    again = PhotodiodeData(d.table.drop(columns=["gear_deg"]), side)
    assert pd.Timestamp(again.units[0]["analyser"]["epoch"]) == d.table["time"].iloc[0]
    assert "epoch" not in side["units"][0]["analyser"]        # the caller's dict untouched


# ------------------------------------------------------------------ forward model
def test_forward_rotating_analyser_matches_the_zenith_closed_form():
    """Malus's law through the forward model's per-row polarizer angles against the zenith of
    a single-scattering sky in closed form: the E-vector is perpendicular to the sun's
    azimuth, and d = sin^2 g / (1 + cos^2 g) with g the sun's zenith angle (Coulson 1988,
    ch. 5). For a zenith unit the unit frame's x points to body azimuth ``azimuth_deg + 180``
    and y (the direction of increasing azimuth at ``azimuth_deg``) to ``azimuth_deg + 90``,
    so an angle ``chi`` from x towards y is body azimuth ``azimuth_deg + 180 - chi``; the
    E-vector's body azimuth is ``sun_az - heading + 90`` (mod 180), hence
    ``chi = heading + azimuth_deg + 90 - sun_az``.
    Tolerance 1e-4 (relative): the forward model's sun comes from 60-s ephemeris knots,
    < 1e-4 deg off (:class:`skysim.sun.SunTrack`), which moves cos 2(chi - a) by < 4e-6."""
    d = read_photodiodes(FIXTURE / "rotating_analyser.csv")
    inst = instrument_from_photodiodes(d)
    fwd = Forward(inst)
    theta = np.zeros(fwd.layout.size)
    theta[fwd.layout.scale] = 0.6
    obs = fwd.observe(theta)
    model = fwd.channel_model(theta, obs)
    sun = sun_position(d.table["time"], SITE["latitude_deg"], SITE["longitude_deg"])
    g = np.radians(sun["zenith_deg"].to_numpy())
    dop = 0.6 * np.sin(g) ** 2 / (1 + np.cos(g) ** 2)
    chi = d.table["yaw_deg"].to_numpy() + 0.0 + 90.0 - sun["azimuth_deg"].to_numpy()
    a = d.polarizer_angles_deg
    expected = 1.0 + dop[:, None] * np.cos(np.radians(2 * (chi[:, None] - a)))
    np.testing.assert_allclose(model, expected, rtol=1e-4)
    # the analyser turns through every angle in each revolution: the reading spans 1 +- d
    assert np.ptp(model[:, 0]) > 1.99 * dop.min()


def test_zenith_compass_cannot_tell_a_heading_from_its_opposite():
    """Noise-free raw readings of the fixture's instrument: the forward model fits them at the
    true heading and equally 180 deg off (the ambiguity the report states), not 90 deg off."""
    d = read_photodiodes(FIXTURE / "rotating_analyser.csv")
    inst = instrument_from_photodiodes(d)
    fwd = Forward(inst)
    theta = np.zeros(fwd.layout.size)
    theta[fwd.layout.scale] = 0.6
    raw = fwd.channel_model(theta, fwd.observe(theta)) + 0.05
    side = dict(d.sidecar, readings="raw", reading_unit="volts", adc_full_scale=5.0,
                saturation_value=5.0)
    table = d.table.copy()
    table[["pd_a", "pd_b"]] = raw
    fwd = Forward(instrument_from_photodiodes(PhotodiodeData(table, side)))
    theta[fwd.layout.off] = 0.05 / fwd.level
    rms = {}
    for shift in (0.0, 180.0, 90.0):
        t = theta.copy()
        t[fwd.layout.heading] = shift
        rms[shift] = float(np.sqrt(np.mean(fwd.residual(t) ** 2)))
    assert rms[0.0] < 1e-9 and rms[180.0] < 1e-6      # the ambiguity: 180 deg off fits
    assert rms[90.0] > 0.05


def test_normalised_rotating_analyser_fit_recovers_the_heading_modulo_180():
    """The fixture's normalised readings (each photodiode scaled to [0, 1] per revolution,
    which keeps no dark level and no modulation depth): with the radiance and polarized
    radiance profiled per half-turn of the analyser and the offsets and DoP scale held, a fit
    of the heading from 20 deg off (the diagnosis starts within 15 deg, a 30-deg grid) returns
    the true heading 0 modulo 180 deg. Tolerance 0.1 deg: the heading's statistical SD here
    is about 0.015 deg (3600 readings, relative noise 0.022 of a mean 0.5, modulation
    amplitude 0.5: sigma / (2 A sqrt(N / 2)) rad)."""
    from calibration.photodiode_diagnosis.fit import fit
    d = read_photodiodes(FIXTURE / "rotating_analyser.csv")
    fwd = Forward(instrument_from_photodiodes(d))
    assert fwd.profile_rows.max() + 1 == 36      # 6 headings x 3 revolutions x 2 half-turns
    theta = np.zeros(fwd.layout.size)
    theta[fwd.layout.scale] = 0.6
    at_truth = float(np.sqrt(np.mean(fwd.residual(theta) ** 2)))
    for start in (20.0, 160.0):
        t = theta.copy()
        t[fwd.layout.heading] = start
        free = ~fwd.held_by_readings()
        free[fwd.layout.pointing] = False
        res = fit(fwd, t, free, sigma=0.03, max_iter=60)
        assert res.converged
        err = heading_error_deg(res.theta[fwd.layout.heading], 0.0, d.heading_ambiguity_deg)
        assert abs(err[0]) < 0.1, (start, res.theta[fwd.layout.heading])
        rms = float(np.sqrt(np.mean(fwd.residual(res.theta) ** 2)))
        assert rms <= at_truth * (1 + 1e-6)
        np.testing.assert_array_equal(res.theta[fwd.layout.off], 0.0)     # held
    # 90 deg off, the profiled polarized radiance would be negative: it is held at 0, so
    # the wrong heading does not fit (the 90-deg twin of a signed profile)
    t = theta.copy()
    t[fwd.layout.heading] = 90.0
    assert np.sqrt(np.mean(fwd.residual(t) ** 2)) > 10 * at_truth


def test_analyser_cycles_count_half_turns_per_sweep():
    from calibration.photodiode_diagnosis.instrument import analyser_cycles
    angle = np.r_[np.arange(0, 720, 30.0), np.arange(350, 350 - 400, -40.0) % 360]
    sweep = np.r_[np.zeros(24, int), np.ones(10, int)]
    c = analyser_cycles(angle, sweep)
    # sweep 0: 6 samples per half-turn (30 deg steps), 4 half-turns; sweep 1 turns backwards
    # (40 deg steps from 350): half-turns below its start, 5 samples each
    assert np.bincount(c[:24]).tolist() == [6, 6, 6, 6]
    assert len(set(c[24:])) == 3 and not set(c[24:]) & set(c[:24])


# ------------------------------------------------------------------ heading error
def test_heading_error_modulo_the_ambiguity():
    est = np.array([10.0, 190.0, 359.0, np.nan, 95.0])
    true = np.array([9.5, 10.0, 1.0, 0.0, 0.0])
    np.testing.assert_allclose(heading_error_deg(est, true), [0.5, -180.0, -2.0, np.nan, 95.0])
    np.testing.assert_allclose(heading_error_deg(est, true, 180), [0.5, 0.0, -2.0, np.nan,
                                                                   -85.0])
    for bad in (90, 0, "180", True, np.nan):
        with pytest.raises(InvalidParameterError, match="ambiguity_deg must be 360 or 180") \
                as exc:
            heading_error_deg(est, true, bad)
        assert str(exc.value).endswith(f"got {bad!r}")
    with pytest.raises(InvalidParameterError, match=r"shape \(5,\).*shape \(2,\)"):
        heading_error_deg(est, [1.0, 2.0])


def test_heading_ambiguity_needs_every_unit_at_the_zenith():
    assert heading_ambiguity_deg([90.0]) == 180.0
    assert heading_ambiguity_deg([90.0, 86.0]) == 180.0
    assert heading_ambiguity_deg([90.0, 84.0]) == 360.0
    assert heading_ambiguity_deg([45.0] * 8) == 360.0


# ------------------------------------------------------------------ first version
def test_first_version_sidecar_is_converted_and_checked_by_its_own_rules():
    v1 = {"schema": PHOTODIODES_SCHEMA_V1, "site": dict(SITE), "yaw_reference": "relative",
          "yaw_sense": "counterclockwise", "readings": "volts", "adc_full_scale": 5.0,
          "saturation_value": 4.9, "frames": "kept",
          "units": [{"azimuth_deg": 45, "elevation_deg": 45, "photodiodes": [0, 45, 90, 135]}]}
    v2 = migrate_sidecar(v1)
    assert v2["schema"] == PHOTODIODES_SCHEMA and v1["schema"] == PHOTODIODES_SCHEMA_V1
    assert v2["readings"] == "raw" and v2["reading_unit"] == "volts"
    assert v2["time_uncertainty_s"] == 0.0 and v2["band"] == "unknown"
    assert v2["frames"] == "kept"
    assert v2["units"] == [{"azimuth_deg": 45.0, "elevation_deg": 45.0,
                            "photodiodes": [0.0, 45.0, 90.0, 135.0],
                            "columns": ["u0_p000", "u0_p045", "u0_p090", "u0_p135"],
                            "analyser": {"kind": "fixed"}}]
    assert migrate_sidecar(v2) == v2                        # idempotent
    # the first version's own rules still hold for its files: 3 angles, whole degrees
    bad = copy.deepcopy(v1)
    bad["units"][0]["photodiodes"] = [0, 90]
    with pytest.raises(PhotodiodeFormatError, match=r"at least 3 photodiodes.*\[0, 90\]"):
        migrate_sidecar(bad)
    bad["units"][0]["photodiodes"] = [0, 45, 90, 22.5]
    with pytest.raises(PhotodiodeFormatError, match="angle 22.5 must be a whole number"):
        migrate_sidecar(bad)


def test_reference_ring_file_reads_unchanged(reference_dir):
    """A real first-version ring session: the same columns, readings and flags as before."""
    path = reference_dir / "gkanias2023" / "tod_Thursday_12-05-22_09-08-12_CEST.csv"
    d = read_photodiodes(path)
    assert d.migrated_from == PHOTODIODES_SCHEMA_V1 and d.readings_kind == "raw"
    assert d.reading_unit == "counts" and d.heading_ambiguity_deg == 360.0
    assert d.columns == [f"u{i}_p{a:03d}" for i in range(8) for a in (0, 45, 90, 135)]
    assert d.rotating_units == [] and d.unrecoverable == [
        {"quantity": "molecular_optical_thickness",
         "reason": "the spectral band is unknown: give 'band' as a name, a centre wavelength "
                   "or a response table"}]
    raw = pd.read_csv(path)
    np.testing.assert_array_equal(d.readings, raw[d.columns].to_numpy(float))
    np.testing.assert_array_equal(d.polarizer_angles_deg,
                                  np.tile([0.0, 45.0, 90.0, 135.0] * 8, (len(raw), 1)))


# ------------------------------------------------------------------ round trip
_angle = st.floats(0.0, 179.99, allow_nan=False).map(lambda a: round(a, 3))


@st.composite
def _instruments(draw):
    n_units = draw(st.integers(1, 3))
    units = []
    for i in range(n_units):
        k = draw(st.integers(2, 5))
        angles = draw(st.lists(_angle, min_size=k, max_size=k,
                               unique_by=lambda a: round(a, 3) % 180))
        kind = draw(st.sampled_from(["fixed", "column", "rate"]))
        analyser = {"fixed": {"kind": "fixed"},
                    "column": {"kind": "rotating", "angle_column": f"wheel{i}_deg"},
                    "rate": {"kind": "rotating",
                             "rate_deg_per_s": draw(st.floats(-720, 720).filter(
                                 lambda r: abs(r) > 1e-3)),
                             "phase_deg": draw(st.floats(-360, 360))}}[kind]
        unit = {"azimuth_deg": draw(st.floats(-180, 360)),
                "elevation_deg": draw(st.floats(0, 90)), "photodiodes": angles,
                "analyser": analyser}
        if draw(st.booleans()):
            unit["columns"] = [f"unit{i}_ch{j}" for j in range(k)]
        units.append(unit)
    readings = draw(st.sampled_from(["raw", "dark-subtracted", "normalised"]))
    band = draw(st.sampled_from(["V", "unknown", {"wavelength_nm": 365.0},
                                 {"response": [[330.0, 0.1], [365.0, 1.0], [400.0, 0.2]]}]))
    side = _side(units=units, readings=readings, band=band,
                 time_uncertainty_s=draw(st.floats(0, 1e4)))
    if readings == "normalised":
        side.update(adc_full_scale=None, saturation_value=None, reading_unit="relative")
    return side


@settings(max_examples=40, deadline=None)
@given(_instruments(), st.sampled_from([".csv", ".parquet"]), st.integers(0, 2 ** 16))
def test_round_trip_property(tmp_path_factory, side, ext, seed):
    """Property: any valid second-version sidecar and table are read back as written: the
    sidecar exactly, readings and per-row polarizer angles to the CSV's float precision."""
    from sensor.photodiodes_io import photodiode_columns
    rng = np.random.default_rng(seed)
    n = 5
    cols = {"time": pd.date_range("2022-06-21T10:00+02:00", periods=n, freq="100ms"),
            "yaw_deg": rng.uniform(0, 360, n)}
    probe = migrate_sidecar(side)
    for c in photodiode_columns(probe["units"]):
        cols[c] = rng.uniform(-1, 4000, n)
    for u in probe["units"]:
        if "angle_column" in u["analyser"]:
            cols[u["analyser"]["angle_column"]] = rng.uniform(0, 360, n)
    data = PhotodiodeData(pd.DataFrame(cols), side)
    path = write_photodiodes(data, tmp_path_factory.mktemp("rt") / f"x{ext}")
    back = read_photodiodes(path)
    assert back.sidecar == data.sidecar and back.columns == data.columns
    np.testing.assert_allclose(back.readings, data.readings, rtol=1e-15)
    err = np.mod(back.polarizer_angles_deg - data.polarizer_angles_deg + 90.0, 180.0) - 90.0
    np.testing.assert_allclose(err, 0.0, atol=1e-9)


# ------------------------------------------------------------------ bad input
def _unit(**over):
    u = {"azimuth_deg": 0.0, "elevation_deg": 90.0, "photodiodes": [0.0, 90.0],
         "columns": ["pd_a", "pd_b"], "analyser": {"kind": "rotating",
                                                   "angle_column": "gear_deg"}}
    u.update(over)
    return u


BAD = [
    ({"readings": "counts"}, "'readings' is 'counts'.*raw, dark-subtracted, normalised.*"
                             "'reading_unit'"),
    ({"readings": "clean"}, "'readings' is 'clean'"),
    ({"reading_unit": "lux"}, "'reading_unit' is 'lux'"),
    ({"saturation_value": None}, "'saturation_value' must be a positive number; got None"),
    ({"adc_full_scale": "4095"}, "'adc_full_scale' must be a positive number; got '4095'"),
    ({"time_uncertainty_s": -1}, "'time_uncertainty_s' must be a number >= 0.*got -1"),
    ({"time_uncertainty_s": "30 s"}, "'time_uncertainty_s'.*got '30 s'"),
    ({"band": "UV"}, "'band' is 'UV'; valid: a band name .U, B, V, R, I."),
    ({"band": {"wavelength_nm": 50.0}}, "band 'wavelength_nm' must be a number in "
                                        r"\[200, 2500\] nm; got 50.0"),
    ({"band": {"fwhm_nm": 30.0}}, "gives no 'wavelength_nm'"),
    ({"band": {"wavelength_nm": 365.0, "fwhm_nm": 0}}, "'fwhm_nm' must be a positive.*got 0"),
    ({"band": {"centre": 365}}, r"'band' is \{'centre': 365\}"),
    ({"band": {"response": [[400.0, 1.0], [350.0, 1.0]]}}, "must increase strictly"),
    ({"band": {"response": [[350.0, 0.0], [400.0, 0.0]]}}, "not all 0"),
    ({"band": {"response": [[350.0, 1.0]]}}, "at least 2"),
    ({"units": [_unit(photodiodes=[0.0])]}, r"unit 0 needs at least 2 photodiodes.*\[0.0\]"),
    ({"units": [_unit(photodiodes=[0.0, 180.0])]}, r"angle 180.0 must be in \[0, 180\)"),
    ({"units": [_unit(photodiodes=[10.0, 10.0])]}, r"distinct polarizer angles.*\[10.0, 10.0\]"),
    ({"units": [_unit(columns=["pd_a"])]}, r"unit 0 columns must be a list of 2.*\['pd_a'\]"),
    ({"units": [_unit(columns=["pd_a", "yaw_deg"])]}, "column 'yaw_deg' is a column the "
                                                      "schema reserves"),
    ({"units": [_unit(columns=["pd_a", "gear_deg"])]}, "column 'gear_deg' is named by both"),
    ({"units": [_unit(elevation_deg=95)]}, r"unit 0 elevation_deg 95 is outside \[0, 90\]"),
    ({"units": [_unit(analyser={"kind": "spinning"})]}, "unit 0 analyser must be.*'spinning'"),
    ({"units": [_unit(analyser="rotating")]}, "unit 0 analyser must be.*got 'rotating'"),
    ({"units": [_unit(analyser={"kind": "fixed", "rate_deg_per_s": 3})]},
     r"analyser is fixed but gives \['rate_deg_per_s'\]"),
    ({"units": [_unit(analyser={"kind": "rotating"})]}, "not neither"),
    ({"units": [_unit(analyser={"kind": "rotating", "angle_column": "gear_deg",
                                "rate_deg_per_s": 90})]}, "not both"),
    ({"units": [_unit(analyser={"kind": "rotating", "rate_deg_per_s": 0})]},
     "'rate_deg_per_s' must be a non-zero number.*got 0"),
    ({"units": [_unit(analyser={"kind": "rotating", "rate_deg_per_s": 90,
                                "phase_deg": "north"})]}, "'phase_deg'.*got 'north'"),
    ({"units": [_unit(analyser={"kind": "rotating", "rate_deg_per_s": 90,
                                "epoch": "2022-06-21T10:00"})]},
     "'epoch' must be an ISO 8601 time with a UTC offset.*got '2022-06-21T10:00'"),
    ({"units": [_unit(analyser={"kind": "rotating", "rate_deg_per_s": 90, "rpm": 15})]},
     r"unknown key\(s\) \['rpm'\]"),
    ({"units": [_unit(analyser={"kind": "rotating", "angle_column": "time"})]},
     "'angle_column' must name a column.*got 'time'"),
    ({"schema": "skysim.photodiodes/3"}, "schema is 'skysim.photodiodes/3', expected "
                                         "'skysim.photodiodes/2'"),
]


@pytest.mark.parametrize("over,match", BAD)
def test_bad_sidecar_battery(over, match):
    """Every field is checked; the message names the field and the value."""
    with pytest.raises(PhotodiodeFormatError, match=match) as exc:
        PhotodiodeData(_table(), _side(**over))
    assert isinstance(exc.value, SkysimError) and "\n" not in str(exc.value)


def test_bad_table_battery():
    t = _table().drop(columns=["gear_deg"])
    with pytest.raises(PhotodiodeFormatError, match="no column 'gear_deg'.*rotating analyser"):
        PhotodiodeData(t, _side())
    t = _table()
    t.loc[3, "gear_deg"] = np.nan
    with pytest.raises(PhotodiodeFormatError, match="gear_deg"):
        PhotodiodeData(t, _side())
    t = _table().rename(columns={"pd_b": "pd_c"})
    with pytest.raises(SidecarMismatchError, match=r"missing from the table \['pd_b'\]"):
        PhotodiodeData(t, _side())
    t = _table()
    t["u3_p022.5"] = 1.0       # a default-named photodiode column no unit announces
    with pytest.raises(SidecarMismatchError) as exc:
        PhotodiodeData(t, _side())
    assert exc.value.unexpected == ["u3_p022.5"]


def test_rotating_unit_refuses_fixed_angle_access():
    d = PhotodiodeData(_table(), _side())
    with pytest.raises(UnsupportedOperationError, match="unit 0 has a rotating analyser"):
        d.unit_readings(0)


def test_fractional_angles_and_a_fixed_crossed_pair():
    """A fixed three-pair-like unit with a fractional angle and a fixed crossed pair load;
    the default column names carry the fraction."""
    side = _side(units=[{"azimuth_deg": 0, "elevation_deg": 60,
                         "photodiodes": [0, 22.5, 67.5, 112.5]},
                        {"azimuth_deg": 180, "elevation_deg": 60, "photodiodes": [0, 90]}])
    n = 12
    cols = {"time": pd.date_range("2022-06-21T10:00+02:00", periods=n, freq="1s"),
            "yaw_deg": 0.0}
    for c in ("u0_p000", "u0_p022.5", "u0_p067.5", "u0_p112.5", "u1_p000", "u1_p090"):
        cols[c] = np.linspace(100, 200, n)
    d = PhotodiodeData(pd.DataFrame(cols), side)
    assert d.pd_unit.tolist() == [0, 0, 0, 0, 1, 1] and d.heading_ambiguity_deg == 360.0
    _, angles, _ = d.unit_readings(0)
    assert angles.tolist() == [0.0, 22.5, 67.5, 112.5]
    assert d.units[0]["analyser"] == {"kind": "fixed"}
