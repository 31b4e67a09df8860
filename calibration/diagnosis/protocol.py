"""What an instrument adapter and a candidate effect implement to take part in the diagnosis.

An **instrument adapter** knows one kind of data (three-pair sensor tables, sky fields,
photodiode rings): how to recognise it, its base model, how to fit the base model plus one
candidate on calibration folds, and how to predict held-out data. It hands those fits to
:mod:`.judge` (folds, held-out scores, paired judge, verdict, shrink; the formulas of
:mod:`.core`) and returns a :class:`.report.DiagnosisReport`.
:func:`calibration.diagnosis.diagnose` asks each registered adapter in turn whether it
:meth:`~InstrumentAdapter.accepts` the data.

An **effect** is one unmodelled physical effect: a named extension of an adapter's base model
with its own parameters, which reduces to the base model at its null parameters.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from .report import DiagnosisReport

__all__ = ["Effect", "InstrumentAdapter", "candidate_names"]


@runtime_checkable
class Effect(Protocol):
    """A candidate effect.

    Attributes
    ----------
    name : str
        Its name in reports and on the command line (``tilt``, ``multiple_scattering``).
    parameter_names : tuple of str
    units : tuple of str
        Unit of each parameter (``deg``, ``s``, ``1`` for dimensionless).
    k : int
        Parameters it adds to the base model (the complexity penalty of the score).
    """

    name: str
    parameter_names: tuple
    units: tuple

    @property
    def k(self) -> int: ...

    def available(self) -> str | None:
        """None when the effect can run here, else why not (a missing optional engine or
        table); the diagnosis then lists it as unavailable instead of failing."""


@runtime_checkable
class InstrumentAdapter(Protocol):
    """An instrument known to the diagnosis.

    Attributes
    ----------
    name : str
        ``DiagnosisReport.instrument`` of its reports.
    """

    name: str

    def accepts(self, data, sidecar: dict | None = None) -> bool:
        """True for data this adapter diagnoses (an object, or a file's sidecar)."""

    def load(self, path) -> object:
        """Read a file this adapter accepts into its data object."""

    def candidates(self, names=None) -> tuple:
        """Validated candidate names (``None``: the default set); raises
        :class:`calibration.effects.UnknownEffectError` for an unknown one."""

    def diagnose(self, data, candidates, *, folds: int, seed: int,
                 **options) -> DiagnosisReport:
        """Fit, score and judge (:mod:`.core`) and return the report."""


def candidate_names(names, known, default, instrument: str) -> tuple:
    """Validated candidate names of an adapter (:meth:`InstrumentAdapter.candidates`).

    Parameters
    ----------
    names : sequence of str or None
        Requested candidates; None gives ``default``.
    known : sequence of str
        Every candidate the instrument knows.
    default : tuple of str
    instrument : str
        Named in the error (``sky``, ``camera``).

    Raises
    ------
    UnknownEffectError
        Naming the unknown candidates and the known ones.
    """
    if names is None:
        return tuple(default)
    names = tuple(names)
    unknown = [e for e in names if e not in known]
    if unknown:
        from ..effects import UnknownEffectError
        raise UnknownEffectError(f"unknown {instrument} candidate(s) {unknown}; choose from "
                                 f"{', '.join(known)}")
    return names
