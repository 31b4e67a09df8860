"""The ``skysim`` command line.

Sub-commands are contributed by the modules of the :mod:`experiments` package and its
subpackages (``cli``, ``workflows``, ``studies``): every module that defines
``register(subparsers)`` adds its commands (and ``reproduce`` targets via
``register_reproduce(targets)``, a dict name -> function(args)). Modules keep heavy imports
inside their command functions so that ``skysim --help`` stays fast.

Errors have one path (:func:`main`). Options are checked when parsed
(:mod:`experiments.cli.argtypes`). Whatever a command raises for bad input (a
:class:`skysim.SkysimError`, the root of the library's errors; a ``ValueError`` of an option
check; an ``OSError`` of the file system) is printed as one line
``skysim CMD: error: ...`` with exit code 2; a missing optional dependency as the command
that installs it into this checkout (:mod:`skysim.extras`); Ctrl-C as ``interrupted`` (exit
130), SIGTERM as ``terminated`` (exit 143), each after the clean-up; a closed pipe (``skysim ... | head``) ends quietly (exit 141, as a process killed by
SIGPIPE); an unexpected exception (a bug) as one ``internal error`` line with exit code 70
(``SKYSIM_TRACEBACK=1`` re-raises it). Files are written atomically (:mod:`skysim.io`), so
none of these leaves a half-written file.
"""

from __future__ import annotations

import os

# The estimators solve many small (batched 6x6 .. 30x30) systems: a multithreaded BLAS only
# adds thread hand-offs (5-100x slower on a busy 2-core machine, measured in the dark-current
# calibration). One BLAS thread per process; sweeps parallelise over processes instead.
# Set before numpy is first imported; a user's own setting wins.
# The radiative-transfer engine (OpenMP) is likewise steadier single-threaded here (0.45 s per
# call vs 0.4-5 s with 2 threads on a busy 2-core machine).
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import importlib  # noqa: E402
import pkgutil  # noqa: E402
import signal  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import experiments
from skysim.exceptions import InvalidParameterError
from experiments.cli.argtypes import output_dir, positive_int, seed

__all__ = ["main", "build_parser", "EXIT_ERROR", "EXIT_INTERRUPTED", "EXIT_TERMINATED",
           "EXIT_BROKEN_PIPE", "EXIT_INTERNAL"]

EXIT_ERROR = 2
"""Exit code of any error in the input (options, files, configurations), as argparse's."""
EXIT_INTERRUPTED = 130
"""Exit code after Ctrl-C (128 + SIGINT, as a shell reports it)."""
EXIT_TERMINATED = 143
"""Exit code after SIGTERM (128 + SIGTERM)."""
EXIT_BROKEN_PIPE = 141
"""Exit code when the reader of the output went away (128 + SIGPIPE)."""
EXIT_INTERNAL = 70
"""Exit code of an unexpected exception, a bug in skysim (``EX_SOFTWARE`` of sysexits.h)."""


def _module_names() -> list[str]:
    """Names, relative to :mod:`experiments` (``"workflows.sweep"``), of the modules that may
    contribute commands: those of the package and of its subpackages, except this one and
    private (``_``) modules."""
    root = Path(experiments.__path__[0])
    names = []
    for info in pkgutil.iter_modules([str(root)]):
        if info.ispkg:
            names += [f"{info.name}.{sub.name}"
                      for sub in pkgutil.iter_modules([str(root / info.name)])
                      if not sub.ispkg and not sub.name.startswith("_")]
        elif not info.name.startswith("_"):
            names.append(info.name)
    return sorted(n for n in names if n != "cli.main")


DEFAULT_SEED = 20140601
"""Seed of a reproduction whose module defines no ``DEFAULT_SEED`` of its own."""


