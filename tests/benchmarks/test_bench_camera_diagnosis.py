"""Camera-image diagnosis benchmark (run with `make bench`; disabled in `make test`).

One diagnosis of a 128 x 128 raw frame (a fisheye sky frame with polarizer offsets injected,
d_max known) with every candidate of :data:`calibration.diagnosis.camera.CAMERA_CANDIDATES`
(crosstalk and overcast included); baseline in the same run: the base model alone (the cost
every diagnosis pays before its candidates). Goal reported (never asserted): <= 30 s on a
2-core machine, what a user waits for one frame at the command line.
"""

import pytest

from calibration.diagnosis import diagnose
from calibration.diagnosis.camera import CAMERA_CANDIDATES


@pytest.fixture(scope="module")
def frame():
    from test_camera_diagnosis import _frame
    return _frame(3, angle_offsets=(2.0, -1.5, 0.0, 1.0))


@pytest.mark.benchmark(group="camera diagnosis 128x128")
def test_camera_diagnosis_base_only_baseline(benchmark, frame):
    benchmark.extra_info.update(items=1, baseline=True)
    rep = benchmark.pedantic(diagnose, args=(frame, []), rounds=2, iterations=1)
    assert rep.verdict.effect == "unexplained"


@pytest.mark.benchmark(group="camera diagnosis 128x128")
def test_camera_diagnosis_all_candidates(benchmark, frame):
    benchmark.extra_info.update(items=1, candidates=len(CAMERA_CANDIDATES),
                                goal={"max_s": 30.0})
    rep = benchmark.pedantic(diagnose, args=(frame, CAMERA_CANDIDATES), rounds=2,
                             iterations=1)
    assert rep.verdict.effect == "polarizer_angles"
