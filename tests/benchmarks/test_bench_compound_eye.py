"""Compound-eye benchmarks (run with `make bench`; disabled in `make test`).

Goals from the issue, reported (never asserted as timings): sampling 1e5 attitudes x 9 units
(sky along every unit's actual direction, photodiodes, table) and one full calibration.
Baselines measured in the same run: the sky sampled one attitude at a time.
"""

import numpy as np
import pandas as pd
import pytest

from calibration.installation import calibrate_installation
from sensor.compound_eye import (body_attitude, patent_configuration,
                                 with_random_installation_errors)
from skysim.sky import RayleighSky
from skysim.sun import Site, sun_vector

SITE = Site(39.98, 116.35, 50.0)
SKY = RayleighSky(0.7)


def _carrier(n, rng):
    times = pd.date_range("2020-06-15T14:30+08:00", "2020-06-15T18:30+08:00", periods=n)
    return times, rng.uniform(0, 360, n), rng.uniform(-10, 10, n), rng.uniform(-10, 10, n)


def _attitudes_and_sun(n, seed=1):
    times, yaw, pitch, roll = _carrier(n, np.random.default_rng(seed))
    return body_attitude(yaw, pitch, roll), sun_vector(times, SITE)[0]


@pytest.fixture(scope="module")
def sensor():
    return with_random_installation_errors(patent_configuration(), 1.0, np.random.default_rng(0))


@pytest.mark.benchmark(group="compound-eye sampling")
def test_observe_per_attitude_baseline(benchmark, sensor):
    """Baseline: observe() called for one attitude at a time (1,000 attitudes x 9 units)."""
    att, sun = _attitudes_and_sun(1000)
    benchmark.extra_info.update(items=1000 * 9, baseline=True)
    benchmark.pedantic(lambda: [sensor.observe(SKY, att[k:k + 1], sun[k:k + 1])
                                for k in range(1000)], rounds=2, iterations=1)


@pytest.mark.benchmark(group="compound-eye sampling")
def test_observe_1e5_attitudes(benchmark, sensor):
    att, sun = _attitudes_and_sun(100_000)
    benchmark.extra_info["items"] = 100_000 * 9
    obs = benchmark.pedantic(sensor.observe, args=(SKY, att, sun), rounds=3, iterations=1)
    assert obs.dop.shape == (100_000, 9)


@pytest.mark.benchmark(group="compound-eye sampling")
def test_sample_table_1e5_attitudes(benchmark, sensor):
    """The full simulator: sun positions, sky, photodiodes, reference attitude, table."""
    rng = np.random.default_rng(2)
    carrier = _carrier(100_000, rng)
    benchmark.extra_info["items"] = 100_000 * 9
    data = benchmark.pedantic(
        lambda: sensor.sample(SKY, SITE, *carrier, rng, attitude_noise_deg=0.1,
                              accel_noise_mps2=0.01), rounds=3, iterations=1)
    assert len(data.table) == 100_000


@pytest.mark.benchmark(group="compound-eye calibration")
def test_full_calibration_1000_attitudes(benchmark, sensor):
    """Steps 1-3 (photodiodes -> E-vectors -> phi_1 -> phi_2..9) on 1,000 attitudes."""
    rng = np.random.default_rng(3)
    data = sensor.sample(SKY, SITE, *_carrier(1000, rng), rng, attitude_noise_deg=0.1,
                         accel_noise_mps2=0.01)
    benchmark.extra_info["items"] = 1000
    cal = benchmark(calibrate_installation, data)
    assert np.all(np.abs(cal.body.rotvec_deg - sensor.installation_error_deg) < 0.05)
