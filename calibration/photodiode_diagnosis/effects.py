"""Unmodelled effects of real multi-unit (ring) compasses, each a physical extension of the
base model that reduces to it at its null parameters (tested), used to fit here and, through
the same physics library (:mod:`skysim`, :mod:`sensor`), to inject in the blind benchmark.

- ``multiple_scattering`` (``tau``, ``albedo``; ``albedo`` alone when the band is known): the
  sky of :class:`skysim.multiple.MultipleScatteringSky` (plane-parallel Rayleigh atmosphere of
  optical thickness ``tau`` over a Lambertian ground, validated against Natraj et al. 2009)
  instead of single scattering; the DoP scale stays free. With the instrument's band known,
  ``tau`` is the air's at the band and the site's pressure, not fitted. Tends to the base sky
  as ``tau -> 0``.
- ``aerosol`` (``aod_550``): Rayleigh and aerosol multiple scattering
  (:class:`skysim.aerosol.AerosolSky`, OPAC continental average) with the AOD fitted.
- ``neutral_points`` (``separation_deg``): the Berry, Dennis & Lee (2004) sky whose neutral
  points stand ``separation / 2`` either side of the sun and anti-sun (the real sky's are
  15-25 deg from the sun): DoP higher near the sun and flatter overall. Base at 0.
- ``overcast`` (``cloud_tau``): a uniform cloud layer over the whole sky
  (:class:`skysim.partly_cloudy.PartlyCloudySky` at cover 1): the clear sky's pattern passes
  below and through the cloud, attenuated with its optical thickness, and the droplets add
  their own bright, weakly polarized light, strongest towards the sun. Base at ``tau = 0``.
- ``fov`` (``hwhm_deg``): each unit's photodiodes weigh the sky's Stokes vector, radiance
  included, by the units' measured angular acceptance (:mod:`.acceptance`: a torch scan of
  the Gkanias et al. 2023 units, HWHM 22.7 deg, an edge steeper than a Gaussian), its width
  free from 0 to 60 deg (a bare photodiode's cosine response, the widest a casing allows);
  Gauss-Legendre in the off-axis angle times equal azimuth steps (:data:`FOV_NODES`), on
  the visible arcs where the horizon cuts the acceptance, the ground dark. Base at
  ``hwhm = 0``.
- ``occlusion`` (``center_deg``, ``width_deg``, ``depolarization``, ``edge_deg``): a sector of
  sky azimuth (world frame) blocked by canopy or buildings. What reaches a unit looking into
  it is foliage-scattered, nearly unpolarized light: its DoP is multiplied by
  ``1 - depolarization * w(az)``, ``w`` a box over the sector with logistic edges of width
  ``edge_deg`` (a unit's own field of view blurs the edge over a fraction of its acceptance
  angle, and a ragged tree line more; at most 12 deg, the blur of the widest cone of view
  the ``fov`` candidate allows). The darkening is absorbed by the profiled radiance.
  Base at ``depolarization = 0``.
- ``yaw_scale`` (``factor``): the recorded yaw change within a sweep is ``factor`` times the
  true change (a gyro scale-factor error): ``true = y_0 + (y_rec - y_0) / factor``. Base at 1.
- ``clock_offset`` (``clock_offset_s``): true minus recorded time, from seconds to whole-hour
  timezone errors (up to +-14 h), searched on whole and half hours before refining.
- ``aureole`` (``amplitude``, ``scale_deg``): unpolarized light added near the sun, from
  aerosol forward scattering (the solar aureole) and stray sunlight inside a unit, with a
  radiance relative to the sky's of ``A exp(-psi / psi_0)`` at angular distance ``psi`` from
  the sun (the aureole falls off roughly exponentially over its first tens of degrees,
  Deepak & Box 1978 [3]_); the DoP becomes ``d / (1 + A exp(-psi / psi_0))``. Base at
  ``A = 0``.
- ``stray_light`` (``S_p`` per photodiode, ``scale_deg``): sunlight scattered inside the
  instrument onto each photodiode, unpolarized and of its own strength, falling off with the
  sun's distance from the unit's axis. Base at ``S = 0``.
- ``side_glare`` (``L_p``, ``R_p`` per photodiode, ``scale_deg``): ``stray_light`` of its
  own strength for the sun on either side of a unit:
  ``exp(-psi / psi_0) (L_p (1 + s) + R_p (1 - s)) / 2``, ``s`` the sine of the sun's bearing
  about the unit's axis (+1 with the sun square to the unit's left, -1 to its right;
  :func:`sun_side`), both strengths non-negative.
  Light reaching a unit's photodiodes unequally through its casing breaks the unit's sum rule
  ``r0 + r90 = r45 + r135`` with a sign that flips with the sun's side, which the model-free
  checks test (:func:`.checks.check_instrument`). Base at ``L = R = 0``; ``stray_light`` at ``L = R``.
- ``read_lag`` (``lag_s``): the readings at recorded time ``t`` were taken at the yaw recorded
  at ``t - lag`` (a delay between the attitude record and the converter); the recorded yaw is
  interpolated within each sweep (:func:`lagged_yaw`). Acts only while the instrument turns,
  so the residual of moving samples drops and that of standing ones does not. Base at 0.
- ``tilt`` (``pitch_deg``, ``roll_deg``): a constant tilt of the instrument on the platform
  (added to the recorded attitude), so the units' views circle the zenith as it turns. Base
  at 0.

References
----------
.. [1] V. Natraj, K.-F. Li, Y. L. Yung, "Rayleigh scattering in planetary atmospheres:
   corrected tables through accurate computation of X and Y functions", ApJ 691:1909 (2009),
   doi:10.1088/0004-637X/691/2/1909.
.. [3] A. Deepak, M. A. Box, "Forward scattering corrections for optical extinction
   measurements in aerosol media", Appl. Opt. 17(18):2900-2908 (1978),
   doi:10.1364/AO.17.002900 (aureole radiance vs scattering angle).
.. [4] R. P. Breault, "Control of stray light", in Handbook of Optics vol. I, 2nd ed.,
   McGraw-Hill (1995), ch. 38 (point-source transmittance of baffled sensors).
.. [5] G. Pomozi, G. Horváth, R. Wehner, "How the clear-sky angle of polarization pattern
   continues underneath clouds", J. Exp. Biol. 204:2933-2942 (2001).
.. [6] R. Hegedüs, S. Åkesson, G. Horváth, "Polarization patterns of thick clouds: overcast
   skies have distribution of the angle of polarization similar to that of clear skies",
   J. Opt. Soc. Am. A 24(8):2347-2356 (2007), doi:10.1364/JOSAA.24.002347.
.. [7] NOAA, NASA, USAF, *U.S. Standard Atmosphere, 1976*, NOAA-S/T 76-1562, U.S.
   Government Printing Office (1976).
.. [8] B. A. Bodhaine, N. B. Wood, E. G. Dutton, J. R. Slusser, "On Rayleigh optical depth
   calculations", J. Atmos. Oceanic Technol. 16(11):1854-1861 (1999),
   doi:10.1175/1520-0426(1999)016<1854:ORODC>2.0.CO;2.
.. [2] E. Gkanias, R. Mitchell, J. Stankiewicz, S. R. Khan, S. Mitra, B. Webb, "Celestial
   compass sensor mimics the insect eye for navigation under cloudy and occluded skies",
   Commun. Eng. 2:82 (2023), doi:10.1038/s44172-023-00132-w (ring compass, canopy scenes).
"""

from __future__ import annotations

import importlib.util
import re
from dataclasses import replace
from typing import ClassVar

import numpy as np

from sensor.compound_eye import SkySample
from skysim.geometry import direction_vector, elevation_azimuth, wrap_deg

