"""calibration: estimation of headings and sensor parameters from raw signals."""

from skysim._lazy import lazy_namespace

_EXPORTS = {
    "NonUnitQuaternionError": ".attitude",
    "attitude_error_deg": ".attitude",
    "estimate_attitude": ".attitude",
    "ChannelModel": ".dark_current",
    "DarkCurrentNotIdentifiableError": ".dark_current",
    "calibrate_dark_current": ".dark_current",
    "solve_combined": ".dark_current",
    "DiagnosisReport": ".diagnosis",
    "diagnose": ".diagnosis",
    "solve_opponent": ".dark_current",
    "CalibrationError": ".exceptions",
    "ConvergenceError": ".exceptions",
    "RankDeficientError": ".exceptions",
    "TooFewSamplesError": ".exceptions",
    "calibrate_installation": ".installation",
    "BatchPairCalibration": ".lsq",
    "PairCalibration": ".lsq",
    "fit_pair": ".lsq",
    "fit_pairs": ".lsq",
    "PAIRS": ".solve",
    "heading_error_deg": ".solve",
    "solve_pair": ".solve",
    "solve_pairs": ".solve",
    "solve_pair_compensated": ".solve",
}
"""Public name -> submodule defining it (imported on first access)."""

__all__ = ["CalibrationError", "ConvergenceError", "RankDeficientError", "TooFewSamplesError",
           "PairCalibration", "BatchPairCalibration", "fit_pair", "fit_pairs",
           "calibrate_installation", "PAIRS", "solve_pair", "solve_pairs", "solve_pair_compensated",
           "heading_error_deg", "ChannelModel", "DarkCurrentNotIdentifiableError",
           "calibrate_dark_current", "solve_combined", "solve_opponent",
           "NonUnitQuaternionError", "attitude_error_deg", "estimate_attitude",
           "DiagnosisReport", "diagnose"]

__getattr__, __dir__ = lazy_namespace(__name__, _EXPORTS)
