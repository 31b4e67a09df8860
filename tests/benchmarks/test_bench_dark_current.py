"""Benchmarks of issue 4: the photodiode channel model over 1e6 samples and one
dark-current calibration (run with `make bench`; no timing assertions)."""

import numpy as np
import pytest

from calibration.dark_current import calibrate_dark_current
from sensor.opponent import channel_outputs
from sensor.photodiode import PhotodiodeChannels


@pytest.mark.benchmark(group="photodiode channel model")
def test_channel_model_2014_equation_baseline(benchmark):
    """Baseline: the foundation's three-pair equation on the same 1e6 samples."""
    rng = np.random.default_rng(0)
    phi, d = rng.uniform(-90, 90, 1_000_000), rng.uniform(0.1, 0.9, 1_000_000)
    benchmark.extra_info.update(items=phi.size, baseline=True)
    benchmark.pedantic(channel_outputs, args=(phi, d), rounds=3, iterations=1)


@pytest.mark.benchmark(group="photodiode channel model")
def test_channel_model_1e6(benchmark):
    rng = np.random.default_rng(0)
    phi, d = rng.uniform(-90, 90, 1_000_000), rng.uniform(0.1, 0.9, 1_000_000)
    I = 10.0 ** rng.uniform(0, 4, 1_000_000)
    p = PhotodiodeChannels.draw(rng)
    benchmark.extra_info["items"] = phi.size
    u = benchmark.pedantic(p.outputs, args=(I, phi, d), rounds=3, iterations=1)
    assert u.shape == (1_000_000, 3)


@pytest.mark.benchmark(group="dark-current calibration")
def test_one_calibration(benchmark):
    """One calibration: 7 levels x 36 angles x 2 DoPs = 504 samples, 24 parameters."""
    rng = np.random.default_rng(1)
    p = PhotodiodeChannels.draw(rng)
    grid = np.meshgrid([1.0, 2, 5, 10, 30, 100, 1000], np.linspace(-90, 90, 36, endpoint=False),
                       [0.3, 0.7], indexing="ij")
    I, phi, d = (a.ravel() for a in grid)
    U, _ = p.sample(I, phi, d, rng)
    benchmark.extra_info["items"] = I.size
    benchmark.extra_info["baseline"] = "none in the same run (first dark-current calibration)"
    cal = benchmark.pedantic(calibrate_dark_current, args=(U, I, phi, d), rounds=3,
                             iterations=1)
    assert cal.n_levels == 7


def _outputs_1e5():
    from calibration.dark_current import ChannelModel
    rng = np.random.default_rng(2)
    p = PhotodiodeChannels.draw(rng)
    n = 100_000
    I = 10.0 ** rng.uniform(0, 4, n)
    U, _ = p.sample(I, rng.uniform(-90, 90, n), 0.6, rng)
    return U, ChannelModel.from_photodiodes(p)


@pytest.mark.benchmark(group="dark-current solve")
def test_solve_opponent_1e5_baseline(benchmark):
    """Baseline: the patent's x = A^-1 b on 1e5 samples."""
    from calibration.dark_current import solve_opponent
    U, model = _outputs_1e5()
    benchmark.extra_info.update(items=U.shape[0], baseline=True)
    benchmark.pedantic(solve_opponent, args=(U, model), rounds=3, iterations=1)


@pytest.mark.benchmark(group="dark-current solve")
def test_solve_combined_1e5(benchmark):
    """The combined solve on the same 1e5 samples (baseline: x = A^-1 b above)."""
    from calibration.dark_current import solve_combined
    U, model = _outputs_1e5()
    benchmark.extra_info.update(items=U.shape[0], baseline="test_solve_opponent_1e5_baseline")
    sol = benchmark.pedantic(solve_combined, args=(U, model, 4e-4), rounds=3, iterations=1)
    assert sol.phi_deg.shape == (U.shape[0],)
