"""Every class of bad input to the command line ends in one specific error line, exit code 2,
the offending value named, no traceback, and no file written or lost.

One test (or one parametrized family) per class: option values, output paths, input files,
sidecars, model options, configurations, resources, interrupts and pipes, missing extras.
"""

from __future__ import annotations

import io
import json
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from experiments.cli.main import (EXIT_BROKEN_PIPE, EXIT_INTERNAL, EXIT_INTERRUPTED, build_parser,
                                  main)

SUN = ["--sun-elevation", "30", "--sun-azimuth", "10"]
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@dataclass(frozen=True)
class CliRun:
    """A command's exit code and what it wrote to standard error."""

    code: int
    err: str

    @property
    def line(self) -> str:
        """The last line of standard error: the error message."""
        lines = self.err.strip().splitlines()
        return lines[-1] if lines else ""

    @property
    def clean(self) -> bool:
        """No traceback, and the last line is the program's own (``skysim ...``)."""
        return "Traceback" not in self.err and self.line.startswith("skysim")

    @property
    def usage_only(self) -> bool:
        """Nothing on standard error before the error line but argparse's usage block."""
        lines = self.err.strip().splitlines()
        return len(lines) <= 1 or (lines[0].startswith("usage: skysim ")
                                   and all(line.startswith(" ") for line in lines[1:-1]))

    def names(self, *needles: str) -> bool:
        """Whether the error line holds every one of ``needles``."""
        return all(n in self.line for n in needles)


def _run_cli(argv, capsys) -> CliRun:
    """Run the command line on ``argv``: its exit code and standard error."""
    code = main(argv)
    return CliRun(code, capsys.readouterr().err)


# --------------------------------------------------------------------------- option values

