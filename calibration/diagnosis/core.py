"""The method every diagnosis shares, one formula each: folds, noise floor, held-out score,
verdict, shrink with its uncertainty, and the slices that say where the gap lies.

An instrument adapter (:mod:`.protocol`) supplies residuals of its own base model and of each
candidate effect on held-out data; everything that turns them into a verdict is here.

1. **Folds by whole block** (:func:`assign_folds`). Blocks (sweeps, time blocks, sky cases)
   go to folds round-robin in time order; rows of one block never straddle the split, so a
   drift cannot leak from the held-out data into the fit (blocked cross-validation, Roberts
   et al. 2017 [1]_).
2. **Noise floor** (:func:`noise_floor`). The white-noise RMS of residuals from second
   differences of consecutive usable values along each block,
   ``sigma^2 = mean((r_{k+1} - 2 r_k + r_{k-1})^2) / 6`` (von Neumann's successive-difference
   estimator [2]_, second order so that smooth systematic residuals cancel). Excluded
   readings are skipped rather than breaking the sequence, so an instrument that converts a
   unit every few samples still has a floor.
3. **Held-out score** (:func:`held_out_score`). ``N ln(max(G_c, f)^2 / max(G_0, f)^2)
   + (k_c - k_0) ln n_cal``: the Gaussian log-likelihood ratio of the held-out residuals
   (``N`` values, gaps ``G`` as RMS) with the complexity penalty of the Bayesian information
   criterion (Schwarz 1978 [3]_) for the ``k_c - k_0`` parameters a candidate adds to the
   base, ``n_cal`` the values one calibration split fits. Gaps below the noise floor ``f``
   count as the floor: the data cannot rank models that both reach it (e.g. two sky models
   reproducing an exact table to 1e-4), and then the simpler one wins; ties go to the
   smaller held-out gap (:func:`rank`).
4. **Verdict** (:func:`judge`, :func:`decide`). ``none`` when the base gap is within the
   floor, ``G_0 <= f (1 + none_margin)``. Otherwise candidates are compared **paired** on the
   same held-out readings: for candidates ``c`` and ``b`` and every held-out block ``j``
   (sweep, session, frame, case) the difference of their held-out sums of squares
   ``S_cj - S_bj``; their difference of held-out mean squares is
   ``D = sum_j (S_cj - S_bj) / sum_j n_j`` and its standard error is the delete-one-block
   jackknife of that ratio over the independent blocks (:func:`jackknife_ratio`, Efron &
   Tibshirani 1993 [5]_). Pairing removes what the two share (the noise of each reading,
   the base model's misfit), so two candidates that fit alike have a small ``D`` with a
   small SE, where two unpaired gaps with their own SEs would overlap whatever their
   difference. The blocks are the units of independence of the split (the folds hold out
   whole blocks); the jackknife is taken over the held-out scores of fixed fits, an
   approximation of refitting every candidate per left-out block that is tested against
   brute-force resampling of independent blocks (``tests/test_diagnosis_judge.py``), and
   which leaves out the spread of the fits themselves (each block's residuals already come
   from a fit that did not see it). The share of the base model's excess held-out variance
   a candidate removes, ``explained_share = (MS_0 - MS_c) / (MS_0 - f^2)``, carries the
   same jackknife SE (floor held fixed). A single effect is named only when it (a) beats
   the base model, and every other candidate that itself beats the base model within the
   range of its parameters, by more than ``paired_se`` (2) paired SE,
   (b) converged with no parameter at a bound of its range (:func:`at_bound`: a bound hit
   means its form is wrong or its range too narrow), and (c) removes at least
   ``min_share`` (0.5) of the excess. Otherwise the verdict is ``group`` (the candidates
   within 2 paired SE of the best, with what would separate them where they say),
   ``partly_explained`` (the best removes a significant share below ``min_share``) or
   ``unexplained``. Two options of the rule for instruments that need them:
   ``block_consistency`` also requires the candidate to lower the held-out sum of squares in
   at least that fraction of the held-out blocks (:func:`blocks_improved`), and an adapter
   that can tell a fitted effect from its null (the ring's clock offset against its
   uncertainty) withholds a candidate whose effect it cannot (``null_excluded``). A
   candidate whose fit or scoring fails (:func:`run_candidate`) is ``not applicable`` with
   the reason, never the end of the run. Each candidate is fitted on its own, so the verdict
   with a candidate withheld is :func:`decide` on the remaining rows.
5. **Shrink** (:func:`shrink_uncertainty`). ``1 - G_after / G_before`` with standard errors
   from a bootstrap over whole held-out blocks (Künsch 1989 [4]_), resampling blocks with
   their sums of squares so the gaps before and after stay paired.
6. **Where** (:func:`partition_slices`). Each dimension partitions the held-out readings;
   a slice's share is its part of the excess squared gap ``sum(r^2) - n f^2`` of the
   dimension (of ``sum(r^2)`` where no slice exceeds the floor), and it carries the gap when
   its RMS exceeds what white noise at the floor reaches in 99 % of slices of its size,
   ``f (1 + margin) sqrt(chi2_0.99(nu) / nu)`` with ``nu`` the slice's degrees of freedom.

References
----------
.. [1] D. R. Roberts et al., "Cross-validation strategies for data with temporal, spatial,
   hierarchical, or phylogenetic structure", Ecography 40(8):913-929 (2017),
   doi:10.1111/ecog.02881.
.. [2] J. von Neumann, R. H. Kent, H. R. Bellinson, B. I. Hart, "The mean square successive
   difference", Ann. Math. Statist. 12(2):153-162 (1941), doi:10.1214/aoms/1177731746.
.. [3] G. Schwarz, "Estimating the dimension of a model", Ann. Statist. 6(2):461-464 (1978),
   doi:10.1214/aos/1176344136.
.. [4] H. R. Künsch, "The jackknife and the bootstrap for general stationary observations",
   Ann. Statist. 17(3):1217-1241 (1989), doi:10.1214/aos/1176347265.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .errors import InsufficientDataError, ThresholdsError
from .report import Slice, rank, sort_slices
from .shares import partition_shares, slice_limit

__all__ = ["Decision", "Thresholds", "assign_folds", "at_bound", "blocks_improved", "decide",
           "excess_removed", "explained_share", "explains", "held_out_score",
           "jackknife_ratio", "judge", "non_finite_reason", "noise_floor", "not_applicable",
           "paired_difference", "partition_shares", "partition_slices", "rank", "rms",
           "run_candidate", "shrink_uncertainty", "slice_limit", "sort_slices"]


@dataclass(frozen=True)
class Thresholds:
    """Decision margins of the verdict (:func:`decide`) and of the gap-only test
    (:func:`explains`).

    none_margin : the base gap is "within the noise floor" when ``G_0 <= floor (1 + m)``;
        also the margin of the slice limit.
    min_share, paired_se : the paired rule's minimum share of the excess a named effect
        removes, and the paired standard errors by which it beats the others (attributes
        below).
    explained_margin : (:func:`explains`) a candidate brings the gap to the floor when
        ``G_c <= floor (1 + m)``, or when it
        removes all but ``residual_excess`` of the excess variance ``G_0^2 - floor^2``.
        0.07 was chosen on a calibration run of the three-pair benchmark (seed 99, 96 data
        sets, not the benchmark seed): 0.10 let a wrong candidate absorb 8 % of weak gaps
        (1.1-2 x floor) in leave-one-out, 0.07 halves that with no loss of correct verdicts,
        0.05 starts to miss true effects.
    residual_excess : the share of the excess variance a candidate may leave and still
        explain the gap (0.02: all but 2 % removed, i.e. down to the floor).
    block_consistency : a candidate explains the gap only when it also lowers the held-out
        sum of squares in at least this fraction of the held-out blocks (0: not required).
        Needed where ``residual_excess`` is large: an instrument whose gap no single effect
        takes to the floor (a real sky) names a candidate that removes part of it, and a
        part may come from a few blocks alone (one sweep the fit happens to suit); a
        candidate that removes nearly all the excess lowers every block's gap anyway.

    The ring (photodiode) instruments use ``block_consistency=0.75``
    (:data:`calibration.photodiode_diagnosis.run.RING_THRESHOLDS`, with the reason there);
    the three-pair sensor ``min_share=0.9``
    (:data:`calibration.diagnosis.three_pair.DEFAULT_THRESHOLDS`).

    Raises
    ------
    ThresholdsError
        For a negative margin, or a ``residual_excess`` or ``block_consistency`` outside
        [0, 1].
    """

    none_margin: float = 0.10
    explained_margin: float = 0.07
    residual_excess: float = 0.02
    block_consistency: float = 0.0
    block_name: str = "blocks"
    """What a held-out block is called in verdict reasons (the ring's are sweeps)."""
    min_share: float = 0.5
    """Least share of the excess held-out variance over the floor a named effect removes."""
    paired_se: float = 2.0
    """Paired standard errors by which a named effect beats every other candidate and the
    base model (2: a one-sided ~2 % chance that noise alone orders two equal candidates)."""

    def __post_init__(self):
        for name in ("none_margin", "explained_margin"):
            if not getattr(self, name) >= 0:
                raise ThresholdsError(f"Thresholds.{name}={getattr(self, name)!r}: expected "
                                      ">= 0")
        if not self.paired_se >= 0:
            raise ThresholdsError(f"Thresholds.paired_se={self.paired_se!r}: expected >= 0")
        for name in ("residual_excess", "block_consistency", "min_share"):
            if not 0 <= getattr(self, name) <= 1:
                raise ThresholdsError(f"Thresholds.{name}={getattr(self, name)!r}: expected "
                                      "a fraction in [0, 1]")

    def to_dict(self) -> dict:
        return {"none_margin": self.none_margin, "explained_margin": self.explained_margin,
                "residual_excess": self.residual_excess,
                "block_consistency": self.block_consistency, "min_share": self.min_share,
                "paired_se": self.paired_se}


# ------------------------------------------------------------------------------ folds
def assign_folds(block, n_folds: int = 3) -> np.ndarray:
    """Fold of every row: whole blocks, round-robin in block order (time order).

    Parameters
    ----------
    block : array (n,)
        Block (sweep, time block, case) of every row; block ids increase with time.
    n_folds : int
        2 <= n_folds <= number of blocks.

    Raises
    ------
    InsufficientDataError
        With fewer than two blocks, or ``n_folds`` out of range.
    """
    block = np.asarray(block)
    ids = np.unique(block)                          # block ids count in time order
    if ids.size < 2:
        raise InsufficientDataError(
            f"only {ids.size} sweep/time block in the data: a held-out split needs at least 2; "
            "record several sweeps (column 'sweep') or a longer session split into time blocks")
    if isinstance(n_folds, bool) or int(n_folds) != n_folds or not 2 <= n_folds <= ids.size:
        raise InsufficientDataError(
            f"folds={n_folds!r}: need a whole number 2 <= folds <= number of sweeps/time "
            f"blocks ({ids.size}); each fold holds out whole sweeps")
    return np.searchsorted(ids, block) % int(n_folds)


# ------------------------------------------------------------------------------ noise
def noise_floor(residual, usable, block) -> tuple[float, np.ndarray]:
    """White-noise RMS of residuals from second differences along each block.

    Parameters
    ----------
    residual : ndarray (n, m)
        Residuals of ``m`` channels, rows in acquisition order [any unit].
    usable : ndarray (n, m) bool
        Readings to use; the others are skipped (consecutive usable readings of a channel
        are differenced).
    block : array (n,)
        Block of every row; differences never span two blocks.

    Returns
    -------
    pooled : float
        RMS over every channel's second differences [unit of ``residual``].
    per_channel : ndarray (m,)
        The same per channel (NaN for a channel with no three consecutive usable readings).
    """
    r = np.asarray(residual, float)
    if r.ndim == 1:
        r = r[:, None]
    ok = np.asarray(usable, bool).reshape(r.shape) & np.isfinite(r)
    block = np.asarray(block)
    sums, counts = np.zeros(r.shape[1]), np.zeros(r.shape[1], int)
    for c in range(r.shape[1]):      # loop over channels; each channel vectorised
        i = np.flatnonzero(ok[:, c])
        if i.size < 3:
            continue
        x, s = r[i, c], block[i]
        same = (s[2:] == s[1:-1]) & (s[1:-1] == s[:-2])
        d2 = (x[2:] - 2 * x[1:-1] + x[:-2])[same]
        sums[c], counts[c] = float(np.sum(d2 ** 2)), int(same.sum())
    with np.errstate(invalid="ignore", divide="ignore"):
        per_channel = np.sqrt(sums / counts / 6.0)
    pooled = float(np.sqrt(sums.sum() / max(counts.sum(), 1) / 6.0))
    return pooled, per_channel


def rms(residual, usable=None) -> float:
    """RMS of the usable (and finite) residuals [unit of ``residual``]."""
    r = np.asarray(residual, float)
    ok = np.isfinite(r) if usable is None else (np.asarray(usable, bool) & np.isfinite(r))
    return float(np.sqrt(np.sum(np.where(ok, r, 0.0) ** 2) / max(int(ok.sum()), 1)))


# ------------------------------------------------------------------------------ score
def held_out_score(gap: float, gap_base: float, floor: float, n_held_out: int,
                   extra_params: int, n_calibration: int) -> float:
    """``N ln(max(G_c, f)^2 / max(G_0, f)^2) + dk ln n_cal`` (module docstring, step 3).

    Parameters
    ----------
    gap, gap_base : float
        Held-out RMS gaps of the candidate and of the base model [one unit].
    floor : float
        Noise floor [same unit].
    n_held_out : int
        Number of held-out residual values ``N``.
    extra_params : int
        Parameters the candidate adds to the base model (may be 0).
    n_calibration : int
        Values one calibration split fits (>= 2).
    """
    g = max(gap, floor)
    g0 = max(gap_base, floor)
    return float(n_held_out * np.log(g ** 2 / g0 ** 2)
                 + extra_params * np.log(max(n_calibration, 2)))


def excess_removed(gap: float, gap_base: float, floor: float) -> float:
    """Share of the excess held-out variance a candidate removes,
    ``(G_0^2 - G_c^2) / (G_0^2 - f^2)`` (negative when it adds to the gap; the denominator
    is kept above 1e-300 for a base gap at the floor)."""
    return float((gap_base ** 2 - gap ** 2) / max(gap_base ** 2 - floor ** 2, 1e-300))


def blocks_improved(res0, res1, block) -> float:
    """Fraction of the held-out blocks whose residual sum of squares the candidate lowers.

    Parameters
    ----------
    res0, res1 : ndarray (n, ...)
        Held-out residuals of the base and of the candidate (NaN where not used).
    block : array (n,)
        Block of every row.
    """
    (ss0, _), (ss1, _) = _block_sums(res0, block), _block_sums(res1, block)
    return float(np.mean(ss1 < ss0))


def _block_sums(res, block) -> tuple[np.ndarray, np.ndarray]:
    """Per block (in block-id order): sum of squared finite residuals, and their count."""
    ids, idx = np.unique(np.asarray(block), return_inverse=True)
    r = np.asarray(res, float).reshape(len(idx), -1)
    return (np.bincount(idx, np.nansum(r ** 2, axis=1), ids.size),
            np.bincount(idx, np.isfinite(r).sum(axis=1), ids.size))


def explains(gap: float, gap_base: float, floor: float, thresholds: Thresholds, *,
             blocks_improved: float | None = None, null_excluded: bool = True) -> bool:
    """True when a candidate explains the held-out gap (module docstring, step 4); False
    when the base's gap is already at the floor (there is nothing to explain).

    Parameters
    ----------
    gap, gap_base, floor : float
        Held-out gaps of the candidate and of the base, noise floor [one unit].
    thresholds : Thresholds
    blocks_improved : float, optional
        :func:`blocks_improved` of the candidate; required when
        ``thresholds.block_consistency`` is above 0.
    null_excluded : bool
        False when the adapter finds the fitted effect indistinguishable from its null
        (within twice its uncertainty); such a candidate is never named, however it fits.

    Raises
    ------
    ThresholdsError
        For ``thresholds.block_consistency > 0`` without ``blocks_improved``.
    """
    if gap_base <= floor * (1 + thresholds.none_margin):
        return False
    if thresholds.block_consistency > 0:
        if blocks_improved is None:
            raise ThresholdsError("thresholds.block_consistency="
                             f"{thresholds.block_consistency!r} needs the candidate's "
                             "blocks_improved")
        if blocks_improved < thresholds.block_consistency:
            return False
    excess0 = max(gap_base ** 2 - floor ** 2, 0.0)
    return bool(null_excluded and (gap <= floor * (1 + thresholds.explained_margin)
                                   or gap ** 2 - floor ** 2
                                   <= thresholds.residual_excess * excess0))


def decide(candidates, gap_before: float, floor: float,
           thresholds: Thresholds | None = None) -> Decision:
    """Verdict of scored candidates (module docstring, step 4): :class:`Decision`.

    Parameters
    ----------
    candidates : sequence of Candidate
        Scored candidates (any order; unavailable ones are ignored) carrying their paired
        comparison (:func:`judge` fills ``paired_difference`` and its SE against the
        best-ranked candidate, ``explained_share`` and its SE, ``at_bound``, ``converged``).
    gap_before, floor : float
        Base held-out gap and noise floor [the candidates' unit].
    thresholds : Thresholds, optional

    Returns
    -------
    Decision
        ``effect`` is a candidate's name only when it (a) beats the base model and every
        other candidate that improves on it by more than ``thresholds.paired_se`` paired
        standard errors, (b)
        converged with no parameter at a bound, (c) removes at least
        ``thresholds.min_share`` of the excess held-out variance (and meets the instrument's
        options: ``block_consistency``, a null excluded); otherwise ``none``, ``group``,
        ``partly_explained`` or ``unexplained``, with the reason.
    """
    t = thresholds or Thresholds()
    if gap_before <= floor * (1 + t.none_margin):
        return Decision("none", "held-out gap within the noise floor")
    rows = rank([c for c in candidates if c.available])
    if not rows:
        return Decision("unexplained", "no candidate effect was applicable")
    best = rows[0]
    share, share_se = best.explained_share, best.explained_share_se
    share_txt = _share_text(share, share_se)
    k = t.paired_se
    if not _beats_base(best, k) or share is None or share <= 0:
        return Decision("unexplained", (
            f"no candidate lowers the held-out gap by more than {k:g} paired standard errors "
            f"(best: {best.effect}, {best.gap_after:.3g} vs {gap_before:.3g} before, floor "
            f"{floor:.3g}; {share_txt} of the excess removed)"), share=share,
            share_se=share_se)
    # the group: candidates that also improve on the base model, fitted within their
    # ranges, and that the best does not beat by k paired SE (a candidate no better than the
    # base explains nothing, however noisy its comparison with the best; one at a bound of
    # its range has the wrong form for these data, as a ground albedo pressed to 0)
    group = [best.effect] + [c.effect for c in rows[1:]
                             if not _beaten(c, k) and _beats_base(c, k) and not c.at_bound]
    separate = {c.effect: c.details["separated_by"] for c in rows
                if c.effect in group and c.details.get("separated_by")}
    if share < t.min_share:
        return Decision("partly_explained", (
            f"{best.effect} removes {share_txt} of the excess held-out variance over the "
            f"noise floor, less than the {100 * t.min_share:.0f} % needed to name it"
            + (f"; indistinguishable from {', '.join(group[1:])} within {k:g} paired SE"
               if len(group) > 1 else "")), group if len(group) > 1 else [], share,
            share_se, separate)
    if len(group) > 1:
        how = "; ".join(f"{e}: {m}" for e, m in separate.items())
        return Decision("group", (
            f"{', '.join(group)} lower the held-out gap alike: none beats the others by more "
            f"than {k:g} paired standard errors ({best.effect} removes {share_txt} of the "
            "excess)" + (f"; to separate them: {how}" if how else "")), group, share,
            share_se, separate)
    if best.at_bound:
        return Decision("unexplained", (
            f"best candidate {best.effect} removes {share_txt} of the excess but its fitted "
            f"{', '.join(best.at_bound)} sits at a bound of its range: its form is wrong for "
            "these data or its range is too narrow, so it is not named"), share=share,
            share_se=share_se)
    if not best.converged:
        return Decision("unexplained", (
            f"best candidate {best.effect} removes {share_txt} of the excess but its fit did "
            "not converge, so it is not named"), share=share, share_se=share_se)
    if not best.details.get("null_excluded", True):
        return Decision("unexplained", (
            f"best candidate {best.effect} removes {share_txt} of the excess but its fitted "
            "effect is indistinguishable from its null (within twice its uncertainty, or at "
            "the null in every fold)"), share=share, share_se=share_se)
    improved = best.details.get("blocks_improved")
    if t.block_consistency > 0 and (improved is None or improved < t.block_consistency):
        return Decision("unexplained", (
            f"best candidate {best.effect} removes {share_txt} of the excess but lowers the "
            f"gap in fewer than {100 * t.block_consistency:.0f} % of the held-out "
            f"{t.block_name}"), share=share, share_se=share_se)
    return Decision(best.effect, (
        f"{best.effect} beats the base model and every other candidate that improves on it "
        f"by more than {k:g} paired standard errors on the same held-out {t.block_name} and "
        "removes "
        f"{share_txt} of the excess held-out variance over the noise floor (at least "
        f"{100 * t.min_share:.0f} % needed)"), [], share, share_se)


def _beats_base(c, k: float) -> bool:
    """True when candidate row ``c`` beats the base model by more than ``k`` paired SE: its
    paired difference from the base, or the share of the base's excess it removes (the same
    paired sums over the same blocks, jackknifed as a ratio, :func:`explained_share`), is
    above zero by ``k`` of its SEs. Where an effect's size varies from block to block, the
    difference's SE takes in that spread, while the share, removed in proportion to each
    block's excess, does not: a dark current removing 97-100 +- 1 % of the excess on every
    one of six sweeps had a difference of fewer than two SEs."""
    d = c.details.get("base_difference")
    if d is not None and d > k * c.details.get("base_difference_se", np.inf):
        return True
    share, se = c.explained_share, c.explained_share_se
    return (share is not None and se is not None and np.isfinite(se)
            and share - k * se > 0)


def _beaten(c, k: float) -> bool:
    """True when candidate row ``c`` loses to the best by more than ``k`` paired SE."""
    d, se = c.paired_difference, c.paired_difference_se
    return d is not None and se is not None and d > k * se


def _share_text(share, se) -> str:
    if share is None:
        return "no part"
    if se is None or not np.isfinite(se):
        return f"{100 * share:.0f} %"
    return f"{100 * share:.0f} +- {100 * se:.0f} %"


@dataclass(frozen=True)
class Decision:
    """The verdict of :func:`decide`.

    Attributes
    ----------
    effect : str
        A candidate's name, ``none``, ``group``, ``partly_explained`` or ``unexplained``.
    reason : str
    group : list of str
        The candidates the data cannot tell apart (the best first), for ``group`` and, when
        more than one, ``partly_explained``.
    share, share_se : float or None
        The best candidate's ``explained_share`` and its jackknife SE.
    separated_by : dict
        ``effect -> measurement`` that would tell the group's members apart, where a
        candidate states it.
    """

    effect: str
    reason: str
    group: list = field(default_factory=list)
    share: float | None = None
    share_se: float | None = None
    separated_by: dict = field(default_factory=dict)

    def __iter__(self):            # ``effect, reason = decide(...)``
        return iter((self.effect, self.reason))

    def __getitem__(self, i):
        return (self.effect, self.reason)[i]


# ------------------------------------------------------------------------------ paired
def jackknife_ratio(num, den) -> tuple[float, float]:
    """``sum(num) / sum(den)`` over independent blocks, with its delete-one-block jackknife
    standard error (module docstring, step 4).

    Parameters
    ----------
    num, den : array (B,)
        Per-block numerator and denominator sums (``den`` > 0 in total).

    Returns
    -------
    value, se : float
        ``se`` is ``sqrt((B - 1) / B * sum((v_(b) - mean v_(.))^2))`` with ``v_(b)`` the
        ratio with block ``b`` left out (Efron & Tibshirani 1993 [5]_, eq. 11.5); ``inf``
        with fewer than two blocks (no spread to read).
    """
    num, den = np.asarray(num, float), np.asarray(den, float)
    N, D = float(num.sum()), float(den.sum())
    value = N / D if D != 0 else np.nan
    B = num.size
    if B < 2:
        return value, np.inf
    with np.errstate(divide="ignore", invalid="ignore"):
        loo = (N - num) / (D - den)
    loo = loo[np.isfinite(loo)]
    if loo.size < 2:
        return value, np.inf
    return value, float(np.sqrt((loo.size - 1) / loo.size * np.sum((loo - loo.mean()) ** 2)))


def _paired_sums(held: dict, names, block):
    """Per block (in block-id order, blocks without a common reading left out): each name's
    residual sum of squares over the readings every name holds (finite for all), and the
    count of those readings."""
    block = np.asarray(block)
    ids, idx = np.unique(block, return_inverse=True)
    arrs = {n: np.asarray(held[n], float).reshape(len(idx), -1) for n in names}
    common = np.logical_and.reduce([np.isfinite(a) for a in arrs.values()])
    count = np.bincount(idx, common.sum(axis=1), ids.size)
    keep = count > 0                 # a block with no common reading carries no comparison
    ss = {n: np.bincount(idx, np.sum(np.where(common, a, 0.0) ** 2, axis=1), ids.size)[keep]
          for n, a in arrs.items()}
    return ss, count[keep]


def paired_difference(held: dict, name: str, reference: str, block) -> tuple[float, float]:
    """Held-out mean square of ``name`` minus that of ``reference`` on the same readings
    [residual unit^2] (positive: ``reference`` fits the held-out data better), with its
    jackknife SE over the held-out blocks (:func:`jackknife_ratio`)."""
    ss, n = _paired_sums(held, (name, reference), block)
    return jackknife_ratio(ss[name] - ss[reference], n)


def explained_share(held: dict, name: str, base: str, block, floor: float
                    ) -> tuple[float, float]:
    """Share of the base model's excess held-out variance over the noise floor that
    ``name`` removes, ``(MS_0 - MS_c) / (MS_0 - floor^2)`` on the same readings, with its
    jackknife SE over the held-out blocks (the floor held fixed)."""
    ss, n = _paired_sums(held, (name, base), block)
    return jackknife_ratio(ss[base] - ss[name], ss[base] - floor ** 2 * n)


def judge(rows, held: dict, block, floor: float, thresholds: Thresholds | None = None, *,
          base: str = "base", scale: float = 1.0) -> tuple[list, Decision]:
    """Rank the candidates, compare them paired on the held-out readings and decide.

    Parameters
    ----------
    rows : sequence of Candidate
        Scored candidates; each available one has its held-out residuals in ``held``.
    held : dict
        ``name -> ndarray (n, ...)`` held-out residuals of the base model (``base``) and of
        every available candidate (NaN where a reading is not used).
    block : array (n,)
        Held-out block of every row of the residuals.
    floor : float
        Noise floor [report unit].
    thresholds : Thresholds, optional
    base : str
        Key of the base model's residuals.
    scale : float
        Report unit per residual unit (1e3 for residuals in V reported in mV).

    Returns
    -------
    rows : list of Candidate
        Ranked (:func:`rank`), each available one with ``paired_difference`` and its SE
        against the best-ranked (in report unit^2), its ``explained_share`` with SE, and in
        ``details`` ``base_difference`` (base minus candidate) with SE.
    decision : Decision
    """
    t = thresholds or Thresholds()
    rows = rank(list(rows))
    scaled = {k: scale * np.asarray(v, float) for k, v in held.items()}
    block = np.asarray(block)
    used = np.isfinite(scaled[base].reshape(block.size, -1)).any(axis=1)
    single = np.unique(block[used]).size < 2
    if single:
        # one held-out block (a sky field scored on one withheld case): no spread between
        # blocks to read, so the comparison is paired over single readings, assumed
        # independent (white measurement noise about a common systematic misfit)
        block = np.arange(block.size)
    avail = [c for c in rows if c.available]
    gap_before = rms(scaled[base])
    for c in avail:
        c.explained_share, c.explained_share_se = explained_share(scaled, c.effect, base,
                                                                   block, floor)
        d, se = paired_difference(scaled, base, c.effect, block)
        c.details["base_difference"], c.details["base_difference_se"] = d, se
    if avail:
        best = avail[0].effect
        avail[0].paired_difference, avail[0].paired_difference_se = 0.0, 0.0
        for c in avail[1:]:
            c.paired_difference, c.paired_difference_se = paired_difference(
                scaled, c.effect, best, block)
    for c in avail:
        alone = decide([c], gap_before, floor, t)
        c.explained = alone.effect == c.effect
    decision = decide(rows, gap_before, floor, t)
    if single and decision.effect != "none":
        decision = replace(decision, reason=decision.reason + (
            " (one held-out block: paired standard errors over single readings, assumed "
            "independent)"))
    return rows, decision


# ------------------------------------------------------------------------------ failures
def not_applicable(exc: BaseException) -> str:
    """The ``not applicable: <reason>`` of a candidate whose fit or scoring raised ``exc``."""
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else "no message"
    return f"not applicable: {type(exc).__name__}: {msg}"


def run_candidate(fn, *args, **kwargs):
    """``(fn(*args, **kwargs), None)``, or ``(None, reason)`` when it raises.

    One candidate's fit or scoring can fail however the data are (an SVD that does not
    converge, a parameter leaving the model's valid range, an engine error); the failure is
    that candidate's, stated as :func:`not_applicable`, and never ends the diagnosis.
    Exhausted memory and interrupts are not a candidate's failure and propagate.
    """
    try:
        return fn(*args, **kwargs), None
    except (MemoryError, RecursionError):
        raise
    except Exception as exc:       # any failure of this candidate alone
        return None, not_applicable(exc)


def non_finite_reason(residual, reference) -> str | None:
    """``not applicable: ...`` when ``residual`` is not finite where ``reference`` (the base
    model's residuals on the same readings) is; else None."""
    r, ref = np.asarray(residual, float), np.asarray(reference, float)
    bad = np.isfinite(ref) & ~np.isfinite(r.reshape(ref.shape))
    if bad.any():
        return (f"not applicable: non-finite held-out residuals at {int(bad.sum())} of "
                f"{int(np.isfinite(ref).sum())} readings")
    return None


def at_bound(values, lower, upper, names, rel: float = 1e-3, null=None) -> list[str]:
    """Names of the parameters within ``rel`` of the width of their range from a finite
    bound (``rel`` of ``max(1, |bound|)`` for a one-sided range); a bound that is the
    parameter's null (no effect: an extinction ratio of 0) does not count.

    Parameters
    ----------
    values : array (m,) or (folds, m)
        Fitted values (any row at a bound counts).
    lower, upper : array (m,)
        Bounds (``-inf``/``inf`` where open).
    names : sequence of str
    null : array (m,), optional
        Null value of each parameter.
    """
    v = np.atleast_2d(np.asarray(values, float))
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    width = np.where(np.isfinite(lo) & np.isfinite(hi), hi - lo, np.nan)
    tol_lo = rel * np.where(np.isfinite(width), width, np.maximum(1.0, np.abs(lo)))
    tol_hi = rel * np.where(np.isfinite(width), width, np.maximum(1.0, np.abs(hi)))
    if null is not None:
        nul = np.asarray(null, float)
        tol_lo = np.where(np.isclose(lo, nul), -np.inf, tol_lo)
        tol_hi = np.where(np.isclose(hi, nul), -np.inf, tol_hi)
    hit = ((np.isfinite(lo) & (v <= lo + tol_lo)) | (np.isfinite(hi) & (v >= hi - tol_hi)))
    return [str(n) for n, h in zip(names, hit.any(axis=0)) if h]


# ------------------------------------------------------------------------------ shrink
def shrink_uncertainty(res0, res1, block, rng: np.random.Generator,
                       n_boot: int = 200) -> dict | None:
    """Bootstrap standard errors of the gaps and the shrink over whole held-out blocks.

    Parameters
    ----------
    res0, res1 : ndarray (n, ...)
        Held-out residuals of the base and of the candidate (NaN where not used).
    block : array (n,)
    rng : numpy.random.Generator
    n_boot : int

    Returns
    -------
    dict or None
        ``gap_before_se``, ``gap_after_se``, ``shrink_se`` [gap unit; shrink unitless];
        None with fewer than two blocks (no spread to resample).
    """
    n_blocks = np.unique(np.asarray(block)).size
    if n_blocks < 2:
        return None
    (ss0, cnt), (ss1, _) = _block_sums(res0, block), _block_sums(res1, block)
    pick = rng.integers(0, n_blocks, (n_boot, n_blocks))
    g0 = np.sqrt(ss0[pick].sum(1) / cnt[pick].sum(1))
    g1 = np.sqrt(ss1[pick].sum(1) / cnt[pick].sum(1))
    return {"gap_before_se": float(np.std(g0)), "gap_after_se": float(np.std(g1)),
            "shrink_se": float(np.std(1 - g1 / g0))}


# ------------------------------------------------------------------------------ where
def partition_slices(dimension: str, masks, labels, r2, floor: float, margin: float, *,
                     dof_per_value: int = 1, bounds=None, bound_unit: str | None = None
                     ) -> list[Slice]:
    """Slices of one dimension (a partition of the held-out values) with their shares.

    Parameters
    ----------
    dimension : str
        Name of the dimension (``channel``, ``sweep``, ``sun_distance_deg``, ...).
    masks : sequence of bool arrays
        One per slice, over the values of ``r2``.
    labels : sequence of str
    r2 : ndarray
        Squared held-out residual per value [unit^2]; NaN where not used.
    floor : float
        Noise floor: the RMS of one value's residual for white noise [unit].
    margin : float
    dof_per_value : int
        Degrees of freedom one value of ``r2`` carries (2 for ``|(dq, du)|^2``).
    bounds : sequence of (lo, hi), optional
        Interval of each slice in ``bound_unit``.

    Returns
    -------
    list of Slice
        Slices holding at least one value, in the given order.
    """
    r2 = np.asarray(r2, float)
    ok = np.isfinite(r2)
    rows = []
    for k, (mask, label) in enumerate(zip(masks, labels)):
        m = np.asarray(mask, bool) & ok
        n = int(m.sum())
        if n:
            lo, hi = (None, None) if bounds is None else map(float, bounds[k])
            rows.append((str(label), n, float(np.sqrt(r2[m].sum() / n)), lo, hi))
    shares = partition_shares([r[1] for r in rows], [r[2] for r in rows], floor)
    out = []
    for (label, n, r, lo, hi), share in zip(rows, shares):
        limit = float(slice_limit(floor, n * dof_per_value, margin))
        out.append(Slice(dimension, label, n, r, float(share), lo, hi,
                         None if lo is None else bound_unit, bool(r > limit), limit))
    return out
