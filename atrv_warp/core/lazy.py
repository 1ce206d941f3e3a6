"""A package's names imported on first use (PEP 562): the package keeps a table of each name and its module, and
imports the module when the name is first asked for, so that importing the package loads nothing heavy. The top-level
package, :mod:`atrv_warp.sim` and :mod:`atrv_warp.core` each give their names so. Standard library only."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from importlib import import_module

__all__ = ["lazy_names"]


def lazy_names(package: str, exports: dict[str, str], names: Sequence[str]) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` for ``package``: a name of ``exports`` from its module (relative to the package),
    imported on first use; ``names``: what ``dir()`` lists (the package's ``__all__``)."""

    def __getattr__(name: str):
        if name in exports:
            return getattr(import_module(f"{package}.{exports[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return list(names)

    return __getattr__, __dir__
