"""Photodiode-level channel model of a polarization-opponent sensor, with dark current.

Generalises the three-pair equation of Yang et al. (2014) [1]_ to the model of the BUAA
dark-current calibration patent [2]_. Photodiode ``i`` behind a (partial) linear polarizer
reads, by Malus's law for partially linearly polarized light [3]_::

    S_i = K_I,i * I * k_i * (1 + eta_i * d * cos 2(chi - p_i)) + D_i

with incident intensity ``I`` (here in lux-equivalent units of scene illuminance), angle of
polarization ``chi`` and degree of polarization ``d``; ``p_i`` the polarizer angle;
``K_I,i`` the intensity response (responsivity) [A/lx]; ``D_i`` the dark current [A]. A
polarizer with principal transmittances ``T1 >= T2`` (extinction ratio ``e = T2/T1``)
transmits ``I/2 [(T1 + T2) + (T1 - T2) d cos 2(chi - p)]`` [3]_, so the extinction-ratio
coefficients are the intensity factor ``k = T1 + T2`` and the polarization-efficiency factor
``eta = (T1 - T2)/(T1 + T2) = (1 - e)/(1 + e)`` (:func:`extinction_factors`); the ideal
polarizer has ``k = 1, eta = 1``.

Opponent channel ``k`` (numerator photodiode ``n``, denominator ``m``) feeds a log-ratio
amplifier with gain ``Ka_k`` [V/decade] and output offset ``V_OSO,k`` [V] [2]_::

    U_k = Ka_k * log10(S_n / S_m) + V_OSO,k

Three-pair sensor (:func:`three_pair_outputs`): channel ``k`` has angle ``a_k`` (60, 0, 120)
deg for (U1, U2, U3); its numerator and denominator photodiodes are mounted at
``alpha = a_k + dth_{2k-1}`` and ``a_k + 90 + dth_{2k}``, measured in the sense of the
polarization azimuth ``phi`` of :mod:`sensor.opponent` (Malus's argument is ``phi + alpha``,
i.e. ``chi = phi`` and ``p = -alpha``). With ``D = 0``, ideal polarizers, ``Ka = 0.5`` and
``V_OSO = 0``::

    U_k = 0.5 * (log10((1 + d cos 2(phi + a_k + dth_{2k-1}))
                      / (1 - d cos 2(phi + a_k + dth_{2k}))) + log10(K_n / K_m))

which is eq. (2) of [1]_ with transmittance term ``f_k = log10(K_n / K_m)``
(:func:`sensor.opponent.channel_outputs`; tested in ``tests/test_photodiode.py``). Unlike the
2014 equation, ``U_k`` now depends on ``I``: the dark current adds ``D/(K k)`` lux-equivalent
of unpolarized light to each photodiode, which pulls the ratio towards ``D_n/D_m`` when
``I`` falls to a few times ``D/(K k)``.

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, "Analysis and compensation of angle errors of
   polarization navigation sensors", Opt. Precision Eng. 22(6):1424-1429 (2014),
   doi:10.3788/OPE.20142206.1424, eqs. (2)-(3).
.. [2] J. Yang, Y. You, P. Hu, X. Liu, L. Guo (Beihang University), "Underwater polarization
   sensor multi-parameter optimization calibration method considering dark current",
   Chinese patent application (2021): photodiode model with intensity response, dark
   current, extinction-ratio coefficients and mounting angle; log amplifier gain and offset.
.. [3] E. Hecht, Optics, 5th ed., Pearson (2017), sect. 8.2 (Malus's law) and 8.3
   (transmittance of imperfect polarizers, extinction ratio).
.. [4] P. Horowitz, W. Hill, The Art of Electronics, 3rd ed. (2015), sect. 8.1.3 (shot noise
   ``sqrt(2 q I B)``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from skysim.exceptions import InvalidParameterError
from skysim.validation import check_finite, check_in_range

from .daq import Daq
from .errors import OpponentErrors
from .opponent import CHANNEL_ANGLES_DEG, GAIN

__all__ = ["InvalidIntensityError", "SaturatedReadingError", "BelowDarkLevelError",
           "ELEMENTARY_CHARGE_C", "extinction_factors", "photodiode_signal", "malus_signal",
           "opponent_log_ratio", "three_pair_signals", "three_pair_outputs", "shot_noise",
           "check_not_saturated", "check_above_dark", "PhotodiodeChannels"]

ELEMENTARY_CHARGE_C = 1.602176634e-19
"""Elementary charge [C] (exact, SI 2019)."""


class InvalidIntensityError(InvalidParameterError):
    """An intensity or a photocurrent is zero, negative or not finite.

    A log-ratio channel needs light (or at least dark current) on both photodiodes; a zero or
    negative intensity is a units or sign error upstream (check the radiance scaling).
    """


class SaturatedReadingError(InvalidParameterError):
    """An ADC reading sits at the converter's rail: the true value is unknown.

    Reduce the amplifier gain or the exposure, or drop the saturated samples explicitly.
    """


class BelowDarkLevelError(InvalidParameterError):
    """A photodiode reading is below its calibrated dark level: no light can explain it.

    Re-measure the dark level (cap the sensor, same temperature) or check the sign/offset of
    the readout.
    """


def _positive(name: str, values, hint: str) -> np.ndarray:
    arr = check_finite(name, values)
    bad = arr <= 0.0
    if bad.any():
        idx = np.flatnonzero(bad)
        raise InvalidIntensityError(
            f"{name} must be > 0; got {arr.ravel()[idx[0]]!r} at flat index {idx[0]}"
            + (f" (and {idx.size - 1} more)" if idx.size > 1 else "") + f". {hint}")
    return arr


def extinction_factors(extinction_ratio, principal_transmittance=1.0):
    """Intensity and polarization-efficiency factors of a partial polarizer [3]_.

    Parameters
    ----------
    extinction_ratio : array-like
        ``e = T2 / T1`` in [0, 1) (0: ideal polarizer; film polarizers 1e-3..1e-2).
    principal_transmittance : array-like
        ``T1`` in (0, 1] [dimensionless].

    Returns
    -------
    k, eta : ndarrays
        ``k = T1 (1 + e)`` (intensity factor, 1 for an ideal polarizer with ``T1 = 1``) and
        ``eta = (1 - e) / (1 + e)`` (polarization efficiency, 1 when ideal).
    """
    e = check_in_range("extinction_ratio", extinction_ratio, 0.0, 1.0, high_open=True)
    t1 = check_in_range("principal_transmittance", principal_transmittance, 0.0, 1.0,
                        low_open=True)
    return t1 * (1.0 + e), (1.0 - e) / (1.0 + e)


def photodiode_signal(intensity, aop_deg, dop, polarizer_deg, *, responsivity=1.0, dark=0.0,
                      extinction_intensity=1.0, extinction_efficiency=1.0) -> np.ndarray:
    """Photodiode output behind a partial linear polarizer, Malus's law plus dark current.

    ``S = responsivity * intensity * k * (1 + eta * dop * cos 2(aop - polarizer)) + dark``
    ([2]_, [3]_); every argument broadcasts.

    Parameters
    ----------
    intensity : array-like
        Incident intensity, > 0 [lx-equivalent, or any unit matching ``responsivity``].
    aop_deg : array-like
        Angle of polarization (E-vector) [deg], same frame and sense as ``polarizer_deg``.
    dop : array-like
        Degree of linear polarization in [0, 1).
    polarizer_deg : array-like
        Transmission axis of the polarizer [deg].
    responsivity : array-like
        Intensity response ``K_I`` [output unit per intensity unit, e.g. A/lx], > 0.
    dark : array-like
        Dark current / dark level ``D`` [output unit], >= 0.
    extinction_intensity, extinction_efficiency : array-like
        ``k`` > 0 and ``eta`` in [0, 1] (:func:`extinction_factors`).

    Returns
    -------
    ndarray
        Photodiode output [same unit as ``responsivity * intensity + dark``].

    Raises
    ------
    InvalidIntensityError
        If an intensity, responsivity or ``k`` is zero or negative.
    InvalidParameterError
        If ``dop`` is outside [0, 1), ``eta`` outside [0, 1] or ``dark`` negative.
    """
    i = _positive("intensity", intensity,
                  "Intensity is scene illuminance [lx] or radiance; check its scaling and sign.")
    r = _positive("responsivity", responsivity, "Responsivity is the photocurrent per lux.")
    k = _positive("extinction_intensity", extinction_intensity,
                  "It is T1 + T2 of the polarizer (1 when ideal).")
    d = check_in_range("dop", dop, 0.0, 1.0, high_open=True)
    eta = check_in_range("extinction_efficiency", extinction_efficiency, 0.0, 1.0)
    dark = check_in_range("dark", dark, 0.0, np.inf,
                          hint="A dark current adds to the signal; a negative one is an offset "
                               "error of the readout.")
    return malus_signal(i, check_finite("aop_deg", aop_deg), d,
                        check_finite("polarizer_deg", polarizer_deg), responsivity=r, dark=dark,
                        extinction_intensity=k, extinction_efficiency=eta)


def malus_signal(intensity, aop_deg, dop, polarizer_deg, *, responsivity=1.0, dark=0.0,
                 extinction_intensity=1.0, extinction_efficiency=1.0) -> np.ndarray:
    """The formula of :func:`photodiode_signal` without its input checks, for inner loops
    (model fits) whose inputs are valid by construction; same arguments, no exceptions."""
    x = np.radians(2.0 * (np.asarray(aop_deg, float) - polarizer_deg))
    return (responsivity * intensity * extinction_intensity
            * (1.0 + extinction_efficiency * dop * np.cos(x)) + dark)


def opponent_log_ratio(signal_a, signal_b, *, gain=GAIN, offset_V=0.0) -> np.ndarray:
    """Log-ratio amplifier output ``gain * log10(a / b) + offset_V`` [V] ([2]_; eq. 2 of [1]_).

    Parameters
    ----------
    signal_a, signal_b : array-like
        Numerator and denominator photocurrents, > 0 [any common unit].
    gain : array-like
        ``Ka`` [V/decade].
    offset_V : array-like
        Output offset ``V_OSO`` [V].

    Raises
    ------
    InvalidIntensityError
        If a current is zero or negative (a log amplifier has no output for it).
    """
    hint = "A log amplifier needs a positive input current (photocurrent plus dark current)."
    a = _positive("signal_a", signal_a, hint)
    b = _positive("signal_b", signal_b, hint)
    return np.asarray(gain, dtype=float) * np.log10(a / b) + np.asarray(offset_V, dtype=float)


def _per_photodiode(name: str, values, default: float) -> np.ndarray:
    """``(..., 6)`` per-photodiode values (a scalar, 6 floats, or one set per leading index,
    e.g. ``(trials, 1, 6)``) as ``(..., 3, 2)``: channel k, numerator/denominator."""
    v = check_finite(name, default if values is None else values)
    if v.ndim == 0 or v.shape[-1] != 6:
        v = np.broadcast_to(v, v.shape[:-1] + (6,) if v.ndim else (6,))
    return v.reshape(v.shape[:-1] + (3, 2))


def three_pair_signals(intensity, phi_deg, dop, *, mounting_error_deg=None, responsivity=None,
                       dark=None, extinction_intensity=None, extinction_efficiency=None):
    """Photodiode outputs of the three-pair sensor, shape ``broadcast(...).shape + (3, 2)``.

    Parameters
    ----------
    intensity : array-like
        Incident intensity, > 0 [lx-equivalent].
    phi_deg : array-like
        Polarization azimuth of :mod:`sensor.opponent` [deg].
    dop : array-like
        Degree of polarization in [0, 1).
    mounting_error_deg : array (..., 6)
        ``dth_1..dth_6`` [deg] (paper order: numerator, denominator of U1, then U2, U3).
        Leading axes broadcast against the samples' shape, e.g. ``(trials, 1, 6)`` for
        ``phi_deg`` of shape ``(trials, n)``: one sensor per Monte-Carlo trial.
    responsivity, dark, extinction_intensity, extinction_efficiency : array (..., 6) each
        Per photodiode, same order and broadcasting (defaults 1, 0, 1, 1).

    Returns
    -------
    ndarray (..., 3, 2)
        ``[..., k, 0]`` numerator and ``[..., k, 1]`` denominator photodiode of channel k.
    """
    mis = _per_photodiode("mounting_error_deg", mounting_error_deg, 0.0)
    alpha = CHANNEL_ANGLES_DEG[:, None] + np.array([0.0, 90.0]) + mis     # (3, 2), sense of phi
    shape = np.broadcast_shapes(np.shape(intensity), np.shape(phi_deg), np.shape(dop))
    expand = (Ellipsis, None, None)
    return photodiode_signal(
        np.broadcast_to(intensity, shape)[expand], np.broadcast_to(phi_deg, shape)[expand],
        np.broadcast_to(dop, shape)[expand], -alpha,
        responsivity=_per_photodiode("responsivity", responsivity, 1.0),
        dark=_per_photodiode("dark", dark, 0.0),
        extinction_intensity=_per_photodiode("extinction_intensity", extinction_intensity, 1.0),
        extinction_efficiency=_per_photodiode("extinction_efficiency", extinction_efficiency,
                                              1.0))


def three_pair_outputs(intensity, phi_deg, dop, *, gain=GAIN, offset_V=0.0,
                       **photodiodes) -> np.ndarray:
    """Channel outputs ``U1..U3`` [V] of the three-pair sensor with the photodiode model.

    Reduces exactly to :func:`sensor.opponent.channel_outputs` (eq. 2 of [1]_) when
    ``dark = 0``, ideal polarizers, ``gain = 0.5``, ``offset_V = 0``, with
    ``transmittance f_k = log10(responsivity_n / responsivity_m)`` (see module docstring).

    Parameters
    ----------
    intensity, phi_deg, dop : array-like
        As :func:`three_pair_signals`.
    gain : float or 3 floats
        ``Ka_k`` [V/decade].
    offset_V : float or 3 floats
        ``V_OSO,k`` [V].
    **photodiodes
        Keyword arguments of :func:`three_pair_signals`.

    Returns
    -------
    ndarray, shape ``broadcast(intensity, phi, dop).shape + (3,)``.
    """
    s = three_pair_signals(intensity, phi_deg, dop, **photodiodes)
    return opponent_log_ratio(s[..., 0], s[..., 1], gain=np.broadcast_to(gain, (3,)),
                              offset_V=np.broadcast_to(offset_V, (3,)))


def shot_noise(current_A, bandwidth_Hz: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian shot noise ``N(0, 2 q I B)`` of photocurrent plus dark current [A] [4]_."""
    i = check_in_range("current_A", current_A, 0.0, np.inf)
    check_in_range("bandwidth_Hz", bandwidth_Hz, 0.0, np.inf)
    return np.sqrt(2.0 * ELEMENTARY_CHARGE_C * i * bandwidth_Hz) * rng.standard_normal(i.shape)


