"""Progress of long runs on stderr (experiments/workflows/progress.py)."""

from __future__ import annotations

import time

from experiments.workflows.progress import (ANNOUNCE_AFTER_S, REPRODUCTION_SECONDS,
                                            STEP_SECONDS, Steps, working)


def test_steps_show_the_run_and_record_each_step(capsys):
    with Steps("skysim reproduce demo", {"first": 8.0, "second": 8.0}) as steps:
        time.sleep(0.05)
        steps.done("first")
        steps.done("second")
    err = capsys.readouterr().err
    assert "skysim reproduce demo" in err and "about 16 s left (first)" in err
    assert err.rstrip().endswith("done")
    assert list(steps.elapsed_s) == ["first", "second"] and steps.elapsed_s["first"] >= 0.05
    assert set(steps.cpu_s) == {"first", "second"}


def test_short_runs_show_nothing(capsys):
    with working("a short call", ANNOUNCE_AFTER_S):
        pass
    assert capsys.readouterr().err == ""


def test_a_run_past_its_estimate_says_so():
    steps = Steps("x", {"only": 1.0}).__enter__()
    steps._last -= 2.0  # two seconds into a step expected to take one
    assert steps._state()[2] == "longer than expected (only)"
    steps.__exit__(None, None, None)


def test_step_costs_add_up_to_the_announced_duration():
    full, quick, _ = REPRODUCTION_SECONDS["physical-sky"]
    assert full == sum(STEP_SECONDS["physical-sky"].values())
    assert quick == sum(STEP_SECONDS["physical-sky --quick"].values())
