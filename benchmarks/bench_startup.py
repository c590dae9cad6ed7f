"""Start-up: ``lvcore --help`` and a 16-row campaign end to end, first and second run.

Usage::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_startup.py [--repeats 3] [--rows 16] [--lvcore PATH]

Runs the ``lvcore`` console script (``--lvcore``, default: the one beside this Python) as a user does and
prints a markdown table of wall and CPU time (user + system, the command and every process it started:
campaign workers included), median of ``--repeats``:

* ``lvcore --help``: the first call of this benchmark, and then the median of the further calls;
* ``lvcore campaign run`` of a ``--rows``-row Sobol design over the ``material`` space (``default`` mesh),
  default options (16 rows or fewer: in this process, cold), **first run**: JAX's persistent compilation cache
  empty (a new ``LVCORE_JAX_CACHE`` folder per repeat), so every program is traced and compiled; **second run**:
  the same command again with the cache the first run filled (what every later campaign of a user gets); then
  the second run with ``--workers 2`` (two spawned workers), and with the exported kernels off
  (``LVCORE_JAX_EXPORT=0``: every process traces and lowers the simulator's kernels), with the indefinite
  tangents sent to SuperLU instead of PARDISO's indefinite LDLᵀ (``LVCORE_PARDISO_INDEFINITE=0``), with the
  in-process rows one at a time instead of on two threads (``LVCORE_IN_PROCESS_THREADS=1``), and with both, see
  :data:`VARIANTS`; ``--variants`` picks some of them (the first run always: it fills the cache).

It ends with the largest relative difference of the campaigns' outputs between the runs (all the same solves).

Every row states the sparse solver the simulator uses here and the load average before it (``uptime``):
the machine is shared, so compare rows of one run.
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported


#: The campaign runs of one repeat, in order: (extra options, extra environment, an untimed run first). The
#: first starts with an empty compilation cache (a new ``LVCORE_JAX_CACHE`` folder per repeat).
VARIANTS = {
    "first run (empty compilation cache), default options": ([], {}, False),
    "second run (the cache the first filled), default options": ([], {}, False),
    "second run, `--workers 2`": (["--workers", "2"], {}, False),
    "second run, `--workers 2 --chained` (the default options before 12-02)": (["--workers", "2", "--chained"], {},
                                                                               False),
    "second run, exported kernels off (`LVCORE_JAX_EXPORT=0`; after an untimed run that fills the cache)":
        ([], {"LVCORE_JAX_EXPORT": "0"}, True),
    "second run, indefinite tangents to SuperLU (`LVCORE_PARDISO_INDEFINITE=0`)":
        ([], {"LVCORE_PARDISO_INDEFINITE": "0"}, False),
    "second run, rows one at a time (`LVCORE_IN_PROCESS_THREADS=1`)": ([], {"LVCORE_IN_PROCESS_THREADS": "1"}, False),
    "second run, both (the solver and the executor before 12-02 12:30)":
        ([], {"LVCORE_PARDISO_INDEFINITE": "0", "LVCORE_IN_PROCESS_THREADS": "1"}, False),
}


def _load() -> str:
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


def timed(cmd: list[str], env: dict | None = None) -> tuple[float, float]:
    """(wall s, CPU s of the command and its children) of one run of ``cmd``; raises if it fails."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, **(env or {})})
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({out.returncode}): {out.stderr[-2000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _largest_difference(stores: list[Path]) -> float:
    """Largest relative difference of the campaigns' outputs between the first store and each other one."""
    import h5py
    import numpy as np

    outs = []
    for f in stores:
        with h5py.File(f, "r") as h5:
            outs.append(h5["outputs"][:])
    return max((float(np.max(np.abs(o - outs[0]) / np.abs(outs[0]))) for o in outs[1:]), default=0.0)


def _solver() -> str:
    out = subprocess.run([sys.executable, "-c", "from lvcore.mechanics.linear import default_backend as d; print(d())"],
                         capture_output=True, text=True)
    return out.stdout.strip() or "?"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3, help="runs per row, median reported (default: 3)")
    ap.add_argument("--rows", type=int, default=16, help="design rows of the campaign (default: 16)")
    ap.add_argument("--lvcore", default=str(Path(sys.executable).with_name("lvcore")),
                    help="the lvcore console script to time (default: the one beside this Python)")
    ap.add_argument("--variants", default="",
                    help="comma-separated numbers (1-based, in the order of VARIANTS) of the campaign runs to time; "
                         "the first run always runs (default: all)")
    args = ap.parse_args(argv)
    exe = args.lvcore
    picked = {1} | {int(v) for v in args.variants.split(",") if v.strip()} if args.variants else None
    variants = {k: v for i, (k, v) in enumerate(VARIANTS.items(), 1) if picked is None or i in picked}
    solver = _solver()
    rows = []

    def row(what, samples, load):
        walls, cpus = zip(*samples)
        rows.append(f"| {what} | {statistics.median(walls):.2f} | {statistics.median(cpus):.2f} | "
                    f"{', '.join(f'{w:.2f}' for w in walls)} | {solver} | {load} |")
        print(rows[-1], file=sys.stderr, flush=True)

    load = _load()
    first = timed([exe, "--help"])
    row("`lvcore --help`, first call", [first], load)
    load = _load()
    row("`lvcore --help`, later calls", [timed([exe, "--help"]) for _ in range(max(args.repeats, 3))], load)

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        design = tmp / "design.csv"
        timed([exe, "design", "sobol", "--space", "material", "--n", str(args.rows), "--seed", "1",
               "--out", str(design)])
        runs = {k: [] for k in variants}
        loads = []
        for k in range(args.repeats):  # the variants alternate, so a drift of the load hits all of them
            cache = {"LVCORE_JAX_CACHE": str(tmp / f"cache{k}")}
            loads.append(_load())
            order = list(enumerate(variants.items()))
            if k % 2:  # every other repeat the later runs in reverse order: a drift of the load within one evens out
                order = order[:1] + order[:0:-1]
            for i, (name, (extra, env, warm_up)) in order:
                cmd = [exe, "campaign", "run", str(design), "--no-progress", *extra, "--out"]
                if warm_up:  # untimed: fills the cache for this variant's programs
                    timed(cmd + [str(tmp / f"{k}-{i}-warm.h5")], {**cache, **env})
                runs[name].append(timed(cmd + [str(tmp / f"{k}-{i}.h5")], {**cache, **env}))
        for name, samples in runs.items():
            row(f"{args.rows}-row campaign, {name}", samples, " → ".join(loads))
        diff = _largest_difference(sorted(tmp.glob("*-*.h5")))
    print(f"largest relative difference of the outputs (LVV, strains) between any two campaign runs: {diff:.2g}")

    print(f"lvcore: {exe}; python {sys.version.split()[0]}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print("| what | wall s (median) | CPU s, all processes (median) | wall s, each run | sparse solver | load before |")
    print("|---|---|---|---|---|---|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
