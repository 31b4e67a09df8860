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
   unit every few samples still has a floor. That estimate holds for white noise only:
   smoothed or pre-filtered readings have second differences far smaller than their noise
   (a 5-point moving average: 0.36 of its RMS). :func:`whiteness` tests it from the
   autocorrelation of the second differences (-2/3 at lag 1 for white noise); where it
   fails, an adapter measures the noise from repeated standing readings
   (:func:`standing_noise`) or reports the floor unknown, and the verdict then measures
   the excess against a zero floor (the whole gap), which never reads ``none``.
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
   means its form is wrong or its range too narrow) and, where it nests a model other than
   the base (its own parameters at their null values: a ground albedo of 0 is the
   black-ground multiple-scattering sky), beats that null model on the same held-out
   readings by more than ``paired_se`` paired SE, as it must beat the base, and (c) removes
   at least ``min_share`` (0.5) of the excess. The nested null is compared on held-out data,
   not by the fitted parameter's distance from its null value in SEs of the fit: that
   distance is read from the readings that fitted it, and noise drew a ground albedo 3.1 SE
   from black on one sky in 16 that held-out data put 4.6 paired SE behind its null.
   Otherwise the verdict is ``group`` (the candidates within 2 paired SE of the best, with
   what would separate them where they say),
   ``partly_explained`` (the best removes a significant share below ``min_share``) or
   ``unexplained``. Where an instrument's identifiability matrix shows that the data can
   make one candidate stand in for another (simulated with the one, diagnosed without it,
   the other was named), :attr:`Thresholds.confusable` lists the pair, and a candidate is
   named alone only when each candidate it can be mistaken for was tried (among the
   candidates and applicable) and lost (beaten by more than 2 paired SE, or no better than
   the base model): a verdict cannot rule out an effect it did not try, and an effect that
   was tried and not beaten is as good an explanation. Otherwise the verdict is a ``group``
   of the best and those confusers, and a confuser left so joins the list of every
   ``group`` or ``partly_explained`` verdict. Two options of the rule for instruments that
   need them:
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
.. [5] B. Efron, R. J. Tibshirani, *An Introduction to the Bootstrap*, Chapman & Hall
   (1993), ch. 11.