def _run_target(targets: dict, args) -> int:
    """Run a reproduce target; ``--seed`` defaults to its module's ``DEFAULT_SEED``.

    Options the target does not use are errors; the memory of ``--trials`` is checked and
    the expected duration announced before any work; the output folder is replaced as a
    whole (:func:`experiments.workflows.run_folder.replacing_folder`)."""
    from experiments.workflows.progress import check_duration, expected_reproduction_seconds
    from experiments.workflows.run_folder import replacing_folder
    func = targets[args.target]
    for option, attr in (("reference", "takes_reference"), ("data", "takes_data")):
        if getattr(args, option) is not None and not getattr(func, attr, False):
            takers = sorted(n for n, f in targets.items() if getattr(f, attr, False))
            raise InvalidParameterError(f"--{option} applies to {', '.join(takers)}, not {args.target}")
    per_trial = getattr(sys.modules.get(func.__module__), "MEMORY_PER_TRIAL_BYTES", None)
    if per_trial and args.trials:
        from skysim.resources import check_memory
        check_memory(args.trials * per_trial, f"{args.trials} trials of {args.target}",
                     "use fewer --trials")
    if args.seed is None:
        args.seed = getattr(sys.modules.get(func.__module__), "DEFAULT_SEED", DEFAULT_SEED)
    run = {"target": args.target, "quick": bool(args.quick), "trials": args.trials,
           "seed": args.seed}
    from experiments.cli.argtypes import refuse_folder_holding_inputs
    refuse_folder_holding_inputs("--out", args.out or _default_out(args.target),
                                 [("--data", args.data), ("--reference", args.reference)])
    check_duration(expected_reproduction_seconds(args.target, args.quick, args.trials),
                   f"{args.target}" + (f" with --trials {args.trials}" if args.trials else ""),
                   "" if args.quick else "fewer --trials or --quick (a small run of a few "
                                         "seconds to minutes) make it shorter",
                   force=args.force, force_flag="--force")
    with replacing_folder(args.out or _default_out(args.target), run, force=args.force) as out:
        args.out = out
        return func(args)


_DEFAULT_OUT = {"dark-current": "results/dark_current",
                "real-sky-compass": "results/real_sky_compass"}
"""Default output folders that are not ``results/<target>``."""


def _default_out(target: str) -> Path:
    return Path(_DEFAULT_OUT.get(target, f"results/{target}"))


