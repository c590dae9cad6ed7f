"""The app's process set-up: one call, once, before numpy, VTK or JAX start.

:func:`setup_process` is called by the entry script (:mod:`lvcore.app.main`)
before anything else is imported; the pages do no set-up of their own. The
test suite does the same in ``tests/conftest.py``.
"""
from __future__ import annotations

import os

from lvcore._exports import moved_names
from lvcore.execution.parallel import pin_threads

#: Chains a calibration from the app runs; each gets its own XLA host device.
APP_CHAINS = 4


def setup_process(num_chains: int = APP_CHAINS) -> None:
    """Pin BLAS/OpenMP to one thread (:func:`lvcore.execution.parallel.pin_threads`), render VTK off-screen with EGL, and give each calibration chain an XLA
    host device (:func:`lvcore.inference.samplers.use_host_devices`). Under an address-space limit
    (``ulimit -v``) it also drops the reservations that hold no data (:func:`lvcore.app.memory.economise`).

    Values already set in the environment are kept. Has an effect only before numpy and JAX start, so the
    entry script calls it first.
    """
    pin_threads()
    from lvcore.app import memory

    if memory.address_space_limit() != float("inf"):
        memory.economise()
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    from lvcore.inference.samplers import use_host_devices

    use_host_devices(num_chains)
    serialise_ast_parse()


def serialise_ast_parse() -> None:
    """Let one thread at a time turn source into an AST (``ast.parse``) in this process.

    CPython 3.11 keeps the AST converter's recursion depth per interpreter, not per thread, so two threads
    parsing at once can fail with ``SystemError: AST constructor recursion depth mismatch``. In the app server
    Streamlit parses page scripts on one session's thread while another session's script runs; seen
    2026-12-02 in the My subject browser test, where it stopped the whole server. Idempotent.
    """
    import ast
    import threading

    if getattr(ast.parse, "_lvcore_serialised", False):
        return
    lock = threading.RLock()
    original = ast.parse

    def parse(*args, **kwargs):
        with lock:
            return original(*args, **kwargs)

    parse.__doc__ = original.__doc__
    parse._lvcore_serialised = True
    ast.parse = parse


__getattr__ = moved_names(__name__, {"THREAD_VARIABLES": "lvcore.execution.parallel:THREAD_VARIABLES"})

__all__ = ["APP_CHAINS", "setup_process", "serialise_ast_parse"]
