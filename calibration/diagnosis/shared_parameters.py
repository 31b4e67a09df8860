"""Parameters a day's sessions should share: their common value, and whether the sessions agree.

A candidate fitted on each session of one instrument gives one estimate per session. Some
parameters belong to the instrument (a field of view, a gyro scale factor, a tilt on the
platform, a read lag, a glare fall-off) and are the same in every session; some belong to
the sky (an optical thickness, an albedo, an aerosol load), which changes slowly over a day;
some belong to one session's scene or log (an occlusion, a clock). For each parameter
fitted in two or more sessions this module gives the inverse-variance weighted mean, the
chi-square of the sessions about it (Cochran's Q) and its p-value, and the between-session
standard deviation beyond the sessions' own uncertainties (the DerSimonian-Laird moment
estimate [1]_): an instrument parameter whose sessions disagree (p < 0.01) is not what its
candidate says, or the sessions' uncertainties are too small. Where they disagree, the rank
correlation of the session values with the sun's elevation (Spearman's rho [3]_) says
whether the disagreement follows the sun: an instrument parameter that drifts with the sun
stands for an angular form the candidate does not have. A day may be combined over all
sessions or only over those where the candidate removes a given share of the excess (where
its parameters are measured on the effect they describe).

References
----------
.. [1] R. DerSimonian, N. Laird, "Meta-analysis in clinical trials", Controlled Clinical
   Trials 7(3):177-188 (1986), doi:10.1016/0197-2456(86)90046-2 (Q, tau^2 moment estimate).
.. [2] W. G. Cochran, "The combination of estimates from different experiments",
   Biometrics 10(1):101-129 (1954), doi:10.2307/3001666.
.. [3] C. Spearman, "The proof and measurement of association between two things",
   American Journal of Psychology 15(1):72-101 (1904), doi:10.2307/1412159.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from .errors import InsufficientDataError

__all__ = ["SharedEstimate", "combine_sessions", "shared_parameters", "sun_trend",
           "PARAMETER_SCOPE", "AGREEMENT_P", "TREND_MIN_SESSIONS", "TREND_EXACT_MAX"]

_PER_PHOTODIODE = re.compile(r"_u\d+_p\d")
"""A per-photodiode parameter's name (a strength of the light on one photodiode, ``S_u0_p045``):
each session fits its own, which a day does not combine."""

AGREEMENT_P = 0.01
"""Sessions agree on a parameter when Cochran's Q has a p-value at or above this; a parameter
drifts with the sun when its rank correlation with the sun's elevation has a p-value below
it."""

TREND_MIN_SESSIONS = 6
"""Fewest sessions with a known sun elevation for the rank correlation with it: with five,
even a perfect ordering has an exact two-sided p of 2/5! = 0.017, above
:data:`AGREEMENT_P`."""

TREND_EXACT_MAX = 9
"""Up to this many sessions the trend's p-value is exact (all n! pairings, 0.6 s at 9);
above, the Student-t approximation of ``scipy.stats.spearmanr``, which is close from about
ten pairs on."""

PARAMETER_SCOPE = {
    "fov": "instrument", "yaw_scale": "instrument", "tilt": "instrument",
    "read_lag": "instrument", "side_glare": "instrument", "stray_light": "instrument",
    "multiple_scattering": "sky", "aerosol": "sky", "neutral_points": "sky",
    "overcast": "sky", "aureole": "sky",
    "occlusion": "session", "clock_offset": "session",
}
"""What each ring candidate's parameters belong to: ``instrument`` (shared by every session
of the instrument), ``sky`` (changes slowly over a day: its spread is reported),
``session`` (one scene or one log: not combined)."""


@dataclass(frozen=True)
class SharedEstimate:
    """One parameter over sessions.

    Attributes
    ----------
    n : int
        Sessions combined.
    mean, se : float
        Inverse-variance weighted mean and its standard error (fixed effect).
    q : float
        Cochran's Q, ``sum w_i (x_i - mean)^2`` with ``w_i = 1 / se_i^2`` [2]_.
    p : float
        Upper tail of chi-square with ``n - 1`` degrees of freedom at ``q``.
    between_sd : float
        Between-session SD beyond the sessions' uncertainties,
        ``sqrt(max(0, (Q - (n - 1)) / (S1 - S2 / S1)))``, ``S1 = sum w``, ``S2 = sum w^2`` [1]_.
    spread : float
        Plain SD of the session values (``ddof = 1``).
    """

    n: int
    mean: float
    se: float
    q: float
    p: float
    between_sd: float
    spread: float

    @property
    def agree(self) -> bool:
        return self.p >= AGREEMENT_P


def combine_sessions(values, se) -> SharedEstimate:
    """Weighted mean, Cochran's Q and the between-session SD of per-session estimates.

    Parameters
    ----------
    values, se : array (n,)
        Estimates and their standard errors, ``n >= 2``, standard errors finite and > 0.

    Raises
    ------
    InsufficientDataError
        Fewer than two estimates, a non-finite value, or a standard error not > 0, naming it.
    """
    x, s = np.asarray(values, float), np.asarray(se, float)
    if x.shape != s.shape or x.ndim != 1 or x.size < 2:
        raise InsufficientDataError(f"need two or more estimates with one SE each; got values of "
                             f"shape {x.shape} and SEs of shape {s.shape}")
    bad = ~np.isfinite(x) | ~np.isfinite(s) | (s <= 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InsufficientDataError(f"estimate {i} is {x[i]!r} with SE {s[i]!r}: values must be "
                             "finite and SEs finite and > 0")
    w = 1.0 / s ** 2
    s1, s2 = float(w.sum()), float((w ** 2).sum())
    mean = float(np.sum(w * x) / s1)
    q = float(np.sum(w * (x - mean) ** 2))
    dof = x.size - 1
    tau2 = max(0.0, (q - dof) / (s1 - s2 / s1))
    return SharedEstimate(n=int(x.size), mean=mean, se=float(np.sqrt(1.0 / s1)), q=q,
                          p=float(stats.chi2.sf(q, dof)), between_sd=float(np.sqrt(tau2)),
                          spread=float(np.std(x, ddof=1)))


def _se(p: dict):
    for key in ("se", "uncertainty"):
        v = p.get(key)
        if v is not None and np.isfinite(v) and v > 0:
            return float(v)
    return None


def sun_trend(values, sun_elevation_deg) -> tuple:
    """Spearman's rank correlation of per-session values with the sessions' sun elevation,
    and its two-sided p-value.

    Parameters
    ----------
    values, sun_elevation_deg : array (n,)
        Session estimates and each session's sun elevation [deg]; sessions whose
        elevation is not finite are left out.

    Returns
    -------
    (rho, p) : tuple of float
        NaN for both when fewer than :data:`TREND_MIN_SESSIONS` sessions are left or the
        values or elevations are all equal. The p-value is exact (a permutation test over
        every pairing, ``scipy.stats.permutation_test``) up to :data:`TREND_EXACT_MAX`
        sessions: the t approximation gives p = 0 to any perfect ordering of a few.

    References
    ----------
    C. Spearman, "The proof and measurement of association between two things", American
    Journal of Psychology 15(1):72-101 (1904), doi:10.2307/1412159.
    """
    x, h = np.asarray(values, float), np.asarray(sun_elevation_deg, float)
    keep = np.isfinite(x) & np.isfinite(h)
    x, h = x[keep], h[keep]
    if x.size < TREND_MIN_SESSIONS or np.ptp(x) == 0 or np.ptp(h) == 0:
        return float("nan"), float("nan")
    rho, p = stats.spearmanr(x, h)
    if x.size <= TREND_EXACT_MAX:
        rh = stats.rankdata(h)
        rh = rh - rh.mean()

        def rank_correlation(a, axis=-1):       # Pearson's r of the ranks, batched
            ra = stats.rankdata(a, axis=-1)
            ra = ra - ra.mean(axis=-1, keepdims=True)
            return (ra @ rh) / np.sqrt(np.sum(ra ** 2, axis=-1) * np.sum(rh ** 2))
        p = stats.permutation_test((x,), rank_correlation, permutation_type="pairings",
                                   n_resamples=np.inf, vectorized=True, batch=50_000).pvalue
    return float(rho), float(p)


def _sun_elevation(report) -> float:
    """The session's sun elevation [deg]: the midpoint of the lowest and highest in its
    report's data (NaN when unknown)."""
    el = (report.data or {}).get("sun_elevation_deg")
    if el is None:
        return float("nan")
    el = np.asarray(el, float)
    return float(np.mean(el)) if el.size and np.all(np.isfinite(el)) else float("nan")


