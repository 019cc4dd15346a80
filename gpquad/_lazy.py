"""Names of a package resolved on first use (PEP 562): importing the package, or one of its
modules, does not import what its public names need (pandas, sympy, the readers)."""

from __future__ import annotations

import importlib
import sys


def imported(module: str, name: str):
    """The attribute `name` of `module`, importing the module if it is not yet."""
    return getattr(importlib.import_module(module), name)


def lazy_attributes(package: str, homes: dict[str, str]):
    """A module-level __getattr__ for `package`: name -> the attribute of the same name of
    module homes[name], imported on first use and then kept in the package."""

    def __getattr__(name: str):
        if name not in homes:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = imported(homes[name], name)
        setattr(sys.modules[package], name, value)
        return value

    return __getattr__
