"""Exceptions raised by the sky layer.

Every exception names the offending value and says how to fix the problem. All of them
subclass :class:`ValueError` so callers that only guard against bad input keep working.
"""

__all__ = ["NaiveDatetimeError", "SunBelowHorizonError", "InvalidParameterError",
           "InvalidTimeError", "BroadcastError"]


class InvalidParameterError(ValueError):
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
