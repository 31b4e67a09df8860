"""The ``skysim`` command line.

Sub-commands are contributed by modules of the :mod:`experiments` package: every module that
defines ``register(subparsers)`` adds its commands (and ``reproduce`` targets via
``register_reproduce(targets)``, a dict name -> function(args)). Modules keep heavy imports
inside their command functions so that ``skysim --help`` stays fast.
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
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import experiments

__all__ = ["main", "build_parser"]


def _module_names() -> list[str]:
    return sorted(info.name for info in pkgutil.iter_modules(experiments.__path__)
                  if info.name != "cli" and not info.name.startswith("_"))


DEFAULT_SEED = 20140601
"""Seed of a reproduction whose module defines no ``DEFAULT_SEED`` of its own."""


def _run_target(targets: dict, args) -> int:
    """Run a reproduce target; ``--seed`` defaults to its module's ``DEFAULT_SEED``."""
    func = targets[args.target]
    if args.seed is None:
        args.seed = getattr(sys.modules.get(func.__module__), "DEFAULT_SEED", DEFAULT_SEED)
    return func(args)


def build_parser(command: str | None = "") -> argparse.ArgumentParser:
    """The ``skysim`` parser; ``command`` (a sub-command name, or None for none) imports only
    the modules that command needs and lists the others from a static index (fast start-up).
    The default builds the whole parser, importing every command module."""
    names = _module_names()
    wanted, index = names, None
    if command != "":
        from ._command_index import read_index
        index = read_index(Path(experiments.__path__[0]), names)
        wanted = index.modules_for(command)
        wanted = names if wanted is None else wanted
    modules = {n: importlib.import_module(f"experiments.{n}") for n in names if n in wanted}
    parser = argparse.ArgumentParser(
        prog="skysim", description="Skylight-polarization simulator and virtual sensor testbed.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    targets: dict = {}
    for mod in modules.values():
        if hasattr(mod, "register_reproduce"):
            mod.register_reproduce(targets)
    rep = sub.add_parser("reproduce", help="run a published experiment's reproduction",
                         description="Run a scripted reproduction; writes tables and figures.")
    rep.add_argument("target", choices=sorted(targets), help="which experiment")
    rep.add_argument("--trials", type=int, default=None,
                     help="Monte-Carlo trials (default: the target's own)")
    rep.add_argument("--seed", type=int, default=None,
                     help="master random seed (default: the target's DEFAULT_SEED)")
    rep.add_argument("--quick", action="store_true",
                     help="a small, fast run (few trials) for smoke tests")
    rep.add_argument("--out", default=None, help="output folder (default results/<target>)")
    rep.add_argument("--data", default=None, metavar="DIR",
                     help="folder of recorded sessions (real-sky-compass; default: the "
                          "reference recordings beside the checkout)")
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


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(next((a for a in argv if not a.startswith("-")), None))
    args = parser.parse_args(argv)
    try:
        rc = args.func(args)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        print(f"skysim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    return int(rc or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
