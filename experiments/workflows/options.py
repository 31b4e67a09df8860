"""Option types and input/output checks of the ``skysim`` commands: every option is checked
when it is parsed.

The commands of :mod:`experiments.cli`, :mod:`experiments.workflows` and
:mod:`experiments.studies` share them from here (the command line sits on top and nothing
imports it). Each function here is an ``argparse`` ``type=``: it converts the text the user
typed or raises :class:`argparse.ArgumentTypeError`, which argparse reports as
``skysim CMD: error: argument --n: must be an integer >= 1; got '0'`` with exit code 2, before
any work starts. Output paths are checked the same way, so that a long run never ends in an
unwritable folder.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

__all__ = ["CLOUD_TAU_DEFAULT", "PANDAS_YEARS", "DefaultsHelpFormatter", "aware_time",
           "cloud_spec", "data_file_and_sidecars", "existing_file", "float_in", "int_at_least",
           "int_in", "name_list", "nonnegative_float", "nonnegative_int", "output_dir",
           "output_file", "positive_float", "positive_int", "refuse_folder_holding_inputs",
           "refuse_replacing_inputs", "seed", "time_step", "wind_spec", "with_sidecar"]


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Adds ``(default: X)`` to an option's help unless the help already speaks of its
    default, or there is none to show (None, False)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text or action.default is None or action.default is False \
                or action.default == argparse.SUPPRESS or not action.option_strings:
            return text
        return text + " (default: %(default)s)"


PANDAS_YEARS = (1678, 2261)
"""Whole years inside pandas' nanosecond time range (1677-09-21 .. 2262-04-11)."""


def _number(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"must be a finite number; got {text!r}")
    return x


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        x = _number(text)  # accept 1e6 and 2000.0, refuse 2.5
        if not x.is_integer():
            raise argparse.ArgumentTypeError(f"must be a whole number; got {text!r}") from None
        return int(x)


def int_at_least(low: int):
    """An integer ``>= low`` (``1e6`` is read as 1000000)."""
    def parse(text: str) -> int:
        n = _integer(text)
        if n < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}; got {text!r}")
        return n
    parse.__name__ = f"integer >= {low}"
    return parse


def int_in(low: int, high: int):
    """An integer in ``[low, high]``."""
    def parse(text: str) -> int:
        n = _integer(text)
        if not low <= n <= high:
            raise argparse.ArgumentTypeError(f"must be an integer in [{low}, {high}]; got "
                                             f"{text!r}")
        return n
    parse.__name__ = f"integer in [{low}, {high}]"
    return parse


positive_int = int_at_least(1)
nonnegative_int = int_at_least(0)
seed = int_at_least(0)
"""A random seed: a non-negative integer (numpy's ``SeedSequence`` refuses negative ones)."""


def float_in(low: float = -math.inf, high: float = math.inf, *, low_open: bool = False,
             high_open: bool = False, unit: str = ""):
    """A finite number in the interval from ``low`` to ``high`` (bounds optionally open)."""
    lb, hb = "(" if low_open else "[", ")" if high_open else "]"
    u = f" {unit}" if unit else ""
    if math.isinf(high) and not math.isinf(low):
        interval = f"{'>' if low_open else '>='} {low:g}{u}"
    elif math.isinf(low) and not math.isinf(high):
        interval = f"{'<' if high_open else '<='} {high:g}{u}"
    else:
        interval = f"in {lb}{low:g}, {high:g}{hb}{u}"

    def parse(text: str) -> float:
        x = _number(text)
        below = x <= low if low_open else x < low
        above = x >= high if high_open else x > high
        if below or above:
            raise argparse.ArgumentTypeError(f"must be {interval}; got {text!r}")
        return x
    parse.__name__ = f"number {interval}"
    return parse


positive_float = float_in(0.0, low_open=True)
nonnegative_float = float_in(0.0)


CLOUD_TAU_DEFAULT = 10.0
"""Cloud optical thickness of ``--clouds COVER`` alone: a stratocumulus (the ISCCP classes put
low clouds of optical thickness 3.6-23 there, Rossow & Schiffer 1999,
doi:10.1175/1520-0477(1999)080<2261:AIUCFI>2.0.CO;2)."""


