"""The on-disk cache of aerosol component optics (skysim.aerosol_types over
skysim.disk_cache): a later process reads back exactly what sasktran2's Mie integration gave,
without integrating; bad entries are recomputed; an unwritable cache folder changes nothing
but speed.

The reference for every value is a direct call of the integration (``_integrate_component``):
deterministic, so equality is bitwise (``np.array_equal`` on float64, ``==`` on floats), no
tolerance. WASO and SOOT with 16 moments keep each integration near 0.1 s.
"""

import io
import os

import numpy as np
import pytest

pytest.importorskip("sasktran2", reason="sasktran2 (extra skysim[rt]) not installed")

import sasktran2.mie.distribution as mie_distribution

from skysim import aerosol_types
from skysim.aerosol_types import COMPONENTS, MIE_CACHE_KIND, _component_optics
from skysim.disk_cache import CACHE_DIR_ENV

N_MOM, LAM = 16, 550.0


@pytest.fixture
def cache_dir(empty_cache_dir):
    """An empty cache folder of this test; the in-process cache emptied before and after."""
    _component_optics.cache_clear()
    yield empty_cache_dir
    _component_optics.cache_clear()


def _entries(cache_dir):
    return sorted((cache_dir / MIE_CACHE_KIND).glob("*.npz"))


def _forbid_integration(monkeypatch):
    def _fail(*_a, **_k):
        raise AssertionError("integrate_mie_cpp called although the entry is on disk")
    monkeypatch.setattr(mie_distribution, "integrate_mie_cpp", _fail)


def _assert_identical(got, want):
    assert got[0] == want[0] and got[1] == want[1]
    assert got[2].dtype == want[2].dtype == np.float64
    assert np.array_equal(got[2], want[2])


def test_fresh_process_reads_disk_entry_bitwise_without_integrating(cache_dir, monkeypatch):
    comp = COMPONENTS["WASO"]
    wasoish = aerosol_types.AerosolType("w", ((comp, 1.0),), 8.0)
    first = _component_optics(comp, LAM, N_MOM)
    mix_first = aerosol_types.aerosol_optics(wasoish, LAM, N_MOM)
    assert len(_entries(cache_dir)) == 1
    _assert_identical(first, aerosol_types._integrate_component(comp, LAM, N_MOM))
    _component_optics.cache_clear()                # a new process: only the disk remains
    _forbid_integration(monkeypatch)
    _assert_identical(_component_optics(comp, LAM, N_MOM), first)
    _component_optics.cache_clear()                # the mixture from disk is the same too
    mix = aerosol_types.aerosol_optics(wasoish, LAM, N_MOM)
    assert mix.extinction == mix_first.extinction and mix.ssa == mix_first.ssa
    assert np.array_equal(mix.greek, mix_first.greek)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty", "wrong_shape", "nan"])
