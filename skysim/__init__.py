"""skysim: the sky layer: where the sun is and what polarized light arrives from each direction."""

from ._lazy import lazy_namespace

__version__ = "0.1.0"

_EXPORTS = {
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

__all__ = ["InvalidParameterError", "NaiveDatetimeError", "SunBelowHorizonError", "Sky",
           "SkyField", "RayleighSky", "MultipleScatteringSky", "BerrySky", "CloudField",
           "PartlyCloudySky", "neutral_points",
           "make_sky", "Site", "sun_position", "sun_vector",
           "__version__"]

__getattr__, __dir__ = lazy_namespace(__name__, _EXPORTS)
