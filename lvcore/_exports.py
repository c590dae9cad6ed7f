"""Lazy public APIs for the subpackages' ``__init__`` modules (PEP 562).

A subpackage lists its public names in ``__all__`` and maps each to the
submodule that defines it; the submodule is imported on first use, so
``import lvcore.viz`` does not pull in Plotly and PyVista, and importing a
subpackage never creates import cycles between layers.

Names that moved keep working for a while: :func:`moved_names` gives a module
the ``__getattr__`` that forwards an old name to its new home with a
``DeprecationWarning``, and :func:`renamed_keywords` lets a function accept a
keyword's old spelling the same way.
"""
from __future__ import annotations

import functools
import importlib
import warnings
from typing import Callable, Mapping


def lazy_exports(package: str, namespace: dict, exports: Mapping[str, str],
                 moved: Mapping[str, str] | None = None) -> tuple[Callable, Callable]:
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
    moved : mapping, optional
        Names the package exported before they moved, as for :func:`moved_names`
        (old name -> ``"package.module:name"``); they resolve with a
        ``DeprecationWarning`` and are not cached or listed.
    """
    forward_moved = moved_names(package, moved) if moved else None

    def __getattr__(name: str):
        if forward_moved is not None and name in moved:
            return forward_moved(name)
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


def moved_names(module: str, moved: Mapping[str, str]) -> Callable:
    """A module ``__getattr__`` (PEP 562) for public names that moved to another home.

    Parameters
    ----------
    module : str
        The old home's ``__name__``.
    moved : mapping
        Old name -> new home as ``"package.module:name"``. Reading the old name
        imports the new home and returns its value with a ``DeprecationWarning``
        that names the new home.
    """

    def __getattr__(name: str):
        try:
            home, _, new = moved[name].partition(":")
        except KeyError:
            raise AttributeError(f"module {module!r} has no attribute {name!r}") from None
        warnings.warn(f"{module}.{name} is deprecated; use {home}.{new}", DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(home), new)

    return __getattr__


def renamed_keywords(**renamed: str) -> Callable:
    """Decorator: the function still accepts old keyword names (``old="new"``) with a ``DeprecationWarning``.

    Giving a keyword under both names is a ``TypeError``, as for any keyword given twice.
    """

    def decorate(fn: Callable) -> Callable:
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            for old, new in renamed.items():
                if old in kwargs:
                    if new in kwargs:
                        raise TypeError(f"{fn.__name__}() got {new!r} and its old name {old!r}; give {new!r} only")
                    warnings.warn(f"{fn.__name__}({old}=...) is deprecated; use {new}=", DeprecationWarning,
                                  stacklevel=2)
                    kwargs[new] = kwargs.pop(old)
            return fn(*args, **kwargs)

        return wrapper

    return decorate
