"""Simulator benchmarks: mesh convergence and timing on the default LV at 8 mmHg.

Usage::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
        python benchmarks/bench_simulator.py [--resolutions PRESET|NC,NL,NT[,GP] ...] [--repeats 5] [--processes]

Prints markdown tables: per resolution the dofs, LVV, EDV/V₀, mean
strain, the largest relative output change against the finest resolution,
Newton iterations (chord iterations included), tangents (= factorisations),
load steps, compile+first-solve time and median warm solve time (of a new
case, and repeated on a case whose mesh and system are already prepared);
with ``--processes`` also the throughput of one vs two worker processes.
Every row carries its date, the load average before it (``uptime``) and the
linear solver, so a later drift is visible.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported


def _resolution(spec: str) -> dict:
    """A preset name, or ``"NC,NL,NT[,GP]"`` (NL may be per-level counts ``2+1+1+2``) as a case resolution."""
    from lvcore.mechanics.resolution import LVResolution

    return LVResolution.from_spec(spec).case_dict()


def _case(spec):
    from lvcore.mechanics.case import Case

    return Case.default_lv(resolution=_resolution(spec))


def run_resolution(res, repeats):
    """(result, first solve incl. compile, median solve of a new case, median repeated solve, load before).

    "A new case" clears the per-process cache of prepared cases (mesh, fibre frames, reference gradients, strain
    operator; :func:`lvcore.mechanics.simulate.prepare_case`), as for one solve of a geometry; "repeated"
    keeps it, as a campaign or sweep on one geometry does.
    """
    from lvcore.mechanics import simulate as sim

    load = _load()
    sim._PREPARED.clear()
    t0 = time.perf_counter()
    r = sim.simulate(_case(res))
    first = time.perf_counter() - t0
    fresh, repeated = [], []
    for _ in range(repeats):  # alternate, so drifts of the shared machine's load hit both
        sim._PREPARED.clear()
        t0 = time.perf_counter()
        r = sim.simulate(_case(res))
        fresh.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        sim.simulate(_case(res))
        repeated.append(time.perf_counter() - t0)
    med = (lambda x: statistics.median(x) if x else float("nan"))
    return r, first, med(fresh), med(repeated), load


def _load() -> str:
    """The load average over 1, 5 and 15 minutes (as `uptime` prints it)."""
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


def _now() -> str:
    import datetime as dt

    return dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def cold_start(res) -> float:
    code = (
        "import time; t=time.perf_counter(); import lvcore; from lvcore.mechanics.case import Case; "
        "from lvcore.mechanics.simulate import simulate; "
        f"r=simulate(Case.default_lv(resolution={_resolution(res)!r})); "
        "print(time.perf_counter()-t)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def _worker(args):
    res, n = args
    from lvcore.mechanics.simulate import simulate

    for _ in range(n):
        simulate(_case(res))
    return n


def throughput(res, n_jobs, n_proc):
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    with ctx.Pool(n_proc) as pool:
        pool.map(_worker, [(res, 1)] * n_proc)  # warm up (compile) each worker
        t0 = time.perf_counter()
        pool.map(_worker, [(res, n_jobs // n_proc)] * n_proc)
        return n_jobs / (time.perf_counter() - t0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolutions", nargs="*", default=None,
                    help="preset names or NC,NL,NT[,GP] (NL may be per-level counts 2+1+1+2); the last is the "
                         "reference; default: every preset, cheapest first")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--processes", action="store_true", help="measure 1 vs 2 worker processes")
    ap.add_argument("--throughput-solves", type=int, default=24, help="solves per throughput measurement")
    ap.add_argument("--throughput-rounds", type=int, default=2,
                    help="alternating 1- and 2-process rounds; the best of each is reported")
    ap.add_argument("--cold", default=None, help="resolution for the cold-start measurement (e.g. default)")
    a = ap.parse_args(argv)
    import numpy as np

    from lvcore.mechanics.linear import available_backends
    from lvcore.mechanics.resolution import RESOLUTION_PRESET_NAMES, resolution_label

    a.resolutions = a.resolutions or list(RESOLUTION_PRESET_NAMES)

    from lvcore.mechanics.linear import default_backend

    solver = default_backend()
    started, load0 = _now(), _load()
    rows = []
    for res in a.resolutions:
        r, first, med, rep, load = run_resolution(res, a.repeats)
        rows.append((res, r, first, med, rep, _now(), load))
        print(f"done {res}: converged={r.converged} {med:.3f} s", file=sys.stderr, flush=True)
    ref = rows[-1][1].outputs()
    print(f"bench_simulator, {started}; load average (1/5/15 min, `uptime`) {load0} at the start, {_load()} after "
          f"the resolutions; linear solver {solver}; {os.cpu_count()} CPUs; median of {a.repeats} solves")
    print(f"Default LV, HO theta=(0.60,1.30,1.00,3.60), 8 mmHg, angles (-60,+90); linear solver {solver}")
    print("CPU shared with other jobs: compare ratios within this table.\n")
    print("| resolution | dofs | LVV (mL) | EDV/V₀ | mean strain | max rel. change vs finest (LVV; strains) "
          "| Newton its | tangents | steps | first solve incl. compile (s) | median solve, new case (s) "
          "| median repeated solve, prepared case cached (s) | measured (UTC) | load before | solver |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for res, r, first, med, rep, when, load in rows:
        y = r.outputs()
        dv = abs(y[0] - ref[0]) / ref[0]
        ds = np.max(np.abs(y[1:] - ref[1:]) / np.abs(ref[1:]))
        print(f"| {resolution_label(res)} | {r.dofs} | {y[0]:.2f} | {r.lvv_standardised:.3f} | {np.mean(y[1:]):.4f} | "
              f"{dv:.2%}; {ds:.2%} | {r.newton_iterations} | {r.timings.get('tangents', '-')} | {r.load_steps} | "
              f"{first:.2f} | {med:.3f} | {rep:.3f} | {when} | {load} | {solver} |")
    if a.cold:
        res = a.cold
        load = _load()
        print(f"\ncold start (new process: import + compile or cache load + first solve) at {res}: "
              f"{cold_start(res):.2f} s ({_now()}, load before {load}, {solver})")
    if a.processes:
        res = rows[0][0] if len(rows) == 1 else a.resolutions[1]
        n = 2 * (a.throughput_solves // 2)
        ones, twos = [], []
        load = _load()
        for _ in range(a.throughput_rounds):  # alternate, so slow drifts in the machine's load hit both
            ones.append(throughput(res, n, 1))
            twos.append(throughput(res, n, 2))
        t1, t2 = max(ones), max(twos)
        print(f"\nthroughput at {res} ({n} solves, best of {a.throughput_rounds} alternating rounds; {_now()}, "
              f"load {load} before, {_load()} after; {solver}): "
              f"1 process {t1:.2f} solves/s {[round(t, 2) for t in ones]}, "
              f"2 processes {t2:.2f} solves/s {[round(t, 2) for t in twos]}, ratio {t2 / t1:.2f}")


if __name__ == "__main__":
    main()
