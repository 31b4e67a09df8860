"""Library of unmodelled physical effects of a three-pair polarization sensor on a turntable.

Each effect is a documented physical extension of the base model of Yang et al. (2014) [1]_
(eqs. 2-3, single-scattering Rayleigh sky with a free ``d_max``), with its own parameters,
used both to *generate* data (:func:`forward` with known parameters plus noise) and to *fit*
data (the same :func:`forward` inside :func:`calibration.diagnosis.three_pair_fit.fit_model`). The generator
and the diagnoser share nothing else.

The forward model runs in two stages, so a fit recomputes only what a parameter touches:

1. **geometry** (from the *recorded* time and heading): the true sample time
   ``t = t_rec + Effect.time_shift_s``, the true heading ``h = h_rec + Effect.heading_shift_deg``,
   the sun at ``t``, then the polarization azimuth ``phi`` and the DoP *shape* seen by the
   sensor (``Effect.polarization``; default: zenith of a Rayleigh sky,
   ``phi = wrap(h - sun_az)``, ``shape = sin^2 g / (1 + cos^2 g)`` with ``g`` the solar zenith
   angle [2]_).
2. **output** (photodiodes and amplifier): channel ``i`` has a numerator photodiode behind a
   polarizer at ``a_i + e1_i`` and a denominator one at ``a_i + 90 + e2_i``::

       U_i = G_i(t) [ log10( (1 + eta_i1 d cos 2x_1 + delta_i1(t))
                           / (1 - eta_i2 d cos 2x_2 + delta_i2(t)) ) + f_i ] + v_i(t)

   with ``x_k = phi + a_i + e_k``, ``d = s * shape``, polarizer efficiencies ``eta`` (1 for an
   ideal polarizer, :mod:`.extinction_ratio`; the intensity factor ``k`` of a partial
   polarizer enters ``f``), dark-to-signal ratios ``delta``
   (:mod:`.dark_current`), gain ``G_i = g (1 + ...)`` and offset ``v_i`` (:mod:`.thermal_drift`).
   With every effect absent this is exactly eq. (2) of [1]_.

Base parameters (always fitted): six mounting errors ``dtheta_1..6`` [deg], three
transmittance terms ``f_1..3`` and the DoP scale ``s`` (the sky's ``d_max``).

References
----------
.. [1] J. Yang, N. Zhou, Y. Huang, X. Liu, Opt. Precision Eng. 22(6):1424 (2014),
   doi:10.3788/OPE.20142206.1424, eqs. (2)-(3).
.. [2] K. L. Coulson, *Polarization and Intensity of Light in the Atmosphere*, A. Deepak
   (1988), ch. 2 (Rayleigh DoP).
"""

from __future__ import annotations

import abc
import importlib
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import pandas as pd

from calibration.exceptions import DiagnosisError
from sensor.opponent import CHANNEL_ANGLES_DEG, GAIN
from sensor.photodiode import opponent_log_ratio, photodiode_signal
from skysim import rayleigh
from skysim.geometry import direction_vector, wrap_axial_deg
from skysim.sun import Site, SunTrack, as_utc_index

__all__ = [
    "BASE_NAMES",
    "EFFECT_NAMES",
    "Context",
    "Effect",
    "SunTrack",
    "UnknownEffectError",
    "all_effects",
    "base_vector",
    "forward",
    "geometry",
    "get_effect",
    "jacobians",
    "outputs",
]

EFFECT_NAMES = ("dark_current", "sun_motion", "clock_offset", "tilt", "turntable_periodic",
                "extinction_ratio", "thermal_drift", "multiple_scattering", "overcast")
"""The registered effects, each in the module of the same name."""

BASE_NAMES = ("dtheta_1_deg", "dtheta_2_deg", "dtheta_3_deg", "dtheta_4_deg", "dtheta_5_deg",
              "dtheta_6_deg", "f_1", "f_2", "f_3", "dop_scale")
"""Base-model parameters in the order of the parameter vector."""


class UnknownEffectError(DiagnosisError, ValueError):
    """An effect name that is not in :data:`EFFECT_NAMES` (the message lists the valid ones)."""


def base_vector(misalignment_deg=(0.0,) * 6, transmittance=(0.0,) * 3,
                dop_scale: float = 1.0) -> np.ndarray:
    """Base parameter vector in :data:`BASE_NAMES` order."""
    return np.r_[np.asarray(misalignment_deg, float), np.asarray(transmittance, float),
                 float(dop_scale)]


