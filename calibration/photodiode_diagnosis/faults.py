"""Faults of a photodiode instrument, found before (and after) the base fit.

Channel faults (a whole photodiode column is excluded and reported):

- ``dead``: one constant value over the file (the reader's flag), or no finite reading;
- ``zero``: at least :data:`ZERO_FRACTION` of the readings exactly 0 (dropped conversions or
  no light);
- ``saturated``: at least :data:`SATURATED_FRACTION` of the readings at the declared
  saturation value or at the instrument's own rail (below);
- ``stuck``: one value in at least :data:`STUCK_FRACTION` of the samples taken while the
  platform turns (a real photodiode's reading changes as its view sweeps the sky);
- ``duplicated``: two photodiodes of one unit equal in at least :data:`DUPLICATE_FRACTION` of
  the samples (a wiring or logging fault: two polarizer angles cannot read the same sky);
- ``not_malus``: after the base fit, residual RMS far above the other channels'
  (:func:`malus_outliers`): the channel does not follow Malus's law against the fitted sky.

Unit faults: a unit left with fewer than three working photodiodes at distinct polarizer
angles (modulo 180 deg), or two on a rotating analyser (:func:`rotating_units`), cannot
measure a linear polarization and is excluded (``too_few``).

Reading exclusions (counted, not faults): missing, zero and saturated readings, every
reading of a unit at a sample where one of its photodiodes is saturated (the sun or its glare
is in the unit's view and the channels are no longer linear), and the unit's readings at the
samples where it is brighter than its glare threshold (:func:`bright_glare`).

Glare: with the sun at the edge of a unit's field of view, direct sunlight (some 10^5 times
the sky's radiance per steradian) reaches the photodiodes at oblique incidence through the
unit's window, diffuser and polarizer film, which no longer act as an ideal analyser: the
Fresnel transmittances of s and p light differ at oblique incidence (Hecht 2017, sect. 4.6),
so the stray sunlight is partly polarized in its own plane of incidence, and a polarizer
film's extinction falls off its axis. The readings then follow neither the sky's polarization
nor Malus's law against it, well before a channel clips. The unit's brightness (its mean
reading over its median across the session) tells these samples apart without any geometry
(so without the heading, the clock or the sun's position the fit is to find): after the base
fit, the unit-samples are binned by brightness in steps of :data:`GLARE_BIN` in log2 above
the median (sparse bins merged upwards until one holds :data:`GLARE_MIN_SAMPLES`), and every
sample from the first bin whose residual RMS exceeds
:data:`GLARE_FACTOR` times that of the samples around the median is glare.

The rail: an instrument can clip below its declared ``saturation_value`` (a light-to-digital
converter's own full scale). Readings within :data:`RAIL_BAND` of the highest reading below
the declared value are a rail when at least :data:`RAIL_MIN_FRACTION` of all readings sit
there and the clipped ones among them, on two or more channels, pile up (at least twice as
many as the readings in the next two bands below: a smooth sky thins out towards its
brightest reading, a clipped one piles up). A reading in the band is clipped when every
photodiode of its unit is in the band with it at that sample (the full scale erases the
polarizers' modulation: on the reference ring's soft clip at 11.1-11.7k counts a unit's four
readings have a median ``(max - min) / (max + min)`` of 0.15-0.2 %), or when it is the top
value itself (a hard clip). A turning unit's
reading follows the sky's brightness and its polarizer's Malus modulation, and the values of
such a curve pile up at its smooth maximum too, but there the crossed photodiode reads its
minimum (a simulated ring whose units weigh the sky over a HWHM of 50 deg: 36 % of the
converter's full scale, its readings within 4 % of the top 2.1 times as many as in the next
two bands, its clipped ones 0.57 times).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .instrument import Instrument

__all__ = ["ZERO_FRACTION", "SATURATED_FRACTION", "STUCK_FRACTION", "DUPLICATE_FRACTION",
           "RAIL_BAND", "RAIL_MIN_FRACTION", "GLARE_BIN", "GLARE_FACTOR", "Screen", "screen",
           "malus_outliers", "bright_glare", "unit_brightness", "rotating_units"]

ZERO_FRACTION = 0.2
SATURATED_FRACTION = 0.25
STUCK_FRACTION = 0.5
DUPLICATE_FRACTION = 0.9
RAIL_BAND = 0.04
RAIL_MIN_FRACTION = 0.002
GLARE_BIN = 0.1
"""Width of the brightness bins of :func:`bright_glare`, in log2 of brightness (7 %)."""
GLARE_FACTOR = 3.0
"""A brightness bin is glare when its residual RMS exceeds this multiple of the RMS of the
unit-samples within one bin of the median: a threefold RMS is a ninefold variance, far more
than the sky's own brightening towards the sun changes the fit (the aureole is smooth and
the profiled radiance absorbs its brightness)."""
GLARE_MIN_SAMPLES = 20
MALUS_FACTOR = 2.5
"""A channel fails Malus's law when its residual RMS exceeds this multiple of the median
channel's and the robust spread of the channels (median + 5 MAD)."""


