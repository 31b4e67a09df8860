"""Exceptions and warnings of skysim: the roots :class:`SkysimError` and :class:`SkysimWarning`,
and the errors of the sky layer.

Every error skysim (with :mod:`sensor`, :mod:`calibration` and the workflows) raises on bad
input derives from :class:`SkysimError`, so one clause catches them all::

    from skysim import SkysimError

    try:
        sky = make_sky(model)
    except SkysimError as exc:     # a bad value, a malformed file, an estimate that failed
        print(f"error: {exc}")

Each class also keeps the built-in base that says what kind of failure it is, so that code
catching the built-in keeps working: :class:`ValueError` for a bad value or a malformed file
(:class:`InvalidParameterError`, :class:`FileFormatError`), :class:`RuntimeError` for an
estimation that failed (:class:`calibration.exceptions.CalibrationError`), :class:`OSError`
for a missing or unwritable file (:class:`MissingFileError`,
:class:`skysim.io.OutputPathError`), :class:`ImportError` for a missing optional package
(:class:`MissingDependencyError`). Every message names the offending
value and says how to fix the problem. Exceptions of the built-in classes themselves mean a
bug in skysim, not bad input.

Every warning skysim issues derives from :class:`SkysimWarning` (a :class:`UserWarning`):
``warnings.simplefilter("error", SkysimWarning)`` turns them all into errors.
"""

__all__ = ["SkysimError", "SkysimWarning", "NaiveDatetimeError", "SunBelowHorizonError",
           "InvalidParameterError", "InvalidTimeError", "BroadcastError", "FileFormatError",
           "MissingFileError",
           "MissingDependencyError", "UnsupportedOperationError"]


class SkysimError(Exception):
    """Root of every error skysim raises on bad input (each subclass adds a built-in base)."""


class SkysimWarning(UserWarning):
    """Root of every warning skysim issues: a result computed where a model is less certain
    (the message says where and by how much)."""


class InvalidParameterError(SkysimError, ValueError):
    """A parameter is outside its valid range or set (latitude, d_max, tau, a model name, ...)."""


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


class FileFormatError(SkysimError, ValueError):
    """An input file whose content does not follow its format (a table, an image, a JSON
    sidecar): the message names the file and the field, row or byte that is wrong."""


class MissingFileError(SkysimError, FileNotFoundError):
    """An input file (a data file, its sidecar, a reference table, a configuration) is not
    there; the message names the path and what it should hold."""


class MissingDependencyError(SkysimError, ImportError):
    """An optional package a feature needs is not installed; the message gives the command
    that installs it (:func:`skysim.extras.missing_extra_message`)."""


class UnsupportedOperationError(SkysimError, NotImplementedError):
    """A model asked for something it does not provide (e.g. an absolute radiance from a
    model whose radiance has no stated unit)."""
