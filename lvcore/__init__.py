"""LV Calibration Lab core package.

Importing :mod:`lvcore` switches JAX to float64 (the simulator needs it) before
any array is created, and turns on JAX's persistent compilation cache
(:mod:`lvcore.execution.jax_cache`; ``LVCORE_JAX_CACHE=off`` disables it). It does not
import JAX itself (``lvcore --help`` and commands that never compute start in a
fraction of a second): where JAX is not imported yet, both settings go into the
environment variables JAX reads when it is imported (``JAX_ENABLE_X64``,
``JAX_COMPILATION_CACHE_DIR``, ...), which worker processes inherit too.

Modules that moved into a subpackage keep their old import paths for a while
(``lvcore.limits`` is ``lvcore.safety.limits``, with a ``DeprecationWarning``;
:data:`lvcore._exports.MOVED_MODULES` lists them).
"""
from __future__ import annotations

from lvcore._exports import install_moved_modules
from lvcore.execution.jax_cache import enable_compilation_cache, enable_x64

install_moved_modules()

enable_x64()
enable_compilation_cache()

__version__ = "0.2.0"


def simulate(case, **options):
    """Run one forward simulation; see :func:`lvcore.mechanics.simulate.simulate`
    (``options`` such as ``with_sensitivities=True`` are passed through)."""
    from lvcore.mechanics.simulate import simulate as _simulate

    return _simulate(case, **options)


def load_case(path):
    """Read and validate a case file; see :func:`lvcore.mechanics.case.load_case`."""
    from lvcore.mechanics.case import load_case as _load_case

    return _load_case(path)


__all__ = ["simulate", "load_case", "__version__"]