@dataclass
class Screen:
    """Result of the fault screen.

    Attributes
    ----------
    faults : list of dict
        ``{"channel", "kind", "evidence"}`` per faulty photodiode or unit.
    channel_ok : ndarray (P,) bool
    unit_ok : ndarray (U,) bool
    reading_ok : ndarray (n, P) bool
        Readings used by the fit (channel and unit working, reading not excluded).
    counts : dict
        Excluded readings by reason.
    rail : float or None
        The instrument's own clipping level, where found.
    """

    faults: list
    channel_ok: np.ndarray
    unit_ok: np.ndarray
    reading_ok: np.ndarray
    counts: dict = field(default_factory=dict)
    rail: float | None = None
    bright: np.ndarray | None = None
    """Unit-sample glare by brightness (n, P), from :func:`bright_glare`."""
    glare: dict | None = None
    """How the glare threshold was found (brightness ratio, RMS by bin), or None."""

    @property
    def faulty_channels(self) -> list:
        return [f["channel"] for f in self.faults]


def _saturation_value(inst: Instrument) -> float:
    """The declared saturation value; infinite when the sidecar declares none (normalised
    readings have no rail)."""
    value = inst.source.get("saturation_value")
    return np.inf if value is None else float(value)


def _rail(values, finite, sat_value, pd_unit=None):
    """The instrument's own clipping level [counts] from the readings (n, P), or None (see
    the module doc). ``pd_unit`` (P,): the unit of each photodiode (None: each its own)."""
    below = finite & (values < sat_value)
    if not below.any():
        return None
    top = float(values[below].max())
    near = below & (values >= (1.0 - RAIL_BAND) * top)
    under = below & (values < (1.0 - RAIL_BAND) * top) & (values >= (1.0 - 3 * RAIL_BAND) * top)
    # a converter's full scale erases the polarizers' modulation: every photodiode of the
    # unit sits at the top with it (or the reading is the top value itself, a hard clip);
    # a sky's brightest reading is its polarizer's Malus maximum, the crossed one's minimum
    P = values.shape[1]
    unit = np.arange(P) if pd_unit is None else np.asarray(pd_unit)
    member = (unit[None, :] == np.unique(unit)[:, None]).astype(float)            # (U, P)
    high = near | (finite & (values >= sat_value))
    whole = ((high.astype(float) @ member.T) == member.sum(axis=1)[None, :]) @ member > 0
    clipped = near & (whole | (values == top))
    pile_up = clipped.sum() >= 2 * under.sum()
    if (pile_up and near.mean() >= RAIL_MIN_FRACTION and (clipped.sum(axis=0) > 0).sum() >= 2
            and top > 0):
        return (1.0 - RAIL_BAND) * top
    return None


def _mode_fraction(x) -> tuple[float, float]:
    if x.size == 0:
        return np.nan, 0.0
    vals, cnt = np.unique(x, return_counts=True)
    k = int(np.argmax(cnt))
    return float(vals[k]), float(cnt[k] / x.size)


def rotating_units(inst: Instrument) -> np.ndarray:
    """(U,) bool: the units whose analyser turns (a photodiode's polarizer angle changes from
    sample to sample, :attr:`Instrument.pd_angle_row_deg`)."""
    out = np.zeros(inst.n_units, bool)
    if inst.pd_angle_row_deg is None or inst.n == 0:
        return out
    turns = np.ptp(np.mod(np.asarray(inst.pd_angle_row_deg, float), 180.0), axis=0) > 0.0
    out[np.unique(inst.pd_unit[turns])] = True
    return out


def _unit_check(inst: Instrument, channel_ok, faults):
    """Units left with too few working photodiodes at distinct polarizer angles: three for a
    fixed analyser (the radiance, the degree and the angle of polarization at each sample),
    two for a turning one (its photodiodes sweep every angle, so a crossed pair samples the
    modulation over each half-turn)."""
    unit_ok = np.ones(inst.n_units, bool)
    turning = rotating_units(inst)
    for u in range(inst.n_units):
        cols = np.flatnonzero((inst.pd_unit == u) & channel_ok)
        angles = {float(a) % 180.0 for a in inst.pd_angle_deg[cols]}
        need = 2 if turning[u] else 3
        if len(angles) < need:
            unit_ok[u] = False
            faults.append({"channel": f"u{u}", "kind": "too_few",
                           "evidence": {"working_photodiodes": [inst.columns[c] for c in cols],
                                        "needed": f"{need} at distinct polarizer angles"}})
    return unit_ok