from ..diagnosis.errors import EffectUnavailableError
from ..effects import UnknownEffectError
from .acceptance import ACCEPTANCE_HWHM_DEG, HWHM_MAX_DEG, observe_cut_acceptance

__all__ = ["RING_EFFECT_NAMES", "RingEffect", "EffectUnavailableError", "get_ring_effect",
           "occlusion_weight", "integrate_stokes", "FIT_STREAMS",
           "fit_engine_settings", "sun_side", "lagged_yaw", "FOV_NODES"]

RING_EFFECT_NAMES = ("neutral_points", "fov", "occlusion", "yaw_scale", "clock_offset",
                     "aureole", "stray_light")
"""The default candidates: those that recover their own simulated effect on a ring
(``skysim identifiability --instrument ring``, ``docs/diagnosis.md``). The others are asked
for by name (``--effects multiple_scattering,...``):

- ``aerosol``: its engine runs (Mie phase matrices on a 25 x 37 table, per AOD and sun node)
  add minutes to a session, beyond the one-minute goal of a default diagnosis on this
  machine class;
- ``multiple_scattering``: a simulated ring under a multiple-scattering sky (tau 0.25,
  albedo 0.1) on three one-minute sweeps keeps a held-out gap of 1.06 times the noise floor
  after the base fit, as clean data do: a 0/90 gain imbalance with the 45 and 135 deg films
  turned by half of it is exactly a change of the polarization each unit sees (a Lorentz
  boost of its Stokes vector, which the per-unit sum rule cannot see), and the base fit
  takes the sky's shape up that way while the sun stands still. With the sun moving
  between sweeps (three sweeps 90 min apart) the gains cannot follow it and the candidate
  is named with its own tau and albedo (and without it the neutral-point sky is named for
  it: ask for it on such sessions); real gains differ by up to 12 % between photodiodes, so
  no prior tying them to a common value could stand in for that;
- ``tilt``: a constant tilt of the instrument turns with it, so it is exactly a change of
  every unit's pointing and polarizer angle, which the base model fits per unit: it can be
  read only with the pointing calibrated on other sessions (``--pointing-from``);
- ``overcast``, ``side_glare``, ``read_lag``: for the skies and instruments that call for
  them (a cloud layer over the whole sky; glare stronger on one side of a unit; readings
  lagging the yaw record, which needs standing samples beside turning ones)."""
OPTIONAL_EFFECT_NAMES = ("aerosol", "multiple_scattering", "tilt", "overcast", "side_glare",
                         "read_lag")


class RingEffect:
    """Base class: the hooks are identities (the base model)."""

    name: ClassVar[str] = ""
    parameter_names: ClassVar[tuple] = ()
    units: ClassVar[tuple] = ()
    null: ClassVar[tuple] = ()
    lower: ClassVar[tuple] = ()
    upper: ClassVar[tuple] = ()
    prior_sd: ClassVar[tuple] = ()
    fd_step: ClassVar[tuple] = ()
    time_margin_s: ClassVar[float] = 0.0
    observes: ClassVar[bool] = False
    output_only: ClassVar[bool] = False
    """True when the parameters act on the readings only (no new sampling of the sky)."""
    per_photodiode: ClassVar[int] = 0
    """Number of leading parameters that are one per photodiode (after :meth:`bind`): a
    multiple of the number of photodiodes, in blocks of one parameter each."""
    geometric: ClassVar[bool] = False
    """True when the effect moves where the units look or where the sun is (clock, tilt, yaw
    scale): its parameters are fitted, with the units' pointing, on the angle of polarization
    alone (the DoP profiled out), so that a DoP profile the sky model lacks cannot be traded
    for a false clock, tilt or pointing; then held."""

    pointing: ClassVar[str] = "held"
    """How the units' pointing is read when the effect is fitted (:func:`.run._fit_start`):
    ``"held"`` where the base model read it (:func:`.fit.fit_pinned`); ``"joint"`` with a
    geometric effect on the angle of polarization (:func:`.run._joint_geometry`);
    ``"under_effect"`` from the angle of polarization under each value of a one-parameter
    effect, the value the profile cost's minimum (:func:`.run._pointing_under_effect`);
    ``"full_fit"`` freed in the full model after the AoP stage, tied to its reading
    (:func:`.run._pointing_in_full_fit`)."""

    continue_iter: ClassVar[int | None] = None
    """Iterations of the continuation of a fit stopped on its way (:func:`.run._continued`);
    None: the default budget (:data:`.run.EFFECT_CONTINUE_ITER`)."""

    hold_at_bounds: ClassVar[bool] = False
    """True when the fits with the effect hold a parameter at a bound while the cost falls
    outwards (:func:`calibration.diagnosis.lm.levenberg_marquardt`), for effects with many
    amplitudes whose null is a bound; otherwise trials are only clipped into the bounds,
    the handling with which the ring's other candidates are measured."""

    dop_scale_in_sky: ClassVar[bool] = False
    """True when the effect's sky takes the DoP scale ``s`` on the base sky it wraps (its
    argument ``base_sky`` is then the base sky of maximum DoP ``s``), instead of ``s``
    scaling the DoP of all the light a unit sees: light the effect adds (a cloud's own) is
    not depolarized with the clear sky."""

    def bind(self, inst) -> None:
        """Adapt the parameter list to an instrument (per-photodiode effects)."""

    def additive(self, p, obs: SkySample, sun_enu, pd_unit) -> np.ndarray | None:
        """An additive reading term (n, P) [session-median units], or None."""
        return None

    @property
    def k(self) -> int:
        return len(self.parameter_names)

    @property
    def prior_mean(self) -> np.ndarray:
        return np.asarray(self.null, float)

    def starts(self, ctx) -> list:
        """Starting vectors (the caller keeps the best after a short fit)."""
        return [np.asarray(self.null, float)]

    def time_shift_s(self, p) -> float:
        return 0.0

    def yaw(self, inst, p) -> np.ndarray:
        return inst.yaw_deg

    def attitude(self, pitch, roll, p):
        return pitch, roll

    def sky(self, p, base_sky, sun_enu):
        return base_sky

    def observe(self, sensor, sky, att, sun, p) -> SkySample:
        """What every unit sees, for effects with ``observes = True`` (default: the sensor's
        own sampling)."""
        return sensor.observe(sky, att, sun)

    def modify(self, obs: SkySample, p, sun_enu=None) -> SkySample:
        return obs

    def available(self) -> str | None:
        """None when the effect can run on this machine, else why not (a missing optional
        engine)."""
        return None

    def available_at(self, sun_elevation_deg) -> str | None:
        """None when the effect can run on a session whose sun (or moon) stands at
        ``sun_elevation_deg`` [deg] (array of the samples' elevations), else why not: what
        :meth:`available` says, or a sky the effect's model does not hold for."""
        return self.available()

    def applicable_to(self, inst) -> str | None:
        """None when the effect can be told apart on this instrument's session, else why not
        (a parameter the base model already fits in another guise)."""
        return None

    holdable: ClassVar[tuple] = ()
    """Parameters that may be held at a given value (:meth:`hold`): those an instrument
    shares across sessions, held at a day's value."""

    def hold(self, values: dict) -> None:
        """Hold parameters at given values instead of fitting them (``values``: name ->
        value, in the parameter's unit); a candidate asked for as
        ``"side_glare(scale_deg=94)"`` (:func:`get_ring_effect`).

        Raises
        ------
        UnknownEffectError
            For a parameter this candidate cannot hold, or a value outside its range,
            naming it.
        """
        bad = sorted(set(values) - set(self.holdable))
        if bad:
            raise UnknownEffectError(
                f"{self.name} cannot hold {', '.join(bad)}; it can hold: "
                f"{', '.join(self.holdable) or 'nothing'}")

    @property
    def held_values(self) -> dict:
        """Parameters held at a value (:meth:`hold`): name -> value; empty when none."""
        return {}


