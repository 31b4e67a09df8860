"""One entry point: :func:`diagnose` picks the instrument adapter for the data and runs it."""

from __future__ import annotations

from pathlib import Path

from .camera import CameraAdapter
from .errors import UnsupportedInstrumentError
from .report import DiagnosisReport
from .rings import RingAdapter
from .sky import SkyAdapter
from .three_pair import ThreePairAdapter

__all__ = ["ADAPTERS", "adapter_for", "diagnose"]

ADAPTERS = (ThreePairAdapter(), RingAdapter(), SkyAdapter(), CameraAdapter())
"""Registered instrument adapters, asked in this order (:class:`.protocol.InstrumentAdapter`)."""


def adapter_for(data, sidecar: dict | None = None):
    """The first adapter that accepts ``data`` (or a file with ``sidecar``).

    Raises
    ------
    UnsupportedInstrumentError
        When none does (the message lists what is read).
    """
    for a in ADAPTERS:
        if a.accepts(data, sidecar):
            return a
    what = (f"a file of schema {sidecar.get('schema')!r}" if sidecar is not None
            else f"a {type(data).__name__}")
    raise UnsupportedInstrumentError(
        f"no diagnosis reads {what}: give a measurement table (skysim.measurement/1, a file, a "
        "Measurement, or a DataFrame with sidecar=...), photodiode data (skysim.photodiodes/1), "
        "a sky field (SkyCases) or polarization-camera frames (skysim.dofp/1 images, "
        "CameraFrames)")


def diagnose(data_or_path, candidates=None, *, folds: int = 3, seed: int = 0,
             **options) -> DiagnosisReport:
    """Diagnose the sim-to-real gap of any instrument: where, which effect, how far.

    Parameters
    ----------
    data_or_path : path, list of paths, DataFrame, Measurement, PhotodiodeData, DiagnosisData, Instrument, SkyCases, CameraFrames or CameraFrame
        A data file with its JSON sidecar ("skysim.measurement/1", "skysim.photodiodes/1" or
        a raw camera image with "skysim.dofp/1"), a folder or list of raw camera images, a
        three-pair measurement table (a DataFrame needs ``sidecar=``), a photodiode session
        (ring, dome or the one-unit three-pair sensor), a sky field or camera frames.
    candidates : sequence of str, optional
        Candidate effects (default: the instrument's default set).
    folds : int
        Held-out folds of whole sweeps (sky fields: of whole cases, at most one per case).
    seed : int
        Seed of the bootstrap of the standard errors.
    **options
        Passed to the adapter: ``thresholds`` (three-pair), ``sidecar`` (DataFrame input),
        ``noise_floor``, ``calibration_cases``, ``settings``, ``n_grid``, ``xatol`` (sky),
        ``dmax``, ``min_elevation_deg``, ``min_signal_dn``, ``block_superpixels`` (camera),
        ``where``, ``pointing``, ``pointing_from``, ``light`` ("sun" or "moon": a night
        session under the moonlit sky), ``time_uncertainty_s`` (of the recorded times, in
        the clock's uncertainty) (photodiode instruments).

    Returns
    -------
    DiagnosisReport

    Raises
    ------
    FileNotFoundError, MeasurementFormatError
        For a file without a readable sidecar or of another schema.
    UnsupportedInstrumentError
        For data no adapter reads.
    UnknownEffectError
        For a candidate the instrument does not know.
    DiagnosisError
        When the data allow no held-out diagnosis (the message says why).
    """
    if _camera_files(data_or_path):
        adapter = next(a for a in ADAPTERS if isinstance(a, CameraAdapter))
        data = adapter.load(data_or_path)
    elif isinstance(data_or_path, (str, Path)):
        from .three_pair_data import read_sidecar
        path = Path(data_or_path)
        sidecar = read_sidecar(path)
        adapter = _file_adapter(path, sidecar)
        data = adapter.load(path)
        if isinstance(adapter, RingAdapter):
            options.setdefault("where", str(path))
    else:
        data = _as_photodiodes(data_or_path, options)
        adapter = adapter_for(data, options.get("sidecar"))
    if not isinstance(adapter, RingAdapter) and options.pop("light", "sun") != "sun":
        raise UnsupportedInstrumentError(
            "light='moon' (a night session under the moonlit sky) applies to photodiode "
            "instruments with several units; the other instruments' diagnoses are of sunlit "
            "skies")
    if not isinstance(adapter, RingAdapter) and options.pop("time_uncertainty_s", 0.0):
        raise UnsupportedInstrumentError(
            "time_uncertainty_s (of recorded times, in the fitted clock's uncertainty) applies "
            "to photodiode instruments with several units, whose diagnosis fits a clock "
            "offset with an uncertainty")
    return adapter.diagnose(data, adapter.candidates(candidates), folds=folds, seed=seed,
                            **options)


def _camera_files(x) -> bool:
    """True for a folder, a raw camera image, or a list of paths (camera frames)."""
    from sensor.camera.files import IMAGE_SUFFIXES
    if isinstance(x, (str, Path)):
        return Path(x).is_dir() or Path(x).suffix.lower() in IMAGE_SUFFIXES
    return isinstance(x, (list, tuple)) and bool(x) and all(isinstance(p, (str, Path))
                                                             for p in x)


def _file_adapter(path, sidecar: dict):
    from sensor.measurement import MEASUREMENT_SCHEMA, MeasurementFormatError
    from sensor.photodiodes_io import PHOTODIODES_SCHEMAS
    for a in ADAPTERS:
        if a.accepts(None, sidecar):
            return a
    raise MeasurementFormatError(
        f"{path}: sidecar schema {sidecar.get('schema')!r} is neither {MEASUREMENT_SCHEMA!r} "
        f"nor one of {', '.join(map(repr, PHOTODIODES_SCHEMAS))}")


def _as_photodiodes(data, options: dict):
    """A DataFrame given with a "skysim.photodiodes" sidecar as :class:`PhotodiodeData`
    (``sidecar`` taken out of ``options``); anything else unchanged."""
    import pandas as pd

    from sensor.photodiodes_io import PHOTODIODES_SCHEMAS, PhotodiodeData
    side = options.get("sidecar") or {}
    if isinstance(data, pd.DataFrame) and side.get("schema") in PHOTODIODES_SCHEMAS:
        return PhotodiodeData(data, options.pop("sidecar"))
    return data
