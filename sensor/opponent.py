"""The three-pair polarization-opponent sensor of Yang et al. (2014).

Each channel ``i`` is a polarization-opponent unit: two photodiodes behind orthogonal
polarizers feed a log-ratio amplifier. With the channel angles ``a = (60, 0, 120)`` deg for
``(U1, U2, U3)``, the output is eqs. (2)-(3) of [1]_::

    U_i = g * ( log10( (1 + d cos 2(phi + a_i + dth_{2i-1}))
                     / (1 - d cos 2(phi + a_i + dth_{2i})) ) + f_i ) + v_i

with gain ``g = 0.5``, degree of polarization ``d`` and polarization azimuth ``phi`` (the
heading of the sensor's reference axis minus the azimuth of the direction perpendicular to
the zenith E-vector; for a Rayleigh sky, heading minus sun azimuth).

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, "Analysis and compensation of angle errors of
   polarization navigation sensors", Opt. Precision Eng. 22(6):1424-1429 (2014),
   doi:10.3788/OPE.20142206.1424, eqs. (2)-(3).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from skysim import __version__
from skysim.geometry import wrap_axial_deg
from skysim.sky import Sky
from skysim.sun import Site, as_utc_index, sun_vector
from skysim.geometry import elevation_azimuth
from skysim.validation import check_dop, check_finite

from .daq import Daq
from .errors import OpponentErrors
from .measurement import MEASUREMENT_SCHEMA, Measurement

__all__ = ["CHANNEL_ANGLES_DEG", "GAIN", "opponent_output", "channel_outputs",
           "zenith_polarization", "OpponentSensor"]

CHANNEL_ANGLES_DEG = np.array([60.0, 0.0, 120.0])
"""Channel angles ``a_i`` [deg] of U1, U2, U3 (paper order)."""

GAIN = 0.5
"""Log-ratio amplifier gain [V per decade] of the paper's sensor."""


def opponent_output(phi_deg, dop, angle_deg, e1_deg, e2_deg, f, gain: float = GAIN):
    """One opponent channel, eq. (2) of [1]_, broadcast over all arguments [V].

    ``angle_deg`` is the channel angle ``a_i``; ``e1_deg``, ``e2_deg`` the mounting errors of
    its numerator and denominator photodiodes; ``f`` its transmittance term. No input checks
    (hot path of the estimators): use :func:`channel_outputs` for validated input.
    """
    x1 = np.radians(phi_deg + angle_deg + e1_deg)
    x2 = np.radians(phi_deg + angle_deg + e2_deg)
    return gain * (np.log10((1.0 + dop * np.cos(2.0 * x1)) / (1.0 - dop * np.cos(2.0 * x2))) + f)


def channel_outputs(phi_deg, dop, misalignment_deg=(0.0,) * 6, transmittance=(0.0,) * 3,
                    gain: float = GAIN) -> np.ndarray:
    """Noise-free channel outputs ``U_1..U_3`` [V], eqs. (2)-(3) of [1]_.

    Parameters
    ----------
    phi_deg : array-like
        Polarization azimuth [deg].
    dop : array-like
        Degree of polarization, 0 < d < 1 (broadcast against ``phi_deg``).
    misalignment_deg : array (..., 6)
        ``dtheta_1..dtheta_6`` [deg]; leading axes broadcast against
        ``broadcast(phi, dop).shape`` (e.g. ``(trials, 1, 6)`` for ``phi`` of shape
        ``(trials, n)``: one sensor per Monte-Carlo trial).
    transmittance : array (..., 3)
        ``f_1..f_3`` [log10 units], broadcast like ``misalignment_deg``.
    gain : float
        Amplifier gain [V/decade].

    Returns
    -------
    ndarray, shape ``broadcast(phi, dop, misalignment[..., 0]).shape + (3,)``.

    Raises
    ------
    InvalidParameterError
        If any ``d`` is not in (0, 1).
    """
    d = check_dop("dop", dop)[..., None]
    phi = check_finite("phi_deg", phi_deg)[..., None]
    mis = check_finite("misalignment_deg", misalignment_deg)
    f = check_finite("transmittance", transmittance)
    return opponent_output(phi, d, CHANNEL_ANGLES_DEG, mis[..., 0::2], mis[..., 1::2], f,
                           gain)


