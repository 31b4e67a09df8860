"""A newcomer's bad inputs to the command line, one case each: wrong units and values, not
numbers, empty, truncated and mis-shaped files, naive times, out-of-range sites, huge and
negative sizes, unknown names, contradictory options, outputs that would replace an input or
each other, unwritable places.

Every case runs the real command line and must end with exit code 2, one line on stderr
(after argparse's usage block, if any) starting ``skysim `` and naming the offending value,
and every file that was there before unchanged (checksums) with no file added.
"""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest
from test_cli_errors import _run_cli

from experiments.cli.main import main

T = "2013-05-22T12:00+08:00"
SUN = ["--sun-elevation", "30", "--sun-azimuth", "10"]
CAM = ["camera", "--lat", "34", "--lon", "108", "--time", T, "--width", "64", "--height", "64"]
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
MOON_DOWN = "2026-12-06T00:00+08:00"
"""The Moon 58 deg below the horizon at the Xi'an site (34.14 N, 108.55 E)."""


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """The files a newcomer has at hand: a measurement table, a camera image, direction
    tables, configurations, and broken copies of them."""
    root = tmp_path_factory.mktemp("battery")
    assert main(["sample", "--out", str(root / "m.csv"), "--n", "40"]) == 0
    assert main([*CAM, "--out", str(root / "sky.png")]) == 0
    text = (root / "m.csv").read_text()
    rows = text.splitlines(keepends=True)                        # cut inside a reading
    (root / "trunc.csv").write_text("".join(rows[:21]) + rows[21][:60])
    shutil.copy(root / "m.csv.json", root / "trunc.csv.json")
    (root / "old.csv").write_text(text)                          # the older sidecar spelling
    shutil.copy(root / "m.csv.json", root / "old.json")
    (root / "cut.png").write_bytes((root / "sky.png").read_bytes()[:100])
    shutil.copy(root / "sky.png.json", root / "cut.png.json")
    (root / "text.png").write_text("not an image\n")
    shutil.copy(root / "sky.png.json", root / "text.png.json")
    (root / "empty.csv").write_text("")
    (root / "blank.json").write_text("")
    (root / "d.csv").write_text("elevation_deg,azimuth_deg\n10,20\n30,40\n")
    (root / "dup.csv").write_text("elevation_deg,azimuth_deg,elevation_deg\n10,20,30\n")
    (root / "nan.csv").write_text("elevation_deg,azimuth_deg\n10,20\nnan,40\n")
    (root / "schema.csv").write_text("el,az\n10,20\n")
    (root / "up.csv").write_text("elevation_deg,azimuth_deg\n10,20\n95,40\n")
    (root / "bad.toml").write_text("[sweep\nname = ")
    (root / "sweep_in").mkdir()                                  # a configuration named like
    shutil.copy(EXAMPLES / "sweep_montecarlo.toml", root / "sweep_in" / "summary.md")  # output
    (root / "a_folder").mkdir()
    (root / "real").mkdir()
    return root


