"""Exceptions of skysim: the root :class:`SkysimError` and those of the sky layer.

Every skysim exception derives from :class:`SkysimError` (``except SkysimError`` catches
anything skysim raises on purpose) and keeps a built-in base that says what kind of failure
it is: :class:`ValueError` for bad input (every exception of this module),
:class:`RuntimeError` for an estimation that failed (:class:`calibration.exceptions.CalibrationError`),
:class:`OSError` for files, :class:`ImportError` for a missing optional engine. Every
exception names the offending value and says how to fix the problem.
"""

__all__ = ["SkysimError", "NaiveDatetimeError", "SunBelowHorizonError",
           "InvalidParameterError", "InvalidTimeError", "BroadcastError"]


class SkysimError(Exception):
    """Root of every exception skysim raises on purpose (subclasses add a built-in base)."""


class InvalidParameterError(SkysimError, ValueError):
    """A physical parameter is outside its valid range (latitude, d_max, tau, albedo, ...)."""


class NaiveDatetimeError(InvalidParameterError):
    """A time has no timezone; skysim never guesses UTC.

    Fix: localise it, e.g. ``pd.Timestamp(t).tz_localize("Asia/Shanghai")`` or
    ``datetime(..., tzinfo=timezone(timedelta(hours=8)))``.
    """


class SunBelowHorizonError(InvalidParameterError):
    """The sun is at or below the horizon where a sunlit sky is required.

    Single-scattering and plane-parallel models of the daylight sky are not valid for a sun
    below the horizon (twilight needs a spherical atmosphere); skysim raises instead of
    returning numbers that look like an answer.
    """


class InvalidTimeError(InvalidParameterError):
    """A time is missing (NaT) or outside the range a model covers.

    Fix: drop or fill missing times before asking for sun positions (e.g.
    ``times.dropna()``), or give the quantity the model cannot supply (such as ``delta_t_s``).
    """


class BroadcastError(InvalidParameterError):
    """Per-sample arrays whose lengths do not broadcast against each other.

    Fix: give a scalar, or a 1-D array with one value per time (or of length 1).
    """
