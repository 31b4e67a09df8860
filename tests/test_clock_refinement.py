"""The refinement of a clock hours off: passes at the corrected times, and the uncertainty of
the refined offset (:func:`calibration.photodiode_diagnosis.clock.refined_uncertainty`).

Measured calibration of the rule (simulated rings, the clock candidate alone unless said,
three folds; z = (fitted - true) / uncertainty; Q: every pass's uncertainty in quadrature,
L: the rule, the last pass's uncertainty with an unsettled last step added):

three-sweep sessions of 60 samples a sweep: "matrix" the identifiability matrix's ring with
the clock error injected, "stamped" the test ring (one fast turn a minute) stamped early;
steps are each pass's fitted offset (its uncertainty) [s]::

      truth seed  session  candidates first fit  steps              refined   z (Q)  z (L)
     +3,300  1   matrix    clock       3,210  +0(49)                 3,210  -1.83  -1.83
     -5,000  1   matrix    clock      -5,002  -0(50)                -5,002  -0.04  -0.04
     +7,000  1   matrix    clock       7,107  -88(132)               7,019  +0.14  +0.14
     +3,300  2   matrix    clock       3,180  +107(157)              3,287  -0.08  -0.08
     -5,000  2   matrix    clock      -4,992  +0(44)                -4,992  +0.17  +0.17
     +7,000  2   matrix    clock       7,084  +0(45)                 7,084  +1.85  +1.85
     +7,000  3   matrix    np+clock    7,134  -0(40)                 7,134  +3.35  +3.35
     -5,000  3   matrix    np+clock   -4,994  +0(40)                -4,994  +0.01  +0.01
     +7,200  1   stamped   clock       9,462  -2274(22) -0(38)       7,188  -0.26  -0.31
     -5,400  1   stamped   clock      -5,400  -0(38)                -5,400  -0.00  -0.00
     +5,400  2   stamped   clock       6,820  -1361(59) +0(43)       5,459  +0.81  +1.36
     +7,200  2   stamped   clock       9,453  -2207(46) +0(43)       7,245  +0.72  +1.05
     +3,600  3   stamped   clock       3,607  +0(39)                 3,607  +0.18  +0.18

z RMS: all 13 cases Q 1.22, L 1.27; the clock alone (11) Q 0.86, L 0.95; the three cases of
two passes, where the rules differ, Q 0.64 (over-covering: the first pass's uncertainty,
of a fit at times still 20-40 min off, counted again), L 1.01. The one |z| > 3 (a
neutral-point sky fitted beside the clock) has one settled pass under either rule. A
twelve-sweep matrix ring (+7,000 s, seed 1) refines in one pass to 7,009 +- 27 s (z 0.32).
"""

import math
from dataclasses import replace

import numpy as np
import pytest

from calibration.diagnosis.errors import InsufficientDataError
from calibration.diagnosis.identifiability import ring_session
from calibration.photodiode_diagnosis import clock, instrument_from_photodiodes
from calibration.photodiode_diagnosis.run import light_track


@pytest.fixture(scope="module")
def inst():
    return instrument_from_photodiodes(ring_session(n_sweeps=2, per_sweep=30), "ring")


def _refine(inst, first, steps, spread=700.0):
    """Refine a first fit ``first`` [s] through passes returning ``steps`` ((step,
    uncertainty) or an exception each); returns the row and the shifts each pass saw."""
    shifts = []

    def one_pass(shifted):
        shifts.append(float(shifted.t_s[0] - inst.t_s[0]))
        step = steps[len(shifts) - 1]
        if isinstance(step, Exception):
            raise step
        return {"effect": "clock_offset", "params": {"clock_offset_s": {"value": step[0]}},
                "uncertainty_s": step[1], "by_sky": {"single_scattering": step[0]}}

    row = {"params": {"clock_offset_s": {"value": first, "uncertainty": 90.0}},
           "uncertainty_s": 90.0, "sky_model_spread_s": spread, "significant": True}
    clock.refine_clock_offset(replace(inst), row, one_pass, light_track(inst))
    return row, shifts


