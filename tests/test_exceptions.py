"""One exception root: every exception class skysim defines (warnings aside) derives from
:class:`skysim.exceptions.SkysimError` and keeps a built-in base (ValueError, RuntimeError,
OSError or ImportError) that says what kind of failure it is."""

import importlib
import pkgutil

import pytest

from skysim.exceptions import SkysimError

PACKAGES = ("skysim", "sensor", "calibration", "experiments")
BUILTIN_BASES = (ValueError, RuntimeError, OSError, ImportError)
OUTSIDE_THE_ROOT: dict = {}


def _exception_classes():
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
                        and not issubclass(obj, Warning) and obj is not SkysimError
                        and obj.__module__ == mod_name):
                    found[f"{mod_name}.{obj.__qualname__}"] = obj
    return found


CLASSES = _exception_classes()


def test_the_walk_found_the_known_families():
    names = set(CLASSES)
    for expected in ("skysim.exceptions.InvalidParameterError",
                     "calibration.exceptions.CalibrationError",
                     "calibration.diagnosis.errors.DiagnosisError",
                     "sensor.measurement.MeasurementFormatError",
                     "calibration.effects.UnknownEffectError"):
        assert expected in names


@pytest.mark.parametrize("name", sorted(CLASSES))
def test_every_exception_has_the_root_and_a_builtin_base(name):
    if name in OUTSIDE_THE_ROOT:
        pytest.skip(OUTSIDE_THE_ROOT[name])
    cls = CLASSES[name]
    assert issubclass(cls, SkysimError), name
    assert issubclass(cls, BUILTIN_BASES), name


def test_one_effect_unavailable_error():
    from calibration.diagnosis import EffectUnavailableError
    from calibration.effects import multiple_scattering
    assert multiple_scattering.EffectUnavailableError is EffectUnavailableError
    shared = [n for n, c in CLASSES.items() if c.__name__ == "EffectUnavailableError"
              and n not in OUTSIDE_THE_ROOT]
    assert shared == ["calibration.diagnosis.errors.EffectUnavailableError"]
