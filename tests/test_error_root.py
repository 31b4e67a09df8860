"""One error root: ``from skysim import SkysimError`` catches every error skysim raises on bad
input, and ``SkysimWarning`` is the root of its warnings.

(a) A scan of the library's source (``ast``) finds no ``raise`` of a bare built-in exception
    class outside an allow-list whose every entry says why the built-in is right there.
(b) Every exception class the project defines derives from ``SkysimError`` and keeps a
    built-in base (``except ValueError`` keeps working); every warning class derives from
    ``SkysimWarning``.
(c) Representative bad inputs through the Python API are each caught by
    ``except skysim.SkysimError``, with a one-line message naming the offending value.
(d) Input files: a CSV header naming a column twice is refused naming the column.
"""

import ast
import builtins
import gzip
import importlib
import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import skysim
from skysim.exceptions import SkysimError, SkysimWarning

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("skysim", "sensor", "calibration", "experiments")
"""The library: what a user's Python code calls (the command line sits on top of it)."""

BUILTIN_EXCEPTIONS = frozenset(
    name for name, obj in vars(builtins).items()
    if isinstance(obj, type) and issubclass(obj, BaseException))

# ------------------------------------------------------------------------------- (a) the scan

ALLOWED = {
    ("skysim/_lazy.py", "lazy_namespace.__getattr__", "AttributeError"):
        "a module's __getattr__ (PEP 562) must raise AttributeError for a name it lacks: "
        "hasattr() and 'from skysim import x' rely on it",
    ("skysim/data/build_rolo_kieffer_stone_2005.py", "main", "SystemExit"):
        "a maintainer's build script run as a program: SystemExit is its exit with a message",
    ("skysim/data/build_water_cloud_phase.py", "main", "SystemExit"):
        "a maintainer's build script run as a program: SystemExit is its exit with a message",
    ("calibration/effects/build_multiple_scattering_table.py", "<module>", "SystemExit"):
        "the build script's exit status when run as a program",
    ("experiments/workflows/sweep.py", "ChunkPlan.__getitem__", "IndexError"):
        "the sequence protocol: iteration and slicing over the chunks stop at IndexError",
}
"""Raise sites of a built-in exception that are right as they are: (file, function, class)."""

OWNED_BY_THE_DIAGNOSIS_REWRITE = {
    ("calibration/diagnosis/three_pair_data.py", "DiagnosisData.__post_init__", "ValueError"):
        "U of the wrong shape",
    ("calibration/diagnosis/three_pair_data.py", "read_sidecar", "FileNotFoundError"):
        "a data file without its sidecar",
    ("calibration/photodiode_diagnosis/instrument.py", "Instrument.with_readings",
     "ValueError"):
        "readings of another shape",
}
"""Owned by the diagnosis rewrite: calibration/diagnosis/ and calibration/photodiode_diagnosis/
are being rewritten; these raise sites are to become project errors there (a
DiagnosisError subclass) and their entries to leave this list."""


