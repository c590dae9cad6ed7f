"""Per-file time of the README's test command: wall seconds and CPU seconds of every test, summed per file.

Runs ``python -m pytest -q -n 2 tests`` (the README's command; extra pytest arguments after ``--``) with this
module loaded as a pytest plugin in every worker. Each test's setup, call and teardown are timed with
``time.perf_counter`` (wall) and ``resource.getrusage`` of the worker and its reaped children (CPU): CPU seconds
hold up on a loaded machine where wall seconds do not. They leave out the child processes a test does not reap
before it ends (the browser tests' Streamlit server and Chromium, reaped at their module's end) and include XLA's
own threads. JAX's own timers (:mod:`jax.monitoring`) split each test's in-process compile work into tracing,
lowering to MLIR and XLA's back-end compile, and count the persistent cache's hits and misses (child processes
not included). Prints one table row per file, the most CPU first, and writes every test's record as JSON lines.

Usage::

    python benchmarks/bench_test_suite.py --out build/suite_times.jsonl
    python benchmarks/bench_test_suite.py --out build/t.jsonl -- tests/test_cli.py -x
    python benchmarks/bench_test_suite.py --table build/suite_times.jsonl   # the table of an earlier run
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Environment variable through which the parent tells the workers' plugin where to write.
OUT_ENV = "LVCORE_SUITE_TIMES"


def _cpu() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


#: JAX's duration events (seconds) summed in this process, by the short name used in the records.
JAX_EVENTS = {"/jax/core/compile/jaxpr_trace_duration": "trace_s",
              "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower_s",
              "/jax/core/compile/backend_compile_duration": "compile_s"}
#: JAX's counted events, by short name.
JAX_COUNTS = {"/jax/compilation_cache/cache_hits": "cache_hits",
              "/jax/compilation_cache/cache_misses": "cache_misses"}
_jax_totals: dict[str, float] = defaultdict(float)
_listening = False


def _listen_to_jax() -> None:
    """Register the listeners once, after the test session has imported JAX (not before conftest's settings)."""
    global _listening
    if _listening or "jax" not in sys.modules:
        return
    from jax import monitoring

    def on_duration(event, duration, **_):
        if event in JAX_EVENTS:
            _jax_totals[JAX_EVENTS[event]] += duration

    def on_event(event, **_):
        if event in JAX_COUNTS:
            _jax_totals[JAX_COUNTS[event]] += 1

    monitoring.register_event_duration_secs_listener(on_duration)
    monitoring.register_event_listener(on_event)
    _listening = True


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Time one test's setup, call and teardown; append its record to this worker's file."""
    _listen_to_jax()
    jax0 = dict(_jax_totals)
    wall0, cpu0 = time.perf_counter(), _cpu()
    yield
    _listen_to_jax()
    out = os.environ.get(OUT_ENV)
    if not out:
        return
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    record = {"file": item.path.name, "test": item.nodeid, "worker": worker,
              "wall_s": round(time.perf_counter() - wall0, 3), "cpu_s": round(_cpu() - cpu0, 3),
              **{k: round(v - jax0.get(k, 0.0), 3) for k, v in _jax_totals.items()}}
    with open(f"{out}.{worker}", "a") as f:
        f.write(json.dumps(record) + "\n")


def table(records: list[dict]) -> str:
    """One row per test file: tests, wall s and CPU s (sums), the most CPU first, and a total row."""
    keys = ("wall_s", "cpu_s", "trace_s", "lower_s", "compile_s", "cache_misses")
    per = defaultdict(lambda: [0] + [0.0] * len(keys))
    for r in records:
        row = per[r["file"]]
        row[0] += 1
        for i, k in enumerate(keys, 1):
            row[i] += r.get(k, 0.0)
    lines = ["| test file | tests | wall s | CPU s | JAX trace s | lower s | XLA compile s | cache misses |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    fmt = "| {} | {} | {:.1f} | {:.1f} | {:.1f} | {:.1f} | {:.1f} | {:.0f} |"
    for name, row in sorted(per.items(), key=lambda kv: -kv[1][2]):
        lines.append(fmt.format(name, *row))
    total = [sum(v[i] for v in per.values()) for i in range(len(keys) + 1)]
    lines.append(fmt.format("**all**", *total))
    return "\n".join(lines)


def _read(path: Path) -> list[dict]:
    files = sorted(path.parent.glob(path.name + ".*")) if not path.is_file() else [path]
    return [json.loads(line) for f in files for line in f.read_text().splitlines() if line.strip()]


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    extra = argv[argv.index("--") + 1:] if "--" in argv else ["tests"]
    argv = argv[:argv.index("--")] if "--" in argv else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=ROOT / "build" / "suite_times.jsonl",
                   help="JSON lines of every test (one file per worker, suffixed; default build/suite_times.jsonl)")
    p.add_argument("--workers", type=int, default=2, help="pytest-xdist processes (default 2, the README's)")
    p.add_argument("--table", type=Path, default=None,
                   help="print the table of an earlier run's --out and exit (default: run the suite)")
    args = p.parse_args(argv)
    if args.table:
        print(table(_read(args.table)))
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    for old in args.out.parent.glob(args.out.name + ".*"):
        old.unlink()
    env = {**os.environ, OUT_ENV: str(args.out.resolve()),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT / "benchmarks"), os.environ.get("PYTHONPATH")]))}
    t0 = time.perf_counter()
    rc = subprocess.call([sys.executable, "-m", "pytest", "-q", "-n", str(args.workers), "-p", "bench_test_suite",
                          *extra], cwd=ROOT, env=env)
    wall = time.perf_counter() - t0
    print(table(_read(args.out)))
    print(f"pytest exit {rc}; whole run {wall:.0f} s wall on {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f} at the end")
    return rc


if __name__ == "__main__":
    sys.exit(main())
