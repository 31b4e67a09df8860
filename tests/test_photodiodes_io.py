"""Photodiode data files: round trips, per-sample flags, specific errors, on sidecars of the
first version (converted on load; the second version's own fields: test_photodiodes_v2.py)."""

import json

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sensor.compound_eye import ring_configuration
from sensor.photodiodes_io import (PHOTODIODES_SCHEMA, PHOTODIODES_SCHEMA_V1, PhotodiodeData,
                                   PhotodiodeFormatError, SidecarMismatchError,
                                   photodiode_column, read_photodiodes, write_photodiodes)
from skysim.io import sidecar_path
from skysim.sky import RayleighSky

SAT = 4095.0


def _sidecar(n_units=2, angles=(0, 45, 90, 135), yaw_reference="north"):
    return {"schema": PHOTODIODES_SCHEMA_V1,
            "site": {"latitude_deg": 39.98, "longitude_deg": 116.35, "altitude_m": 50.0},
            "yaw_reference": yaw_reference, "yaw_sense": "clockwise",
            "units": [{"azimuth_deg": 90.0 * i, "elevation_deg": 45.0, "photodiodes": list(angles)}
                      for i in range(n_units)],
            "readings": "counts", "adc_full_scale": SAT, "saturation_value": SAT}


def _table(n=12, n_units=2, angles=(0, 45, 90, 135), seed=0):
    rng = np.random.default_rng(seed)
    t = pd.date_range("2020-06-15T14:00+08:00", periods=n, freq="1s")
    cols = {"time": t, "yaw_deg": rng.uniform(0, 360, n)}
    for i in range(n_units):
        for a in angles:
            cols[photodiode_column(i, a)] = rng.integers(100, 4000, n).astype(float)
    return pd.DataFrame(cols)


def test_column_names():
    assert photodiode_column(0, 45) == "u0_p045"
    assert photodiode_column(12, 0) == "u12_p000"
    assert photodiode_column(1, 22.5) == "u1_p022.5"
    assert photodiode_column(0, 0.125) == "u0_p000.125"
    with pytest.raises(PhotodiodeFormatError, match=r"angle 180 of unit 0 .* \[0, 180\)"):
        photodiode_column(0, 180)


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_round_trip_keeps_values_times_and_extra_columns(tmp_path, ext):
    table = _table()
    table["lamp_state"] = ["on"] * len(table)            # unknown column: kept as metadata
    data = PhotodiodeData(table.copy(), _sidecar())
    path = write_photodiodes(data, tmp_path / f"run{ext}")
    assert sidecar_path(path).exists()
    back = read_photodiodes(path)
    assert back.sidecar == data.sidecar
    # a first-version sidecar is converted on load, and the writer writes the second version
    assert data.migrated_from == PHOTODIODES_SCHEMA_V1 and back.migrated_from is None
    assert json.loads(sidecar_path(path).read_text())["schema"] == PHOTODIODES_SCHEMA
    np.testing.assert_array_equal(back.readings, data.readings)   # integer counts: exact
    assert (back.table["time"] == table["time"]).all()
    np.testing.assert_allclose(back.table["yaw_deg"], table["yaw_deg"], rtol=0, atol=1e-12)
    assert back.extra_columns == ["lamp_state"]
    assert list(back.table["lamp_state"]) == ["on"] * len(table)


def test_flags_mark_but_never_drop_or_invent(tmp_path):
    table = _table(n=12)
    table.loc[3, "u0_p000"] = SAT                 # saturated
    table.loc[4, "u1_p045"] = 0.0                 # zero
    table.loc[5, "u1_p090"] = np.nan              # missing reading
    table["u1_p135"] = 777.0                      # dead: stuck over the whole file
    table.loc[7, "time"] = table.loc[6, "time"]   # repeated timestamp
    path = tmp_path / "bad.csv"
    write_photodiodes(PhotodiodeData(table.copy(), _sidecar()), path)
    data = read_photodiodes(path)
    assert len(data.table) == 12                  # nothing dropped
    f = data.flags
    j = data.columns.index
    assert np.flatnonzero(f.saturated[:, j("u0_p000")]).tolist() == [3]
    assert f.saturated.sum() == 1
    assert np.flatnonzero(f.zero[:, j("u1_p045")]).tolist() == [4] and f.zero.sum() == 1
    assert np.flatnonzero(f.missing[:, j("u1_p090")]).tolist() == [5] and f.missing.sum() == 1
    assert np.isnan(data.readings[5, j("u1_p090")])   # not invented
    assert f.dead[:, j("u1_p135")].all() and f.dead.sum() == 12
    assert np.flatnonzero(f.repeated_time).tolist() == [7]
    assert data.readings[3, j("u0_p000")] == SAT and data.readings[4, j("u1_p045")] == 0.0
    s = f.summary()
    assert s == {"saturated": 1, "zero": 1, "missing": 1, "dead_photodiodes": ["u1_p135"],
                 "repeated_time": 1}
    frame = f.to_frame()
    assert frame.shape[0] == 12 and frame["u0_p000_saturated"].sum() == 1


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(0, int(SAT)), min_size=4 * 2 * 3, max_size=4 * 2 * 3))
def test_flags_match_values(values):
    """Property: the saturated/zero flags are exactly the readings at full scale / at zero."""
    table = _table(n=3)
    cols = [c for c in table.columns if c.startswith("u")]
    table[cols] = np.array(values, float).reshape(3, len(cols))
    data = PhotodiodeData(table, _sidecar())
    np.testing.assert_array_equal(data.flags.saturated, data.readings >= SAT)
    np.testing.assert_array_equal(data.flags.zero, data.readings == 0)
    assert not data.flags.dead.any()              # fewer than DEAD_MIN_SAMPLES samples