def _parts(text: str, n_max: int, form: str) -> list[str]:
    parts = [t.strip() for t in text.split(",")]
    if not 1 <= len(parts) <= n_max or any(not t for t in parts):
        raise argparse.ArgumentTypeError(f"write {form}; got {text!r}")
    return parts


def cloud_spec(text: str) -> tuple[float, float, int]:
    """``COVER[,TAU[,SEED]]``: cloud cover (fraction of the sky, 0-1), cloud optical thickness
    at 550 nm (0-100, default :data:`CLOUD_TAU_DEFAULT`) and the seed of the cloud field
    (integer >= 0, default 0)."""
    parts = _parts(text, 3, "COVER[,TAU[,SEED]], e.g. 0.5 or 0.5,10 or 0.5,10,3")
    cover = float_in(0.0, 1.0)(parts[0])
    tau = float_in(0.0, 100.0)(parts[1]) if len(parts) > 1 else CLOUD_TAU_DEFAULT
    return cover, tau, seed(parts[2]) if len(parts) > 2 else 0


cloud_spec.__name__ = "COVER[,TAU[,SEED]]"


def wind_spec(text: str) -> tuple[float, float]:
    """``SPEED,FROM``: wind speed [m/s, 0-100] and the azimuth it blows from [deg]."""
    parts = _parts(text, 2, "SPEED,FROM (m/s, deg), e.g. 8,270")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"write SPEED,FROM (m/s, deg), e.g. 8,270; got "
                                         f"{text!r}")
    return float_in(0.0, 100.0, unit="m/s")(parts[0]), _number(parts[1])


wind_spec.__name__ = "SPEED,FROM"


def aware_time(text: str):
    """A timezone-aware ISO 8601 time (``2013-05-22T17:10+08:00``) as a pandas Timestamp."""
    import pandas as pd
    try:
        t = pd.Timestamp(text)
    except (ValueError, TypeError, OverflowError) as exc:
        if isinstance(exc, pd.errors.OutOfBoundsDatetime) or "out of bounds" in str(exc).lower():
            raise argparse.ArgumentTypeError(
                f"{text!r} is outside the supported years {PANDAS_YEARS[0]}-"
                f"{PANDAS_YEARS[1]}") from None
        raise argparse.ArgumentTypeError(
            f"cannot read {text!r} as a time; write ISO 8601 with a UTC offset, e.g. "
            "2013-05-22T17:10:00+08:00") from None
    if t is pd.NaT:
        raise argparse.ArgumentTypeError(f"{text!r} is not a time")
    if not PANDAS_YEARS[0] <= t.year <= PANDAS_YEARS[1]:
        raise argparse.ArgumentTypeError(
            f"{text!r} is outside the supported years {PANDAS_YEARS[0]}-{PANDAS_YEARS[1]}")
    if t.tzinfo is None:
        raise argparse.ArgumentTypeError(
            f"{text!r} has no UTC offset; skysim never guesses the timezone: write e.g. "
            f"{t.isoformat()}+08:00 (or Z for UTC)")
    return t


def existing_file(text: str) -> Path:
    """An existing file (not a folder)."""
    p = Path(text)
    if p.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder; give a file")
    if not p.is_file():
        raise argparse.ArgumentTypeError(f"no file {text}")
    return p


def _path_error(check, text: str, what: str) -> Path:
    from skysim.io import OutputPathError
    try:
        return check(text, what)
    except OutputPathError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def output_file(*suffixes: str):
    """An output file that can be written, optionally with one of ``suffixes``."""
    def parse(text: str) -> Path:
        from skysim.io import check_output_file
        if suffixes and Path(text).suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(
                f"must end in {' or '.join(suffixes)}; got {Path(text).name!r}")
        return _path_error(check_output_file, text, "output file")
    parse.__name__ = "output file"
    return parse


def output_dir(text: str) -> Path:
    """An output folder that exists or can be created, and is writable."""
    from skysim.io import check_output_dir
    return _path_error(check_output_dir, text, "output folder")


