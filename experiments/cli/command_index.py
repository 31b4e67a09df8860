"""Which module of :mod:`experiments` (or of its subpackages) defines which ``skysim``
sub-command, read without importing the modules.

Building the full parser imports every command module, and with them numpy, pandas, scipy
and the sky models: about a second before ``skysim --help`` prints anything. This index reads
only the ``register``/``register_reproduce`` functions of each module's source (a few
milliseconds), so that the command line imports just the module whose command runs, and
``--help`` lists every command from the index alone. A module whose registration cannot be
read statically (a computed command name) is simply imported, as before.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["CommandIndex", "read_index"]

_FUNCTION = re.compile(r"^def (register|register_reproduce)\(.*?(?=^\S|\Z)", re.M | re.S)


@dataclass
class CommandIndex:
    """Sub-commands and reproduce targets of the command modules, by module name."""

    commands: dict[str, tuple[str, str | None]] = field(default_factory=dict)
    """command name -> (module name, help text or None)"""
    reproduce_modules: list[str] = field(default_factory=list)
    """modules that add ``reproduce`` targets"""
    unreadable: list[str] = field(default_factory=list)
    """modules whose registration must be imported to be known"""

    def modules_for(self, command: str | None) -> list[str] | None:
        """Modules to import for ``command``; None means all (an unknown command or name)."""
        if command == "reproduce":
            return sorted(set(self.reproduce_modules) | set(self.unreadable))
        if command is None:
            return list(self.unreadable)
        if command in self.commands:
            return sorted({self.commands[command][0], *self.unreadable})
        return None


def _literal(node) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def read_index(package_dir: Path, module_names) -> CommandIndex:
    """Scan the source of each module name (relative to ``package_dir``, dotted for a
    subpackage's module: ``"workflows.sweep"`` is ``package_dir/workflows/sweep.py``); see the
    module docstring."""
    index = CommandIndex()
    for name in module_names:
        source = (package_dir.joinpath(*name.split(".")).with_suffix(".py")
                  .read_text(encoding="utf-8"))
        for match in _FUNCTION.finditer(source):
            try:
                tree = ast.parse(match.group(0))
            except SyntaxError:
                index.unreadable.append(name)
                break
            if match.group(1) == "register_reproduce":
                index.reproduce_modules.append(name)
                continue
            calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
                     and isinstance(n.func, ast.Attribute) and n.func.attr == "add_parser"]
            names = [_literal(c.args[0]) if c.args else None for c in calls]
            if not calls or None in names:
                index.unreadable.append(name)
                break
            for call, command in zip(calls, names):
                help_text = next((_literal(k.value) for k in call.keywords if k.arg == "help"),
                                 None)
                index.commands[command] = (name, help_text)
    return index
