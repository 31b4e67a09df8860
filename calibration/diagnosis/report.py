"""The diagnosis report, schema ``skysim.diagnosis/2``: one shape for every instrument.

A :class:`DiagnosisReport` answers three questions about the held-out gap between a model
and data: *where* it lies (a list of :class:`Slice`), *which* candidate effect explains it
(:class:`Candidate` rows and the :class:`Verdict`) and *how far* (gaps before and after, the
shrink with standard errors, the fitted parameters). All gaps, noise floors and slice RMS of
one report are in one unit, :attr:`DiagnosisReport.unit` (mV for the three-pair sensor's
channels, DoLP units for sky fields, the fraction of a unit's mean reading for photodiode
instruments, written "1"); what the user measures in other units (e.g. heading error [deg]) is in
``extra``.

:meth:`DiagnosisReport.to_dict` writes the ``skysim.diagnosis/2`` dict (``diagnosis.json``);
:meth:`DiagnosisReport.from_dict` reads it, and reads the three ``skysim.diagnosis/1`` dicts
the separate diagnoses wrote before (three-pair sensor, ``level: sky``, ``instrument:
photodiodes``) into the same report.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields, replace

from skysim.io import _json_default

from .errors import ReportFormatError
from .legacy import from_legacy_dict

__all__ = ["DIAGNOSIS_SCHEMA", "LEGACY_SCHEMA", "PREVIOUS_SCHEMA", "Candidate",
           "DiagnosisReport", "Slice", "Verdict", "rank", "sort_slices"]

DIAGNOSIS_SCHEMA = "skysim.diagnosis/3"
PREVIOUS_SCHEMA = "skysim.diagnosis/2"
"""Schema of the reports written before the paired verdict (no ``group``, shares or paired
differences; read by :meth:`DiagnosisReport.from_dict` with those fields empty)."""
LEGACY_SCHEMA = "skysim.diagnosis/1"
"""Schema of the report dicts written before the diagnoses shared one report (read by
:meth:`DiagnosisReport.from_dict`)."""


def _jsonable(x):
    """Plain Python numbers and containers (numpy scalars and arrays converted)."""
    return json.loads(json.dumps(x, default=_json_default))


@dataclass(frozen=True)
class Slice:
    """A part of the held-out data and its share of the gap.

    Attributes
    ----------
    dimension : str
        What the data are sliced by (``channel``, ``sweep``, ``unit``, ``sun_distance_deg``,
        ...); the slices of one dimension partition the held-out values.
    label : str
    n : int
        Held-out values in the slice.
    rms : float
        RMS held-out residual of the slice [report unit].
    share : float
        Share of the dimension's excess squared gap ``sum(r^2) - n floor^2`` (of
        ``sum(r^2)`` where no slice exceeds the floor); the shares of a dimension add to 1.
    lo, hi : float or None
        Interval of the slice in ``bound_unit`` for ordered dimensions.
    bound_unit : str or None
        ``deg``, ``lx``, ...; written as ``lo_<unit>``/``hi_<unit>`` (``lo_deg``).
    carries_gap : bool
        ``rms > limit``.
    limit : float
        RMS that white noise at the floor stays below in 99 % of slices of this size
        (:func:`calibration.diagnosis.shares.slice_limit`) [report unit].
    """

    dimension: str
    label: str
    n: int
    rms: float
    share: float
    lo: float | None = None
    hi: float | None = None
    bound_unit: str | None = None
    carries_gap: bool = False
    limit: float | None = None

    def to_dict(self) -> dict:
        d = {"dimension": self.dimension, "label": self.label, "n": self.n, "rms": self.rms,
             "share": self.share, "carries_gap": self.carries_gap, "limit": self.limit}
        if self.lo is not None:
            d[f"lo_{self.bound_unit}"], d[f"hi_{self.bound_unit}"] = self.lo, self.hi
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Slice:
        lo_key = next((k for k in d if k.startswith("lo_")), None)
        unit = lo_key[3:] if lo_key else None
        return cls(str(d["dimension"]), str(d["label"]), int(d["n"]),
                   _float(d.get("rms")), float(d["share"]),
                   _float(d.get(lo_key)) if lo_key else None,
                   _float(d.get(f"hi_{unit}")) if lo_key else None, unit,
                   bool(d.get("carries_gap", False)), _float(d.get("limit")))


def _float(x):
    return None if x is None else float(x)


@dataclass
class Candidate:
    """One candidate effect, fitted on the calibration folds and scored on the held-out ones.

    Attributes
    ----------
    effect : str
    available : bool
        False when the effect could not run here (``error`` says why).
    k : int
        Parameters it adds to the base model.
    gap_after : float
        Held-out gap with the effect [report unit].
    shrink : float
        ``1 - gap_after / gap_before``.
    score : float
        Held-out score (:func:`calibration.diagnosis.core.held_out_score`), lower is better.
    explained : bool
        Whether it brings the gap to the floor (:func:`calibration.diagnosis.core.explains`).
    converged : bool
    params : dict
        ``name -> {"value", "unit", "se"...}`` (``se``: standard error where known).
    error : str or None
    details : dict
        What an instrument adds (e.g. the clock offset's sensitivity; for an unavailable
        candidate, e.g. ``degenerate_with``: the parameter it cannot be told from here).
    paired_difference, paired_difference_se : float or None
        Held-out mean square of this candidate minus that of the best-ranked one on the same
        held-out readings [report unit^2] (0 for the best), with its jackknife SE over the
        held-out blocks (:func:`calibration.diagnosis.core.paired_difference`).
    explained_share, explained_share_se : float or None
        Share of the base model's excess held-out variance over the noise floor it removes,
        with its jackknife SE.
    at_bound : list of str
        Its parameters fitted at a bound of their range (in any fold).
    not_applicable : str or None
        ``not applicable: <reason>`` when its fit or scoring failed on these data.
    """

    effect: str
    available: bool = True
    k: int = 0
    gap_after: float | None = None
    shrink: float | None = None
    score: float | None = None
    explained: bool = False
    converged: bool = True
    params: dict = field(default_factory=dict)
    error: str | None = None
    details: dict = field(default_factory=dict)
    paired_difference: float | None = None
    paired_difference_se: float | None = None
    explained_share: float | None = None
    explained_share_se: float | None = None
    at_bound: list = field(default_factory=list)
    not_applicable: str | None = None

    @classmethod
    def unavailable(cls, effect: str, error: str, details: dict | None = None) -> Candidate:
        return cls(effect, available=False, explained=False, error=error,
                   details=dict(details or {}),
                   not_applicable=error if error.startswith("not applicable") else None)

    def to_dict(self) -> dict:
        if not self.available:
            return _jsonable({"effect": self.effect, "available": False, "error": self.error,
                              "not_applicable": self.not_applicable, **self.details})
        d = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "details"}
        d.pop("error")
        return _jsonable({**d, **self.details})

    @classmethod
    def from_dict(cls, d: dict) -> Candidate:
        own = {f.name for f in fields(cls)}
        if not d.get("available", True):
            return cls.unavailable(str(d["effect"]), str(d.get("error", "")),
                                   {k: v for k, v in d.items() if k not in own})
        kw = {k: d[k] for k in own if k in d and k != "details"}
        kw.setdefault("k", 0)
        return cls(**kw, details={k: v for k, v in d.items() if k not in own})


@dataclass
class Verdict:
    """Which effect explains the gap, and how far.

    Attributes
    ----------
    effect : str
        An effect name (it meets every condition of the verdict rule,
        :func:`calibration.diagnosis.core.decide`), ``none`` (the base model is within the
        noise floor), ``group`` (candidates the held-out data cannot tell apart, listed in
        ``group``), ``partly_explained`` (the best candidate removes a share of the excess
        below the rule's minimum) or ``unexplained``.
    reason : str
    best_candidate : str or None
        The best-ranked available candidate (None without one).
    gap_before, gap_after : float or None
        Held-out gap of the base model and after the verdict's effect (the base gap for
        ``none``; the best candidate's for ``unexplained``) [report unit]; None when the data
        hold no signal to fit.
    shrink : float or None
        ``1 - gap_after / gap_before``.
    gap_before_se, gap_after_se, shrink_se : float or None
        Bootstrap standard errors over held-out blocks (None where the split has one block).
    params : dict
        The named effect's parameters (empty unless an effect is named).
    group : list of str
        The candidates the data cannot tell apart, best first, and any candidate the best
        can be mistaken for that was not tried (``group``; ``partly_explained`` when
        several share the best's place).
    explained_share, explained_share_se : float or None
        Share of the base model's excess held-out variance over the noise floor that the
        best-ranked candidate removes, with its jackknife SE over held-out blocks.
    separated_by : dict
        ``effect -> measurement`` that would tell the group's members apart, where the
        candidates state it.
    """

    effect: str
    reason: str
    best_candidate: str | None = None
    gap_before: float | None = None
    gap_after: float | None = None
    shrink: float | None = None
    gap_before_se: float | None = None
    gap_after_se: float | None = None
    shrink_se: float | None = None
    params: dict = field(default_factory=dict)
    group: list = field(default_factory=list)
    explained_share: float | None = None
    explained_share_se: float | None = None
    separated_by: dict = field(default_factory=dict)


def rank(candidates: list[Candidate]) -> list[Candidate]:
    """Available candidates by score, ties by held-out gap; unavailable ones last."""
    ok = sorted((c for c in candidates if c.available), key=lambda c: (c.score, c.gap_after))
    return ok + [c for c in candidates if not c.available]


def sort_slices(slices) -> list[Slice]:
    """Slices by share, largest first (stable within equal shares)."""
    return sorted(slices, key=lambda s: -s.share)


@dataclass
class DiagnosisReport:
    """One diagnosis (module docstring).

    Attributes
    ----------
    instrument : str
        ``three_pair``, ``sky`` or ``photodiodes``.
    metric : str
        What the gap measures.
    unit : str
        Unit of every gap, floor and slice RMS of the report.
    verdict : Verdict
    candidates : list of Candidate
        Ranked (:func:`rank`); unavailable ones last.
    where : list of Slice
        Held-out residuals of the base model, by share, largest first.
    where_after : list of Slice or None
        The same for the verdict's best candidate, where the instrument computes it.
    noise_floor : float or None
    noise_floor_method : str
    faults : list of dict
        ``{"channel", "kind", "evidence"}`` per faulty channel found.
    data : dict
        Provenance, cleaning and the held-out split.
    thresholds : dict
    seed : int or None
    extra : dict
        What an instrument reports beside (base fit, heading error [deg], harmonics, ...).
    notes : list of str
        Sentences for the reader of the markdown report.
    """

    instrument: str
    metric: str
    unit: str
    verdict: Verdict
    candidates: list = field(default_factory=list)
    where: list = field(default_factory=list)
    where_after: list | None = None
    noise_floor: float | None = None
    noise_floor_method: str = ""
    faults: list = field(default_factory=list)
    data: dict = field(default_factory=dict)
    thresholds: dict = field(default_factory=dict)
    seed: int | None = None
    extra: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    # -------------------------------------------------------------------- access
    def candidate(self, effect: str) -> Candidate | None:
        """The candidate row of ``effect`` (None when it was not tried)."""
        return next((c for c in self.candidates if c.effect == effect), None)

    def carrying_gap(self, after: bool = False) -> list[Slice]:
        """Slices whose RMS exceeds their noise limit (of ``where_after`` with ``after``)."""
        return [s for s in ((self.where_after or []) if after else self.where)
                if s.carries_gap]

    # -------------------------------------------------------------------- dict
    def to_dict(self) -> dict:
        """The ``skysim.diagnosis/2`` dict (JSON-serialisable as is)."""
        verdict = {**asdict(self.verdict), "metric": f"{self.metric} [{self.unit}]",
                   "noise_floor": self.noise_floor}     # the verdict block reads on its own
        d = {"schema": DIAGNOSIS_SCHEMA, "instrument": self.instrument, "metric": self.metric,
             "unit": self.unit, "verdict": verdict,
             "candidates": [c.to_dict() for c in self.candidates],
             "where": [s.to_dict() for s in self.where],
             "where_after": (None if self.where_after is None
                             else [s.to_dict() for s in self.where_after]),
             "noise_floor": self.noise_floor, "noise_floor_method": self.noise_floor_method,
             "faults": self.faults, "data": self.data, "thresholds": self.thresholds,
             "seed": self.seed, "extra": self.extra, "notes": self.notes}
        return _jsonable(d)

    @classmethod
    def from_dict(cls, d: dict) -> DiagnosisReport:
        """Read a ``skysim.diagnosis/2`` dict, or a ``skysim.diagnosis/1`` dict of the
        three-pair, sky or photodiode diagnosis (also when labelled with the new schema but
        shaped as before, without ``unit``: the photodiode diagnosis's own result dict).

        Raises
        ------
        ReportFormatError
            For another schema, or a dict missing a required key.
        """
        if not isinstance(d, dict):
            raise ReportFormatError(f"a diagnosis report is a dict; got {type(d).__name__}")
        schema = d.get("schema")
        try:
            if schema in (DIAGNOSIS_SCHEMA, PREVIOUS_SCHEMA) and "unit" in d:
                return cls._from_v2(d)
            if schema in (LEGACY_SCHEMA, DIAGNOSIS_SCHEMA, PREVIOUS_SCHEMA):
                # no "unit": a v1-shaped dict, rewritten in the current shape
                r = cls._from_v2(from_legacy_dict(d))
                return replace(r, candidates=rank(r.candidates), where=sort_slices(r.where),
                               where_after=(None if r.where_after is None
                                            else sort_slices(r.where_after)))
        except KeyError as exc:
            raise ReportFormatError(f"diagnosis report ({schema}) without the key "
                                    f"{exc.args[0]!r}") from None
        raise ReportFormatError(f"schema {schema!r} is none of {DIAGNOSIS_SCHEMA!r}, "
                                f"{PREVIOUS_SCHEMA!r}, {LEGACY_SCHEMA!r}")

    @classmethod
    def _from_v2(cls, d: dict) -> DiagnosisReport:
        wa = d.get("where_after")
        own = {f.name for f in fields(Verdict)}
        verdict = Verdict(**{k: v for k, v in d["verdict"].items() if k in own})
        return cls(d["instrument"], d["metric"], d["unit"], verdict,
                   [Candidate.from_dict(c) for c in d["candidates"]],
                   [Slice.from_dict(s) for s in d["where"]],
                   None if wa is None else [Slice.from_dict(s) for s in wa],
                   d.get("noise_floor"), d.get("noise_floor_method", ""),
                   list(d.get("faults", [])), dict(d.get("data", {})),
                   dict(d.get("thresholds", {})), d.get("seed"), dict(d.get("extra", {})),
                   list(d.get("notes", [])))

    # -------------------------------------------------------------------- markdown
    def to_markdown(self) -> str:
        """``report.md``: verdict, candidates, where, faults, data and split."""
        from .markdown import report_markdown
        return report_markdown(self)
