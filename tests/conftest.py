import functools
import os
from pathlib import Path

import pytest

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
# the app's background warm-up (lvcore.app.warmup) would compile the Calibration page's samplers in every
# test process that starts the app; tests that want it call lvcore.app.warmup.warm themselves
os.environ.setdefault("LVCORE_APP_WARMUP", "0")
# `lvcore calibrate`'s derived quantities run the FE simulator for 100 posterior draws (about a minute); the
# tests that check them (tests/test_inference_derived.py) ask for them with --derived-draws, the others skip them
os.environ.setdefault("LVCORE_DERIVED_DRAWS", "0")
# A study's figures are written as HTML and, through kaleido (a Chromium started per figure, about 3-6 s), as PNG:
# 24 PNGs made the realistic-operators mini study 84 s of CI time. The study tests check the HTML and the results;
# the PNG path of lvcore.studies._common.save_figure is tested in tests/test_studies_common.py (a real export, a
# failing and a hung one), which unsets this variable.
os.environ.setdefault("LVCORE_NO_PNG", "1")
# XLA's LLVM back end at -O0 for the tests (child processes, the app servers and CLI runs inherit it): CI runs
# the suite with JAX's persistent cache cold, and compiling thousands of small programs dominates it. Measured
# 2026-12-02, cold cache: a discrepancy-sampler test 89 -> 69 CPU-s, the simulator's forward and verification
# tests 78 -> 62 CPU-s, same results. Users' runs keep XLA's default (-O2); a flag set by the caller is kept. At
# -O0 one soft-corner campaign row once reached another equilibrium from a clean-looking warm path; the simulator
# now solves that corner cold whatever the start (lvcore.mechanics.forward.soft_corner), and
# tests/test_campaign_reproducible.py passes at -O0 and -O2.
# XLA's CPU fusion emitters off as well (the older elemental emitters: the same HLO, cheaper to compile) and
# one LLVM module per program (no split for parallel codegen, which only adds work on 2 busy cores). Measured
# 2026-12-02, cold cache, one process, -O0 both: tests/test_inference_verdict.py 23.2 -> 15.1 CPU-s (XLA
# compile 13.4 -> 8.8 s), tests/test_inference_gibbs.py 68.1 -> 51.2 (33.1 -> 23.3 s), the simulator's
# forward tests 14.0 -> 12.4 (2.8 -> 1.1 s); the same results within every test's tolerance (bit-for-bit
# reference draws are recorded per flag set, tests/test_inference_gibbs.py).
TEST_XLA_FLAGS = {"xla_backend_optimization_level": "0", "xla_cpu_use_fusion_emitters": "false",
                  "xla_cpu_parallel_codegen_split_count": "1"}
_flags = os.environ.get("XLA_FLAGS", "")
os.environ["XLA_FLAGS"] = " ".join([_flags, *(f"--{k}={v}" for k, v in TEST_XLA_FLAGS.items() if k not in _flags)]).strip()

import lvcore  # noqa: E402,F401  (turns on float64 before any test makes arrays)
from lvcore.inference.samplers import use_host_devices  # noqa: E402

# As the app and the CLI do: one XLA host device per chain (up to 4), set before JAX starts, so the
# chain method does not depend on which test happens to start JAX first.
use_host_devices(4)


#: Test files that take longest, run first; the rest keep their order. Measured (BENCHMARKS.md "Test suite time",
#: CPU s, 2026-12-02): the browser file (its server and Chromium besides), loaded states 96, CLI 75, real-data
#: benchmark 64, emulator build script 43, emulator model 40, inference CLI 30, report page 26, physiology 23;
#: the NUTS, study, verification and My-subject files were not reached there and are placed by their runs (NUTS
#: fits, mini studies, FE benchmarks). With ``-n 2`` (README) pytest-xdist hands out whole files in this order
#: (``--dist loadfile --no-loadscope-reorder`` in pyproject.toml), so a long file does not start last on one worker
#: while the other idles. Only the order changes: no test depends on it.
LONGEST_FIRST = (
    "test_browser.py",
    "test_inference_samplers.py",
    "test_app_subject_flow.py",
    "test_inference_loaded_states.py",
    "test_cli.py",
    "test_benchmarks_real_data.py",
    "test_studies_mismatch.py",
    "test_studies_fibre_discrepancy.py",
    "test_emulator_build_script.py",
    "test_emulator_model.py",
    "test_mechanics_verification.py",
    "test_app_uploads.py",
    "test_inference_cli.py",
    "test_report.py",
    "test_app_report_page.py",
    "test_app_physiology.py",
    "test_mechanics_materials.py",
)


