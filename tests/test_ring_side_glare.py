"""The ring's side glare recovers its own effect on the identifiability matrix's simulated
ring (twelve one-turn sweeps, ``calibration.diagnosis.identifiability.ring_session``), is not
named on clean data, and with it withheld no single other effect is named."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.diagnosis.api import diagnose
from calibration.diagnosis.identifiability import ring_session

CONFUSERS = ("side_glare", "stray_light", "aureole")
"""The side glare and what it can stand in for (the ring's confusable candidates): named
alone only over these."""


@pytest.mark.slow
@pytest.mark.parametrize("L, R", [(0.15, 0.05), (0.3, 0.1)])
def test_side_glare_named_and_recovered(L, R):
    """Light three times as strong with the sun on each unit's left as on its right
    (strengths 0.15/0.05 and 0.3/0.1 of the session's median reading), falling off over
    20 deg: named, converged away from its bounds, and its 65 parameters recovered with
    z-scores of RMS within 0.6-1.6 (measured 1.05 and 1.07 on seed 31; with 65 z-scores
    the RMS of calibrated ones lies within 1 +- 0.18 at 2 SD, widened for the correlation of
    one fit's strengths) and the fall-off within 3 SE (20.27 +- 0.22, 20.08 +- 0.11)."""
    truth = {"L": L, "R": R, "scale_deg": 20.0}
    rep = diagnose(ring_session("side_glare", truth, 31), CONFUSERS, seed=0)
    v = rep.verdict
    assert v.effect == "side_glare", v.reason
    c = rep.candidate("side_glare")
    assert c.converged and not c.at_bound
    z = np.array([(p["value"] - truth[k.split("_")[0] if k[:2] in ("L_", "R_") else k])
                  / p["uncertainty"] for k, p in c.params.items()])
    assert z.size == 65
    assert 0.6 <= np.sqrt(np.mean(z ** 2)) <= 1.6, z
    scale = c.params["scale_deg"]
    assert abs(scale["value"] - 20.0) <= 3.0 * scale["uncertainty"], scale


@pytest.mark.slow
def test_side_glare_not_named_on_clean_data_nor_stood_in_for():
    """Clean data: `none`. The side glare withheld (0.3/0.1): the stray light, which it
    nests, comes close (94 % of the excess on seed 31) but is not named alone: the verdict
    is their group."""
    clean = diagnose(ring_session(None, None, 31), CONFUSERS, seed=0)
    assert clean.verdict.effect == "none", clean.verdict.reason
    truth = {"L": 0.3, "R": 0.1, "scale_deg": 20.0}
    held = diagnose(ring_session("side_glare", truth, 31), CONFUSERS[1:], seed=0)
    assert held.verdict.effect in ("group", "partly_explained", "unexplained"), \
        held.verdict.reason
    assert held.verdict.effect != "group" or "side_glare" in held.verdict.group
