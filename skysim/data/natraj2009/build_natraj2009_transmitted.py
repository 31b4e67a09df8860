"""Build ``natraj2009_transmitted.csv.gz``: the rows of the Natraj et al. (2009) tables that
``skysim reproduce physical-sky`` and ``skysim reproduce sky-gap`` validate against.

Source: the subset of the corrected Coulson-Dave-Sekera tables of

    V. Natraj, K.-F. Li, Y. L. Yung, "Rayleigh scattering in planetary atmospheres: corrected
    tables through accurate computation of X and Y functions", ApJ 691:1909-1920 (2009),
    doi:10.1088/0004-637X/691/2/1909

as distributed with the project's shared reference data (``natraj2009_subset.csv.gz``:
tau in {0.02, 0.1, 0.25, 1.0}, ground albedo in {0, 0.25}, both fields). Kept: the
transmitted field (the diffuse sky seen from the ground) at view cosines mu >= 0.1, the
rows the two reproductions use; the values are copied unchanged (same columns, same text).

Usage (from the repository root)::

    python skysim/data/natraj2009/build_natraj2009_transmitted.py \
        ../shared/reference/natraj2009/natraj2009_subset.csv.gz

The output is byte-identical for the same input (gzip without a time stamp).
"""

from __future__ import annotations

import csv
import gzip
import io
import os
import sys
from pathlib import Path

MIN_MU = 0.1
OUT = Path(__file__).with_name("natraj2009_transmitted.csv.gz")


def build(source: Path, out: Path = OUT) -> int:
    """Copy the transmitted rows with ``mu >= MIN_MU`` from ``source`` to ``out``; return
    the number of rows written."""
    with gzip.open(source, "rt", newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    field, mu = header.index("field"), header.index("mu")
    kept = [r for r in body if r[field] == "transmitted" and float(r[mu]) >= MIN_MU]
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerows([header, *kept])
    tmp = out.with_name(out.name + ".tmp")
    with open(tmp, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0,
                                               filename="") as gz:
        gz.write(text.getvalue().encode())
    os.replace(tmp, out)  # never a half-written table
    return len(kept)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    print(f"wrote {build(Path(sys.argv[1]))} rows to {OUT}")
