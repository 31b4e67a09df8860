"""A moonlit sky map of 10,000 directions (one time), against the sunlit Rayleigh map of the
same directions timed in the same run (the baseline: the polarization pattern alone).

Goal (reported by ``tests/benchmarks/ratios.py``, never asserted as a timing): the whole
night sky (the Moon's position from astropy, ROLO irradiance, the Sun's position, K&S
radiance, Rayleigh Stokes, background) of 10k directions in under 0.5 s a map. Each
benchmark checks its result (DoP in [0, 1), AoP equal to the Rayleigh pattern about the
Moon), so a fast wrong answer fails.
"""

import numpy as np
import pytest

pytest.importorskip("astropy", reason="the Moon's position needs astropy (extra 'moon')")

from skysim.moon import moon_position  # noqa: E402
from skysim.night import night_sky  # noqa: E402
from skysim.rayleigh import polarization_field  # noqa: E402
from skysim.sun import Site  # noqa: E402

SITE = Site(-24.6272, -70.4042, 2635.0)
TIME = "2021-01-27T05:00:00Z"
N = 10_000
_rng = np.random.default_rng(3)
EL = np.degrees(np.arcsin(_rng.uniform(0.0, 1.0, N)))  # uniform over the upper hemisphere
AZ = _rng.uniform(0.0, 360.0, N)
MOON = moon_position(TIME, SITE.latitude_deg, SITE.longitude_deg, SITE.altitude_m).iloc[0]


@pytest.mark.benchmark(group="moonlit_sky_10k")
def test_bench_rayleigh_pattern_10k(benchmark):
    benchmark.extra_info.update(baseline=True, items=N)
    f = benchmark(polarization_field, EL, AZ, MOON.elevation_deg, MOON.azimuth_deg)
    assert np.all((f["dop"] >= 0) & (f["dop"] < 1))


@pytest.mark.benchmark(group="moonlit_sky_10k")
def test_bench_night_sky_10k(benchmark):
    benchmark.extra_info.update(items=N, goal={"max_s": 0.5})
    ns = benchmark(night_sky, EL, AZ, TIME, SITE, "V")
    assert np.all((ns.field.dop >= 0) & (ns.field.dop < 1))
    ref = polarization_field(EL, AZ, MOON.elevation_deg, MOON.azimuth_deg)["aop_deg"]
    diff = (ns.field.aop_deg - ref + 90.0) % 180.0 - 90.0
    assert np.max(np.abs(diff)) < 1e-6
