"""Optional extras of skysim and the command that installs one into this checkout.

PyPI has an unrelated package called ``skysim``: an install hint must never say
``pip install skysim[...]``. The hint names the interpreter that runs skysim and the folder of
this checkout (``pip install -e '<checkout>[extra]'``), so copying it installs the extra
exactly where it is missing.
"""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["EXTRAS", "extra_for_module", "install_command", "missing_extra_message"]

EXTRAS = {"sasktran2": "rt", "SALib": "sweep", "dask": "sweep", "distributed": "sweep",
          "tifffile": "camera", "cv2": "camera", "astropy": "moon", "h5netcdf": "series"}
"""Top-level module -> the optional extra of ``pyproject.toml`` that installs it."""


def extra_for_module(module: str | None) -> str | None:
    """The extra providing ``module`` (``"dask.distributed"`` -> ``"sweep"``), or None."""
    return EXTRAS.get((module or "").partition(".")[0])


def install_command(extra: str) -> str:
    """``<python> -m pip install -e '<checkout>[extra]'`` for this interpreter and checkout."""
    root = Path(__file__).resolve().parents[1]
    source = root if (root / "pyproject.toml").is_file() else "<your skysim checkout>"
    return f"{sys.executable} -m pip install -e '{source}[{extra}]'"


def missing_extra_message(module: str, what: str) -> str:
    """One line: ``what`` needs ``module``, from extra ..., install it with ..."""
    extra = extra_for_module(module)
    top = module.partition(".")[0]
    return (f"{what} needs the optional package {top!r} (skysim extra {extra!r}), which is not "
            f"installed; install it with: {install_command(extra)}")
