import os

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
# the app's background warm-up (lvcore.app.warmup) would compile the Calibration page's samplers in every
# test process that starts the app; tests that want it call lvcore.app.warmup.warm themselves
os.environ.setdefault("LVCORE_APP_WARMUP", "0")
# `lvcore calibrate`'s derived quantities run the FE simulator for 100 posterior draws (about a minute); the
# tests that check them (tests/test_inference_derived.py) ask for them with --derived-draws, the others skip them
os.environ.setdefault("LVCORE_DERIVED_DRAWS", "0")

import lvcore  # noqa: E402,F401  (turns on float64 before any test makes arrays)
from lvcore.inference.samplers import use_host_devices  # noqa: E402

# As the app and the CLI do: one XLA host device per chain (up to 4), set before JAX starts, so the
# chain method does not depend on which test happens to start JAX first.
use_host_devices(4)


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """After each test module, let go of the XLA programs it compiled.

    Every compiled CPU executable keeps a few executable memory mappings, and the kernel allows 65,530 per
    process (``vm.max_map_count``). One pytest process compiles thousands of programs (app pages, samplers,
    simulator kernels); kept to the end, they passed that limit and LLVM aborted the run (SIGABRT, CI exit
    134, 2026-11-27). JAX's caches, the samplers and the verdict's best-fit programs are cleared here; the
    persistent compilation cache (:mod:`lvcore.jax_cache`) makes a later module's recompile a disk load.
    """
    yield
    import gc

    import jax

    from lvcore.inference import samplers, verdict

    samplers.clear_sampler_cache()
    verdict.clear_best_fit_programs()
    jax.clear_caches()
    gc.collect()


# ----------------------------------------------------------------------------
# Session-scoped fixtures: solved once per test run, shared by the modules that use them.
# Each returns frozen/read-only data; tests must not modify what they get.
# ----------------------------------------------------------------------------
@pytest.fixture(scope="session")
def fast_lv_case():
    """The default LV at the ``fast`` resolution with the population HO parameters (a, b, af, bf) =
    (0.6, 1.3, 1.0, 3.6) kPa / -, EDP 8 mmHg."""
    from lvcore.mechanics.case import Case

    return Case.default_lv({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}, resolution="fast")


@pytest.fixture(scope="session")
def fast_lv_result(fast_lv_case):
    """:func:`simulate` of :func:`fast_lv_case` with adjoint sensitivities (solved once per session)."""
    from lvcore.mechanics.simulate import simulate

    return simulate(fast_lv_case, with_sensitivities=True)


# ---------------------------------------------------------------------------- mismatch study results (made up)
def _mismatch_result(doses=((0.01, 0.031, 0.01), (0.03, 0.04, 0.02), (0.06, 0.07, 0.04)), source="dispersion"):
    """A study result from summarise() over made-up per-data-set metrics (test fixture, not study output)."""
    import numpy as np

    from lvcore.studies import mismatch as mm

    rng = np.random.default_rng(1)
    fits, rms = {}, {}
    for d, (r, iid_sigma, iid_err) in enumerate(doses):
        rec = {m: {"coverage": list(rng.uniform(0.5, 1, 20)),
                   "output_error": list(abs(({"iid": iid_err}.get(m, 0.01)) + 0.002 * rng.standard_normal(20))),
                   "min_ess": list(rng.uniform(100, 300, 20)), "max_rhat": list(rng.uniform(1.0, 1.02, 20))}
               for m in mm.MODELS}
        for m, s in (("iid", iid_sigma), ("discrepancy", 0.03)):
            rec[m]["sigma_s"] = list(s + 0.002 * rng.standard_normal(20))
        fits[(source, float(d + 1))] = {"HV1": rec}
        rms[(source, float(d + 1))] = {"mean": r, "min": r * 0.8, "max": r * 1.2}
    rows = mm.summarise(fits, rms)
    return {"study": "mismatch", "synthetic": True, "volunteers": ["HV1"], "seeds_per_dose": 20, "emulator": "chapter",
            "resolution": "default", "sampler": {"num_warmup": 300, "num_samples": 300, "num_chains": 2},
            "rows": rows, "appearance": mm.appearance(rows), "failed": [], "folder": "/tmp/x",
            "timings_s": {"simulate": 60.0, "calibrate": 600.0, "total": 660.0}}


@pytest.fixture
def mismatch_result():
    """A factory of mismatch-study results from :func:`lvcore.studies.mismatch.summarise` over made-up
    per-data-set metrics: ``mismatch_result(doses=((rms, iid σ_S, iid output error), ...))``."""
    return _mismatch_result
