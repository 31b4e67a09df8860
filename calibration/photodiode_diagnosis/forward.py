"""Forward model of a photodiode instrument under a sky: the base model and its parameters.

Geometry (what each unit sees) is the project's compound-eye sensor's sampling
(:meth:`sensor.compound_eye.CompoundEyeSensor.observe`, computed to rounding by
:func:`.acceptance.observe_axes`) of a :class:`skysim.sky.Sky` along each unit's view at the
body attitude of every sample; the readings from Malus's law of
the photodiode channel model (:func:`sensor.photodiode.photodiode_signal`, its formula
without input checks in the fit's inner loop):

``r_ip = I_iu g_p (1 + s d_iu cos 2(chi_iu - a_p - beta_p - delta_u)) + o_p``

with ``d_iu``, ``chi_iu`` the degree and angle of linear polarization of the light reaching
unit ``u`` at sample ``i`` (unit frame), ``a_p`` the nominal polarizer angle (``a_ip`` at
sample ``i`` when the unit's analyser turns: the photodiode's angle on the analyser plus the
analyser's angle at that sample), ``beta_p`` the
photodiode's own deviation from it (a hand-cut polarizer film is placed within a few degrees),
``delta_u`` the unit's polarizer-angle (installation) offset, ``s`` the DoP scale (the sky's ``d_max``),
``g_p = exp(lambda_p)`` the photodiode's gain and ``o_p`` its dark offset. The radiance
``I_iu`` reaching a unit is a nuisance profiled out in closed form (least squares over the
unit's photodiodes at each sample, variable projection, Golub & Pereyra 1973 [1]_): a
polarization compass does not use it, and the single-scattering radiance misses the real
sky's aerosol brightening near the sun and horizon by factors of several, which would bury
every polarization effect. Residuals are relative: ``(r - r_hat) / mean_u(r)``.

What the readings are fixes part of the model: dark-subtracted and normalised readings carry
no dark offset (``o_p`` is 0 whatever its parameter, :meth:`Forward.held_by_readings`).
Normalised readings (scaled by their authors, e.g. each photodiode to [0, 1] over each
analyser revolution) carry no degree of polarization either: the polarized radiance
``J = I d`` is then profiled out beside ``I`` (the DoP-free prediction below), and ``s`` has
no effect (:attr:`sensor.photodiodes_io.PhotodiodeData.unrecoverable`). With a rotating
analyser a unit's photodiodes see one angle per sample, so ``I`` and ``J`` are shared by the
samples of each half-turn of the analyser (:attr:`Instrument.analyser_cycle`): the sky does
not change within a half-turn of a few seconds, and a crossed pair's two readings per sample
could not determine both. They are profiled per photodiode there, not per unit: each
photodiode was normalised on its own, with its own scale and zero for each revolution (the
extremes of its noisy readings), which a unit's shared ``I`` and ``J`` cannot absorb (on the
simulated rotating-analyser session they left a held-out gap 17 % above the white-noise
floor); what a normalised photodiode tells over a half-turn is the phase of its modulation,
the angle of polarization.

Which parameters are shared and which are per sweep: gains, offsets, polarizer angles, the
pointing of every unit's axis (elevation and azimuth offsets from nominal) and the DoP scale
belong to the instrument and the sky of a session, so they are shared by all sweeps
(fitted on the training sweeps, held fixed on the held-out ones). The heading offset between
the recorded (relative) yaw and the true heading is re-fitted for every sweep, training and
held-out alike, because the platform's IMU is re-zeroed between recordings; with absolute
yaw it is one shared offset (a mounting offset of the yaw reference).

References
----------
.. [1] G. H. Golub, V. Pereyra, "The differentiation of pseudo-inverses and nonlinear least
   squares problems whose variables separate", SIAM J. Numer. Anal. 10(2):413-432 (1973),
   doi:10.1137/0710036.
.. [2] E. Hecht, Optics, 5th ed., Pearson (2017), sect. 8.2 (Malus's law).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sensor.compound_eye import SkySample, body_attitude
from skysim.geometry import cos_sin_deg
from skysim.sky import RayleighSky
from skysim.sun import SunTrack

from .acceptance import observe_axes
from .instrument import Instrument

__all__ = ["Layout", "SunTrack", "Forward", "RELATIVE_FLOOR"]

MIN_PHOTODIODES_USED = 3
"""Usable photodiodes a unit needs at a sample for its relative residuals to be formed (fewer
in a unit that has fewer: both of a crossed pair): with the radiance profiled out, three
readings leave two degrees of freedom for the polarization, so one faulty photodiode of a
four-polarizer unit does not silence the unit."""

RELATIVE_FLOOR = 1e-3
"""Floor of a unit's mean reading, as a fraction of the session's median reading, below which
its relative residuals are not formed (a unit in the dark carries no polarization signal)."""


@dataclass(frozen=True)
class Layout:
    """Positions of the parameter groups in the parameter vector.

    Order: ``lambda_p`` (P log-gains), ``o_p`` (P offsets, in units of the session's median
    reading), ``beta_p`` (P polarizer-angle deviations of each photodiode [deg]),
    ``delta_u`` (U polarizer offsets [deg]), ``s`` (DoP scale), ``epsilon_u``,
    ``alpha_u`` (U elevation and U azimuth offsets of the unit axes [deg]), ``h_k`` (one heading
    offset per sweep [deg]; one shared offset for absolute yaw), effect parameters.
    """

    n_pd: int
    n_units: int
    n_heading: int
    n_effect: int

    @property
    def lam(self):
        return slice(0, self.n_pd)

    @property
    def off(self):
        return slice(self.n_pd, 2 * self.n_pd)

    @property
    def angle(self):
        """Per-photodiode polarizer-angle deviations from nominal [deg]."""
        return slice(2 * self.n_pd, 3 * self.n_pd)

    @property
    def delta(self):
        return slice(3 * self.n_pd, 3 * self.n_pd + self.n_units)

    @property
    def scale(self) -> int:
        return 3 * self.n_pd + self.n_units

    @property
    def pointing(self):
        """Per-unit elevation offsets (U) then azimuth offsets (U) of the optical axes [deg]."""
        return slice(self.scale + 1, self.scale + 1 + 2 * self.n_units)

    @property
    def heading(self):
        return slice(self.pointing.stop, self.pointing.stop + self.n_heading)

    @property
    def effect(self):
        return slice(self.heading.stop, self.heading.stop + self.n_effect)

    @property
    def size(self) -> int:
        return self.effect.stop

    @property
    def n_base(self) -> int:
        return self.heading.start


class Forward:
    """Predicted readings of an instrument for a parameter vector (base model + one effect).

    ``polarizer_sign`` is -1 when the instrument counts its polarizer angles in the opposite
    sense to the unit frame's (from the meridian towards decreasing azimuth); the base model
    finds it from the data (:func:`calibration.photodiode_diagnosis.run.orient`).
    ``heading_override`` (n,) replaces the headings, for heading decoding.

    Parameters
    ----------
    inst : Instrument
    effect : RingEffect, optional
    sun : SunTrack, optional
        Shared between folds (built once per data set).
    """

    def __init__(self, inst: Instrument, effect=None, sun: SunTrack | None = None,
                 polarizer_sign: float = 1.0):
        self.inst = inst
        self.polarizer_sign = float(polarizer_sign)
        self.heading_override = None
        self._attitudes = []
        """The last attitudes computed, ``((heading, pitch, roll), Rotation)``, newest last."""
        self._modulations = None
        self._double_angle = None
        """``(obs, (cos 2 chi, sin 2 chi))`` of the last sky sample's units (n, U)."""
        self._additive_last = None
        """The last additive light of the effect, ``(obs, parameters, values)``."""
        """The last modulation terms, ``(obs, key, values)`` (:meth:`_modulation`)."""
        self.effect = effect
        if effect is not None:
            effect.bind(inst)
        k = 0 if effect is None else effect.k
        n_heading = 1 if inst.absolute_yaw else inst.n_sweeps
        self.layout = Layout(inst.readings.shape[1], inst.n_units, n_heading, k)
        self.sun = sun or SunTrack(inst.site, inst.t_s.min(), inst.t_s.max(),
                                   margin_s=0.0 if effect is None else effect.time_margin_s)
        good = ~inst.flagged & np.isfinite(inst.readings)
        self.good = good
        r = np.where(good, inst.readings, 0.0)
        self.level = float(np.median(inst.readings[good])) if good.any() else 1.0
        self.level = max(self.level, 1e-12)
        self.y = r / self.level                        # readings in session-median units
        units = inst.pd_unit
        self.member = (units[None, :] == np.arange(inst.n_units)[:, None]).astype(float)  # (U, P)
        cnt = good.astype(float) @ self.member.T        # (n, U)
        mean = (self.y @ self.member.T) / np.maximum(cnt, 1.0)
        self.unit_mean = mean
        need = np.minimum(self.member.sum(axis=1), MIN_PHOTODIODES_USED)    # (U,)
        self.usable = good & ((mean > RELATIVE_FLOOR) & (cnt >= need))[:, units]
        self._usable_f = self.usable.astype(float)
        self.pd_angle_deg = (inst.pd_angle_deg if inst.pd_angle_row_deg is None
                             else np.asarray(inst.pd_angle_row_deg, float))
        """Nominal polarizer angles, (P,) with fixed analysers or (n, P) per sample [deg]."""
        self._scale = np.where(self.usable, mean[:, units], 1.0)
        kind = getattr(inst, "readings_kind", "raw")
        self.fit_offsets = kind == "raw"
        """False for dark-subtracted and normalised readings: their dark offset is 0."""
        self.normalised = kind == "normalised"
        """Normalised readings: predictions always profile ``J = I d`` (DoP-free)."""
        self.profile_rows = None
        """Group label (n,) of the samples that share the profiled radiance (and polarized
        radiance) of each unit; None: every sample its own. Normalised readings of a rotating
        analyser share them over each half-turn of the analyser."""
        self._profile_member = self.member
        """Which photodiodes share a profiled radiance (K, P): each unit's (K = U), or each
        photodiode its own (K = P) for normalised readings of a rotating analyser."""
        self._profile_col = units
        """Profile (0..K-1) of every photodiode (P,)."""
        cycle = getattr(inst, "analyser_cycle", None)
        if self.normalised and cycle is not None:
            self.profile_rows = np.unique(np.asarray(cycle), return_inverse=True)[1].ravel()
            # each photodiode normalised on its own (its own scale and zero per revolution):
            # its own radiance and polarized radiance per half-turn, which absorb them
            P = units.size
            self._profile_member, self._profile_col = np.eye(P), np.arange(P)
        self._sky = RayleighSky(1.0)
        self._dop_in_sky = bool(effect is not None and effect.dop_scale_in_sky)
        """The DoP scale is the base sky's ``d_max`` inside the effect's sky (see
        :attr:`~.effects.RingEffect.dop_scale_in_sky`), not a factor on every unit's DoP."""
        self.dop_free = False
        self.aop_sky = None
        """A sky (:class:`skysim.sky.Sky`) whose angle of polarization the DoP-free stage
        uses instead of single scattering's (None: the base sky)."""

    def held_by_readings(self) -> np.ndarray:
        """Parameters (size,) bool that the readings leave without effect, to be held in
        every fit (and not reported as fitted): the dark offsets of dark-subtracted and
        normalised readings (no dark level survives them), and the DoP scale of normalised
        ones (no modulation depth survives them)."""
        held = np.zeros(self.layout.size, bool)
        if not self.fit_offsets:
            held[self.layout.off] = True
        if self.normalised:
            held[self.layout.scale] = True
        return held

    def absorbed_by_profile(self) -> np.ndarray:
        """Parameters (size,) bool that the profiled radiance absorbs whatever the readings
        are: the gains of photodiodes profiled each on their own (normalised readings of a
        rotating analyser, where each photodiode's radiance and polarized radiance per
        half-turn take up its gain). Held in every fit and not reported as fitted."""
        out = np.zeros(self.layout.size, bool)
        if self._profile_member is not self.member:
            out[self.layout.lam] = True
        return out

    # ---------------------------------------------------------------- geometry stage
    def headings(self, theta) -> np.ndarray:
        """True headings [deg, clockwise from north] of every sample."""
        if self.heading_override is not None:
            return self.heading_override
        L, inst = self.layout, self.inst
        h = theta[L.heading]
        off = h[0] if inst.absolute_yaw else h[inst.sweep]
        if self.effect is not None:
            return off + self.effect.yaw(inst, theta[L.effect])
        return off + inst.yaw_deg

    def observe(self, theta) -> SkySample:
        """What every unit sees (degree of polarization for ``s = 1``)."""
        inst, e = self.inst, self.effect
        pe = None if e is None else theta[self.layout.effect]
        t = inst.t_s if e is None else inst.t_s + e.time_shift_s(pe)
        pitch, roll = inst.pitch_deg, inst.roll_deg
        if e is not None:
            pitch, roll = e.attitude(pitch, roll, pe)
        att = self._attitude(self.headings(theta), pitch, roll)
        sun = self.sun(t)
        base_sky = self.aop_sky if self.dop_free and self.aop_sky is not None else self._sky
        if self._dop_in_sky and not self.dop_free:
            base_sky = RayleighSky(float(np.clip(theta[self.layout.scale], 0.0, 1.0)))
        sky = base_sky if e is None else e.sky(pe, base_sky, sun)
        sensor = self.pointed_sensor(theta)
        if e is not None and e.observes:
            return e.observe(sensor, sky, att, sun, pe)
        obs = observe_axes(sensor, sky, att, sun)
        return obs if e is None else e.modify(obs, pe, sun)

    ATTITUDES_KEPT = 2
    """Attitudes :meth:`_attitude` remembers: a fit's Jacobian samples the sky at the current
    headings, at headings one step away and at the current ones again (the effect's
    column)."""

    def _attitude(self, heading, pitch, roll):
        """:func:`body_attitude`, remembered for the last :attr:`ATTITUDES_KEPT` headings and
        tilts (a fit's steps in the pointing, polarization or effect parameters leave them
        unchanged)."""
        key = (np.asarray(heading, float), np.asarray(pitch, float), np.asarray(roll, float))
        for known, att in self._attitudes:
            if all(a.shape == b.shape and np.array_equal(a, b) for a, b in zip(key, known)):
                return att
        att = body_attitude(*key)
        self._attitudes = (self._attitudes + [(tuple(a.copy() for a in key), att)])[
            -self.ATTITUDES_KEPT:]
        return att

    def _modulation(self, obs: SkySample, angle, s=None) -> np.ndarray:
        """Malus's modulation ``1 + d cos 2(chi - angle)`` (n, P), ``d`` the DoP of ``obs``
        times ``s`` (clipped to [0, 0.999]), or ``cos 2(chi - angle)`` alone without ``s``, at
        each photodiode's unit: remembered for the last sky sample, polarizer angles and DoP
        scale (a fit's steps in the gains and offsets leave them unchanged).

        ``cos 2(chi - a) = cos 2chi cos 2a + sin 2chi sin 2a``: the trigonometry of the units'
        angles (n, U) once per sky sample and of the polarizer angles (P,) once per call, not
        a cosine per reading (n, P) at each of a Jacobian's polarizer-angle columns (equal to
        Malus's law written out to rounding, tested)."""
        key = (np.array(angle, float), s)
        last = self._modulations
        if (last is not None and last[0] is obs and last[1][1] == s
                and np.array_equal(last[1][0], key[0])):
            return last[2]
        u = self.inst.pd_unit
        if self._double_angle is None or self._double_angle[0] is not obs:
            self._double_angle = (obs, cos_sin_deg(2.0 * obs.aop_unit_deg))
        c2, s2 = (x[:, u] for x in self._double_angle[1])
        ca, sa = cos_sin_deg(2.0 * key[0])
        out = c2 * ca
        out += s2 * sa
        if s is not None:
            out *= np.clip(s * obs.dop[:, u], 0.0, 0.999)
            out += 1.0
        self._modulations = (obs, key, out)
        return out

    def pointed_sensor(self, theta):
        """The sensor with every unit's axis at its nominal elevation and azimuth plus the
        fitted pointing offsets (a hand-built ring's mounting angles differ from nominal) and
        the instrument's calibrated ones (:attr:`Instrument.pointing_deg`), if any."""
        p = theta[self.layout.pointing]
        if self.inst.pointing_deg is not None:
            p = p + np.nan_to_num(self.inst.pointing_deg)
        if not np.any(p):
            return self.inst.sensor
        U = self.layout.n_units
        units = tuple(replace(u, elevation_deg=float(min(max(u.elevation_deg + p[i], 0.0), 90.0)),
                              azimuth_deg=float(u.azimuth_deg + p[U + i]))
                      for i, u in enumerate(self.inst.sensor.units))
        return replace(self.inst.sensor, units=units)

    # ---------------------------------------------------------------- output stage
    def channel_model(self, theta, obs: SkySample) -> np.ndarray:
        """``g_p (1 + s d cos 2(chi - a_p - beta_p - delta_u))`` (n, P), Malus's law [2]_."""
        L, inst = self.layout, self.inst
        u = inst.pd_unit
        s = 1.0 if self._dop_in_sky else theta[L.scale]
        angle = self.polarizer_sign * self.pd_angle_deg + theta[L.angle] + theta[L.delta][u]
        return np.exp(theta[L.lam]) * self._modulation(obs, angle, float(s))

    def _unit_sums(self, x, weight=None) -> np.ndarray:
        """Sums of ``x`` (n, P) over the photodiodes of each profile (n, K: each unit's, or
        each photodiode alone, :attr:`_profile_member`), each photodiode's term times
        ``weight`` (P,) when given, and over the samples of each group of
        :attr:`profile_rows` when it is set (G, K)."""
        m = self._profile_member if weight is None else self._profile_member * weight
        s = x @ m.T
        if self.profile_rows is None:
            return s
        out = np.zeros((int(self.profile_rows.max()) + 1, s.shape[1]))
        np.add.at(out, self.profile_rows, s)
        return out

    def _per_sample(self, v) -> np.ndarray:
        """Per-group values (G, U) at every sample (n, U); per-sample values unchanged."""
        return v if self.profile_rows is None else v[self.profile_rows]

    def predict(self, theta, obs: SkySample):
        """Predicted readings (n, P) in session-median units and the profiled radiance (n, U)."""
        if self.dop_free or self.normalised:
            return self._predict_dop_free(theta, obs)
        m = self.channel_model(theta, obs)
        off = self._offsets(theta, obs)
        w = self.usable
        yo = np.where(w, self.y - off, 0.0)
        mw = np.where(w, m, 0.0)
        num = self._unit_sums(yo * mw)
        den = self._unit_sums(mw * mw)
        radiance = self._per_sample(num / np.maximum(den, 1e-300))
        return radiance[:, self._profile_col] * m + off, radiance

    def _offsets(self, theta, obs: SkySample):
        """Dark offsets (P,) (0 unless the readings are raw) plus an effect's additive light
        (n, P), if any."""
        L, e = self.layout, self.effect
        off = theta[L.off] if self.fit_offsets else np.zeros(L.n_pd)
        if e is not None:
            add = self._additive(theta[L.effect], obs)
            if add is not None:
                off = off + add
        return off

    def _additive(self, pe, obs: SkySample):
        """The effect's additive light (n, P) or None, remembered for the last sky sample and
        effect parameters (a fit's steps in the gains, offsets and polarizer angles leave
        them unchanged)."""
        last = self._additive_last
        if last is not None and last[0] is obs and np.array_equal(last[1], pe):
            return last[2]
        add = self.effect.additive(pe, obs, self.sun(self.inst.t_s), self.inst.pd_unit)
        self._additive_last = (obs, np.array(pe, float), add)
        return add

    def _predict_dop_free(self, theta, obs: SkySample):
        """Predictions with the polarized radiance ``I d`` of every unit and sample profiled
        out beside ``I`` (the angle of polarization alone informs the fit).

        ``r_p - o_p = I g_p + J g_p cos 2(chi - a_p - beta_p - delta_u)``, linear in
        ``(I, J = I d)``: a 2 x 2 least-squares solve per unit and sample (variable projection
        [1]_). The sky model's DoP and the DoP scale drop out; what remains is the angle
        ``chi`` the model predicts at each unit, which a mispointed unit, a wrong sun or a
        wrong clock change, but a DoP profile of another shape does not.
        """
        L, inst = self.layout, self.inst
        u = inst.pd_unit
        g = np.exp(theta[L.lam])
        angle = self.polarizer_sign * self.pd_angle_deg + theta[L.angle] + theta[L.delta][u]
        mod = self._modulation(obs, angle)
        off = self._offsets(theta, obs)
        w = self.usable
        yo = np.where(w, self.y - off, 0.0)
        mw = np.where(w, mod, 0.0)
        S = self._unit_sums
        # a trial step of a fit to gains of e^700 overflows here; its cost is then not finite
        # and the step is rejected (:func:`.fit.fit`), so the overflow is not reported
        with np.errstate(over="ignore", invalid="ignore"):
            # the basis (g, g cos 2(chi - a)) of each reading, its gain carried by the sums'
            # weights: five sums over (n, P) products instead of eight
            g2 = g * g
            a00, a01, a11 = S(self._usable_f, g2), S(mw, g2), S(mw * mw, g2)
            c0, c1 = S(yo, g), S(yo * mw, g)
            det = np.maximum(a00 * a11 - a01 * a01, 1e-300)
            radiance = (a11 * c0 - a01 * c1) / det
            polarized = (a00 * c1 - a01 * c0) / det
            if self.normalised:
                # the polarized radiance is not negative: J < 0 would pass an angle 90 deg
                # from the sky's off as a fit (one zenith unit's angle follows the heading
                # exactly); there the best fit has J = 0 and the radiance alone
                neg = polarized < 0
                polarized = np.where(neg, 0.0, polarized)
                radiance = np.where(neg, c0 / np.maximum(a00, 1e-300), radiance)
            radiance, polarized = self._per_sample(radiance), self._per_sample(polarized)
            k = self._profile_col
            pred = polarized[:, k] * mod
            pred += radiance[:, k]
            pred *= g
            pred += off
            return pred, radiance

    def residual(self, theta, obs: SkySample | None = None) -> np.ndarray:
        """Relative residuals (n, P): ``(r - r_hat) / unit mean``, 0 where not usable."""
        obs = self.observe(theta) if obs is None else obs
        pred, _ = self.predict(theta, obs)
        return np.where(self.usable, (self.y - pred) / self._scale, 0.0)
