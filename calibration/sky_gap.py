"""Sky-level gap diagnosis: the names of :mod:`calibration.diagnosis.sky` (the sky-field
adapter of the shared diagnosis), importable from here as well."""

from .diagnosis.sky import *  # noqa: F401,F403
from .diagnosis.sky import __all__  # noqa: F401
