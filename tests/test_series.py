"""Time series of sky maps: blocks within a memory budget, chunked writers, the command."""

import json
import subprocess
import sys
import tracemalloc

import numpy as np
import pandas as pd
import pytest

from experiments.cli.main import main
from experiments.workflows.sky_series import SERIES_SCHEMA, write_sky_series
from skysim.exceptions import InvalidParameterError, SunBelowHorizonError
from skysim.series import VALUES_PER_POINT, iter_sky_series, suns_per_block
from skysim.sky import RayleighSky

RNG = np.random.default_rng(8)
EL, AZ = RNG.uniform(0, 90, 2_000), RNG.uniform(0, 360, 2_000)
SUN_EL, SUN_AZ = np.linspace(5, 60, 150), np.linspace(80, 280, 150)


def test_blocks_cover_the_series_and_equal_one_call():
    sky = RayleighSky(0.7)
    budget = 40 * VALUES_PER_POINT * 8 * EL.size       # 40 suns per block
    blocks = list(iter_sky_series(sky, EL, AZ, SUN_EL, SUN_AZ, max_block_bytes=budget))
    assert [b.stop - b.start for b, _ in blocks] == [40, 40, 40, 30]
    whole = sky.field(EL[None, :], AZ[None, :], SUN_EL[:, None], SUN_AZ[:, None])
    for name in ("I", "Q", "U", "dop", "aop_deg"):
        got = np.concatenate([getattr(f, name) for _, f in blocks])
        np.testing.assert_array_equal(got, getattr(whole, name))


def test_peak_memory_of_a_block_within_the_budget():
    """The budget bounds the numpy memory alive while a block is evaluated (tracemalloc sees
    numpy's allocations): VALUES_PER_POINT covers the model's outputs and temporaries."""
    sky = RayleighSky(0.7)
    budget = 4 * 2**20
    tracemalloc.start()
    try:
        for _, f in iter_sky_series(sky, EL, AZ, SUN_EL, SUN_AZ, max_block_bytes=budget):
            f.dop, f.aop_deg
            del f
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak <= budget
    assert suns_per_block(EL.size, budget) * 5 * 8 * EL.size > budget / 4  # not trivially small


def test_series_input_errors():
    sky = RayleighSky()
    with pytest.raises(InvalidParameterError, match="below one sun"):
        next(iter_sky_series(sky, EL, AZ, SUN_EL, SUN_AZ, max_block_bytes=1000))
    with pytest.raises(InvalidParameterError, match="differ in length"):
        next(iter_sky_series(sky, EL, AZ[:-1], SUN_EL, SUN_AZ))
    with pytest.raises(InvalidParameterError, match="one-dimensional"):
        next(iter_sky_series(sky, EL.reshape(2, -1), AZ.reshape(2, -1), SUN_EL, SUN_AZ))
    with pytest.raises(SunBelowHorizonError):
        next(iter_sky_series(sky, EL, AZ, [10.0, -11.0], [0.0, 0.0]))   # below twilight


def test_parquet_series_round_trip(tmp_path):
    times = pd.date_range("2013-05-22T08:00+08:00", periods=SUN_EL.size, freq="1min")
    sky = RayleighSky(0.7, dtype="float32")
    info = write_sky_series(tmp_path / "s.parquet", sky, EL, AZ, SUN_EL, SUN_AZ, times=times,
                            max_block_bytes=8 * 2**20)
    assert info["n_blocks"] > 1
    table = pd.read_parquet(tmp_path / "s.parquet")
    assert len(table) == SUN_EL.size * EL.size and table.dop.dtype == np.float32
    row = table.iloc[3 * EL.size + 5]                   # time step 3, direction 5
    assert row.time == times[3] and row.elevation_deg == EL[5]
    ref = sky.field(EL[5], AZ[5], SUN_EL[3], SUN_AZ[3])
    assert abs(row.dop - ref.dop) < 1e-6 and abs(row.aop_deg - ref.aop_deg) < 1e-4  # float32
    side = json.loads((tmp_path / "s.parquet.json").read_text())   # named after the file
    assert side["schema"] == SERIES_SCHEMA and side["sky"]["dtype"] == "float32"


