"""What a long command tells its user while it runs: the expected duration before the work,
progress bars during it (tqdm, on stderr), and warnings as one readable line each.

Every command that can run longer than :data:`ANNOUNCE_AFTER_S` says so before it starts
(:func:`announce_duration`), so that a user can stop a run that would take too long instead of
waiting for it in silence.
"""

from __future__ import annotations

import sys
import warnings

__all__ = ["ANNOUNCE_AFTER_S", "REPRODUCTION_SECONDS", "TIME_BUDGET_S", "announce_duration",
           "check_duration",
           "expected_reproduction_seconds", "format_duration", "install_warning_format",
           "report_run", "reproduction"]

ANNOUNCE_AFTER_S = 10.0
"""Runs expected to take longer than this [s] print their expected duration first."""


REPRODUCTION_SECONDS = {
    # target: (full run [s], --quick run [s], trials of the full run or None)
    "yang2014": (60.0, 8.0, 200),
    "dark-current": (80.0, 16.0, 100),
    "compound-eye": (20.0, 4.0, 50),
    "jin2020": (73.0, 28.0, 20),
    "sky-gap": (840.0, 114.0, None),
    "physical-sky": (420.0, 41.0, None),
    "camera": (53.0, 18.0, 10),
    "real-sky-compass": (1706.0, 64.0, None),
    "moonlit-sky": (160.0, 6.0, None),
    "moonlit-compass": (13.0, 3.0, None),
    "cloudy-compass": (23.0, 5.0, 8),
}
"""Measured wall time of each reproduction on a shared 2-core machine [s]: the full runs of
sky-gap (14 min), physical-sky (7 min with its aerosol skies), jin2020 (73 s), camera (53 s),
real-sky-compass (28 min for the 14 reference sessions and its clock check), moonlit-sky (2.7 min) and
cloudy-compass (23 s; its --trials are camera images, which take most of the time), every
--quick run;
the other full runs scaled from their quick runs by the number of trials (an upper bound:
the fixed costs are scaled too). Zero: not measured (nothing is announced)."""


def expected_reproduction_seconds(target: str, quick: bool, trials: int | None) -> float:
    """Expected wall time of ``skysim reproduce target`` [s] (0 when unknown); ``--trials``
    scales the full run's time in proportion."""
    full, short, full_trials = REPRODUCTION_SECONDS.get(target, (0.0, 0.0, None))
    if quick:
        return short
    if trials and full_trials:
        return full * trials / full_trials
    return full


def format_duration(seconds: float) -> str:
    """``seconds`` [s] in words a person reads at a glance: ``45 s``, ``14 min``, ``2.5 h``,
    ``6 days``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    if seconds < 48 * 3600:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.0f} days"


def announce_duration(seconds: float, what: str, how_to_shorten: str = "") -> None:
    """Print ``what: expected duration about ...`` to stderr when ``seconds`` [s] exceeds
    :data:`ANNOUNCE_AFTER_S`; ``how_to_shorten`` names the option that makes it faster."""
    if seconds <= ANNOUNCE_AFTER_S:
        return
    hint = f"; {how_to_shorten}" if how_to_shorten else ""
    print(f"{what}: expected duration about {format_duration(seconds)}{hint}",
          file=sys.stderr, flush=True)


TIME_BUDGET_S = 24 * 3600.0
"""Longest expected duration of one run [s] started without ``--force``: a day. Longer runs
are refused before any work, with the estimate (a mistyped size, e.g. 1e9 trials, would
otherwise hold the machine for months)."""


def check_duration(seconds: float, what: str, how_to_shorten: str = "", *,
                   force: bool = False, force_flag: str = "") -> None:
    """Refuse a run expected to take longer than :data:`TIME_BUDGET_S`, unless ``force``;
    else announce its expected duration (:func:`announce_duration`).

    Parameters
    ----------
    seconds : float
        Expected wall time [s].
    what : str
        The run, e.g. ``"skysim reproduce camera"``.
    how_to_shorten : str
        The option that makes it shorter.
    force : bool
        Run even over the budget (the user asked for it).
    force_flag : str
        The option that sets ``force`` (named in the message), or "" if the command has none.

    Raises
    ------
    skysim.exceptions.InvalidParameterError
        If the run would exceed the budget and ``force`` is not set.
    """
    if seconds > TIME_BUDGET_S and not force:
        from skysim.exceptions import InvalidParameterError
        override = f" ({force_flag} runs it anyway)" if force_flag else ""
        hint = f"; {how_to_shorten}" if how_to_shorten else ""
        raise InvalidParameterError(
            f"{what}: expected duration about {format_duration(seconds)}, more than the "
            f"{TIME_BUDGET_S / 3600:g} h one run may take{hint}{override}")
    announce_duration(seconds, what, how_to_shorten)


def _one_line(message, category, filename, lineno, line=None) -> str:
    """A warning as ``skysim: warning: message (Category)``: no source line, no file path."""
    text = " ".join(str(message).split())
    return f"skysim: warning: {text} ({category.__name__})\n"


def install_warning_format() -> None:
    """Show every warning as one line (:func:`_one_line`); which warnings show is left to
    Python's filters (``-W``, ``PYTHONWARNINGS``)."""
    warnings.formatwarning = _one_line


def report_run(title: str, summary: str, elapsed_s: float, out, files) -> None:
    """What a reproduction prints when it is done: its title, its summary lines, the wall
    time [s] and the files it wrote into ``out``."""
    print(title)
    print(summary)
    print(f"{elapsed_s:.1f} s; wrote {out}/{', '.join(files)}")


def reproduction(target: str, title: str, run, summarize, files):
    """The ``skysim reproduce target`` function of a study whose ``run(quick=, trials=,
    seed=, out=)`` returns a dict with ``summary["elapsed_s"]``: it runs into ``--out``
    (default ``results/<target>``) and prints :func:`report_run` with ``summarize(result)``.
    It reports ``run``'s module as its own, where the command line finds the study's
    ``DEFAULT_SEED``."""
    def _reproduce(args) -> int:
        from pathlib import Path
        out = Path(args.out or f"results/{target}")
        result = run(quick=args.quick, trials=args.trials, seed=args.seed, out=out)
        report_run(title, summarize(result), result["summary"]["elapsed_s"], out, files)
        return 0
    _reproduce.__module__ = run.__module__
    return _reproduce
