"""The Natraj et al. (2009) rows shipped with skysim (``skysim/data/natraj2009/``).

The shipped file must be the published values unchanged (compared, when the project's shared
reference folder is present, with the subset it was built from, and rebuilt byte for byte by
its builder), and must hold everything ``physical-sky`` and ``sky-gap`` read, so that both run
from a bare clone. A physical check that needs no engine: the single-scattering limit.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pandas as pd
import pytest

from experiments.studies.physical_sky import QUICK_CASES
from skysim.natraj import NATRAJ_FILE, natraj_path, read_natraj


def test_shipped_rows_are_the_published_subset_unchanged(reference_dir):
    source = reference_dir / "natraj2009" / "natraj2009_subset.csv.gz"
    full = pd.read_csv(source)
    want = full[(full.field == "transmitted") & (full.mu >= 0.1)].reset_index(drop=True)
    got = pd.read_csv(NATRAJ_FILE)
    pd.testing.assert_frame_equal(got, want, check_exact=True)   # the same text, so exact


def test_builder_reproduces_the_shipped_file_byte_for_byte(reference_dir, tmp_path):
    spec = importlib.util.spec_from_file_location(
        "builder", NATRAJ_FILE.with_name("build_natraj2009_transmitted.py"))
    builder = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(builder)
    out = tmp_path / "t.csv.gz"
    n = builder.build(reference_dir / "natraj2009" / "natraj2009_subset.csv.gz", out)
    assert n == 5488 and out.read_bytes() == NATRAJ_FILE.read_bytes()


def test_shipped_rows_cover_both_reproductions():
    """Every case physical-sky and sky-gap use is present: 4 tau x 2 albedo x 7 suns, 14
    view cosines >= 0.1, 7 azimuths (0..180 step 30), in a file small enough to ship."""
    from experiments.studies.sky_gap import cases_from_natraj, natraj_table
    d = read_natraj(NATRAJ_FILE)
    assert NATRAJ_FILE.stat().st_size < 100_000
    assert len(d) == 4 * 2 * 7 * 14 * 7
    for tau, albedo, mu0 in QUICK_CASES:
        assert ((d.tau == tau) & (d.albedo == albedo) & (d.mu0 == mu0)).sum() == 14 * 7
    t = natraj_table()
    for (_, _), g in t.groupby(["tau", "albedo"]):
        _, mu0s = cases_from_natraj(g)
        assert mu0s.tolist() == [0.1, 0.2, 0.4, 0.6, 0.8, 0.92, 1.0]


def test_thin_atmosphere_rows_follow_single_scattering():
    """Independent closed form: at tau = 0.02 over a black ground, the zenith DoP of the
    diffuse sky is within 0.03 of single-scattering Rayleigh, sin^2(g)/(1 + cos^2(g)) with
    g the sun's zenith angle (multiple scattering is of order tau = 2 % of the light)."""
    d = read_natraj(NATRAJ_FILE)
    z = d[(d.tau == 0.02) & (d.albedo == 0.0) & (d.mu == 1.0) & (d.phi == 0.0)]
    cos_g = z.mu0.to_numpy()
    single = (1 - cos_g ** 2) / (1 + cos_g ** 2)
    dop = np.hypot(z.Q, z.U).to_numpy() / z.I.to_numpy()
    np.testing.assert_allclose(dop, single, atol=0.03)


def test_reference_option_takes_a_file_or_a_folder(tmp_path):
    assert natraj_path(None) == NATRAJ_FILE
    assert natraj_path(NATRAJ_FILE) == NATRAJ_FILE
    assert natraj_path(NATRAJ_FILE.parent) == NATRAJ_FILE
    assert natraj_path(NATRAJ_FILE.parent.parent) == NATRAJ_FILE    # .../natraj2009/ inside
    with pytest.raises(FileNotFoundError, match="no Natraj table there"):
        natraj_path(tmp_path)
    bad = tmp_path / "t.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match=r"missing column\(s\)"):
        read_natraj(bad)


def test_reproduce_refuses_a_bad_reference_without_traceback(tmp_path, capsys):
    from experiments.cli.main import main
    assert main(["reproduce", "physical-sky", "--reference", str(tmp_path),
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "no Natraj table" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()
