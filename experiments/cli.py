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

import experiments

__all__ = ["main", "build_parser"]


def _command_modules():
    for info in sorted(pkgutil.iter_modules(experiments.__path__), key=lambda m: m.name):
        if info.name == "cli" or info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"experiments.{info.name}")
        yield mod


DEFAULT_SEED = 20140601
"""Seed of a reproduction whose module defines no ``DEFAULT_SEED`` of its own."""


def _run_target(targets: dict, args) -> int:
    """Run a reproduce target; ``--seed`` defaults to its module's ``DEFAULT_SEED``."""
    func = targets[args.target]
    if args.seed is None:
        args.seed = getattr(sys.modules.get(func.__module__), "DEFAULT_SEED", DEFAULT_SEED)
    return func(args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="skysim", description="Skylight-polarization simulator and virtual sensor testbed.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    targets: dict = {}
    modules = list(_command_modules())
    for mod in modules:
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
    for mod in modules:
        if hasattr(mod, "register"):
            mod.register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        rc = args.func(args)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        print(f"skysim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    return int(rc or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