def test_settled_refinement_carries_the_last_pass_uncertainty(inst):
    """Three passes as on the two-photodiode compass (steps 3,000, 400 and 100 s with
    uncertainties 5,098, 3,411 and 340 s): each pass is fitted at the times the ones before
    corrected, the refined offset is the first fit plus every step, 8,500 s, and, the last
    step (100 s) being under a third of the 900-s threshold, its uncertainty is the last
    pass's, 340 s: the refined offset is the fixed shift 8,400 s plus that pass's fit."""
    row, shifts = _refine(inst, 5000.0, [(3000.0, 5098.0), (400.0, 3411.0), (100.0, 340.0)])
    assert shifts == [5000.0, 8000.0, 8400.0]
    param = row["params"]["clock_offset_s"]
    assert param["value"] == 8500.0
    # the passes ended 3,500 s from the first fit: its sky-model spread is not kept
    assert param["uncertainty"] == 340.0
    assert row["uncertainty_s"] == param["uncertainty"]
    assert "sky_model_spread_kept_s" not in row["refinement"]
    assert row["significant"] is True
    assert [p["uncertainty_s"] for p in row["refinement"]["passes"]] == [5098.0, 3411.0,
                                                                           340.0]
    assert row["refinement"]["method"].endswith(clock.REFINED_RULE)


def test_unsettled_refinement_adds_its_last_step(inst):
    """Passes that run out (three) with the last step, 600 s, still a third of the threshold
    or more: the offset has not settled, and the step is added in quadrature to the last
    pass's uncertainty, sqrt(200^2 + 600^2) = 632.5 s."""
    row, shifts = _refine(inst, 4000.0, [(3000.0, 500.0), (1500.0, 400.0), (600.0, 200.0)])
    assert shifts == [4000.0, 7000.0, 8500.0]
    param = row["params"]["clock_offset_s"]
    assert param["value"] == 9100.0
    assert param["uncertainty"] == pytest.approx(math.hypot(200.0, 600.0), rel=1e-12)


def test_failed_pass_leaves_the_last_step_unsettled(inst):
    """A pass that fails after a 2,000-s step ends the refinement with its error, and the
    offset, not settled, carries that step: sqrt(300^2 + 2000^2) s."""
    row, _ = _refine(inst, 3000.0, [(2000.0, 300.0),
                                    InsufficientDataError("no usable sweep")])
    assert row["refinement_error"] == "no usable sweep"
    assert row["params"]["clock_offset_s"]["value"] == 5000.0
    assert row["params"]["clock_offset_s"]["uncertainty"] == pytest.approx(
        math.hypot(300.0, 2000.0), rel=1e-12)


def test_refinement_near_the_first_fit_keeps_the_sky_model_spread(inst):
    """One settled pass 120 s from the first fit: that fit's sky candidates were fitted at
    about the right times, so its 700-s sky-model spread stays, in quadrature."""
    row, _ = _refine(inst, 5000.0, [(120.0, 80.0)])
    param = row["params"]["clock_offset_s"]
    assert param["value"] == 5120.0
    assert param["uncertainty"] == pytest.approx(math.hypot(80.0, 700.0), rel=1e-12)
    assert row["refinement"]["sky_model_spread_kept_s"] == 700.0


def _injected(truth, seed):
    """A three-sweep ring of the identifiability matrix with its clock ``truth`` [s] off."""
    return ring_session("clock_offset", {"clock_offset_s": truth}, seed=seed, n_sweeps=3,
                        per_sweep=60)


def _stamped_early(truth, seed):
    """The three-sweep test ring (one fast turn a minute) stamped ``truth`` [s] early."""
    import pandas as pd
    from ring_sessions import ring_session as test_ring

    from sensor.photodiodes_io import PhotodiodeData
    s = test_ring(n_sweeps=3, per_sweep=60, seed=seed)
    t = s.table.copy()
    t["time"] = t["time"] - pd.Timedelta(seconds=truth)
    return PhotodiodeData(t, s.sidecar)


SLOW_CASES = [(-5000.0, 2, _injected), (7200.0, 1, _stamped_early)]


@pytest.mark.slow
@pytest.mark.parametrize("truth, seed, shift_session", SLOW_CASES)
def test_refined_clock_covers_the_truth(truth, seed, shift_session):
    """Simulated rings with a clock hours off, diagnosed with the clock candidate alone:
    the refined offset lies within 3 of its uncertainties of the truth (an |z| of 3 has a
    probability of 0.3 % for a calibrated Gaussian error)."""
    from calibration import diagnose
    data = shift_session(truth, seed)
    c = next(c for c in diagnose(data, ("clock_offset",), folds=3).candidates
             if c.effect == "clock_offset")
    p = c.params["clock_offset_s"]
    assert "refinement" in c.details
    assert abs(p["value"] - truth) < 3.0 * p["uncertainty"]
    assert np.isfinite(p["uncertainty"]) and p["uncertainty"] > 0.0
