"""Lazy public APIs for the subpackages' ``__init__`` modules (PEP 562).

A subpackage lists its public names in ``__all__`` and maps each to the
submodule that defines it; the submodule is imported on first use, so
``import lvcore.viz`` does not pull in Plotly and PyVista, and importing a
subpackage never creates import cycles between layers.
"""
from __future__ import annotations

import importlib
from typing import Callable, Mapping


def lazy_exports(package: str, namespace: dict, exports: Mapping[str, str]) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` for ``package`` exporting ``exports``.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    namespace : dict
        The package's ``globals()``; resolved names are cached there.
    exports : mapping
        Public name -> submodule (relative to ``package``) that defines it; a
        name equal to its submodule exports the submodule itself.
    """

    def __getattr__(name: str):
        try:
            sub = exports[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        module = importlib.import_module(f"{package}.{sub}")
        value = module if name == sub else getattr(module, name)
        namespace[name] = value
        return value

    def __dir__():
        return sorted(set(namespace) | set(exports))

    return __getattr__, __dir__
