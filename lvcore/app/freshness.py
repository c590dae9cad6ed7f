"""Results that remember the inputs they were computed with, and say so when the inputs move on.

A page stores a result with :func:`remember` (in ``st.session_state``, with its
input signature) and shows it inside :func:`shown`: the block states the
inputs it was computed with, and when the current inputs differ it is greyed
out under an "inputs changed, re-run" warning naming what changed. A result is
never credited to parameters it was not computed with.

The comparison (:func:`changed_inputs`, :func:`describe`) is pure and needs no
Streamlit.
"""
from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

#: Opacity of a stale result.
STALE_OPACITY = 0.35


@dataclass(frozen=True)
class Stored:
    """A result and the inputs it was computed with."""

    result: Any
    inputs: Mapping[str, Any]


def _same(x, y) -> bool:
    if isinstance(x, float) or isinstance(y, float):
        try:
            return math.isclose(float(x), float(y), rel_tol=1e-12, abs_tol=1e-12)
        except (TypeError, ValueError):
            return False
    if isinstance(x, (list, tuple)) and isinstance(y, (list, tuple)):
        return len(x) == len(y) and all(_same(a, b) for a, b in zip(x, y))
    if isinstance(x, Mapping) and isinstance(y, Mapping):
        return set(x) == set(y) and all(_same(x[k], y[k]) for k in x)
    return x == y


def changed_inputs(old: Mapping[str, Any], new: Mapping[str, Any]) -> list[str]:
    """Names of the inputs whose value differs between ``old`` and ``new`` (missing counts as changed)."""
    return [k for k in dict.fromkeys([*old, *new]) if k not in old or k not in new or not _same(old[k], new[k])]


def _fmt(v) -> str:
    """A value as the user reads it: never Python's ``True``/``False``/``None`` (yes, no, –), nor an empty ``{}``/``[]``
    (none)."""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple, Mapping)) and not len(v):
        return "none"
    if isinstance(v, (list, tuple)):
        return "(" + ", ".join(_fmt(x) for x in v) + ")" if len(v) <= 6 else f"{len(v)} values"
    if isinstance(v, Mapping):
        return ", ".join(f"{k} {_fmt(x)}" for k, x in v.items())
    return str(v)


def describe(inputs: Mapping[str, Any]) -> str:
    """One line naming every input and its value, e.g. ``a (kPa) 0.6; EDP (mmHg) 8``."""
    return "; ".join(f"{k} {_fmt(v)}" for k, v in inputs.items())


def remember(key: str, result: Any, inputs: Mapping[str, Any]) -> None:
    """Store ``result`` with the ``inputs`` it was computed with under ``st.session_state[key]``."""
    import streamlit as st

    st.session_state[key] = Stored(result, dict(inputs))


def recall(key: str) -> Stored | None:
    """The stored result under ``key``, or None."""
    import streamlit as st

    value = st.session_state.get(key)
    return value if isinstance(value, Stored) else None


@contextlib.contextmanager
def shown(stored: Stored, current: Mapping[str, Any], key: str) -> Iterator[bool]:
    """Show a stored result in a block that states its inputs and greys out when they are stale.

    Yields True when the result is fresh (its inputs equal ``current``).
    """
    import streamlit as st

    changed = changed_inputs(stored.inputs, current)
    if changed:
        st.warning("Inputs changed, re-run: the result below was computed with different "
                   + ", ".join(changed) + ".", icon=":material/history:")
        st.html(f"<style>.st-key-stale_{key} {{opacity: {STALE_OPACITY}; filter: grayscale(1);}}</style>")
    box = st.container(key=f"fresh_{key}" if not changed else f"stale_{key}")
    box.caption("Computed with: " + describe(stored.inputs))
    with box:
        yield not changed


def readable(v) -> str:
    """One value as the user reads it (as in :func:`describe`): yes/no, – for no value, none for an empty set."""
    return _fmt(v)


__all__ = ["Stored", "STALE_OPACITY", "changed_inputs", "describe", "readable", "remember", "recall", "shown"]