def _bare_builtin_raises(root: Path = ROOT, folders=SCANNED) -> dict:
    """``{(file, enclosing function, class): [line, ...]}`` of every ``raise X(...)`` or
    ``raise X`` with X a built-in exception class, in ``folders`` under ``root``."""
    found: dict = {}
    for top in folders:
        for path in sorted((root / top).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            tree = ast.parse(path.read_text(), filename=rel)

            def visit(node, scope):
                for child in ast.iter_child_nodes(node):
                    if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                        visit(child, scope + [child.name])
                        continue
                    if isinstance(child, ast.Raise) and child.exc is not None:
                        target = child.exc.func if isinstance(child.exc, ast.Call) else child.exc
                        if isinstance(target, ast.Name) and target.id in BUILTIN_EXCEPTIONS:
                            key = (rel, ".".join(scope) or "<module>", target.id)
                            found.setdefault(key, []).append(child.lineno)
                    visit(child, scope)
            visit(tree, [])
    return found


RAISES = _bare_builtin_raises()


def test_no_bare_builtin_raise_on_bad_input():
    unexplained = {k: v for k, v in RAISES.items()
                   if k not in ALLOWED and k not in OWNED_BY_THE_DIAGNOSIS_REWRITE}
    assert not unexplained, (
        "raise a project exception (skysim.exceptions: InvalidParameterError, FileFormatError, "
        "MissingFileError, MissingDependencyError, ...) or, for a bug, add the site to ALLOWED "
        "with the reason: " + "; ".join(f"{f}:{lines} {fn} raises {cls}"
                                        for (f, fn, cls), lines in sorted(unexplained.items())))


def test_every_allowed_site_still_exists():
    """The allow-list holds no entry its code has left (one that would hide a new raise)."""
    assert not sorted(set(ALLOWED) - set(RAISES))


def test_the_scan_sees_a_bare_raise(tmp_path):
    """The scan itself: bare built-in raises are found with their function; a project
    exception, a re-raise and a raise of a caught exception are not."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "m.py").write_text(
        "class A:\n    def f(self):\n        raise ValueError('x')\n"
        "def g():\n    raise KeyError\n    raise SkysimError('fine')\n"
        "try:\n    pass\nexcept OSError as exc:\n    raise exc\n")
    assert _bare_builtin_raises(tmp_path, ("pkg",)) == {
        ("pkg/m.py", "A.f", "ValueError"): [3], ("pkg/m.py", "g", "KeyError"): [5]}


# ----------------------------------------------------------------- (b) one class hierarchy

PACKAGES = ("skysim", "sensor", "calibration", "experiments")
BUILTIN_BASES = (ValueError, RuntimeError, OSError, ImportError, TypeError)


def _classes_defined():
    """``{"module.Class": class}`` of every exception and warning class the packages define
    (modules needing an optional extra that is not installed are skipped)."""
    found = {}
    for name in PACKAGES:
        pkg = importlib.import_module(name)
        mods = [name] + [m.name for m in pkgutil.walk_packages(pkg.__path__, name + ".")]
        for mod_name in mods:
            try:
                mod = importlib.import_module(mod_name)
            except ImportError:        # an optional extra not installed here
                continue
            for obj in vars(mod).values():
                if (isinstance(obj, type) and issubclass(obj, Exception)
                        and obj.__module__ == mod_name):
                    found[f"{mod_name}.{obj.__qualname__}"] = obj
    return found


CLASSES = _classes_defined()
ERRORS = {n: c for n, c in CLASSES.items() if not issubclass(c, Warning) and c is not SkysimError}
WARNINGS = {n: c for n, c in CLASSES.items() if issubclass(c, Warning) and c is not SkysimWarning}


def _all_subclasses(cls) -> set:
    out = set()
    for sub in cls.__subclasses__():
        out |= {sub} | _all_subclasses(sub)
    return out


def test_the_walk_found_the_known_families():
    for expected in ("skysim.exceptions.InvalidParameterError",
                     "skysim.exceptions.FileFormatError",
                     "calibration.exceptions.CalibrationError",
                     "calibration.exceptions.DiagnosisError",
                     "calibration.diagnosis.errors.InsufficientDataError",
                     "sensor.measurement.MeasurementFormatError",
                     "sensor.camera.files.DofpFormatError",
                     "calibration.effects.UnknownEffectError"):
        assert expected in ERRORS
    for expected in ("skysim.rt_sasktran.TauBeyondTablesWarning",
                     "sensor.illuminance.DepthBeyondValidationWarning",
                     "calibration.photodiode_diagnosis.errors.YawInRadiansWarning"):
        assert expected in WARNINGS


@pytest.mark.parametrize("name", sorted(ERRORS))
def test_every_exception_has_the_root_and_a_builtin_base(name):
    cls = ERRORS[name]
    assert issubclass(cls, SkysimError), name
    assert issubclass(cls, BUILTIN_BASES), name


def test_the_root_knows_every_exception_class():
    """Walking down from the root reaches every class the packages define."""
    assert set(ERRORS.values()) <= _all_subclasses(SkysimError)
    assert set(WARNINGS.values()) <= _all_subclasses(SkysimWarning)


@pytest.mark.parametrize("name", sorted(WARNINGS))
def test_every_warning_has_the_root(name):
    assert issubclass(WARNINGS[name], SkysimWarning) and issubclass(WARNINGS[name], UserWarning)


def test_builtin_bases_are_kept_for_existing_handlers():
    """Code written against the built-ins keeps catching what it caught."""
    from calibration.diagnosis import DiagnosisError
    from calibration.effects import UnknownEffectError
    from skysim.exceptions import (InvalidParameterError, MissingFileError, NaiveDatetimeError,
                                   UnsupportedOperationError)
    from skysim.io import JsonValueError, OutputPathError
    assert issubclass(UnknownEffectError, DiagnosisError)
    assert issubclass(UnknownEffectError, ValueError)
    assert issubclass(InvalidParameterError, ValueError)
    assert issubclass(NaiveDatetimeError, ValueError)
    assert issubclass(MissingFileError, FileNotFoundError)
    assert issubclass(OutputPathError, OSError)
    assert issubclass(UnsupportedOperationError, NotImplementedError)
    assert issubclass(JsonValueError, TypeError)


def test_the_root_is_exported_and_cheap():
    assert skysim.SkysimError is SkysimError and skysim.SkysimWarning is SkysimWarning
    assert {"SkysimError", "SkysimWarning"} <= set(skysim.__all__)
    assert "SkysimError" in (skysim.__doc__ or "")
    # the lazy namespace: the root does not import the sun's dependencies
    code = ("import sys; from skysim import SkysimError, SkysimWarning; "
            "print(sorted(m for m in ('pandas', 'scipy', 'pysolar') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


# ---------------------------------------------------------------- (c) bad inputs, one clause


def _naive_times():
    from skysim import sun_position
    return sun_position(pd.DatetimeIndex(["2013-05-22 10:00"]), 34.1, 108.5)


def _bad_lens():
    from sensor.camera.lens import FisheyeLens
    return FisheyeLens(focal_px=100.0, cx=50.0, cy=50.0, fov_deg=180.0, model="pinhole")


def _bad_demosaic():
    from sensor.camera.demosaic import demosaic_operator
    return demosaic_operator(np.ones((2, 2, 3)), method="magic")


def _bad_pair():
    from calibration.solve import pair_index
    return pair_index((1, 1))


def _bad_on_failure():
    from calibration.lsq import fit_pairs
    return fit_pairs(np.zeros(4), np.zeros((4, 3)), dop=0.5, on_failure="ignore")


def _bad_effect():
    from calibration.effects import get_effect
    return get_effect("tilt2")


def _missing_table(tmp_path):
    from sensor.measurement import read_measurement
    return read_measurement(tmp_path / "nowhere.csv")


def _unjsonable(tmp_path):
    from skysim.io import write_json_atomic
    return write_json_atomic(tmp_path / "x.json", {"when": {1, 2}})


def _bad_flip():
    from sensor.camera.files import undo_readout
    return undo_readout(np.zeros((2, 2), np.uint16), flip="diagonal")


def _bad_backend():
    from experiments.workflows.sweep_backends import run_tasks
    return run_tasks(print, [], backend="mpi")


def _bad_method():
    from skysim import sun_position
    return sun_position(pd.DatetimeIndex(["2013-05-22 10:00+08:00"]), 34.1, 108.5,
                        method="fast")


def _bad_site_value():
    from skysim import Site
    return Site.from_dict({"latitude_deg": "north", "longitude_deg": 108.5})


def _bad_band():
    from skysim.bands import get_band
    return get_band("Q")


def _bad_preset():
    from skysim.aerosol_types import aerosol_type
    return aerosol_type("smog")


def _text_latitude():
    from skysim import sun_position
    return sun_position(pd.DatetimeIndex(["2013-05-22 10:00+08:00"]), "north", 108.5)


def _unreadable_time():
    from skysim import sun_position
    return sun_position(["yesterday"], 34.1, 108.5)


def _shapes_apart():
    return skysim.make_sky("rayleigh").field(np.full(3, 45.0), np.zeros(2), 30.0, 100.0)


def _text_ring():
    from sensor import ring_configuration
    return ring_configuration("six")


CASES = {
    "unknown sky model": (lambda tmp: skysim.make_sky("foo"), "'foo'"),
    "naive time": (lambda tmp: _naive_times(), "2013-05-22 10:00:00"),
    "latitude out of range": (lambda tmp: skysim.Site(95.0, 0.0), "95.0"),
    "site value not a number": (lambda tmp: _bad_site_value(), "'north'"),
    "unknown band": (lambda tmp: _bad_band(), "'Q'"),
    "unknown aerosol preset": (lambda tmp: _bad_preset(), "'smog'"),
    "unknown sun method": (lambda tmp: _bad_method(), "'fast'"),
    "unknown lens model": (lambda tmp: _bad_lens(), "'pinhole'"),
    "unknown demosaicing": (lambda tmp: _bad_demosaic(), "'magic'"),
    "unknown readout flip": (lambda tmp: _bad_flip(), "'diagonal'"),
    "one channel twice": (lambda tmp: _bad_pair(), "(1, 1)"),
    "unknown failure policy": (lambda tmp: _bad_on_failure(), "'ignore'"),
    "unknown effect": (lambda tmp: _bad_effect(), "'tilt2'"),
    "missing data file": (_missing_table, "nowhere.csv"),
    "metadata without JSON form": (_unjsonable, "set"),
    "unknown sweep backend": (lambda tmp: _bad_backend(), "'mpi'"),
    "latitude as text": (lambda tmp: _text_latitude(), "'north'"),
    "d_max as text": (lambda tmp: skysim.make_sky("rayleigh", dmax="high"), "'high'"),
    "time that is not a time": (lambda tmp: _unreadable_time(), "'yesterday'"),
    "shapes that do not broadcast": (lambda tmp: _shapes_apart(), "(3,), (2,)"),
    "ring of text units": (lambda tmp: _text_ring(), "'six'"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_is_caught_by_the_root(case, tmp_path):
    call, named = CASES[case]
    try:
        call(tmp_path)
    except skysim.SkysimError as exc:
        message = str(exc)
    else:
        pytest.fail(f"{case}: accepted")
    assert named in message, message
    assert "\n" not in message
    assert not list(tmp_path.iterdir())   # nothing written on the way


def test_unknown_effect_is_a_diagnosis_error():
    from calibration.diagnosis import DiagnosisError
    with pytest.raises(DiagnosisError, match="'tilt2'"):
        _bad_effect()


def test_warnings_share_the_root():
    from sensor.illuminance import WATER_TYPES, check_validated_depth
    water = next(iter(WATER_TYPES))
    with pytest.warns(SkysimWarning, match=r"depth_m 470\.0 m"):
        check_validated_depth(470.0, water)


# ------------------------------------------------------------------- (d) input-file columns


def _measurement_csv(path: Path, header: str) -> Path:
    rows = ["2013-05-22T17:10:00+08:00,10.0,0.1,-0.1,0.05",
            "2013-05-22T17:10:15+08:00,20.0,0.1,-0.1,0.05"]
    path.write_text("\n".join([header] + rows) + "\n")
    path.with_name(path.name + ".json").write_text(json.dumps({
        "schema": "skysim.measurement/1",
        "site": {"latitude_deg": 34.1, "longitude_deg": 108.5, "altitude_m": 400.0}}))
    return path


def test_a_repeated_csv_column_is_refused_naming_it(tmp_path):
    from sensor.measurement import read_measurement
    good = _measurement_csv(tmp_path / "good.csv", "time,heading_deg,U1_V,U2_V,U3_V")
    assert len(read_measurement(good).table) == 2
    # pandas would read the second U1_V as 'U1_V.1' and the reader use the first one
    bad = _measurement_csv(tmp_path / "bad.csv", "time,heading_deg,U1_V,U1_V,U3_V")
    with pytest.raises(SkysimError, match=r"bad\.csv: column 'U1_V' appears 2 times"):
        read_measurement(bad)
    quoted = _measurement_csv(tmp_path / "quoted.csv", 'time,heading_deg,U1_V,"U1_V",U3_V')
    with pytest.raises(SkysimError, match="column 'U1_V' appears 2 times"):
        read_measurement(quoted)


def test_a_repeated_column_in_a_compressed_csv_is_refused(tmp_path):
    from skysim.exceptions import FileFormatError
    from skysim.io import check_csv_header
    path = tmp_path / "t.csv.gz"
    with gzip.open(path, "wt") as f:
        f.write("mu,phi,mu\n1,2,3\n")
    with pytest.raises(FileFormatError, match=r"t\.csv\.gz: column 'mu' appears 2 times"):
        check_csv_header(path)
    with gzip.open(path, "wt") as f:
        f.write("mu,phi,I\n1,2,3\n")
    check_csv_header(path)   # distinct names pass


def test_a_table_with_a_repeated_column_is_not_written(tmp_path):
    from sensor.tables import write_table_and_sidecar
    table = pd.DataFrame([[1.0, 2.0]], columns=["a", "a"])
    with pytest.raises(SkysimError, match="column 'a' twice"):
        write_table_and_sidecar(table, {}, tmp_path / "t.csv")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("edit,named", [
    (lambda s: s["site"].update(latitude_deg=95), "latitude_deg"),
    (lambda s: s["site"].update(altitude_m="high"), "altitude_m must be a number; got 'high'"),
    (lambda s: s.update(sensor=[1]), "'sensor' must be an object"),
    (lambda s: s.update(generator=5), "'generator' must be an object"),
])
def test_measurement_sidecar_fields_are_named(tmp_path, edit, named):
    from sensor.measurement import read_measurement
    path = _measurement_csv(tmp_path / "m.csv", "time,heading_deg,U1_V,U2_V,U3_V")
    side = path.with_name("m.csv.json")
    doc = json.loads(side.read_text())
    edit(doc)
    side.write_text(json.dumps(doc))
    with pytest.raises(SkysimError) as err:
        read_measurement(path)
    assert named in str(err.value) and "m.csv" in str(err.value)


# ------------------------------------------------------------------ the command line on top


@pytest.mark.parametrize("raised,code,line", [
    (lambda: skysim.exceptions.InvalidParameterError("flip 'x' is wrong"), 2,
     "skysim camera-heading: error: flip 'x' is wrong"),
    (lambda: skysim.exceptions.MissingFileError("no raw image a.png"), 2,
     "skysim camera-heading: error: no raw image a.png"),
    (lambda: RuntimeError("an invariant broke"), 70,
     "skysim camera-heading: internal error: RuntimeError: an invariant broke"),
])
def test_the_command_line_catches_the_root(tmp_path, monkeypatch, capsys, raised, code, line):
    """A SkysimError (whatever its built-in base) is one line with exit 2; a bare built-in
    RuntimeError is a bug: the internal-error line and exit 70."""
    from experiments.cli.main import main
    from sensor.camera import files

    def fail(*args, **kwargs):
        raise raised()
    monkeypatch.setattr(files, "read_raw", fail)
    monkeypatch.delenv("SKYSIM_TRACEBACK", raising=False)
    image = tmp_path / "a.png"
    image.write_bytes(b"\x89PNG")
    assert main(["camera-heading", str(image)]) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(line)
