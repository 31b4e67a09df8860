"""Ground-truth generation at memory speed (run with `make bench`; disabled in `make test`).

Goals, printed as met or not by ratios.py from ``extra_info["goal"]`` (never asserted as
timings), all against baselines and floors measured in the same run:

- full-sky single-scattering field (I, Q, U, DoP, AoP) on 99,856 directions: >= 1.5x a
  textbook numpy float64 formula, the float32 path >= 3x, and within 8x of one bare
  ``np.cos`` pass over the grid; the peer package skylight timed where it imports
  (pyskylumos needs Python >= 3.12 and is not timed here);
- a series of 1,000 suns x 10,000 directions streamed in blocks at the per-value speed of one
  full-sky map (>= 0.8x);
- heading solve for the three pairs >= 1e7 samples/s and within 4x of three ``arctan2``
  passes over the same arrays;
- ``skysim --help``, ``skysim sky --help`` and a whole ``skysim sky ... --out x.parquet`` run
  <= 0.3 s of imports (python -X importtime).
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.solve import PAIRS, solve_pairs
from sensor.opponent import channel_outputs
from skysim.series import iter_sky_series
from skysim.sky import RayleighSky

from importtime import command_import_s  # tests/benchmarks/importtime.py
from written_out import pair_by_cramer    # tests/written_out.py

N_SIDE = 316                      # 316^2 = 99,856 directions
_E, _A = np.meshgrid(np.linspace(0.0, 90.0, N_SIDE),
                     np.linspace(0.0, 360.0, N_SIDE, endpoint=False), indexing="ij")
EL, AZ = _E.ravel(), _A.ravel()
SUN_EL, SUN_AZ, DMAX = 30.0, 275.0, 0.7


def textbook_field(el, az, sun_el, sun_az, dmax, dtype=np.float64):
    """The formulas as printed, each trigonometric term computed once: cos g by the spherical
    law of cosines, g by arccos, DoP (Yang et al. 2014 eq. 1) and I from g, the AoP from
    tan chi = (cos h sin h_s - sin h cos h_s cos dA) / (cos h_s sin dA), Q and U from 2 chi."""
    h, a = np.radians(el.astype(dtype)), np.radians(az.astype(dtype))
    hs, as_ = np.radians(dtype(sun_el)), np.radians(dtype(sun_az))
    sin_h, cos_h, sin_hs, cos_hs = np.sin(h), np.cos(h), np.sin(hs), np.cos(hs)
    cos_da, sin_da = np.cos(a - as_), np.sin(a - as_)
    g = np.arccos(np.clip(sin_h * sin_hs + cos_h * cos_hs * cos_da, -1.0, 1.0))
    cos2_g = np.cos(g) ** 2
    dop = dmax * np.sin(g) ** 2 / (1.0 + cos2_g)
    intensity = 0.75 * (1.0 + cos2_g)
    with np.errstate(divide="ignore", invalid="ignore"):
        chi = np.arctan((cos_h * sin_hs - sin_h * cos_hs * cos_da) / (cos_hs * sin_da))
    q, u = intensity * dop * np.cos(2 * chi), intensity * dop * np.sin(2 * chi)
    return intensity, q, u, dop, np.degrees(chi)


def _skysim_field(sky):
    f = sky.field(EL, AZ, SUN_EL, SUN_AZ)
    return f.I, f.Q, f.U, f.dop, f.aop_deg


@pytest.mark.benchmark(group="sky field 99,856 directions")
def test_sky_field_textbook_float64_baseline(benchmark):
    benchmark.extra_info.update(items=EL.size, baseline=True)
    i, q, u, dop, _ = benchmark(textbook_field, EL, AZ, SUN_EL, SUN_AZ, DMAX)
    ours = _skysim_field(RayleighSky(DMAX))          # the same field, so the race is fair
    for mine, theirs in zip(ours, (i, q, u, dop)):
        np.testing.assert_allclose(mine, theirs, atol=1e-12)


@pytest.mark.benchmark(group="sky field 99,856 directions")
def test_sky_field_textbook_float32(benchmark):
    benchmark.extra_info.update(items=EL.size)
    benchmark(textbook_field, EL, AZ, SUN_EL, SUN_AZ, DMAX, np.float32)


@pytest.mark.benchmark(group="sky field 99,856 directions")
def test_sky_field_skysim_float64(benchmark):
    benchmark.extra_info.update(items=EL.size, goal={"min_speedup": 1.5, "max_floor_ratio": 8})
    benchmark(_skysim_field, RayleighSky(DMAX))


@pytest.mark.benchmark(group="sky field 99,856 directions")
def test_sky_field_skysim_float32(benchmark):
    benchmark.extra_info.update(items=EL.size, goal={"min_speedup": 3.0})
    benchmark(_skysim_field, RayleighSky(DMAX, dtype="float32"))


@pytest.mark.benchmark(group="sky field 99,856 directions")
def test_sky_field_cos_floor(benchmark):
    """Floor: one bare np.cos pass over the grid's elevations."""
    benchmark.extra_info.update(items=EL.size, floor=True)
    benchmark(np.cos, EL)


