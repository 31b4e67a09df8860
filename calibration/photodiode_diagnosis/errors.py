"""Errors of the photodiode-instrument diagnosis (each message says how to fix the input)."""

from __future__ import annotations

from skysim.exceptions import SkysimWarning

from ..diagnosis.errors import DiagnosisError, InsufficientDataError

__all__ = ["InstrumentDataError", "InsufficientDataError", "NoUsableChannelsError",
           "PointingCalibrationError",
           "SunTooLowError", "YawInRadiansWarning"]


class InstrumentDataError(DiagnosisError, ValueError):
    """A photodiode file whose content cannot be diagnosed as it is (names value and row)."""


class NoUsableChannelsError(DiagnosisError, ValueError):
    """After the fault screen too few units keep three or more working photodiodes."""


class SunTooLowError(DiagnosisError, ValueError):
    """The sun is below the twilight limit (-10 deg) at a recorded time: the sky is dark."""


class YawInRadiansWarning(SkysimWarning):
    """Every yaw lies within +-pi (or [0, 2 pi]) while the yaw spans more than 3: the
    ``yaw_deg`` column looks like radians (a full turn then reads as 6.3 deg)."""


class PointingCalibrationError(DiagnosisError, ValueError):
    """A pointing calibration that cannot be used: not a diagnosis report of a photodiode
    instrument, a report without a fitted pointing, or units that do not match."""
