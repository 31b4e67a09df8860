"""pyskylumos's camera chain against skysim's on the same scene (tests/peer/compare_pyskylumos.py).

pyskylumos needs Python >= 3.12: where it does not import, this test is skipped with the reason.
"""

import numpy as np
import pytest

pytest.importorskip("pyskylumos", reason="pyskylumos is not installed (it needs Python >= 3.12); "
                    "run tests/peer/compare_pyskylumos.py in an environment that has it")

from compare_pyskylumos import compare  # noqa: E402  (after the skip)


@pytest.mark.parametrize("lens", ["equidistant", "equisolid"])
def test_same_scene_same_camera_chain(lens):
    r = compare(lens)
    # the same projections, pixel for pixel: 1e-5 deg is 1/100000 of a pixel (measured 2e-6)
    assert r["lens_max_angle_deg"] < 1e-5
    # the same single-scattering sky to rounding (measured 1e-15 and 2e-13 deg)
    assert r["sky_dop_max_diff"] < 1e-12 and r["sky_aop_max_diff_deg"] < 1e-9
    for tag in ("ideal", "eps0.9"):
        # identical inputs and settings: raw counts differ by pyskylumos's floor against
        # skysim's rounding only, at most one count
        assert r[f"chain_{tag}_raw_max_diff_counts"] <= 1.0
        assert r[f"chain_{tag}_samples"] > 3000
        # one count on a few hundred: a few 1e-3 of DoLP (measured 0.0045)
        assert r[f"chain_{tag}_dolp_max_diff"] < 0.01
    # noise differs by design: pyskylumos's is proportional to the signal (SNR 100), skysim's
    # shot noise to its square root (plus 2.3 e- read noise); 16384 samples give the standard
    # deviations to 0.6 %, 3 % allows for the ADC's rounding
    (p1, s1), (p5, s5) = r["noise_std_counts_at_0.1"], r["noise_std_counts_at_0.5"]
    full = 2 ** 12 - 1
    assert p1 == pytest.approx(0.1 * full / 100, rel=0.03)
    assert p5 == pytest.approx(0.5 * full / 100, rel=0.03)
    assert s1 == pytest.approx(np.sqrt(0.1 * full + 2.3 ** 2 + 1 / 12), rel=0.03)
    assert s5 == pytest.approx(np.sqrt(0.5 * full + 2.3 ** 2 + 1 / 12), rel=0.03)