def time_step(text: str):
    """A positive time step as a pandas offset (``1s``, ``10min``, ``1h``, ``1D``)."""
    import pandas as pd
    try:
        offset = pd.tseries.frequencies.to_offset(text)
        step = (pd.Timestamp("2000-01-01", tz="UTC") + offset) - pd.Timestamp("2000-01-01",
                                                                               tz="UTC")
    except (ValueError, TypeError):
        raise argparse.ArgumentTypeError(
            f"not a time step: {text!r}; write a number and a unit, e.g. 1s, 10min, 1h, "
            "1D") from None
    if step <= pd.Timedelta(0):
        raise argparse.ArgumentTypeError(f"must be a positive time step; got {text!r}")
    return offset


def _same_file(a: Path, b: Path) -> bool:
    import os
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def data_file_and_sidecars(path) -> list[Path]:
    """A data file and those spellings of its JSON sidecar (``m.csv.json``, ``m.json``) that
    exist: what reading it may read."""
    from skysim.io import legacy_sidecar_path, sidecar_path
    return [Path(path)] + [s for s in (sidecar_path(path), legacy_sidecar_path(path))
                           if s.exists()]


def refuse_replacing_inputs(outputs, inputs=()) -> None:
    """Refuse, before any work, an output that would replace an input file or another output
    of the same run.

    Parameters
    ----------
    outputs, inputs : iterable of (str, path or None)
        ``(what, path)`` pairs, ``what`` naming the option as the user typed it (e.g.
        ``"--out"``, ``"the sidecar of --out"``); None paths are skipped. List every file the
        run writes (sidecars included) as an output, and every file it reads (with the
        sidecars it may read, :func:`data_file_and_sidecars`) as an input.

    Raises
    ------
    skysim.io.OutputPathError
        Naming both paths, if an output is the same file as an input or as another output.
    """
    from skysim.io import OutputPathError
    inputs = [(what, Path(p)) for what, p in inputs if p is not None]
    outputs = [(what, Path(p)) for what, p in outputs if p is not None]
    for i, (what_out, out) in enumerate(outputs):
        for what_in, inp in inputs:
            if _same_file(out, inp):
                raise OutputPathError(f"{what_out} {out} would replace the input {what_in} {inp}; "
                                 "write the output elsewhere")
        for what_other, other in outputs[i + 1:]:
            if _same_file(out, other):
                raise OutputPathError(f"{what_out} {out} and {what_other} {other} are the same "
                                 "file: one output would replace the other; give each its "
                                 "own name")


def with_sidecar(what: str, path) -> list[tuple[str, Path | None]]:
    """``(what, path)`` and ``("the sidecar of what", <path>.json)``: the files a writer of a
    data file with a JSON sidecar writes (for :func:`refuse_replacing_inputs`)."""
    if path is None:
        return [(what, None)]
    from skysim.io import sidecar_path
    return [(what, Path(path)), (f"the sidecar of {what}", sidecar_path(path))]


def refuse_folder_holding_inputs(what: str, folder, inputs) -> None:
    """Refuse, before any work, an output folder that a run replaces as a whole (or fills
    with files of its own names) when it holds one of the run's inputs (or is one).

    Parameters
    ----------
    what : str
        The option of the folder as the user typed it (``"--out"``).
    folder : path or None
        The output folder; None is skipped.
    inputs : iterable of (str, path or None)
        ``(what, path)`` pairs of the files and folders the run reads; None paths are skipped.

    Raises
    ------
    skysim.io.OutputPathError
        Naming the folder and the input.
    """
    from skysim.io import OutputPathError
    if folder is None:
        return
    out = Path(folder).resolve()
    for what_in, inp in inputs:
        if inp is None:
            continue
        p = Path(inp).resolve()
        if p == out or out in p.parents:
            raise OutputPathError(f"{what} {folder} holds the input {what_in} {inp}, which the run "
                             "would replace; write the output elsewhere")


def name_list(text: str) -> tuple[str, ...]:
    """A comma-separated list of names (``a,b``), at least one; no empty name."""
    names = tuple(t.strip() for t in text.split(","))
    if not any(names):
        raise argparse.ArgumentTypeError(f"give at least one name; got {text!r}")
    if not all(names):
        raise argparse.ArgumentTypeError(f"an empty name in the list {text!r}; write "
                                         "comma-separated names, e.g. a,b")
    return names


name_list.__name__ = "comma-separated names"