class ClockOffset(RingEffect):
    name = "clock_offset"
    geometric = True
    parameter_names = ("clock_offset_s",)
    units = ("s",)
    null = (0.0,)
    lower = (-14 * 3600.0,)
    upper = (14 * 3600.0,)
    prior_sd = (6 * 3600.0,)
    fd_step = (5.0,)
    time_margin_s = 15 * 3600.0
    pointing: ClassVar[str] = "joint"
    """Fitted jointly with the units' pointing on the angle of polarization
    (:func:`.run._joint_geometry`): over a session of real length (12 sweeps over 12 min)
    the sun's track tells a clock from a common shift of the units' elevations (on a
    simulated ring, 923 +- 16 s for a 900 s error, where the pointing held at the base fit's
    gave -7 +- 11 s)."""
    COARSE_S: ClassVar[np.ndarray] = np.arange(-28, 29) * 1800.0
    """Whole and half hours within +-14 h: timezone and daylight-saving errors."""

    def time_shift_s(self, p) -> float:
        return float(p[0])


class YawScale(RingEffect):
    name = "yaw_scale"
    geometric = True
    parameter_names = ("factor",)
    units = ("1",)
    null = (1.0,)
    lower = (0.8,)
    upper = (1.25,)
    prior_sd = (0.1,)
    fd_step = (1e-4,)
    pointing: ClassVar[str] = "joint"
    """Fitted jointly with the units' pointing on the angle of polarization: constant
    pointing offsets cannot stand in for a heading error that grows along each turn
    (:func:`.run._joint_geometry`)."""

    def starts(self, ctx) -> list:
        """Factors 0.85-1.15 in steps of 0.01 (the best-scoring one starts the fit, with the
        pointing re-read there): the base fit's pointing takes up part of a gyro scale, and
        from the null the fit can stop in another valley on a session of few sweeps."""
        return [np.array([f]) for f in np.round(np.arange(0.85, 1.1501, 0.01), 2)]

    def yaw(self, inst, p) -> np.ndarray:
        first = np.r_[True, inst.sweep[1:] != inst.sweep[:-1]]
        y0 = inst.yaw_deg[first][np.cumsum(first) - 1]
        return y0 + (inst.yaw_deg - y0) / float(p[0])


ZENITH_UNIT_DEG = 85.0
"""A unit this high [deg, nominal elevation] looks at the zenith (its pointing offsets cannot
stand in for a tilt of the instrument)."""


class Tilt(RingEffect):
    name = "tilt"
    geometric = True
    parameter_names = ("pitch_deg", "roll_deg")
    units = ("deg", "deg")
    null = (0.0, 0.0)
    lower = (-15.0, -15.0)
    upper = (15.0, 15.0)
    prior_sd = (5.0, 5.0)
    fd_step = (1e-2, 1e-2)

    def attitude(self, pitch, roll, p):
        return pitch + p[0], roll + p[1]

    def applicable_to(self, inst) -> str | None:
        """A tilt in the body frame turns with the instrument: every unit's view and
        polarizer are rotated by one fixed rotation, which for units looking away from the
        zenith is exactly a change of each unit's pointing (elevation and azimuth offsets)
        and polarizer angle. With that pointing fitted on the session the two cannot be told
        apart; with it calibrated on other sessions they can. A unit at the zenith has no
        azimuth to offset and its elevation cannot rise past 90 deg, so its pointing cannot
        stand in for a tilt."""
        p = inst.pointing_deg
        at_zenith = any(u.elevation_deg >= ZENITH_UNIT_DEG for u in inst.sensor.units)
        if not at_zenith and (p is None or not np.all(np.isfinite(p))):
            return ("a constant tilt turns with the instrument, as a change of every unit's "
                    "pointing and polarizer angle, which the base model fits on this session: "
                    "calibrate the pointing on other sessions (--pointing-from) to fit it")
        return None


FOV_NODES = (6, 6)
"""Gauss-Legendre nodes in the off-axis angle x midpoint nodes in the azimuth of the ``fov``
candidate's quadrature where the horizon does not cut the acceptance
(:func:`.acceptance.acceptance_quadrature`; where it cuts, :attr:`FieldOfView.nodes`).
Against a 32 x 64 rule on the single-scattering sky seen by units at 45 deg elevation, its
normalised Stokes parameters ``Q/I``, ``U/I`` differ by at most 4e-5 at a HWHM of 10 deg and
1.5e-4 at 22.7 and 30 deg, the radiance by 4e-5, 1.5e-4 and 5e-4 (tested; a ring's readings
carry about 4e-3 of noise; 4 x 6 nodes: 3e-3 at 22.7 deg)."""


def integrate_stokes(radiance, dop, aop_deg, axis, weights=None):
    """Weighted sum of the Stokes vectors along ``axis``: ``(I, dop, aop_deg)``.

    ``I = sum w L``, ``Q = sum w L d cos 2 chi``, ``U = sum w L d sin 2 chi``: the sky's
    radiance ``L`` weights each direction's polarization, as in a photodiode's reading.

    Parameters
    ----------
    radiance, dop, aop_deg : ndarray
        Radiance, degree [0-1] and angle [deg] of polarization of each direction, one frame
        for the angles along ``axis``.
    axis : int
        Axis to integrate over.
    weights : ndarray, optional
        Weights along ``axis`` (1-D, summing to 1); equal weights when omitted.

    Returns
    -------
    I, dop, aop_deg : ndarray
        Integrated radiance, its degree and angle [deg] of polarization.
    """
    x = np.radians(2.0 * np.asarray(aop_deg, float))
    radiance = np.asarray(radiance, float)
    if weights is None:
        w = np.full(radiance.shape[axis], 1.0 / radiance.shape[axis])
    else:
        w = np.asarray(weights, float)
    w = np.expand_dims(w, tuple(i for i in range(radiance.ndim) if i != axis % radiance.ndim))
    I = np.sum(w * radiance, axis=axis)
    Q = np.sum(w * radiance * dop * np.cos(x), axis=axis)
    U = np.sum(w * radiance * dop * np.sin(x), axis=axis)
    return I, np.hypot(Q, U) / I, 0.5 * np.degrees(np.arctan2(U, Q))


class FieldOfView(RingEffect):
    """Each unit's photodiodes weigh the sky by the units' measured angular acceptance
    (:mod:`.acceptance`) of half-width ``hwhm_deg``; base at 0 (a pencil beam)."""

    name = "fov"
    parameter_names = ("hwhm_deg",)
    units = ("deg",)
    null = (0.0,)
    lower = (0.0,)
    upper = (HWHM_MAX_DEG,)
    prior_sd = (30.0,)
    fd_step = (0.05,)
    observes = True
    pointing: ClassVar[str] = "under_effect"
    """The units' pointing is read again from the angle of polarization under each width,
    and the width is the minimum of the full model's cost along that path
    (:func:`.run._pointing_under_effect`): the base model's pointing, read under a pencil
    beam, takes up part of an acceptance the horizon cuts (every elevation 1.5 deg high at
    a HWHM of 45 deg)."""
    two_step_sd: ClassVar[bool] = True
    """Its SE is the two-step sandwich over samples (:func:`.run._two_step_sd`) along the
    pointing the angle of polarization reads under the width: the width trades with the
    DoP scale and the gains, and with that pointing."""

    def starts(self, ctx) -> list:
        return [np.array([ACCEPTANCE_HWHM_DEG]), np.array([8.0])]

    nodes: ClassVar[tuple] = (FOV_NODES[0], FOV_NODES[1], 8)
    """Nodes of its rule (:func:`.acceptance.horizon_quadrature`): Gauss-Legendre in the
    off-axis angle on the visible cap and on the band the horizon cuts, midpoints in the
    azimuth on the cap's full circles, Gauss-Legendre on the band's visible arcs. Against a
    200 x 200 equal-area grid that drops every direction below the horizon at each sample,
    on the single-scattering sky seen by units at 45 deg elevation, its ``Q/I`` and ``U/I``
    differ by at most 4e-5 at a HWHM of 30-60 deg and its radiance by 1.6e-4 (6 nodes on
    the arcs: 4e-4 in ``Q/I``; a rule that drops the directions below the horizon whole:
    4e-3 to 8e-3); just past where the horizon starts to cut (24-28 deg) the cap's nodes
    span the acceptance's steep edge as the uncut rule's do, 1.7e-4 to 2.7e-4 in ``Q/I``;
    below a HWHM of about 23.8 deg the horizon does not cut the acceptance and the rule is
    :data:`FOV_NODES` (tested in ``tests/test_fov_horizon.py``)."""

    def observe(self, sensor, sky, att, sun, p) -> SkySample:
        if p[0] <= 0.0:
            return sensor.observe(sky, att, sun)
        n_polar, n_azimuth, n_arc = self.nodes
        return observe_cut_acceptance(sensor, sky, att, sun, p[0], n_polar=n_polar,
                                      n_azimuth=n_azimuth, n_arc=n_arc)