def test_corrupt_entry_is_recomputed_and_overwritten(cache_dir, monkeypatch, damage):
    comp = COMPONENTS["WASO"]
    want = _component_optics(comp, LAM, N_MOM)
    (path,) = _entries(cache_dir)
    good = path.read_bytes()
    if damage == "garbage":
        path.write_bytes(b"not a zip file at all")
    elif damage == "truncated":
        path.write_bytes(good[: len(good) // 2])
    elif damage == "empty":
        path.write_bytes(b"")
    else:                                          # a readable npz with unusable arrays
        with np.load(path) as npz:
            arrays = dict(npz)
        arrays["greek"] = (arrays["greek"][:4] if damage == "wrong_shape"
                           else np.full_like(arrays["greek"], np.nan))
        with open(path, "wb") as f:
            np.savez(f, **arrays)
    _component_optics.cache_clear()
    calls = []
    real = mie_distribution.integrate_mie_cpp
    monkeypatch.setattr(mie_distribution, "integrate_mie_cpp",
                        lambda *a, **k: calls.append(1) or real(*a, **k))
    _assert_identical(_component_optics(comp, LAM, N_MOM), want)
    assert len(calls) == 1                         # recomputed ...
    with np.load(path) as npz, np.load(io.BytesIO(good)) as orig:   # ... and rewritten
        assert npz.files == orig.files
        assert all(np.array_equal(npz[k], orig[k]) for k in orig.files)
    assert [p.name for p in (cache_dir / MIE_CACHE_KIND).iterdir()] == [path.name]  # no temp


def test_unwritable_cache_folder_still_gives_the_right_values(tmp_path, monkeypatch):
    blocker = tmp_path / "a_file"
    blocker.write_text("a file where the cache folder should be")
    monkeypatch.setenv(CACHE_DIR_ENV, str(blocker / "cache"))   # cannot be created, even by root
    _component_optics.cache_clear()
    comp = COMPONENTS["SOOT"]
    try:
        got = _component_optics(comp, LAM, N_MOM)
    finally:
        _component_optics.cache_clear()
    _assert_identical(got, aerosol_types._integrate_component(comp, LAM, N_MOM))
    assert blocker.read_text() == "a file where the cache folder should be"


def test_failing_write_still_gives_the_right_values(cache_dir, monkeypatch):
    """A write failing part-way (e.g. a full disk) leaves no entry and no temporary file."""
    def _full(*_a, **_k):
        raise OSError(28, "No space left on device")
    comp = COMPONENTS["SOOT"]
    with monkeypatch.context() as m:
        m.setattr(np, "savez", _full)
        got = _component_optics(comp, LAM, N_MOM)
    _assert_identical(got, aerosol_types._integrate_component(comp, LAM, N_MOM))
    assert list((cache_dir / MIE_CACHE_KIND).iterdir()) == []


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0,
                    reason="a privileged user can write into a read-only folder")
def test_read_only_cache_folder_still_gives_the_right_values(cache_dir):
    (cache_dir / MIE_CACHE_KIND).mkdir(parents=True)
    (cache_dir / MIE_CACHE_KIND).chmod(0o500)
    try:
        comp = COMPONENTS["SOOT"]
        got = _component_optics(comp, LAM, N_MOM)
        _assert_identical(got, aerosol_types._integrate_component(comp, LAM, N_MOM))
        assert _entries(cache_dir) == []
    finally:
        (cache_dir / MIE_CACHE_KIND).chmod(0o700)


def test_each_component_wavelength_and_moment_count_has_its_own_entry(cache_dir, monkeypatch):
    cases = [(COMPONENTS["WASO"], 550.0, N_MOM), (COMPONENTS["WASO"], 450.0, N_MOM),
             (COMPONENTS["SOOT"], 550.0, N_MOM), (COMPONENTS["WASO"], 550.0, N_MOM + 1),
             (aerosol_types.AerosolComponent("WASO", 0.0212, 2.24, 1.53 - 0.007j), 550.0,
              N_MOM)]                              # same name, another refractive index
    first = [_component_optics(*c) for c in cases]
    assert len(_entries(cache_dir)) == len(cases)
    _component_optics.cache_clear()
    _forbid_integration(monkeypatch)
    for case, want in zip(cases, first):
        got = _component_optics(*case)
        _assert_identical(got, want)
    exts = [f[0] for f in first]
    assert len(set(exts)) == len(exts) - 1         # only the moment count leaves C_ext alone


def test_another_engine_version_misses(cache_dir, monkeypatch):
    comp = COMPONENTS["WASO"]
    _component_optics(comp, LAM, N_MOM)
    _component_optics.cache_clear()
    import importlib.metadata as md
    real = md.version
    monkeypatch.setattr(md, "version", lambda name: "0.0.0" if name == "sasktran2"
                        else real(name))
    _component_optics(comp, LAM, N_MOM)
    assert len(_entries(cache_dir)) == 2
