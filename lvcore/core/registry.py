"""The allow-list of named forward models that campaign stores may refer to.

A campaign store records the *name* of its forward model (e.g.
``"simulator"``), never code: ``lvcore campaign resume`` looks the name up
here and refuses anything it does not know. Users add their own forward
models in code, before running or resuming a campaign::

    from lvcore.core import register_forward
    register_forward("my-model", lambda space, resolution: MyForward(space.names))

A factory takes the campaign's :class:`~lvcore.core.space.ParameterSpace`
and resolution preset and returns a :class:`~lvcore.core.forward.Forward`
whose ``input_names`` are ``space.names`` (the fixed inputs of the space are
bound in). The forward object travels to worker processes by pickling, so it
must be picklable (a module-level class, not a lambda).

Stores written before this registry recorded ``"lvcore:simulate"``; that
exact string is read as ``"simulator"``. Any other ``"module:function"``
string is refused: a data file never chooses which code runs.
"""
from __future__ import annotations

import re
from typing import Callable

from lvcore.exceptions import CampaignError

#: (space, resolution) -> Forward.
ForwardFactory = Callable[..., object]

#: The default forward model of a campaign.
DEFAULT_FORWARD_NAME = "simulator"
#: Exact legacy store attributes and the names they stand for.
LEGACY_FORWARD_NAMES = {"lvcore:simulate": DEFAULT_FORWARD_NAME}
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


#: Name -> factory. The default, ``"simulator"``, is registered by the simulator adapter
#: (:mod:`lvcore.mechanics.forward`, imported by the campaign runner): this layer knows no implementation.
_REGISTRY: dict[str, ForwardFactory] = {}


def register_forward(name: str, factory: ForwardFactory, *, overwrite: bool = False) -> None:
    """Allow campaigns to use forward model ``name``, built by ``factory(space, resolution)``.

    Raises
    ------
    CampaignError
        If the name is malformed (letters, digits, ``_ . -``; no ``:``), the
        factory is not callable, or the name is taken and ``overwrite`` is False.
    """
    if not isinstance(name, str) or not _NAME.match(name):
        raise CampaignError(f"forward name {name!r}: use 1-64 letters, digits, '_', '.' or '-' (no ':')")
    if not callable(factory):
        raise CampaignError(f"forward '{name}': the factory must be callable (space, resolution) -> Forward")
    if name in _REGISTRY and not overwrite and _REGISTRY[name] is not factory:
        raise CampaignError(f"forward '{name}' is already registered; pass overwrite=True to replace it")
    _REGISTRY[name] = factory


def forward_names() -> tuple[str, ...]:
    """Names of the registered forward models."""
    return tuple(sorted(_REGISTRY))


def registered_name(name: str) -> str:
    """The registered name that ``name`` (from a store or the command line) stands for.

    Maps the legacy ``"lvcore:simulate"`` to ``"simulator"``.

    Raises
    ------
    CampaignError
        If the name is not registered (e.g. a ``"module:function"`` string).
    """
    key = LEGACY_FORWARD_NAMES.get(str(name), str(name))
    if key not in _REGISTRY:
        hint = (" Forward models are no longer imported from a 'module:function' string; register yours in code "
                "with lvcore.core.register_forward(name, factory) and use its name.") if ":" in str(name) else ""
        raise CampaignError(f"unknown forward model {str(name)!r}; registered: {', '.join(forward_names())}.{hint}")
    return key


def make_forward(name: str, space, resolution: str = "default"):
    """Build registered forward model ``name`` for a campaign over ``space`` at ``resolution``."""
    key = registered_name(name)
    fwd = _REGISTRY[key](space, resolution)
    names = tuple(getattr(fwd, "input_names", ()))
    if set(names) != set(space.names) or not callable(getattr(fwd, "evaluate", None)):
        raise CampaignError(f"forward '{key}' does not read the space's inputs {list(space.names)} (it reads "
                            f"{list(names)}; its factory must return a Forward with input_names = space.names)")
    return fwd


__all__ = ["register_forward", "forward_names", "registered_name", "make_forward", "DEFAULT_FORWARD_NAME",
           "LEGACY_FORWARD_NAMES", "ForwardFactory"]
