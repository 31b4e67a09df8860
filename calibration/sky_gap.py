"""Sky-level gap diagnosis: the names of :mod:`calibration.diagnosis.sky` (the sky-field
adapter of the shared diagnosis), importable from here as well."""

from .diagnosis import sky as _sky
from .diagnosis.sky import *

__all__ = _sky.__all__