def occlusion_weight(azimuth_deg, center_deg, width_deg, edge_deg: float = 3.0):
    """Soft box over the sector ``center +- width / 2`` of azimuth [deg]: 1 inside, 0 outside."""
    d = np.abs(wrap_deg(np.asarray(azimuth_deg, float) - center_deg))
    return 1.0 / (1.0 + np.exp((d - 0.5 * width_deg) / edge_deg))


class Occlusion(RingEffect):
    name = "occlusion"
    parameter_names = ("center_deg", "width_deg", "depolarization", "edge_deg")
    units = ("deg", "deg", "1", "deg")
    null = (180.0, 90.0, 0.0, 3.0)
    lower = (-720.0, 10.0, 0.0, 1.0)
    upper = (1080.0, 300.0, 1.0, 12.0)
    """The edge's logistic scale is at most 12 deg: a sharp occluder seen through a unit's
    cone of view of half-angle ``alpha`` fades in over about ``2 alpha`` (10-90 % over 1.3
    ``alpha``, a logistic scale of about ``0.3 alpha``), 12 deg at the widest cone the
    ``fov`` candidate allows (40 deg). A DoP deficit that fades over wider angles is the
    sky's own (neutral points, many orders of scattering), not an occluder's: its fit puts
    the edge at this bound, which keeps the occlusion from being named for it."""
    prior_sd = (np.inf, np.inf, 1.0, np.inf)
    fd_step = (0.2, 0.2, 1e-3, 0.05)
    two_step_sd: ClassVar[bool] = True
    """Its SE is the two-step sandwich over samples (:func:`.run._two_step_sd`): the model
    covariance, scaled by the white-noise RMS of all readings, is several times the
    spread of its errors on simulated rings."""
    n_fits: ClassVar[int] = 3
    """Short fits from this many of the best-scoring distinct starts (a sector near the sun
    can at first look like the sky's own misfit there)."""

    def starts(self, ctx) -> list:
        """Sectors every 30 deg, 60, 120 and 180 deg wide, depolarizing 30, 60 and 90 %: a
        start that depolarizes a sector far more than it is scores below the wrong sectors
        (a sector at 100 deg depolarizing 20 %, started at 60 %, scored best at 240 deg)."""
        return [np.array([c, w, d, 3.0]) for c in np.arange(0.0, 360.0, 30.0)
                for w in (60.0, 120.0, 180.0) for d in (0.3, 0.6, 0.9)]

    def modify(self, obs: SkySample, p, sun_enu=None) -> SkySample:
        w = occlusion_weight(obs.view_azimuth_deg, p[0], p[1], p[3])
        return replace(obs, dop=obs.dop * (1.0 - p[2] * w))


FIT_STREAMS = 16
"""Discrete-ordinates streams of the engine runs behind the ``multiple_scattering`` candidate
(the validated default is 32). A Rayleigh phase matrix has Legendre moments up to 2 only, so
the diffuse field converges fast in the number of streams: 16 streams run 2-3 times faster
and differ from 32 by at most 1e-3 in DoLP, 0.06 deg in AoP and 3e-3 in I/I over
tau 0.02-1, albedo 0-0.6 and mu0 0.05-0.98 (tested in ``tests/test_photodiode_diagnosis.py``),
ten times below the relative noise of a real ring's readings (about 1e-2); the radiance is
profiled out of the fit anyway."""


def fit_engine_settings():
    """:class:`skysim.rt_sasktran.EngineSettings` of the candidate's engine runs."""
    from skysim.rt_sasktran import EngineSettings
    return EngineSettings(n_streams=FIT_STREAMS)


class GridMultipleSky:
    """Multiple-scattering sky at any ``(tau, albedo)`` from engine runs on a node grid.

    Nodes: ``tau`` in :data:`TAU_NODES` (interpolated linearly in ``ln tau``), albedo 0, 0.3,
    0.6 (quadratic in albedo: the ground term ``A T / (1 - A s)`` of Chandrasekhar's
    reduction bends by less than ``A s`` ~ 0.1 over the range). The node skies are
    :class:`skysim.multiple.MultipleScatteringSky` objects sharing the sun nodes
    ``sun_step_deg``, ``sun_origin_deg`` (:func:`skysim.multiple.sun_bracket`), so every engine
    run is cached per (tau, albedo, sun node) and reused by every fold and every fit step;
    the node skies a ``(tau, albedo)`` needs at one sun node come from one engine call, and
    their Fourier modes are mixed before they are evaluated (the field is linear in them),
    so a sky costs one evaluation per sun node, not one per node sky.
    """

    TAU_NODES: ClassVar[np.ndarray] = np.array([0.02, 0.05, 0.1, 0.2, 0.4, 1.0])
    ALBEDO_NODES: ClassVar[np.ndarray] = np.array([0.0, 0.3, 0.6])

    def __init__(self, sun_step_deg, sun_origin_deg: float = 0.0, tau: float | None = None):
        """``tau``: one optical thickness, the only node (a thickness fixed by the band and
        the pressure); None: :data:`TAU_NODES`."""
        from skysim.multiple import MultipleScatteringSky
        self.tau_nodes = self.TAU_NODES if tau is None else np.array([float(tau)])
        self.skies = {(i, j): MultipleScatteringSky(tau=float(t), albedo=float(a),
                                                    sun_step_deg=sun_step_deg,
                                                    sun_node_origin_deg=sun_origin_deg,
                                                    settings=fit_engine_settings())
                      for i, t in enumerate(self.tau_nodes)
                      for j, a in enumerate(self.ALBEDO_NODES)}

    def at(self, tau: float, albedo: float):
        from skysim.sky import Sky
        grid = self

        class _Mixed(Sky):
            name = "multiple"

            def _stokes(self, vel, vaz, sel, saz):
                return grid.stokes(tau, albedo, vel, vaz, sel, saz)

            def describe(self):
                return {"model": "multiple", "tau": tau, "albedo": albedo,
                        "interpolated": "ln tau linear, albedo quadratic"}
        return _Mixed()

    def weights(self, tau, albedo) -> dict:
        """Weights of the node skies ``{(i_tau, j_albedo): w}`` (nonzero only) at
        ``(tau, albedo)``."""
        lt = np.log(self.tau_nodes)
        if lt.size == 1:
            i, f = 0, 0.0
        else:
            x = float(np.clip(np.log(tau), lt[0], lt[-1]))
            i = int(np.clip(np.searchsorted(lt, x) - 1, 0, lt.size - 2))
            f = (x - lt[i]) / (lt[i + 1] - lt[i])
        a0, a1, a2 = self.ALBEDO_NODES
        A = float(albedo)
        wa = [(A - a1) * (A - a2) / ((a0 - a1) * (a0 - a2)),
              (A - a0) * (A - a2) / ((a1 - a0) * (a1 - a2)),
              (A - a0) * (A - a1) / ((a2 - a0) * (a2 - a1))]
        return {(ii, j): wt * wa[j] for ii, wt in ((i, 1.0 - f), (i + 1, f))
                for j in range(3) if wt * wa[j] != 0.0}

    def stokes(self, tau, albedo, vel, vaz, sel, saz):
        from skysim.multiple import interval_stokes, mix_modes, prefetch_modes
        w = self.weights(tau, albedo)
        skies = [self.skies[k] for k in w]
        prefetch_modes(skies, sel)   # one engine call per sun node for all node skies

        def modes_at(el):
            return mix_modes([s.modes(el) for s in skies], list(w.values()))
        lo, hi = skies[0]._bracket(sel)
        out = interval_stokes(90.0 - vel, vaz - saz, sel, lo, hi, modes_at)
        return tuple(c.reshape(vel.shape) for c in out)