def build_parser(command: str | None = "") -> argparse.ArgumentParser:
    """The ``skysim`` parser; ``command`` (a sub-command name, or None for none) imports only
    the modules that command needs and lists the others from a static index (fast start-up).
    The default builds the whole parser, importing every command module."""
    names = _module_names()
    wanted, index = names, None
    if command != "":
        from .command_index import read_index
        index = read_index(Path(experiments.__path__[0]), names)
        wanted = index.modules_for(command)
        wanted = names if wanted is None else wanted
    modules = {n: importlib.import_module(f"experiments.{n}") for n in names if n in wanted}
    parser = argparse.ArgumentParser(
        prog="skysim", description="Skylight-polarization simulator and virtual sensor testbed.")
    parser.add_argument("--version", action="version", version=f"skysim {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    targets: dict = {}
    for mod in modules.values():
        if hasattr(mod, "register_reproduce"):
            mod.register_reproduce(targets)
    rep = sub.add_parser("reproduce", help="run a published experiment's reproduction",
                         description="Run a scripted reproduction; writes tables and figures.")
    rep.add_argument("target", choices=sorted(targets), help="which experiment")
    rep.add_argument("--trials", type=positive_int, default=None,
                     help="Monte-Carlo trials, >= 1 (default: the experiment's own)")
    rep.add_argument("--seed", type=seed, default=None,
                     help="master random seed, >= 0 (default: the experiment's own)")
    rep.add_argument("--quick", action="store_true",
                     help="a small, fast run (few trials) for smoke tests")
    rep.add_argument("--out", type=output_dir, default=None,
                     help="output folder, replaced as a whole when the run ends (an interrupted "
                          "or failed run leaves the earlier one) (default: results/<target>)")
    rep.add_argument("--force", action="store_true",
                     help="replace an --out folder that holds other files, or a full run by a "
                          "--quick one; run even when the expected duration exceeds a day")
    rep.add_argument("--data", default=None, metavar="DIR",
                     help="real-sky-compass: folder of recorded photodiode sessions; "
                          "moonlit-sky: folder of the FORS2 moonlit-sky table (default: the "
                          "reference data beside the checkout)")
    rep.add_argument("--reference", default=None,
                     help="physical-sky, sky-gap: another copy of the Natraj et al. (2009) "
                          "tables, the file or a folder holding it (default: the tables "
                          "shipped with skysim)")
    rep.set_defaults(func=lambda args: _run_target(targets, args))
    for name in names:
        if name in modules:
            if hasattr(modules[name], "register"):
                modules[name].register(sub)
        else:  # listed from the index, imported only when it runs
            for cmd, (module_name, help_text) in index.commands.items():
                if module_name == name:
                    sub.add_parser(cmd, help=help_text)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("skysim")
    except PackageNotFoundError:  # run from a source tree without installing
        from skysim import __version__
        return __version__


def _missing_extra(exc: ImportError, command: str) -> str | None:
    """The install hint for an optional package that failed to import, else None."""
    from skysim.extras import extra_for_module, missing_extra_message
    name = exc.name or getattr(exc.__cause__, "name", None)
    if extra_for_module(name) is None:
        return None
    return str(exc) if "pip install -e" in str(exc) else missing_extra_message(name, command)


def describe_error(exc: BaseException) -> str:
    """One line for an error: the message, or for a bare ``OSError`` its file and reason."""
    if isinstance(exc, OSError) and exc.strerror and exc.filename:
        return f"{exc.filename}: {exc.strerror}"
    text = str(exc) or type(exc).__name__
    # one line: a library's message may quote a file's bytes (newlines, control characters)
    return " ".join("".join(c if c.isprintable() else " " for c in text).split())


def _quiet_stdout() -> None:
    """After a broken pipe, point stdout at /dev/null so the interpreter's final flush does
    not raise again (Python docs, "Note on SIGPIPE")."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # stdout is not a file (e.g. captured)
        pass


def main(argv=None) -> int:
    """Run ``skysim`` with ``argv``; return the exit code (see the module docstring)."""
    from experiments.workflows.progress import install_warning_format
    from skysim.exceptions import SkysimError
    command = "skysim"
    argv = sys.argv[1:] if argv is None else list(argv)
    install_warning_format()   # a library's warning as one line, not its source line
    previous_term = _stop_on_sigterm()
    try:
        try:
            parser = build_parser(next((a for a in argv if not a.startswith("-")), None))
            args = parser.parse_args(argv)
        except SystemExit as exc:  # argparse: --help, --version, or a usage error (printed)
            return exc.code if isinstance(exc.code, int) else EXIT_ERROR
        command = f"skysim {args.command}"
        rc = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, inside the handlers below
    except Terminated:
        print(f"\n{command}: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        print(f"\n{command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_BROKEN_PIPE
    except ImportError as exc:
        hint = _missing_extra(exc, command)
        if hint is None:
            return _internal_error(command, exc)
        print(f"{command}: error: {hint}", file=sys.stderr)
        return EXIT_ERROR
    except MemoryError:
        print(f"{command}: error: out of memory; use a smaller size (fewer trials, directions "
              "or samples)", file=sys.stderr)
        return EXIT_ERROR
    except (SkysimError, ValueError, OSError) as exc:
        # SkysimError: the library's bad-input errors; ValueError: the command line's own
        # option checks; OSError: the file system (a missing or unreadable file, a full disk)
        print(f"{command}: error: {describe_error(exc)}", file=sys.stderr)
        return EXIT_ERROR
    except Exception as exc:  # a bug
        return _internal_error(command, exc)
    finally:
        if previous_term is not None:
            signal.signal(signal.SIGTERM, previous_term)
    return int(rc or 0)


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a batch scheduler's time limit), raised where the program is so that
    every clean-up runs (temporary files removed, an earlier output folder put back)."""


def _raise_terminated(signum, frame):
    raise Terminated


def _stop_on_sigterm():
    """Turn SIGTERM into :class:`Terminated`; return the previous handler (None when not in
    the main thread, where Python allows no handler)."""
    import threading
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _raise_terminated)


def _internal_error(command: str, exc: Exception) -> int:
    """A bug: one line, or the traceback with ``SKYSIM_TRACEBACK=1``."""
    if os.environ.get("SKYSIM_TRACEBACK"):
        raise exc
    print(f"{command}: internal error: {type(exc).__name__}: {exc} (a bug in skysim; run again "
          "with SKYSIM_TRACEBACK=1 to see where, and report it)", file=sys.stderr)
    return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
