"""Errors raised by estimators and the diagnosis. A fit either succeeds or raises one of these:
never a NaN. All are :class:`skysim.exceptions.SkysimError` (``from skysim import
SkysimError`` catches them)."""

from skysim.exceptions import SkysimError

__all__ = ["CalibrationError", "TooFewSamplesError", "RankDeficientError", "ConvergenceError",
           "DiagnosisError"]


class CalibrationError(SkysimError, RuntimeError):
    """Base class of estimation failures (a :class:`skysim.exceptions.SkysimError`)."""


class TooFewSamplesError(CalibrationError, ValueError):
    """Fewer samples than parameters: the least-squares problem is under-determined."""


class RankDeficientError(CalibrationError):
    """The normal matrix is singular: some parameter is not observable from these samples
    (e.g. every sample at the same heading). Spread the headings over [-90, 90) deg."""


class ConvergenceError(CalibrationError):
    """The iteration did not converge; ``last_step`` holds the size of the last update."""

    def __init__(self, message: str, last_step: float | None = None, iterations: int = 0):
        super().__init__(message)
        self.last_step = last_step
        self.iterations = iterations


class DiagnosisError(CalibrationError):
    """Base class of diagnosis failures caused by the data (the message says how to fix it);
    :mod:`calibration.diagnosis.errors` lists its subclasses. Defined here, with the other
    estimation errors, so that :mod:`calibration.effects` can derive from it without importing
    the diagnosis package."""