@dataclass
class Context:
    """Everything the forward model needs besides the parameters (one data set).

    Attributes
    ----------
    site : Site
    t_s : ndarray (n,)
        Recorded sample times [s since 1970-01-01 UTC].
    heading_deg : ndarray (n,)
        Recorded heading of the sensor reference axis [deg].
    block : ndarray (n,) of int
        Sweep (acquisition block) index of each sample.
    frac : ndarray (n,)
        Position of each sample within its block, 0 (first row) .. 1 (last row).
    illuminance_lx : ndarray (n,) or None
        Scene illuminance [lx] where recorded.
    temperature_C : ndarray (n,) or None
        Sensor temperature [degC] where recorded.
    sun : SunTrack
    t_ref_s : float
        Reference time [s] of time-proxy drifts (the first sample of the whole data set).
    """

    site: Site
    t_s: np.ndarray
    heading_deg: np.ndarray
    block: np.ndarray
    frac: np.ndarray
    illuminance_lx: np.ndarray | None = None
    temperature_C: np.ndarray | None = None
    sun: SunTrack | None = None
    t_ref_s: float | None = None
    cache: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        self.t_s = np.asarray(self.t_s, dtype=float)
        self.heading_deg = np.asarray(self.heading_deg, dtype=float)
        if self.t_ref_s is None:
            self.t_ref_s = float(self.t_s.min())
        if self.sun is None:
            self.sun = SunTrack(self.site, float(self.t_s.min()), float(self.t_s.max()))

    @classmethod
    def from_arrays(cls, site: Site, times, heading_deg, block=None, illuminance_lx=None,
                    temperature_C=None) -> Context:
        """Build a context from timezone-aware times and per-sample arrays (row order kept)."""
        t_s = as_utc_index(times).as_unit("ns").asi8 / 1e9
        n = t_s.size
        block = np.zeros(n, int) if block is None else pd.factorize(np.asarray(block))[0]
        rank = pd.Series(np.arange(n)).groupby(block).rank(method="first").to_numpy() - 1.0
        size = pd.Series(block).map(pd.Series(block).value_counts()).to_numpy()
        frac = rank / np.maximum(size - 1, 1)
        opt = [None if a is None else np.asarray(a, float) for a in (illuminance_lx,
                                                                       temperature_C)]
        return cls(site, t_s, np.asarray(heading_deg, float), block, frac, *opt)

    @property
    def n(self) -> int:
        return self.t_s.size

    def subset(self, rows) -> Context:
        """The same data set restricted to ``rows`` (a boolean mask or indices)."""
        pick = (lambda a: None if a is None else a[rows])
        return Context(self.site, self.t_s[rows], self.heading_deg[rows], self.block[rows],
                       self.frac[rows], pick(self.illuminance_lx), pick(self.temperature_C),
                       self.sun, self.t_ref_s)


class Effect(abc.ABC):
    """One unmodelled physical effect: parameters, priors, forward hooks and generation range.

    Subclasses set the class attributes and override the hooks their physics touches; every
    hook's default leaves the base model unchanged, and every effect reduces to the base model
    at its :attr:`null` parameters (tested).

    Attributes
    ----------
    name : str
    parameter_names, units : tuple of str
    bounds : ndarray (k, 2)
        Physical bounds; a fit clips its parameters into them.
    prior_mean, prior_sd : ndarray (k,)
        Gaussian prior of a fit (weak; it only fixes directions the data cannot see).
    fd_step : ndarray (k,)
        Finite-difference step of each parameter for the fit Jacobian.
    stage : {"geometry", "output"}
        Which forward stage the parameters enter.
    null : ndarray (k,)
        Parameters at which the effect vanishes.
    generation_range : dict
        Documented magnitudes :meth:`draw` samples from (human-readable, for reports).
    """

    name = "abstract"
    parameter_names: tuple = ()
    units: tuple = ()
    bounds = np.zeros((0, 2))
    prior_mean = np.zeros(0)
    prior_sd = np.zeros(0)
    fd_step = np.zeros(0)
    stage = "output"
    null = np.zeros(0)
    generation_range: ClassVar[dict] = {}

    @property
    def k(self) -> int:
        return len(self.parameter_names)

    def available(self) -> str | None:
        """None when the effect can run here, else why not (a missing optional engine)."""
        return None

    def starts(self) -> list[np.ndarray]:
        """Initial parameter vectors of a fit (several for multi-modal problems)."""
        return [np.clip(self.prior_mean, self.bounds[:, 0], self.bounds[:, 1])]

    @abc.abstractmethod
    def draw(self, rng: np.random.Generator) -> np.ndarray:
        """Draw parameters from :attr:`generation_range` (benchmark generator); every effect
        defines its own documented magnitudes."""

    def clip(self, p) -> np.ndarray:
        return np.clip(np.asarray(p, float), self.bounds[:, 0], self.bounds[:, 1])

    # --- forward hooks (defaults: no change) ---------------------------------------------
    def time_shift_s(self, ctx: Context, p) -> np.ndarray | float:
        """True minus recorded time [s] of each sample."""
        return 0.0

    def heading_shift_deg(self, ctx: Context, p) -> np.ndarray | float:
        """True minus recorded heading [deg] of each sample."""
        return 0.0

    def polarization(self, ctx: Context, p, heading_deg, sun_el_deg, sun_az_deg):
        """``(phi_deg, dop_shape)`` seen by the sensor, or None for the base zenith model."""
        return

    def channel_terms(self, ctx: Context, p) -> dict:
        """Output-stage terms, any of: ``extinction`` = ``(k, eta)`` of the six polarizers
        (:func:`sensor.photodiode.extinction_factors`), ``dark_ratio`` (n or 1, 6) dark-to-signal
        ratios, ``gain_factor`` (n, 1 or 3) and ``offset_V`` (n, 3) [V] of the amplifiers."""
        return {}

    def output_jacobian(self, ctx: Context, p, parts: dict):
        """Analytic ``dU/dp`` (n, 3, k) of an output-stage effect, or None (finite differences).

        ``parts`` holds the per-sample quantities of :func:`jacobians`: ``A``, ``B`` (numerator
        and denominator terms, (n, 3)), ``dc1``, ``dc2`` (``d cos 2x``), ``G_ln10`` (gain over
        ln 10), ``gain`` (nominal) and ``log_ratio`` (the bracket of the module equation).
        """
        return

    def describe(self, p) -> dict:
        return dict(zip(self.parameter_names, np.asarray(p, float).tolist()))


