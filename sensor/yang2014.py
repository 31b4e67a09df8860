"""The instrument of Yang, Zhou, Huang & Liu (2014) [1]_ as skysim simulates it: the error
magnitudes its three-pair polarization-opponent sensors are drawn with, and the rooftop site
where it was measured.

Used by the reproduction of the paper (``skysim reproduce yang2014``), by the commands that
simulate a sensor with random errors (``skysim sample --errors random``, ``skysim generate``),
by the gap-diagnosis benchmark (``skysim gap-benchmark``) and by the studies that borrow its
channel noise and DAQ (dark current, moonlit compass).

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424.
"""

from __future__ import annotations

from dataclasses import dataclass

from skysim.sun import Site

from .errors import OpponentErrors

__all__ = ["ErrorModel", "ERROR_MODEL", "SITE"]


@dataclass(frozen=True)
class ErrorModel:
    """Error magnitudes of a three-pair sensor and its turntable sweep, each with its physical
    motivation (symbols of :class:`sensor.errors.OpponentErrors`; eqs. (2)-(3) of [1]_).

    Attributes
    ----------
    misalignment_max_deg : float
        Polarizer film assembly error, U(-1, 1) deg per polarizer. The paper calls the
        mounting error "less than 1 deg"; hand assembly of film polarizers on a holder is
        typically at that level.
    transmittance_sd : float
        2 % (1 sigma) spread of each photodiode path's transmittance x responsivity:
        polarizer-film transmittance (~1-2 %) and photodiode responsivity (~1-3 % within a
        batch) combine to a few percent.
    noise_range_V : tuple of 2 floats
        Total output noise of each channel [V], referred to the log-amplifier output, drawn
        per channel and sensor from U(0.25, 0.55) mV: the USB-4716's input noise (~1-2 LSB
        rms at +/-10 V, 0.3-0.6 mV) dominates the log amplifier's own noise (tens of uV) and
        the photocurrent shot noise (uV); the spread stands for unit-to-unit differences and
        for the paper not reporting its noise.
    daq_bits, daq_range_V : int, float
        16-bit, +/-10 V (Advantech USB-4716, as in the paper).
    turntable_error_deg : float
        0.01 deg (1 sigma) reading error of a precision turntable.
    dmax_range : tuple of 2 floats
        ``d_max`` of a clear sky, U(0.6, 0.8) per trial (multiple scattering, aerosols and
        ground reflection keep real skies below the single-scattering value of ~0.94).
    n_stops, sweep_duration_s : int, float
        One sweep: 181 turntable stops, 1 deg apart, evenly over 600 s (the paper's
        ~10-minute sweeps over phi in [-90, 90) deg).
    """

    misalignment_max_deg: float = 1.0
    transmittance_sd: float = 0.02
    noise_range_V: tuple = (0.25e-3, 0.55e-3)
    daq_bits: int = 16
    daq_range_V: float = 10.0
    turntable_error_deg: float = 0.01
    dmax_range: tuple = (0.6, 0.8)
    n_stops: int = 181
    sweep_duration_s: float = 600.0

    def draw_errors(self, rng) -> OpponentErrors:
        """One sensor's errors drawn with these magnitudes
        (:meth:`sensor.errors.OpponentErrors.draw`); ``rng`` a :class:`numpy.random.Generator`."""
        return OpponentErrors.draw(rng, misalignment_max_deg=self.misalignment_max_deg,
                                   transmittance_sd=self.transmittance_sd,
                                   noise_range_V=self.noise_range_V,
                                   turntable_error_deg=self.turntable_error_deg)


ERROR_MODEL = ErrorModel()
"""The error magnitudes of the Yang et al. (2014) [1]_ sensor (:class:`ErrorModel`'s defaults),
never tuned to the paper's results."""

SITE = Site(latitude_deg=34 + 8 / 60 + 41 / 3600, longitude_deg=108 + 32 / 60 + 48 / 3600,
            altitude_m=400.0, name="Xi'an rooftop (Yang et al. 2014)")
"""Site of the Yang et al. (2014) [1]_ experiment: 108 deg 32' 48" E, 34 deg 8' 41" N (the
paper's coordinates); altitude ~400 m (Xi'an city elevation; the paper gives none)."""