@pytest.mark.parametrize("argv,needles", [
    (["sky", "--sun-elevation", "95", "--sun-azimuth", "1"], ["--sun-elevation", "'95'"]),
    (["sky", *SUN, "--grid-step", "0"], ["--grid-step", "'0'"]),
    (["sky", *SUN, "--grid-step", "nan"], ["--grid-step", "'nan'"]),
    (["sky", *SUN, "--dmax", "1.5"], ["--dmax", "'1.5'"]),
    (["sky", "--lat", "95", "--lon", "1", "--time", "2013-05-22T17:10Z"], ["--lat", "'95'"]),
    (["sky", "--lat", "34", "--lon", "108", "--time", "2013-05-22T17:10"],
     ["--time", "no UTC offset"]),
    (["sky", "--lat", "34", "--lon", "108", "--time", "3000-01-01T00:00+08:00"],
     ["--time", "1678-2261"]),
    (["sky", "--lat", "34", "--lon", "108", "--time", "teatime"], ["--time", "'teatime'"]),
    (["sample", "--out", "x.csv", "--n", "0"], ["--n", "'0'"]),
    (["sample", "--out", "x.csv", "--n", "-5"], ["--n", "'-5'"]),
    (["sample", "--out", "x.csv", "--n", "2.5"], ["--n", "'2.5'"]),
    (["sample", "--out", "x.csv", "--seed", "-1"], ["--seed", "'-1'"]),
    (["sample", "--out", "x.csv", "--duration", "-600"], ["--duration", "'-600'"]),
    (["sample", "--out", "x.csv", "--sweeps", "0"], ["--sweeps", "'0'"]),
    (["reproduce", "yang2014", "--trials", "0"], ["--trials", "'0'"]),
    (["reproduce", "yang2014", "--trials", "-5"], ["--trials", "'-5'"]),
    (["jin2020", "--trials", "0"], ["--trials", "'0'"]),
    (["diagnose", str(EXAMPLES / "sweep_montecarlo.toml"), "--time-uncertainty", "-60"], ["--time-uncertainty", "'-60'"]),
    (["sweep", str(EXAMPLES / "sweep_montecarlo.toml"), "--workers", "0"],
     ["--workers", "'0'"]),
])
def test_option_values_are_checked_when_parsed(argv, needles, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = _run_cli(argv, capsys)
    assert res.code == 2 and res.clean and res.names(*needles), res.err
    assert list(tmp_path.iterdir()) == []


def test_values_in_range_but_inconsistent(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = _run_cli(["sample", "--out", "x.csv", "--sweeps", "2", "--duration", "600",
                    "--sweep-interval", "60"], capsys)
    assert (res.code == 2 and res.clean
            and res.names("--sweep-interval 60", "--duration 600")), res.err
    res = _run_cli(["sample", "--out", "x.csv", "--start", "2261-12-31T00:00+00:00",
                    "--sweeps", "3", "--sweep-interval", "1e9"], capsys)
    assert res.code == 2 and res.clean and res.names("1678-2261"), res.err
    res = _run_cli(["sky", "--sun-elevation", "30"], capsys)
    assert res.code == 2 and res.clean and res.names("--sun-azimuth"), res.err
    assert list(tmp_path.iterdir()) == []


def test_another_models_option_is_an_error(capsys):
    res = _run_cli(["sky", *SUN, "--tau", "0.3"], capsys)
    assert (res.code == 2 and res.clean
            and res.names("--tau", "--model multiple", "--model rayleigh")), res.err
    res = _run_cli(["sky", *SUN, "--model", "berry", "--albedo", "0.2"], capsys)
    assert res.code == 2 and res.clean and res.names("--albedo"), res.err
    from skysim.exceptions import InvalidParameterError
    from skysim.sky import make_sky
    with pytest.raises(InvalidParameterError, match=r"has no parameter\(s\) \['tau'\]"):
        make_sky("rayleigh", tau=0.3)


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("skysim ")


def _help_texts():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.choices and "sky" in a.choices)
    return {name: p.format_help() for name, p in sub.choices.items()}


@pytest.mark.parametrize("name", sorted(_help_texts()))
def test_help_speaks_to_users(name):
    text = " ".join(_help_texts()[name].split())
    assert not re.search(r"\bissue \d", text, flags=re.I), name
    assert not re.search(r"\(default:? [^)]*\) \(default", text), name


# --------------------------------------------------------------------------- output paths

WRITERS = [
    ["sky", *SUN, "--out", "{bad}/t.csv"],
    ["sky", *SUN, "--plot", "{bad}/p.png"],
    ["sample", "--out", "{bad}/s.csv"],
    ["reproduce", "yang2014", "--quick", "--out", "{bad}/r"],
    ["generate", "{cfg}", "--out", "{bad}/g"],
    ["compare", "{data}", "{data}", "--report", "{bad}/r.json"],
    ["calibrate", "{data}", "--out", "{bad}/c.json"],
    ["sweep", "{sweep}", "--out", "{bad}/w"],
]


@pytest.fixture
def inputs(tmp_path):
    data = tmp_path / "in" / "m.csv"
    assert main(["sample", "--out", str(data), "--n", "40"]) == 0
    cfg = tmp_path / "in" / "g.toml"
    cfg.write_text('seed = 1\n[[sky_map]]\nname = "m"\nsun_elevation_deg = 30.0\n'
                   'sun_azimuth_deg = 0.0\ngrid_step_deg = 30.0\n')
    sweep = tmp_path / "in" / "w.toml"
    sweep.write_text('[sweep]\nname = "w"\ntrials = 64\nstops = 16\n'
                     '[parameters]\nnoise_V = {uniform = [0.0001, 0.002]}\n')
    return {"data": str(data), "cfg": str(cfg), "sweep": str(sweep)}


@pytest.mark.parametrize("argv", WRITERS, ids=lambda a: " ".join(a[:2]))
@pytest.mark.parametrize("kind", ["under_a_file", "name_taken"])
def test_unwritable_outputs_fail_before_any_work(argv, kind, inputs, tmp_path, capsys):
    if kind == "under_a_file":     # e.g. --out sky.csv/t.csv
        blocker = tmp_path / "blocker"
        blocker.write_text("a file, not a folder")
        args = [a.format(bad=blocker, **inputs) for a in argv]
        needle = str(blocker)
    else:                          # a folder where a file is wanted, a file where a folder is
        args = [a.format(bad=tmp_path / "ok", **inputs) for a in argv]
        target = Path(args[-1])
        target.parent.mkdir()
        if target.suffix:
            target.mkdir()
        else:
            target.write_text("a file, not a folder")
        needle = str(target)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    capsys.readouterr()
    res = _run_cli(args, capsys)
    assert res.code == 2 and res.clean and res.names(needle), res.err
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux /proc (not writable)")
def test_a_folder_that_refuses_files(capsys, tmp_path, monkeypatch):
    """/proc accepts no new files even for root (os.access would say it does)."""
    res = _run_cli(["sky", *SUN, "--out", "/proc/skysim-test/t.csv"], capsys)
    assert res.code == 2 and res.clean and res.names("cannot write"), res.err
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        res = _run_cli(["sample", "--out", str(ro / "s.csv")], capsys)
        assert res.code == 2 and res.clean and res.names("cannot write"), res.err


def test_written_files_have_ordinary_permissions(tmp_path):
    from skysim.io import _FILE_MODE
    out = tmp_path / "s.csv"
    assert main(["sample", "--out", str(out), "--n", "20"]) == 0
    for p in (out, tmp_path / "s.csv.json"):
        assert p.stat().st_mode & 0o777 == _FILE_MODE
    mask = os.umask(0)
    os.umask(mask)
    assert _FILE_MODE == 0o666 & ~mask   # 0644 under the usual umask 022


# --------------------------------------------------------------------------- input files

@pytest.mark.parametrize("content,needle", [
    ("", "is empty"),
    ("elevation_deg,azimuth_deg\n", "no directions"),
    ("elevation_deg,azimuth_deg\n10,20\nhigh,30\n", "row 2 is 'high'"),
    ("el,az\n10,20\n", "missing column(s) ['azimuth_deg', 'elevation_deg']"),
])
def test_directions_file_errors_name_file_and_row(content, needle, tmp_path, capsys):
    f = tmp_path / "d.csv"
    f.write_text(content)
    res = _run_cli(["sky", *SUN, "--directions", str(f)], capsys)
    assert res.code == 2 and res.clean and res.names(needle, "d.csv"), res.err


def test_directions_folder_and_missing_file(tmp_path, capsys):
    res = _run_cli(["sky", *SUN, "--directions", str(tmp_path)], capsys)
    assert res.code == 2 and res.clean and res.names("is a folder"), res.err
    res = _run_cli(["sky", *SUN, "--directions", str(tmp_path / "none.csv")], capsys)
    assert res.code == 2 and res.clean and res.names("no file"), res.err


@pytest.mark.parametrize("content,needle", [
    ('{"misalignment_deg": [0, 0, 0, 0, 0, 0]}', "missing key(s) ['transmittance', 'noise_V']"),
    ('{"misalignment_deg": [0, 0], "transmittance": [0, 0, 0], "noise_V": 0.001}',
     "misalignment_deg must be a list of 6 numbers"),
    ('{"misalignment": [0, 0, 0, 0, 0, 0], "transmittance": [0, 0, 0], "noise_V": 0}',
     "unknown key(s) ['misalignment']"),
    ("[1, 2]", "got a list"),
    ("{nope", "not valid JSON"),
])
def test_errors_json_is_checked(content, needle, tmp_path, capsys):
    f = tmp_path / "e.json"
    f.write_text(content)
    res = _run_cli(["sample", "--out", str(tmp_path / "s.csv"), "--errors", str(f)], capsys)
    assert res.code == 2 and res.clean and res.names(needle), res.err
    assert not (tmp_path / "s.csv").exists()


# --------------------------------------------------------------------------- sidecars

@pytest.fixture
def table(tmp_path):
    out = tmp_path / "m.csv"
    assert main(["sample", "--out", str(out), "--n", "40"]) == 0
    return out


def test_sidecar_named_after_the_whole_file_name(tmp_path):
    """sky.parquet then sky.csv (the README's consecutive examples) keep their own sidecars."""
    a, b = tmp_path / "sky.parquet", tmp_path / "sky.csv"
    assert main(["sky", *SUN, "--grid-step", "30", "--out", str(a)]) == 0
    assert main(["sky", "--sun-elevation", "50", "--sun-azimuth", "10", "--grid-step", "30",
                 "--out", str(b)]) == 0
    sa = json.loads((tmp_path / "sky.parquet.json").read_text())
    sb = json.loads((tmp_path / "sky.csv.json").read_text())
    assert sa["sun"]["elevation_deg"] == 30 and sb["sun"]["elevation_deg"] == 50
    assert not (tmp_path / "sky.json").exists()


def test_reader_accepts_the_older_sidecar_spelling(table):
    from sensor.measurement import read_measurement
    new = table.with_name(table.name + ".json")
    new.rename(table.with_suffix(".json"))          # m.csv.json -> m.json
    assert len(read_measurement(table).table) == 40


@pytest.mark.parametrize("kind", ["list", "folder", "not_json", "no_site", "daq_bits"])
def test_bad_sidecars_are_named(kind, table, capsys):
    side = table.with_name(table.name + ".json")
    side.unlink()
    if kind == "folder":
        side.mkdir()
    elif kind == "list":
        side.write_text("[1, 2]")
    elif kind == "not_json":
        side.write_text("{nope")
    elif kind == "no_site":
        side.write_text(json.dumps({"schema": "skysim.measurement/1", "site": {"lat": 3}}))
    else:
        side.write_text(json.dumps({"schema": "skysim.measurement/1",
                                    "site": {"latitude_deg": 34.1, "longitude_deg": 108.5},
                                    "sensor": {"daq": {"bits": "sixteen", "range_V": 10}}}))
    needle = {"list": "must be a JSON object", "folder": "is a folder",
              "not_json": "not valid JSON", "no_site": "latitude_deg",
              "daq_bits": "sensor.daq: DAQ bits must be a whole number"}[kind]
    res = _run_cli(["calibrate", str(table)], capsys)
    assert res.code == 2 and res.clean and res.names(needle), res.err


@pytest.mark.parametrize("time,needle", [
    ("3013-05-22T17:10:00+08:00", "in row 5 is outside the supported years 1678-2261"),
    ("2013-05-32T17:10:00+08:00", "in row 5 is not an ISO 8601 time"),
    ("yesterday+08:00", "in row 5 is not an ISO 8601 time"),
])
def test_bad_times_in_a_table_name_row_and_value(time, needle, table, capsys):
    t = pd.read_csv(table)
    t.loc[5, "time"] = time
    t.to_csv(table, index=False)
    res = _run_cli(["calibrate", str(table)], capsys)
    assert res.code == 2 and res.clean and res.names(needle, repr(time)), res.err
    assert "You might want" not in res.line   # no advice relayed from pandas


def test_dead_channel_is_named(table, capsys):
    t = pd.read_csv(table)
    t["U2_V"] = 0.25
    t.to_csv(table, index=False)
    res = _run_cli(["calibrate", str(table)], capsys)
    assert res.code == 2 and res.clean and res.names("U2_V (constant 0.25 V)"), res.err


# --------------------------------------------------------------------------- configurations

GOOD_MAP = '[[sky_map]]\nname = "a"\nsun_elevation_deg = 30.0\nsun_azimuth_deg = 0.0\n' \
           'grid_step_deg = 30.0\n'


@pytest.mark.parametrize("entry,needle", [
    ('[[sky_map]]\nname = "b"\nsun_elevation_deg = 30.0\nsun_azimuth_deg = 0.0\ngrid_stp = 5\n',
     "unknown key(s) ['grid_stp']"),
    ('[[sky_map]]\nname = "b"\nsun_elevation_deg = 30.0\nsun_azimuth_deg = 0.0\n'
     'grid_step_deg = "fine"\n', "grid_step_deg must be a number"),
    ('[[sky_map]]\nname = "b"\nsun_elevation_deg = 30.0\nsun_azimuth_deg = 0.0\n'
     'sky = {model = "rayleigh", dmax = 1.5}\n', "'b': dmax must lie in (0.0, 1.0); got 1.5"),
    ('[site]\nlatitude_deg = 34.0\nlongitude_deg = 108.0\n[[measurement]]\nname = "b"\n'
     'start = "2013-05-22T17:10:00+08:00"\nn = 20\ndaq_bits = "sixteen"\n', "'sixteen'"),
    ('[site]\nlatitude_deg = 34.0\nlongitude_deg = 108.0\n[[measurement]]\nname = "b"\n'
     'start = "2013-05-22T17:10:00+08:00"\nn = 0\n', "n must be an integer >= 1"),
    ('[site]\nlatitude_deg = 34.0\nlongitude_deg = 108.0\n[[measurement]]\nname = "b"\n'
     'start = "2013-05-22T17:10:00+08:00"\nn = 20\nduration_s = -600.0\n', "duration_s"),
])
def test_failed_generate_leaves_earlier_output_and_no_data_without_manifest(
        entry, needle, tmp_path, capsys):
    out = tmp_path / "truth"
    good = tmp_path / "good.toml"
    good.write_text("seed = 1\n" + GOOD_MAP)
    assert main(["generate", str(good), "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    bad = tmp_path / "bad.toml"   # the good entry first: it is written before the bad one fails
    bad.write_text("seed = 2\n" + entry.replace("[[", GOOD_MAP + "[[", 1)
                   if entry.startswith("[[") else "seed = 2\n" + entry + GOOD_MAP)
    capsys.readouterr()
    res = _run_cli(["generate", str(bad), "--out", str(out)], capsys)
    assert res.code == 2 and res.clean and res.names(needle), res.err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_compare_tolerances(tmp_path, capsys):
    cfg = tmp_path / "g.toml"
    cfg.write_text("seed = 1\n" + GOOD_MAP)
    assert main(["generate", str(cfg), "--out", str(tmp_path / "t")]) == 0
    t = str(tmp_path / "t")
    res = _run_cli(["compare", t, t, "--tol", "aop_deg=-1"], capsys)
    assert res.code == 2 and res.clean and res.names("'aop_deg=-1'", ">= 0"), res.err
    res = _run_cli(["compare", t, t, "--tol", "aop_deg=tiny"], capsys)
    assert res.code == 2 and res.clean and res.names("'aop_deg=tiny'"), res.err
    assert main(["compare", t, t, "--tol", "aop_deg=0"]) == 0   # identical data, zero tolerance


def test_daq_bits_must_be_a_whole_number():
    from sensor.daq import Daq
    from skysim.exceptions import InvalidParameterError
    for bits in ("sixteen", 16.5, 0, 40, True):
        with pytest.raises(InvalidParameterError, match="DAQ bits"):
            Daq(bits)
    with pytest.raises(InvalidParameterError, match="range_V"):
        Daq(16, -1.0)


def test_failed_sweep_leaves_no_state_and_the_corrected_rerun_runs(tmp_path, capsys):
    cfg = tmp_path / "w.toml"
    base = ('[sweep]\nname = "w"\ntrials = 64\nstops = 16\n[parameters]\n'
            'noise_V = {uniform = [0.0001, 0.002]}\n')
    cfg.write_text(base + '[sky]\nmodel = "rayleigh"\ndmax = 1.5\n')
    out = tmp_path / "out"
    res = _run_cli(["sweep", str(cfg), "--out", str(out), "--no-figures", "--no-progress"], capsys)
    assert res.code == 2 and res.clean and res.names("[sky]", "1.5"), res.err
    assert not out.exists()
    # a folder left by an older version in the same state (sweep.json, empty chunks/)
    (out / "chunks").mkdir(parents=True)
    (out / "sweep.json").write_text(json.dumps({"digest": "0" * 64, "status": "running"}))
    cfg.write_text(base + '[sky]\nmodel = "rayleigh"\ndmax = 0.7\n')
    assert main(["sweep", str(cfg), "--out", str(out), "--no-figures", "--no-progress"]) == 0
    assert json.loads((out / "sweep.json").read_text())["status"] == "complete"


# --------------------------------------------------------------------------- resources

def test_memory_is_estimated_before_allocating(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = _run_cli(["sky", *SUN, "--grid-step", "0.01"], capsys)
    assert (res.code == 2 and res.clean
            and res.names("324036000 sky directions", "--grid-step")), res.err
    res = _run_cli(["reproduce", "yang2014", "--trials", "1e9"], capsys)
    assert res.code == 2 and res.clean and res.names("1000000000 trials", "--trials"), res.err
    monkeypatch.setenv("SKYSIM_MEMORY_LIMIT_MB", "1")
    res = _run_cli(["sample", "--out", "s.csv", "--n", "10000"], capsys)
    assert (res.code == 2 and res.clean
            and res.names("10000 samples", "SKYSIM_MEMORY_LIMIT_MB")), res.err
    big = tmp_path / "big.toml"
    big.write_text('seed = 1\n[[sky_map]]\nname = "a"\nsun_elevation_deg = 30.0\n'
                   'sun_azimuth_deg = 0.0\ngrid_step_deg = 0.001\n')
    res = _run_cli(["generate", str(big), "--out", "g"], capsys)
    assert res.code == 2 and res.clean and res.names("'a': 32400360000 sky directions"), res.err
    big.unlink()
    monkeypatch.setenv("SKYSIM_MEMORY_LIMIT_MB", "lots")
    res = _run_cli(["sample", "--out", "s.csv"], capsys)
    assert res.code == 2 and res.clean and res.names("'lots'"), res.err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("target", ["yang2014", "dark-current", "compound-eye", "jin2020"])
def test_reproductions_refuse_trials_that_do_not_fit(target, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SKYSIM_MEMORY_LIMIT_MB", "100")
    res = _run_cli(["reproduce", target, "--trials", "100000", "--out", str(tmp_path / "o")],
                   capsys)
    assert (res.code == 2 and res.clean
            and res.names(f"100000 trials of {target}", "--trials")), res.err
    assert not (tmp_path / "o").exists()


def test_huge_sweep_is_refused_at_once_and_planned_lazily(tmp_path, capsys):
    from dataclasses import replace

    from experiments.workflows.sweep import plan_chunks
    from experiments.workflows.sweep_config import load_config
    cfg = tmp_path / "w.toml"
    cfg.write_text('[sweep]\nname = "w"\ntrials = 1000000000000\n[parameters]\n'
                   'noise_V = {uniform = [0.0001, 0.002]}\n')
    res = _run_cli(["sweep", str(cfg), "--out", str(tmp_path / "o")], capsys)
    assert res.code == 2 and res.clean and res.names("1000000000000 trials"), res.err
    assert not (tmp_path / "o").exists()
    c = replace(load_config(cfg), chunk_trials=64)
    plan = plan_chunks(c, tmp_path, "d", c.trials)          # constant time and memory
    assert len(plan) == 10**12 // 64 and plan[-1].stop == 10**12
    assert [t.start for t in plan[2:4]] == [128, 192]


def test_sweep_chunks_must_fit_beside_each_other(tmp_path, capsys, monkeypatch):
    cfg = tmp_path / "w.toml"
    cfg.write_text('[sweep]\nname = "w"\ntrials = 100000\n[execution]\nmemory_mb = 1e9\n'
                   '[parameters]\nnoise_V = {uniform = [0.0001, 0.002]}\n')
    monkeypatch.setenv("SKYSIM_MEMORY_LIMIT_MB", "1000")
    res = _run_cli(["sweep", str(cfg), "--out", str(tmp_path / "o"), "--workers", "2"], capsys)
    assert (res.code == 2 and res.clean
            and res.names("2 chunk(s) of 100000 trials x 182 stops", "memory_mb")), res.err
    assert not (tmp_path / "o").exists()


def test_expected_trials_match_the_designs():
    from dataclasses import replace

    from experiments.workflows.sweep import design, expected_trials
    from experiments.workflows.sweep_config import load_config
    for name in ("sobol", "morris", "montecarlo"):
        c = load_config(EXAMPLES / f"sweep_{name}.toml")
        if name != "montecarlo":
            c = replace(c, base_samples=4)
        assert expected_trials(c) == design(c)[0], name


# --------------------------------------------------------------------------- interrupts, pipes

def test_ctrl_c_prints_one_line(monkeypatch, capsys):
    import experiments.cli.commands as commands

    def interrupted(args):
        raise KeyboardInterrupt
    monkeypatch.setattr(commands, "_sky", interrupted)
    assert main(["sky", *SUN]) == EXIT_INTERRUPTED
    err = capsys.readouterr().err
    assert "interrupted" in err and "Traceback" not in err


def test_a_bug_is_one_line_unless_the_traceback_is_asked_for(monkeypatch, capsys):
    import experiments.cli.commands as commands

    def buggy(args):
        raise TypeError("unsupported operand")
    monkeypatch.setattr(commands, "_sky", buggy)
    assert main(["sky", *SUN]) == EXIT_INTERNAL
    err = capsys.readouterr().err
    assert "internal error: TypeError: unsupported operand" in err and "Traceback" not in err
    monkeypatch.setenv("SKYSIM_TRACEBACK", "1")
    with pytest.raises(TypeError):
        main(["sky", *SUN])


def test_closed_pipe_ends_quietly(monkeypatch, capsys):
    class ClosedPipe(io.StringIO):
        def write(self, s):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            raise BrokenPipeError(32, "Broken pipe")
    monkeypatch.setattr(sys, "stdout", ClosedPipe())
    assert main(["sky", *SUN, "--grid-step", "30"]) == EXIT_BROKEN_PIPE
    assert capsys.readouterr().err == ""


def test_missing_extra_gives_the_install_command_for_this_checkout(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "sasktran2", None)   # `import sasktran2` fails
    res = _run_cli(["sky", "--model", "multiple", "--tau", "0.1", *SUN], capsys)
    assert (res.code == 2 and res.clean
            and res.names("'sasktran2'", "extra 'rt'", "pip install -e")), res.err
    root = Path(__file__).resolve().parents[1]
    assert f"'{root}[rt]'" in res.line and "install 'skysim" not in res.line


# --------------------------------------------------------------------------- sample

def test_sample_writes_several_sweeps(tmp_path):
    from sensor.measurement import read_measurement
    out = tmp_path / "s.csv"
    assert main(["sample", "--out", str(out), "--n", "30", "--sweeps", "3", "--duration", "300",
                 "--sweep-interval", "900", "--errors", "none", "--no-daq"]) == 0
    m = read_measurement(out).table
    assert sorted(m.sweep.unique()) == [0, 1, 2] and len(m) == 90
    starts = m.groupby("sweep").time.min().diff().dt.total_seconds().dropna()
    np.testing.assert_allclose(starts, 900.0, atol=1e-3)
    # each sweep starts with the reference axis 90 deg counter-clockwise of its own sun
    first = m.groupby("sweep").head(1)
    np.testing.assert_allclose(first.true_phi_deg.abs(), 90.0, atol=1e-6)


def _slow_marker(path):
    import time
    time.sleep(0.5)
    Path(path).write_text("done")
    return path


def test_ctrl_c_stops_the_workers_instead_of_draining_the_queue(tmp_path):
    """After Ctrl-C the pool's queued chunks must not run on: the workers are stopped."""
    import signal
    import threading

    from experiments.workflows.sweep_backends import run_tasks
    tasks = [str(tmp_path / f"t{k}") for k in range(24)]
    started = threading.Event()

    def interrupt():
        started.wait(10)
        while not any(Path(t).exists() for t in tasks):   # the pool is running
            threading.Event().wait(0.05)
        os.kill(os.getpid(), signal.SIGINT)
    # Ctrl-C as the interpreter handles it (other tests' libraries may install handlers)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    threading.Thread(target=interrupt, daemon=True).start()
    started.set()
    try:
        with pytest.raises(KeyboardInterrupt):
            run_tasks(_slow_marker, tasks, workers=2, progress=False)
    finally:
        signal.signal(signal.SIGINT, previous)
    import concurrent.futures.process as cfp   # what the interpreter joins at exit
    for t in list(cfp._threads_wakeups):
        t.join(timeout=30)
    done = sum(Path(t).exists() for t in tasks)
    assert 1 <= done <= 8, done        # 24 would mean the queue was drained


# --------------------------------------------------------------------------- sky-series

SERIES = ["sky-series", "--lat", "34.1", "--lon", "108.5", "--start",
          "2013-05-22T10:00+08:00", "--grid-step", "30"]


@pytest.mark.parametrize("extra,needles", [
    (["--periods", "0"], ["--periods", "'0'"]),
    (["--periods", "-3"], ["--periods", "'-3'"]),
    (["--periods", "2.5"], ["--periods", "'2.5'"]),
    (["--periods", "5", "--freq", "0s"], ["--freq", "positive", "'0s'"]),
    (["--periods", "5", "--freq=-1min"], ["--freq", "positive", "'-1min'"]),
    (["--periods", "5", "--freq", "fortnightly"], ["--freq", "'fortnightly'"]),
    (["--end", "2013-05-22T09:00+08:00"], ["--end 2013-05-22T09:00:00+08:00",
                                            "before --start"]),
    (["--end", "2013-05-22T11:00"], ["--end", "no UTC offset"]),
    (["--periods", "3", "--end", "2013-05-22T11:00+08:00"], ["--end or --periods"]),
    ([], ["--end or --periods"]),
    (["--periods", "1e9"], ["--periods 1000000000", "1678-2261"]),
    (["--periods", "3", "--model", "multiple"], ["--model multiple needs --tau"]),
    (["--periods", "3", "--tau", "0.1"], ["--tau", "--model multiple"]),
    (["--periods", "3", "--model", "berry", "--float32"], ["--float32", "--model berry"]),
    (["--periods", "3", "--max-memory-mb", "0"], ["--max-memory-mb", "'0'"]),
    (["--periods", "3", "--dmax", "1.5"], ["--dmax", "'1.5'"]),
    (["--periods", "3", "--lat", "nan"], ["--lat", "'nan'"]),
])
def test_sky_series_options(extra, needles, capsys, tmp_path):
    out = tmp_path / "s.nc"
    res = _run_cli([*SERIES, *extra, "--out", str(out)], capsys)
    assert res.code == 2 and res.clean and res.names(*needles), res.err
    assert list(tmp_path.iterdir()) == []


def test_sky_series_refuses_what_does_not_fit_before_any_work(capsys, tmp_path, monkeypatch):
    out = tmp_path / "s.parquet"
    # 1e8 steps of 1 s fit the years; their times alone would need ~20 GB
    monkeypatch.setenv("SKYSIM_MEMORY_LIMIT_MB", "1000")
    res = _run_cli([*SERIES, "--periods", "1e8", "--freq", "1s", "--out", str(out)], capsys)
    assert (res.code == 2 and res.clean
            and res.names("100000000 time steps x 48 directions", "--periods")), res.err
    monkeypatch.delenv("SKYSIM_MEMORY_LIMIT_MB")
    import shutil
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage._replace(free=10_000))
    res = _run_cli([*SERIES, "--periods", "100", "--out", str(out)], capsys)
    assert (res.code == 2 and res.clean
            and res.names(str(out), "100 time steps x 48 directions",
                          "only 10 kB is free")), res.err
    # the library's writer checks too
    from experiments.workflows.sky_series import write_sky_series
    from skysim.io import WriteError
    from skysim.sky import make_sky
    with pytest.raises(WriteError, match="1000 time steps x 2 directions would take about 80 kB"):
        write_sky_series(tmp_path / "s.nc", make_sky("rayleigh"), [10, 20], [0, 0],
                         np.full(1000, 30.0), np.zeros(1000))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".nc", ".parquet"])
def test_sky_series_failed_write_names_the_file_and_leaves_nothing(suffix, capsys, tmp_path,
                                                                    monkeypatch):
    """A disk that fills up part-way: one error line naming the file, no partial file, and an
    earlier series of the same name kept."""
    pytest.importorskip("h5netcdf")
    import errno

    import experiments.workflows.sky_series as ss
    out = tmp_path / f"s{suffix}"
    assert main([*SERIES, "--periods", "3", "--out", str(out)]) == 0
    before = out.read_bytes()
    writer = "_write_netcdf" if suffix == ".nc" else "_write_parquet"
    real = getattr(ss, writer)

    def full_disk(tmp, blocks, *rest):
        real(tmp, iter(list(blocks)[:1]), *rest)       # part of the series reaches the disk
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(ss, writer, full_disk)
    capsys.readouterr()
    res = _run_cli([*SERIES, "--periods", "5", "--freq", "10min", "--out", str(out)], capsys)
    assert (res.code == 2 and res.clean
            and res.names(f"writing {out} failed (No space left on device)")), res.err
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [out.name] + ([out.name + ".json"] if suffix == ".parquet" else []))


def test_sky_series_multiple_takes_tau_and_albedo(tmp_path):
    pytest.importorskip("sasktran2")
    out = tmp_path / "s.parquet"
    assert main([*SERIES, "--grid-step", "45", "--periods", "1", "--model", "multiple",
                 "--tau", "0.1", "--albedo", "0.2", "--out", str(out)]) == 0
    side = json.loads((tmp_path / "s.parquet.json").read_text())
    assert side["sky"]["tau"] == 0.1 and side["sky"]["albedo"] == 0.2


def test_dmax_one_is_accepted_as_its_help_says(tmp_path):
    """d_max lies in (0, 1]: 1 (an ideal Rayleigh atmosphere) is the model default."""
    out = tmp_path / "sky.csv"
    assert main(["sky", *SUN, "--dmax", "1", "--grid-step", "30", "--out", str(out)]) == 0
    assert pd.read_csv(out).dop.max() == pytest.approx(1.0, abs=0.02)
    assert main([*SERIES, "--periods", "2", "--dmax", "1", "--out",
                 str(tmp_path / "s.parquet")]) == 0


# --------------------------------------------------------------------------- TOML datetimes

def test_an_unquoted_toml_datetime_is_the_same_time_as_a_quoted_one(tmp_path, capsys):
    text = ('seed = 1\n[site]\nlatitude_deg = 34.0\nlongitude_deg = 108.0\n[[sky_map]]\n'
            'name = "a"\ntime = {t}\ngrid_step_deg = 30.0\n[[measurement]]\nname = "b"\n'
            'start = {t}\nn = 20\n')
    for name, t in (("bare", "2013-05-22T17:10:00+08:00"), ("quoted", '"2013-05-22T17:10:00+08:00"')):
        (tmp_path / f"{name}.toml").write_text(text.format(t=t))
        assert main(["generate", str(tmp_path / f"{name}.toml"), "--out",
                     str(tmp_path / name)]) == 0
    for f in ("a.csv", "b.csv", "manifest.json"):
        assert (tmp_path / "bare" / f).read_bytes() == (tmp_path / "quoted" / f).read_bytes()
    (tmp_path / "naive.toml").write_text(text.format(t="2013-05-22T17:10:00"))
    res = _run_cli(["generate", str(tmp_path / "naive.toml"), "--out", str(tmp_path / "n")], capsys)
    assert (res.code == 2 and res.clean
            and res.names("'2013-05-22T17:10:00'", "timezone-naive")), res.err
    assert not (tmp_path / "n").exists()


# --------------------------------------------------------------------------- outputs vs inputs

@pytest.mark.parametrize("case", ["sky_directions", "calibrate_sidecar", "compare_manifest",
                                  "compare_sidecar", "generate_config", "series_sidecar",
                                  "sample_sidecar"])
def test_an_output_never_replaces_an_input(case, inputs, tmp_path, capsys):
    data, cfg = Path(inputs["data"]), Path(inputs["cfg"])
    dirs = tmp_path / "in" / "d.csv"
    dirs.write_text("elevation_deg,azimuth_deg\n10,20\n")
    sdirs = tmp_path / "in" / "d.parquet.json"   # named like the sidecar of d.parquet
    sdirs.write_text(dirs.read_text())
    truth = tmp_path / "truth"
    assert main(["generate", str(cfg), "--out", str(truth)]) == 0
    errors = tmp_path / "in" / "x.csv.json"      # named like the sidecar of x.csv
    errors.write_text('{"misalignment_deg": [0, 0, 0, 0, 0, 0], "transmittance": [0, 0, 0], '
                      '"noise_V": [0, 0, 0]}')
    cfg_in_out = truth / "m.csv"      # the data file its own entry "m" writes
    argv, victim = {
        "sky_directions": (["sky", *SUN, "--directions", str(dirs), "--out", str(dirs)], dirs),
        "calibrate_sidecar": (["calibrate", str(data), "--out", f"{data}.json"],
                              Path(f"{data}.json")),
        "compare_manifest": (["compare", str(truth), str(truth), "--report",
                              str(truth / "manifest.json")], truth / "manifest.json"),
        "compare_sidecar": (["compare", str(truth / "m.csv"), str(truth / "m.csv"), "--report",
                             str(truth / "m.csv.json")], truth / "m.csv.json"),
        "generate_config": (["generate", str(cfg_in_out), "--out", str(truth)], cfg_in_out),
        "series_sidecar": ([*SERIES, "--periods", "2", "--directions", str(sdirs), "--out",
                            str(sdirs.with_name("d.parquet"))], sdirs),
        "sample_sidecar": (["sample", "--errors", str(errors), "--out",
                            str(errors.with_name("x.csv"))], errors),
    }[case]
    if case == "generate_config":
        cfg_in_out.write_text(cfg.read_text())
    before = victim.read_bytes()
    capsys.readouterr()
    res = _run_cli(argv, capsys)
    assert (res.code == 2 and res.clean
            and res.names("would replace the input", str(victim))), res.err
    assert res.line.count(str(victim)) == 2
    assert victim.read_bytes() == before


# --------------------------------------------------------------------------- reproduction folders

def _interrupting_target(monkeypatch, module: str):
    """Make ``module``'s reproduction write one file, then be interrupted (Ctrl-C)."""
    import importlib
    mod = importlib.import_module(f"experiments.studies.{module}")
    real = mod._reproduce

    def interrupted(args):
        (Path(args.out) / "table1.csv").write_text("seed,partial\n")
        raise KeyboardInterrupt
    monkeypatch.setattr(mod, "_reproduce", interrupted)
    return real


def test_reproduction_folder_is_replaced_whole(tmp_path, capsys, monkeypatch):
    out = tmp_path / "r"
    assert main(["reproduce", "compound-eye", "--trials", "3", "--out", str(out)]) == 0
    full = {p.name: p.read_bytes() for p in out.iterdir()}
    assert json.loads(full["run.json"]) == {"target": "compound-eye", "quick": False,
                                            "trials": 3, "seed": 20140601}
    # a quick run would replace the full one: refused, then allowed with --force
    res = _run_cli(["reproduce", "compound-eye", "--quick", "--out", str(out)], capsys)
    assert (res.code == 2 and res.clean
            and res.names(f"--out {out} holds a full run of compound-eye", "--force")), res.err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == full
    # another target, or a folder of other files: refused
    res = _run_cli(["reproduce", "yang2014", "--quick", "--out", str(out)], capsys)
    assert res.code == 2 and res.clean and res.names("not a run of yang2014"), res.err
    other = tmp_path / "notes"
    other.mkdir()
    (other / "mine.txt").write_text("keep")
    res = _run_cli(["reproduce", "yang2014", "--quick", "--out", str(other)], capsys)
    assert res.code == 2 and res.clean and res.names(f"--out {other} already holds files"), res.err
    assert (other / "mine.txt").read_text() == "keep"
    # an interrupted run leaves the earlier run as it was, with nothing of its own
    _interrupting_target(monkeypatch, "compound_eye")
    assert main(["reproduce", "compound-eye", "--trials", "2", "--seed", "5", "--out",
                 str(out)]) == EXIT_INTERRUPTED
    assert {p.name: p.read_bytes() for p in out.iterdir()} == full
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes", "r"]   # nothing left aside
    monkeypatch.undo()
    # --force: the quick run replaces the folder; no file of the full run stays beside it
    assert main(["reproduce", "compound-eye", "--quick", "--force", "--out", str(out)]) == 0
    assert json.loads((out / "run.json").read_text())["quick"] is True
    quick_names = {p.name for p in out.iterdir()}
    assert quick_names <= set(full) and all(
        (out / n).stat().st_mtime_ns >= (out / "run.json").stat().st_mtime_ns - 10**11
        for n in quick_names)


def test_reproduction_options_that_do_not_apply(tmp_path, capsys):
    res = _run_cli(["reproduce", "yang2014", "--data", str(tmp_path),
                    "--out", str(tmp_path / "o")], capsys)
    assert (res.code == 2 and res.clean
            and res.names("--data applies to moonlit-sky, real-sky-compass, not yang2014")), res.err
    res = _run_cli(["gap-benchmark", "--real", str(tmp_path / "none"),
                    "--out", str(tmp_path / "o")], capsys)
    assert res.code == 2 and res.clean and res.names("give --real DIR"), res.err
    assert not (tmp_path / "o").exists()


def test_gap_benchmark_size_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SKYSIM_MEMORY_LIMIT_MB", "100")
    res = _run_cli(["gap-benchmark", "--n", "1e6", "--out", str(tmp_path / "o")], capsys)
    assert (res.code == 2 and res.clean
            and res.names("1000000 data sets of gap-benchmark", "--n")), res.err
    assert not (tmp_path / "o").exists()


def test_long_runs_state_their_expected_duration(capsys):
    from experiments.workflows.progress import announce_duration, expected_reproduction_seconds
    assert expected_reproduction_seconds("sky-gap", False, None) == 840.0
    assert expected_reproduction_seconds("yang2014", False, 2000) == 10 * \
        expected_reproduction_seconds("yang2014", False, None)
    announce_duration(5.0, "a run of five seconds")      # below 10 s: silent
    announce_duration(840.0, "skysim reproduce sky-gap", "--quick is shorter")
    err = capsys.readouterr().err
    assert err == "skysim reproduce sky-gap: expected duration about 14 min; --quick is " \
                  "shorter\n"


def test_runs_over_the_time_budget_are_refused_unless_forced(capsys, monkeypatch):
    import experiments.workflows.progress as progress
    assert progress.TIME_BUDGET_S == 24 * 3600.0
    progress.check_duration(2 * progress.TIME_BUDGET_S, "a forced run", force=True)
    assert capsys.readouterr().err == "a forced run: expected duration about 2 days\n"
    monkeypatch.setattr(progress, "TIME_BUDGET_S", 3600.0)
    with pytest.raises(ValueError, match=r"a run: expected duration about 2\.0 h, more than "
                                         r"the 1 h one run may take.*\(--force runs it"):
        progress.check_duration(7200.0, "a run", force_flag="--force")


def test_sky_states_its_duration_from_its_directions(tmp_path, capsys, monkeypatch):
    """The estimate (per direction, from the model and the output's format) is printed
    before the work, from the number of rows of --directions."""
    import experiments.workflows.sky_options as sky_options
    monkeypatch.setitem(sky_options.SKY_SECONDS_PER_DIRECTION, "rayleigh", 1.0)
    d = tmp_path / "d.csv"
    d.write_text("elevation_deg,azimuth_deg\n" + "".join(f"{k},{k}\n" for k in range(30)))
    assert main(["sky", *SUN, "--directions", str(d)]) == 0
    assert "skysim sky: 30 directions: expected duration about 30 s" in capsys.readouterr().err


def test_warnings_are_one_readable_line():
    """A library's warning during a command: one line on stderr, no source line (run in a
    fresh interpreter: pytest records warnings itself)."""
    import subprocess
    code = ("import warnings, experiments.cli.commands as c\n"
            "def warns(args):\n"
            "    warnings.warn('invalid value encountered in\\n    arccos', RuntimeWarning)\n"
            "    return 0\n"
            "c._sky = warns\n"
            "from experiments.cli.main import main\n"
            "raise SystemExit(main(['sky', '--sun-elevation', '30', '--sun-azimuth', '10']))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stderr == "skysim: warning: invalid value encountered in arccos " \
                         "(RuntimeWarning)\n"


# --------------------------------------------------------------------------- help of every option

def _all_options():
    import argparse
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, p in sorted(sub.choices.items()):
        for action in p._actions:
            if not isinstance(action, argparse._HelpAction):
                yield name, p, action


@pytest.mark.parametrize("name,parser,action", list(_all_options()),
                         ids=lambda x: x if isinstance(x, str) else getattr(x, "dest", ""))
def test_every_option_has_help_and_no_empty_default(name, parser, action):
    assert action.help and len(action.help) > 10, (name, action.option_strings or action.dest)
    fmt = parser._get_formatter()
    text = fmt._expand_help(action) if action.help else ""
    assert "default: None" not in text, (name, action.dest, text)
    if action.required or not action.option_strings:
        assert "(default:" not in text, (name, action.dest, text)
    if action.choices and not isinstance(action.choices, dict):
        usage = parser.format_help()
        assert all(str(c) in usage for c in action.choices), (name, action.dest)


def test_durations_read_at_a_glance():
    from experiments.workflows.progress import format_duration
    assert [format_duration(s) for s in (45, 840, 9000, 5.3e5)] == [
        "45 s", "14 min", "2.5 h", "6 days"]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs POSIX signals")
def test_sigterm_cleans_up_like_ctrl_c(tmp_path):
    """``kill`` (or a scheduler's time limit) mid-run: the earlier output folder is put back."""
    import signal
    import subprocess
    import time
    out = tmp_path / "r"
    assert main(["reproduce", "compound-eye", "--trials", "2", "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    proc = subprocess.Popen([sys.executable, "-m", "experiments.cli.main", "reproduce", "camera",
                             "--trials", "1000", "--out", str(out), "--force"],
                            stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while not any(p.name.startswith(".r.earlier-") for p in tmp_path.iterdir()):
        assert time.time() < deadline and proc.poll() is None, proc.stderr.read()
        time.sleep(0.2)
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 143
    assert "terminated" in proc.stderr.read()
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert [p.name for p in tmp_path.iterdir()] == ["r"]


# --------------------------------------------------------------------------- fuzz batteries

_FUZZ_BASE = {
    "sky": ["sky", *SUN, "--grid-step", "30"],
    "sky-series": [*SERIES, "--periods", "2", "--out", "s.parquet"],
    "sample": ["sample", "--out", "s.csv", "--n", "20"],
}
_FUZZ_OPTIONS = {
    "sky": ["--alt", "--sun-elevation", "--sun-azimuth", "--grid-step", "--dmax", "--tau",
            "--albedo", "--wavelength-nm", "--pressure-hPa", "--delta-deg"],
    "sky-series": ["--lat", "--lon", "--alt", "--periods", "--grid-step", "--dmax",
                   "--max-memory-mb"],
    "sample": ["--lat", "--lon", "--alt", "--duration", "--n", "--sweeps", "--sweep-interval",
               "--dmax", "--seed"],
}
_FUZZ_VALUES = ["0", "-1", "1e30", "1e-300", "nan", "-inf", "1e400", "x"]


@pytest.mark.parametrize("command,option", [(c, o) for c, os_ in _FUZZ_OPTIONS.items()
                                            for o in os_])
def test_numeric_options_fuzzed(command, option, tmp_path, capsys, monkeypatch):
    """Zero, negative, huge, tiny, not-a-number and non-numeric values of every numeric
    option: a result (exit 0) or one specific error line (exit 2); never a bug, a traceback
    or a leftover file. Values that are not finite numbers are refused when parsed, naming
    the option."""
    monkeypatch.chdir(tmp_path)
    for value in _FUZZ_VALUES:
        rc = main(_FUZZ_BASE[command] + [f"{option}={value}"])   # "-inf" is not an option
        err = capsys.readouterr().err.strip().splitlines()
        assert rc in (0, 2), (option, value, err[-1:])
        if value in ("nan", "-inf", "1e400", "x"):
            assert rc == 2 and f"argument {option}" in err[-1] and repr(value) in err[-1]
        if rc == 2:
            assert err[-1].startswith(f"skysim {command}: error: "), (option, value, err)
            assert "internal error" not in err[-1] and "\n" not in err[-1]
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(".tmp-")]
        for p in tmp_path.iterdir():
            p.unlink()


@pytest.fixture(scope="module")
def fuzz_inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    assert main(["sample", "--out", str(root / "good.csv"), "--n", "40", "--sweeps", "3"]) == 0
    cfg = root / "g.toml"
    cfg.write_text('seed = 1\n[[sky_map]]\nname = "m"\nsun_elevation_deg = 30.0\n'
                   'sun_azimuth_deg = 0.0\ngrid_step_deg = 30.0\n')
    assert main(["generate", str(cfg), "--out", str(root / "truth")]) == 0
    return root


_BAD_CONTENT = {
    "empty": b"",
    "binary": bytes(range(256)) * 4,
    "prose": b"hello world\n",
    "semicolons": b"a;b;c\n1;2;3\n",
    "json_list": b"[1, 2]",
    "broken_toml": b"seed = = 1\n[[",
    "header_only": b"time,heading_deg,U1_V,U2_V,U3_V\n",
}


def _file_commands(f: str, root: Path) -> dict:
    truth = str(root / "truth" / "m.csv")
    return {
        "sky --directions": ["sky", *SUN, "--directions", f],
        "sky-series --directions": [*SERIES, "--periods", "2", "--directions", f, "--out",
                                    str(root / "o.parquet")],
        "calibrate": ["calibrate", f],
        "diagnose": ["diagnose", f, "--out", str(root / "dg")],
        "compare theirs": ["compare", f, truth],
        "compare truth": ["compare", truth, f],
        "generate": ["generate", f, "--out", str(root / "gg")],
        "sweep": ["sweep", f, "--out", str(root / "sw"), "--no-progress", "--no-figures"],
        "sample --errors": ["sample", "--errors", f, "--out", str(root / "se.csv")],
    }


@pytest.mark.parametrize("kind", [*_BAD_CONTENT, "folder", "missing"])
@pytest.mark.parametrize("suffix", [".csv", ".toml", ".json"])
def test_malformed_input_files(kind, suffix, fuzz_inputs, capsys):
    """Every file-reading command given an empty, binary, wrongly formatted, header-only,
    missing file or a folder (a data file with a valid sidecar beside it, so that the table
    itself is what is wrong): exit 2, one line naming the file, nothing written."""
    root = fuzz_inputs
    f = root / f"in_{kind}{suffix}"
    if kind == "folder":
        f.mkdir(exist_ok=True)
    elif kind != "missing":
        f.write_bytes(_BAD_CONTENT[kind])
        if suffix == ".csv":
            (root / f"in_{kind}.csv.json").write_bytes((root / "good.csv.json").read_bytes())
    before = sorted(p.name for p in root.iterdir())
    for name, argv in _file_commands(str(f), root).items():
        capsys.readouterr()
        rc = main(argv)
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2, (name, rc, err[-1:])
        assert err[-1].startswith("skysim ") and "internal error" not in err[-1], (name, err)
        assert f.name in err[-1], (name, err[-1])
        assert sorted(p.name for p in root.iterdir()) == before, name
