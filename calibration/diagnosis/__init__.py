"""Sim-to-real gap diagnosis: where a model disagrees with data, which effect explains it, how
far it closes the gap; one method for every instrument (``docs/diagnosis.md``).

- :mod:`.judge`: the method, run once for every instrument (folds, held-out scores, the
  paired judge, the verdict and the shrink), around the fits an adapter supplies;
- :mod:`.core`: folds by whole block, noise floor, held-out score, verdict, shrink with its
  uncertainty, slices (one formula each; slice shares in :mod:`.shares`);
- :mod:`.protocol`: what an instrument adapter and a candidate effect implement;
- adapters: :mod:`.three_pair` (three-pair sensor tables, with :mod:`.three_pair_data` and
  :mod:`.three_pair_fit`), :mod:`.sky` (sky fields), :mod:`.rings` (multi-unit photodiode
  instruments, through :mod:`calibration.photodiode_diagnosis`);
- :mod:`.report`: :class:`DiagnosisReport` (schema ``skysim.diagnosis/3``) and its readers
  of the earlier report dicts (:mod:`.legacy`), markdown (:mod:`.markdown`);
- :func:`diagnose` (:mod:`.api`): the one entry point.
"""

from skysim._lazy import lazy_namespace

_EXPORTS = {
    "diagnose": ".api",
    **dict.fromkeys(("CameraFrame", "CameraFrames", "CameraInputError", "diagnose_camera"),
                    ".camera"),
    **dict.fromkeys(("Thresholds", "assign_folds", "decide", "noise_floor"), ".core"),
    **dict.fromkeys(("AllNaNChannelError", "DiagnosisError", "EffectUnavailableError",
                     "InsufficientDataError", "MissingSiteError", "ReportFormatError",
                     "SingleHeadingError", "ThresholdsError", "UnsupportedInstrumentError"),
                    ".errors"),
    "FitResult": ".fit_result",
    **dict.fromkeys(("DIAGNOSIS_SCHEMA", "LEGACY_SCHEMA", "Candidate", "DiagnosisReport",
                     "Slice", "Verdict"), ".report"),
    **dict.fromkeys(("DEFAULT_CANDIDATES", "cross_validate", "diagnose_three_pair"),
                    ".three_pair"),
    **dict.fromkeys(("DiagnosisData", "data_from_photodiodes", "data_from_table",
                     "load_diagnosis_data", "_daq_saturation_V"), ".three_pair_data"),
    "fit_model": ".three_pair_fit",
}
"""Each public name and the submodule that defines it, imported on first use (PEP 562), so
that importing one submodule (a ring module importing :mod:`.core`) does not import every
adapter, and no import cycle runs through this package."""

_getattr, __dir__ = lazy_namespace(__name__, _EXPORTS)


def __getattr__(name: str):
    if name == "noise_floor_V":   # the noise floor of three-pair residuals in volts
        return _getattr("noise_floor")
    return _getattr(name)


__all__ = sorted(n for n in _EXPORTS if not n.startswith("_")) + ["noise_floor_V"]