@pytest.mark.benchmark(group="sky field 99,856 directions")
def test_sky_field_skylight_peer(benchmark):
    """The peer package skylight (Gkanias), its analytical (Wilkie/Preetham) sky on the same
    grid and sun; timed where it imports (it is not a dependency: it pulls in numba)."""
    pytest.importorskip("skylight", reason="peer package skylight not installed")
    import skylight.geometry as geo
    from skylight import AnalyticalSky

    ori = geo.sph2ori(np.radians(EL), np.radians(AZ))
    sky = AnalyticalSky(np.radians(SUN_EL), np.radians(SUN_AZ))
    one = np.array([540.0])                      # one wavelength [nm], as the others
    sky(ori, wavelengths=one)  # its first call compiles (numba)
    benchmark.extra_info.update(items=EL.size)
    info = benchmark(sky, ori, wavelengths=one)
    assert np.shape(info.degree_of_polarisation)[-1] == EL.size


N_SUNS, N_DIRS = 1_000, 10_000
_RNG = np.random.default_rng(5)
SERIES_EL = np.degrees(np.arcsin(_RNG.uniform(0.0, 1.0, N_DIRS)))
SERIES_AZ = _RNG.uniform(0.0, 360.0, N_DIRS)
SERIES_SUN_EL = np.linspace(5.0, 60.0, N_SUNS)
SERIES_SUN_AZ = np.linspace(90.0, 270.0, N_SUNS)


@pytest.mark.benchmark(group="sky series")
def test_sky_series_one_map_baseline(benchmark):
    """Per-value reference: one full-sky map (one sun, 99,856 directions)."""
    benchmark.extra_info.update(items=EL.size, baseline=True)
    benchmark(_skysim_field, RayleighSky(DMAX))


@pytest.mark.benchmark(group="sky series")
def test_sky_series_1000_suns_10000_directions(benchmark):
    """1e7 values streamed in blocks of a 64 MiB budget (each block's five arrays touched)."""
    sky = RayleighSky(DMAX)

    def stream():
        total = 0.0
        for _, f in iter_sky_series(sky, SERIES_EL, SERIES_AZ, SERIES_SUN_EL, SERIES_SUN_AZ,
                                    max_block_bytes=64 * 2**20):
            total += float(f.dop[0, 0] + f.aop_deg[0, 0] + f.I[0, 0] + f.Q[0, 0] + f.U[0, 0])
        return total

    benchmark.extra_info.update(items=N_SUNS * N_DIRS, goal={"min_speedup": 0.8})
    benchmark.pedantic(stream, rounds=5, iterations=1)


