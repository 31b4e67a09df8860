"""Intensity, polarization angle and DoP from opponent channels with dark current, and the
multi-parameter calibration of the dark-current model (BUAA patent, 2021 [1]_).

Channel model (:mod:`sensor.photodiode`): channel ``k`` with numerator photodiode ``n`` and
denominator ``m``, mounting angles ``alpha`` (sense of ``phi``), polarization efficiencies
``eta``, log amplifier gain ``Ka`` and offset ``V_OSO``::

    U_k = Ka_k log10( (K_n k_n I (1 + eta_n d cos 2(phi + alpha_n)) + D_n)
                    / (K_m k_m I (1 + eta_m d cos 2(phi + alpha_m)) + D_m) ) + V_OSO,k

**Identifiable parameters.** Only ratios of photodiode signals reach the output, so
``K_n k_n``, ``K_m k_m``, ``D_n``, ``D_m`` of a channel can be multiplied by a common factor
without changing ``U_k``, and ``log10(K_n k_n / K_m k_m)`` is indistinguishable from
``V_OSO,k / Ka_k``. From the outputs the identifiable set per channel is 8 parameters:
``alpha_n, alpha_m`` [deg], ``eta_n, eta_m``, the *dark-equivalent illuminances*
``delta = D / (K k)`` [lx] of both photodiodes, ``Ka`` [V/decade] and the effective offset
``c = V_OSO + Ka log10(K_n k_n / (K_m k_m))`` [V]. Dark currents in amperes follow as
``D = delta K k`` once the responsivity is known (a photodiode-level measurement); this module
estimates ``delta``. With ``r_k = 10**((U_k - c_k)/Ka_k)``::

    r_k (delta_m + I (1 + eta_m d cos 2(phi + alpha_m))) = delta_n + I (1 + eta_n d cos 2(phi + alpha_n))

is linear in ``x = (I, I d cos 2phi, I d sin 2phi)``: row ``A_k = h_n - r_k h_m`` with
``h = (1, eta cos 2alpha, -eta sin 2alpha)`` and ``b_k = r_k delta_m - delta_n``. The patent's
solution is ``x = A^-1 b`` for three channels (least squares ``(A^T A)^-1 A^T b`` for more);
``I = x_1``, ``phi = 1/2 atan2(x_3, x_2)``, ``d = hypot(x_2, x_3) / x_1``.

**Ambiguity.** ``atan2`` alone fixes ``phi`` modulo 180 deg only if the sign of ``x`` is
right; as in :func:`calibration.solve.solve_pair` (``d > 0``), the sign is chosen so that
``I > 0`` (and hence ``d > 0``), which resolves the 90-deg ambiguity. In bright light
(``I >> delta``) ``b`` is small against the noise in ``A``: the *direction* of ``x`` (phi, d)
stays well determined but its length (``I``) does not; the calibration below therefore
weights the ``I`` residuals by their predicted uncertainty and drops them where ``I`` is
not identifiable.

**Bright light: the combined solve** (:func:`solve_combined`). Dividing ``A x = b`` by
``I`` gives a system linear in ``y = (p, q, u) = (d cos 2phi, d sin 2phi, 1/I)``::

    A_k1 p + A_k2 q - b_k u = -A_k0

For three channels its solution is ``x = A^-1 b`` reparametrised, but it stays finite as
``I -> inf`` (``u -> 0``): the instability of ``x = A^-1 b`` in bright light is ``x_1``
passing through infinity and changing sign, which the ``I > 0`` rule turns into a 90-deg
flip. ``u`` itself is then pure noise, and estimating it costs heading precision: fixing
``u = 0`` (dark current negligible; weighted least squares for ``(p, q)`` over the three
channels) is better there. The restricted estimate (``u = 0``) has the smaller mean squared
error iff ``u^2 < var(u_hat)`` (Toro-Vizcarrondo & Wallace [4]_; ``u`` enters linearly, so
the criterion is the same for phi and d); ``u_hat^2 - var(u_hat)`` estimates ``u^2``, so
the dark-current model is used where ``u_hat > sqrt(2) sd(u_hat)``, i.e. where the
estimated dark-to-signal ratio ``rho = delta_mean / I`` exceeds ``sqrt(2)`` times its
standard error (propagated from the output noise). ``u`` may be pooled over samples taken
under the same illuminance (a turntable sweep, a short time window: illuminance changes over
minutes, the sensor samples at >= 10 Hz), which makes both the decision and the dark
correction nearly noise-free.

**Calibration** (:func:`calibrate_dark_current`): reference sequences of integrating-sphere
intensity ``I_ref``, reference polarization angle ``phi_ref`` and DoP ``d_ref`` at several
intensity levels; residuals of the solved ``(phi, d, I)`` against the references, each
divided by its standard deviation propagated from the output noise; nonlinear least squares
(``scipy.optimize.least_squares``: Levenberg-Marquardt in output space, trust-region
reflective for the patent's solution-space residuals) from the nominal values with the
analytic Jacobian obtained by implicit differentiation of ``A x = b``::

    dx/dtheta = (A^T A)^-1 (dA/dtheta^T e) + (A^T A)^-1 A^T (db/dtheta - dA/dtheta x),  e = b - A x

Parameter covariance: sandwich ``s^2 H^-1 (J^T C J) H^-1`` with ``H = J^T J``, ``C`` the
per-sample correlation of the three whitened residuals (they come from the same three
outputs) and ``s^2`` the reduced chi-square.

References
----------
.. [1] J. Yang, Y. You, P. Hu, X. Liu, L. Guo (Beihang University), "Underwater polarization
   sensor multi-parameter optimization calibration method considering dark current",
   Chinese patent application (2021): solution x = A^-1 b for intensity, polarization angle and
   DoP; multi-parameter optimisation over reference sequences at several intensity levels.
.. [2] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424, eqs. (2)-(9) (the model without an intensity term).
.. [3] H. White, "A heteroskedasticity-consistent covariance matrix estimator",
   Econometrica 48(4):817-838 (1980), doi:10.2307/1912934 (sandwich covariance).
.. [4] T. Toro-Vizcarrondo, T. D. Wallace, "A test of the mean square error criterion for
   restrictions in linear regression", J. Am. Stat. Assoc. 63(322):558-572 (1968),
   doi:10.1080/01621459.1968.11009275 (restricted least squares has the smaller MSE iff the
   noncentrality ``beta^2 / var(beta_hat) <= 1``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from sensor.daq import Daq
from sensor.opponent import CHANNEL_ANGLES_DEG, GAIN
from sensor.photodiode import (InvalidIntensityError, PhotodiodeChannels, check_above_dark,
                               check_not_saturated)
from skysim.exceptions import InvalidParameterError
from skysim.geometry import wrap_axial_deg
from skysim.validation import check_finite, check_in_range

from .exceptions import CalibrationError, ConvergenceError, RankDeficientError, TooFewSamplesError

__all__ = ["TooFewChannelsError", "DarkCurrentNotIdentifiableError",
           "IntensityNotIdentifiableError", "ChannelModel", "PolarizationSolution",
           "solve_opponent", "solve_photodiodes", "DarkCurrentCalibration",
           "calibrate_dark_current", "output_model", "PARAMETER_NAMES",
           "MAX_SD_PHI_DEG", "MAX_SD_DOP", "CombinedSolution", "solve_combined",
           "MSE_FACTOR"]

PARAMETER_NAMES = ("alpha_n_deg", "alpha_m_deg", "eta_n", "eta_m", "dark_n_lx", "dark_m_lx",
                   "gain_V", "offset_V")
"""The 8 identifiable parameters of each channel, in the order of the parameter vector."""

MAX_SD_PHI_DEG = 2.0
"""Samples whose solved phi has a propagated sd above this [deg] carry no residual in the
``residuals="solution"`` calibration (unstable solve, linearisation invalid)."""
MAX_SD_DOP = 0.05
"""Same for the solved DoP."""

MSE_FACTOR = 2.0
"""The dark-current model is used where ``u_hat^2 > MSE_FACTOR var(u_hat)`` (and ``u_hat > 0``):
``u_hat^2 - var(u_hat)`` is the unbiased estimate of ``u^2``, compared with ``var(u_hat)``
(Toro-Vizcarrondo & Wallace [4]_)."""

_DEG = np.pi / 180.0
_LN10 = np.log(10.0)


class TooFewChannelsError(TooFewSamplesError):
    """Fewer than 3 channels (or photodiodes): I, phi and d need at least three equations."""


class DarkCurrentNotIdentifiableError(RankDeficientError):
    """The calibration set has one intensity level only: a dark-equivalent illuminance then
    acts exactly like a change of polarization efficiency and offset at that level, so the
    dark current is not identifiable. Record the reference sequence at >= 2 (better >= 4)
    intensity levels spanning the dark level (e.g. 1 to 1000 lx)."""


class IntensityNotIdentifiableError(CalibrationError, ValueError):
    """All dark currents are zero: the log-ratio outputs are then independent of the
    intensity, so ``A x = 0`` has no intensity scale. Use
    :func:`calibration.solve.solve_pair` for phi and d, or calibrate the dark currents."""


@dataclass(frozen=True)
class ChannelModel:
    """Identifiable parameters of ``n`` opponent channels (see module docstring).

    Attributes
    ----------
    alpha_deg : ndarray (n, 2)
        Mounting angles of numerator and denominator photodiodes [deg] (sense of phi).
    eta : ndarray (n, 2)
        Polarization efficiencies.
    dark_lx : ndarray (n, 2)
        Dark-equivalent illuminances ``D / (K k)`` [lx].
    gain_V : ndarray (n,)
        ``Ka`` [V/decade].
    offset_V : ndarray (n,)
        Effective offsets ``V_OSO + Ka log10(K_n k_n / (K_m k_m))`` [V].
    """

    alpha_deg: np.ndarray
    eta: np.ndarray
    dark_lx: np.ndarray
    gain_V: np.ndarray
    offset_V: np.ndarray

    def __post_init__(self):
        a = check_finite("alpha_deg", self.alpha_deg)
        if a.ndim != 2 or a.shape[1] != 2:
            raise InvalidParameterError(f"alpha_deg must have shape (n, 2); got {a.shape}")
        n = a.shape[0]
        object.__setattr__(self, "alpha_deg", a)
        for name, shape in (("eta", (n, 2)), ("dark_lx", (n, 2)), ("gain_V", (n,)),
                            ("offset_V", (n,))):
            object.__setattr__(self, name, np.broadcast_to(
                check_finite(name, getattr(self, name)), shape).astype(float))

    @property
    def n_channels(self) -> int:
        return self.alpha_deg.shape[0]

    @classmethod
    def nominal(cls, dark_lx: float = 1.0, n_channels: int = 3) -> "ChannelModel":
        """Design values of the three-pair sensor: angles (60, 0, 120) and +90 deg, ideal
        polarizers, gain 0.5, zero offset, a datasheet dark-equivalent illuminance [lx]."""
        if n_channels != 3:
            raise InvalidParameterError("nominal() describes the three-pair sensor (n_channels=3)")
        alpha = CHANNEL_ANGLES_DEG[:, None] + np.array([0.0, 90.0])
        return cls(alpha, np.ones((3, 2)), np.full((3, 2), dark_lx), np.full(3, GAIN),
                   np.zeros(3))

    @classmethod
    def from_photodiodes(cls, p: PhotodiodeChannels) -> "ChannelModel":
        """The identifiable combination of a full photodiode parameter set (ground truth)."""
        kk = (np.asarray(p.responsivity_A_per_lx) * np.asarray(p.extinction_intensity)
              ).reshape(3, 2)
        gain = np.asarray(p.gain_V)
        return cls(p.mounting_angle_deg, np.reshape(p.extinction_efficiency, (3, 2)),
                   np.reshape(p.dark_equivalent_lx, (3, 2)), gain,
                   np.asarray(p.offset_V) + gain * np.log10(kk[:, 0] / kk[:, 1]))

    def to_vector(self) -> np.ndarray:
        """Parameter vector, channel-major, per channel in :data:`PARAMETER_NAMES` order."""
        return np.column_stack([self.alpha_deg, self.eta, self.dark_lx, self.gain_V,
                                self.offset_V]).ravel()

    @classmethod
    def from_vector(cls, theta) -> "ChannelModel":
        t = np.asarray(theta, dtype=float).reshape(-1, 8)
        return cls(t[:, 0:2], t[:, 2:4], t[:, 4:6], t[:, 6], t[:, 7])

    def parameter_labels(self) -> list[str]:
        return [f"U{k + 1}.{name}" for k in range(self.n_channels) for name in PARAMETER_NAMES]

    def to_dict(self) -> dict:
        return dict(zip(self.parameter_labels(), self.to_vector().tolist()))


@dataclass(frozen=True)
class PolarizationSolution:
    """Solved intensity [lx], polarization azimuth [deg, in [-90, 90)] and DoP per sample."""

    intensity_lx: np.ndarray
    phi_deg: np.ndarray
    dop: np.ndarray


def _h(alpha_deg, eta):
    """Rows ``(1, eta cos 2alpha, -eta sin 2alpha)``, shape alpha.shape + (3,)."""
    two = 2.0 * np.radians(alpha_deg)
    return np.stack([np.ones_like(two), eta * np.cos(two), -eta * np.sin(two)], axis=-1)


def _system(U, model: ChannelModel):
    """Ratios r (N, n) and the linear system A (N, n, 3), b (N, n)."""
    r = 10.0 ** ((U - model.offset_V) / model.gain_V)
    hn = _h(model.alpha_deg[:, 0], model.eta[:, 0])
    hm = _h(model.alpha_deg[:, 1], model.eta[:, 1])
    A = hn - r[..., None] * hm
    b = r * model.dark_lx[:, 1] - model.dark_lx[:, 0]
    return r, hn, hm, A, b


def _least_squares(A, b):
    """Batched ``x = (A^T A)^-1 A^T b`` (``A^-1 b`` when square); also ``(A^T A)^-1``."""
    At = np.swapaxes(A, -1, -2)
    Ninv = np.linalg.inv(At @ A)
    x = (Ninv @ (At @ b[..., None]))[..., 0]
    return x, Ninv


def _from_x(x):
    """``(I, phi_deg, d)`` with the sign of ``x`` chosen so that ``I > 0`` (ambiguity)."""
    s = np.where(x[..., 0] < 0, -1.0, 1.0)
    z = x * s[..., None]
    phi = wrap_axial_deg(0.5 * np.degrees(np.arctan2(z[..., 2], z[..., 1])))
    return z[..., 0], phi, np.hypot(z[..., 1], z[..., 2]) / z[..., 0]


def _check_outputs(U, n_min: int = 3, daq: Daq | None = None) -> np.ndarray:
    U = check_finite("U", U)
    if U.ndim < 1 or U.shape[-1] < n_min:
        raise TooFewChannelsError(
            f"need at least {n_min} channels to solve for intensity, polarization angle and "
            f"DoP; got outputs of shape {U.shape} (last axis = channels)")
    if daq is not None:
        check_not_saturated(U, daq)
    return U


def solve_opponent(U, model: ChannelModel, *, daq: Daq | None = None) -> PolarizationSolution:
    """Intensity, polarization azimuth and DoP from ``n >= 3`` opponent channels, ``x = A^-1 b``
    of [1]_ (least squares for ``n > 3``), ambiguity resolved by ``I > 0``.

    Parameters
    ----------
    U : array (..., n)
        Channel outputs [V], channel order as ``model``.
    model : ChannelModel
        Calibrated (or nominal) channel parameters.
    daq : Daq, optional
        If given, readings at its rails raise :class:`SaturatedReadingError`.

    Returns
    -------
    PolarizationSolution

    Raises
    ------
    TooFewChannelsError
        Fewer than 3 channels.
    IntensityNotIdentifiableError
        If every dark-equivalent illuminance of ``model`` is zero.
    SaturatedReadingError
        If ``daq`` is given and a reading is at the rail.
    """
    U = _check_outputs(U, 3, daq)
    if U.shape[-1] != model.n_channels:
        raise InvalidParameterError(
            f"U has {U.shape[-1]} channels but the model {model.n_channels}")
    if not np.any(model.dark_lx):
        raise IntensityNotIdentifiableError(
            "all dark-equivalent illuminances are zero: the outputs do not depend on the "
            "intensity; use calibration.solve.solve_pair for phi and d")
    _, _, _, A, b = _system(U, model)
    x, _ = _least_squares(A, b)
    return PolarizationSolution(*_from_x(x))


def solve_photodiodes(signals, polarizer_deg, *, responsivity=1.0, dark=0.0,
                      extinction_intensity=1.0, extinction_efficiency=1.0
                      ) -> PolarizationSolution:
    """Intensity, AoP and DoP from ``n >= 3`` raw photodiode readings, ``x = A^-1 b`` [1]_.

    Inverts :func:`sensor.photodiode.photodiode_signal`: row ``A_i = K_i k_i (1,
    eta_i cos 2p_i, eta_i sin 2p_i)``, ``b_i = S_i - D_i``, ``x = (I, I d cos 2chi,
    I d sin 2chi)``; least squares for ``n > 3``.

    Parameters
    ----------
    signals : array (..., n)
        Photodiode readings [output unit].
    polarizer_deg : array (n,)
        Polarizer angles [deg].
    responsivity, dark, extinction_intensity, extinction_efficiency : float or (n,)
        As in :func:`sensor.photodiode.photodiode_signal`.

    Returns
    -------
    PolarizationSolution
        ``intensity_lx`` in the unit of ``signals / responsivity``, ``phi_deg`` = AoP ``chi``
        [deg] in the frame of ``polarizer_deg``.

    Raises
    ------
    TooFewChannelsError, BelowDarkLevelError
    """
    S = _check_outputs(signals, 3)
    n = S.shape[-1]
    p = np.radians(2.0 * np.broadcast_to(check_finite("polarizer_deg", polarizer_deg), (n,)))
    S = check_above_dark(S, np.broadcast_to(dark, (n,)))
    kk = np.broadcast_to(responsivity, (n,)) * np.broadcast_to(extinction_intensity, (n,))
    eta = np.broadcast_to(extinction_efficiency, (n,))
    A = kk[:, None] * np.stack([np.ones(n), eta * np.cos(p), eta * np.sin(p)], axis=-1)
    x, _ = _least_squares(np.broadcast_to(A, S.shape + (3,)), S - np.broadcast_to(dark, (n,)))
    return PolarizationSolution(*_from_x(x))


@dataclass(frozen=True)
class CombinedSolution(PolarizationSolution):
    """:class:`PolarizationSolution` of :func:`solve_combined`; ``intensity_lx`` is ``inf``
    where the dark-current model was not used (intensity not resolvable from the noise).

    Attributes
    ----------
    dark_to_signal : ndarray
        Estimated dark-to-signal ratio ``delta_mean u_hat`` (pooled if asked); may be < 0.
    dark_to_signal_sd : ndarray
        Its standard deviation propagated from the output noise.
    dark_model : ndarray of bool
        Where the dark-current model was used (criterion of :data:`MSE_FACTOR`).
    """

    dark_to_signal: np.ndarray = None
    dark_to_signal_sd: np.ndarray = None
    dark_model: np.ndarray = None


def _inverse_intensity_system(U, model: ChannelModel, noise):
    """``y = (p, q, u)`` least squares of ``A_k1 p + A_k2 q - b_k u = -A_k0``, sd of ``u``
    from the output noise, and the residual derivatives ``dres_k/dU_k`` (N, n)."""
    r, _, hm, A, b = _system(U, model)
    M = np.stack([A[..., 1], A[..., 2], -b], axis=-1)
    At = np.swapaxes(M, -1, -2)
    P = np.linalg.solve(At @ M, At)                       # (M^T M)^-1 M^T, (..., 3, n)
    y = -np.einsum("...ik,...k->...i", P, A[..., 0])
    g = (hm[..., 0] + hm[..., 1] * y[..., 0, None] + hm[..., 2] * y[..., 1, None]
         + model.dark_lx[:, 1] * y[..., 2, None])
    dres = g * r * _LN10 / model.gain_V                   # d res_k / d U_k
    sd_u = np.sqrt(np.sum((P[..., 2, :] * dres * noise) ** 2, axis=-1))
    return A, b, y, sd_u, dres


def solve_combined(U, model: ChannelModel, noise_V, *, pool_axis: int | None = None,
                   mse_factor: float = MSE_FACTOR, daq: Daq | None = None
                   ) -> CombinedSolution:
    """Polarization azimuth, DoP and (where resolvable) intensity, stable from dark to
    daylight: the dark-current model where dark current matters, the same calibrated model
    with ``1/I = 0`` in bright light (module docstring, *Bright light*).

    Parameters
    ----------
    U : array (..., n)
        Channel outputs [V], ``n >= 3``.
    model : ChannelModel
        Calibrated channel parameters (at least one dark level > 0).
    noise_V : float or (n,)
        Output noise per channel [V] (noise and quantisation), > 0.
    pool_axis : int, optional
        Axis of ``U[..., 0]`` along which the samples share one illuminance: ``u = 1/I`` is
        pooled (inverse-variance mean) along it before the decision and the correction.
    mse_factor : float
        Use the dark-current model where ``u_hat > sqrt(mse_factor) sd(u_hat)``
        (default :data:`MSE_FACTOR`; ``inf``: never, i.e. the bright-light arm ``1/I = 0``;
        ``0``: wherever ``u_hat > 0``).
    daq : Daq, optional
        If given, saturated readings raise :class:`SaturatedReadingError`.

    Returns
    -------
    CombinedSolution

    Raises
    ------
    TooFewChannelsError, SaturatedReadingError
        As :func:`solve_opponent`.
    IntensityNotIdentifiableError
        If the dark levels of ``model`` are equal within every channel (zero included).
    InvalidParameterError
        If ``noise_V`` is not positive or ``mse_factor`` negative.
    """
    U = _check_outputs(U, 3, daq)
    n = U.shape[-1]
    if n != model.n_channels:
        raise InvalidParameterError(f"U has {n} channels but the model {model.n_channels}")
    if np.allclose(model.dark_lx[:, 0], model.dark_lx[:, 1], rtol=1e-12, atol=0.0):
        raise IntensityNotIdentifiableError(
            f"dark-equivalent illuminances {model.dark_lx.tolist()} lx are equal within every "
            "channel: a common dark level acts as extra unpolarized light and 1/I has no "
            "equation of its own (only the mismatch identifies I); calibrate the dark levels "
            "(calibrate_dark_current) or use calibration.solve.solve_pair for phi and d")
    noise = np.broadcast_to(check_in_range("noise_V", noise_V, 0.0, np.inf, low_open=True),
                            (n,))
    c = float(mse_factor)
    if not c >= 0.0:
        raise InvalidParameterError(
            f"mse_factor must be >= 0 (inf: never use the dark-current model); got {mse_factor!r}")
    A, b, y, sd_u, dres = _inverse_intensity_system(U, model, noise)
    u, sd = y[..., 2], sd_u
    if pool_axis is not None:
        w = 1.0 / sd ** 2
        u = np.sum(w * u, axis=pool_axis, keepdims=True) / np.sum(w, axis=pool_axis,
                                                                   keepdims=True)
        sd = 1.0 / np.sqrt(np.sum(w, axis=pool_axis, keepdims=True))
        u, sd = np.broadcast_to(u, sd_u.shape), np.broadcast_to(sd, sd_u.shape)
    dark = u > np.sqrt(c) * sd
    u_fix = np.where(dark, u, 0.0)
    # weighted least squares for (p, q) with u fixed (exactly the (p, q, u) solution for
    # three channels where the dark model is used per sample)
    w = 1.0 / (np.abs(dres) * noise)
    Mw = A[..., 1:] * w[..., None]
    rhs = (b * u_fix[..., None] - A[..., 0]) * w
    Mt = np.swapaxes(Mw, -1, -2)
    pq = np.linalg.solve(Mt @ Mw, (Mt @ rhs[..., None]))[..., 0]
    phi = wrap_axial_deg(0.5 * np.degrees(np.arctan2(pq[..., 1], pq[..., 0])))
    with np.errstate(divide="ignore"):
        intensity = np.where(dark, 1.0 / np.where(dark, u_fix, 1.0), np.inf)
    delta = float(np.mean(model.dark_lx))
    return CombinedSolution(intensity, phi, np.hypot(pq[..., 0], pq[..., 1]),
                            dark_to_signal=delta * u, dark_to_signal_sd=delta * sd,
                            dark_model=dark)


# --------------------------------------------------------------------------------------------
# Calibration


def _row_derivatives(U, model: ChannelModel, r, hm):
    """Derivatives of row k of ``A`` (N, n, q, 3) and of ``b_k`` (N, n, q) with respect to the
    8 parameters of channel k and, last (q = 9), to the output ``U_k``."""
    N, n = U.shape
    an, am = np.radians(2.0 * model.alpha_deg[:, 0]), np.radians(2.0 * model.alpha_deg[:, 1])
    en, em = model.eta[:, 0], model.eta[:, 1]
    dm = model.dark_lx[:, 1]
    ka, c = model.gain_V, model.offset_V
    dA = np.zeros((N, n, 9, 3))
    db = np.zeros((N, n, 9))
    zero = np.zeros(n)
    dhn_da = 2.0 * _DEG * en[:, None] * np.stack([zero, -np.sin(an), -np.cos(an)], axis=-1)
    dhm_da = 2.0 * _DEG * em[:, None] * np.stack([zero, -np.sin(am), -np.cos(am)], axis=-1)
    dA[:, :, 0] = dhn_da
    dA[:, :, 1] = -r[..., None] * dhm_da
    dA[:, :, 2] = np.stack([zero, np.cos(an), -np.sin(an)], axis=-1)
    dA[:, :, 3] = -r[..., None] * np.stack([zero, np.cos(am), -np.sin(am)], axis=-1)
    db[:, :, 4] = -1.0
    db[:, :, 5] = r
    dr = np.stack([-r * _LN10 * (U - c) / ka ** 2,      # d r / d Ka
                   -r * _LN10 / ka,                     # d r / d c
                   r * _LN10 / ka], axis=-1)            # d r / d U
    dA[:, :, 6:9] = -dr[..., None] * hm[:, None, :]
    db[:, :, 6:9] = dr * dm[:, None]
    return dA, db


def _solution_jacobian(U, model: ChannelModel):
    """Solution (I, phi_deg, d) and its derivatives (N, 3, n, 9): quantity, channel,
    parameter (8 model parameters of that channel, then U_k)."""
    r, _, hm, A, b = _system(U, model)
    x, Ninv = _least_squares(A, b)
    e = b - np.einsum("Nkj,Nj->Nk", A, x)
    dA, db = _row_derivatives(U, model, r, hm)
    # dx = Ninv (dA_k e_k) + Ninv A_k (db_k - dA_k . x)
    g = db - np.einsum("Nkqj,Nj->Nkq", dA, x)
    dx = (np.einsum("Nij,Nkqj->Nikq", Ninv, dA * e[:, :, None, None])
          + np.einsum("Nij,Nkj,Nkq->Nikq", Ninv, A, g))
    s = np.where(x[:, 0] < 0, -1.0, 1.0)
    I, phi, d = _from_x(x)
    rho = np.hypot(x[:, 1], x[:, 2])
    dI = s[:, None, None] * dx[:, 0]
    dphi = np.degrees(0.5 * (x[:, 1, None, None] * dx[:, 2] - x[:, 2, None, None] * dx[:, 1])
                      / rho[:, None, None] ** 2)
    dd = s[:, None, None] * ((x[:, 1, None, None] * dx[:, 1] + x[:, 2, None, None] * dx[:, 2])
                             / (rho * I)[:, None, None]
                             - (rho / I ** 2)[:, None, None] * dx[:, 0])
    return (I, phi, d), np.stack([dI, dphi, dd], axis=1)


@dataclass(frozen=True)
class DarkCurrentCalibration:
    """Result of :func:`calibrate_dark_current`.

    Attributes
    ----------
    model : ChannelModel
        Fitted identifiable parameters.
    covariance : ndarray (p, p)
        Sandwich covariance of the parameter vector (``model.to_vector()`` order).
    rms_phi_deg, rms_dop, rms_intensity_rel : float
        RMS of the unweighted residuals (intensity: relative, where identifiable).
    chi2_reduced : float
        Sum of squared whitened residuals over (m - p).
    n_samples, n_levels : int
    nfev : int
    success : bool
    """

    model: ChannelModel
    covariance: np.ndarray
    rms_phi_deg: float
    rms_dop: float
    rms_intensity_rel: float
    chi2_reduced: float
    n_samples: int
    n_levels: int
    nfev: int
    success: bool = True
    parameter_names: list = field(default_factory=list)

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))

    def solve(self, U, daq: Daq | None = None) -> PolarizationSolution:
        """Calibrated intensity [lx], phi [deg] and DoP for outputs ``U`` (..., 3)."""
        return solve_opponent(U, self.model, daq=daq)

    def to_dict(self) -> dict:
        return {"parameters": self.model.to_dict(),
                "standard_errors": dict(zip(self.parameter_names,
                                            self.standard_errors.tolist())),
                "rms_phi_deg": self.rms_phi_deg, "rms_dop": self.rms_dop,
                "rms_intensity_rel": self.rms_intensity_rel, "chi2_reduced": self.chi2_reduced,
                "n_samples": self.n_samples, "n_levels": self.n_levels, "nfev": self.nfev,
                "success": self.success}


def _whitening(U, model, noise_V, intensity_ref, max_rel_intensity_sd):
    """Whitening of the (I, phi, d) residuals by their covariance propagated from the output
    noise: ``W`` (N, 3, 3) with ``W Sigma W^T = 1`` per sample (inverse Cholesky factor).

    The I residual is dropped (row and column of ``W`` zero) where sd(I)/I exceeds
    ``max_rel_intensity_sd`` (bright light: I not identifiable, linearisation invalid).
    """
    _, jac = _solution_jacobian(U, model)
    G = jac[..., 8] * noise_V                                  # (N, 3 quantities, 3 outputs)
    sd = np.sqrt(np.sum(G ** 2, axis=-1))
    keep_I = sd[:, 0] / intensity_ref <= max_rel_intensity_sd
    # bright light: when noise brings the solved I near 0 the direction of x is lost and the
    # linearisation fails for phi and d too: such samples carry no residual
    stable = np.isfinite(sd).all(axis=1) & (sd[:, 1] <= MAX_SD_PHI_DEG) & (sd[:, 2] <= MAX_SD_DOP)
    G[~keep_I, 0] = 0.0
    G[~stable] = 0.0
    cov = G @ np.swapaxes(G, 1, 2)
    cov[~keep_I | ~stable, 0, 0] = 1.0                         # placeholders, zeroed below
    cov[~stable, 1, 1] = cov[~stable, 2, 2] = 1.0
    W = np.linalg.inv(np.linalg.cholesky(cov))
    W[~keep_I, 0, :] = 0.0
    W[~stable] = 0.0
    return W


def output_model(intensity_lx, phi_deg, dop, model: ChannelModel, *, jacobian: bool = False):
    """Forward model in the identifiable parameters: ``U`` (N, n) [V] and, if asked, its
    Jacobian (N, n, 8) with respect to the channel's own parameters (per degree for angles)::

        U_k = Ka/ln10 (ln s_n - ln s_m) + c,  s = delta + I (1 + eta d cos 2(phi + alpha))
    """
    I = np.asarray(intensity_lx, dtype=float)[:, None, None]
    arg = np.radians(2.0 * (np.asarray(phi_deg, dtype=float)[:, None, None] + model.alpha_deg))
    pol = I * np.asarray(dop, dtype=float)[:, None, None]                  # (N, 1, 1)
    s = model.dark_lx + I * (1.0 + model.eta * pol / I * np.cos(arg))      # (N, n, 2)
    k = model.gain_V / _LN10
    U = k * (np.log(s[..., 0]) - np.log(s[..., 1])) + model.offset_V
    if not jacobian:
        return U
    sign = np.array([1.0, -1.0])
    kk = k[:, None] * sign / s                                             # d U / d s (N, n, 2)
    J = np.empty(U.shape + (8,))
    J[..., 0:2] = kk * model.eta * pol * (-2.0 * np.sin(arg)) * _DEG
    J[..., 2:4] = kk * pol * np.cos(arg)
    J[..., 4:6] = kk
    J[..., 6] = (np.log(s[..., 0]) - np.log(s[..., 1])) / _LN10
    J[..., 7] = 1.0
    return U, J


def _fit_outputs(U, I_ref, phi_ref, d_ref, theta0, noise, max_nfev, x_scale):
    """Output-space weighted least squares (maximum likelihood for Gaussian output noise).

    Levenberg-Marquardt (MINPACK): the problem is unconstrained, and MINPACK's own QR
    avoids the per-iteration SVD of the trust-region-reflective solver (same minimum; ~10x
    faster on a loaded 2-core machine with multithreaded BLAS)."""
    N, n = U.shape

    def fun(theta):
        return ((output_model(I_ref, phi_ref, d_ref, ChannelModel.from_vector(theta)) - U)
                / noise).ravel()

    def jac(theta):
        _, Jc = output_model(I_ref, phi_ref, d_ref, ChannelModel.from_vector(theta),
                             jacobian=True)
        J = np.zeros((N, n, n, 8))
        J[:, np.arange(n), np.arange(n)] = Jc / noise[:, None]
        return J.reshape(N * n, n * 8)

    sol = least_squares(fun, theta0, jac=jac, method="lm", x_scale=x_scale,
                        max_nfev=max_nfev, xtol=1e-12, ftol=1e-12, gtol=1e-12)
    if sol.status <= 0:
        raise ConvergenceError(f"least_squares (outputs) failed: {sol.message}",
                               iterations=sol.nfev)
    return sol


def calibrate_dark_current(U, intensity_lx, phi_deg, dop, *,
                           initial: ChannelModel | None = None, noise_V=0.4e-3,
                           daq: Daq | None = None, residuals: str = "outputs",
                           max_rel_intensity_sd: float = 0.3,
                           max_nfev: int = 200) -> DarkCurrentCalibration:
    """Multi-parameter calibration of the dark-current channel model [1]_.

    Parameters
    ----------
    U : array (N, 3)
        Channel outputs [V] for the reference sequence.
    intensity_lx : array (N,)
        Reference (integrating-sphere) intensity [lx], at >= 2 distinct levels.
    phi_deg : array (N,)
        Reference polarization azimuth [deg].
    dop : array (N,)
        Reference degree of polarization in (0, 1).
    initial : ChannelModel, optional
        Start (default: :meth:`ChannelModel.nominal`, 1 lx dark-equivalent illuminance).
    noise_V : float or (3,)
        Output noise of each channel [V] used to weight the residuals (its overall scale is
        re-estimated from the residuals by the reduced chi-square).
    daq : Daq, optional
        If given, saturated readings raise :class:`SaturatedReadingError`.
    residuals : {"outputs", "solution"}
        ``"outputs"`` (default): residuals in U, whitened by ``noise_V`` (maximum likelihood
        for Gaussian output noise; unbiased in the Monte-Carlo of
        ``skysim reproduce dark-current``). ``"solution"``: the patent's residuals in the
        solved (I, phi, d), whitened by their covariance propagated from the output noise,
        started from the output-space fit. The (I, phi, d) solve is strongly nonlinear in
        the noise at low light, so this variant is biased by several of its standard errors
        (see docs/dark_current.md); it is kept for comparison with the patent.
    max_rel_intensity_sd : float
        Samples whose predicted relative intensity uncertainty exceeds this carry no intensity
        residual (bright light: I not identifiable).
    max_nfev : int
        Evaluation budget of ``least_squares``.

    Returns
    -------
    DarkCurrentCalibration

    Raises
    ------
    DarkCurrentNotIdentifiableError
        If the reference sequence has a single intensity level.
    TooFewSamplesError
        If there are fewer residuals than parameters.
    InvalidIntensityError
        If a reference intensity is zero or negative.
    RankDeficientError
        If some parameter is not observable from the sequence (names it).
    ConvergenceError
        If ``least_squares`` fails.
    """
    U = _check_outputs(U, 3, daq)
    if U.ndim != 2 or U.shape[1] != 3:
        raise InvalidParameterError(f"U must have shape (N, 3); got {U.shape}")
    N = U.shape[0]
    I_ref = check_finite("intensity_lx", intensity_lx).ravel()
    if (I_ref <= 0).any():
        bad = I_ref[I_ref <= 0][0]
        raise InvalidIntensityError(f"reference intensity must be > 0 lx; got {bad!r}. "
                                    "Use the integrating sphere's calibrated illuminance.")
    phi_ref = np.broadcast_to(check_finite("phi_deg", phi_deg).ravel(), (N,))
    d_ref = np.broadcast_to(check_in_range("dop", dop, 0.0, 1.0, low_open=True,
                                           high_open=True).ravel(), (N,))
    if I_ref.shape != (N,):
        raise InvalidParameterError(
            f"intensity_lx must have one value per sample ({N}); got {I_ref.shape}")
    levels = np.unique(np.round(np.log10(I_ref), 6))
    if levels.size < 2:
        raise DarkCurrentNotIdentifiableError(
            f"the calibration set has a single intensity level ({I_ref[0]:g} lx): the dark "
            "current is not identifiable (it mimics a change of polarization efficiency and "
            "offset). Record the reference sequence at >= 2 intensity levels spanning the "
            "dark level, e.g. 1, 3, 10, 100, 1000 lx")
    model0 = initial or ChannelModel.nominal()
    theta0 = model0.to_vector()
    p = theta0.size
    noise = np.broadcast_to(check_in_range("noise_V", noise_V, 0.0, np.inf, low_open=True), (3,))
    if 3 * N <= p:
        raise TooFewSamplesError(f"{N} samples give {3 * N} residuals for {p} parameters; "
                                 "record more reference angles per level")
    n = 3
    labels = model0.parameter_labels()
    if residuals not in ("solution", "outputs"):
        raise InvalidParameterError(
            f"residuals must be 'solution' or 'outputs'; got {residuals!r}")
    x_scale = np.tile([0.1, 0.1, 0.01, 0.01, 0.1, 0.1, 0.005, 0.005], n)
    # stage 1: output space from the nominal values (the solve is singular at the nominal
    # model: equal dark levels in a channel make I + delta, not I, the only scale)
    sol = _fit_outputs(U, I_ref, phi_ref, d_ref, theta0, noise, max_nfev, x_scale)
    theta, nfev = sol.x, sol.nfev

    def solution_residuals(theta, W):
        model = ChannelModel.from_vector(theta)
        (I, phi, d), jac = _solution_jacobian(U, model)
        res = np.stack([I - I_ref, wrap_axial_deg(phi - phi_ref), d - d_ref], axis=1)
        J = np.einsum("Nij,Njp->Nip", W, jac[..., :8].reshape(N, 3, p))
        return np.einsum("Nij,Nj->Ni", W, res), J.reshape(3 * N, p), (I, phi, d)

    if residuals == "solution":
        # stage 2: the patent's residuals in (I, phi, d), whitened by their covariance
        # propagated from the output noise at the stage-1 solution
        W = _whitening(U, ChannelModel.from_vector(theta), noise, I_ref, max_rel_intensity_sd)
        sol = least_squares(lambda t: solution_residuals(t, W)[0].ravel(), theta,
                            jac=lambda t: solution_residuals(t, W)[1], method="trf",
                            x_scale=x_scale, max_nfev=max_nfev, xtol=1e-12, ftol=1e-12,
                            gtol=1e-12)
        nfev += sol.nfev
        if sol.status <= 0:
            raise ConvergenceError(f"least_squares (I, phi, d) failed: {sol.message}",
                                   iterations=sol.nfev)
        theta = sol.x
        r, J, (I, phi, d) = solution_residuals(theta, W)
        m = int(np.count_nonzero(np.any(W != 0, axis=2)))
        ident = np.any(W[:, 0] != 0, axis=1)
    else:
        r, J = sol.fun, sol.jac
        (I, phi, d), jac = _solution_jacobian(U, ChannelModel.from_vector(theta))
        m = r.size
        ident = (np.sqrt(np.sum((jac[:, 0, :, 8] * noise) ** 2, axis=-1)) / I_ref
                 <= max_rel_intensity_sd)
    norms = np.linalg.norm(J, axis=0)
    safe = np.where(norms > 0, norms, 1.0)
    # singular values of J from its 24 x 24 triangular factor (same values; the SVD of the
    # tall J is ~10-100x slower with multithreaded BLAS on a loaded machine)
    R = np.linalg.qr(J / safe, mode="r")
    sv = np.linalg.svd(R, compute_uv=False)
    if norms.min() == 0 or sv[-1] < 1e-10 * sv[0]:
        _, _, vt = np.linalg.svd(R)
        worst = labels[int(np.argmax(np.abs(vt[-1])))]
        raise RankDeficientError(
            f"parameter {worst!r} is not observable from this reference sequence (singular "
            f"value ratio {sv[-1] / sv[0]:.2e}); spread phi over [-90, 90) deg and use >= 2 "
            "DoP and intensity levels")
    chi2 = float(np.sum(r ** 2) / max(m - p, 1))
    cov = chi2 * np.linalg.inv(J.T @ J)
    return DarkCurrentCalibration(
        model=ChannelModel.from_vector(theta), covariance=cov,
        rms_phi_deg=float(np.sqrt(np.mean(wrap_axial_deg(phi - phi_ref) ** 2))),
        rms_dop=float(np.sqrt(np.mean((d - d_ref) ** 2))),
        rms_intensity_rel=float(np.sqrt(np.mean(((I - I_ref) / I_ref)[ident] ** 2)))
        if ident.any() else float("inf"),
        chi2_reduced=chi2, n_samples=N, n_levels=int(levels.size), nfev=nfev,
        parameter_names=labels)
