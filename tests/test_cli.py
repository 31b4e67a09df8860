"""The command line: foundation sub-commands end to end, errors as exit code 2."""

import json

import numpy as np
import pandas as pd
import pytest

from experiments.cli.main import main


def test_sky_command_with_site_and_time(tmp_path, capsys):
    out = tmp_path / "sky.csv"
    rc = main(["sky", "--lat", "34.14", "--lon", "108.55", "--time", "2013-05-22T17:10+08:00",
               "--dmax", "0.7", "--grid-step", "10", "--out", str(out),
               "--plot", str(tmp_path / "sky.png")])
    assert rc == 0
    t = pd.read_csv(out)
    assert list(t.columns) == ["elevation_deg", "azimuth_deg", "dop", "aop_deg", "I", "Q", "U"]
    assert t.dop.max() == pytest.approx(0.7, abs=0.01)  # grid passes near 90 deg from the sun
    np.testing.assert_allclose(np.hypot(t.Q, t.U) / t.I, t.dop, atol=1e-12)
    side = json.loads((tmp_path / "sky.csv.json").read_text())
    assert side["sky"] == {"model": "rayleigh", "dmax": 0.7} and "meridian" in side["aop_convention"]
    assert (tmp_path / "sky.png").stat().st_size > 10_000


def test_sky_command_with_sun_angles_and_directions(tmp_path):
    dirs = tmp_path / "dirs.csv"
    pd.DataFrame({"elevation_deg": [90.0, 0.0], "azimuth_deg": [0.0, 30.0]}).to_csv(dirs)
    out = tmp_path / "sky.parquet"
    assert main(["sky", "--sun-elevation", "30", "--sun-azimuth", "300", "--directions",
                 str(dirs), "--out", str(out)]) == 0
    t = pd.read_parquet(out)
    # zenith: gamma = 60 deg -> 0.75/1.25; horizon at 270 deg azimuth from the sun: gamma = 90
    np.testing.assert_allclose(t.dop, [0.6, 1.0], atol=1e-12)


def test_sample_then_calibrate(tmp_path, capsys):
    data = tmp_path / "m.csv"
    assert main(["sample", "--out", str(data), "--seed", "3"]) == 0
    assert main(["calibrate", str(data), "--out", str(tmp_path / "cal.json")]) == 0
    text = capsys.readouterr().out
    assert "compensated_3sigma_deg" in text
    cal = json.loads((tmp_path / "cal.json").read_text())
    assert len(cal["pairs"]) == 3 and all(p["converged"] for p in cal["pairs"])


def test_reproduce_yang2014_small(tmp_path, capsys):
    assert main(["reproduce", "yang2014", "--trials", "5", "--out", str(tmp_path)]) == 0
    assert "paper values inside" in capsys.readouterr().out
    assert (tmp_path / "table1.csv").exists()


@pytest.mark.parametrize("argv,msg", [
    (["sky", "--lat", "34", "--lon", "108", "--time", "2013-05-22T17:10"], "no UTC offset"),
    (["sky", "--lat", "95", "--lon", "108", "--time", "2013-05-22T17:10Z"], "--lat"),
    (["sky", "--sun-elevation", "-12", "--sun-azimuth", "10"], "twilight limit"),
    (["sky", "--model", "mie", "--sun-elevation", "3", "--sun-azimuth", "10"], "valid"),
    (["calibrate", "/nonexistent.csv"], "no file /nonexistent.csv"),
])
def test_errors_exit_2_with_message(argv, msg, capsys):
    assert main(argv) == 2
    assert msg in capsys.readouterr().err