def check_not_saturated(U, daq: Daq) -> np.ndarray:
    """Return ``U`` [V] as an array; raise :class:`SaturatedReadingError` at the ADC rails."""
    u = check_finite("U", U)
    if daq.bits is None:
        return u
    lo, hi = -daq.range_V, daq.range_V - daq.lsb_V
    bad = (u <= lo) | (u >= hi)
    if bad.any():
        idx = np.flatnonzero(bad)
        raise SaturatedReadingError(
            f"ADC reading {u.ravel()[idx[0]]!r} V at flat index {idx[0]} is at the rail of the "
            f"+/-{daq.range_V} V converter" + (f" ({idx.size} saturated)" if idx.size > 1 else "")
            + "; lower the gain or exclude these samples explicitly")
    return u


def check_above_dark(signal, dark) -> np.ndarray:
    """Return photodiode readings as an array; raise :class:`BelowDarkLevelError` if any is
    below its dark level (readings at exactly the dark level mean no light: also rejected)."""
    s = check_finite("signal", signal)
    dk = np.broadcast_to(check_finite("dark", dark), s.shape)
    bad = s <= dk
    if bad.any():
        idx = np.flatnonzero(bad)
        raise BelowDarkLevelError(
            f"photodiode reading {s.ravel()[idx[0]]!r} at flat index {idx[0]} is not above its "
            f"dark level {dk.ravel()[idx[0]]!r}" + (f" ({idx.size} such readings)"
                                                    if idx.size > 1 else "")
            + "; re-measure the dark level at the working temperature or check the readout offset")
    return s