def get_effect(name: str) -> Effect:
    """The effect called ``name``.

    Raises
    ------
    UnknownEffectError
        For a name not in :data:`EFFECT_NAMES` (the message lists the valid names).
    """
    if name not in EFFECT_NAMES:
        raise UnknownEffectError(f"unknown effect {name!r}; valid: {', '.join(EFFECT_NAMES)}")
    module = importlib.import_module(f"{__name__}.{name}")
    return module.EFFECT


def all_effects(names=EFFECT_NAMES) -> list[Effect]:
    """Effects by name, in the given order (validates every name first)."""
    names = list(names)
    for n in names:
        if n not in EFFECT_NAMES:
            get_effect(n)  # raises with the list of valid names
    return [get_effect(n) for n in names]


def zenith_rayleigh(heading_deg, sun_el_deg, sun_az_deg):
    """Base sky seen at the zenith: ``phi = wrap(h - sun_az)`` and the Rayleigh DoP shape.

    At the zenith the scattering angle equals the solar zenith angle and the single-scattering
    E-vector is perpendicular to the solar meridian (Coulson 1988, ch. 2).
    """
    phi = wrap_axial_deg(np.asarray(heading_deg) - sun_az_deg)
    shape = rayleigh.degree_of_polarization(90.0 - np.asarray(sun_el_deg), 1.0)
    return phi, shape


def geometry(ctx: Context, effect: Effect | None = None, p=None):
    """Stage 1: ``(phi_deg, dop_shape)`` of every sample (see module docstring)."""
    t = ctx.t_s
    h = ctx.heading_deg
    if effect is not None:
        t = t + effect.time_shift_s(ctx, p)
        h = h + effect.heading_shift_deg(ctx, p)
    sun_el, sun_az = ctx.sun.elevation_azimuth(t)
    out = None if effect is None else effect.polarization(ctx, p, h, sun_el, sun_az)
    return zenith_rayleigh(h, sun_el, sun_az) if out is None else out


_A = CHANNEL_ANGLES_DEG
_DOP_MAX = 1.0 - 1e-9


def outputs(ctx: Context, phi_deg, dop_shape, base, effect: Effect | None = None, p=None,
            gain: float = GAIN) -> np.ndarray:
    """Stage 2: channel outputs ``U`` (n, 3) [V] (module docstring equation).

    The photodiodes and amplifiers are those of :mod:`sensor.photodiode` (Malus's law for a
    partial polarizer plus dark current, log-ratio amplifier) at unit intensity: the
    responsivities ``(10^f_i, 1)`` of each pair carry the transmittance term, a dark-to-signal
    ratio ``delta`` becomes the dark level ``delta * responsivity * k``.
    """
    base = np.asarray(base, float)
    terms = {} if effect is None else effect.channel_terms(ctx, p)
    d = np.clip(base[9] * np.asarray(dop_shape, float), 0.0, _DOP_MAX)[:, None, None]
    phi = np.asarray(phi_deg, float)[:, None, None]
    alpha = _A[:, None] + np.array([0.0, 90.0]) + base[:6].reshape(3, 2)
    resp = np.stack([10.0 ** base[6:9], np.ones(3)], axis=-1)
    k, eta = terms.get("extinction", (np.ones(6), np.ones(6)))
    k, eta = np.reshape(k, (-1, 3, 2)), np.reshape(eta, (-1, 3, 2))
    dark = np.reshape(terms.get("dark_ratio", np.zeros(6)), (-1, 3, 2)) * resp * k
    s = photodiode_signal(1.0, phi, d, -alpha, responsivity=resp, dark=dark,
                          extinction_intensity=k, extinction_efficiency=eta)
    return opponent_log_ratio(s[..., 0], s[..., 1], gain=gain * terms.get("gain_factor", 1.0),
                              offset_V=terms.get("offset_V", 0.0))


