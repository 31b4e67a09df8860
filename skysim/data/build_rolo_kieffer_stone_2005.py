"""Builder of ``rolo_kieffer_stone_2005.csv``: the ROLO lunar disk-reflectance coefficients.

The numbers are Table 4 of Kieffer & Stone (2005), Astron. J. 129:2887,
doi:10.1086/430185: per ROLO band the wavelength [nm] and a0..a3, b1..b3, d1..d3 of their
eq. (10); the band-independent c1..c4 and p1..p4 are written as the header comment of the
file. The per-band rows were read from ``par.txt`` of the public repository
``SN-CRISP/Moon-Skypol`` (the source of the FORS2 moonlit-sky table), which tabulates them
in that column order without a header; c3 is the published 0.00095906.

Run: ``python build_rolo_kieffer_stone_2005.py PATH/TO/par.txt`` (writes the CSV beside this
file).
"""

import sys
from pathlib import Path

COLUMNS = ("wavelength_nm", "a0", "a1", "a2", "a3", "b1", "b2", "b3", "d1", "d2", "d3")
C = (0.00034115, -0.0013425, 0.00095906, 0.00066229)   # Kieffer & Stone 2005, Table 4
P = (4.06054, 12.8802, -30.5858, 16.7498)               # [deg], Table 4


def main(par_txt: str) -> None:
    rows = [line.split() for line in Path(par_txt).read_text().splitlines() if line.strip()]
    if any(len(r) != len(COLUMNS) for r in rows):
        raise SystemExit(f"{par_txt}: expected {len(COLUMNS)} numbers per row")
    out = Path(__file__).with_name("rolo_kieffer_stone_2005.csv")
    head = ["# ROLO lunar disk-reflectance model, Kieffer & Stone (2005) AJ 129:2887, "
            "doi:10.1086/430185, Table 4 (eq. 10)",
            "# rows from par.txt of github.com/SN-CRISP/Moon-Skypol; built by "
            "build_rolo_kieffer_stone_2005.py",
            "# c1..c4 = " + " ".join(map(str, C)),
            "# p1..p4 [deg] = " + " ".join(map(str, P)),
            ",".join(COLUMNS)]
    out.write_text("\n".join(head + [",".join(r) for r in rows]) + "\n")


if __name__ == "__main__":
    main(sys.argv[1])
