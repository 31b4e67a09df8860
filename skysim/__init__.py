"""skysim: the sky layer: where the sun is and what polarized light arrives from each direction.

Errors: every error skysim, :mod:`sensor` and :mod:`calibration` raise on bad input (a value
out of range, a malformed file, an estimate that cannot be made) derives from
:class:`SkysimError`, and every warning they issue from :class:`SkysimWarning`::

    from skysim import SkysimError, make_sky

    try:
        make_sky("foo")
    except SkysimError as exc:
        print(exc)   # unknown sky model 'foo'; valid: ...

Each error also keeps a built-in base (``ValueError`` for bad input, ``RuntimeError`` for a
failed estimation, ``OSError`` for files, ``ImportError`` for a missing optional package):
see :mod:`skysim.exceptions`.
"""

from ._lazy import lazy_namespace

__version__ = "0.1.0"

_EXPORTS = {
    "SkysimError": ".exceptions",
    "SkysimWarning": ".exceptions",
    "InvalidParameterError": ".exceptions",
    "NaiveDatetimeError": ".exceptions",
    "SunBelowHorizonError": ".exceptions",
    "BerrySky": ".berry",
    "CloudField": ".cloud_field",
    "PartlyCloudySky": ".partly_cloudy",
    "MultipleScatteringSky": ".multiple",
    "neutral_points": ".neutral_points",
    "RayleighSky": ".sky",
    "Sky": ".sky",
    "SkyField": ".sky",
    "make_sky": ".sky",
    "Site": ".sun",
    "sun_position": ".sun",
    "sun_vector": ".sun",
}
"""Public name -> submodule defining it (imported on first access: the sun pulls in pandas)."""

__all__ = ["SkysimError", "SkysimWarning", "InvalidParameterError", "NaiveDatetimeError",
           "SunBelowHorizonError", "Sky",
           "SkyField", "RayleighSky", "MultipleScatteringSky", "BerrySky", "CloudField",
           "PartlyCloudySky", "neutral_points",
           "make_sky", "Site", "sun_position", "sun_vector",
           "__version__"]

__getattr__, __dir__ = lazy_namespace(__name__, _EXPORTS)