def screen(inst: Instrument) -> Screen:
    """Find the faulty channels and units and the readings to exclude (see module doc)."""
    R = inst.readings
    n, P = R.shape
    finite = np.isfinite(R)
    sat_value = _saturation_value(inst)
    rail = _rail(R, finite, sat_value, inst.pd_unit)
    finite, saturated, zero = _masks(inst, rail)
    faults, ok = [], np.ones(P, bool)
    for p, col in enumerate(inst.columns):
        x = R[:, p]
        f = finite[:, p]
        if not f.any() or (f.sum() >= 10 and np.nanmax(x) == np.nanmin(x)):
            faults.append({"channel": col, "kind": "dead",
                           "evidence": {"value": None if not f.any() else float(np.nanmax(x)),
                                        "finite_readings": int(f.sum())}})
            ok[p] = False
            continue
        zf = float(zero[:, p].sum() / f.sum())
        if zf >= ZERO_FRACTION:
            faults.append({"channel": col, "kind": "zero", "evidence": {"zero_fraction": zf}})
            ok[p] = False
            continue
        sf = float(saturated[:, p].sum() / f.sum())
        if sf >= SATURATED_FRACTION:
            faults.append({"channel": col, "kind": "saturated",
                           "evidence": {"saturated_fraction": sf,
                                        "level": rail if rail is not None else sat_value}})
            ok[p] = False
            continue
        turning = f & inst.rotating & ~saturated[:, p] & ~zero[:, p]
        value, mf = _mode_fraction(x[turning])
        if turning.sum() >= 20 and mf >= STUCK_FRACTION:
            faults.append({"channel": col, "kind": "stuck",
                           "evidence": {"value": value, "fraction_while_turning": mf}})
            ok[p] = False
    for u in range(inst.n_units):
        cols = np.flatnonzero(inst.pd_unit == u)
        for i, a in enumerate(cols):
            for b in cols[i + 1:]:
                if not (ok[a] or ok[b]):
                    continue
                both = finite[:, a] & finite[:, b] & ~saturated[:, a] & ~saturated[:, b]
                if both.sum() < 20:
                    continue
                eq = float(np.mean(R[both, a] == R[both, b]))
                if eq >= DUPLICATE_FRACTION:
                    for c, other in ((a, b), (b, a)):
                        faults.append({"channel": inst.columns[c], "kind": "duplicated",
                                       "evidence": {"same_as": inst.columns[other],
                                                    "equal_fraction": eq}})
                        ok[c] = False
    unit_ok = _unit_check(inst, ok, faults)
    return _finish(inst, faults, ok, unit_ok, saturated, zero, finite, rail)


def _masks(inst: Instrument, rail):
    """Finite, saturated (declared value or rail) and zero readings (n, P)."""
    R = inst.readings
    finite = np.isfinite(R)
    sat_value = _saturation_value(inst)
    with np.errstate(invalid="ignore"):
        saturated = finite & ((R >= sat_value) | ((R >= rail) if rail is not None else False))
        zero = finite & (R == 0.0)
    return finite, saturated, zero


def _finish(inst, faults, ok, unit_ok, saturated, zero, finite, rail, bright=None,
            glare_info=None) -> Screen:
    n, P = inst.readings.shape
    bright = np.zeros((n, P), bool) if bright is None else bright
    usable_channel = ok & unit_ok[inst.pd_unit]
    member = inst.pd_unit[None, :] == np.arange(inst.n_units)[:, None]
    glare_unit = (saturated & usable_channel[None, :]).astype(float) @ member.T.astype(float) > 0
    glare = glare_unit[:, inst.pd_unit] & ~saturated
    bright = bright & finite & ~saturated & ~zero & ~glare
    reading_ok = (usable_channel[None, :] & finite & ~saturated & ~zero & ~glare & ~bright
                  & ~inst.flagged)
    counts = {"readings": int(n * P), "missing": int((~finite).sum()),
              "saturated": int(saturated.sum()), "zero": int(zero.sum()),
              "glare_unit_readings": int((glare & usable_channel[None, :]).sum()),
              "bright_glare_readings": int((bright & usable_channel[None, :]).sum()),
              "faulty_channel_readings": int((~usable_channel).sum() * n),
              "used": int(reading_ok.sum())}
    return Screen(faults, ok, unit_ok, reading_ok, counts, rail, bright, glare_info)


