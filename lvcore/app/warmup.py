"""Warm the Calibration page when the app starts: its samplers and the verdict's best fit, compiled in the background.

A click on "Run calibration" traces, lowers and compiles (or loads from JAX's
persistent cache, :mod:`lvcore.execution.jax_cache`) two samplers and the verdict's
best fit before it samples: measured 2026-11-27 on the 2-core machine, with
the persistent cache warm, ≈ 2.6 CPU-s for iid, ≈ 5.2 CPU-s for the
discrepancy model and ≈ 6 CPU-s for the best fit (numpyro's model
initialisation). :func:`start` does that work once per server process, in a
daemon thread, for the page's defaults (the shared sidebar's subject and
emulator, :data:`lvcore.inference.samplers.INTERACTIVE`). The compiled
programs take the data, PC scores, EDP, angles and scale as arguments
(:func:`lvcore.inference.samplers.runtime_conditions`), so they serve every
subject of that emulator; the samplers are kept in the process
(:func:`lvcore.inference.samplers.precompile`), the best fit's programs in
:mod:`lvcore.inference.verdict`.

``LVCORE_APP_WARMUP=0`` turns it off (the test suite does).

Memory (:mod:`lvcore.app.memory`): the warm-up adds address space to the
server process (measured 2026-12-02 on the 2-core machine, persistent cache
warm: the data, emulator and iid sampler with the best fit +0.45 GB, the
discrepancy sampler +0.3 GB). Before loading and before each likelihood it
checks the room left (:func:`lvcore.app.memory.headroom_bytes`: under an
address-space limit, ``ulimit -v``, the room under it; else the memory
available) and stops, with a note the app shows in the sidebar
(:func:`note`), when less than :data:`STAGE_BYTES` plus
:data:`RESERVE_BYTES` (kept for the users' own simulations) is left: under a
tight limit the warm-up does less, or nothing, and the first calibration
compiles on the click instead. A failure inside the warm-up (a Python
exception, ``MemoryError`` included) only ends the warm-up.

Exit: a process that ends while the warm-up is compiling (a server stopped
during its first minute, a script that started the app's helpers) stops it
between stages. :func:`start` registers an exit handler (run before the
``atexit`` handlers, JAX's among them) that asks the thread to stop and waits
up to :data:`EXIT_WAIT_S` for it; a daemon thread still inside XLA when the
interpreter tears down aborted the process (SIGABRT, "exception not
rethrown") after its work was done.
"""
from __future__ import annotations

import os
import threading
import time

from lvcore.app import memory

#: The environment variable that turns the warm-up off (``0``).
ENV = "LVCORE_APP_WARMUP"
#: Likelihoods warmed: the Calibration page's default selection.
MODELS = ("iid", "discrepancy")
#: Address space one warm-up stage may add (bytes): the data, emulator, iid sampler and best fit took 0.45 GB,
#: the discrepancy sampler 0.3 GB (2-core machine, 2026-12-02), rounded up.
STAGE_BYTES = 0.5 * memory.GiB
#: Room kept for the users' own work while the warm-up runs (bytes): the Simulator page's first ``fast``
#: simulation (its FE kernels compiled) took 0.45 GB of address space, an ``accurate`` one 0.3 GB more.
RESERVE_BYTES = 1.0 * memory.GiB

#: Longest wait (s) at the process's exit for the warm-up to finish its current stage (one sampler's compile,
#: 3-20 s on 2 cores with a cold cache).
EXIT_WAIT_S = 60.0

_started = False
_lock = threading.Lock()
_stop = threading.Event()
_thread: threading.Thread | None = None
#: What the warm-up did: ``state`` (``running``, ``done``, ``partial``, ``skipped``, ``failed``, ``stopped``,
#: ``off``),
#: per-stage wall seconds, error, and ``note`` (for the user, when it did less than asked; else None).
STATUS: dict = {"state": "not started", "stages": {}, "error": None, "note": None}


class ShortOfMemory(RuntimeError):
    """Too little memory is left for the next warm-up stage (the warm-up stops; the app carries on)."""


class Stopped(RuntimeError):
    """The process is exiting: the warm-up stops before its next stage."""


def check_room(stage: str, need: float = STAGE_BYTES, reserve: float = RESERVE_BYTES) -> None:
    """Raise :class:`ShortOfMemory` unless ``need + reserve`` bytes are left (:func:`lvcore.app.memory.state`)."""
    mem = memory.state()
    if mem.headroom < need + reserve:
        raise ShortOfMemory(f"{stage}: {mem.headroom / memory.GiB:.1f} GB left, the warm-up keeps "
                            f"{(need + reserve) / memory.GiB:.1f} GB for itself and the users ({mem.text()})")


