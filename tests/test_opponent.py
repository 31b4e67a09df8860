"""Three-pair sensor (Yang et al. 2014 eqs. 2-3), DAQ and measurement tables (schema v1)."""

import json
import os

import numpy as np
import pandas as pd
import pytest

from sensor.daq import Daq
from sensor.errors import OpponentErrors
from sensor.measurement import MeasurementFormatError, read_measurement
from sensor.opponent import OpponentSensor, channel_outputs, zenith_polarization
from skysim.exceptions import InvalidParameterError, SunBelowHorizonError
from skysim.sky import RayleighSky
from skysim.sun import sun_position

START = "2013-05-22T17:10:00+08:00"


def test_ideal_outputs_closed_form():
    """At phi = 0 channel U2 (a = 0) sees cos 0 = 1: U2 = 0.5 log10((1+d)/(1-d)); U1 and U3
    (a = 60, 120) see cos 120 = cos 240 = -1/2: U = 0.5 log10((1-d/2)/(1+d/2))."""
    d = 0.5
    u = channel_outputs(0.0, d)
    np.testing.assert_allclose(u, [0.5 * np.log10(0.75 / 1.25), 0.5 * np.log10(3.0),
                                   0.5 * np.log10(0.75 / 1.25)], rtol=1e-14)


def test_errors_enter_as_in_eq2():
    """A transmittance term adds g*f; equal mounting errors of a channel's two photodiodes
    shift that channel's phase exactly."""
    phi = np.linspace(-90, 89, 50)
    base = channel_outputs(phi, 0.6)
    f = (0.01, -0.02, 0.005)
    np.testing.assert_allclose(channel_outputs(phi, 0.6, transmittance=f) - base,
                               np.broadcast_to(0.5 * np.array(f), base.shape), atol=1e-14)
    shifted = channel_outputs(phi, 0.6, misalignment_deg=(0.7, 0.7, 0, 0, 0, 0))
    np.testing.assert_allclose(shifted[:, 0], channel_outputs(phi + 0.7, 0.6)[:, 0], atol=1e-14)


@pytest.mark.parametrize("d", [1.0, 1.5, 0.0, -0.2, np.nan])
def test_bad_dop_raises(d):
    with pytest.raises(InvalidParameterError, match="dop"):
        channel_outputs(10.0, d)


def test_daq_quantisation_and_saturation():
    daq = Daq(16, 10.0)
    assert daq.lsb_V == pytest.approx(20 / 65536)
    v, sat = daq.acquire([0.12345, 12.0, -11.0])
    assert abs(v[0] - 0.12345) <= daq.lsb_V / 2
    assert sat.tolist() == [False, True, True]
    assert v[1] == pytest.approx(10 - daq.lsb_V) and v[2] == -10.0


def test_sample_uses_each_samples_own_sun(xian, rng):
    """phi = heading - sun azimuth at that sample's own time (DESIGN.md); over 10 minutes at
    17:10 the sun azimuth moves ~1.5 deg, so a constant heading gives a drifting phi."""
    times = pd.date_range(START, periods=61, freq="10s")
    heading = 200.0
    m = OpponentSensor().sample(RayleighSky(0.7), xian, times, np.full(61, heading), rng)
    sun = sun_position(times, xian.latitude_deg, xian.longitude_deg, xian.altitude_m)
    expected = (heading - sun.azimuth_deg.to_numpy() + 90) % 180 - 90
    np.testing.assert_allclose(m.table.true_phi_deg, expected, atol=1e-9)
    assert np.ptp(m.table.true_phi_deg) > 0.1


def test_sample_noise_free_matches_model(xian, rng):
    times = pd.date_range(START, periods=20, freq="30s")
    err = OpponentErrors(misalignment_deg=(0.3, -0.2, 0.5, 0.1, -0.4, 0.2),
                         transmittance=(0.01, -0.01, 0.0))
    m = OpponentSensor(err, daq=Daq(None)).sample(RayleighSky(0.7), xian, times,
                                                  np.linspace(180, 360, 20), rng)
    u = channel_outputs(m.table.true_phi_deg, m.table.true_dop, err.misalignment_deg,
                        err.transmittance)
    np.testing.assert_allclose(m.channels, u, atol=1e-15)


def test_sample_sun_below_horizon_raises(xian, rng):
    times = pd.date_range("2013-05-22T22:00:00+08:00", periods=3, freq="1min")
    with pytest.raises(SunBelowHorizonError, match="sun elevation"):
        OpponentSensor().sample(RayleighSky(0.7), xian, times, [0.0, 1.0, 2.0], rng)


