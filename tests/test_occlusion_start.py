"""The ring's occlusion candidate starts its fit from the occluded sector, partly or strongly
depolarizing, on a simulated session of real length (12 one-turn sweeps over 12 min,
:func:`calibration.diagnosis.identifiability.ring_session`).

The references are independent of the start search: the generator's truth (the sensor
simulator with the sector's DoP lowered in the sky it observes, which the fits never see),
and the fit started at that truth. Tolerances: the search's fit must reach the optimum the
fit from the truth reaches (cost within 1e-3 of it: fits that end in the same minimum agree
to the fit's own convergence tolerance, while the next-best minimum, a sector at 298 deg for
the one at 100 deg, costs thousands of times more), and the fitted sector must lie within
1 deg of the truth's centre and width (the fit from the truth lands within 0.01 deg of
them, its sandwich SE about 0.002 deg, so 1 deg fails only a start in another minimum).
"""

from __future__ import annotations

import numpy as np
import pytest

from ring_sessions import base_fit_and_effect

from calibration.diagnosis.identifiability import ring_session
from calibration.photodiode_diagnosis.instrument import instrument_from_photodiodes
from calibration.photodiode_diagnosis.run import (
    _extend,
    _fit_effect,
    _start_effect,
)

SECTOR = {"width_deg": 90.0, "edge_deg": 5.0}


@pytest.mark.parametrize("center_deg, depolarization", [(100.0, 0.4), (100.0, 0.2), (250.0, 0.8)])
def test_occlusion_search_reaches_the_fit_from_the_truth(center_deg, depolarization):
    """A sector of 90 deg with edges of 5 deg, at 100 deg depolarizing 40 % (the base fit
    takes up much of it in dark offsets, gains and a DoP scale at its bound, and scored
    under that instrument the best starts lie at 240-270 deg) or 20 % (started at 60 %
    under the nominal instrument, sectors at 240-270 deg score best as well), and at 250 deg
    depolarizing 80 %: the fit from the searched starts ends where the fit from the truth
    ends."""
    truth = {"center_deg": center_deg, "depolarization": depolarization, **SECTOR}
    inst = instrument_from_photodiodes(ring_session("occlusion", truth, seed=31))
    s, fe, e, _ = base_fit_and_effect(inst, "occlusion")
    L = fe.layout
    searched, _ = _fit_effect(fe, _start_effect(fe, s.theta, s.base, e, s.sigma), s.sigma)
    p_true = np.array([truth[n] for n in e.parameter_names])
    from_truth, _ = _fit_effect(fe, _extend(s.theta, s.base, fe, p_true), s.sigma)
    assert searched.cost <= from_truth.cost * (1.0 + 1e-3), (searched.cost, from_truth.cost,
                                                             searched.theta[L.effect])
    centre, width = searched.theta[L.effect][:2]
    assert abs((centre - center_deg + 180.0) % 360.0 - 180.0) < 1.0, centre
    assert abs(width - SECTOR["width_deg"]) < 1.0, width