@pytest.mark.benchmark(group="sky series written to netCDF")
def test_sky_series_write_netcdf_200_suns(benchmark, tmp_path):
    """200 suns x 10,000 directions written block by block to netCDF (5 x 16 MB)."""
    pytest.importorskip("h5netcdf", reason="h5netcdf (extra skysim[series]) not installed")
    from experiments.workflows.sky_series import write_sky_series
    sky = RayleighSky(DMAX)
    benchmark.extra_info.update(items=200 * N_DIRS)
    benchmark.pedantic(write_sky_series, args=(tmp_path / "s.nc", sky, SERIES_EL, SERIES_AZ,
                                               SERIES_SUN_EL[:200], SERIES_SUN_AZ[:200]),
                       rounds=3, iterations=1)


N_SAMPLES = 1_000_000
_U = channel_outputs(np.random.default_rng(1).uniform(-90, 90, N_SAMPLES), 0.5)


def textbook_three_pairs(U):
    """Eqs. (5)-(9) of Yang et al. 2014 written out, pair after pair."""
    return [pair_by_cramer(U, pair) for pair in PAIRS]


@pytest.mark.benchmark(group="heading solve three pairs")
def test_heading_three_pairs_textbook_baseline(benchmark):
    benchmark.extra_info.update(items=N_SAMPLES, baseline=True)
    ref = benchmark.pedantic(textbook_three_pairs, args=(_U,), rounds=5, iterations=1)
    phi, dop = solve_pairs(_U)
    for k, (p_ref, d_ref) in enumerate(ref):
        np.testing.assert_allclose(phi[:, k], p_ref, atol=1e-9)
        np.testing.assert_allclose(dop[:, k], d_ref, atol=1e-12)


@pytest.mark.benchmark(group="heading solve three pairs")
def test_heading_solve_pairs_1e6(benchmark):
    benchmark.extra_info.update(items=N_SAMPLES,
                                goal={"min_items_per_s": 1e7, "max_floor_ratio": 4})
    phi, _ = benchmark.pedantic(solve_pairs, args=(_U,), rounds=7, iterations=1)
    assert phi.shape == (N_SAMPLES, 3)


@pytest.mark.benchmark(group="heading solve three pairs")
def test_heading_arctan2_floor(benchmark):
    """Floor: three bare arctan2 passes over two contiguous channel arrays."""
    y, x = np.ascontiguousarray(_U[:, 0]), np.ascontiguousarray(_U[:, 1])
    benchmark.extra_info.update(items=N_SAMPLES, floor=True)
    benchmark.pedantic(lambda: [np.arctan2(y, x) for _ in range(3)], rounds=7, iterations=1)


@pytest.mark.benchmark(group="start-up imports")
@pytest.mark.parametrize("argv", [["--help"], ["sky", "--help"]], ids=["help", "sky-help"])
def test_startup_imports(benchmark, argv):
    """Wall time of the whole process; the goal is on its import time (extra_info)."""
    total, times = benchmark.pedantic(command_import_s, args=(argv,), rounds=3, iterations=1)
    benchmark.extra_info.update(import_s=total, goal={"max_import_s": 0.3},
                                slowest={k: round(v, 4) for k, v in sorted(
                                    times.items(), key=lambda kv: -kv[1])[:5]})
    assert "scipy" not in times and "pandas" not in times


@pytest.mark.benchmark(group="start-up imports")
def test_startup_imports_sky_run(benchmark, tmp_path):
    """A whole `skysim sky ... --out x.parquet` run (numpy, pyarrow; no pandas, no scipy)."""
    argv = ["sky", "--sun-elevation", "30", "--sun-azimuth", "275", "--out",
            str(tmp_path / "sky.parquet")]
    total, times = benchmark.pedantic(command_import_s, args=(argv,), rounds=3, iterations=1)
    benchmark.extra_info.update(import_s=total, goal={"max_import_s": 0.3},
                                slowest={k: round(v, 4) for k, v in sorted(
                                    times.items(), key=lambda kv: -kv[1])[:5]})
    assert "scipy" not in times and "pandas" not in times