def unit_brightness(inst: Instrument, reading_ok) -> np.ndarray:
    """Each unit's mean reading over its median across the session (n, U); NaN where the
    unit has no usable reading."""
    member = (inst.pd_unit[None, :] == np.arange(inst.n_units)[:, None]).astype(float)
    total = np.where(reading_ok, inst.readings, 0.0) @ member.T
    cnt = reading_ok.astype(float) @ member.T
    mean = np.where(cnt > 0, total / np.maximum(cnt, 1.0), np.nan)
    out = np.full_like(mean, np.nan)
    for u in range(inst.n_units):
        live = np.isfinite(mean[:, u])
        if live.any():
            out[:, u] = mean[:, u] / np.median(mean[live, u])
    return out


def bright_glare(inst: Instrument, scr: Screen, residual, usable) -> Screen:
    """Exclude the unit-samples brighter than the glare threshold found from the base-fit
    residuals (n, P) (see module doc); returns the updated screen.

    The screen's ``glare`` records the threshold (``brightness_ratio``, None when no bin
    qualifies) and the residual RMS by brightness bin.
    """
    w = usable & scr.reading_ok
    b = unit_brightness(inst, scr.reading_ok)                        # (n, U)
    r2 = np.where(w, residual, 0.0) ** 2
    member = (inst.pd_unit[None, :] == np.arange(inst.n_units)[:, None]).astype(float)
    ss, cnt = r2 @ member.T, w.astype(float) @ member.T              # (n, U)
    ok = (cnt > 0) & np.isfinite(b) & (b > 0)
    level = np.floor(np.log2(np.where(ok, b, 1.0)) / GLARE_BIN).astype(int)
    core = ok & (np.abs(level) <= 1)
    if core.sum() < GLARE_MIN_SAMPLES:
        return scr
    core_rms = float(np.sqrt(ss[core].sum() / cnt[core].sum()))
    bins, threshold = [], None
    top = int(level[ok].max(initial=0))
    k = 1
    while k <= top and threshold is None:
        j = k                  # merge sparse bins upwards until one holds enough samples
        while j < top and (ok & (level >= k) & (level <= j)).sum() < GLARE_MIN_SAMPLES:
            j += 1
        m = ok & (level >= k) & (level <= j)
        if m.sum() >= GLARE_MIN_SAMPLES:
            rms = float(np.sqrt(ss[m].sum() / cnt[m].sum()))
            bins.append({"brightness_from": float(2.0 ** (k * GLARE_BIN)), "rms": rms,
                         "unit_samples": int(m.sum())})
            if rms > GLARE_FACTOR * core_rms:
                threshold = float(2.0 ** (k * GLARE_BIN))
        k = j + 1
    info = {"brightness_ratio": threshold, "core_rms": core_rms, "factor": GLARE_FACTOR,
            "bins": bins}
    if threshold is None:
        return replace(scr, glare=info)
    bright_unit = ok & (b >= threshold * (1 - 1e-12))
    bright = bright_unit[:, inst.pd_unit]
    finite, saturated, zero = _masks(inst, scr.rail)
    return _finish(inst, scr.faults, scr.channel_ok, scr.unit_ok, saturated, zero, finite,
                   scr.rail, bright, info)


def malus_outliers(inst: Instrument, scr: Screen, residual, usable) -> Screen:
    """Add ``not_malus`` faults from base-fit residuals (n, P) and return the updated screen."""
    w = usable & scr.reading_ok
    cnt = w.sum(axis=0)
    rms = np.sqrt(np.where(cnt > 0, np.sum(np.where(w, residual, 0.0) ** 2, axis=0)
                           / np.maximum(cnt, 1), np.nan))
    live = scr.channel_ok & scr.unit_ok[inst.pd_unit] & (cnt > 0)
    if live.sum() < 4:
        return scr
    med = float(np.median(rms[live]))
    mad = float(np.median(np.abs(rms[live] - med)))
    limit = max(MALUS_FACTOR * med, med + 5.0 * 1.4826 * mad)
    faults, ok = list(scr.faults), scr.channel_ok.copy()
    for p in np.flatnonzero(live & (rms > limit)):
        faults.append({"channel": inst.columns[p], "kind": "not_malus",
                       "evidence": {"residual_rms": float(rms[p]), "median_rms": med,
                                    "limit": float(limit)}})
        ok[p] = False
    if ok.sum() == scr.channel_ok.sum():
        return scr
    faults = [f for f in faults if f["kind"] != "too_few"]
    unit_ok = _unit_check(inst, ok, faults)
    finite, saturated, zero = _masks(inst, scr.rail)
    return _finish(inst, faults, ok, unit_ok, saturated, zero, finite, scr.rail, scr.bright,
                   scr.glare)
