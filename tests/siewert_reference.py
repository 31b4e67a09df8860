"""Reader of the Siewert (2000) Problem IIA reference (``../shared/reference/siewert2000/``).

The files are Julia source holding data only: ``const NAME = (row1 = [...], ...)`` for the
Greek coefficients and ``const NAME = [a b c; d e f]`` for the tables. They are parsed as
data here (numbers between brackets), never executed.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference" / "siewert2000"
"""Default folder (tests pass the ``reference_dir`` fixture's ``siewert2000/``)."""
MU0 = 0.6            # siewert2000_IIA.yaml: the driver's mu0 (sun zenith 53.13 deg)
SSA = 0.973527       # single-scattering albedo of the slab
TAU = 1.0            # optical thickness; the ground (bottom) is tau = 1
TABLES = {("I", 0.0): 2, ("Q", 0.0): 3, ("I", 90.0): 4, ("Q", 90.0): 5, ("U", 90.0): 6,
          ("I", 180.0): 8, ("Q", 180.0): 9}
"""(Stokes parameter, relative azimuth [deg]) -> table number (the truth file's header)."""


def _numbers(text: str) -> np.ndarray:
    return np.array([float(x) for x in re.findall(r"[-+]?\d+\.?\d*(?:[eE][-+]?\d+)?", text)])


def greek_rows(folder: Path = REFERENCE) -> dict:
    """``{1: row1, ..., 6: row6}`` of PROBLEM_IIA (VLIDORT order: alpha2, alpha1, beta1,
    alpha4, beta2, alpha3; beta1 and beta2 in VLIDORT's (Mishchenko's) sign)."""
    text = (folder / "siewert2000_IIA_greek.jl").read_text()
    return {int(k): _numbers(v) for k, v in re.findall(r"row(\d)\s*=\s*\[([^\]]*)\]", text)}


def downwelling_bottom(table: int, folder: Path = REFERENCE):
    """``(mu, values)`` of a table's downwelling rows (mu >= 0) at tau = 1 (last column)."""
    text = (folder / "siewert2000_IIA_truth.jl").read_text()
    cos = _numbers(re.search(rf"SIEWERT_TABLE{table}_COSINES\s*=\s*\[([^\]]*)\]", text).group(1))
    body = re.search(rf"SIEWERT_TABLE{table}\s*=\s*\[([^\]]*)\]", text).group(1)
    rows = np.array([_numbers(r) for r in body.strip().split(";")])
    down = np.arange(cos.size) >= cos.size // 2      # the second half: +0.0 ... 1.0
    return cos[down], rows[down, -1]