STANDARD_PRESSURE_HPA = 1013.25
"""Sea-level pressure of the standard atmosphere [hPa]."""


def standard_pressure_hPa(altitude_m) -> np.ndarray:
    """Pressure [hPa] of the standard atmosphere at ``altitude_m`` [m] (troposphere, up to
    11 km): ``p0 (1 - L h / T0)^(g M / (R L))`` with ``L`` = 6.5 K/km, ``T0`` = 288.15 K and
    exponent 5.25588 (U.S. Standard Atmosphere 1976 [7]_, eq. 33a). A site's weather moves
    its pressure by about 1-3 %, and the molecular optical thickness with it."""
    h = np.asarray(altitude_m, float)
    return STANDARD_PRESSURE_HPA * (1.0 - 0.0065 * h / 288.15) ** 5.25588


class MultipleScattering(RingEffect):
    """The multiple-scattering sky of a plane-parallel molecular atmosphere over a
    Lambertian ground (module docstring). With the instrument's band known (the sidecar's
    ``band``), the optical thickness is not fitted: it is the molecular one of the band's
    effective wavelength at the site's standard-atmosphere pressure and gravity (Bodhaine et
    al. 1999 [8]_, :func:`skysim.molecular.bodhaine_optical_thickness`;
    :func:`standard_pressure_hPa`), and only the ground albedo is. With the band unknown,
    ``tau`` stays free beside the albedo and takes up whatever lowers the DoP (aerosols as
    well as molecules), so it reads as an effective thickness, not the air's. With ``tau``
    fixed the candidate has no null that is the base sky (the air's multiple scattering is
    always there, as the ``aerosol`` candidate's lowest node is): its null is a black
    ground, the lower bound of the albedo, where a fit is reported at a bound."""

    name = "multiple_scattering"
    aop_from_own_sky = True
    """The units' pointing is read from the angle of polarization under this sky
    (:func:`.fit.fit_pinned`): held where single scattering's AoP puts it (2 deg low on a
    simulated ring under tau 0.25), the fit runs tau to its lower bound."""

    def __init__(self):
        self._grid = None
        self.tau_fixed = None
        """The band's molecular optical thickness when the band is known, else None."""
        self._set_parameters()

    def _set_parameters(self) -> None:
        if self.tau_fixed is None:
            self.parameter_names, self.units = ("tau", "albedo"), ("1", "1")
            self.null, self.lower, self.upper = (0.0, 0.0), (0.02, 0.0), (1.0, 0.6)
            self.prior_sd, self.fd_step = (0.5, 0.3), (2e-3, 2e-3)
        else:
            self.parameter_names, self.units = ("albedo",), ("1",)
            self.null, self.lower, self.upper = (0.0,), (0.0,), (0.6,)
            self.prior_sd, self.fd_step = (0.3,), (2e-3,)

    def bind(self, inst) -> None:
        """Fix ``tau`` from the instrument's band and site (class docstring), or free it
        when the band is unknown."""
        from skysim.molecular import bodhaine_optical_thickness
        band = (inst.source or {}).get("band_wavelength_nm")
        tau = None
        if band is not None:
            site = inst.site
            tau = float(bodhaine_optical_thickness(
                float(band), standard_pressure_hPa(site.altitude_m), site.latitude_deg,
                site.altitude_m))
        if tau != self.tau_fixed:
            self.tau_fixed, self._grid = tau, None
            self._set_parameters()

    @property
    def prior_mean(self) -> np.ndarray:
        return np.array([0.1] if self.tau_fixed is not None else [0.15, 0.1])

    def starts(self, ctx) -> list:
        return [self.prior_mean]

    def available(self) -> str | None:
        if importlib.util.find_spec("sasktran2") is None:
            return (f"{self.name} needs the radiative-transfer engine: pip install -e "
                    "'.[rt]' in the skysim checkout")
        return None

    def available_at(self, sun_elevation_deg) -> str | None:
        if np.min(sun_elevation_deg) <= 0.0:
            return (f"{self.name} needs the sun above the horizon (plane-parallel "
                    f"atmosphere); got {float(np.min(sun_elevation_deg)):.2f} deg")
        return self.available()

    @staticmethod
    def _session_nodes(sun_enu):
        """Sun-node step and origin [deg] for a session's suns (unit vectors, (n, 3)):
        :func:`skysim.multiple.session_sun_nodes`."""
        from skysim.multiple import session_sun_nodes
        return session_sun_nodes(elevation_azimuth(np.asarray(sun_enu, float))[0])

    def sky(self, p, base_sky, sun_enu):
        if self._grid is None:
            self._grid = GridMultipleSky(*self._session_nodes(sun_enu), tau=self.tau_fixed)
        if self.tau_fixed is not None:
            return self._grid.at(self.tau_fixed, float(p[0]))
        return self._grid.at(float(p[0]), float(p[1]))


class NeutralPoints(RingEffect):
    """The sky of Berry, Dennis & Lee (2004) (:class:`skysim.berry.BerrySky`): the sun's and
    anti-sun's zero of polarization split into neutral-point pairs ``separation_deg`` apart
    (Babinet and Brewster about the sun, Arago about the anti-sun), which makes the DoP
    higher near the sun and flatter overall, as multiple scattering by molecules and aerosols
    does; the AoP departs from single scattering only near the neutral points. Reduces to the
    base sky at separation 0 (the DoP mapping ``|w| / (2 - |w|)`` is then the Rayleigh
    DoP, tested)."""

    name = "neutral_points"
    aop_from_own_sky = True
    """The units' pointing is read from the angle of polarization under this sky
    (:func:`.fit.fit_pinned`): held where single scattering's AoP puts it (8.4 deg low on a
    simulated ring under neutral points 40 deg apart), the fit stops at 6 deg."""
    pointing: ClassVar[str] = "full_fit"
    """The pointing the AoP stage read is then freed beside the separation in the full
    model, tied to that reading (:func:`.run._pointing_in_full_fit`): held, the AoP's
    error of the units' common elevation moved the separation by 4.5 times that error
    (0.2 deg for 20 deg between noise draws, nine times its SD)."""
    parameter_names = ("separation_deg",)
    units = ("deg",)
    null = (0.0,)
    lower = (0.0,)
    upper = (70.0,)
    prior_sd = (40.0,)
    fd_step = (0.05,)

    def starts(self, ctx) -> list:
        return [np.array([d]) for d in (10.0, 25.0, 40.0)]

    def sky(self, p, base_sky, sun_enu):
        from skysim.berry import BerrySky
        return BerrySky(delta_deg=float(p[0]), dmax=1.0)


