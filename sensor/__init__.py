"""sensor: instruments that sample a sky and produce raw signals."""

from .daq import Daq
from .errors import OpponentErrors
from .measurement import Measurement, MeasurementFormatError, read_measurement
from .opponent import CHANNEL_ANGLES_DEG, OpponentSensor, channel_outputs

__all__ = ["Daq", "OpponentErrors", "Measurement", "MeasurementFormatError",
           "read_measurement", "CHANNEL_ANGLES_DEG", "OpponentSensor", "channel_outputs"]
