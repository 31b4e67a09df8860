"""What a long command tells its user while it runs: the expected duration before the work,
progress bars during it (tqdm, on stderr), and warnings as one readable line each.

Every command that can run longer than :data:`ANNOUNCE_AFTER_S` says so before it starts
(:func:`announce_duration`), so that a user can stop a run that would take too long instead of
waiting for it in silence.
"""

from __future__ import annotations

import sys
import warnings

__all__ = ["ANNOUNCE_AFTER_S", "COMMAND_SECONDS", "ESTIMATE_OVER_CPU", "REPRODUCTION_SECONDS",
           "STEP_SECONDS", "Steps", "TIME_BUDGET_S", "announce_duration", "check_duration",
           "expected_reproduction_seconds", "format_duration", "install_warning_format",
           "report_run", "reproduction", "working"]

ANNOUNCE_AFTER_S = 10.0
"""Runs expected to take longer than this [s] print their expected duration first."""


ESTIMATE_OVER_CPU = 1.5
"""Expected wall time over measured processor time. A run on a quiet 2-core machine takes
about its processor time (one BLAS thread, numpy single-threaded); on a shared one under
moderate load up to three times it: 1.5 keeps the estimate within 2x of both."""

STEP_SECONDS = {
    "physical-sky": {"validation against the Natraj tables": 66.0, "neutral points": 35.0,
                     "zenith DoP": 0.5, "sky maps and figures": 5.0, "aerosol skies": 54.0},
    "physical-sky --quick": {"validation against the Natraj tables": 6.0,
                             "neutral points": 7.0, "zenith DoP": 0.5,
                             "sky maps and figures": 5.0, "aerosol skies": 29.0},
}
"""Expected cost [s] of each step of the reproductions that show their progress step by step
(:class:`Steps`), in their order: :data:`ESTIMATE_OVER_CPU` times the processor time of each
step measured on a shared 2-core machine (``Steps.cpu_s``, written to the run's
``summary.json`` as ``step_cpu_s``): physical-sky 44.1, 23.4, 0.0 (the zenith DoP reuses the
neutral points' engine runs), 3.0 and 35.8 s; --quick 3.9, 4.6, 0.0, 3.0 and 19.4 s."""

REPRODUCTION_SECONDS = {
    # target: (full run [s], --quick run [s], trials of the full run or None)
    "yang2014": (4.0, 3.0, 200),
    "dark-current": (10.0, 5.0, 100),
    "compound-eye": (7.0, 4.0, 50),
    "jin2020": (73.0, 17.0, 20),
    "sky-gap": (840.0, 114.0, None),
    "physical-sky": (sum(STEP_SECONDS["physical-sky"].values()),
                     sum(STEP_SECONDS["physical-sky --quick"].values()), None),
    "camera": (22.0, 9.0, 10),
    "real-sky-compass": (1706.0, 64.0, None),
    "moonlit-sky": (160.0, 6.0, None),
    "moonlit-compass": (15.0, 5.0, None),
    "cloudy-compass": (22.0, 7.0, 8),
}
"""Expected wall time of each reproduction [s]: :data:`ESTIMATE_OVER_CPU` times the
processor time measured on a shared 2-core machine (AMD EPYC; ``/usr/bin/time`` user + sys,
imports included), full and --quick: yang2014 2.4 and 2.1 s, dark-current 6.6 and 3.0 s,
compound-eye 4.7 and 2.4 s, physical-sky 108 and 32 s (its steps in :data:`STEP_SECONDS`),
camera 14.7 and 6.0 s, moonlit-compass 10.1 and 3.6 s, cloudy-compass 14.4 and 4.6 s, jin2020
--quick 11.3 s. Measured as wall time on a shared machine, not re-measured this way: the full
runs of jin2020 (73 s), sky-gap (14 min), real-sky-compass (28 min for the 14 reference
sessions and its clock check, --quick 64 s) and moonlit-sky (2.7 min, --quick 6 s), and
sky-gap --quick. ``--trials`` scales the full run in proportion (an upper bound: the fixed
costs are scaled too)."""


COMMAND_SECONDS = {"diagnose camera image 512x512": 19.0, "diagnose camera image 256x256": 8.0,
                   "diagnose ring, two effects": 6.0, "sky --model aerosol": 12.0}
"""Expected wall time [s] of commands that call one long library function without progress
of their own (for :func:`working` around that call): :data:`ESTIMATE_OVER_CPU` times the
processor time measured as above: ``skysim diagnose`` on the README's camera image (12.7 s)
and on a 256 x 256 one (5.4 s), on the README's ring sessions with ``--effects
yaw_scale,tilt`` (4.1 s), and the README's ``skysim sky --model aerosol`` with the Mie optics
cached (7.9 s)."""


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