AEROSOL_PRESET = "continental_average"
"""Aerosol type of the ``aerosol`` candidate (:data:`skysim.aerosol_types.PRESETS`; OPAC
continental average, Hess et al. 1998): the common type over land away from cities."""
AEROSOL_WAVELENGTH_NM = 500.0
"""Wavelength [nm] of the ``aerosol`` candidate's sky when the instrument's sidecar gives no
band (or ``unknown``): a silicon photodiode behind polarizer film under daylight responds
across the visible; the fitted AOD takes up the rest of the molecular-to-aerosol ratio. With
a band, its effective wavelength (:attr:`sensor.photodiodes_io.PhotodiodeData.band_wavelength_nm`)."""
AEROSOL_ALBEDO = 0.15
"""Lambertian ground albedo of the ``aerosol`` candidate (grass, dry soil and low vegetation:
0.1-0.25 in the visible); the ring looks at the sky, where the albedo changes the DoP by a
few percent at most."""
AEROSOL_GRID = (25, 37)
"""Table grid (view zenith x relative azimuth nodes) of the candidate's engine runs: the
validated grid of :class:`skysim.aerosol.AerosolSky`. A 13 x 25 grid on 16 streams costs a
third but missed the validated sky by up to 0.02 in DoP and 5 deg in AoP (AOD 0.55, sun 30
deg, views 25-65 deg), as large as a real ring's held-out gap, so it is not used."""


class GridAerosolSky:
    """Aerosol sky at any AOD from engine runs at :data:`AOD_NODES`, linear in ``ln AOD``
    (the sky's Stokes vector changes smoothly with the aerosol load; the interpolation error
    between nodes a factor 3 apart is tested). The node skies are
    :class:`skysim.aerosol.AerosolSky` objects with the sun-step interpolation, so every engine
    run is cached per (AOD, sun node) and shared by folds and fit steps; the AODs of one sun
    node come from one engine call."""

    AOD_NODES: ClassVar[np.ndarray] = np.array([0.03, 0.1, 0.3, 1.0])

    def __init__(self, sun_step_deg, sun_origin_deg: float = 0.0,
                 wavelength_nm: float = AEROSOL_WAVELENGTH_NM):
        from skysim.aerosol import AerosolSky
        self.skies = [AerosolSky(AEROSOL_PRESET, aod_550=float(a), albedo=AEROSOL_ALBEDO,
                                 wavelength_nm=float(wavelength_nm),
                                 sun_step_deg=sun_step_deg, sun_node_origin_deg=sun_origin_deg,
                                 n_zenith=AEROSOL_GRID[0],
                                 n_azimuth=AEROSOL_GRID[1], settings=fit_engine_settings())
                      for a in self.AOD_NODES]

    def at(self, aod: float):
        from skysim.sky import Sky
        grid = self

        class _Interpolated(Sky):
            name = "aerosol"

            def _stokes(self, vel, vaz, sel, saz):
                return grid.stokes(aod, vel, vaz, sel, saz)

            def describe(self):
                return {"model": "aerosol", "aod_550": aod, "preset": AEROSOL_PRESET,
                        "interpolated": "ln AOD linear between engine nodes"}
        return _Interpolated()

    def stokes(self, aod, vel, vaz, sel, saz):
        from skysim.aerosol import prefetch_tables
        la = np.log(self.AOD_NODES)
        x = float(np.clip(np.log(aod), la[0], la[-1]))
        i = int(np.clip(np.searchsorted(la, x) - 1, 0, la.size - 2))
        f = (x - la[i]) / (la[i + 1] - la[i])
        used = [(k, w) for k, w in ((i, 1.0 - f), (i + 1, f)) if w != 0.0]
        # every AOD node of a sun node in one engine call: the engine's set-up of the rays
        # (about 1.6 s for a table's 925) is paid once per sun node, not once per AOD bracket
        prefetch_tables(self.AOD_NODES, sel, sky=self.skies[0])
        out = 0.0
        for k, w in used:
            out = out + w * np.stack(self.skies[k]._stokes(vel, vaz, sel, saz))
        return out[0], out[1], out[2]


class Aerosol(RingEffect):
    """Rayleigh and aerosol multiple scattering (:class:`skysim.aerosol.AerosolSky`, an OPAC
    continental aerosol) with the aerosol optical depth at 550 nm fitted: the aerosol makes
    the sky brighter and less polarized near the sun and moves the neutral points away from
    the sun and anti-sun. The molecular sky at AOD -> 0 is the multiple-scattering one, not
    single scattering; the candidate's null is its lowest node (0.03)."""

    name = "aerosol"
    parameter_names = ("aod_550",)
    units = ("1",)
    null = (0.03,)
    lower = (0.03,)
    upper = (1.0,)
    prior_sd = (0.5,)
    fd_step = (2e-3,)

    @property
    def prior_mean(self) -> np.ndarray:
        return np.array([0.15])

    def starts(self, ctx) -> list:
        # one start per bracket of the AOD nodes: the held radiance and DoP scale make the
        # cost of the AOD far from quadratic, and a fit from one start can stall at a bound
        return [np.array([a]) for a in (0.05, 0.15, 0.5)]

    def __init__(self):
        self._grid = None
        self.wavelength_nm = AEROSOL_WAVELENGTH_NM

    available = MultipleScattering.available
    available_at = MultipleScattering.available_at

    def bind(self, inst) -> None:
        """The sky at the instrument's band (the sidecar's ``band``; without one, or
        ``unknown``, :data:`AEROSOL_WAVELENGTH_NM`)."""
        band = (inst.source or {}).get("band_wavelength_nm")
        wavelength = AEROSOL_WAVELENGTH_NM if band is None else float(band)
        if wavelength != self.wavelength_nm:
            self.wavelength_nm, self._grid = wavelength, None

    def sky(self, p, base_sky, sun_enu):
        if self._grid is None:
            self._grid = GridAerosolSky(*MultipleScattering._session_nodes(sun_enu),
                                        wavelength_nm=self.wavelength_nm)
        return self._grid.at(float(p[0]))


OVERCAST_BASE_M = 1000.0
"""Cloud base [m above the site] of the ``overcast`` candidate: stratus and stratocumulus,
the layer clouds that cover a whole sky, have bases from near the ground to about 2 km
(WMO International Cloud Atlas, 2017). The base sets only the share of the sky's light
scattered by the air below the cloud, a few percent of the light at the zenith."""
OVERCAST_MAX_TAU = 10.0
"""Upper bound of the fitted cloud optical thickness [1]: beyond it the sky's pattern is
hidden (transmitted share ``exp(-0.206 tau / mu) < 0.13`` overhead) and the cloud's own light,
polarized below about 0.16 under a thick overcast (Hegedüs et al. 2007 [6]_), is nearly all a
unit sees."""


class Overcast(RingEffect):
    """A uniform overcast: a cloud layer of optical thickness ``tau`` (550 nm) over the whole
    sky in front of the base sky (:class:`skysim.partly_cloudy.PartlyCloudySky` with a
    :class:`skysim.cloud_field.CloudField` of cover 1): the clear sky's E-vector pattern
    continues below and through the cloud (Pomozi, Horváth & Wehner 2001 [5]_), attenuated, while
    the droplets' own light adds bright, weakly polarized radiance, most of it in the forward
    peak towards the sun. So the DoP falls with ``tau``, most near the sun, and the AoP keeps
    the clear-sky pattern. Checked against the radiative transfer of an overcast layer
    (:class:`skysim.clouds.CloudySky`, ``docs/clouds.md``). Base at ``tau = 0`` (exactly: no
    cloud light, full transmission)."""

    name = "overcast"
    dop_scale_in_sky = True
    parameter_names = ("cloud_tau",)
    units = ("1",)
    null = (0.0,)
    lower = (0.0,)
    upper = (OVERCAST_MAX_TAU,)
    prior_sd = (5.0,)
    fd_step = (1e-3,)

    def starts(self, ctx) -> list:
        # thin (the pattern through the cloud), medium, thick (the cloud's own light)
        return [np.array([t]) for t in (0.3, 1.0, 3.0)]

    def available_at(self, sun_elevation_deg) -> str | None:
        if np.min(sun_elevation_deg) <= 0.0:
            return (f"{self.name} needs the sun above the horizon (the cloud is lit by the "
                    f"sunbeam); got {float(np.min(sun_elevation_deg)):.2f} deg")
        return None

    def sky(self, p, base_sky, sun_enu):
        from skysim.cloud_field import CloudField
        from skysim.partly_cloudy import PartlyCloudySky
        clouds = CloudField(1.0, float(p[0]), 0, base_m=OVERCAST_BASE_M, n_modes=16)
        return PartlyCloudySky(base_sky, clouds)


