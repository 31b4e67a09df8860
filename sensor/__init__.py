"""sensor: instruments that sample a sky and produce raw signals."""

from .compound_eye import (CompoundEyeSensor, Unit, patent_configuration, ring_configuration,
                           with_random_installation_errors)
from .daq import Daq
from .errors import OpponentErrors
from .measurement import Measurement, MeasurementFormatError, read_measurement
from .opponent import CHANNEL_ANGLES_DEG, OpponentSensor, channel_outputs
from .photodiodes_io import (PhotodiodeData, PhotodiodeFormatError, read_photodiodes,
                             write_photodiodes)

__all__ = ["Daq", "OpponentErrors", "Measurement", "MeasurementFormatError",
           "read_measurement", "CHANNEL_ANGLES_DEG", "OpponentSensor", "channel_outputs",
           "CompoundEyeSensor", "Unit", "patent_configuration", "ring_configuration",
           "with_random_installation_errors", "PhotodiodeData", "PhotodiodeFormatError",
           "read_photodiodes", "write_photodiodes"]
