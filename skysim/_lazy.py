"""Lazy package namespaces (PEP 562): ``import skysim`` stays cheap.

A package lists its public names and the submodule that defines each; a name's submodule is
imported on first access (``skysim.sun_position`` imports pandas and pysolar then, not when
``skysim.sky`` is imported by a command that never needs the sun).
"""

from __future__ import annotations

import importlib

__all__ = ["lazy_namespace"]


def lazy_namespace(package: str, exports: dict[str, str]):
    """Return ``(__getattr__, __dir__)`` for ``package`` from ``{name: ".submodule"}``."""
    def __getattr__(name: str):
        if name not in exports:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(exports[name], package), name)
        setattr(importlib.import_module(package), name, value)  # later lookups skip this
        return value

    def __dir__():
        return sorted(set(vars(importlib.import_module(package))) | set(exports))

    return __getattr__, __dir__
