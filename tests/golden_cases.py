"""Golden cases of the three diagnoses: small, fast data sets taken from their own tests, and
the verdicts and held-out gaps the diagnoses gave on them when recorded.

Each case is a function returning the diagnosis report of one data set; :func:`summary`
keeps what must not change when the diagnosis code is reorganised: the verdict (effect name,
best candidate), the gaps before and after, the shrink, the noise floor and every available
candidate's held-out gap (units: mV for the three-pair sensor, DoLP units for sky fields,
fractions of the unit's mean reading for photodiode rings).

Record (only when a behaviour change is intended, and say so in the commit)::

    python tests/golden_cases.py

writes ``tests/golden/<family>.json``; ``tests/test_golden_diagnosis.py`` compares.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

GOLDEN_DIR = Path(__file__).resolve().parent / "golden"
THREE_PAIR_SENSOR_CANDIDATES = ("tilt", "turntable_periodic", "sun_motion", "clock_offset")


def _report_dict(report) -> dict:
    """The report as a dict (a report object, or a dict as the diagnoses returned before)."""
    return report if isinstance(report, dict) else report.to_dict()


def summary(report) -> dict:
    """What the golden test compares (see module docstring)."""
    d = _report_dict(report)
    v = d["verdict"]
    cands = {c["effect"]: c["gap_after"] for c in d["candidates"]
             if c.get("available", True)}
    floor = v["noise_floor"]
    return {"verdict": v["effect"], "best_candidate": v.get("best_candidate"),
            "gap_before": v["gap_before"], "gap_after": v["gap_after"], "shrink": v["shrink"],
            "noise_floor": None if floor is None else float(floor),
            "candidate_gaps": {k: float(g) for k, g in cands.items()},
            "unavailable": sorted(c["effect"] for c in d["candidates"]
                                  if not c.get("available", True))}


# ----------------------------------------------------------------------- three-pair sensor
def _three_pair(label, seed, params, candidates):
    from calibration.diagnosis import diagnose
    from experiments.diagnose import simulate_session
    ds = simulate_session(label, np.random.default_rng(seed), params=params)
    return diagnose(ds["data"], candidates)


def three_pair_tilt_named():
    """tests/test_diagnosis.py ``tilt_case`` data (tilt 1.2, -0.8 deg), four candidates."""
    return _three_pair("tilt", 21, [1.2, -0.8], THREE_PAIR_SENSOR_CANDIDATES)


def three_pair_tilt_withheld():
    """The same data with the true effect withheld: the leave-one-out ``unexplained``."""
    return _three_pair("tilt", 21, [1.2, -0.8], ("turntable_periodic", "sun_motion",
                                                   "dark_current"))


def three_pair_none():
    """tests/test_diagnosis.py ``none_case`` data (no effect)."""
    return _three_pair(None, 22, None, ("tilt", "sun_motion", "dark_current"))


# ----------------------------------------------------------------------- sky fields
def sky_rayleigh_none():
    """tests/test_sky_gap.py: a single-scattering field (d_max 0.7) with noise; no engine."""
    from calibration.sky_gap import diagnose_sky
    from skysim.sky import RayleighSky
    from test_sky_gap import FLOOR, make_cases
    c = make_cases(RayleighSky(dmax=0.7), np.random.default_rng(1))
    return diagnose_sky(c, [0], candidates=("d_max",), noise_floor=FLOOR)


def sky_multiple_scattering_named():
    """tests/test_sky_gap.py: a multiple-scattering field (tau 0.3, black ground), 8-stream
    sasktran2 (needs the ``rt`` extra)."""
    from calibration.sky_gap import diagnose_sky
    from skysim.multiple import MultipleScatteringSky
    from skysim.rt_sasktran import EngineSettings
    from test_sky_gap import FLOOR, make_cases
    settings = EngineSettings(n_streams=8)
    c = make_cases(MultipleScatteringSky(tau=0.3, albedo=0.0, settings=settings),
                   np.random.default_rng(2))
    return diagnose_sky(c, [0], candidates=("multiple_scattering",), noise_floor=FLOOR,
                        settings=settings, n_grid=5)


# ----------------------------------------------------------------------- photodiode rings
def ring_yaw_scale_named():
    """tests/test_photodiode_diagnosis.py: the simulated ring with a gyro scale injected."""
    from calibration.photodiode_diagnosis import diagnose_photodiodes
    from experiments.real_injection import inject
    from test_photodiode_diagnosis import ring_session
    data, _ = inject(ring_session(), "yaw_scale", np.random.default_rng(3))
    return diagnose_photodiodes(data, ("yaw_scale",), n_folds=3)


def ring_no_candidates():
    """The same simulated ring, noise-free counts, no candidate: its gap is left unexplained."""
    from calibration.photodiode_diagnosis import diagnose_photodiodes
    from test_photodiode_diagnosis import ring_session
    return diagnose_photodiodes(ring_session(), (), n_folds=3)


CASES = {
    "three_pair": {"tilt_named": three_pair_tilt_named,
                   "tilt_withheld": three_pair_tilt_withheld,
                   "none": three_pair_none},
    "sky": {"rayleigh_none": sky_rayleigh_none,
            "multiple_scattering_named": sky_multiple_scattering_named},
    "rings": {"yaw_scale_named": ring_yaw_scale_named,
              "no_candidates": ring_no_candidates},
}
NEEDS_ENGINE = {("sky", "multiple_scattering_named")}


def record(family: str) -> Path:
    """Run every case of ``family`` and write ``golden/<family>.json``."""
    GOLDEN_DIR.mkdir(exist_ok=True)
    out = {name: summary(case()) for name, case in CASES[family].items()}
    path = GOLDEN_DIR / f"{family}.json"
    path.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    return path


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    for fam in sys.argv[1:] or CASES:
        print("wrote", record(fam))
