"""Errors of the sim-to-real gap diagnosis (each message says how to fix the input).

Every diagnosis error is a :class:`DiagnosisError`, itself a
:class:`calibration.exceptions.CalibrationError` (and so a :class:`skysim.exceptions.SkysimError`);
those caused by bad input are also :class:`ValueError`. An unknown candidate effect is
:class:`calibration.effects.UnknownEffectError`, a :class:`DiagnosisError` too.
"""

from __future__ import annotations

from sensor.measurement import MeasurementFormatError

from ..exceptions import DiagnosisError, RankDeficientError, TooFewSamplesError

__all__ = ["AllNaNChannelError", "DiagnosisError", "EffectUnavailableError",
           "InsufficientDataError", "MissingSiteError", "ReportFormatError",
           "SingleHeadingError", "ThresholdsError", "UnsupportedInstrumentError"]


class InsufficientDataError(DiagnosisError, TooFewSamplesError):
    """Too little data for a held-out split (fewer than two usable sweeps or time blocks)."""


class SingleHeadingError(DiagnosisError, RankDeficientError):
    """All samples share (nearly) one heading: the mounting errors are not observable."""


class AllNaNChannelError(DiagnosisError, ValueError):
    """A channel holds no finite value at all."""


class MissingSiteError(DiagnosisError, MeasurementFormatError):
    """The sidecar has no ``site``: the sun, hence the model, cannot be computed."""


class UnsupportedInstrumentError(DiagnosisError, ValueError):
    """Data no instrument adapter of the diagnosis reads (the message lists what is read)."""


class EffectUnavailableError(DiagnosisError, RuntimeError):
    """A candidate effect cannot be evaluated here (a missing optional engine or table, a sun
    outside the range its model holds for); the diagnosis lists it as unavailable."""


class ThresholdsError(DiagnosisError, ValueError):
    """Decision thresholds out of range, or a rule option used without the value it needs
    (:class:`calibration.diagnosis.core.Thresholds`)."""


class ReportFormatError(DiagnosisError, ValueError):
    """A diagnosis report dict of an unknown schema, or missing a required key."""
