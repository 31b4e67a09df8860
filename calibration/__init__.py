"""calibration: estimation of headings and sensor parameters from raw signals."""

from .attitude import NonUnitQuaternionError, attitude_error_deg, estimate_attitude
from .dark_current import (ChannelModel, DarkCurrentNotIdentifiableError,
                           calibrate_dark_current, solve_combined, solve_opponent)
from .exceptions import (CalibrationError, ConvergenceError, RankDeficientError,
                         TooFewSamplesError)
from .installation import calibrate_installation
from .lsq import BatchPairCalibration, PairCalibration, fit_pair, fit_pairs
from .solve import PAIRS, heading_error_deg, solve_pair, solve_pair_compensated

__all__ = ["CalibrationError", "ConvergenceError", "RankDeficientError", "TooFewSamplesError",
           "PairCalibration", "BatchPairCalibration", "fit_pair", "fit_pairs",
           "calibrate_installation", "PAIRS", "solve_pair", "solve_pair_compensated",
           "heading_error_deg", "ChannelModel", "DarkCurrentNotIdentifiableError",
           "calibrate_dark_current", "solve_combined", "solve_opponent",
           "NonUnitQuaternionError", "attitude_error_deg", "estimate_attitude"]
