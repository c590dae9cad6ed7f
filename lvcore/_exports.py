"""Lazy public APIs for the subpackages' ``__init__`` modules (PEP 562).

A subpackage lists its public names in ``__all__`` and maps each to the
submodule that defines it; the submodule is imported on first use, so
``import lvcore.viz`` does not pull in Plotly and PyVista, and importing a
subpackage never creates import cycles between layers.

Names that moved keep working for a while: :func:`moved_names` gives a module
the ``__getattr__`` that forwards an old name to its new home with a
``DeprecationWarning``, :func:`renamed_keywords` lets a function accept a
keyword's old spelling the same way, and :func:`install_moved_modules` (called
by ``lvcore/__init__.py``) lets the old import path of a module that moved into
a subpackage (:data:`MOVED_MODULES`) import the module at its new path.
"""
from __future__ import annotations

import functools
import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from typing import Callable, Mapping

#: Modules that moved into a subpackage: old import path -> new one. ``import lvcore.limits`` (or
#: ``from lvcore import limits``) still works and gives the module at its new path, with a ``DeprecationWarning``
#: that names it (:func:`install_moved_modules`).
MOVED_MODULES = {
    "lvcore.bounded_cache": "lvcore.execution.bounded_cache",
    "lvcore.chains": "lvcore.execution.chains",
    "lvcore.conditions": "lvcore.domain.conditions",
    "lvcore.headers": "lvcore.safety.headers",
    "lvcore.isolation": "lvcore.safety.isolation",
    "lvcore.jax_cache": "lvcore.execution.jax_cache",
    "lvcore.limits": "lvcore.safety.limits",
    "lvcore.outputs": "lvcore.domain.outputs",
    "lvcore.parallel": "lvcore.execution.parallel",
    "lvcore.physiology": "lvcore.domain.physiology",
    "lvcore.units": "lvcore.domain.units",
    "lvcore.uploads": "lvcore.app.uploads",
}


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


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Import finder and loader for the old paths of :data:`MOVED_MODULES`: the module itself, at its new path.

    The old path's entry in ``sys.modules`` and its attribute on the parent package are the new module object
    (one module, one state: patching either name patches both).
    """

    def __init__(self, moved: Mapping[str, str]):
        self.moved = dict(moved)

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in self.moved:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec):
        new = self.moved[spec.name]
        warnings.warn(f"the module {spec.name} moved to {new}; import {new}", DeprecationWarning, stacklevel=2)
        module = importlib.import_module(new)
        spec.loader_state = module.__spec__  # the import system sets __spec__ to the old path's: put it back
        return module

    def exec_module(self, module):
        module.__spec__ = module.__spec__.loader_state


def install_moved_modules(moved: Mapping[str, str] = MOVED_MODULES) -> None:
    """Let the old import paths of ``moved`` (old -> new module name) import the moved modules.

    Idempotent: a finder is put first on ``sys.meta_path`` once per process (``lvcore/__init__.py`` calls this,
    so any ``import lvcore.<old>`` finds it, the package being imported first).
    """
    if not any(isinstance(f, _MovedModuleFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _MovedModuleFinder(moved))