def test_netcdf_series_opens_as_xarray_dataset(tmp_path):
    pytest.importorskip("h5netcdf", reason="h5netcdf (extra skysim[series]) not installed")
    xr = pytest.importorskip("xarray", reason="xarray not installed")
    times = pd.date_range("2013-05-22T00:00Z", periods=SUN_EL.size, freq="10s")
    sky = RayleighSky(0.7)
    write_sky_series(tmp_path / "s.nc", sky, EL, AZ, SUN_EL, SUN_AZ, times=times,
                     max_block_bytes=8 * 2**20)
    with xr.open_dataset(tmp_path / "s.nc", engine="h5netcdf") as ds:
        assert dict(ds.sizes) == {"time": SUN_EL.size, "direction": EL.size}
        assert ds.time.values[7] == times[7].tz_convert(None).to_datetime64()
        whole = sky.field(EL[None, :], AZ[None, :], SUN_EL[:, None], SUN_AZ[:, None])
        np.testing.assert_array_equal(ds.aop_deg.values, whole.aop_deg)
        np.testing.assert_array_equal(ds.I.values, whole.I)
        assert ds.attrs["schema"] == SERIES_SCHEMA and ds.dop.attrs["units"] == "1"


def test_failed_series_leaves_no_file(tmp_path):
    with pytest.raises(SunBelowHorizonError):
        write_sky_series(tmp_path / "s.parquet", RayleighSky(), EL, AZ, [20.0, 10.0, -12.0],
                         [0.0, 0.0, 0.0], max_block_bytes=VALUES_PER_POINT * 8 * EL.size)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match=".nc or .parquet"):
        write_sky_series(tmp_path / "s.csv", RayleighSky(), EL, AZ, SUN_EL, SUN_AZ)


def test_sky_series_command(tmp_path, capsys):
    out = tmp_path / "day.parquet"
    rc = main(["sky-series", "--lat", "34.14", "--lon", "108.55", "--start",
               "2013-05-22T04:00+08:00", "--end", "2013-05-22T07:00+08:00", "--freq", "30min",
               "--daylight-only", "--grid-step", "10", "--float32", "--out", str(out)])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "have the sun down; left out" in printed and "wrote" in printed
    table = pd.read_parquet(out)
    assert table.sun_elevation_deg.min() > 0 and table.dop.dtype == np.float32
    assert main(["sky-series", "--lat", "34.14", "--lon", "108.55", "--start",
                 "2013-05-22T04:00+08:00", "--periods", "3", "--freq", "1h",
                 "--out", str(tmp_path / "night.parquet")]) == 2
    assert "sun elevation must be above -10 deg" in capsys.readouterr().err   # -18 deg at 04:00
    assert not (tmp_path / "night.parquet").exists()


def _imported_by(code: str) -> set[str]:
    proc = subprocess.run([sys.executable, "-c", code + "\nimport sys\nprint(' '.join("
                           "sorted(sys.modules)))"], capture_output=True, text=True, check=True)
    return set(proc.stdout.split())


@pytest.mark.parametrize("argv", [["--help"], ["sky", "--help"], ["sample", "--help"]])
def test_command_line_start_up_imports_no_heavy_module(argv):
    """Start-up stays light (the speed itself is a benchmark): the parser and a command's help
    import neither pandas nor scipy, nor the sky models."""
    mods = _imported_by("from experiments.cli.main import main\ntry:\n"
                        f"    main({argv!r})\nexcept SystemExit:\n    pass")
    assert not {"pandas", "scipy", "scipy.signal", "calibration", "skysim.sun"} & mods


def test_packages_import_lazily_and_resolve_every_public_name():
    mods = _imported_by("import skysim, sensor, calibration")
    assert "pandas" not in mods and "scipy" not in mods
    import calibration
    import sensor
    import skysim
    for package in (skysim, sensor, calibration):
        for name in package.__all__:
            assert getattr(package, name) is not None
        assert set(package.__all__) <= set(dir(package))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        skysim.nope


def test_sky_parquet_run_imports_no_pandas(tmp_path):
    """`skysim sky` with given sun angles writes Parquet through pyarrow alone; the table
    reads back as before."""
    out = tmp_path / "sky.parquet"
    mods = _imported_by("from experiments.cli.main import main\n"
                        f"main(['sky', '--sun-elevation', '30', '--sun-azimuth', '275', "
                        f"'--grid-step', '10', '--out', {str(out)!r}])")
    assert "pandas" not in mods and "scipy" not in mods
    table = pd.read_parquet(out)
    assert list(table.columns) == ["elevation_deg", "azimuth_deg", "dop", "aop_deg", "I", "Q",
                                   "U"]
    ref = RayleighSky(1.0).field(table.elevation_deg.to_numpy(), table.azimuth_deg.to_numpy(),
                                 30.0, 275.0)
    np.testing.assert_array_equal(table.dop.to_numpy(), ref.dop)
