"""Warm the Calibration page when the app starts: its samplers and the verdict's best fit, compiled in the background.

A click on "Run calibration" traces, lowers and compiles (or loads from JAX's
persistent cache, :mod:`lvcore.jax_cache`) two samplers and the verdict's
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
"""
from __future__ import annotations

import os
import threading
import time

#: The environment variable that turns the warm-up off (``0``).
ENV = "LVCORE_APP_WARMUP"
#: Likelihoods warmed: the Calibration page's default selection.
MODELS = ("iid", "discrepancy")

_started = False
_lock = threading.Lock()
#: What the warm-up did: ``state`` (``running``, ``done``, ``failed``, ``off``), per-stage wall seconds, error.
STATUS: dict = {"state": "not started", "stages": {}, "error": None}


def enabled() -> bool:
    """False when ``LVCORE_APP_WARMUP`` is ``0``/``off``/``false``."""
    return os.environ.get(ENV, "1").strip().lower() not in ("0", "off", "false", "no")


def warm(subject: str | None = None, emulator: str | None = None, models=MODELS) -> dict:
    """Compile the page's default calibration (samplers and best fit) in this process; returns stage wall times (s).

    Parameters
    ----------
    subject : str, optional
        Bundled volunteer whose data and geometry are used (default: the shared sidebar's subject).
    emulator : str, optional
        Emulator name (default: the shared sidebar's emulator).
    models : sequence of str
        Likelihoods to compile.
    """
    from lvcore.app.controls import DEFAULT_SUBJECT
    from lvcore.conditions import SIGMA_V_ML, SIMULATOR_DEFAULT_EDP_MMHG
    from lvcore.emulator.forward import emulator_forward
    from lvcore.emulator.io import available_emulators, load_emulator
    from lvcore.geometry.scaling import ScaledForward
    from lvcore.inference import guards, samplers, verdict
    from lvcore.inference.cli import DEFAULT_EMULATOR
    from lvcore.inference.data import read_measured_csv
    from lvcore.resources import bundled_volunteers, volunteer_files

    stages = {}
    t0 = time.perf_counter()
    names = bundled_volunteers()
    emulators = available_emulators()
    subject = subject or (DEFAULT_SUBJECT if DEFAULT_SUBJECT in names else (names[0] if names else None))
    emulator = emulator or (DEFAULT_EMULATOR if DEFAULT_EMULATOR in emulators else (emulators[0] if emulators else None))
    if subject is None or emulator is None:
        return stages
    vol = volunteer_files(subject)
    data = read_measured_csv(vol.measured)[0]
    geo = guards.resolve_geometry(str(vol.geometry))
    emu = load_emulator(emulator)
    # built as the Calibration page builds it (pages/5_Calibration.py): the same conditions are bound
    conditions = {"edp_mmhg": SIMULATOR_DEFAULT_EDP_MMHG, **guards.check_conditions(emu)}
    edp = guards.subject_edp(data, conditions, emu, emulator, None)
    forward = ScaledForward(emulator_forward(emu, geo.h, name=emulator, edp_mmhg=edp), geo.scale)
    stages["load"] = time.perf_counter() - t0
    for m in models:
        stages[m] = samplers.precompile(m, data.y, forward, samplers.INTERACTIVE)
    t1 = time.perf_counter()
    verdict.consistency_check(data.y, forward, SIGMA_V_ML)
    stages["best fit"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    from lvcore.viz import inference_figures, report_figures  # noqa: F401 - the results' imports
    stages["imports"] = time.perf_counter() - t1
    return stages


def _run() -> None:
    import sys

    STATUS["state"] = "running"
    t0 = time.perf_counter()
    try:
        STATUS["stages"] = warm()
        STATUS["state"] = "done"
    except Exception as err:  # noqa: BLE001 - an optimisation only: the page compiles on the click instead
        STATUS["state"], STATUS["error"] = "failed", f"{type(err).__name__}: {err}"
    stages = ", ".join(f"{k} {v:.1f} s" for k, v in STATUS["stages"].items())
    print(f"lvcore app warm-up {STATUS['state']} in {time.perf_counter() - t0:.1f} s ({stages})"
          + (f": {STATUS['error']}" if STATUS["error"] else ""), file=sys.stderr, flush=True)


def start() -> bool:
    """Start :func:`warm` in a daemon thread, once per process; False if already started or turned off."""
    global _started
    with _lock:
        if _started:
            return False
        _started = True
        if not enabled():
            STATUS["state"] = "off"
            return False
        threading.Thread(target=_run, name="lvcore-calibration-warmup", daemon=True).start()
        return True


__all__ = ["ENV", "MODELS", "STATUS", "enabled", "warm", "start"]