CASES = {
    # outputs that would replace an input or another output
    "figure over its input image": (["camera-heading", "sky.png", "--figure", "sky.png"],
                                    ["--figure sky.png", "input image sky.png"]),
    "figure over the raw image": ([*CAM, "--out", "same.png", "--figure", "same.png"],
                                  ["--out same.png", "--figure same.png"]),
    "figure over the raw image by another path": (
        [*CAM, "--out", "same.png", "--figure", "a_folder/../same.png"],
        ["--out same.png", "a_folder/../same.png"]),
    "calibration over the older sidecar": (["calibrate", "old.csv", "--out", "old.json"],
                                           ["--out old.json", "would replace"]),
    "calibration over the sidecar": (["calibrate", "m.csv", "--out", "m.csv.json"],
                                     ["--out m.csv.json", "would replace"]),
    "sky table over its directions": (["sky", *SUN, "--directions", "d.csv", "--out", "d.csv"],
                                      ["--out d.csv", "--directions d.csv"]),
    "diagnosis into the folder of its reports": (
        ["diagnose", "m.csv", "--out", ".", "--pointing-from", "diagnosis.json"],
        ["diagnosis.json"]),
    "reproduction folder holding its data": (
        ["reproduce", "real-sky-compass", "--data", "real", "--out", "."],
        ["--out .", "--data real"]),
    "sweep into the folder of its configuration": (
        ["sweep", "sweep_in/summary.md", "--out", "sweep_in"],
        ["--out sweep_in/summary.md", "config sweep_in/summary.md"]),
    # contradictory options
    "time with sun angles": (["sky", *SUN, "--time", T], ["--time 2013-05-22T12:00:00+08:00",
                                                          "--sun-elevation 30"]),
    "site with sun angles": (["sky", *SUN, "--lat", "34"], ["--lat 34", "--sun-elevation 30"]),
    "sun azimuth alone": (["sky", "--sun-azimuth", "10", "--lat", "34", "--lon", "108",
                           "--time", T], ["--sun-azimuth 10", "--sun-elevation"]),
    "moon below the horizon": (["sky", "--source", "moon", "--lat", "34.14", "--lon", "108.55",
                                "--time", MOON_DOWN, "--out", "m2.csv"],
                               ["--source moon", "-58.", "2026-12-06T00:00:00+08:00"]),
    "empty effect list": (["diagnose", "m.csv", "--effects", ""], ["--effects", "''"]),
    "an empty effect name": (["diagnose", "m.csv", "--effects", "tilt,,fov"],
                             ["--effects", "'tilt,,fov'"]),
    "empty report list": (["diagnose", "m.csv", "--pointing-from", " "],
                          ["--pointing-from", "' '"]),
    "sweep of no duration": (["sample", "--out", "s.csv", "--duration", "0"],
                             ["--duration", "'0'"]),
    "multiple without thickness": (["sky", *SUN, "--model", "multiple"], ["--tau"]),
    "another model's option": (["sky", *SUN, "--dmax", "0.5", "--model", "multiple", "--tau",
                                "0.1"], ["--dmax", "--model multiple"]),
    # sizes refused before the work
    "a billion camera trials": (["reproduce", "camera", "--trials", "1e9", "--out", "r"],
                                ["1000000000 trials"]),
    "camera trials for days": (["reproduce", "camera", "--trials", "100000", "--out", "r"],
                               ["--trials 100000", "days"]),
    "a huge camera image": ([*CAM[:-4], "--width", "1e6", "--height", "1e6", "--out", "c.tif"],
                            ["1000000x1000000"]),
    "a sky grid too fine": (["sky", *SUN, "--grid-step", "1e-6", "--out", "g.csv"],
                            ["--grid-step 1e-06"]),
    "10^30 samples": (["sample", "--out", "s.csv", "--n", "1e30"], ["--n 1000000000000000"]),
    "a benchmark for weeks": (["gap-benchmark", "--n", "1e7"], ["10000000 data sets"]),
    # values: not numbers, wrong units, out of range, negative
    "yaw not a number": ([*CAM, "--out", "c.tif", "--yaw", "nan"], ["--yaw", "'nan'"]),
    "altitude infinite": ([*CAM, "--out", "c.tif", "--alt", "inf"], ["--alt", "'inf'"]),
    "altitude in feet": ([*CAM, "--out", "c.tif", "--alt", "29000"], ["--alt", "'29000'"]),
    "ADC of 99 bits": ([*CAM, "--out", "c.tif", "--adc-bits", "99"], ["--adc-bits", "'99'"]),
    "latitude out of range": (["camera", "--lat", "91", *CAM[3:], "--out", "c.tif"],
                              ["--lat", "'91'"]),
    "longitude out of range": (["sky", "--lat", "34", "--lon", "400", "--time", T],
                               ["--lon", "'400'"]),
    "sun elevation overflowing": (["sky", "--sun-elevation", "1e400", "--sun-azimuth",
                                          "0"], ["--sun-elevation", "'1e400'"]),
    "sun azimuth not a number": (["sky", "--sun-elevation", "30", "--sun-azimuth", "nan"],
                                 ["--sun-azimuth", "'nan'"]),
    "negative sample count": (["sample", "--out", "s.csv", "--n", "-3"], ["--n", "'-3'"]),
    "fractional seed": (["sample", "--out", "s.csv", "--seed", "1.5"], ["--seed", "'1.5'"]),
    "cloud cover as percent": (["sky", *SUN, "--clouds", "50"], ["--clouds", "'50'"]),
    "wind without direction": (["sample", "--out", "s.csv", "--wind", "8"], ["--wind", "'8'"]),
    "infinite time uncertainty": (["diagnose", "m.csv", "--time-uncertainty", "inf"],
                                  ["--time-uncertainty", "'inf'"]),
    "one fold": (["diagnose", "m.csv", "--folds", "1"], ["--folds", "'1'"]),
    "zero exposure": ([*CAM, "--out", "c.tif", "--exposure", "0"], ["--exposure", "'0'"]),
    # times
    "naive camera time": ([*CAM[:6], "2013-05-22T12:00", *CAM[7:], "--out", "c.tif"],
                          ["--time", "no UTC offset"]),
    "naive sample start": (["sample", "--out", "s.csv", "--start", "2013-05-22 17:10"],
                           ["--start", "no UTC offset"]),
    "a date beyond the calendar": (["sky", "--lat", "34", "--lon", "108", "--time",
                                    "3000-01-01T00:00Z"], ["--time", "1678-2261"]),
    # unknown names
    "unknown sky model": (["sky", *SUN, "--model", "mie"], ["--model", "'mie'"]),
    "unknown reproduction": (["reproduce", "nosuch"], ["'nosuch'"]),
    "unknown errors spelling": (["sample", "--out", "s.csv", "--errors", "nope.json"],
                                ["--errors", "nope.json"]),
    "data option of another reproduction": (["reproduce", "yang2014", "--data", "real",
                                             "--out", "r"], ["--data"]),
    # files: missing, folders, empty, truncated, mis-shaped
    "missing image": (["camera-heading", "nope.png"], ["nope.png"]),
    "a folder as the image": (["camera-heading", "a_folder"], ["a_folder"]),
    "truncated image": (["camera-heading", "cut.png"], ["cut.png"]),
    "text named .png": (["camera-heading", "text.png"], ["text.png"]),
    "empty errors file": (["sample", "--out", "s.csv", "--errors", "blank.json"],
                          ["blank.json"]),
    "empty measurement": (["calibrate", "empty.csv"], ["empty.csv"]),
    "truncated measurement": (["calibrate", "trunc.csv"], ["trunc.csv", "row"]),
    "doubled direction column": (["sky", *SUN, "--directions", "dup.csv"],
                                 ["dup.csv", "elevation_deg"]),
    "direction not a number": (["sky", *SUN, "--directions", "nan.csv"], ["nan.csv", "row 2"]),
    "directions of another schema": (["sky", *SUN, "--directions", "schema.csv"],
                                     ["schema.csv", "missing column"]),
    "direction below the zenith's range": (["sky", *SUN, "--directions", "up.csv"],
                                           ["up.csv", "row 2", "95"]),
    "empty directions": (["sky", *SUN, "--directions", "empty.csv"], ["empty.csv"]),
    "broken sweep configuration": (["sweep", "bad.toml"], ["bad.toml"]),
    "broken generate configuration": (["generate", "bad.toml", "--out", "g"], ["bad.toml"]),
    # outputs that cannot be written
    "output folder is a file": (["generate", "bad.toml", "--out", "m.csv"], ["m.csv"]),
    "output in a folder that refuses files": (["sky", *SUN, "--out", "/proc/skysim/t.csv"],
                                              ["/proc/skysim/t.csv"]),
    "output under a file": (["sample", "--out", "m.csv/s.csv"], ["m.csv"]),
    "output of the wrong kind": (["sky", *SUN, "--out", "t.txt"], ["t.txt"]),
    "image of the wrong kind": ([*CAM, "--out", "c.bmp"], ["c.bmp"]),
}


def _checksums(root: Path) -> dict:
    return {p.relative_to(root): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_and_loses_nothing(case, folder, capsys, monkeypatch):
    argv, needles = CASES[case]
    if "moon" in argv:
        pytest.importorskip("astropy", reason="the Moon's position needs the 'moon' extra")
    monkeypatch.chdir(folder)
    before = _checksums(folder)
    capsys.readouterr()
    res = _run_cli(argv, capsys)
    assert res.code == 2 and res.clean and res.usage_only and res.names(*needles), res.err
    assert _checksums(folder) == before


def test_the_battery_is_large():
    assert len(CASES) >= 40
