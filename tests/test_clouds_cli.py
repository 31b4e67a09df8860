"""``--clouds`` on the command line: ``skysim sky``, ``camera``, ``sample`` and the ``clouds``
table of ``skysim generate``."""

import json

import numpy as np
import pandas as pd
import pytest

from experiments.cli.main import main

SUN = ["--sun-elevation", "35", "--sun-azimuth", "120"]


def _sidecar(path):
    return json.loads(path.with_name(path.name + ".json").read_text())


def test_help_states_units_and_form(capsys):
    assert main(["sky", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "COVER[,TAU[,SEED]]" in out and "fraction of the sky, 0-1" in out
    assert "optical thickness at 550 nm" in out and "[deg]" in out and "[m]" in out
    assert main(["sample", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "--wind SPEED,FROM" in out and "speed [m/s]" in out


def test_sky_map_with_clouds_differs_from_the_clear_one_only_under_the_clouds(tmp_path):
    clear, cloudy = tmp_path / "clear.csv", tmp_path / "cloudy.csv"
    assert main(["sky", *SUN, "--grid-step", "10", "--out", str(clear)]) == 0
    assert main(["sky", *SUN, "--grid-step", "10", "--clouds", "0.5,8,2", "--cloud-scale",
                 "15", "--cloud-base", "2000", "--out", str(cloudy)]) == 0
    a, b = pd.read_csv(clear), pd.read_csv(cloudy)
    side = _sidecar(cloudy)["sky"]
    assert side["model"] == "partly-cloudy" and side["clear"]["model"] == "rayleigh"
    assert side["clouds"]["cover"] == 0.5 and side["clouds"]["tau"] == 8.0
    assert side["clouds"]["seed"] == 2 and side["clouds"]["correlation_deg"] == 15.0
    assert side["clouds"]["base_m"] == 2000.0
    from skysim.cloud_field import CloudField
    cloud = CloudField(0.5, 8.0, 2, correlation_deg=15.0, base_m=2000.0).cloudy(
        b.elevation_deg, b.azimuth_deg)
    assert 0.2 < cloud.mean() < 0.8
    # a sunlit cloud is brighter than the blue sky it hides (above 10 deg: lower down the
    # clouds fade into the haze); where no cloud is seen the sky can only be shaded
    high = b.elevation_deg.to_numpy() >= 10.0
    assert np.all(b.I[cloud & high] > a.I[cloud & high])
    assert np.all(b.I[~cloud] <= a.I[~cloud] * (1 + 1e-12))


@pytest.mark.parametrize("argv, message", [
    (["--clouds", "1.5"], "must be in [0, 1]"),
    (["--clouds", "0.5,-1"], "must be in [0, 100]"),
    (["--clouds", "0.5,5,-2"], "must be an integer >= 0"),
    (["--clouds", "0.5,5,2,9"], "COVER[,TAU[,SEED]]"),
    (["--clouds", "half"], "not a number"),
    (["--clouds", "0.5,,2"], "COVER[,TAU[,SEED]]"),
    (["--cloud-scale", "5"], "give --clouds"),
    (["--clouds", "0.5", "--cloud-scale", "0"], "must be in (0, 60] deg"),
    (["--clouds", "0.5", "--cloud-base", "20"], "must be in [50, 15000] m"),
])
def test_bad_cloud_options_are_errors(capsys, argv, message):
    assert main(["sky", *SUN, "--grid-step", "30", *argv]) == 2
    assert message in capsys.readouterr().err


def test_clouds_need_the_sunlit_sky(capsys):
    pytest.importorskip("astropy", reason="the Moon's position needs the 'moon' extra")
    assert main(["sky", "--source", "moon", "--lat", "-24.6", "--lon", "-70.4", "--time",
                 "2024-06-22T04:00Z", "--clouds", "0.5", "--grid-step", "30"]) == 2
    assert "lit by the Sun" in capsys.readouterr().err


def test_camera_image_under_clouds(tmp_path):
    pytest.importorskip("tifffile", reason="16-bit TIFF needs the 'camera' extra")
    out = tmp_path / "cam.tif"
    args = ["camera", "--lat", "34.1", "--lon", "108.5", "--time", "2024-05-01T10:00+08:00",
            "--width", "64", "--height", "64", "--out", str(out)]
    assert main(args + ["--clouds", "0.6,5,1"]) == 0
    doc = json.loads(out.with_suffix(".json").read_text()) if out.with_suffix(".json").exists() \
        else _sidecar(out)
    assert doc["generator"]["sky"]["model"] == "partly-cloudy"
    assert doc["generator"]["sky"]["clouds"]["cover"] == 0.6


def test_sample_under_drifting_clouds(tmp_path):
    # the three-pair sensor under clouds that drift with a 10 m/s wind: the recorded truth
    # (zenith DoP) changes as clouds pass, and the clear run does not see them
    cloudy, clear = tmp_path / "cloudy.csv", tmp_path / "clear.csv"
    base = ["sample", "--n", "60", "--duration", "600", "--errors", "none", "--no-daq"]
    assert main(base + ["--out", str(clear)]) == 0
    assert main(base + ["--out", str(cloudy), "--clouds", "0.6,5,4", "--wind", "10,270"]) == 0
    a, b = pd.read_csv(clear), pd.read_csv(cloudy)
    side = _sidecar(cloudy)["generator"]["sky"]
    assert side["clouds"]["wind_speed_m_s"] == 10.0 and side["time_s"] == "one per sun position"
    assert np.ptp(b.true_dop) > 5 * np.ptp(a.true_dop)
    assert main(base + ["--out", str(tmp_path / "x.csv"), "--wind", "10,270"]) == 2


def test_generate_takes_a_clouds_table(tmp_path):
    cfg = tmp_path / "g.toml"
    cfg.write_text("""seed = 7
[site]
latitude_deg = 34.1
longitude_deg = 108.5
[[sky_map]]
name = "cloudy_map"
clouds = {cover = 0.5, tau = 8.0, seed = 2}
sun_elevation_deg = 40.0
sun_azimuth_deg = 120.0
grid_step_deg = 15.0
[[photodiodes]]
name = "cloudy_ring"
clouds = {cover = 0.6, tau = 5.0, seed = 3, wind_speed_m_s = 10.0}
start = "2013-05-22T17:10:00+08:00"
duration_s = 60.0
n = 12
""")
    assert main(["generate", str(cfg), "--out", str(tmp_path / "out")]) == 0
    side = _sidecar(tmp_path / "out" / "cloudy_ring.csv")
    assert side["generator"]["sky"]["clouds"]["seed"] == 3
    cfg.write_text(cfg.read_text().replace("seed = 3,", "seed = 3, puffy = 1,"))
    assert main(["generate", str(cfg), "--out", str(tmp_path / "out2")]) == 2
    cfg.write_text(cfg.read_text().replace("puffy = 1,", "").replace("cover = 0.6", "cover = 2"))
    assert main(["generate", str(cfg), "--out", str(tmp_path / "out3")]) == 2