def jacobians(ctx: Context, phi_deg, dop_shape, base, effect: Effect | None = None,
              p=None, gain: float = GAIN):
    """Analytic derivatives of :func:`outputs`: base (n, 3, 10) and effect (n, 3, k) or None.

    With ``A = 1 + eta_1 d cos 2x_1 + delta_1``, ``B = 1 - eta_2 d cos 2x_2 + delta_2`` and
    ``G`` the gain (module docstring)::

        dU/de1 = -(G / ln10) 2 eta_1 d sin 2x_1 / A * pi/180
        dU/de2 = -(G / ln10) 2 eta_2 d sin 2x_2 / B * pi/180
        dU/df  = G
        dU/ds  =  (G / ln10) shape (eta_1 cos 2x_1 / A + eta_2 cos 2x_2 / B)

    (eq. 12 of Yang et al. 2014 generalised; reduces to :mod:`calibration.model` when
    ``eta = 1``, ``delta = 0``). Columns for the mounting errors of other channels are zero.
    Output-stage effects supply their columns through :meth:`Effect.output_jacobian` from the
    same intermediate quantities; the effect block is None when they do not (a fit then uses
    finite differences).
    """
    base = np.asarray(base, float)
    terms = {} if effect is None else effect.channel_terms(ctx, p)
    shape = np.asarray(dop_shape, float)[:, None]
    d = np.clip(base[9] * shape, 0.0, _DOP_MAX)
    phi = np.asarray(phi_deg, float)[:, None]
    x1 = np.radians(2.0 * (phi + _A + base[0:6:2]))
    x2 = np.radians(2.0 * (phi + _A + base[1:6:2]))
    kfac, eta = terms.get("extinction", (np.ones(6), np.ones(6)))
    eta = np.broadcast_to(eta, (1, 6)) if np.ndim(eta) == 1 else eta
    n = len(phi)
    delta = np.broadcast_to(terms.get("dark_ratio", np.zeros((1, 6))), (n, 6))
    dc1, dc2 = d * np.cos(x1), d * np.cos(x2)
    A = 1.0 + eta[:, 0::2] * dc1 + delta[:, 0::2]
    B = 1.0 - eta[:, 1::2] * dc2 + delta[:, 1::2]
    G = gain * np.broadcast_to(terms.get("gain_factor", 1.0), (n, 3))
    k = G / np.log(10.0)
    J = np.zeros((n, 3, 10))
    rad = np.pi / 180.0
    ch = np.arange(3)
    J[:, ch, 2 * ch] = -k * 2 * eta[:, 0::2] * d * np.sin(x1) / A * rad
    J[:, ch, 2 * ch + 1] = -k * 2 * eta[:, 1::2] * d * np.sin(x2) / B * rad
    J[:, ch, 6 + ch] = G
    J[:, :, 9] = k * shape * (eta[:, 0::2] * np.cos(x1) / A + eta[:, 1::2] * np.cos(x2) / B)
    Je = None
    if effect is not None:
        kfac = np.reshape(kfac, (-1, 6))
        log_ratio = (np.log10(kfac[:, 0::2] * A / (kfac[:, 1::2] * B)) + base[6:9])
        parts = {"A": A, "B": B, "dc1": dc1, "dc2": dc2, "G_ln10": k, "gain": gain,
                 "log_ratio": log_ratio}
        Je = effect.output_jacobian(ctx, p, parts)
    return J, Je


def forward(ctx: Context, base, effect: Effect | None = None, p=None,
            gain: float = GAIN) -> np.ndarray:
    """Noise-free channel outputs (n, 3) [V] of the base model plus one effect."""
    phi, shape = geometry(ctx, effect, p)
    return outputs(ctx, phi, shape, base, effect, p, gain)


def unit_vector_frame(heading_deg):
    """Level sensor frame at a heading: reference axis ``x``, ``y`` (x turned 90 deg clockwise
    seen from above) and ``z`` (up), each (n, 3) in ENU."""
    h = np.asarray(heading_deg, dtype=float)
    x = direction_vector(0.0, h)
    y = direction_vector(0.0, h + 90.0)
    z = np.broadcast_to(np.array([0.0, 0.0, 1.0]), x.shape)
    return x, y, z