#: Address space a calibration adds besides compiling its samplers (bytes): its draws, the verdict's checks and
#: the result figures. Measured 2026-12-02 (2-core machine, under ``ulimit -v`` 4 GB): a 1-chain 100 + 100 run of
#: both likelihoods with the discrepancy sampler compiled on the click took the server from 3.05 to 3.44 GB,
#: of which the compile is :data:`STAGE_BYTES` at most; rounded up.
CALIBRATION_RUN_BYTES = 0.25 * memory.GiB


def calibration_room(models, state: "memory.MemoryState | None" = None) -> str | None:
    """Why a calibration of likelihoods ``models`` cannot start in this process now, or None when it can.

    It needs :data:`CALIBRATION_RUN_BYTES` plus :data:`STAGE_BYTES` for each likelihood whose sampler the warm-up
    has not compiled (:data:`STATUS`); a compile that runs out of address space aborts the whole server (LLVM
    cannot allocate section memory), so the app checks before it starts, not after.

    Parameters
    ----------
    models : sequence of str
        The likelihoods chosen.
    state : MemoryState, optional
        The memory now (default :func:`lvcore.app.memory.state`).
    """
    mem = memory.state() if state is None else state
    compiled = set(STATUS.get("stages") or {}) if STATUS.get("state") in ("done", "partial", "skipped") else set()
    to_compile = [m for m in models if m not in compiled]
    need = CALIBRATION_RUN_BYTES + STAGE_BYTES * len(to_compile)
    if mem.headroom >= need:
        return None
    what = f", compiling the {' and '.join(to_compile)} sampler{'s' if len(to_compile) > 1 else ''}" if to_compile \
        else ""
    return (f"memory is short on this server: a calibration needs about {need / memory.GiB:.1f} GB{what}, and "
            f"{mem.headroom / memory.GiB:.1f} GB is left ({mem.text()}). Choose fewer likelihoods, wait for other "
            "sessions' calibrations to finish, or start the server with more memory (at least a 4 GB address "
            "space: docs/reliability.md).")


def enabled() -> bool:
    """False when ``LVCORE_APP_WARMUP`` is ``0``/``off``/``false``."""
    return os.environ.get(ENV, "1").strip().lower() not in ("0", "off", "false", "no")


def warm(subject: str | None = None, emulator: str | None = None, models=MODELS, room=None) -> dict:
    """Compile the page's default calibration (samplers and best fit) in this process; returns stage wall times (s).

    Parameters
    ----------
    subject : str, optional
        Bundled volunteer whose data and geometry are used (default: the shared sidebar's subject).
    emulator : str, optional
        Emulator name (default: the shared sidebar's emulator).
    models : sequence of str
        Likelihoods to compile.
    room : callable, optional
        ``room(stage)`` is called before loading and before each likelihood and may raise (e.g.
        :func:`check_room`, as :func:`start` passes it) to stop the warm-up; the stages done so far are kept
        and their times are in the exception's ``stages`` attribute.
    """
    stages = {}
    room = room or (lambda stage: None)
    try:
        _warm(subject, emulator, models, room, stages)
    except Exception as err:
        err.stages = stages  # what was done before the stop (shown in STATUS)
        raise
    return stages