def test_sample_is_reproducible_from_seed(xian):
    times = pd.date_range(START, periods=10, freq="30s")
    err = OpponentErrors(noise_V=5e-4)
    a = OpponentSensor(err).sample(RayleighSky(0.7), xian, times, np.arange(10.0),
                                   np.random.default_rng(7), seed=7)
    b = OpponentSensor(err).sample(RayleighSky(0.7), xian, times, np.arange(10.0),
                                   np.random.default_rng(7), seed=7)
    pd.testing.assert_frame_equal(a.table, b.table)
    assert a.sidecar["generator"]["seed"] == 7


@pytest.mark.parametrize("ext", [".csv", ".parquet"])
def test_measurement_round_trip(tmp_path, xian, rng, ext):
    times = pd.date_range(START, periods=30, freq="20s")
    m = OpponentSensor(OpponentErrors(noise_V=3e-4)).sample(RayleighSky(0.7), xian, times,
                                                            np.linspace(185, 365, 30), rng,
                                                            seed=1, sweep="a")
    path = m.write(tmp_path / f"data{ext}")
    side = json.loads((tmp_path / f"data{ext}.json").read_text())
    assert side["schema"] == "skysim.measurement/1" and side["site"]["latitude_deg"] > 34
    back = read_measurement(path)
    assert (back.table.time == m.table.time).all()
    np.testing.assert_allclose(back.channels, m.channels, rtol=0, atol=1e-15)
    assert "true_phi_deg" in back.table  # unknown extra columns are kept


def _write_table(tmp_path, table, sidecar=None):
    path = tmp_path / "t.csv"
    table.to_csv(path, index=False)
    sidecar = sidecar or {"schema": "skysim.measurement/1",
                          "site": {"latitude_deg": 34.1, "longitude_deg": 108.5}}
    (tmp_path / "t.json").write_text(json.dumps(sidecar))
    return path


def _table(**over):
    t = pd.DataFrame({"time": ["2013-05-22T17:10:00+08:00"] * 3, "heading_deg": [1.0, 2, 3],
                      "U1_V": [0.1, 0.2, 0.3], "U2_V": [0.1, 0.2, 0.3], "U3_V": [0.0, 0, 0]})
    for k, v in over.items():
        t[k] = v
    return t


def test_reader_rejects_bad_files(tmp_path):
    with pytest.raises(MeasurementFormatError, match="missing required column"):
        read_measurement(_write_table(tmp_path, _table().drop(columns="U3_V")))
    with pytest.raises(MeasurementFormatError, match="'U2_V' has 1 NaN"):
        read_measurement(_write_table(tmp_path, _table(U2_V=[0.1, np.nan, 0.2])))
    with pytest.raises(MeasurementFormatError, match="no UTC offset"):
        read_measurement(_write_table(tmp_path, _table(time=["2013-05-22T17:10:00"] * 3)))
    with pytest.raises(MeasurementFormatError, match="no 'site'"):
        read_measurement(_write_table(tmp_path, _table(), {"schema": "skysim.measurement/1"}))
    with pytest.raises(MeasurementFormatError, match="schema"):
        read_measurement(_write_table(tmp_path, _table(), {"schema": "other/2", "site": {}}))
    (tmp_path / "t.json").write_text("{not json")
    with pytest.raises(MeasurementFormatError, match="not valid JSON"):
        read_measurement(tmp_path / "t.csv")
    os.remove(tmp_path / "t.json")
    with pytest.raises(FileNotFoundError, match="sidecar"):
        read_measurement(tmp_path / "t.csv")


def test_writer_leaves_nothing_half_written(tmp_path, xian, rng, monkeypatch):
    """If writing the sidecar fails, neither file appears (and an old file is untouched)."""
    times = pd.date_range(START, periods=5, freq="20s")
    m = OpponentSensor().sample(RayleighSky(0.7), xian, times, np.arange(5.0), rng)
    m.sidecar["generator"]["bad"] = object()  # not JSON serialisable: the sidecar write fails
    with pytest.raises(TypeError):
        m.write(tmp_path / "x.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_zenith_polarization_matches_design_convention(xian):
    """For a Rayleigh sky phi = wrap(heading - sun azimuth) into [-90, 90)."""
    times = pd.date_range(START, periods=5, freq="2min")
    headings = np.array([0.0, 100.0, 275.0, 300.0, 359.0])
    phi, dop, el, az = zenith_polarization(RayleighSky(0.7), xian, times, headings)
    np.testing.assert_allclose(phi, (headings - az + 90) % 180 - 90, atol=1e-9)
    np.testing.assert_allclose(dop, 0.7 * np.cos(np.radians(el)) ** 2
                               / (1 + np.sin(np.radians(el)) ** 2), rtol=1e-12)
