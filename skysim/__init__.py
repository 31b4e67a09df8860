"""skysim: the sky layer: where the sun is and what polarized light arrives from each direction."""

from .exceptions import InvalidParameterError, NaiveDatetimeError, SunBelowHorizonError
from .berry import BerrySky
from .multiple import MultipleScatteringSky
from .neutral_points import neutral_points
from .sky import RayleighSky, Sky, SkyField, make_sky
from .sun import Site, sun_position, sun_vector

__version__ = "0.1.0"

__all__ = ["InvalidParameterError", "NaiveDatetimeError", "SunBelowHorizonError", "Sky",
           "SkyField", "RayleighSky", "MultipleScatteringSky", "BerrySky", "neutral_points",
           "make_sky", "Site", "sun_position", "sun_vector",
           "__version__"]
