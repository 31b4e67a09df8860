"""Argument types of the ``skysim`` command line (:mod:`experiments.workflows.options`, where
the commands of every layer share them): each option is checked when it is parsed, and
argparse reports a bad value as one line with exit code 2 before any work starts."""

from experiments.workflows.options import *  # noqa: F401,F403
from experiments.workflows.options import __all__  # noqa: F401
