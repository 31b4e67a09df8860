"""The rail test of the fault screen on a ring whose units weigh the sky over a wide
acceptance: the smooth maxima of a turning unit's readings are not a clip, a clip of the
same readings is."""

import numpy as np
import pytest

from calibration.diagnosis.identifiability import ring_session
from calibration.photodiode_diagnosis.faults import RAIL_BAND, screen
from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes
from sensor.photodiodes_io import PhotodiodeData


@pytest.fixture(scope="module")
def wide():
    """A simulated ring (twelve sweeps) whose units weigh the sky by the measured acceptance
    widened to a HWHM of 50 deg: its readings peak at 36 % of the converter's full scale."""
    return ring_session("fov", {"hwhm_deg": 50.0}, seed=31)


def test_a_wide_acceptance_is_not_taken_for_a_clip(wide):
    """Its readings within 4 % of the top are 2.1 times as many as in the next two bands (a
    turning unit's reading piles up at its smooth maximum), but the crossed photodiode of
    the same unit reads its minimum there: no rail, no saturated channel, no reading
    excluded."""
    inst = instrument_from_photodiodes(wide)
    R = inst.readings
    top = R.max()
    near = (R >= (1 - RAIL_BAND) * top).sum()
    under = ((R < (1 - RAIL_BAND) * top) & (R >= (1 - 3 * RAIL_BAND) * top)).sum()
    assert near >= 2 * under                 # the pile-up that alone was taken for a clip
    assert top < 0.4 * wide.sidecar["saturation_value"]
    scr = screen(inst)
    assert scr.rail is None
    assert not [f for f in scr.faults if f["kind"] == "saturated"], scr.faults
    assert scr.counts["saturated"] == 0 and scr.reading_ok.all()


@pytest.mark.parametrize("level", [0.85, 0.95])
def test_a_clip_of_the_same_readings_is_found(wide, level):
    """The same readings clipped at 85 or 95 % of their top (a converter's hard full scale,
    which reaches the polarizers' maxima, not every photodiode of a unit): the rail is found
    within :data:`RAIL_BAND` below the clip and the clipped readings are excluded."""
    cols = list(wide.columns)
    R = wide.table[cols].to_numpy(float)
    clip = float(np.round(level * R.max()))
    t = wide.table.copy()
    t[cols] = np.minimum(R, clip)
    scr = screen(instrument_from_photodiodes(PhotodiodeData(t, wide.sidecar)))
    assert scr.rail is not None and (1 - RAIL_BAND) * clip - 1 <= scr.rail < clip
    assert scr.counts["saturated"] >= int((R >= clip).sum())