.. [6] G. E. P. Box, G. M. Jenkins, G. C. Reinsel, *Time Series Analysis: Forecasting and
   Control*, 4th ed., Wiley (2008), sect. 2.1.6 (Bartlett's formula, eq. 2.1.13).
.. [7] B. Efron, C. Stein, "The jackknife estimate of variance", Ann. Stat. 9(3):586-596
   (1981), doi:10.1214/aos/1176345462.
.. [8] J. Shao, D. Tu, *The Jackknife and Bootstrap*, Springer (1995), sect. 2.1
   (jackknife t-statistics with ``n - 1`` degrees of freedom).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from .errors import InsufficientDataError, ThresholdsError
from .report import Slice, rank, sort_slices
from .shares import partition_shares, slice_limit

__all__ = ["Decision", "Thresholds", "assign_folds", "at_bound", "blocks_improved", "decide",
           "excess_removed", "explained_share", "explains", "held_out_score",
           "jackknife_ratio", "judge", "non_finite_reason", "noise_floor", "not_applicable",
           "paired_difference", "paired_margin", "partition_shares", "partition_slices", "rank", "rms",
           "run_candidate", "shrink_uncertainty", "slice_limit", "sort_slices",
           "standing_noise", "Whiteness", "whiteness", "Floor", "checked_floor",
           "bartlett_lag1", "difference_acf"]


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

    confusable : mapping ``name -> tuple of names``
        Per candidate, the candidates the instrument's identifiability matrix showed it can
        be mistaken for (``{"aureole": ("stray_light",)}``: with the stray light withheld,
        a stray-light sky was named ``aureole``). A candidate is then named alone only when
        each of these was tried and lost (:func:`decide`). Given as any mapping (or as
        ``(name, names)`` pairs); kept as sorted ``(name, tuple of names)`` pairs so that the
        thresholds stay frozen and hashable (:meth:`confusers` reads it). Default: none.

    The ring (photodiode) instruments use ``block_consistency=0.75`` and a confusable table
    of the aureole and the stray light, the side glare that holds the stray light, and the
    field of view and the neutral-point sky
    (:data:`calibration.photodiode_diagnosis.run.RING_THRESHOLDS`, with the reason there);
    the three-pair sensor ``min_share=0.9``
    (:data:`calibration.diagnosis.three_pair.DEFAULT_THRESHOLDS`). The sky field needs no
    table: its ground albedo, once taken for a multiple-scattering sky withheld, nests that
    sky and must beat it on held-out data (:data:`calibration.diagnosis.sky.NULL_MODELS`).

    Raises
    ------
    ThresholdsError
        For a negative margin, a ``residual_excess`` or ``block_consistency`` outside
        [0, 1], or a ``confusable`` that is not a mapping of candidate names to tuples of
        other candidate names.
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
    confusable: tuple = ()
    """``((name, (other, ...)), ...)``: the candidates each can be mistaken for (above)."""

    def __post_init__(self):
        object.__setattr__(self, "confusable", _frozen_confusable(self.confusable))
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

    def confusers(self, name: str) -> tuple[str, ...]:
        """The candidates ``name`` can be mistaken for (empty when none is listed)."""
        return dict(self.confusable).get(name, ())

    def for_blocks(self, n_blocks: int) -> Thresholds:
        """These thresholds with ``paired_se`` applied as Student's t for ``n_blocks``
        held-out blocks (:func:`paired_margin`): what the verdict applies and the report
        shows."""
        return replace(self, paired_se=paired_margin(self.paired_se, n_blocks))

    def to_dict(self) -> dict:
        return {"none_margin": self.none_margin, "explained_margin": self.explained_margin,
                "residual_excess": self.residual_excess,
                "block_consistency": self.block_consistency, "min_share": self.min_share,
                "paired_se": self.paired_se,
                "confusable": {name: list(others) for name, others in self.confusable}}


def _frozen_confusable(value) -> tuple:
    """``value`` (a mapping ``name -> names``, or ``(name, names)`` pairs) as sorted
    ``(name, tuple of names)`` pairs, names without repeats; :class:`ThresholdsError`
    naming the offending entry otherwise."""
    if isinstance(value, Mapping):
        pairs = list(value.items())
    else:
        try:
            pairs = [tuple(p) for p in value]
        except TypeError:
            pairs = None
        if (isinstance(value, (str, bytes)) or pairs is None
                or any(len(p) != 2 for p in pairs)):
            raise ThresholdsError(f"Thresholds.confusable={value!r}: expected a mapping "
                                  "of candidate name -> tuple of candidate names")
    out = {}
    for name, others in pairs:
        if not isinstance(name, str) or not name:
            raise ThresholdsError(f"Thresholds.confusable key {name!r}: expected a "
                                  "candidate name (a non-empty string)")
        if isinstance(others, (str, bytes)) or not isinstance(others, Iterable):
            raise ThresholdsError(f"Thresholds.confusable[{name!r}]={others!r}: expected a "
                                  "tuple of candidate names (one name is ('name',))")
        others = tuple(dict.fromkeys(others))
        for o in others:
            if not isinstance(o, str) or not o or o == name:
                raise ThresholdsError(
                    f"Thresholds.confusable[{name!r}] lists {o!r}: expected the name of "
                    f"another candidate than {name!r}")
        if name in out:
            raise ThresholdsError(f"Thresholds.confusable lists {name!r} twice")
        if others:
            out[name] = others
    return tuple(sorted(out.items()))


def paired_margin(paired_se: float, n_blocks: int) -> float:
    """The paired-SE margin applied with ``n_blocks`` held-out blocks.

    The paired differences' standard errors are jackknifed over the held-out blocks
    (:func:`paired_difference`), so each is itself estimated with ``n_blocks - 1`` degrees
    of freedom and a difference over its SE follows Student's t, not the normal law (Efron &
    Stein 1981 [7]_; Shao & Tu 1995 [8]_ sect. 2.1). ``paired_se`` (normal SEs, one-sided) is
    converted to the t quantile at the same level: 2 SE (97.7 %) is 2.65 with six blocks,
    2.25 with twelve, 2 in the limit.

    Parameters
    ----------
    paired_se : float
        Margin in normal standard errors (:attr:`Thresholds.paired_se`).
    n_blocks : int
        Held-out blocks (the jackknife's).

    Returns
    -------
    float
        The margin in jackknife standard errors, to 0.01 (``paired_se`` itself with fewer
        than two blocks, where the judge compares single readings).
    """
    from scipy.stats import norm, t
    if n_blocks < 2 or paired_se <= 0:
        return float(paired_se)
    # to 0.01, as the verdict's reason prints it
    return round(float(t.ppf(norm.cdf(paired_se), n_blocks - 1)), 2)


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


WHITE_LAG1 = -2.0 / 3.0
"""Lag-1 autocorrelation of the second differences of white noise (:func:`whiteness`)."""

WHITE_LAG2 = 1.0 / 6.0
"""Lag-2 autocorrelation of the second differences of white noise (:func:`whiteness`)."""

WHITE_LAG1_FOURTH = -4.0 / 5.0
"""Lag-1 autocorrelation of the fourth differences of white noise (:func:`whiteness`)."""

WHITENESS_ALPHA = 1e-3
"""False-alarm probability of each of the two tests of the whiteness rule on white noise
(:func:`whiteness`)."""

WHITENESS_MIN_SHIFT = 0.05
"""Least rise of the second differences' lag-1 autocorrelation above -2/3 that counts as not
white (:func:`whiteness`): a rise this small biases a filtered floor by a few per cent only."""

WHITENESS_MIN_SHIFT_FOURTH = 0.025
"""Least departure of the fourth differences' lag-1 autocorrelation from -4/5 that counts
(:func:`whiteness`): half the least a moving average gives (0.05)."""


def difference_acf(k: int, lag: int) -> float:
    """Lag-``lag`` autocorrelation of the ``k``-th differences of white noise,
    ``(-1)^lag C(2k, k + lag) / C(2k, k)`` (0 beyond lag ``k``)."""
    from math import comb
    lag = abs(int(lag))
    return 0.0 if lag > k else (-1) ** lag * comb(2 * k, k + lag) / comb(2 * k, k)


def bartlett_lag1(k: int) -> float:
    """``N var(rho_1)`` of the lag-1 autocorrelation estimated over ``N`` pairs of ``k``-th
    differences of white noise (Bartlett's formula [6]_, eq. 2.1.13, with the exact
    autocorrelations of :func:`difference_acf`): 49/162 for ``k = 2``, 0.1518 for 4."""
    r = [difference_acf(k, j) for j in range(-2 * k - 3, 2 * k + 5)]
    rho = dict(zip(range(-2 * k - 3, 2 * k + 5), r))
    r1 = rho[1]
    return float(sum(rho[j] ** 2 + rho[j + 1] * rho[j - 1] - 4 * r1 * rho[j] * rho[j - 1]
                     + 2 * rho[j] ** 2 * r1 ** 2 for j in range(-2 * k - 2, 2 * k + 4)))


@dataclass(frozen=True)
class Whiteness:
    """Autocorrelation of the second (and fourth) differences of residuals, pooled over
    channels and blocks (:func:`whiteness`).

    Attributes
    ----------
    lag1, lag2 : float
        Pooled autocorrelations of the second differences (-2/3 and +1/6 for white noise);
        NaN without pairs.
    lag1_se, lag2_se : float
        Delete-one-block jackknife SE over the blocks (inf with fewer than two).
    lag1_se_white : float
        SE of ``lag1`` for white noise, ``sqrt(49 / 162 / n_pairs)``.
    n_pairs : int
        Pairs of consecutive second differences pooled for ``lag1``.
    z : float
        ``(lag1 + 2/3) / lag1_se_white``.
    lag1_fourth, z_fourth : float
        Lag-1 autocorrelation of the fourth differences (-4/5 for white noise) and its
        departure in white-noise SE.
    white : bool
        False when the residuals are not white (the rule of :func:`whiteness`).
    """

    lag1: float
    lag1_se: float
    lag2: float
    lag2_se: float
    lag1_se_white: float
    n_pairs: int
    z: float
    lag1_fourth: float
    z_fourth: float
    white: bool

    def to_dict(self) -> dict:
        def num(x):
            return float(x) if np.isfinite(x) else None
        return {"lag1": num(self.lag1), "lag1_se": num(self.lag1_se),
                "lag2": num(self.lag2), "lag2_se": num(self.lag2_se),
                "lag1_white_noise": WHITE_LAG1, "lag2_white_noise": WHITE_LAG2,
                "lag1_se_white": num(self.lag1_se_white), "n_pairs": int(self.n_pairs),
                "z": num(self.z), "lag1_fourth_differences": num(self.lag1_fourth),
                "lag1_fourth_white_noise": WHITE_LAG1_FOURTH,
                "z_fourth_differences": num(self.z_fourth), "white": bool(self.white)}


def _differences(residual, usable, block, k: int):
    """Per channel: ``k``-th differences of consecutive usable values, whether their
    ``k + 1`` values lie in one block, and the block of each."""
    r = np.asarray(residual, float)
    if r.ndim == 1:
        r = r[:, None]
    r = r.reshape(r.shape[0], -1)
    ok = np.asarray(usable, bool).reshape(r.shape) & np.isfinite(r)
    block = np.asarray(block)
    for c in range(r.shape[1]):
        i = np.flatnonzero(ok[:, c])
        if i.size < k + 1:
            continue
        x, s = r[i, c], block[i]
        same = np.ones(i.size - k, bool)
        for j in range(1, k + 1):
            same &= s[j:i.size - k + j] == s[:i.size - k]
        yield np.diff(x, k), same, s[:i.size - k]


def _pooled_acf(residual, usable, block, k: int, lags) -> dict:
    """``lag -> (per-block numerators, denominators)`` of the pooled autocorrelation of the
    ``k``-th differences, ``sum d_j d_{j+L} / sum (d_j^2 + d_{j+L}^2) / 2`` over pairs within
    one block; and the number of lag-1 pairs."""
    ids = np.unique(np.asarray(block))
    sums = {L: (np.zeros(ids.size), np.zeros(ids.size)) for L in lags}
    n_pairs = 0
    for d, same, s in _differences(residual, usable, block, k):
        where = np.searchsorted(ids, s)
        for L, (num, den) in sums.items():
            pair = same[L:] & same[:-L]
            a, b = d[:-L][pair], d[L:][pair]
            num += np.bincount(where[:-L][pair], a * b, ids.size)
            den += np.bincount(where[:-L][pair], (a * a + b * b) / 2, ids.size)
            if L == 1:
                n_pairs += int(pair.sum())
    return sums, n_pairs


def whiteness(residual, usable, block, *, alpha: float = WHITENESS_ALPHA,
              min_shift: float = WHITENESS_MIN_SHIFT,
              min_shift_fourth: float = WHITENESS_MIN_SHIFT_FOURTH) -> Whiteness:
    """Whether residuals are white along each block: the autocorrelation of their second
    differences, with the fourth differences to tell a filter from a smooth misfit.

    For white noise ``e_k`` of variance ``sigma^2`` the second difference
    ``d_k = e_{k+1} - 2 e_k + e_{k-1}`` has the filter ``(1, -2, 1)``, so
    ``var d = (1 + 4 + 1) sigma^2 = 6 sigma^2`` (the floor of :func:`noise_floor`),
    ``cov(d_k, d_{k+1}) = (1)(-2) + (-2)(1) = -4 sigma^2`` and
    ``cov(d_k, d_{k+2}) = (1)(1) = sigma^2``: the lag-1 autocorrelation is exactly
    ``-4/6 = -2/3``, the lag-2 ``1/6``, and all further ones 0, whatever ``sigma``
    (generally, ``k``-th differences: :func:`difference_acf`). Low-pass filtering raises
    lag 1: a moving average of ``w >= 3`` points gives ``d`` the filter
    ``(1, -1, 0, ..., 0, -1, 1) / w`` and a lag-1 autocorrelation of ``-1/2``; a two-point
    average ``-1/4``; heavier smoothing (a Butterworth well below Nyquist) towards ``+1``.

    A model misfit that changes along the record also raises it, when its second
    differences outweigh the noise's (a base model 80 times the noise from the data: lag 1
    near +0.7). Differencing twice more cancels a misfit that is smooth over a few readings:
    the fourth differences (filter ``(1, -4, 6, -4, 1)``) of white noise have lag-1
    autocorrelation ``-16/20 = -4/5``; a moving average of ``w >= 5`` points gives them
    ``-3/4`` (two copies of the third differences' filter), of 4 points ``-0.725``, of 3
    ``-6/7``, of 2 about ``-1/2``. So the readings are called not white only when both move.

    Estimates, pooled over channels and blocks on the pairs ``(d_k, d_{k+L})`` whose values
    all lie in one block, ``rho_L = sum d_k d_{k+L} / sum (d_k^2 + d_{k+L}^2) / 2`` (zero
    mean: differences of residuals have none to speak of), with the delete-one-block
    jackknife SE (:func:`jackknife_ratio`). Under white noise, Bartlett's formula
    (Box, Jenkins & Reinsel 2008 [6]_, eq. 2.1.13) gives ``N var(rho_1) = 49/162`` over
    ``N`` pairs of second differences and 0.1518 for fourth ones (:func:`bartlett_lag1`;
    checked by simulation in the tests).

    **Rule.** Not white when (a) ``z = (rho_1 + 2/3) / sqrt(49 / 162 / N)`` exceeds the
    one-sided normal quantile at ``1 - alpha`` and ``rho_1 + 2/3 > min_shift``, and (b) the
    fourth differences' lag 1 departs from -4/5 by more than the two-sided quantile at
    ``1 - alpha / 2`` of its white-noise SE and by more than ``min_shift_fourth``. Each of
    (a) and (b) fires on white noise with probability ``alpha`` (0.1 %); ``min_shift``
    keeps a large session's statistical power from calling a misfit of a few per cent of
    the variance non-white. Measured in ``tests/test_noise_whiteness.py``: on white noise of
    3-8 blocks of 10-130 samples and 1-32 channels the rule fired in 0-3 of 3,000
    sessions each (at most 0.1 %; the second-difference test alone in up to 0.33 %, its
    estimate skewed on a single short channel); a 3-, 5- or 9-point moving average is caught in every session of 3
    blocks of 90 samples and 32 channels (a ring); with one channel of 3 x 300 samples in
    86, 60 and 63 % (fourth differences need many pairs to see a 0.05 shift).

    Parameters
    ----------
    residual : ndarray (n, ...)
        Residuals, rows in acquisition order [any unit].
    usable : ndarray bool, shape of ``residual``
        Values to use; the others are skipped (as :func:`noise_floor`).
    block : array (n,)
        Block of every row; differences never span two blocks.
    alpha : float
        False-alarm probability of each test, in (0, 0.5).
    min_shift, min_shift_fourth : float
        Least departures that count (>= 0).

    Returns
    -------
    Whiteness
        ``white`` is True without enough pairs to tell (fewer than 10).

    Raises
    ------
    ThresholdsError
        For ``alpha`` outside (0, 0.5) or a negative ``min_shift``.
    """
    if not 0 < alpha < 0.5:
        raise ThresholdsError(f"alpha={alpha!r}: expected a probability in (0, 0.5)")
    for name, v in (("min_shift", min_shift), ("min_shift_fourth", min_shift_fourth)):
        if not v >= 0:
            raise ThresholdsError(f"{name}={v!r}: expected >= 0")
    sums, n_pairs = _pooled_acf(residual, usable, block, 2, (1, 2))
    if n_pairs < 10:
        return Whiteness(np.nan, np.inf, np.nan, np.inf, np.inf, n_pairs, np.nan, np.nan,
                         np.nan, True)

    def ratio(num, den):
        keep = den > 0
        return jackknife_ratio(num[keep], den[keep]) if keep.any() else (np.nan, np.inf)
    lag1, se1 = ratio(*sums[1])
    lag2, se2 = ratio(*sums[2])
    se_white = float(np.sqrt(bartlett_lag1(2) / n_pairs))
    z = (lag1 - WHITE_LAG1) / se_white
    from scipy.stats import norm
    second = bool(z > norm.ppf(1 - alpha) and lag1 - WHITE_LAG1 > min_shift)
    s4, n4 = _pooled_acf(residual, usable, block, 4, (1,))
    lag4 = ratio(*s4[1])[0] if n4 else np.nan
    z4 = ((lag4 - WHITE_LAG1_FOURTH) / np.sqrt(bartlett_lag1(4) / n4) if n4 else np.nan)
    fourth = bool(np.isfinite(z4) and abs(z4) > norm.ppf(1 - alpha / 2)
                  and abs(lag4 - WHITE_LAG1_FOURTH) > min_shift_fourth)
    return Whiteness(float(lag1), float(se1), float(lag2), float(se2), se_white, n_pairs,
                     float(z), float(lag4), float(z4), not (second and fourth))


def standing_noise(residual, usable, stretch, *, min_length: int = 5) -> tuple[float, int]:
    """Noise RMS from the scatter of repeated standing readings about each stretch's mean.

    A *stretch* is a run of readings taken at one attitude (the instrument standing). The
    residuals are those of a model that already follows the sky's slow drift with time, so
    within a stretch what the model misses is one constant (its misfit at that attitude)
    and the scatter about the stretch's mean is the noise:
    ``sigma^2 = sum (r - mean_s)^2 / sum (n_s - 1)`` over the stretches and channels with at
    least ``min_length`` usable values. It needs no whiteness: smoothing along the record
    shrinks the scatter only by the correlation within a stretch. For a 5-point moving
    average it reads 0.80 of the noise RMS over 10-reading stretches and 0.95 over 40
    (``(n / (n - 1)) (gamma_0 - var(mean)) / gamma_0`` with the moving average's
    autocovariance; measured in the tests), against 0.36 from second differences.

    Parameters
    ----------
    residual : ndarray (n, ...)
        Residuals, rows in acquisition order [any unit].
    usable : ndarray bool, shape of ``residual``
    stretch : array (n,) of int
        Stretch of every row (one id for one run of standing readings at one attitude),
        negative for rows not standing.
    min_length : int
        Fewest usable values of a stretch and channel to enter (>= 2).

    Returns
    -------
    rms : float
        NaN without any stretch long enough [unit of ``residual``].
    dof : int
        Degrees of freedom of the estimate.
    """
    r = np.asarray(residual, float)
    r = r.reshape(r.shape[0], -1)
    stretch = np.asarray(stretch)
    ok = (np.asarray(usable, bool).reshape(r.shape) & np.isfinite(r)
          & (stretch >= 0)[:, None])
    _, idx = np.unique(stretch, return_inverse=True)
    size = int(idx.max(initial=-1) + 1) * r.shape[1]
    group = (idx[:, None] * r.shape[1] + np.arange(r.shape[1])[None, :])[ok]
    y = r[ok]
    n = np.bincount(group, minlength=size).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.bincount(group, y, size) / n
    ss = np.bincount(group, (y - mean[group]) ** 2, size)
    use = n >= max(int(min_length), 2)
    dof = int(np.sum(n[use] - 1))
    if dof <= 0:
        return float("nan"), 0
    return float(np.sqrt(float(np.sum(ss[use])) / dof)), dof


STANDING_MIN_DOF = 30
"""Fewest degrees of freedom of a standing-readings noise estimate (:func:`checked_floor`):
its relative SE ``1 / sqrt(2 dof)`` is then 13 % or less."""

STANDING_METHOD = ("the residuals are not white along each {block} (lag-1 autocorrelation "
                   "of their second differences {lag1:.3f} +- {se:.3f}, -2/3 for white "
                   "noise), so second differences do not measure the noise; measured instead "
                   "from the scatter of repeated standing readings about each standing "
                   "stretch's mean ({dof} degrees of freedom)")
"""Method text of a floor measured from standing readings (:func:`checked_floor`)."""

UNKNOWN_METHOD = ("unknown: the residuals are not white along each {block} (lag-1 "
                  "autocorrelation of their second differences {lag1:.3f} +- {se:.3f}, -2/3 "
                  "for white noise: smoothed or pre-filtered readings, or a misfit that "
                  "changes from one reading to the next), so second differences do not "
                  "measure the noise, and the data hold no repeated standing readings to "
                  "measure it from")
"""Method text of a floor that cannot be measured (:func:`checked_floor`)."""

FLOOR_UNKNOWN_NOTE = ("noise floor unknown (residuals not white, no standing readings): every "
                      "share is of the whole held-out gap and the gap is never read as within "
                      "the noise")
"""What a verdict reason says first when the floor is unknown (:func:`judge`)."""


@dataclass(frozen=True)
class Floor:
    """A noise floor checked for whiteness (:func:`checked_floor`).

    Attributes
    ----------
    rms : float or None
        The floor [residual unit]; None when unknown.
    method : str
        How it was measured, or why it is unknown.
    white_rms : float
        The second-difference estimate (:func:`noise_floor`), whatever the check.
    whiteness : Whiteness
    standing_dof : int
        Degrees of freedom of a standing-readings estimate (0: not used).
    """

    rms: float | None
    method: str
    white_rms: float
    whiteness: Whiteness
    standing_dof: int = 0

    @property
    def value(self) -> float:
        """The floor the verdict measures against: 0 when unknown (the whole gap)."""
        return 0.0 if self.rms is None else float(self.rms)

    @property
    def note(self) -> str | None:
        """:data:`FLOOR_UNKNOWN_NOTE` when the floor is unknown, else None."""
        return FLOOR_UNKNOWN_NOTE if self.rms is None else None

    def parts(self) -> dict:
        """Its parts for a report: the second-difference RMS, the whiteness check and the
        standing estimate's degrees of freedom where used."""
        out = {"white_noise_rms": float(self.white_rms),
               "whiteness": self.whiteness.to_dict()}
        if self.standing_dof:
            out["standing_rms"] = float(self.rms)
            out["standing_dof"] = int(self.standing_dof)
        return out


def checked_floor(residual, usable, block, white_method: str, stretch=None, *,
                  block_name: str = "block", min_dof: int = STANDING_MIN_DOF,
                  tested=None) -> Floor:
    """The noise floor of residuals, from second differences where they are white
    (:func:`noise_floor`, :func:`whiteness`), else from repeated standing readings
    (:func:`standing_noise`, when ``stretch`` gives at least ``min_dof`` degrees of
    freedom), else unknown.

    Parameters
    ----------
    residual, usable, block
        As :func:`noise_floor`.
    white_method : str
        The method text of the second-difference floor.
    stretch : array (n,) of int, optional
        Standing stretch of every row (negative: not standing), :func:`standing_noise`.
    block_name : str
        What a block is called in the method text (``sweep``, ``row of super-pixels``).
    min_dof : int
        Fewest degrees of freedom of a standing estimate.
    tested : ndarray, optional
        Residuals whose whiteness is tested, same shape (default ``residual``): those of the
        model that fits the held-out data best. A base model far from the data (a gyro
        scale error 80 times the noise) leaves a misfit whose second differences outweigh
        the noise's, smooth (lag 1 near +0.7) though the readings are not; tested on the
        residuals of the model that takes it up, the noise shows white again.

    Returns
    -------
    Floor
    """
    white_rms, _ = noise_floor(residual, usable, block)
    check = whiteness(residual if tested is None else tested, usable, block)
    if check.white:
        return Floor(white_rms, white_method, white_rms, check)
    words = dict(block=block_name, lag1=check.lag1, se=check.lag1_se_white)
    if stretch is not None:
        rms_s, dof = standing_noise(residual, usable, stretch)
        if dof >= min_dof:
            return Floor(rms_s, STANDING_METHOD.format(dof=dof, **words), white_rms, check,
                         dof)
    return Floor(None, UNKNOWN_METHOD.format(**words), white_rms, check)


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
    """Fraction of the held-out blocks whose residual sum of squares the candidate lowers
    (blocks with no used reading, such as calibration-only blocks, are not counted).

    Parameters
    ----------
    res0, res1 : ndarray (n, ...)
        Held-out residuals of the base and of the candidate (NaN where not used).
    block : array (n,)
        Block of every row.
    """
    (ss0, n0), (ss1, _) = _block_sums(res0, block), _block_sums(res1, block)
    held = n0 > 0
    return float(np.mean(ss1[held] < ss0[held])) if held.any() else float("nan")


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
        converged with no parameter at a bound and, where it nests a model other than the
        base (``details["null_model"]``), beats that null by more than ``paired_se`` paired
        SE on the held-out readings, (c) removes at least
        ``thresholds.min_share`` of the excess held-out variance (and meets the instrument's
        options: ``block_consistency``, a null excluded) and (d) every candidate
        ``thresholds.confusable`` lists for it was tried and lost: it is among
        ``candidates``, applicable, and beaten by more than ``paired_se`` paired SE or no
        better than the base model by that margin. Otherwise ``none``, ``group``,
        ``partly_explained`` or ``unexplained``, with the reason. A confuser that fails (d)
        joins the candidates a ``group`` or ``partly_explained`` verdict lists, whichever
        path it takes, and the reason says which one was not tried, not applicable or not
        beaten.
    """
    t = thresholds or Thresholds()
    if gap_before <= floor * (1 + t.none_margin):
        return Decision("none", "held-out gap within the noise floor")
    candidates = list(candidates)
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
    # the candidates the identifiability matrix showed the listed ones can be mistaken for,
    # where they were not tried here or not beaten: they join the list (the data did not
    # rule them out), in every verdict that lists candidates
    untold = _untold_confusers(group, candidates, k, t)
    listed = group + [e for e, _, _ in untold]
    confused = "".join(
        f"; the instrument's identifiability matrix shows that {of} can be mistaken for {e}, "
        f"which {why}" for e, of, why in untold)
    separate = {c.effect: c.details["separated_by"] for c in rows
                if c.effect in listed and c.details.get("separated_by")}
    how = "; ".join(f"{e}: {m}" for e, m in separate.items())
    if share < t.min_share:
        return Decision("partly_explained", (
            f"{best.effect} removes {share_txt} of the excess held-out variance over the "
            f"noise floor, less than the {100 * t.min_share:.0f} % needed to name it"
            + (f"; indistinguishable from {', '.join(group[1:])} within {k:g} paired SE"
               if len(group) > 1 else "") + confused), listed if len(listed) > 1 else [],
            share, share_se, separate)
    if len(group) > 1:
        return Decision("group", (
            f"{', '.join(group)} lower the held-out gap alike: none beats the others by more "
            f"than {k:g} paired standard errors ({best.effect} removes {share_txt} of the "
            "excess)" + confused + (f"; to separate them: {how}" if how else "")), listed,
            share, share_se, separate)
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
    if not _beats_null(best, k):
        return Decision("unexplained", (
            f"best candidate {best.effect} removes {share_txt} of the excess but does not "
            f"beat the model it nests, {best.details['null_model']}, on the same held-out "
            f"{t.block_name} by more than {k:g} paired standard errors ({_null_text(best)}): "
            f"what makes it {best.effect} is not seen in data it was not fitted on"),
            share=share, share_se=share_se)
    improved = best.details.get("blocks_improved")
    if t.block_consistency > 0 and (improved is None or improved < t.block_consistency):
        return Decision("unexplained", (
            f"best candidate {best.effect} removes {share_txt} of the excess but lowers the "
            f"gap in fewer than {100 * t.block_consistency:.0f} % of the held-out "
            f"{t.block_name}"), share=share, share_se=share_se)
    if untold:
        return Decision("group", (
            f"{best.effect} beats the base model and every other candidate tried that "
            f"improves on it by more than {k:g} paired standard errors and removes "
            f"{share_txt} of the excess, but it is not named alone" + confused
            + (f"; to separate them: {how}" if how else "")), listed, share, share_se,
            separate)
    return Decision(best.effect, (
        f"{best.effect} beats the base model and every other candidate that improves on it "
        f"by more than {k:g} paired standard errors on the same held-out {t.block_name} and "
        "removes "
        f"{share_txt} of the excess held-out variance over the noise floor (at least "
        f"{100 * t.min_share:.0f} % needed)"), [], share, share_se)


def _untold_confusers(members, candidates, k: float, t: Thresholds) -> list:
    """``(name, of, why)`` for each candidate that ``t.confusable`` says a listed one
    (``members``, then those added, in turn) can be mistaken for, and that was not tried
    here (not among ``candidates``, or not applicable) or was tried and not beaten: it does
    not lose to the best by more than ``k`` paired SE and it improves on the base model by
    more than ``k`` (:func:`_beats_base`). A tried confuser at a bound of its range is not
    beaten by that: the bound says its form or range does not suit these data, not that
    the other effect is the one present. ``of`` is the listed candidate it is mistaken
    for, ``why`` completes "which ..." in the verdict's reason."""
    if not t.confusable:
        return []
    tried = {c.effect: c for c in candidates}
    listed, out = list(members), []
    for of in listed:                       # grows as confusers join
        for e in t.confusers(of):
            if e in listed:
                continue
            c = tried.get(e)
            if c is None:
                why = "was not tried (not among the candidates)"
            elif not c.available:
                na = c.not_applicable or f"not applicable: {c.error or 'unavailable'}"
                why = f"was not tried ({na})"
            elif _beaten(c, k) or not _beats_base(c, k):
                continue                    # tried and lost
            else:
                why = (f"was tried and not beaten by more than {k:g} paired standard errors"
                       + (f" (fitted at a bound of its range: {', '.join(c.at_bound)})"
                          if c.at_bound else ""))
            listed.append(e)
            out.append((e, of, why))
    return out


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


def _beats_null(c, k: float) -> bool:
    """True when candidate row ``c`` declares no nested null model (``details["null_model"]``,
    :func:`judge`), or beats it on the held-out readings by more than ``k`` paired SE
    (``null_difference`` is the null's held-out mean square minus the candidate's). A null
    whose held-out residuals are missing (its fit failed) leaves the candidate unproven."""
    if c.details.get("null_model") is None:
        return True
    d, se = c.details.get("null_difference"), c.details.get("null_difference_se")
    return d is not None and se is not None and bool(np.isfinite(se)) and d > k * se


def _null_text(c) -> str:
    """The held-out comparison of candidate row ``c`` with its null, for a verdict's reason."""
    d, se = c.details.get("null_difference"), c.details.get("null_difference_se")
    if d is None or se is None:
        return "the null's fit failed, so it was not compared"
    return (f"held-out mean square of the null minus the candidate's {d:.3g} +- {se:.3g}"
            + (f", {d / se:+.1f} SE" if se > 0 and np.isfinite(se) else ""))


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
        The candidates the data cannot tell apart (the best first), then those the
        instrument's identifiability matrix shows a listed one can be mistaken for and that
        were not tried or not beaten (:attr:`Thresholds.confusable`), for ``group`` and,
        when more than one, ``partly_explained``.
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
          base: str = "base", scale: float = 1.0,
          floor_note: str | None = None) -> tuple[list, Decision]:
    """Rank the candidates, compare them paired on the held-out readings and decide.

    Parameters
    ----------
    rows : sequence of Candidate
        Scored candidates; each available one has its held-out residuals in ``held``. A
        candidate that nests a model other than the base (it reduces to that model with its
        own parameters at their null values: a ground albedo of 0 is the black-ground
        multiple-scattering sky) names it in ``details["null_model"]``, a key of ``held``.
    held : dict
        ``name -> ndarray (n, ...)`` held-out residuals of the base model (``base``), of
        every available candidate and of every declared null model (NaN where a reading is
        not used).
    block : array (n,)
        Held-out block of every row of the residuals.
    floor : float
        Noise floor [report unit].
    thresholds : Thresholds, optional
    base : str
        Key of the base model's residuals.
    scale : float
        Report unit per residual unit (1e3 for residuals in V reported in mV).
    floor_note : str, optional
        Said first in the verdict's reason (:attr:`Floor.note`: a floor unknown, given as
        0, so that shares are of the whole gap).

    Returns
    -------
    rows : list of Candidate
        Ranked (:func:`rank`), each available one with ``paired_difference`` and its SE
        against the best-ranked (in report unit^2), its ``explained_share`` with SE, and in
        ``details`` ``base_difference`` (base minus candidate) with SE, and
        ``null_difference`` (null minus candidate, None when the null's residuals are
        missing) with SE for a candidate that declares a ``null_model``.
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
        null = c.details.get("null_model")
        if null is not None:
            # a candidate that nests another model (its parameters at their null values) is
            # compared with it as with the base model: paired, on the same held-out readings
            c.details["null_difference"], c.details["null_difference_se"] = (
                paired_difference(scaled, null, c.effect, block) if null in scaled
                else (None, None))
    if avail:
        best = avail[0].effect
        avail[0].paired_difference, avail[0].paired_difference_se = 0.0, 0.0
        for c in avail[1:]:
            c.paired_difference, c.paired_difference_se = paired_difference(
                scaled, c.effect, best, block)
    # ``explained``: the candidate's own fit meets the rule (a)-(c); whether another effect
    # could stand in for it (``confusable``) is the verdict's question, not this column's
    solo = replace(t, confusable=())
    for c in avail:
        alone = decide([c], gap_before, floor, solo)
        c.explained = alone.effect == c.effect
    decision = decide(rows, gap_before, floor, t)
    if single and decision.effect != "none":
        decision = replace(decision, reason=decision.reason + (
            " (one held-out block: paired standard errors over single readings, assumed "
            "independent)"))
    if floor_note:
        decision = replace(decision, reason=f"{floor_note}; {decision.reason}")
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
