"""The layers of :mod:`experiments`, read from the source with :mod:`ast`: the command line
(``experiments/cli/``) sits on top and nothing else imports it; a workflow never imports a
study; and no module takes another module's private names.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "experiments"
MODULES = sorted(PACKAGE.rglob("*.py"))


def _module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, root: Path = ROOT) -> list[tuple[str, list[str], int]]:
    """``(absolute module, imported names, line)`` of every import in ``path`` (a module
    under ``root``), at any depth (imports inside functions count); relative imports resolved
    against the module."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = _module_name(path, root).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(a.name, [], node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            found.append((module, [a.name for a in node.names], node.lineno))
    return found


def _where(path: Path, line: int) -> str:
    return f"{path.relative_to(ROOT)}:{line}"


def test_the_modules_are_found():
    names = {_module_name(p) for p in MODULES}
    assert {"experiments.cli.main", "experiments.workflows.options",
            "experiments.studies.camera"} <= names


def test_resolves_relative_imports(tmp_path):
    """The reader of the test itself: ``from .x import y`` in a subpackage's module and in a
    package's ``__init__`` resolve to the absolute module."""
    pkg = tmp_path / "experiments" / "workflows"
    pkg.mkdir(parents=True)
    (pkg / "m.py").write_text("from .options import a\nfrom ..studies import b\n")
    (pkg / "__init__.py").write_text("from .m import c\n")
    assert [m for m, _, _ in _imports(pkg / "m.py", tmp_path)] == [
        "experiments.workflows.options", "experiments.studies"]
    assert [m for m, _, _ in _imports(pkg / "__init__.py", tmp_path)] == [
        "experiments.workflows.m"]


@pytest.mark.parametrize("path", [p for p in MODULES
                                  if "cli" not in p.relative_to(PACKAGE).parts],
                         ids=lambda p: str(p.relative_to(PACKAGE)))
def test_nothing_below_the_command_line_imports_it(path):
    bad = [_where(path, line) + f" imports {m}" for m, names, line in _imports(path)
           if m == "experiments.cli" or m.startswith("experiments.cli.")
           or (m == "experiments" and "cli" in names)]
    assert not bad, bad


@pytest.mark.parametrize("path", sorted((PACKAGE / "workflows").glob("*.py")),
                         ids=lambda p: p.name)
def test_no_workflow_imports_a_study(path):
    bad = [_where(path, line) + f" imports {m}" for m, names, line in _imports(path)
           if m == "experiments.studies" or m.startswith("experiments.studies.")
           or (m == "experiments" and "studies" in names)]
    assert not bad, bad


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_takes_another_modules_private_names(path):
    bad = [_where(path, line) + f" takes {n} from {m}" for m, names, line in _imports(path)
           if m.startswith("experiments") for n in names
           if n.startswith("_") and not n.startswith("__")]
    assert not bad, bad