def test_sidecar_announcing_a_missing_column():
    table = _table().drop(columns=["u1_p045"])
    with pytest.raises(SidecarMismatchError, match="u1_p045") as exc:
        PhotodiodeData(table, _sidecar())
    assert exc.value.missing == ["u1_p045"] and exc.value.unexpected == []


def test_photodiode_column_not_in_sidecar(tmp_path):
    table = _table(n_units=3)
    path = tmp_path / "x.csv"
    table.assign(time=table["time"].astype(str)).to_csv(path, index=False)
    sidecar_path(path).write_text(json.dumps(_sidecar(n_units=2)))
    with pytest.raises(SidecarMismatchError) as exc:
        read_photodiodes(path)
    assert exc.value.unexpected == [f"u2_p{a:03d}" for a in (0, 45, 90, 135)]


@pytest.mark.parametrize("key,value,match", [
    ("schema", "skysim.measurement/1", "expected 'skysim.photodiodes/2'"),
    ("yaw_reference", "magnetic", "yaw_reference"),
    ("yaw_sense", "cw", "yaw_sense"),
    ("readings", "amps", "readings"),
    ("saturation_value", -1, "saturation_value"),
    ("units", [], "units"),
    ("units", [{"azimuth_deg": 0, "elevation_deg": 45, "photodiodes": [0, 90, 180]}],
     "3 photodiodes at distinct"),
])
def test_malformed_sidecar(key, value, match):
    side = _sidecar()
    side[key] = value
    with pytest.raises(PhotodiodeFormatError, match=match):
        PhotodiodeData(_table(), side)


@pytest.mark.parametrize("site,match", [
    ("Sardinia", "'site' must give the numbers latitude_deg.*got 'Sardinia'"),
    ({"latitude_deg": 39.2}, "'site' must give the numbers.*got {'latitude_deg': 39.2}"),
    ({"latitude_deg": 39.2, "longitude_deg": None}, "'longitude_deg': None"),
    ({"latitude_deg": 39.2, "longitude_deg": 8.4, "altitude_m": "sea"}, "'altitude_m': 'sea'"),
])
def test_malformed_site(site, match):
    side = _sidecar()
    side["site"] = site
    with pytest.raises(PhotodiodeFormatError, match=match):
        PhotodiodeData(_table(), side)


@pytest.mark.parametrize("key,value,match", [
    ("elevation_deg", "high", "unit 1 elevation_deg must be a finite number.*got 'high'"),
    ("elevation_deg", None, "unit 1 elevation_deg must be a finite number.*got None"),
    ("elevation_deg", -5.0, r"unit 1 elevation_deg -5.0 is outside \[0, 90\]"),
    ("azimuth_deg", "east", "unit 1 azimuth_deg must be a finite number.*got 'east'"),
    ("azimuth_deg", float("nan"), "unit 1 azimuth_deg must be a finite number.*got nan"),
    ("photodiodes", 4, "unit 1 photodiodes must be a list of polarizer angles.*got 4"),
    ("photodiodes", "0,45,90,135", "unit 1 photodiodes must be a list.*got '0,45,90,135'"),
    ("photodiodes", [0, 45, None, 135], r"got \[0, 45, None, 135\]"),
])
def test_malformed_unit_values(key, value, match):
    """A hand-edited sidecar's unit value of the wrong type is named, with its unit."""
    side = _sidecar()
    side["units"][1][key] = value
    with pytest.raises(PhotodiodeFormatError, match=match):
        PhotodiodeData(_table(), side)


