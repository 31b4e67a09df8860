"""The ring's occlusion candidate reports uncertainties that cover its errors: z-scores
(fitted - true) / uncertainty over simulated rings with an occluded sector."""

import numpy as np
import pytest


@pytest.mark.slow
def test_occlusion_uncertainties_are_calibrated_on_simulated_rings():
    """A strong occluded sector (centre 250 deg, 90 deg wide, depolarization 0.8, edges 5
    deg) on four noise draws of a twelve-sweep ring: the occlusion is named in each, and the
    z-scores of its four parameters have an RMS between 0.4 and 1.5.

    The uncertainty is the two-step sandwich over samples; the report's adds the fold
    spread to the mean fold SD (each fold fitted on two thirds of the sweeps), about 1.4
    times the SD of the folds' mean, so a calibrated SD gives a z RMS near 0.7. Sixteen
    z-scores from four draws (each draw's four parameters move together): on seeds 31-34
    the RMS was 0.59 (the model covariance scaled by the white-noise RMS of all readings,
    before: 0.11, six times too wide for the sector's centre). The bounds leave room for
    the spread of an RMS of four draws and fail a covariance several times too wide or
    too narrow."""
    from calibration import diagnose
    from calibration.diagnosis.identifiability import ring_session
    truth = {"center_deg": 250.0, "width_deg": 90.0, "depolarization": 0.8, "edge_deg": 5.0}
    z = []
    for seed in (35, 36, 37, 38):
        rep = diagnose(ring_session("occlusion", truth, seed=seed), ("occlusion",), folds=3)
        assert rep.verdict.effect == "occlusion"
        (cand,) = [c for c in rep.candidates if c.effect == "occlusion"]
        for name, value in truth.items():
            p = cand.params[name]
            z.append((p["value"] - value) / p["uncertainty"])
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.4 < rms < 1.5, (rms, np.round(z, 2))
