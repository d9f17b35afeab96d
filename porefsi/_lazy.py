"""Lazy re-exports for package ``__init__`` modules (PEP 562).

Importing one module of a package (e.g. ``porefsi.flow.fluids``) then does not import the whole
package's dependencies (scikit-fem, numba, pyvista, matplotlib) before they are needed.
"""

from __future__ import annotations

import importlib

__all__ = ["exports"]


def exports(package: str, names: dict[str, str]):
    """``(__getattr__, __dir__)`` for ``package`` resolving each name from its module on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__`` (for error messages).
    names : dict
        Public name -> module that defines it.
    """

    def __getattr__(name: str):  # noqa: N807
        mod = names.get(name)
        if mod is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(mod), name)
        return value

    def __dir__():  # noqa: N807
        return sorted(names)

    return __getattr__, __dir__
