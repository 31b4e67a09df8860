"""Recorded times that are themselves uncertain (reconstructed after the fact, not logged):
the fitted clock's uncertainty includes theirs."""

import numpy as np
import pytest
from ring_sessions import ring_session

from calibration import diagnose
from calibration.diagnosis import UnsupportedInstrumentError
from calibration.photodiode_diagnosis.errors import InstrumentDataError


@pytest.fixture(scope="module")
def reports():
    """One short session with a right clock, diagnosed with the clock candidate alone, with
    the recorded times taken as exact and as uncertain by 2 min."""
    s = ring_session(n_sweeps=3, per_sweep=60)
    return (diagnose(s, ("clock_offset",), folds=3),
            diagnose(s, ("clock_offset",), folds=3, time_uncertainty_s=120.0))


def _clock(report):
    return next(c for c in report.candidates if c.effect == "clock_offset")


def test_time_uncertainty_adds_in_quadrature(reports):
    """The three terms are independent (the noise of this session, the spread of the clock
    over sky models, the error of the times), so their variances add: the reported
    uncertainty is their root sum of squares, to round-off."""
    exact, uncertain = (_clock(r).details for r in reports)
    assert exact["recorded_times_uncertainty_s"] == 0.0
    assert uncertain["recorded_times_uncertainty_s"] == 120.0
    for e in (exact, uncertain):
        expected = np.sqrt(e["statistical_uncertainty_s"] ** 2 + e["sky_model_spread_s"] ** 2
                           + e["recorded_times_uncertainty_s"] ** 2)
        assert e["uncertainty_s"] == pytest.approx(expected, rel=1e-12)
    # the fit itself does not depend on what is known of the times
    assert _clock(reports[1]).params["clock_offset_s"]["value"] == pytest.approx(
        _clock(reports[0]).params["clock_offset_s"]["value"], abs=1e-6)
    assert uncertain["uncertainty_s"] > 120.0 > exact["uncertainty_s"]


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_bad_time_uncertainty_is_refused(bad):
    s = ring_session(n_sweeps=2, per_sweep=20)
    with pytest.raises(InstrumentDataError, match="time_uncertainty_s must be a finite"):
        diagnose(s, ("clock_offset",), folds=2, time_uncertainty_s=bad)


def test_time_uncertainty_is_for_rings_only():
    """A three-pair sensor's diagnosis fits no clock with an uncertainty: asked for one, it
    says so rather than ignoring it."""
    from experiments.workflows.diagnose import simulate_session
    ds = simulate_session(None, np.random.default_rng(1))
    with pytest.raises(UnsupportedInstrumentError, match="time_uncertainty_s"):
        diagnose(ds["data"], ("tilt",), time_uncertainty_s=60.0)


def test_session_index_marks_estimated_times(tmp_path):
    """The reproduction reads which sessions' times were estimated from the folder's
    ``sessions.csv``; logged, unlisted and index-less sessions count as exact."""
    from experiments.studies.real_compass import ESTIMATED_TIMES_UNCERTAINTY_S, times_uncertainty
    files = [tmp_path / n for n in ("a.csv", "b.csv", "c.csv")]
    (tmp_path / "sessions.csv").write_text("file,sample_times\na.csv,estimated\nb.csv,logged\n")
    u = times_uncertainty(files)
    assert u == {files[0]: ESTIMATED_TIMES_UNCERTAINTY_S, files[1]: 0.0, files[2]: 0.0}
    (tmp_path / "sessions.csv").unlink()
    assert set(times_uncertainty(files).values()) == {0.0}


def test_refined_clock_keeps_the_sky_model_spread():
    """A clock hours off is refined by passes that fit it alone, under single scattering;
    when the passes stay within 15 min of the first fit, that fit read the clock under every
    sky candidate at about the right times, so the spread over those skies stays in the
    refined uncertainty: the root sum of squares of the last pass's uncertainty and the
    first fit's ``sky_model_spread_s``, to round-off.

    The first fit reads this far clock under single scattering in every stage
    (:func:`calibration.photodiode_diagnosis.clock.far_clock`); read under the neutral-point
    sky fitted at the recorded times, it would stop near 5,970 s, 1,214 s from the refined
    value, and the passes would not stay within 15 min of it."""
    import pandas as pd

    from sensor.photodiodes_io import PhotodiodeData
    s = ring_session(n_sweeps=3, per_sweep=60)
    t = s.table.copy()
    t["time"] = t["time"] - pd.Timedelta(hours=2)
    doc = diagnose(PhotodiodeData(t, s.sidecar), ("neutral_points", "clock_offset"), folds=3)
    c = _clock(doc).details
    ref = c["refinement"]
    assert abs(_clock(doc).params["clock_offset_s"]["value"] - ref["first_fit_s"]) <= 900.0
    assert ref["sky_model_spread_kept_s"] == c["sky_model_spread_s"] > 0.0
    assert set(c["by_sky"]) == {"single_scattering", "neutral_points"}
    expected = np.hypot(ref["passes"][-1]["uncertainty_s"], c["sky_model_spread_s"])
    assert c["uncertainty_s"] == pytest.approx(expected, rel=1e-12)
    assert _clock(doc).params["clock_offset_s"]["uncertainty"] == c["uncertainty_s"]


def test_sky_model_spread_is_read_from_the_recorded_times(monkeypatch):
    """Within half an hour of the recorded times, the clock is read under each sky model as
    the candidate reads it: from the recorded times (start 0), with the base's pointing; a
    start at the fitted offset would first re-read the pointing there, and that pointing has
    already taken up the offset. Hours away, the start is the fitted offset."""
    from calibration.photodiode_diagnosis import clock

    starts = []
    real = clock._aop_clock_fit

    def spy(fe, theta_base, layout, start_s, sigma):
        starts.append(start_s)
        return real(fe, theta_base, layout, start_s, sigma)

    monkeypatch.setattr(clock, "_aop_clock_fit", spy)
    s = ring_session(n_sweeps=3, per_sweep=60)
    doc = diagnose(s, ("neutral_points", "clock_offset"), folds=3)
    assert abs(_clock(doc).params["clock_offset_s"]["value"]) < clock.CLOCK_NEAR_S
    assert starts == [0.0, 0.0]          # single scattering and the neutral-point sky