class Aureole(RingEffect):
    name = "aureole"
    parameter_names = ("amplitude", "scale_deg")
    units = ("1", "deg")
    null = (0.0, 15.0)
    lower = (0.0, 2.0)
    upper = (50.0, 60.0)
    prior_sd = (10.0, np.inf)
    fd_step = (1e-3, 0.05)
    nominal_starts: ClassVar[bool] = True
    """Each start is scored on the base fit's instrument and on the nominal one, each at its
    best DoP scale, beside the base fit's parameters as they are: the base fit, made without
    the aureole, takes a strong one up in negative dark offsets (about -0.2 of the median
    reading for ``A = 2``, ``psi_0 = 15 deg``) and a lower DoP scale, and an aureole started
    there is taken up twice; from there the fit ran to the amplitude's bound."""
    two_step_sd: ClassVar[bool] = True
    """Its SE is the two-step sandwich over samples (:func:`.run._two_step_sd`): the model
    covariance, scaled by the white-noise RMS of all readings, is 3-11 times the spread of
    its errors on simulated rings (z RMS 0.09 at amplitude 2, 0.38 at 0.5; with the sandwich
    0.67 and 0.79 over eight noise draws). The aureole lowers the DoP alone, so the angle of
    polarization the pointing is read from is the base model's."""

    def starts(self, ctx) -> list:
        return [np.array([a, s]) for a in (0.5, 2.0) for s in (5.0, 15.0, 30.0)]

    def modify(self, obs: SkySample, p, sun_enu=None) -> SkySample:
        extra = p[0] * np.exp(-sun_distance_deg(obs, sun_enu) / p[1])
        return replace(obs, dop=obs.dop / (1.0 + extra))


SCALE_MAX_DEG = 1000.0
"""Upper bound [deg] of the stray light's and side glare's fall-off ``psi_0``: light that no
longer falls with the sun's distance (``exp(-180 / 1000) = 0.84`` across the sky), as light
through a unit's casing does."""


def sun_distance_deg(obs: SkySample, sun_enu) -> np.ndarray:
    """Angular distance [deg] (n, U) between each unit's view and the sun."""
    view = direction_vector(obs.view_elevation_deg, obs.view_azimuth_deg)
    cos_psi = np.clip(np.einsum("nuk,nk->nu", view, np.asarray(sun_enu, float)), -1.0, 1.0)
    return np.degrees(np.arccos(cos_psi))


class StrayLight(RingEffect):
    """Sunlight scattered inside the instrument onto each photodiode (housing, baffles, the
    polarizer's edge): unpolarized, reaching each photodiode with its own strength ``S_p``
    behind no polarizer, and falling off with the sun's angular distance ``psi`` from the
    unit's axis as ``exp(-psi / psi_0)`` (a point-source transmittance of a baffled
    aperture falls off steeply outside its field of view, Breault 1995 [4]_). Adds
    ``S_p exp(-psi / psi_0)`` to the reading (in units of the session's median reading).
    Base at ``S = 0``. The fall-off may run to 1000 deg, light that no longer falls with the
    sun's distance (exp(-180/1000) = 0.84 across the sky): on the reference ring's 16:01
    session it ran to a 90-deg bound, light through the casing rather than glare at the
    aperture (:class:`SideGlare`)."""

    name = "stray_light"
    units = ()
    output_only = True
    two_step_sd: ClassVar[bool] = True
    """Its SE is the two-step sandwich over samples (:func:`.run._two_step_sd`): the model
    covariance, scaled by the white-noise RMS of all readings, is about three times the
    spread of the strengths' errors on simulated rings (z RMS 0.28; with the sandwich 0.71
    over eight noise draws)."""
    hold_at_bounds: ClassVar[bool] = True
    """Its fit holds a strength at 0 while the cost falls outwards (:func:`.fit.fit`): the
    photodiodes the light does not reach sit at their null, and with trials merely clipped
    into the box the fit crawled (the 16:01 session's stray light not converged, 15 % of
    the excess; held, converged, 42 %)."""
    continue_iter: ClassVar[int | None] = 500
    """A strength per photodiode (65 parameters with the side glare's two) descends slowly
    where many photodiodes hold light from few directions: the side glare's fits on the
    reference ring's 14:09 session converged in 72, 89 and 242 iterations (150 left the
    third short, and the session's side glare unnamed, 92 % of the excess), 40-75 on the
    16:01 session."""

    holdable: ClassVar[tuple] = ("scale_deg",)
    """The fall-off belongs to the instrument: a day's sessions may hold it at one value
    (``shared_parameters``; ``skysim reproduce real-sky-compass`` holds the side glare's)."""

    def __init__(self):
        self.parameter_names, self.units = ("scale_deg",), ("deg",)
        self.null, self.lower, self.upper = (15.0,), (2.0,), (SCALE_MAX_DEG,)
        self.prior_sd, self.fd_step = (np.inf,), (0.05,)
        self.held_scale_deg = None
        """The fall-off held at this value [deg] (:meth:`hold`), or None: fitted."""

    def hold(self, values: dict) -> None:
        """Hold the fall-off ``scale_deg`` [deg] at ``values["scale_deg"]``, within its range
        2-:data:`SCALE_MAX_DEG`; before :meth:`bind`, which then leaves it out of the
        parameters (:func:`get_ring_effect` does both in this order)."""
        super().hold(values)
        v = float(values["scale_deg"])
        if not 2.0 <= v <= SCALE_MAX_DEG:
            raise UnknownEffectError(f"{self.name}: scale_deg = {v!r} is outside its range "
                                     f"2-{SCALE_MAX_DEG:g} deg")
        self.held_scale_deg = v

    @property
    def held_values(self) -> dict:
        return {} if self.held_scale_deg is None else {"scale_deg": self.held_scale_deg}

    def _strengths(self, names, P) -> None:
        """Parameter lists of ``P`` strengths named ``names`` and the fall-off, unless held."""
        keep = slice(None) if self.held_scale_deg is None else slice(0, P)
        self.parameter_names = (tuple(names) + ("scale_deg",))[keep]
        self.units = (("1",) * P + ("deg",))[keep]
        self.null = ((0.0,) * P + (15.0,))[keep]
        self.lower = ((0.0,) * P + (2.0,))[keep]
        self.upper = ((20.0,) * P + (SCALE_MAX_DEG,))[keep]
        self.prior_sd = ((5.0,) * P + (np.inf,))[keep]
        self.fd_step = ((1e-4,) * P + (0.05,))[keep]

    def bind(self, inst) -> None:
        self.per_photodiode = len(inst.columns)
        self._strengths([f"S_{c}" for c in inst.columns], self.per_photodiode)

    def starts(self, ctx) -> list:
        P = self.per_photodiode
        if self.held_scale_deg is not None:
            return [np.full(P, 0.05)]
        return [np.r_[np.full(P, 0.05), s] for s in (5.0, 15.0, 30.0)]

    def _falloff(self, p, psi):
        """``exp(-psi / psi_0)`` with the fitted or held fall-off ``psi_0`` [deg], ``psi``
        the sun's distance from the unit's axis [deg]."""
        scale = self.held_scale_deg if self.held_scale_deg is not None else p[self.per_photodiode]
        return np.exp(-psi / scale)

    def additive(self, p, obs, sun_enu, pd_unit):
        P = self.per_photodiode
        psi = sun_distance_deg(obs, sun_enu)[:, pd_unit]
        return np.asarray(p[:P]) * self._falloff(p, psi)