def pytest_collection_modifyitems(config, items):
    """Run the files of LONGEST_FIRST first, in that order (a stable sort: the rest keep pytest's order)."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


#: Share of the kernel's per-process limit on memory mappings (``vm.max_map_count``) at which the compiled XLA
#: programs of the test modules run so far are let go (see _release_compiled_programs).
MAP_SHARE = 0.4
#: Resident memory (bytes) at which they are let go as well: 2 xdist workers on a 2-core CI machine stay far
#: below its memory.
RSS_LIMIT = 4 * 2**30
#: Environment variable naming a file to which every test module's end appends its process's (mappings, their
#: limit, resident bytes) and whether the compiled programs were let go (measurement only).
PRESSURE_LOG_ENV = "LVCORE_TEST_PRESSURE_LOG"


def _process_pressure() -> tuple[int, int, int] | None:
    """(memory mappings, their limit, resident bytes) of this process, or None where /proc cannot tell."""
    try:
        with open("/proc/self/maps", "rb") as f:
            maps = sum(1 for _ in f)
        limit = int(Path("/proc/sys/vm/max_map_count").read_text())
        with open("/proc/self/statm") as f:
            rss = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError):
        return None
    return maps, limit, rss


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs(request):
    """After a test module, let go of the XLA programs compiled so far when this process holds many.

    Every compiled CPU executable keeps a few executable memory mappings, and the kernel allows 65,530 per
    process (``vm.max_map_count``). One pytest process compiles thousands of programs (app pages, samplers,
    simulator kernels); kept to the end, they passed that limit and LLVM aborted the run (SIGABRT, CI exit
    134, 2026-11-27). JAX's caches, the samplers and the verdict's best-fit programs are cleared once the
    process holds MAP_SHARE of that limit or RSS_LIMIT of memory (and after every module where /proc cannot
    tell), not after every module: a module that compiles what an earlier one compiled (the fast simulator,
    the chapter emulator's samplers) then reuses it, where a recompile costs its tracing again (measured
    2026-12-02: the fast default LV's first solve with sensitivities 22 CPU s, after ``jax.clear_caches()``
    7.4 s, warm 0.4 s; the persistent compilation cache, :mod:`lvcore.execution.jax_cache`, spares only XLA's part).
    """
    yield
    _return_free_memory()
    pressure = _process_pressure()
    release = pressure is None or pressure[0] >= MAP_SHARE * pressure[1] or pressure[2] >= RSS_LIMIT
    if os.environ.get(PRESSURE_LOG_ENV):  # measurement only: how often a module ends with the programs let go
        with open(os.environ[PRESSURE_LOG_ENV], "a") as log:
            log.write(f"{os.getpid()} {request.module.__name__} {pressure} release={release}\n")
    if not release:
        return
    import gc

    import jax

    from lvcore.inference import samplers, verdict

    samplers.clear_sampler_cache()
    verdict.clear_best_fit_programs()
    jax.clear_caches()
    gc.collect()
    _return_free_memory()


def _return_free_memory() -> None:
    """Give the C heap's free pages back to the system (glibc's ``malloc_trim``; nothing elsewhere).

    Freed memory stays in the process's resident size until trimmed: without this the workers sat near
    RSS_LIMIT after their first large modules, and nearly every later module let its compiled programs go
    and the next one traced and compiled them again. Measured 2026-12-02: a fast-LV solve and two samplers,
    950 MB resident; after letting the programs go 942 MB; after the trim 400 MB.
    """
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


@functools.cache
def _malloc_trim():
    """glibc's ``malloc_trim`` from the symbols already loaded in this process (no library search, which runs
    ``ldconfig``), looked up once; None where the C library has none."""
    import ctypes

    try:
        return getattr(ctypes.CDLL(None), "malloc_trim", None)
    except OSError:
        return None


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