def test_unit_values_as_numeric_text_still_read():
    side = _sidecar()
    side["units"][1].update(azimuth_deg="90", elevation_deg="45.0",
                            photodiodes=["0", "45", "90", "135"])
    assert PhotodiodeData(_table(), side).columns[4:] == ["u1_p000", "u1_p045", "u1_p090",
                                                          "u1_p135"]


def test_missing_site_and_missing_sidecar(tmp_path):
    side = _sidecar()
    del side["site"]
    with pytest.raises(PhotodiodeFormatError, match="site"):
        PhotodiodeData(_table(), side)
    path = tmp_path / "lonely.csv"
    _table().to_csv(path, index=False)
    with pytest.raises(FileNotFoundError, match="sidecar"):
        read_photodiodes(path)


def test_bad_table_values(tmp_path):
    table = _table()
    table["time"] = table["time"].dt.tz_localize(None).astype(str)
    with pytest.raises(PhotodiodeFormatError, match="no UTC offset"):
        PhotodiodeData(table, _sidecar())
    table = _table().astype({"u0_p000": object})
    table.loc[2, "u0_p000"] = "overflow"
    with pytest.raises(PhotodiodeFormatError, match="non-numeric value 'overflow' in row 2"):
        PhotodiodeData(table, _sidecar())
    table = _table()
    table.loc[1, "yaw_deg"] = np.nan
    with pytest.raises(PhotodiodeFormatError, match="yaw_deg"):
        PhotodiodeData(table, _sidecar())


def test_times_with_an_hour_only_offset(tmp_path):
    """ISO 8601 allows an offset of whole hours, ``+02``; it was refused as 'no UTC offset'.
    A bare date still has none (its day is not an offset)."""
    table = _table()
    path = tmp_path / "x.csv"
    table.assign(time=table["time"].dt.strftime("%Y-%m-%dT%H:%M:%S+08")).to_csv(path,
                                                                              index=False)
    sidecar_path(path).write_text(json.dumps(_sidecar()))
    assert (read_photodiodes(path).table["time"] == table["time"]).all()
    table = _table()
    table["time"] = table["time"].dt.strftime("%Y-%m-%d")
    with pytest.raises(PhotodiodeFormatError, match="time '2020-06-15' in row 0 has no UTC"):
        PhotodiodeData(table, _sidecar())


def test_empty_time_cell_is_named(tmp_path):
    """An empty time cell (a truncated last line) was reported as "time nan ... has no UTC
    offset"."""
    table = _table()
    path = tmp_path / "x.csv"
    table.assign(time=table["time"].astype(str)).to_csv(path, index=False)
    lines = path.read_text().splitlines()
    lines[4] = "," + lines[4].split(",", 1)[1]                    # data row 3 without a time
    path.write_text("\n".join(lines) + "\n")
    sidecar_path(path).write_text(json.dumps(_sidecar()))
    with pytest.raises(PhotodiodeFormatError, match="time is empty in row 3;"):
        read_photodiodes(path)


def test_atomic_writer_leaves_nothing_on_failure(tmp_path):
    data = PhotodiodeData(_table(), _sidecar())
    with pytest.raises(ValueError, match="unsupported extension"):
        write_photodiodes(data, tmp_path / "x.txt")
    assert list(tmp_path.iterdir()) == []
    path = write_photodiodes(data, tmp_path / "x.csv")
    before = path.read_bytes()
    data.sidecar["site"] = {"latitude_deg": object()}     # not serialisable: the write fails
    with pytest.raises(TypeError):
        write_photodiodes(data, path)
    assert path.read_bytes() == before                    # old file untouched, no temporaries
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.csv", "x.csv.json"]


def test_ring_with_relative_yaw_round_trip(tmp_path, rng):
    """The common real instrument: 45-deg ring, four photodiodes per unit, relative yaw."""
    from skysim.sun import Site
    ring = ring_configuration(6, 45.0)
    times = pd.date_range("2020-06-15T15:00+08:00", periods=20, freq="2s")
    yaw = np.linspace(0, 342, 20)
    data = ring.sample(RayleighSky(0.7), Site(39.98, 116.35), times, yaw, 0.0, 0.0, rng,
                       yaw_reference="relative", yaw_offset_deg=30.0)
    path = write_photodiodes(data, tmp_path / "ring.parquet")
    back = read_photodiodes(path)
    assert back.sidecar["yaw_reference"] == "relative"
    assert back.columns == [f"u{i}_p{a:03d}" for i in range(6) for a in (0, 45, 90, 135)]
    np.testing.assert_allclose(np.mod(back.table["yaw_deg"] + 30.0, 360.0), np.mod(yaw, 360.0),
                               atol=1e-9)
    assert back.flags.summary()["saturated"] == 0
