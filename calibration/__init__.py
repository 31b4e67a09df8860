"""calibration: estimation of headings and sensor parameters from raw signals."""

from .exceptions import (CalibrationError, ConvergenceError, RankDeficientError,
                         TooFewSamplesError)
from .lsq import PairCalibration, fit_pair
from .solve import PAIRS, heading_error_deg, solve_pair, solve_pair_compensated

__all__ = ["CalibrationError", "ConvergenceError", "RankDeficientError", "TooFewSamplesError",
           "PairCalibration", "fit_pair", "PAIRS", "solve_pair",
           "solve_pair_compensated", "heading_error_deg"]
