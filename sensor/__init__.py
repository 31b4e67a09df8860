"""sensor: instruments that sample a sky and produce raw signals."""

from skysim._lazy import lazy_namespace

_EXPORTS = {
    "CompoundEyeSensor": ".compound_eye",
    "Unit": ".compound_eye",
    "patent_configuration": ".compound_eye",
    "ring_configuration": ".compound_eye",
    "with_random_installation_errors": ".compound_eye",
    "Daq": ".daq",
    "OpponentErrors": ".errors",
    "WATER_TYPES": ".illuminance",
    "DepthBeyondValidationWarning": ".illuminance",
    "IncidentLight": ".illuminance",
    "OutsideSnellWindowError": ".illuminance",
    "WaterType": ".illuminance",
    "sky_light": ".illuminance",
    "underwater_light": ".illuminance",
    "AccelSpec": ".imu",
    "GyroSpec": ".imu",
    "ImuSpec": ".imu",
    "InvalidRateError": ".imu",
    "Measurement": ".measurement",
    "MeasurementFormatError": ".measurement",
    "read_measurement": ".measurement",
    "CHANNEL_ANGLES_DEG": ".opponent",
    "OpponentSensor": ".opponent",
    "channel_outputs": ".opponent",
    "PhotodiodeChannels": ".photodiode",
    "opponent_log_ratio": ".photodiode",
    "photodiode_signal": ".photodiode",
    "three_pair_outputs": ".photodiode",
    "PhotodiodeData": ".photodiodes_io",
    "PhotodiodeFormatError": ".photodiodes_io",
    "read_photodiodes": ".photodiodes_io",
    "write_photodiodes": ".photodiodes_io",
    "TrajectoryTooShortError": ".platform",
    "dynamic_trajectory": ".platform",
    "sample_run": ".platform",
    "static_trajectory": ".platform",
}
"""Public name -> submodule defining it (imported on first access)."""

__all__ = ["Daq", "OpponentErrors", "Measurement", "MeasurementFormatError",
           "read_measurement", "CHANNEL_ANGLES_DEG", "OpponentSensor", "channel_outputs",
           "CompoundEyeSensor", "Unit", "patent_configuration", "ring_configuration",
           "with_random_installation_errors", "PhotodiodeData", "PhotodiodeFormatError",
           "read_photodiodes", "write_photodiodes", "PhotodiodeChannels", "photodiode_signal",
           "opponent_log_ratio", "three_pair_outputs", "WATER_TYPES", "IncidentLight",
           "DepthBeyondValidationWarning", "OutsideSnellWindowError", "WaterType", "sky_light",
           "underwater_light",
           "AccelSpec", "GyroSpec", "ImuSpec", "InvalidRateError", "TrajectoryTooShortError",
           "dynamic_trajectory", "sample_run", "static_trajectory"]

__getattr__, __dir__ = lazy_namespace(__name__, _EXPORTS)
