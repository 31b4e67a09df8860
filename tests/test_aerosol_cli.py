"""``skysim sky --model aerosol``: options, help, errors, a small map with its sidecar."""

import json
import sys

import numpy as np
import pandas as pd
import pytest

from experiments.cli import commands
from experiments.cli.main import main

SUN = ["--sun-elevation", "30", "--sun-azimuth", "180"]


def test_preset_choices_match_the_presets():
    from skysim.aerosol_types import PRESETS
    assert sorted(commands._AEROSOL_PRESETS) == sorted(PRESETS)


def test_help_states_units(capsys):
    assert main(["sky", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "aerosol optical depth at 550 nm [1]" in out
    assert "aerosol: wavelength [nm]" in out and "surface pressure [hPa]" in out


def test_aerosol_option_with_another_model_is_an_error(capsys):
    assert main(["sky", "--model", "multiple", "--tau", "0.1", "--aod", "0.2", *SUN]) == 2
    err = capsys.readouterr().err
    assert "--aod is an option of --model aerosol" in err and "--tau" in err


def test_missing_engine_gives_the_install_command(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "sasktran2", None)   # `import sasktran2` fails
    assert main(["sky", "--model", "aerosol", "--aod", "0.2", *SUN]) == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "'sasktran2'" in last and "extra 'rt'" in last and "pip install -e" in last


def test_aerosol_map_with_sidecar(tmp_path):
    pytest.importorskip("sasktran2", reason="sasktran2 (extra skysim[rt]) not installed")
    out = tmp_path / "sky.csv"
    assert main(["sky", "--model", "aerosol", "--aerosol", "urban", "--aod", "0.2",
                 "--albedo", "0.1", "--wavelength", "450", "--grid-step", "30", *SUN,
                 "--out", str(out)]) == 0
    t = pd.read_csv(out)
    side = json.loads((tmp_path / "sky.csv.json").read_text()) \
        if (tmp_path / "sky.csv.json").exists() else json.loads((tmp_path / "sky.json").read_text())
    assert side["sky"]["model"] == "aerosol" and side["sky"]["aerosol"]["name"] == "urban"
    assert side["sky"]["aod_550"] == 0.2 and side["sky"]["wavelength_nm"] == 450.0
    assert np.all(t.I > 0) and np.all((t.dop >= 0) & (t.dop < 1))
