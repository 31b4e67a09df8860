"""The diagnoses keep their behaviour: verdicts and held-out gaps of small recorded cases.

The expected values in ``tests/golden/*.json`` were recorded by ``tests/golden_cases.py``
from the diagnoses as they stood before their code was brought into one package; the cases
are data sets of the diagnoses' own tests (``tests/golden_cases.py`` says which).

Tolerances: verdict and best-candidate names exactly. Gaps, shrink and noise floor within
1e-9 relative (plus 1e-15 absolute for a zero shrink): the same arithmetic on the same data
reproduces them to rounding (~1e-15); the iterative fits start and stop at the same points,
and a fit that converged to 1e-8 in relative cost cannot move a gap by 1e-9 unless it took a
different path, which is the behaviour change this test exists to catch. The one case run
through a threaded radiative-transfer engine has a looser, stated tolerance
(``golden_cases.REL_TOLERANCE``).
"""

import json

import pytest
from golden_cases import CASES, GOLDEN_DIR, NEEDS_ENGINE, REL_TOLERANCE, summary

REL = 1e-9
ABS = 1e-15

PARAMS = [(fam, name) for fam, cases in CASES.items() for name in cases]


def _expected(family: str, name: str) -> dict:
    path = GOLDEN_DIR / f"{family}.json"
    return json.loads(path.read_text())[name]


@pytest.mark.parametrize("family,name", PARAMS, ids=[f"{f}-{n}" for f, n in PARAMS])
def test_golden(family, name):
    if (family, name) in NEEDS_ENGINE:
        pytest.importorskip("sasktran2", reason="sasktran2 (extra skysim[rt]) not installed")
    want = _expected(family, name)
    got = summary(CASES[family][name]())
    rel = REL_TOLERANCE.get((family, name), REL)
    assert got["verdict"] == want["verdict"]
    assert got["best_candidate"] == want["best_candidate"]
    assert got["unavailable"] == want["unavailable"]
    assert sorted(got["candidate_gaps"]) == sorted(want["candidate_gaps"])
    for key in ("gap_before", "gap_after", "shrink", "noise_floor"):
        if want[key] is None:
            assert got[key] is None, key
        else:
            assert got[key] == pytest.approx(want[key], rel=rel, abs=ABS), key
    for eff, gap in want["candidate_gaps"].items():
        assert got["candidate_gaps"][eff] == pytest.approx(gap, rel=rel, abs=ABS), eff
