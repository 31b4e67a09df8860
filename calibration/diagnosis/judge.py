"""The diagnosis method, written once for every instrument.

An instrument adapter brings what only it knows: its data split into blocks, a function that
fits the base model and each candidate on the training blocks of one fold and returns their
residuals on the held-out block (:func:`cross_validate`), its noise floor and its slices.
The method itself is here, in the order it runs (the formulas are :mod:`.core`'s):

1. **Folds** by whole block (:func:`.core.assign_folds`), each fitted and held out in turn
   (:func:`cross_validate`); a candidate whose fit fails, or leaves non-finite held-out
   residuals, is ``not applicable`` from then on and never ends the run.
2. **Scores** of each candidate on the held-out readings against the base model's
   (:func:`score`: gap, shrink, held-out score, excess removed, blocks improved, convergence,
   parameters at a bound).
3. **The paired judge, the decision and the shrink** (:func:`verdict`): candidates compared
   paired on the same held-out readings with jackknife SE over blocks, the one verdict rule
   (:func:`.core.decide`), and the gap after the verdict with bootstrap SE over blocks.

The shape is that of scikit-image's ``ransac(data, model_class, ...)``: the loop, the
scoring and the decision are the method's; fitting one fold is the adapter's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import core
from .errors import InsufficientDataError
from .report import Verdict

__all__ = ["FoldFit", "HeldOut", "cross_validate", "fold_mean_se", "score", "verdict"]


@dataclass
class FoldFit:
    """One model fitted on a fold's training blocks and scored on its held-out block.

    Attributes
    ----------
    residual : ndarray
        Held-out residuals, one row per held-out reading row (the rows of ``held`` given to
        the fold).
    params : ndarray
        The candidate's own parameters as fitted (empty for the base model).
    converged : bool
    sd : list or None
        Posterior standard deviation of each parameter, where the fit gives one.
    state : object
        What the adapter keeps of the fit (to continue it, or to decode with it).
    """

    residual: np.ndarray
    params: np.ndarray = field(default_factory=lambda: np.zeros(0))
    converged: bool = True
    sd: list | None = None
    state: object = None


def fold_mean_se(values, sds=None) -> tuple[float | None, float | None, float | None]:
    """Standard error of a parameter's mean over ``k`` cross-validation folds, each fitted
    on the other ``k - 1`` blocks of data.

    The mean over folds stands for a fit of every block. Its SE is the larger of two:

    - the model's, ``sqrt(mean(sd_f^2) (k - 1) / k)``: each fold's posterior SD ``sd_f`` is
      that of a fit on ``(k - 1) / k`` of the data, and a fit on all of it has that variance
      times ``(k - 1) / k``;
    - the delete-a-group jackknife's over the folds, ``sqrt((k - 1) / k sum_f (v_f -
      mean v)^2)`` (Efron & Stein 1981; Shao & Tu 1995, sect. 2.1): each fold's value is the
      estimate with one group deleted. It reads the spread between blocks that a form wrong
      for these data leaves, which the model's SD does not see. For two folds (disjoint
      halves) it is the SE of the mean of two independent fits, ``std_f / sqrt(2)``.

    Under noise alone both estimate the same variance and the larger one gives z-scores with
    an RMS of ``sqrt(1 - 1/e + E1(1))`` = 0.92 for three folds of a linear-Gaussian
    estimator (the jackknife's variance there is the model's times an Exp(1) variate);
    adding the two in quadrature counts the same noise twice (RMS 0.72).

    Parameters
    ----------
    values : array (k,)
        The parameter as each fold fitted it.
    sds : sequence of float or None, optional
        Each fold's posterior SD (None where its fit gives none; the model's SE is read
        from the folds that give one).

    Returns
    -------
    se, model_se, jackknife_se : float or None
        The SE, and the two it is the larger of (None where it cannot be read: the model's
        when no fold has an SD, the jackknife's for one fold). ``se`` is None when neither
        can be read.

    References
    ----------
    .. [1] B. Efron and C. Stein, "The jackknife estimate of variance", Ann. Statist. 9,
       586-596 (1981).
    .. [2] J. Shao and D. Tu, *The Jackknife and Bootstrap* (Springer, 1995).
    """
    v = np.asarray(values, float)
    k = v.size
    sd = [s for s in (sds or []) if s is not None]
    model = float(np.sqrt(np.mean(np.square(sd)) * max(k - 1, 1) / k)) if k and sd else None
    jack = float(np.sqrt((k - 1) / k * np.sum((v - v.mean()) ** 2))) if k > 1 else None
    known = [x for x in (model, jack) if x is not None]
    return (max(known) if known else None), model, jack


@dataclass
class HeldOut:
    """Held-out residuals of the base model and every candidate over all folds.

    Attributes
    ----------
    residual : dict
        ``name -> ndarray`` over every reading row (``"base"`` the base model's).
    usable : ndarray of bool
        Readings held out and usable (the base model's held-out mask).
    fits : dict
        ``name -> [FoldFit]``, one per fold it was fitted on, in fold order.
    rows : dict
        ``name -> [ndarray]``, the held-out rows of each of its fold fits.
    unavailable : dict
        ``name -> why`` for the candidates that are not applicable here.
    """

    residual: dict
    usable: np.ndarray
    fits: dict
    rows: dict
    unavailable: dict

    def put(self, name: str, rows, fit: FoldFit, index: int | None = None) -> None:
        """Record ``fit`` of ``name`` on the held-out ``rows`` (replacing fold fit ``index``
        when given: a fit continued after the first pass)."""
        self.residual[name][rows] = fit.residual
        if index is None:
            self.fits[name].append(fit)
            self.rows[name].append(rows)
        else:
            self.fits[name][index] = fit

    def held(self, name: str) -> np.ndarray:
        """Held-out residuals of ``name``, NaN where a reading is not used."""
        return np.where(self.usable, self.residual[name], np.nan)

    def available(self, names) -> list:
        return [n for n in names if n not in self.unavailable]


def cross_validate(folds, names, shape, fit_fold, unavailable: dict | None = None, *,
                   held_folds=None) -> HeldOut:
    """Fit and hold out every fold (module doc, step 1).

    Parameters
    ----------
    folds : array (n,)
        Fold of every reading row (:func:`.core.assign_folds`).
    names : sequence of str
        The candidates.
    shape : tuple
        Shape of the residuals over all rows.
    fit_fold : callable
        ``fit_fold(train, held, skip) -> (usable, {name: FoldFit or reason})``: the base
        model (``"base"``) and each candidate not in ``skip`` fitted on the ``train`` rows
        and scored on the ``held`` rows; ``usable`` marks the held-out readings used. A
        candidate's reason (a string) makes it not applicable.
    unavailable : dict, optional
        ``name -> why`` of the candidates known not to apply before any fit (a missing
        engine, a sun too low for the effect's model); they are never fitted.
    held_folds : sequence of int, optional
        The folds held out in turn (default: every fold). The rows of the other folds are
        only ever fitted on: a split the user gives (calibration rows and withheld rows) is
        one held-out fold.

    Returns
    -------
    HeldOut

    Raises
    ------
    InsufficientDataError
        For a held-out fold that no row belongs to.
    """
    out = HeldOut({k: np.zeros(shape) for k in ("base", *names)}, np.zeros(shape, bool),
                  {k: [] for k in ("base", *names)}, {k: [] for k in ("base", *names)},
                  {} if unavailable is None else unavailable)
    folds = np.asarray(folds)
    every = np.unique(folds)
    if held_folds is None:
        held_folds = every
    missing = [int(f) for f in held_folds if f not in every]
    if missing:
        raise InsufficientDataError(f"held-out folds {missing} hold no row; the rows' folds are "
                         f"{every.tolist()}")
    for f in held_folds:
        train, held = np.flatnonzero(folds != f), np.flatnonzero(folds == f)
        usable, fits = fit_fold(train, held, out.unavailable)
        out.usable[held] = usable
        base = fits["base"]
        for name, fit in fits.items():
            if isinstance(fit, FoldFit) and name != "base":
                why = core.non_finite_reason(np.where(usable, fit.residual, np.nan),
                                             np.where(usable, base.residual, np.nan))
                fit = fit if why is None else why
            if isinstance(fit, str):
                out.unavailable[name] = fit
            else:
                out.put(name, held, fit)
    return out


def score(held: HeldOut, name: str, k: int, block, floor: float, n_cal: int, *,
          n_held_out: int | None = None, scale: float = 1.0) -> dict:
    """A candidate's held-out scores against the base model (module doc, step 2): ``gap_after``,
    ``shrink``, ``score``, ``k``, ``excess_removed``, ``blocks_improved`` (over the blocks
    holding a held-out reading), ``converged`` (in every fold).

    ``n_held_out`` is the number of independent held-out values of the score
    (:func:`.core.held_out_score`); by default the usable held-out readings. A reading row
    whose values are constrained (four analyser outputs that sum to zero carry three) gives
    fewer. ``floor`` is in residual units; ``gap_after`` is reported in ``scale`` report
    units per residual unit (1e3 for residuals in V reported in mV).
    """
    g0, gc = core.rms(held.held("base")), core.rms(held.held(name))
    n_ho = int(held.usable.sum()) if n_held_out is None else int(n_held_out)
    return {"effect": name, "gap_after": scale * gc, "shrink": 1 - gc / g0,
            "score": core.held_out_score(gc, g0, floor, n_ho, k, n_cal), "k": k,
            "excess_removed": core.excess_removed(gc, g0, floor),
            "blocks_improved": core.blocks_improved(held.held("base"), held.held(name), block),
            "converged": all(f.converged for f in held.fits[name])}


def verdict(rows, held: dict, block, floor: float, thresholds: core.Thresholds,
            rng: np.random.Generator, *, base: str = "base",
            scale: float = 1.0, floor_note: str | None = None) -> tuple[list, Verdict]:
    """Rank, judge paired, decide and measure the shrink (module doc, step 3).

    Parameters
    ----------
    rows : sequence of Candidate
        Scored candidates, available or not.
    held : dict
        ``name -> ndarray`` held-out residuals of the base model (``base``) and of every
        available candidate (NaN where not used).
    block : array (n,)
        Held-out block of every row of the residuals.
    floor : float
        Noise floor [report unit].
    thresholds : Thresholds
    rng : Generator
        Of the block bootstrap of the shrink.
    scale : float
        Report unit per residual unit.
    floor_note : str, optional
        Said first in the verdict's reason: a floor unknown and given as 0
        (:attr:`.core.Floor.note`).

    Returns
    -------
    rows : list of Candidate
        Ranked, with their paired differences and shares (:func:`.core.judge`).
    verdict : Verdict
        Gaps before and after the verdict's effect (the base gap for ``none`` and where no
        candidate is available), with bootstrap SE over blocks (None with one held-out
        block); the parameters of a named effect.
    """
    ranked, decision = core.judge(list(rows), held, block, floor, thresholds, base=base,
                                  scale=scale, floor_note=floor_note)
    avail = [c for c in ranked if c.available]
    best = avail[0] if avail else None
    named = best is not None and decision.effect == best.effect
    after = best.effect if best is not None and decision.effect != "none" else base
    se = core.shrink_uncertainty(held[base], held[after], block, rng)
    g0, g1 = core.rms(held[base]), core.rms(held[after])
    moved = after != base

    def scaled(key):    # no SE from a single held-out block
        return None if se is None else scale * se[key]
    return ranked, Verdict(
        decision.effect, decision.reason, None if best is None else best.effect,
        scale * g0, scale * g1, 1 - g1 / g0, scaled("gap_before_se"),
        scaled("gap_after_se" if moved else "gap_before_se"),
        None if se is None else (se["shrink_se"] if moved else 0.0),
        best.params if named else {}, decision.group, decision.share, decision.share_se,
        decision.separated_by)
