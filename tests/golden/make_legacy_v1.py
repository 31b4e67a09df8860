"""Write tests/golden/legacy_*_v1.json: "skysim.diagnosis/1" report dicts as the three separate
diagnoses wrote them before they shared one package (read by tests/test_diagnosis_report.py).

They can only be made with that code, from the commit before the package (8e225c7)::

    git worktree add /tmp/old 8e225c7
    cd /tmp/old && PYTHONPATH=/tmp/old python /path/to/checkout/tests/golden/make_legacy_v1.py

Data: the three-pair ``tilt`` session of tests/test_diagnosis.py (seed 21), the noisy
single-scattering field of tests/test_sky_gap.py and a small simulated ring session of
tests/test_photodiode_diagnosis.py.
"""

import sys
from pathlib import Path

import numpy as np

from skysim.io import write_json_atomic

OUT = Path(__file__).resolve().parent


def main() -> None:
    sys.path.insert(0, "tests")
    import calibration
    if not (Path(calibration.__file__).parent / "diagnosis.py").is_file():
        raise SystemExit("run in a checkout of the commit before the diagnosis package")
    from test_photodiode_diagnosis import ring_session
    from test_sky_gap import FLOOR, make_cases

    from calibration.diagnosis import diagnose
    from calibration.photodiode_diagnosis import diagnose_photodiodes
    from calibration.sky_gap import diagnose_sky
    from experiments.workflows.diagnose import simulate_session
    from skysim.sky import RayleighSky

    ds = simulate_session("tilt", np.random.default_rng(21), params=[1.2, -0.8])
    c = make_cases(RayleighSky(dmax=0.7), np.random.default_rng(1))
    sky = diagnose_sky(c, [0], candidates=("d_max",), noise_floor=FLOOR)
    sky.pop("seconds")
    out = {"three_pair": diagnose(ds["data"], ("tilt", "sun_motion")), "sky": sky,
           "rings": diagnose_photodiodes(ring_session(n_sweeps=2, per_sweep=60),
                                         ("yaw_scale",), n_folds=2)}
    for k, v in out.items():
        path = OUT / f"legacy_{k}_v1.json"
        write_json_atomic(path, v)
        print("wrote", path)


if __name__ == "__main__":
    main()