class Steps:
    """Progress of a run made of named steps of measured cost, on stderr: one bar counted in
    expected seconds, refreshed once a second. A step that ends adds its cost; within a step
    the bar follows the clock, held below the step's end. The time left is the remaining
    steps' cost scaled by how fast this run has gone so far (a loaded machine's run says
    so as it goes). Runs expected to take at most :data:`ANNOUNCE_AFTER_S` show nothing.

    A context manager; :meth:`done` after each step, in the order of ``costs_s``::

        with Steps("skysim reproduce physical-sky", {"tables": 40.0, "maps": 8.0}) as steps:
            ...
            steps.done("tables")

    Each step's wall time [s] is kept in :attr:`elapsed_s` and its processor time (this
    process, every thread) in :attr:`cpu_s`: the costs are measured from them.
    """

    def __init__(self, what: str, costs_s: dict[str, float]):
        self.what, self.costs_s = what, {k: float(v) for k, v in costs_s.items()}
        self.elapsed_s: dict[str, float] = {}
        self.cpu_s: dict[str, float] = {}
        self._thread = None

    def __enter__(self):
        import threading
        import time
        self._t0 = self._last = time.perf_counter()
        self._last_cpu = time.process_time()
        if sum(self.costs_s.values()) > ANNOUNCE_AFTER_S:
            self._stop = threading.Event()
            self._thread = threading.Thread(target=self._tick, daemon=True)
            self._thread.start()
        return self

    def done(self, step: str) -> None:
        """Step ``step`` (a key of the costs) has ended."""
        import time
        now, cpu = time.perf_counter(), time.process_time()
        self.elapsed_s[step], self.cpu_s[step] = now - self._last, cpu - self._last_cpu
        self._last, self._last_cpu = now, cpu

    def _state(self) -> tuple[float, float, str]:
        """Bar position [expected s], time left [s] and the note after the bar."""
        import time
        done = [k for k in self.costs_s if k in self.elapsed_s]
        rest = [k for k in self.costs_s if k not in self.elapsed_s]
        cost_done = sum(self.costs_s[k] for k in done)
        speed = sum(self.elapsed_s[k] for k in done) / cost_done if cost_done > 0 else 1.0
        if not rest:
            return cost_done, 0.0, ""
        current = self.costs_s[rest[0]]
        in_step = (time.perf_counter() - self._last) / max(speed, 1e-9)
        position = cost_done + min(in_step, 0.95 * current)
        left = max(sum(self.costs_s[k] for k in rest) - in_step, 0.0) * speed
        note = f"about {format_duration(left)} left" if in_step <= current else \
            "longer than expected"
        return position, left, note + (f" ({rest[0]})" if rest[0] else "")

    def _tick(self) -> None:
        from tqdm import tqdm
        total = round(sum(self.costs_s.values()), 1)
        bar = tqdm(total=total, desc=self.what, file=sys.stderr, postfix=self._state()[2],
                   bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed} elapsed{postfix}",
                   mininterval=0.0)
        while True:
            position, _, note = self._state()
            bar.n = round(min(position, total), 1)
            bar.set_postfix_str(note, refresh=False)
            bar.refresh()
            if self._stop.wait(1.0):
                break
        bar.n = total
        bar.set_postfix_str("done", refresh=False)
        bar.close()

    def __exit__(self, *exc) -> None:
        if self._thread is not None:
            self._stop.set()
            self._thread.join()


def working(what: str, expected_s: float) -> Steps:
    """Elapsed time against an expected duration [s] on stderr while one long call runs that
    reports no progress of its own (:class:`Steps` of one step)::

        with working("skysim diagnose", expected_s):
            report = diagnose(...)
    """
    return Steps(what, {"": expected_s})


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
    (default ``results/<target>``), showing the elapsed time against
    :func:`expected_reproduction_seconds` (:func:`working`), and prints :func:`report_run`
    with ``summarize(result)``. It reports ``run``'s module as its own, where the command
    line finds the study's ``DEFAULT_SEED``."""
    def _reproduce(args) -> int:
        from pathlib import Path
        out = Path(args.out or f"results/{target}")
        with working(f"skysim reproduce {target}",
                     expected_reproduction_seconds(target, args.quick, args.trials)):
            result = run(quick=args.quick, trials=args.trials, seed=args.seed, out=out)
        report_run(title, summarize(result), result["summary"]["elapsed_s"], out, files)
        return 0
    _reproduce.__module__ = run.__module__
    return _reproduce