def _warm(subject, emulator, models, room, stages) -> None:
    from lvcore.app.controls import DEFAULT_SUBJECT
    from lvcore.emulator.io import available_emulators, load_emulator
    from lvcore.inference import guards, samplers
    from lvcore.inference.cli import DEFAULT_EMULATOR
    from lvcore.inference.data import read_measured_csv
    from lvcore.inference.request import build_request
    from lvcore.resources import bundled_volunteers, volunteer_files

    room("load")
    t0 = time.perf_counter()
    names = bundled_volunteers()
    emulators = available_emulators()
    subject = subject or (DEFAULT_SUBJECT if DEFAULT_SUBJECT in names else (names[0] if names else None))
    emulator = emulator or (DEFAULT_EMULATOR if DEFAULT_EMULATOR in emulators else (emulators[0] if emulators else None))
    if subject is None or emulator is None:
        return
    vol = volunteer_files(subject)
    data = read_measured_csv(vol.measured)[0]
    geo = guards.resolve_geometry(str(vol.geometry))
    emu = load_emulator(emulator)
    # the Calibration page's request (pages/5_Calibration.py): the same forward model, floor and verdict inputs
    request = build_request(emu, emulator, geo, row=data, allow_extrapolation=True)
    forward = request.forward
    stages["load"] = time.perf_counter() - t0
    for k, m in enumerate(models):
        room(m)
        stages[m] = samplers.precompile(m, data.y, forward, samplers.INTERACTIVE)
        if k == 0:  # the best fit after the first likelihood: a click on the default selection finds both
            t1 = time.perf_counter()
            request.consistency()
            stages["best fit"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    from lvcore.viz import inference_figures, report_figures  # noqa: F401 - the results' imports
    stages["imports"] = time.perf_counter() - t1


def _run() -> None:
    import sys

    STATUS["state"] = "running"
    t0 = time.perf_counter()
    try:
        STATUS["stages"] = warm(room=_room_unless_stopping)
        STATUS["state"] = "done"
    except Stopped as err:
        STATUS["stages"] = getattr(err, "stages", {})
        STATUS["state"] = "stopped"
    except ShortOfMemory as err:
        STATUS["stages"] = getattr(err, "stages", {})
        STATUS["state"] = "partial" if any(m in STATUS["stages"] for m in MODELS) else "skipped"
        STATUS["error"] = str(err)
        STATUS["note"] = ("Memory is short on this server, so the calibration samplers were "
                          + ("only partly " if STATUS["state"] == "partial" else "not ")
                          + "prepared in advance: a first calibration compiles them on the click (slower).")
    except Exception as err:  # noqa: BLE001 - an optimisation only: the page compiles on the click instead
        STATUS["stages"] = getattr(err, "stages", {})
        STATUS["state"], STATUS["error"] = "failed", f"{type(err).__name__}: {err}"
    stages = ", ".join(f"{k} {v:.1f} s" for k, v in STATUS["stages"].items())
    print(f"lvcore app warm-up {STATUS['state']} in {time.perf_counter() - t0:.1f} s ({stages})"
          + (f": {STATUS['error']}" if STATUS["error"] else "") + f"; memory: {memory.state().text()}",
          file=sys.stderr, flush=True)


def _room_unless_stopping(stage: str) -> None:
    """:func:`check_room`, after :class:`Stopped` once the process has begun to exit."""
    if _stop.is_set():
        raise Stopped(f"the process is exiting; the warm-up stopped before its {stage!r} stage")
    check_room(stage)


def _stop_at_exit() -> None:
    """Ask the warm-up to stop and wait (at most EXIT_WAIT_S) until it is out of XLA (an exit handler)."""
    _stop.set()
    if _thread is not None:
        _thread.join(EXIT_WAIT_S)


def _register_before_atexit(fn) -> None:
    """Call ``fn`` at the interpreter's exit before the ``atexit`` handlers (where Python allows it).

    JAX's own ``atexit`` handler (``jax._src.api.clean_up``) clears its backends and caches. JAX may be imported
    only by the warm-up thread, after :func:`start`, and ``atexit`` runs the latest handler first, so a plain
    ``atexit`` handler of ours would stop the warm-up only after JAX had been torn down under it (seen: the
    stage then failed with a ``KeyError`` from JAX's tracer). ``threading._register_atexit`` (the hook
    :mod:`concurrent.futures` uses) runs in the interpreter's thread shutdown, before every ``atexit`` handler.
    """
    import atexit

    register = getattr(threading, "_register_atexit", None)
    if register is None:  # no such hook on this Python
        atexit.register(fn)
        return
    try:
        register(fn)
    except RuntimeError:  # the interpreter's shutdown has begun: "can't register atexit after shutdown"
        atexit.register(fn)


def note() -> str | None:
    """A line for the user when the warm-up did less than asked because memory was short; else None."""
    return STATUS.get("note")


def start() -> bool:
    """Start :func:`warm` in a daemon thread, once per process; False if already started or turned off."""
    global _started, _thread
    with _lock:
        if _started:
            return False
        _started = True
        if not enabled():
            STATUS["state"] = "off"
            return False
        _thread = threading.Thread(target=_run, name="lvcore-calibration-warmup", daemon=True)
        _register_before_atexit(_stop_at_exit)
        _thread.start()
        return True


__all__ = ["ENV", "MODELS", "STAGE_BYTES", "RESERVE_BYTES", "CALIBRATION_RUN_BYTES", "EXIT_WAIT_S", "STATUS",
           "ShortOfMemory", "Stopped", "enabled", "check_room", "calibration_room", "warm", "note", "start"]
