"""sensor: instruments that sample a sky and produce raw signals."""

from .compound_eye import (CompoundEyeSensor, Unit, patent_configuration, ring_configuration,
                           with_random_installation_errors)
from .daq import Daq
from .errors import OpponentErrors
from .illuminance import (WATER_TYPES, IncidentLight, OutsideSnellWindowError, WaterType,
                          sky_light, underwater_light)
from .imu import AccelSpec, GyroSpec, ImuSpec, InvalidRateError
from .measurement import Measurement, MeasurementFormatError, read_measurement
from .opponent import CHANNEL_ANGLES_DEG, OpponentSensor, channel_outputs
from .photodiode import (PhotodiodeChannels, opponent_log_ratio, photodiode_signal,
                         three_pair_outputs)
from .photodiodes_io import (PhotodiodeData, PhotodiodeFormatError, read_photodiodes,
                             write_photodiodes)
from .platform import (TrajectoryTooShortError, dynamic_trajectory, sample_run,
                       static_trajectory)

__all__ = ["Daq", "OpponentErrors", "Measurement", "MeasurementFormatError",
           "read_measurement", "CHANNEL_ANGLES_DEG", "OpponentSensor", "channel_outputs",
           "CompoundEyeSensor", "Unit", "patent_configuration", "ring_configuration",
           "with_random_installation_errors", "PhotodiodeData", "PhotodiodeFormatError",
           "read_photodiodes", "write_photodiodes", "PhotodiodeChannels", "photodiode_signal",
           "opponent_log_ratio", "three_pair_outputs", "WATER_TYPES", "IncidentLight",
           "OutsideSnellWindowError", "WaterType", "sky_light", "underwater_light",
           "AccelSpec", "GyroSpec", "ImuSpec", "InvalidRateError", "TrajectoryTooShortError",
           "dynamic_trajectory", "sample_run", "static_trajectory"]
