"""Sim-to-real gap diagnosis: where a model disagrees with data, which effect explains it, how
far it closes the gap; one method for every instrument (``docs/diagnosis.md``).

- :mod:`.core`: folds by whole block, noise floor, held-out score, verdict, shrink with its
  uncertainty, slices (one formula each);
- :mod:`.protocol`: what an instrument adapter and a candidate effect implement;
- adapters: :mod:`.three_pair` (three-pair sensor tables, with :mod:`.three_pair_data` and
  :mod:`.three_pair_fit`), :mod:`.sky` (sky fields), :mod:`.rings` (multi-unit photodiode
  instruments, through :mod:`calibration.photodiode_diagnosis`);
- :mod:`.report`: :class:`DiagnosisReport` (schema ``skysim.diagnosis/3``) and its readers
  of the earlier report dicts (:mod:`.legacy`), markdown (:mod:`.markdown`);
- :func:`diagnose` (:mod:`.api`): the one entry point.
"""

from .api import diagnose
from .camera import CameraFrame, CameraFrames, CameraInputError, diagnose_camera
from .core import Thresholds, assign_folds, decide, noise_floor
from .errors import (
    AllNaNChannelError,
    DiagnosisError,
    EffectUnavailableError,
    InsufficientDataError,
    MissingSiteError,
    ReportFormatError,
    SingleHeadingError,
    ThresholdsError,
    UnsupportedInstrumentError,
)
from .fit_result import FitResult
from .report import (
    DIAGNOSIS_SCHEMA,
    LEGACY_SCHEMA,
    Candidate,
    DiagnosisReport,
    Slice,
    Verdict,
)
from .three_pair import DEFAULT_CANDIDATES, cross_validate, diagnose_three_pair
from .three_pair_data import (
    DiagnosisData,
    data_from_photodiodes,
    data_from_table,
    load_diagnosis_data,
)
from .three_pair_data import (
    _daq_saturation_V as _daq_saturation_V,  # the DAQ rails, tested on their own
)
from .three_pair_fit import fit_model

noise_floor_V = noise_floor
"""The noise floor of three-pair residuals in volts: :func:`.core.noise_floor`."""

__all__ = [
    "DEFAULT_CANDIDATES",
    "DIAGNOSIS_SCHEMA",
    "LEGACY_SCHEMA",
    "AllNaNChannelError",
    "CameraFrame",
    "CameraFrames",
    "CameraInputError",
    "Candidate",
    "DiagnosisData",
    "DiagnosisError",
    "DiagnosisReport",
    "EffectUnavailableError",
    "FitResult",
    "InsufficientDataError",
    "MissingSiteError",
    "ReportFormatError",
    "SingleHeadingError",
    "Slice",
    "Thresholds",
    "ThresholdsError",
    "UnsupportedInstrumentError",
    "Verdict",
    "assign_folds",
    "cross_validate",
    "data_from_photodiodes",
    "data_from_table",
    "decide",
    "diagnose",
    "diagnose_camera",
    "diagnose_three_pair",
    "fit_model",
    "load_diagnosis_data",
    "noise_floor",
    "noise_floor_V",
]
