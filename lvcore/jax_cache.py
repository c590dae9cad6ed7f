"""JAX's persistent compilation cache for everything lvcore compiles.

The simulator's Newton kernels, the emulators and the NUTS / HMC-within-Gibbs
samplers are all jit-compiled; with the cache on, a second process that
compiles the same program (same shapes, same constants) loads it from disk
instead of compiling it again. It is switched on when :mod:`lvcore` is
imported.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

#: Where compiled programs go unless ``LVCORE_JAX_CACHE`` says otherwise.
DEFAULT_JAX_CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "lvcore" / "jax"
#: Smallest compile time (s) of a program that is written to the cache. Zero: every program, also the many
#: small kernels of a solve that compile in well under a second each but add up to seconds per process
#: (a second ``lvcore campaign run`` and every campaign worker load them instead).
MIN_COMPILE_TIME_S = 0.0


def _set(option: str, value) -> None:
    """Set JAX's config ``option`` now if JAX is imported, else through the environment variable JAX reads."""
    if "jax" in sys.modules:
        sys.modules["jax"].config.update(option, value)
    else:
        os.environ[option.upper()] = str(value).lower() if isinstance(value, bool) else str(value)


def enable_x64() -> None:
    """Switch JAX to float64 (the simulator needs it), without importing JAX where it is not imported yet."""
    _set("jax_enable_x64", True)


def enable_compilation_cache(path: str | os.PathLike | None = None) -> str | None:
    """Turn on JAX's persistent compilation cache.

    Does not import JAX: where it is not imported yet the settings go into the environment
    variables it reads on import (and that child processes inherit).

    Parameters
    ----------
    path : path, optional
        Cache directory; default ``LVCORE_JAX_CACHE`` or
        ``$XDG_CACHE_HOME/lvcore/jax`` (``~/.cache/lvcore/jax``). The value
        ``off`` (in ``path`` or ``LVCORE_JAX_CACHE``) disables the cache.

    Returns
    -------
    str or None
        The directory used, or None when disabled or not writable.
    """
    path = str(path or os.environ.get("LVCORE_JAX_CACHE") or DEFAULT_JAX_CACHE)
    if path.lower() == "off":
        if "jax" not in sys.modules:  # nor the cache a parent process that imported lvcore passed on
            os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
        return None
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
        _set("jax_compilation_cache_dir", path)
        _set("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)
        _set("jax_persistent_cache_min_entry_size_bytes", 0)
    except Exception:  # noqa: BLE001 - read-only home etc.: the cache is an optimisation only
        return None
    return path
