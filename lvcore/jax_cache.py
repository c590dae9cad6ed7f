"""JAX's persistent compilation cache for everything lvcore compiles.

The simulator's Newton kernels, the emulators and the NUTS / HMC-within-Gibbs
samplers are all jit-compiled; with the cache on, a second process that
compiles the same program (same shapes, same constants) loads it from disk
instead of compiling it again. It is switched on when :mod:`lvcore` is
imported.
"""
from __future__ import annotations

import os
from pathlib import Path

import jax

#: Where compiled programs go unless ``LVCORE_JAX_CACHE`` says otherwise.
DEFAULT_JAX_CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "lvcore" / "jax"


def enable_compilation_cache(path: str | os.PathLike | None = None) -> str | None:
    """Turn on JAX's persistent compilation cache.

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
        return None
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", path)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except Exception:  # noqa: BLE001 - read-only home etc.: the cache is an optimisation only
        return None
    return path
