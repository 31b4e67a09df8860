"""The blind check of the diagnosis on real photodiode sessions (``skysim gap-benchmark --real
DIR``): known effects injected into each session (:mod:`.real_injection`), the diagnosis run
blind, and each case scored on where, which and how far; and the sessions of a folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from skysim.exceptions import MissingFileError
from skysim.io import atomic_write, write_json_atomic

__all__ = ["run_real_benchmark", "session_files"]


def session_files(folder, option: str = "--data") -> list[Path]:
    """Photodiode sessions (data files with a ``skysim.photodiodes`` sidecar, version 1 or 2)
    of a folder; ``option`` is the command-line option that names the folder (for the error
    message)."""
    import json
    folder = Path(folder)
    if not folder.is_dir():
        raise MissingFileError(
            f"no session folder {folder}: give {option} DIR with skysim.photodiodes files "
            "(e.g. the ring-compass recordings of Gkanias et al. 2023)")
    out = []
    for f in sorted(folder.iterdir()):
        if f.suffix not in (".csv", ".parquet"):
            continue
        for side in (f.with_name(f.name + ".json"), f.with_suffix(".json")):
            if side.exists():
                try:
                    if json.loads(side.read_text()).get("schema") in ("skysim.photodiodes/1",
                                                                   "skysim.photodiodes/2"):
                        out.append(f)
                except (ValueError, OSError):
                    pass
                break
    if not out:
        raise MissingFileError(f"{folder} holds no skysim.photodiodes session")
    return out


def run_real_benchmark(folder, effects_to_inject, candidates, out: Path, n_sessions: int,
                       seed: int, folds: int = 3) -> pd.DataFrame:
    """Inject each effect into real sessions and score where / which / how far."""
    from tqdm import tqdm

    from calibration import diagnose
    from sensor.photodiodes_io import read_photodiodes

    from .real_injection import inject
    files = session_files(folder, "--real")[:n_sessions]
    rng = np.random.default_rng(seed)
    rows = []
    jobs = [(f, e) for f in files for e in effects_to_inject]
    for f, e in tqdm(jobs, desc="injected sessions", unit="case"):
        data, truth = inject(read_photodiodes(f), e, rng)
        report = diagnose(data, candidates, folds=folds, seed=seed, where=str(f))
        rows.append(_score_case(Path(f).name, truth, report))
    table = pd.DataFrame(rows)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "real_cases.csv", lambda p: table.to_csv(p, index=False))
    summary = {"cases": len(table), "named": float(table["named"].mean()) if len(table) else None,
               "parameter_ok": float(table["parameter_ok"].mean()) if len(table) else None,
               "seed": seed, "sessions": [Path(f).name for f in files]}
    write_json_atomic(out / "real_summary.json", summary)
    return table


def _score_case(name, truth, report) -> dict:
    e = truth["effect"]
    v = report.verdict
    row = {"session": name, "effect": e, "verdict": v.effect, "truth": str(truth)}
    if e == "stuck":
        row["named"] = any(f["channel"] == truth["channel"] and f["kind"] in ("stuck", "dead")
                           for f in report.faults)
        row["parameter_ok"] = row["named"]
        return row
    row["named"] = v.effect == e
    cand = report.candidate(e)
    row["excess_removed"] = cand.details.get("excess_removed") if cand else None
    row["rank"] = next((i + 1 for i, c in enumerate(report.candidates) if c.effect == e), None)
    p = cand.params if cand is not None and cand.available else {}
    if e == "clock_offset" and p:
        row["error"] = abs(p["clock_offset_s"]["value"] - truth["clock_offset_s"])
        row["parameter_ok"] = row["error"] <= 600.0
    elif e == "yaw_scale" and p:
        row["error"] = abs(p["factor"]["value"] / truth["factor"] - 1.0)
        row["parameter_ok"] = row["error"] <= 0.015
    elif e == "occlusion":
        offs = report.extra["base_fit"]["heading_offset_deg"]
        shift = float(np.degrees(np.angle(np.mean(np.exp(1j * np.radians(offs))))))
        c = (truth["center_deg"] + shift) % 360.0
        top = [w for w in report.where if w.dimension == "sky_azimuth_deg"][:3]
        hw = 0.5 * truth["width_deg"]
        row["parameter_ok"] = any(abs(((0.5 * (w.lo + w.hi) - c + 180) % 360) - 180)
                                  <= hw + 15 for w in top)
    else:
        row["parameter_ok"] = False
    return row
