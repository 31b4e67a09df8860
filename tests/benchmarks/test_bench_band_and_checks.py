"""Band-integrated skies and the model-free ring checks (run with `make bench`; disabled in
`make test`). Reported, never asserted as timings.

- Band sky: eight wavelength nodes (product integration in the wavenumber) against the
  baseline of a 1-nm sum over the B band (about 270 monochromatic skies), same directions;
  goal: 20 times faster (the two agree to 2e-5, tests/test_spectral.py).
- Ring checks on a session of the reference instrument's size (5,000 samples x 8 units x 4
  photodiodes): gains, sum rule by sun distance, side and motion, with sweep jackknives;
  goal: under 2 s, so that every ring diagnosis can carry them.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from test_instrument_checks import _session  # noqa: E402
from test_spectral import AZ, EL, SUN, ThinRayleighSlab  # noqa: E402

from calibration.photodiode_diagnosis.checks import check_instrument  # noqa: E402
from skysim.spectral import band_sky, blackbody_spectrum, get_response  # noqa: E402


def _fine_band(response, step_nm=1.0):
    from scipy.integrate import trapezoid
    lam = np.arange(response.wavelength_nm[0], response.wavelength_nm[-1], step_nm)
    w = np.interp(lam, response.wavelength_nm, response.response) * blackbody_spectrum(lam)
    s = np.array([[getattr(f, k) for k in "IQU"] for f in (
        ThinRayleighSlab(x).field(EL, AZ, *SUN) for x in lam)])
    return trapezoid(w[:, None, None, None] * s, lam, axis=0) / trapezoid(w, lam)


@pytest.mark.benchmark(group="band sky (B band, 432 directions)")
def test_band_fine_sum_baseline(benchmark):
    benchmark.extra_info.update(baseline=True)
    benchmark.pedantic(_fine_band, args=(get_response("B"),), rounds=3, iterations=1)


@pytest.mark.benchmark(group="band sky (B band, 432 directions)")
def test_band_sky_eight_nodes(benchmark):
    benchmark.extra_info["goal"] = {"min_speedup": 20.0}
    f = benchmark.pedantic(lambda: band_sky(ThinRayleighSlab, "B").field(EL, AZ, *SUN),
                           rounds=5, iterations=1)
    assert f.I.shape == EL.shape


@pytest.fixture(scope="module")
def big_ring():
    return _session(n_sweeps=38)      # 38 x 130 = 4,940 samples, the reference sessions' size


@pytest.mark.benchmark(group="ring checks (5,000 samples x 32 photodiodes)")
def test_ring_checks(benchmark, big_ring):
    inst, sun = big_ring
    benchmark.extra_info["goal"] = {"max_s": 2.0}
    checks = benchmark.pedantic(check_instrument, args=(inst, 0.0, sun), rounds=3,
                                iterations=1)
    assert checks.units_failing_in_motion == []
