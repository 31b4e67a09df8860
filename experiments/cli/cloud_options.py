"""The ``--clouds`` options of the commands that image or sample a sky
(:mod:`experiments.workflows.cloud_options`, shared by every layer)."""

from experiments.workflows.cloud_options import *  # noqa: F401,F403
from experiments.workflows.cloud_options import __all__  # noqa: F401
