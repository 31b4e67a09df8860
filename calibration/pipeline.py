"""Calibrate a measurement table (schema "skysim.measurement/1") end to end.

The reference polarization azimuth of each sample is ``phi = wrap(heading - sun azimuth)``
evaluated at that sample's own time (DESIGN.md); more generally the heading minus the
azimuth perpendicular to the zenith E-vector of the chosen sky model. The DoP *shape* comes
from the sky model with ``d_max = 1`` and the LSM fits its scale (``d_max``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sensor.measurement import Measurement
from sensor.opponent import zenith_polarization
from skysim.exceptions import SkysimError
from skysim.sky import RayleighSky, Sky

from .lsq import PairCalibration, fit_pair
from .solve import PAIRS, heading_error_deg, solve_pair

__all__ = ["DeadChannelError", "MeasurementCalibration", "reference_polarization",
           "calibrate_measurement", "check_live_channels"]

DEAD_SPREAD_V = 1e-6
"""[V] A channel whose outputs span less than this over a table is dead or stuck: a live
channel swings by ~0.1-1 V over a 180-deg sweep (eq. 2 at d = 0.3-0.8); 1 uV is 1/300 of
one 16-bit LSB on +/-10 V."""


class DeadChannelError(SkysimError, ValueError):
    """A channel's outputs do not change over the table (dead, stuck or disconnected)."""


def check_live_channels(measurement: Measurement, pairs=PAIRS) -> None:
    """Raise :class:`DeadChannelError` naming every channel of ``pairs`` whose outputs span
    less than :data:`DEAD_SPREAD_V`, with its value (a constant channel makes the LSM's
    Jacobian singular, which would otherwise be reported as a geometry problem)."""
    from sensor.measurement import CHANNEL_COLUMNS
    U = measurement.channels
    used = sorted({c for pair in pairs for c in pair})
    dead = [k for k in used if np.ptp(U[:, k - 1]) < DEAD_SPREAD_V]
    if dead:
        what = ", ".join(f"{CHANNEL_COLUMNS[k - 1]} (constant {U[0, k - 1]:.6g} V)"
                         for k in dead)
        raise DeadChannelError(
            f"dead or stuck channel(s) over all {len(U)} samples: {what}; check the wiring "
            "and the acquisition, or calibrate only the pairs without them")


def reference_polarization(measurement: Measurement, sky: Sky | None = None):
    """Reference phi [deg] and DoP shape of every sample of a measurement table.

    Raises
    ------
    SunBelowHorizonError
        If a sample was taken with the sun below the horizon.
    """
    sky = sky or RayleighSky(dmax=1.0)
    t = measurement.table
    phi, dop, sun_el, sun_az = zenith_polarization(
        sky, measurement.site, t["time"], t["heading_deg"].to_numpy(dtype=float))
    return phi, dop, sun_el, sun_az


@dataclass(frozen=True)
class MeasurementCalibration:
    """Per-pair calibrations of one table, with in-sample heading errors."""

    pairs: dict
    phi_reference_deg: np.ndarray
    raw_error_deg: dict
    compensated_error_deg: dict

    def summary_rows(self) -> list[dict]:
        rows = []
        for pair, cal in self.pairs.items():
            raw = self.raw_error_deg[pair]
            comp = self.compensated_error_deg[pair]
            row = {"pair": f"{pair[0]}-{pair[1]}",
                   "raw_3sigma_deg": float(3 * np.sqrt(np.mean(raw ** 2))),
                   "raw_max_abs_deg": float(np.max(np.abs(raw))),
                   "compensated_3sigma_deg": float(3 * np.sqrt(np.mean(comp ** 2)))}
            d = cal.to_dict()
            for name, value in d["parameters"].items():
                row[name] = value
                row[name + "_se"] = d["standard_errors"][name]
            rows.append(row)
        return rows


def calibrate_measurement(measurement: Measurement, pairs=PAIRS, sky: Sky | None = None,
                          fit_dop_scale: bool = True) -> MeasurementCalibration:
    """Fit every pair of a measurement table by the LSM of Yang et al. (2014).

    Raises :class:`DeadChannelError` for a constant channel, the errors of
    :func:`calibration.lsq.fit_pair` (too few samples, rank deficiency, non-convergence) and
    of :func:`reference_polarization`.
    """
    check_live_channels(measurement, pairs)
    phi, shape, _, _ = reference_polarization(measurement, sky)
    U = measurement.channels
    fits: dict[tuple, PairCalibration] = {}
    raw, comp = {}, {}
    for pair in pairs:
        pair = tuple(pair)
        cal = fit_pair(phi, U, pair, shape, fit_dop_scale=fit_dop_scale)
        fits[pair] = cal
        raw[pair] = heading_error_deg(solve_pair(U, pair)[0], phi)
        comp[pair] = heading_error_deg(cal.solve(U)[0], phi)
    return MeasurementCalibration(fits, phi, raw, comp)
