"""Jin et al. 2020 reproduction: sun-time reading, acceptance over 20 seeds, CLI outputs."""

import json

import numpy as np
import pandas as pd
import pytest

from experiments.cli.main import build_parser, main
from experiments.studies.jin2020 import (
    PAPER_SUN,
    QUICK,
    SITE,
    azimuth_from_south,
    run,
    sun_discrepancy_table,
)


@pytest.fixture(scope="module")
def sun_table():
    return sun_discrepancy_table()


def test_azimuth_from_south_convention():
    """The paper's azimuth: from south, west negative (so north-clockwise 270 (west) -> -90)."""
    np.testing.assert_allclose(azimuth_from_south([180.0, 270.0, 90.0, 280.89]),
                               [0.0, -90.0, 90.0, -100.89], atol=1e-12)


def test_paper_sun_angles_match_local_apparent_solar_time(sun_table):
    """Read as local apparent solar time, the paper's times give its sun angles. The paper
    rounds to 0.01 deg and the sun moves 0.19 deg/min here, so 0.02 deg (6 s of time)
    allows rounding plus the ephemeris difference (pysolar/SPA vs the paper's source)."""
    last = sun_table[sun_table.reading == "apparent_solar"]
    assert len(last) == len(PAPER_SUN)
    assert np.abs(last.d_elevation_deg).max() < 0.02
    assert np.abs(last.d_azimuth_deg).max() < 0.02


def test_beijing_reading_is_off_by_the_solar_time_offset(sun_table):
    """Read as Beijing time the sun is ~1.7 deg lower (the issue: 18.78/-102.20 at 17:20).
    The clock offset LAST - BJT = 4 min/deg x (121.53 - 120) + equation of time; the equation
    of time from Spencer's 1971 series (pvlib, independent of the SPA) agrees within 0.1 min
    (Spencer's series is good to ~0.5 min; tolerance 0.6 min)."""
    pvlib = pytest.importorskip("pvlib")
    bj = sun_table[sun_table.reading == "beijing"].set_index("paper_time")
    assert bj.loc["17:20", "elevation_deg"] == pytest.approx(18.78, abs=0.01)
    assert bj.loc["17:20", "azimuth_south_deg"] == pytest.approx(-102.20, abs=0.01)
    assert np.all(bj.d_elevation_deg < -1.5)
    doy = pd.Timestamp("2018-05-25").day_of_year
    eot_min = float(pvlib.solarposition.equation_of_time_spencer71(doy))
    expected = 4.0 * (SITE.longitude_deg - 120.0) + eot_min
    np.testing.assert_allclose(sun_table.time_offset_min, expected, atol=0.6)
    np.testing.assert_allclose(sun_table.time_offset_min, 9.2, atol=0.1)   # the value


def test_acceptance_over_20_seeds(tmp_path):
    """Acceptance (issue 6), quick runs (120 s static, 60 s dynamic) with 20 seeds: in the
    dynamic run the dynamic step's RMS attitude error is below the fixed step's on the mean
    over seeds and by a one-sided paired sign test at 1 % (>= 16 of 20 seeds); in the static
    run both beat gyro-only for every seed."""
    res = run(trials=20, seed=11, out=tmp_path, scenario=QUICK, figures=False,
              multiple_scattering=False)
    s = res["summary"]
    assert s["trials"] == 20
    assert all(s["acceptance"].values()), s["acceptance"]
    assert s["accepted"]
    assert s["acceptance_counts"]["dynamic_run_seeds_dynamic_below_fixed"] >= 16
    assert s["acceptance_counts"]["static_run_seeds_fixed_below_gyro"] == 20
    e = res["errors"]
    assert len(e) == 2 * 3 * 20 and np.all(np.isfinite(e.total_rms_deg))
    for name in ("sun_positions.csv", "errors.csv", "table.md", "summary.json",
                 "timeseries_static.csv", "timeseries_dynamic.csv"):
        assert (tmp_path / name).stat().st_size > 0
    sidecar = json.loads((tmp_path / "timeseries_dynamic.csv.json").read_text())
    assert sidecar["schema"] == "skysim.jin2020.timeseries/1" and sidecar["seed"] == 11


def test_cli_quick_writes_figures(tmp_path, capsys):
    assert main(["jin2020", "--quick", "--trials", "2", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "apparent_solar" in out and "dynamic step" in out
    for fig in ("fig3_static.png", "fig4_dynamic.png", "fig5_errors.png"):
        assert (tmp_path / fig).stat().st_size > 10_000
    assert build_parser().parse_args(["reproduce", "jin2020"]).target == "jin2020"


def test_multiple_scattering_sky_biases_the_rayleigh_form_and_not_the_model_form():
    """Static run (60 s, 4 seeds) under the multiple-scattering sky (tau 0.25): the E-vectors
    depart from "normal to the sun" by up to degrees; the Rayleigh error vector turns that
    into an attitude bias (roll > 0.3 deg observed ~1 deg over 20 seeds), the
    measured-vs-predicted form with the same sky removes it (bias below 0.05 deg; observed
    below 0.01 deg, the level of the 0.1-deg E-vector noise averaged over the run) and
    halves the RMS error at least."""
    pytest.importorskip("sasktran2", reason="sasktran2 (extra skysim[rt]) not installed")
    from dataclasses import replace

    from experiments.studies.jin2020 import multiple_scattering_runs
    sc = replace(QUICK, static_s=60.0, ms_taus=(0.25,))
    r = multiple_scattering_runs(4, np.random.default_rng(5), sc).set_index("form")
    assert r.loc["perpendicular", "aop_departure_max_deg"] > 1.0
    assert abs(r.loc["perpendicular", "roll_bias_deg"]) > 0.3
    for k in ("yaw_bias_deg", "pitch_bias_deg", "roll_bias_deg"):
        assert abs(r.loc["model", k]) < 0.05, k
    assert (r.loc["model", "total_rms_second_half_deg"]
            < 0.5 * r.loc["perpendicular", "total_rms_second_half_deg"])