@dataclass(frozen=True)
class PhotodiodeChannels:
    """Parameters of the three-pair sensor's six photodiodes and three log amplifiers [2]_.

    Per-photodiode tuples have 6 entries in the paper order (numerator, denominator of U1,
    then U2, U3); per-channel tuples have 3.

    Parameters
    ----------
    mounting_error_deg : 6 floats
        ``dth_1..dth_6`` [deg]: mounting angle ``alpha`` minus its nominal value.
    responsivity_A_per_lx : 6 floats
        ``K_I`` [A/lx] (default 50 pA/lx: a BPW34-class silicon photodiode, ~50 nA/lx under
        illuminant A, behind a polarizer (x0.4), a blue filter (x0.15) and a ~6 deg field stop
        (x0.01 of the hemispheric illuminance)).
    dark_A : 6 floats
        ``D`` [A] (default 50 pA: zero-bias dark current plus log-amplifier input bias, ~1 lx
        equivalent).
    extinction_intensity, extinction_efficiency : 6 floats
        ``k`` and ``eta`` (:func:`extinction_factors`).
    gain_V : 3 floats
        ``Ka`` [V/decade].
    offset_V : 3 floats
        ``V_OSO`` [V].
    """

    mounting_error_deg: tuple = field(default=(0.0,) * 6)
    responsivity_A_per_lx: tuple = field(default=(50e-12,) * 6)
    dark_A: tuple = field(default=(50e-12,) * 6)
    extinction_intensity: tuple = field(default=(1.0,) * 6)
    extinction_efficiency: tuple = field(default=(1.0,) * 6)
    gain_V: tuple = field(default=(GAIN,) * 3)
    offset_V: tuple = field(default=(0.0,) * 3)

    def __post_init__(self):
        for name, n in (("mounting_error_deg", 6), ("responsivity_A_per_lx", 6), ("dark_A", 6),
                        ("extinction_intensity", 6), ("extinction_efficiency", 6),
                        ("gain_V", 3), ("offset_V", 3)):
            arr = np.broadcast_to(check_finite(name, getattr(self, name)), (n,))
            object.__setattr__(self, name, tuple(float(x) for x in arr))
        _positive("responsivity_A_per_lx", self.responsivity_A_per_lx, "")
        _positive("extinction_intensity", self.extinction_intensity, "")
        _positive("gain_V", self.gain_V, "The log amplifier gain is positive [V/decade].")
        check_in_range("dark_A", self.dark_A, 0.0, np.inf)
        check_in_range("extinction_efficiency", self.extinction_efficiency, 0.0, 1.0)

    @property
    def dark_equivalent_lx(self) -> np.ndarray:
        """``D / (K_I k)`` [lx]: the illuminance whose signal equals the dark current (6,)."""
        return (np.asarray(self.dark_A) / np.asarray(self.responsivity_A_per_lx)
                / np.asarray(self.extinction_intensity))

    @property
    def mounting_angle_deg(self) -> np.ndarray:
        """Mounting angles ``alpha`` [deg], shape (3, 2), in the sense of ``phi``."""
        return (CHANNEL_ANGLES_DEG[:, None] + np.array([0.0, 90.0])
                + np.reshape(self.mounting_error_deg, (3, 2)))

    @classmethod
    def from_opponent_errors(cls, errors: OpponentErrors, **overrides) -> "PhotodiodeChannels":
        """The 2014 error model as photodiode parameters: no dark current, ideal polarizers,
        ``K_n / K_m = 10**f_k`` (denominator at the default responsivity)."""
        k0 = cls.__dataclass_fields__["responsivity_A_per_lx"].default[0]
        f = np.asarray(errors.transmittance)
        resp = np.stack([k0 * 10.0 ** f, np.full(3, k0)], axis=-1).ravel()
        params = dict(mounting_error_deg=errors.misalignment_deg,
                      responsivity_A_per_lx=tuple(resp), dark_A=(0.0,) * 6)
        params.update(overrides)
        return cls(**params)

    @classmethod
    def draw(cls, rng: np.random.Generator, *, mounting_max_deg: float = 1.0,
             responsivity_sd: float = 0.02, dark_range_A=(20e-12, 100e-12),
             extinction_ratio_range=(1e-3, 1e-2), gain_sd: float = 0.01,
             offset_sd_V: float = 2e-3) -> "PhotodiodeChannels":
        """Draw one sensor: mounting errors ~ U(-max, max) [deg]; responsivity ~ K0 N(1, sd);
        dark current log-uniform in ``dark_range_A``; extinction ratio log-uniform in its
        range (film polarizers), ``T1`` ~ U(0.85, 0.9); ``Ka ~ 0.5 N(1, gain_sd)``;
        ``V_OSO ~ N(0, offset_sd_V)``."""
        k0 = cls.__dataclass_fields__["responsivity_A_per_lx"].default[0]
        mis = rng.uniform(-mounting_max_deg, mounting_max_deg, 6)
        resp = k0 * (1.0 + responsivity_sd * rng.standard_normal(6))
        dark = np.exp(rng.uniform(*np.log(dark_range_A), 6))
        ratio = np.exp(rng.uniform(*np.log(extinction_ratio_range), 6))
        k, eta = extinction_factors(ratio, rng.uniform(0.85, 0.9, 6))
        gain = GAIN * (1.0 + gain_sd * rng.standard_normal(3))
        offset = offset_sd_V * rng.standard_normal(3)
        return cls(tuple(mis), tuple(resp), tuple(dark), tuple(k), tuple(eta), tuple(gain),
                   tuple(offset))

    def with_(self, **changes) -> "PhotodiodeChannels":
        """A copy with some parameters replaced."""
        return replace(self, **changes)

    def signals_A(self, intensity_lx, phi_deg, dop) -> np.ndarray:
        """Noise-free photocurrents [A], shape (..., 3, 2)."""
        return three_pair_signals(intensity_lx, phi_deg, dop,
                                  mounting_error_deg=self.mounting_error_deg,
                                  responsivity=self.responsivity_A_per_lx, dark=self.dark_A,
                                  extinction_intensity=self.extinction_intensity,
                                  extinction_efficiency=self.extinction_efficiency)

    def outputs(self, intensity_lx, phi_deg, dop) -> np.ndarray:
        """Noise-free channel outputs ``U1..U3`` [V], shape (..., 3)."""
        s = self.signals_A(intensity_lx, phi_deg, dop)
        return opponent_log_ratio(s[..., 0], s[..., 1], gain=np.asarray(self.gain_V),
                                  offset_V=np.asarray(self.offset_V))

    def sample(self, intensity_lx, phi_deg, dop, rng: np.random.Generator, *,
               noise_V=0.4e-3, bandwidth_Hz: float = 10.0, daq: Daq | None = None):
        """Noisy, quantised outputs [V]: shot noise on each photocurrent [4]_, additive output
        noise ``noise_V`` (float or 3) [V], then the DAQ. Returns ``(U, saturated_mask)``."""
        s = self.signals_A(intensity_lx, phi_deg, dop)
        # the Gaussian approximation of shot noise cannot make a current negative
        s = np.maximum(s + shot_noise(s, bandwidth_Hz, rng), 1e-18)
        u = opponent_log_ratio(s[..., 0], s[..., 1], gain=np.asarray(self.gain_V),
                               offset_V=np.asarray(self.offset_V))
        u = u + rng.standard_normal(u.shape) * np.broadcast_to(noise_V, (3,))
        return (daq or Daq()).acquire(u)

    def to_dict(self) -> dict:
        return {k: list(getattr(self, k)) for k in self.__dataclass_fields__}

    @classmethod
    def from_dict(cls, d: dict) -> "PhotodiodeChannels":
        return cls(**{k: tuple(v) for k, v in d.items() if k in cls.__dataclass_fields__})