def sun_side(obs: SkySample, sun_enu) -> np.ndarray:
    """Sine of the sun's bearing about each unit's axis (n, U): ``+1`` with the sun square
    to the unit's left (looking along its axis, the horizontal direction ``z x view``),
    ``-1`` to its right, 0 with the sun in the vertical plane of the axis or on it.

    Parameters
    ----------
    obs : SkySample
        Views of every unit, elevation and azimuth (n, U) [deg, azimuth clockwise from north].
    sun_enu : array (n, 3)
        Unit vectors to the sun in east-north-up.
    """
    el = np.radians(obs.view_elevation_deg)
    az = np.radians(obs.view_azimuth_deg)
    sun = np.asarray(sun_enu, float)
    # z x view for view = (sin az cos el, cos az cos el, sin el) is cos el (-cos az, sin az, 0)
    left = sun[:, None, 0] * -np.cos(az) + sun[:, None, 1] * np.sin(az)
    view = np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], axis=-1)
    cos_psi = np.clip(np.einsum("nuk,nk->nu", view, sun), -1.0, 1.0)
    sin_psi = np.sqrt(1.0 - cos_psi ** 2)
    return np.where(sin_psi > 1e-9, np.clip(left / np.maximum(sin_psi, 1e-9), -1.0, 1.0), 0.0)


class SideGlare(StrayLight):
    """Unpolarized glare per photodiode, falling off with the sun's distance from the unit's
    axis and of its own strength for the sun on either side of the unit (module docstring):
    ``exp(-psi / psi_0) (L_p (1 + s) + R_p (1 - s)) / 2``, ``L_p``, ``R_p >= 0``.

    This is ``S_p (1 + b_p s)`` with ``|b_p| <= 1`` written as two strengths
    (``L = S (1 + b)``, ``R = S (1 - b)``): light from one side only is then a strength at its
    null, not a side fraction at a bound of its range, and the model is linear in all but
    the fall-off. On the reference ring's sessions the fitted fall-off is 51-356 deg, broad
    light through a unit's casing rather than glare at its aperture. Its fit holds strengths
    at 0 as the stray light's does: with trials merely clipped into the box, the
    65-parameter fit was not converged after 150 iterations on the 16:01 session; held, in
    40-75."""

    name = "side_glare"

    def bind(self, inst) -> None:
        cols = inst.columns
        self.per_photodiode = 2 * len(cols)
        self._strengths([f"L_{c}" for c in cols] + [f"R_{c}" for c in cols],
                        self.per_photodiode)

    # starts: the stray light's, as much light from either side

    def additive(self, p, obs, sun_enu, pd_unit):
        P = self.per_photodiode // 2
        p = np.asarray(p, float)
        psi = sun_distance_deg(obs, sun_enu)[:, pd_unit]
        side = sun_side(obs, sun_enu)[:, pd_unit]
        return (self._falloff(p, psi)
                * (p[:P] * (1.0 + side) + p[P:2 * P] * (1.0 - side)) / 2.0)


def lagged_yaw(t_s, yaw_deg, sweep, lag_s: float) -> np.ndarray:
    """The recorded yaw at ``t - lag`` [deg], interpolated linearly within each sweep and
    held at its first and last samples.

    Parameters
    ----------
    t_s : array (n,)
        Sample times [s], increasing within each sweep.
    yaw_deg : array (n,)
        Recorded yaw [deg], unwrapped within each sweep.
    sweep : array (n,) of int
        Sweep of each sample; sweeps are contiguous runs of samples.
    lag_s : float
        Delay of the readings behind the attitude record [s].
    """
    t = np.asarray(t_s, float)
    yaw = np.asarray(yaw_deg, float)
    sweep = np.asarray(sweep)
    if lag_s == 0.0 or t.size == 0:
        return yaw
    start = np.r_[True, sweep[1:] != sweep[:-1]]
    run = np.cumsum(start) - 1
    first = np.flatnonzero(start)
    last = np.r_[first[1:] - 1, t.size - 1]
    # each sweep on its own stretch of one time axis, far apart, so that one interpolation
    # never reaches into the neighbouring sweep
    span = float(np.max(t) - np.min(t)) + abs(lag_s) + 1.0
    shift = run * 2.0 * span
    query = np.clip(t - lag_s, t[first][run], t[last][run]) + shift
    return np.interp(query, t + shift, yaw)


class ReadLag(RingEffect):
    """Readings that lag the attitude record by ``lag_s`` seconds (module docstring)."""

    name = "read_lag"
    geometric = True
    parameter_names = ("lag_s",)
    units = ("s",)
    null = (0.0,)
    lower = (-2.0,)
    upper = (2.0,)
    prior_sd = (1.0,)
    fd_step = (2e-3,)
    pointing: ClassVar[str] = "joint"
    """Fitted jointly with the units' pointing on the angle of polarization: a lag moves the
    heading by the turn rate times the lag, in turns only, where constant pointing offsets
    cannot stand in for it (:func:`.run._joint_geometry`)."""

    def starts(self, ctx) -> list:
        return [np.array([v]) for v in (-0.3, 0.0, 0.3)]

    def yaw(self, inst, p) -> np.ndarray:
        return lagged_yaw(inst.t_s, inst.yaw_deg, inst.sweep, float(p[0]))


_EFFECTS = {c.name: c for c in (MultipleScattering, Aerosol, NeutralPoints, Overcast, FieldOfView,
                                Occlusion, YawScale, ClockOffset, Tilt, Aureole, StrayLight,
                                SideGlare, ReadLag)}


_HELD = re.compile(r"^\s*(\w+)\s*\((.*)\)\s*$")
"""A candidate with held parameters: ``name(parameter=value, ...)``."""


def _held_values(name: str, text: str) -> dict:
    """``{parameter: value}`` from the ``a=1, b=2`` inside a held candidate's parentheses
    (values in the parameter's unit).

    Raises
    ------
    UnknownEffectError
        For nothing inside the parentheses, an item that is not ``parameter=number``, or a
        parameter given twice, naming it.
    """
    values = {}
    for item in (t.strip() for t in text.split(",")):
        key, sep, value = item.partition("=")
        key = key.strip()
        try:
            number = float(value)
        except ValueError:
            sep = ""
        if not sep or not key:
            raise UnknownEffectError(f"{name!r}: {item!r} is not parameter=value "
                                     "(a number in the parameter's unit)")
        if key in values:
            raise UnknownEffectError(f"{name!r}: {key} is given twice")
        values[key] = number
    return values


def get_ring_effect(name: str) -> RingEffect:
    """The effect of that name; ``"name(parameter=value, ...)"`` holds those parameters at
    those values (:meth:`RingEffect.hold`), e.g. ``"side_glare(scale_deg=94)"``: a day's
    shared fall-off. The effect keeps its own name in the report.

    Raises
    ------
    UnknownEffectError
        Listing the valid names; for a malformed or out-of-range held value, naming it.
    """
    held = _HELD.match(name)
    base = held.group(1) if held else name
    if base not in _EFFECTS:
        raise UnknownEffectError(f"unknown effect {name!r} for a photodiode instrument; valid: "
                                 f"{', '.join(RING_EFFECT_NAMES + OPTIONAL_EFFECT_NAMES)}")
    effect = _EFFECTS[base]()
    if held:
        effect.hold(_held_values(name, held.group(2)))
    return effect
