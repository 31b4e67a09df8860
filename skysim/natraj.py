"""The Natraj et al. (2009) tables of the diffuse Rayleigh sky: where they are and how they read.

The corrected Coulson-Dave-Sekera tables [1]_ [2]_ give Stokes I, Q, U of the light leaving a
homogeneous, conservative, non-depolarizing Rayleigh slab over a Lambertian ground; skysim
validates its multiple-scattering sky against them (``skysim reproduce physical-sky``) and
diagnoses the single-scattering gap on them (``skysim sky-gap``). The transmitted rows of the
published subset (view cosines >= 0.1) ship with skysim in ``skysim/data/natraj2009/``, with
their README (columns, conventions) and the script that builds them from the subset.

Sign conventions of the tables: ``Q = I_r - I_l``, so ``Q_skysim = -Q_table`` and
``U_skysim = U_table`` (``docs/conventions.md``).

References
----------
.. [1] V. Natraj, K.-F. Li, Y. L. Yung, "Rayleigh scattering in planetary atmospheres:
   corrected tables through accurate computation of X and Y functions", ApJ 691:1909-1920
   (2009), doi:10.1088/0004-637X/691/2/1909.
.. [2] K. L. Coulson, J. V. Dave, Z. Sekera, *Tables Related to Radiation Emerging from a
   Planetary Atmosphere with Rayleigh Scattering*, Univ. California Press (1960).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from .exceptions import FileFormatError, MissingFileError

__all__ = ["NATRAJ_FILE", "NATRAJ_NAMES", "NATRAJ_COLUMNS", "natraj_path", "read_natraj"]

NATRAJ_FILE = Path(__file__).with_name("data") / "natraj2009" / "natraj2009_transmitted.csv.gz"
"""The Natraj et al. (2009) [1]_ rows shipped with skysim (transmitted field, mu >= 0.1; built
by ``build_natraj2009_transmitted.py`` beside it from the published subset)."""
NATRAJ_NAMES = ("natraj2009_subset.csv.gz", "natraj2009_transmitted.csv.gz")
"""File names of a copy of the tables, looked for in a folder (the full subset first)."""
NATRAJ_COLUMNS = ("tau", "albedo", "mu0", "mu", "phi", "I", "Q", "U", "field")
"""Columns of a table file: optical thickness, ground albedo, solar and view zenith cosines,
relative azimuth [deg], Stokes I, Q, U (incident flux pi) and ``transmitted``/``reflected``."""


def natraj_path(reference=None) -> Path:
    """The Natraj table file: the shipped one (``reference`` None), the file ``reference``, or
    the first of :data:`NATRAJ_NAMES` in the folder ``reference`` or its ``natraj2009/``.

    Raises
    ------
    MissingFileError
        If ``reference`` is neither such a file nor a folder holding one.
    """
    if reference is None:
        return NATRAJ_FILE
    ref = Path(reference)
    if ref.is_file():
        return ref
    for folder in (ref, ref / "natraj2009"):
        for name in NATRAJ_NAMES:
            if (folder / name).is_file():
                return folder / name
    raise MissingFileError(f"{ref}: no Natraj table there; give the table file or "
                           f"a folder holding {' or '.join(NATRAJ_NAMES)} (directly or in "
                           "natraj2009/)")


def read_natraj(table_path=NATRAJ_FILE, min_mu: float = 0.1) -> pd.DataFrame:
    """Transmitted-field rows of the Natraj et al. (2009) [1]_ subset with view cosine
    ``mu >= min_mu``, in the table's own sign conventions (``Q_table = -Q``, ``U_table = U``).

    Raises
    ------
    MissingFileError
        If the table is missing.
    FileFormatError
        If it is not a readable CSV with the columns :data:`NATRAJ_COLUMNS`, or holds no
        transmitted rows at ``mu >= min_mu``.
    """
    path = Path(table_path)
    if not path.is_file():
        raise MissingFileError(f"no Natraj table {path}; give the table file or a folder "
                               f"holding {' or '.join(NATRAJ_NAMES)}")
    from .io import check_csv_header
    check_csv_header(path)
    try:
        d = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, OSError,
            EOFError) as exc:
        raise FileFormatError(f"{path}: not a readable Natraj table ({exc})") from None
    missing = [c for c in NATRAJ_COLUMNS if c not in d.columns]
    if missing:
        raise FileFormatError(f"{path}: missing column(s) {missing} of a Natraj table; found "
                              f"{list(d.columns)}")
    d = d[(d.field == "transmitted") & (d.mu >= min_mu)]
    if d.empty:
        raise FileFormatError(f"{path}: no transmitted-field rows with mu >= {min_mu}")
    return d
