"""Lazy package namespaces (PEP 562): a package's public names are imported
from their modules on first use, so importing a package costs nothing until a
name is used (the plugin protocol must not start Taichi)."""

from __future__ import annotations

import importlib


def lazy_exports(package: str, exports: dict[str, tuple[str, ...]], modules: dict[str, str] | None = None):
    """``__getattr__``, ``__dir__`` and ``__all__`` for ``package``: ``exports``
    maps a module (relative to the package, e.g. ``".body.scene"``) to the names
    taken from it; ``modules`` maps a public name to a module that it stands for."""
    where = {name: module for module, names in exports.items() for name in names}
    modules = dict(modules or {})

    def __getattr__(name: str):
        if name in where:
            value = getattr(importlib.import_module(where[name], package), name)
        elif name in modules:
            value = importlib.import_module(modules[name], package)
        else:
            raise AttributeError(f"module '{package}' has no attribute '{name}'")
        globals_of(package)[name] = value  # later lookups skip __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(globals_of(package)) | set(where) | set(modules))

    return __getattr__, __dir__, sorted(where)


def globals_of(package: str) -> dict:
    return vars(importlib.import_module(package))
