"""The diagnosis of a zenith rotating-analyser compass (tests/fixtures/rotating_analyser: two
UV photodiodes behind crossed polarizers on a gear, readings normalised per revolution):
end to end from the command line (``none`` on the clean session), a tilt injected into the
simulation recovered, one decoded heading per half-turn of the analyser modulo 180 deg, the
unit checks of a turning crossed pair, and the parameters the readings cannot inform held
and reported as such."""

import importlib.util
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calibration.photodiode_diagnosis.faults import rotating_units, screen
from calibration.photodiode_diagnosis.fit import fit
from calibration.photodiode_diagnosis.forward import Forward
from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes
from calibration.photodiode_diagnosis.run import (_base_fit_report, _units_needed,
                                                  decode_headings, diagnose_instrument)
from experiments.cli.main import main
from sensor.photodiodes_io import PhotodiodeData, heading_error_deg, read_photodiodes

FIXTURE = Path(__file__).resolve().parent / "fixtures" / "rotating_analyser"
CSV = FIXTURE / "rotating_analyser.csv"


def _instrument(path=CSV):
    return instrument_from_photodiodes(read_photodiodes(path), str(path))


def _truth(fwd: Forward) -> np.ndarray:
    """The simulation's parameters: heading offset 0 (the recorded yaw is the true heading),
    nominal angles and pointing, the sky's d_max 0.6."""
    theta = np.zeros(fwd.layout.size)
    theta[fwd.layout.scale] = 0.6
    return theta


