"""Model-free checks of a photodiode polarization instrument: the sum rule and motion.

Whatever the sky, an ideal polarization unit's photodiodes follow Malus's law, each reading
a linear function of the three Stokes parameters seen by the unit::

    r_j = g_j (I + Q cos 2 theta_j + U sin 2 theta_j) / 2            (Malus; Hecht 2017, 8.2)

so a unit with ``k >= 4`` photodiodes at distinct polarizer angles (modulo 180 deg) has
``k - 3`` combinations of its gain-corrected readings that vanish for every sky: the null
space ``nu`` of the ``k x 3`` matrix ``[1, cos 2 theta, sin 2 theta]``. For the common
0/45/90/135 deg unit it is one combination, the *sum rule* ``r_0 + r_90 = r_45 + r_135``.
Its relative residual ::

    s = sum_j nu_j r_j / g_j  /  (sum_j r_j / g_j / k)                     [1]

(``nu`` normalised to ``sum |nu_j| = k``: ``s = 4 (r0 - r45 + r90 - r135) / (r0 + ... + r135)``
for 0/45/90/135 deg, where ``nu = (1, -1, 1, -1)``) measures light that does not reach the
photodiodes as a Malus analyser would pass it: stray light reaching them unequally through
the casing near the sun, channels read at different instants while the platform turns
(a multiplexed converter), or a faulty channel. It needs no sky model, no heading and no
clock, only the readings. For units of more than four photodiodes the residual is the norm
of the readings' null-space part (unsigned).

Gains from the sum rule: ``sum_j nu_j r_tj w_j = c`` at every sample ``t`` for ``w_j =
1 / g_j``, with ``c`` what the dark offsets add to the combination, a homogeneous linear
system in ``(w, c)`` whose null vector is unique up to scale once the unit has seen enough
brightness and polarization states (the readings' Malus part spans three dimensions). So the relative gains of
a unit's photodiodes are measured from the readings alone (the smallest right singular vector
of the stacked rows, each row scaled by its sample's mean reading), which a common sky shape
fitted to all units cannot absorb. They are taken from the readings farther than
:data:`GAIN_MIN_SUN_DISTANCE_DEG` from the sun and standing, where enough of those remain, so
that neither glare nor a unit misreading only while the platform turns bends them. A unit whose readings span too few polarization states is
reported as not identifiable (NaN gains, ratio of the two smallest singular values above
:data:`GAIN_IDENTIFIABLE_RATIO`).

Where the residual sits: by the angular distance from the unit's optical axis to the sun and
the side of the axis the sun is on (left or right as the unit looks out: the sign of
``(view x sun) . up``), and by motion (standing or turning samples, :attr:`Instrument.rotating`).
Means have a standard error from a delete-one-sweep jackknife (Efron & Tibshirani 1993,
ch. 11), since samples within a sweep are serially correlated; groups within one sweep have
no SE (NaN).

A unit *fails in motion* when its residual RMS on turning samples is more than
:data:`MOTION_FACTOR` times its RMS on standing samples at the same sun distances (standing
bins reweighted to the turning samples' distance distribution) and more than
:data:`MOTION_FACTOR` times the median turning RMS of the instrument's units. Without enough
standing samples (:data:`MIN_SAMPLES`), only the comparison with the other units is made.
When turning breaks the rule on most units (the median ratio above :data:`MOTION_FACTOR`),
the cause is the instrument's, not a unit's: channels of a unit converted at different
instants (a multiplexed converter whose readings are held between conversions) see
different skies while the platform turns.

References
----------
.. [1] E. Hecht, *Optics*, 5th ed., Pearson (2017), sect. 8.2 (Malus's law).
.. [2] B. Efron and R. J. Tibshirani, *An Introduction to the Bootstrap*, Chapman & Hall
   (1993), ch. 11 (the jackknife).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .instrument import Instrument

__all__ = ["DISTANCE_BINS_DEG", "GAIN_IDENTIFIABLE_RATIO", "GAIN_MIN_SUN_DISTANCE_DEG",
           "GLARE_NEAR_DEG", "MIN_SAMPLES", "MOTION_FACTOR", "MOTION_SCREEN_KINDS",
           "SIDE_FAMILY_ALPHA", "InstrumentChecks", "check_instrument", "motion_faults",
           "null_combinations", "sum_rule_gains", "sum_rule_residual", "sun_geometry"]

DISTANCE_BINS_DEG = (0.0, 20.0, 35.0, 50.0, 70.0, 90.0, 180.0)
"""Edges of the sun-distance bins [deg] of the sum-rule table."""

GAIN_IDENTIFIABLE_RATIO = 0.3
"""A unit's sum-rule gains are reported only when its smallest singular value is below this
fraction of the next (a well-defined null direction)."""

GAIN_MIN_SUN_DISTANCE_DEG = 50.0
"""Readings whose unit axis is closer than this to the sun [deg] are left out of the gain
estimate where enough others remain: glare breaks the sum rule there."""

GLARE_NEAR_DEG = 50.0
"""Unit axes closer than this to the sun [deg] enter the side asymmetry."""

SIDE_FAMILY_ALPHA = 0.01
"""False-alarm probability of the side-asymmetry test over all units of a session: a unit's
asymmetry is side-dependent when it exceeds Student's t quantile for ``sweeps - 1`` degrees
of freedom (the jackknife SE's) at ``1 - alpha / (2 U)`` (Bonferroni over ``U`` units) times
its SE."""

MIN_SAMPLES = 20
"""Fewest samples for a standing or turning RMS to be compared."""

MOTION_FACTOR = 2.0
"""Turning RMS over standing RMS (and over the units' median) above which a unit fails in
motion."""


def null_combinations(angles_deg) -> np.ndarray:
    """Combinations of a unit's readings that vanish under Malus's law, ``(k - 3, k)``.

    Parameters
    ----------
    angles_deg : array (k,)
        Polarizer angles of the unit's photodiodes [deg].

    Returns
    -------
    ndarray (k - 3, k)
        Orthogonal rows spanning the null space of ``[1, cos 2 theta, sin 2 theta]``, each
        scaled to ``sum |nu_j| = k`` with its first non-zero entry positive; empty ``(0, k)``
        when fewer than four distinct angles (modulo 180 deg) leave no redundancy.
    """
    th = np.radians(np.asarray(angles_deg, float))
    a = np.stack([np.ones_like(th), np.cos(2 * th), np.sin(2 * th)], axis=1)
    k = th.size
    rank = np.linalg.matrix_rank(a)
    if k - rank <= 0 or rank < 3:
        return np.zeros((0, k))
    _, _, vt = np.linalg.svd(a.T)
    null = vt[rank:]
    first = np.argmax(np.abs(null) > 1e-9, axis=1)
    null = null * np.sign(null[np.arange(len(null)), first])[:, None]
    return null * (k / np.abs(null).sum(axis=1))[:, None]


def _units(pd_unit, pd_angle_deg, n_units):
    """Per unit: its photodiode columns and its null combinations."""
    out = []
    for u in range(n_units):
        cols = np.flatnonzero(np.asarray(pd_unit) == u)
        out.append((cols, null_combinations(np.asarray(pd_angle_deg, float)[cols])))
    return out


def sum_rule_residual(readings, pd_unit, pd_angle_deg, gains=None, usable=None,
                      rule_offsets=None) -> np.ndarray:
    """Relative sum-rule residual ``s`` of every unit at every sample, eq. [1] of the module.

    Parameters
    ----------
    readings : array (n, P)
        Photodiode readings, any unit (dark offsets removed: an offset breaks the rule).
    pd_unit : array (P,) of int ; pd_angle_deg : array (P,)
        Unit and polarizer angle [deg] of each photodiode.
    gains : array (P,), optional
        Relative photodiode gains (default 1), e.g. from :func:`sum_rule_gains`.
    usable : array (n, P) bool, optional
        False for readings to leave out (flagged); a unit-sample with any left out is NaN.
    rule_offsets : array (U, k - 3), optional
        What dark offsets add to each null combination of the gain-corrected readings
        [reading units], subtracted (:func:`sum_rule_gains`); default 0.

    Returns
    -------
    ndarray (n, U)
        Signed residual [1] for units with one null combination, its norm for units with
        several; NaN for units without redundancy (fewer than four distinct angles).
    """
    r = np.asarray(readings, float)
    g = np.ones(r.shape[1]) if gains is None else np.asarray(gains, float)
    r = r / g
    if usable is not None:
        r = np.where(usable, r, np.nan)
    n_units = int(np.max(pd_unit)) + 1
    out = np.full((r.shape[0], n_units), np.nan)
    for u, (cols, null) in enumerate(_units(pd_unit, pd_angle_deg, n_units)):
        if len(null) == 0:
            continue
        ru = r[:, cols]
        mean = ru.mean(axis=1)
        c = 0.0 if rule_offsets is None else np.nan_to_num(np.asarray(rule_offsets)[u,
                                                                              :len(null)])
        comb = (ru @ null.T - c) / mean[:, None]
        out[:, u] = comb[:, 0] if len(null) == 1 else np.linalg.norm(comb, axis=1)
    return out


def sum_rule_gains(readings, pd_unit, pd_angle_deg, usable=None):
    """Relative photodiode gains and the dark offsets' share of the sum rule (module
    docstring), from the readings alone.

    With dark offsets ``o_j`` the rule reads ``sum_j nu_j w_j r_tj = c`` at every sample,
    ``c = sum_j nu_j w_j o_j`` one constant per null combination: the unknowns ``(w, c)``
    are the null vector of the rows ``[nu_m * r_t, -e_m]`` (each scaled by the sample's mean
    reading), unique up to scale once the unit's brightness and polarization vary.

    Parameters
    ----------
    readings, pd_unit, pd_angle_deg, usable
        As :func:`sum_rule_residual`.

    Returns
    -------
    gains : ndarray (P,)
        Mean 1 per unit; NaN for the photodiodes of units without redundancy or without a
        well-defined null direction (:data:`GAIN_IDENTIFIABLE_RATIO`).
    rule_offsets : ndarray (U, max(k) - 3)
        ``c`` per unit and null combination [reading units, on the gain-corrected readings];
        NaN where not identified.
    identifiable : ndarray (U,) bool
    """
    r = np.asarray(readings, float)
    n_units = int(np.max(pd_unit)) + 1
    units = _units(pd_unit, pd_angle_deg, n_units)
    gains = np.full(r.shape[1], np.nan)
    offsets = np.full((n_units, max(1, max(len(nl) for _, nl in units))), np.nan)
    ok = np.zeros(n_units, bool)
    for u, (cols, null) in enumerate(units):
        k, m = len(cols), len(null)
        if m == 0:
            continue
        ru = r[:, cols]
        keep = np.all(np.isfinite(ru), axis=1)
        if usable is not None:
            keep &= np.all(np.asarray(usable)[:, cols], axis=1)
        ru = ru[keep]
        if len(ru) < 3 * (k + m):
            continue
        scale = ru.mean(axis=1)
        ref = np.median(scale)   # c in units of a typical reading: columns of one size
        rows = np.concatenate([
            (ru[:, None, :] * null[None, :, :]).reshape(-1, k),
            -np.kron(ref / scale[:, None], np.eye(m))], axis=1)
        rows[:, :k] /= np.repeat(scale, m)[:, None]
        sv, vt = np.linalg.svd(rows, full_matrices=False)[1:]
        if sv[-1] > GAIN_IDENTIFIABLE_RATIO * sv[-2]:
            continue
        sol = vt[-1] * np.sign(vt[-1][:k].sum())
        w, c = sol[:k], sol[k:] * ref
        if np.any(w <= 0):   # a gain cannot be negative: the readings do not obey the rule
            continue
        g = 1.0 / w
        norm = g.mean()
        gains[cols] = g / norm
        offsets[u, :m] = c * norm   # the rule on r / (g / mean g)
        ok[u] = True
    return gains, offsets, ok


def sun_geometry(inst: Instrument, heading_offset_deg: float, sun_enu) -> tuple:
    """Angular distance [deg] from each unit's axis to the sun, and the sun's side.

    Parameters
    ----------
    inst : Instrument
    heading_offset_deg : float or array (n,)
        Heading minus recorded yaw [deg] (0 for an absolute yaw; a relative yaw's offset
        from the base fit, one per sample when the fit has one per sweep).
    sun_enu : array (n, 3)
        Sun (or Moon) unit vectors in east-north-up at the samples.

    Returns
    -------
    distance_deg : ndarray (n, U)
    side : ndarray (n, U) of int
        +1 when the sun is to the left of the unit's axis as the unit looks out
        (``(view x sun) . up > 0``), -1 to the right, 0 on the axis or straight behind.
    """
    from sensor.compound_eye import body_attitude
    att = body_attitude(inst.yaw_deg + np.asarray(heading_offset_deg, float), inst.pitch_deg,
                        inst.roll_deg)
    views = inst.sensor.nominal().view_directions_sensor()                    # (U, 3)
    enu = np.stack([att.apply(v) for v in views], axis=1)                     # (n, U, 3)
    sun = np.asarray(sun_enu, float)[:, None, :]
    dist = np.degrees(np.arccos(np.clip(np.sum(enu * sun, axis=-1), -1.0, 1.0)))
    up = np.cross(enu, np.broadcast_to(sun, enu.shape))[..., 2]
    return dist, np.sign(np.round(up, 12)).astype(int)


@dataclass(frozen=True)
class InstrumentChecks:
    """The model-free checks of one session.

    Attributes
    ----------
    gains : ndarray (P,)
        Relative photodiode gains from the sum rule (NaN: not identifiable).
    sum_rule : pandas.DataFrame
        One row per unit x sun-distance bin x side x motion: ``unit``, ``distance_deg``
        (bin label), ``side`` (``left``/``right``), ``motion`` (``standing``/``turning``),
        ``n``, ``mean``, ``mean_se`` (sweep jackknife over ``sweeps``), ``rms`` of the gain-corrected
        residual [1].
    motion : pandas.DataFrame
        One row per unit: ``rms_standing`` (reweighted to the turning samples' sun
        distances), ``rms_turning``, ``ratio``, ``fails_in_motion`` (bool).
    glare : pandas.DataFrame
        One row per unit: ``n`` readings within :data:`GLARE_NEAR_DEG` of the sun, the
        number of ``sweeps`` they come from, the ``side_asymmetry`` (mean of the residual
        times +1 with the sun on the left, -1 on the right) with its jackknife SE, and ``side_dependent`` (beyond
        :data:`SIDE_FAMILY_ALPHA`: stray light reaching the photodiodes unequally, by
        the side the sun is on).
    gain_source : list of str
        Per unit: ``"sum rule"`` (its own readings), ``"given"`` (the gains and offsets
        handed in) or ``"none"`` (uncorrected: its residual includes gain and offset
        differences, so it is tabulated but neither named for glare or motion nor part of
        :attr:`turning_ratio`).
    """

    gains: np.ndarray
    sum_rule: pd.DataFrame
    motion: pd.DataFrame
    glare: pd.DataFrame
    gain_source: list

    @property
    def units_failing_in_motion(self) -> list:
        return [int(u) for u in self.motion.unit[self.motion.fails_in_motion]]

    @property
    def turning_ratio(self) -> float:
        """Median over units of the turning over standing residual RMS (NaN without
        standing samples): well above 1 on every unit, turning breaks the rule for the whole
        instrument (channels converted at different instants, a lag of the attitude
        record), not for one faulty unit."""
        r = self.motion.ratio.to_numpy(float)
        return float(np.median(r[np.isfinite(r)])) if np.isfinite(r).any() else float("nan")

    @property
    def motion_breaks_rule(self) -> bool:
        return bool(self.turning_ratio > MOTION_FACTOR)

    @property
    def units_with_side_glare(self) -> list:
        return [int(u) for u in self.glare.unit[self.glare.side_dependent]]

    def to_dict(self) -> dict:
        """Plain JSON types, NaN as None."""
        def records(df):
            return [{k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                     for k, v in row.items()} for row in df.to_dict(orient="records")]
        ratio = self.turning_ratio
        return {"gains": [None if not np.isfinite(g) else float(g) for g in self.gains],
                "gain_source": list(self.gain_source),
                "sum_rule": records(self.sum_rule),
                "motion": records(self.motion),
                "glare": records(self.glare),
                "units_failing_in_motion": self.units_failing_in_motion,
                "turning_ratio": ratio if np.isfinite(ratio) else None,
                "motion_breaks_rule": self.motion_breaks_rule,
                "units_with_side_glare": self.units_with_side_glare}


def _jackknife_means(df: pd.DataFrame, keys: list) -> pd.DataFrame:
    """Mean, RMS and count of ``s`` per group, with the delete-one-sweep jackknife SE of the
    mean (:func:`calibration.diagnosis.core.jackknife_ratio` of the per-sweep sums and
    counts, [2]_ eq. 11.5; NaN for a group seen in one sweep) and the number of ``sweeps``."""
    from ..diagnosis.core import jackknife_ratio
    per = df.groupby(keys + ["sweep"], observed=True).s.agg(["sum", "count"]).reset_index()
    rows = []
    for key, g in per.groupby(keys, observed=True):
        sd = jackknife_ratio(g["sum"].to_numpy(), g["count"].to_numpy())[1]
        key = key if isinstance(key, tuple) else (key,)
        rows.append((*key, sd if np.isfinite(sd) else np.nan, len(g)))
    se = pd.DataFrame(rows, columns=keys + ["mean_se", "sweeps"]).astype({"sweeps": int})
    out = df.assign(s2=df.s ** 2).groupby(keys, observed=True).agg(
        n=("s", "count"), mean=("s", "mean"), ms=("s2", "mean")).reset_index()
    out["rms"] = np.sqrt(out.pop("ms"))
    return out.merge(se, on=keys, how="left")


def check_instrument(inst: Instrument, heading_offset_deg, sun_enu, *, gains=None,
                     dark_offsets=None) -> InstrumentChecks:
    """Sum rule by sun distance, side and motion, and the motion test, of one session.

    Parameters
    ----------
    inst : Instrument
    heading_offset_deg : float or array (n,)
        Heading minus recorded yaw [deg] (:func:`sun_geometry`).
    sun_enu : array (n, 3)
        The light source's ENU unit vectors at the samples.
    gains, dark_offsets : array (P,), optional
        Photodiode gains and dark offsets [reading units] known otherwise (a base fit's),
        used for the units whose readings do not define their own (NaN: none known);
        ``InstrumentChecks.gain_source`` says which each unit got.

    Returns
    -------
    InstrumentChecks
    """
    usable = ~inst.flagged
    r = np.array(inst.readings, float)
    dist, side = sun_geometry(inst, heading_offset_deg, sun_enu)
    # gains from the readings far from the sun (no glare) and standing (a unit misreading
    # only while turning must not bend them), each where enough such samples remain
    fit = usable.copy()
    for keep in (dist[:, inst.pd_unit] >= GAIN_MIN_SUN_DISTANCE_DEG,
                 np.broadcast_to(~inst.rotating[:, None], usable.shape)):
        enough = np.count_nonzero(fit & keep, axis=0) >= 3 * MIN_SAMPLES
        fit &= np.where(enough, keep, True)
    rule_gains, rule_offsets, own = sum_rule_gains(r, inst.pd_unit, inst.pd_angle_deg, fit)
    source = np.where(own, "sum rule", "none").astype(object)
    if gains is not None:   # the units without their own: the given gains and offsets
        g = np.asarray(gains, float)
        o = np.zeros_like(g) if dark_offsets is None else np.asarray(dark_offsets, float)
        for u in np.flatnonzero(~own):
            cols = np.flatnonzero(inst.pd_unit == u)
            if np.all(np.isfinite(g[cols])) and np.all(np.isfinite(o[cols])):
                r[:, cols] = (r[:, cols] - o[cols]) / (g[cols] / g[cols].mean())
                rule_offsets[u] = 0.0
                source[u] = "given"
    s = sum_rule_residual(r, inst.pd_unit, inst.pd_angle_deg,
                          np.where(np.isfinite(rule_gains), rule_gains, 1.0), usable,
                          rule_offsets)
    n, U = s.shape
    df = pd.DataFrame({
        "unit": np.tile(np.arange(U), n), "s": s.ravel(),
        "distance_deg": pd.cut(dist.ravel(), DISTANCE_BINS_DEG, include_lowest=True),
        "side": np.where(side.ravel() >= 0, "left", "right"),
        "motion": np.repeat(np.where(inst.rotating, "turning", "standing"), U),
        "sweep": np.repeat(inst.sweep, U)}).dropna(subset=["s"])
    df["distance_deg"] = df.distance_deg.astype(str)
    table = _jackknife_means(df, ["unit", "distance_deg", "side", "motion"])
    near = dist.ravel()[np.isfinite(s.ravel())] < GLARE_NEAR_DEG
    signed = df[near].assign(s=df.s[near] * np.where(df.side[near] == "left", 1.0, -1.0))
    glare = _jackknife_means(signed, ["unit"]).rename(
        columns={"mean": "side_asymmetry", "mean_se": "side_asymmetry_se"})
    from scipy.stats import t as student_t
    crit = student_t.ppf(1.0 - SIDE_FAMILY_ALPHA / (2.0 * U), glare.sweeps - 1)
    corrected = np.array([src != "none" for src in source])
    glare["side_dependent"] = ((np.abs(glare.side_asymmetry) > crit * glare.side_asymmetry_se)
                               .fillna(False).astype(bool) & corrected[glare.unit])
    motion = _motion(df[corrected[df.unit.to_numpy()]], U)
    return InstrumentChecks(rule_gains, table, motion,
                            glare[["unit", "n", "sweeps", "side_asymmetry",
                                   "side_asymmetry_se", "side_dependent"]],
                            [str(x) for x in source])


def _motion(df: pd.DataFrame, n_units: int) -> pd.DataFrame:
    """Turning against standing RMS per unit at matched sun distances (module docstring)."""
    sq = df.assign(s2=df.s ** 2)
    by = sq.groupby(["unit", "motion", "distance_deg"], observed=True).s2.agg(["mean", "count"])
    rows = []
    for u in range(n_units):
        turn = by.loc[(u, "turning")] if (u, "turning") in by.index.droplevel(2) else None
        stand = by.loc[(u, "standing")] if (u, "standing") in by.index.droplevel(2) else None
        rms_t = rms_s = np.nan
        if turn is not None and turn["count"].sum() >= MIN_SAMPLES:
            rms_t = float(np.sqrt(np.average(turn["mean"], weights=turn["count"])))
            if stand is not None and stand["count"].sum() >= MIN_SAMPLES:
                common = turn.index.intersection(stand.index)
                if len(common):
                    rms_s = float(np.sqrt(np.average(stand.loc[common, "mean"],
                                                     weights=turn.loc[common, "count"])))
        rows.append({"unit": u, "rms_standing": rms_s, "rms_turning": rms_t})
    out = pd.DataFrame(rows)
    out["ratio"] = out.rms_turning / out.rms_standing
    typical = np.nanmedian(out.rms_turning) if np.isfinite(out.rms_turning).any() else np.nan
    above_units = out.rms_turning > MOTION_FACTOR * typical
    above_self = (out.ratio > MOTION_FACTOR) | ~np.isfinite(out.rms_standing)
    out["fails_in_motion"] = (above_units & above_self).fillna(False).astype(bool)
    return out


MOTION_SCREEN_KINDS = frozenset({"not_malus", "too_few"})
"""Fault kinds of the screen that a unit failing only in motion draws (its photodiodes off
Malus's law while turning, and then too few left): the units so excluded are checked for
motion on their readings before the screen (:func:`motion_faults`)."""


def motion_faults(checks: dict, unscreened: dict | None = None, screen_faults=()) -> list:
    """Fault-list entries of the units that fail only in motion.

    Parameters
    ----------
    checks : dict
        :meth:`InstrumentChecks.to_dict` of a session's screened readings.
    unscreened : dict, optional
        The same checks of the readings before the fault screen: they name a unit whose
        photodiodes the screen excluded for leaving Malus's law only
        (:data:`MOTION_SCREEN_KINDS`: their readings off it while the ring turns), which the
        screened checks no longer see; a unit with a dead, stuck, zero, saturated or
        duplicated photodiode is not named from them.
    screen_faults : sequence of dict
        The screen's faults (``channel``, ``kind``), to tell which units it excluded.

    Returns
    -------
    list of dict
        ``{"channel": "u<k>", "kind": "fails_in_motion", "evidence": {...}}`` per unit named
        by the screened checks, or by the unscreened ones among the units the screen
        excluded: its sum-rule residual RMS turning and standing (at the turning samples'
        sun distances), their ratio, the units' median turning RMS, the factor both must
        exceed (:data:`MOTION_FACTOR`), which checks named it (``readings``: ``screened``
        or ``unscreened``) and ``excluded_by_screen`` (the screen's fault kinds of its
        photodiodes, empty when none). This fault excludes nothing: standing, the unit obeys
        the rule, and a lag or read order that spoils it while turning is what the
        diagnosis's candidates are for.
    """
    def unit_of(channel: str) -> int | None:
        head = str(channel).split("_")[0]
        return int(head[1:]) if head.startswith("u") and head[1:].isdigit() else None

    excluded: dict = {}
    for f in screen_faults:
        u = unit_of(f.get("channel", ""))
        if u is not None:
            excluded.setdefault(u, set()).add(str(f.get("kind")))
    named = [(int(u), checks, "screened") for u in checks.get("units_failing_in_motion", [])]
    if unscreened is not None:
        seen = {u for u, _, _ in named}
        named += [(int(u), unscreened, "unscreened")
                  for u in unscreened.get("units_failing_in_motion", [])
                  if int(u) in excluded and int(u) not in seen
                  and excluded[int(u)] <= MOTION_SCREEN_KINDS]
    out = []
    for u, source, which in sorted(named, key=lambda x: x[0]):
        rows = {int(r["unit"]): r for r in source.get("motion", [])}
        turning = [r["rms_turning"] for r in rows.values() if r.get("rms_turning") is not None]
        r = rows.get(u, {})
        out.append({"channel": f"u{u}", "kind": "fails_in_motion", "evidence": {
            "sum_rule_rms_turning": r.get("rms_turning"),
            "sum_rule_rms_standing": r.get("rms_standing"),
            "turning_over_standing": r.get("ratio"),
            "units_median_rms_turning": float(np.median(turning)) if turning else None,
            "factor": MOTION_FACTOR, "readings": which,
            "excluded_by_screen": sorted(excluded.get(u, ()))}})
    return out