def zenith_polarization(sky: Sky, site: Site, times, headings_deg):
    """Polarization azimuth [deg] and DoP seen by a zenith-pointing sensor.

    ``phi`` is the heading of the reference axis minus the azimuth of the direction
    perpendicular to the zenith E-vector, wrapped to [-90, 90); each sample's sun comes
    from its own time.

    Returns
    -------
    phi_deg, dop, sun_elevation_deg, sun_azimuth_deg : ndarrays of shape (n,)
    """
    headings = check_finite("headings_deg", headings_deg)
    vec, _ = sun_vector(times, site)
    sun_el, sun_az = elevation_azimuth(vec)
    headings = np.broadcast_to(headings, sun_el.shape)
    fld = sky.field(90.0, headings, sun_el, sun_az)
    e = fld.e_vector
    e_azimuth = np.degrees(np.arctan2(e[..., 0], e[..., 1]))
    phi = wrap_axial_deg(headings - e_azimuth - 90.0)
    return phi, fld.dop, sun_el, sun_az


@dataclass(frozen=True)
class OpponentSensor:
    """A three-pair sensor pointing at the zenith, with injected errors and a DAQ."""

    errors: OpponentErrors = field(default_factory=OpponentErrors)
    gain: float = GAIN
    daq: Daq = field(default_factory=Daq)

    def describe(self) -> dict:
        return {"type": "three-pair opponent", "channel_angles_deg": CHANNEL_ANGLES_DEG.tolist(),
                "channel_order": ["U1 (60 deg)", "U2 (0 deg)", "U3 (120 deg)"],
                "gain_V_per_decade": self.gain, "daq": self.daq.to_dict()}

    def sample(self, sky: Sky, site: Site, times, headings_deg, rng: np.random.Generator,
               *, seed=None, include_truth: bool = True, sweep=None) -> Measurement:
        """Simulate a measurement table (schema "skysim.measurement/1").

        Parameters
        ----------
        sky : Sky
        site : Site
        times : timezone-aware times, length n
        headings_deg : array (n,)
            True heading of the reference axis [deg]. The recorded ``heading_deg`` adds the
            turntable reading error.
        rng : numpy.random.Generator
        seed : optional
            Recorded in the sidecar (the seed ``rng`` was made from).
        include_truth : bool
            Add ``true_phi_deg`` and ``true_dop`` columns (kept as metadata by readers).
        sweep : array (n,), optional
            Acquisition group labels.

        Raises
        ------
        SunBelowHorizonError
            If the sun is below the horizon at any sample time.
        """
        err = self.errors
        phi, dop, sun_el, _ = zenith_polarization(sky, site, times, headings_deg)
        u = channel_outputs(phi, dop, err.misalignment_deg, err.transmittance, self.gain)
        u = u + rng.standard_normal(u.shape) * np.asarray(err.noise_V)
        u, _ = self.daq.acquire(u)
        n = len(phi)
        heading_rec = np.broadcast_to(np.asarray(headings_deg, dtype=float), (n,)) \
            + err.turntable_error_deg * rng.standard_normal(n)
        idx = as_utc_index(times)
        tz = getattr(times, "tz", None) or getattr(getattr(times, "dt", None), "tz", None)
        table = pd.DataFrame({"time": idx.tz_convert(tz) if tz is not None else idx,
                              "heading_deg": heading_rec,
                              "U1_V": u[:, 0], "U2_V": u[:, 1], "U3_V": u[:, 2]})
        if sweep is not None:
            table["sweep"] = np.broadcast_to(np.asarray(sweep), (n,))
        if include_truth:
            table["true_phi_deg"] = phi
            table["true_dop"] = dop
            table["true_sun_elevation_deg"] = sun_el
        sidecar = {"schema": MEASUREMENT_SCHEMA, "site": site.to_dict(),
                   "sensor": self.describe(),
                   "generator": {"package": "skysim", "version": __version__,
                                 "sky": sky.describe(), "errors": err.to_dict(),
                                 "seed": seed}}
        return Measurement(table, sidecar)