# ------------------------------------------------------------------ end to end
@pytest.mark.slow
def test_clean_session_diagnosed_from_the_command_line(tmp_path, capsys):
    """``skysim diagnose`` on the clean simulated session: within the noise floor, with the
    heading error modulo 180 deg and what normalised readings cannot give said.

    Heading error below 0.2 deg: the statistical SD of one half-turn's heading is
    sigma / (2 A sqrt(N)) rad with relative noise sigma 0.022, relative modulation A about 1
    and N about 100 readings (50 samples x 2 photodiodes), 0.06 deg; the per-revolution
    normalisation, made from the noisy extremes of each revolution, adds its own share
    (measured 0.08 deg RMS)."""
    out = tmp_path / "ra"
    assert main(["diagnose", str(CSV), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    doc = json.loads((out / "diagnosis.json").read_text())
    assert doc["verdict"]["effect"] == "none"
    assert doc["verdict"]["gap_before"] <= doc["noise_floor"] * 1.1
    he = doc["extra"]["heading_error"]
    assert he["ambiguity_deg"] == 180.0 and "modulo 180 deg" in he["ambiguity"]
    assert 0.0 < he["base_deg"] < 0.2
    base = doc["extra"]["base_fit"]
    assert base["dop_scale"] is None
    assert set(base["offset"].values()) == {None} and set(base["gain"].values()) == {None}
    assert base["at_bound"] == []
    assert {u["quantity"] for u in base["not_recoverable"]} == {
        "dop_scale", "dark_offset", "radiance", "heading_beyond_180_deg"}
    # modulo 180 deg, the fitted heading offset is the simulation's 0
    assert abs(heading_error_deg(base["heading_offset_deg"][0], 0.0, 180.0)) < 0.5
    reasons = {c["effect"]: c.get("not_applicable") for c in doc["candidates"]}
    for name in ("fov", "occlusion", "aureole"):
        assert reasons[name].startswith("not applicable: the readings are normalised")
    assert "no sweep turns" in reasons["yaw_scale"]
    assert "modulo 180 deg" in printed and "not recoverable: dop_scale" in printed
    assert "modulo 180 deg" in (out / "report.md").read_text()


def _simulate(tmp_path, monkeypatch, pitch_deg: float, roll_deg: float) -> Path:
    """The fixture's session simulated again by its own generator with the instrument tilted
    by ``pitch_deg``, ``roll_deg`` (not recorded: the file holds no attitude beside the
    yaw), converted as the fixture was; returns the converted file."""
    spec = importlib.util.spec_from_file_location("make_rotating_analyser",
                                                  FIXTURE / "make_rotating_analyser.py")
    mk = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mk)
    import sensor.compound_eye as ce
    level = ce.body_attitude
    monkeypatch.setattr(ce, "body_attitude", lambda h, p, r: level(
        h, np.asarray(p, float) + pitch_deg, np.asarray(r, float) + roll_deg))
    table = mk.simulate()
    monkeypatch.setattr(ce, "body_attitude", level)
    table.to_csv(tmp_path / "authors.csv", index=False)
    return mk.convert_authors_layout(tmp_path / "authors.csv", tmp_path / "tilted.csv")


@pytest.mark.slow
def test_injected_tilt_is_named_and_recovered(tmp_path, monkeypatch):
    """A tilt of the zenith unit (pitch 4 deg, roll -3 deg) moves its view off the zenith, so
    the angle of polarization it reads changes with the heading: named ``tilt``, recovered
    within 0.1 deg (20 times the spread of the fold fits, 0.005 deg: the fit holds the base
    model's pointing, which took up part of the tilt before it, so the recovery is limited
    by that hold, not by the noise), inside its reported uncertainty, and the heading error
    falls with it."""
    path = _simulate(tmp_path, monkeypatch, 4.0, -3.0)
    report = diagnose_instrument(_instrument(path), ("tilt", "clock_offset", "yaw_scale"))
    v = report.verdict
    assert v.effect == "tilt", v.reason
    assert v.explained_share > 0.9
    params = v.params
    for name, true in (("pitch_deg", 4.0), ("roll_deg", -3.0)):
        p = params[name]
        assert abs(p["value"] - true) < 0.1, (name, p)
        assert abs(p["value"] - true) < p["uncertainty"]
    he = report.extra["heading_error"]
    assert he["ambiguity_deg"] == 180.0 and he["best_deg"] < 0.2 < he["base_deg"]


# ------------------------------------------------------------------ pieces
def test_decoded_heading_one_per_half_turn_modulo_180():
    """Every half-turn of the analyser gets one decoded heading, the true one modulo 180 deg
    (within 0.5 deg: the statistical SD of a half-turn's heading is about 0.06 deg, see the
    end-to-end test, and the grid's parabola refinement is exact to well below that for a
    cost quadratic near its minimum)."""
    inst = _instrument()
    fwd = Forward(inst)
    h = decode_headings(fwd, _truth(fwd))
    cycle = inst.analyser_cycle
    for c in np.unique(cycle):
        assert np.ptp(h[cycle == c]) == 0.0
    err = heading_error_deg(h, inst.yaw_deg, inst.heading_ambiguity_deg)
    assert np.all(np.abs(err) < 0.5), np.abs(err).max()
    # modulo 360 about half the half-turns come out at the opposite heading (both fit
    # alike, noise picks one): the error the report gives is modulo 180 deg
    opposite = np.abs(heading_error_deg(h, inst.yaw_deg, 360.0)) > 90.0
    assert inst.heading_ambiguity_deg == 180.0 and 0.2 < opposite.mean() < 0.8


def test_a_turning_crossed_pair_is_one_working_unit():
    """Two photodiodes at distinct angles suffice on a turning analyser (they sweep every
    angle); the same pair on a fixed analyser is ``too_few`` (three needed), and one unit is
    enough only when an analyser turns."""
    inst = _instrument()
    assert rotating_units(inst).tolist() == [True]
    scr = screen(inst)
    assert scr.unit_ok.tolist() == [True] and not scr.faults
    assert _units_needed(inst) == 1
    fixed = replace(inst, pd_angle_row_deg=None, analyser_cycle=None)
    scr = screen(fixed)
    assert scr.unit_ok.tolist() == [False]
    assert scr.faults[0]["kind"] == "too_few"
    assert scr.faults[0]["evidence"]["needed"] == "3 at distinct polarizer angles"
    assert _units_needed(fixed) == 2
    assert _units_needed(inst, np.array([False])) == 2     # no working unit turns


def test_parameters_the_readings_cannot_inform_stay_held():
    """Normalised readings: a fit started with the DoP scale at its bound 1.0, dark offsets
    at -0.27 and gains of 1.5 leaves all three where they started (held, not fitted) and
    the base-fit report gives them as null, not as findings at a bound."""
    inst = _instrument()
    fwd = Forward(inst)
    L = fwd.layout
    theta = _truth(fwd)
    theta[L.scale], theta[L.off], theta[L.lam] = 1.0, -0.27, np.log(1.5)
    theta[L.heading] = 10.0
    res = fit(fwd, theta, sigma=0.02, max_iter=20)
    assert res.theta[L.scale] == 1.0
    np.testing.assert_array_equal(res.theta[L.off], -0.27)
    np.testing.assert_array_equal(res.theta[L.lam], np.log(1.5))
    assert abs(heading_error_deg(res.theta[L.heading][0], 0.0, 180.0)) < 0.5
    rep = _base_fit_report(res.theta, L, fwd, inst, 1.0)
    assert rep["dop_scale"] is None and rep["at_bound"] == []
    assert set(rep["offset"].values()) == {None} and set(rep["gain"].values()) == {None}


def test_raw_readings_report_a_base_fit_at_its_bound():
    """The same instrument with raw readings fits its DoP scale and dark offsets; a fit that
    ends with the DoP scale at its bound 1.0 and an offset at its bound is reported so."""
    d = read_photodiodes(CSV)
    side = dict(d.sidecar, readings="raw", reading_unit="volts", adc_full_scale=5.0,
                saturation_value=5.0)
    raw = PhotodiodeData(d.table.assign(pd_a=d.table["pd_a"] + 0.1,
                                        pd_b=d.table["pd_b"] + 0.1), side)
    inst = instrument_from_photodiodes(raw)
    fwd = Forward(inst)
    L = fwd.layout
    assert not (fwd.held_by_readings() | fwd.absorbed_by_profile()).any()
    theta = _truth(fwd)
    theta[L.scale] = 1.0
    theta[L.off.start] = -0.5
    rep = _base_fit_report(theta, L, fwd, inst, 1.0)
    assert rep["at_bound"] == ["offset:pd_a", "dop_scale"]
    assert rep["dop_scale"] == 1.0 and rep["gain"]["pd_a"] == 1.0
    assert rep["not_recoverable"] == [{"quantity": "heading_beyond_180_deg",
                                       "reason": d.unrecoverable[-1]["reason"]}]
