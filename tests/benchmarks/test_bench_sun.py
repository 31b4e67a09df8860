"""Sun position for every time pattern, against pvlib's numpy NREL SPA timed in the same run.

Goals (reported by ``tests/benchmarks/ratios.py`` as speed-ups against each group's pvlib
baseline, never asserted as timings): 1,000 random instants over a year no slower than pvlib
(>= 1x); 10,000 random instants >= 2x; a year at 1 min >= 10x; a day at 0.1 s >= 10x; 2,000
instants with a site each >= 2x faster than calling pvlib once per site. Every benchmark
checks its result against pvlib (0.01 deg in elevation), so a fast wrong answer fails.
"""

import numpy as np
import pandas as pd
import pytest

from skysim.sun import sun_position

pvlib = pytest.importorskip("pvlib", reason="pvlib's SPA is the baseline (test extra)")

LAT, LON, ALT = 34.1447, 108.5467, 400.0


def _random_instants(n: int, seed: int = 0) -> pd.DatetimeIndex:
    rng = np.random.default_rng(seed)
    seconds = rng.uniform(0, 365 * 86400, n)  # unsorted, as a sampler draws them
    return pd.DatetimeIndex(pd.Timestamp("2024-01-01T00:00Z") + pd.to_timedelta(seconds, "s"))


PATTERNS = {
    "1k_random": (_random_instants(1_000), 20),
    "10k_random": (_random_instants(10_000, 1), 10),
    "year_1min": (pd.date_range("2024-01-01T00:00Z", periods=525_600, freq="1min"), 3),
    "day_100ms": (pd.date_range("2024-06-21T00:00Z", periods=864_000, freq="100ms"), 3),
}


def _pvlib(times, lat=LAT, lon=LON, alt=ALT):
    return pvlib.solarposition.spa_python(times, lat, lon, altitude=alt, how="numpy")


def _check(ours, times):
    sub = slice(None, None, max(1, len(times) // 2000))
    ref = _pvlib(times[sub])
    assert len(ours) == len(times)
    assert np.abs(ours.elevation_deg.to_numpy()[sub] - ref.elevation.to_numpy()).max() <= 0.01


@pytest.mark.parametrize("pattern", list(PATTERNS))
def test_sun_pvlib_spa_baseline(benchmark, pattern):
    times, rounds = PATTERNS[pattern]
    benchmark.group = f"sun position: {pattern}"
    benchmark.extra_info.update(items=len(times), baseline=True)
    out = benchmark.pedantic(_pvlib, args=(times,), rounds=max(2, rounds // 3), iterations=1,
                             warmup_rounds=1 if len(times) < 100_000 else 0)
    assert len(out) == len(times)


@pytest.mark.parametrize("pattern", list(PATTERNS))
def test_sun_skysim(benchmark, pattern):
    times, rounds = PATTERNS[pattern]
    benchmark.group = f"sun position: {pattern}"
    benchmark.extra_info["items"] = len(times)
    out = benchmark.pedantic(sun_position, args=(times, LAT, LON, ALT), rounds=rounds,
                             iterations=1, warmup_rounds=1)
    _check(out, times)


def _sites(n=2_000, seed=2):
    rng = np.random.default_rng(seed)
    return (_random_instants(n, seed), rng.uniform(-60, 60, n), rng.uniform(-180, 180, n),
            rng.uniform(0, 3000, n))


@pytest.mark.benchmark(group="sun position: 2k instants, a site each")
def test_sun_site_per_instant_pvlib_per_site_baseline(benchmark):
    """Baseline: pvlib called once per (site, instant), what a sampler over sites needs."""
    times, lat, lon, alt = _sites()
    benchmark.extra_info.update(items=len(times), baseline=True)
    out = benchmark.pedantic(
        lambda: [_pvlib(times[k:k + 1], lat[k], lon[k], alt[k]) for k in range(len(times))],
        rounds=2, iterations=1)
    assert len(out) == len(times)


@pytest.mark.benchmark(group="sun position: 2k instants, a site each")
def test_sun_site_per_instant_skysim(benchmark):
    times, lat, lon, alt = _sites()
    benchmark.extra_info["items"] = len(times)
    out = benchmark.pedantic(sun_position, args=(times, lat, lon, alt), rounds=10,
                             iterations=1, warmup_rounds=1)
    ref = [_pvlib(times[k:k + 1], lat[k], lon[k], alt[k]).elevation.iloc[0]
           for k in range(0, len(times), 50)]
    assert np.abs(out.elevation_deg.to_numpy()[::50] - ref).max() <= 0.01