def shared_parameters(reports: dict, scope: dict | None = None,
                      min_share: float | None = None) -> pd.DataFrame:
    """Per parameter of every candidate fitted with an uncertainty in two or more sessions:
    its combination over the sessions (:func:`combine_sessions`) and its rank correlation
    with the sessions' sun elevation (:func:`sun_trend`).

    Parameters
    ----------
    reports : dict
        Session name -> :class:`calibration.diagnosis.report.DiagnosisReport`.
    scope : dict, optional
        Candidate -> ``instrument``, ``sky`` or ``session`` (default
        :data:`PARAMETER_SCOPE`); ``session`` candidates and candidates it does not list are
        left out, and so are per-photodiode parameters (one photodiode's glare).
    min_share : float, optional
        Combine a candidate only over the sessions where it removes at least this share of
        the excess over the noise floor (its ``explained_share``; sessions without one are
        left out). Default: every session that fitted it.

    Returns
    -------
    pandas.DataFrame
        Columns ``candidate, parameter, scope, unit, sessions, mean, se, between_sd,
        spread, q, p, agree, sun_trend_rho, sun_trend_p, drifts_with_sun`` (empty when
        nothing is fitted twice); ``drifts_with_sun`` is True when the trend's p-value is
        below :data:`AGREEMENT_P`, None when there is no trend to test.
    """
    scope = PARAMETER_SCOPE if scope is None else scope
    if min_share is not None and not 0.0 <= min_share <= 1.0:
        raise InsufficientDataError(f"min_share = {min_share!r}: expected a share within 0-1")
    found: dict = {}
    for name, report in reports.items():
        for c in report.candidates:
            kind = scope.get(c.effect)
            if kind not in ("instrument", "sky") or not c.available or c.not_applicable:
                continue
            if min_share is not None and not (c.explained_share is not None
                                              and c.explained_share >= min_share):
                continue
            for pname, p in c.params.items():
                if _PER_PHOTODIODE.search(pname):
                    continue
                se = _se(p)
                if se is None or p.get("value") is None or not np.isfinite(p["value"]):
                    continue
                found.setdefault((c.effect, pname, kind, p.get("unit", "")), []).append(
                    (name, float(p["value"]), se, _sun_elevation(report)))
    rows = []
    for (effect, pname, kind, unit), got in sorted(found.items()):
        if len(got) < 2:
            continue
        est = combine_sessions([g[1] for g in got], [g[2] for g in got])
        rho, p_trend = sun_trend([g[1] for g in got], [g[3] for g in got])
        rows.append({"candidate": effect, "parameter": pname, "scope": kind, "unit": unit,
                     "sessions": est.n, "mean": est.mean, "se": est.se,
                     "between_sd": est.between_sd, "spread": est.spread, "q": est.q,
                     "p": est.p, "agree": est.agree, "sun_trend_rho": rho,
                     "sun_trend_p": p_trend,
                     "drifts_with_sun": bool(p_trend < AGREEMENT_P) if np.isfinite(p_trend)
                     else None})
    columns = ["candidate", "parameter", "scope", "unit", "sessions", "mean", "se",
               "between_sd", "spread", "q", "p", "agree", "sun_trend_rho", "sun_trend_p",
               "drifts_with_sun"]
    return pd.DataFrame(rows, columns=columns)
