"""Campaign throughput: warm-started continuation chains against cold solves, and 1 vs 2 workers.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_campaign.py --chains [--rows 1000] [--cold-rows 100]
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_campaign.py [--rows 24] [--resolution fast]   # 1 vs 2 workers

``--chains``: one seeded θ design (``--box moderate``: a, af in
[0.3, 1.5] kPa, b, bf in [1, 5], log-uniform; ``--box material``: the whole
``material`` space) on the ``default`` mesh, through the same code path as
``lvcore campaign run`` (rows recorded in an HDF5 store as they arrive), in one
run:

* the cold loop: one process, one cold ``simulate`` per row (the first ``--cold-rows`` rows);
* cold rows on a 2-worker pool, one task per row (``lvcore campaign run --cold``), same rows;
* warm-chained on 1 worker and on 2 workers, every row (``lvcore campaign run``, the default);

and checks that the chained rows equal the cold ones (largest difference of
LVV and strains over the common rows). Each pool is started and warmed up
(imports, compile) before its timed run. The load average (``uptime``) is
printed before and after every phase: the machine is shared, so compare ratios
within one run.

Without ``--chains``: the older 1 vs 2 workers comparison (cold rows; best of
``--repeats`` alternating runs).

``--chain-profile N``: where the time of a warm-chained solve goes.
The first N points of the same design's continuation order are solved in this
process, one chain (:func:`lvcore.execution.chains.solve_in_order`, each point warm-started
from the nearest converged one, as a campaign worker does), after one
compile run. Printed per solve: Newton iterations, tangents (= numeric
factorisations), residual evaluations and cold fallbacks (deterministic
counts: comparable on a loaded machine), and the wall and CPU time split into
tangent assembly, factorisation, back-substitutions, residuals (line search),
the rest of Newton and the rest of the solve (case set-up, outputs)::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_campaign.py --chain-profile 200
"""
from __future__ import annotations

import argparse
import datetime as _dt
import os
import tempfile
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402

from lvcore.campaigns.designs import Design  # noqa: E402
from lvcore.campaigns.runner import DEFAULT_FORWARD, _drive, execute_row, row_inputs  # noqa: E402
from lvcore.campaigns.space import get_space  # noqa: E402
from lvcore.campaigns.store import CampaignStore, read_store  # noqa: E402
from lvcore.core.registry import make_forward, registered_name  # noqa: E402
from lvcore.execution.parallel import LocalExecutor  # noqa: E402


def _load() -> str:
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


def _design(box: str, rows: int, seed: int) -> Design:
    space = get_space("material")
    rng = np.random.default_rng(seed)
    if box == "moderate":
        # a, af in [0.3, 1.5] kPa; b, bf in [1, 5] (log-uniform): typical solves, no extreme corners
        u = rng.uniform(0, np.log(5), (rows, 4))
        return Design(space, np.exp(np.log([0.3, 1.0, 0.3, 1.0]) + u), "custom", seed)
    return Design(space, space.from_unit(rng.random((rows, 4))), "custom", seed)


def _campaign(ex: LocalExecutor, design: Design, fwd, forward: str, resolution: str, chained: bool, tmp: str):
    """Warm the pool up, then time one campaign over ``design``; returns (rows/s, store contents, chain stats)."""
    warm = [ex.submit(execute_row, fwd, -1, row_inputs(design, i % design.n)) for i in range(ex.workers)]
    for f in ex.as_completed(warm):
        f.result()
    path = os.path.join(tmp, f"s{time.monotonic_ns()}.h5")
    with CampaignStore.create(path, design, forward=registered_name(forward), resolution=resolution) as store:
        t0 = time.perf_counter()
        stats = _drive(store, store.pending_rows(), ex, forward=fwd, progress=False, chained=chained)
        wall = time.perf_counter() - t0
    return design.n / wall, read_store(path), stats


def chains_table(args) -> int:
    from lvcore.mechanics.linear import default_backend

    design = _design(args.box, args.rows, args.seed)
    n_cold = min(args.cold_rows, design.n)
    cold_design = Design(design.space, design.points[:n_cold], "custom", args.seed)
    fwd = make_forward(args.forward, design.space, args.resolution)
    started = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    rows, loads = [], []

    # 1. the cold loop in this process
    loads.append(_load())
    execute_row(fwd, -1, row_inputs(design, 0))  # compile
    t0 = time.perf_counter()
    cold = [execute_row(fwd, i, row_inputs(design, i)) for i in range(n_cold)]
    rate = n_cold / (time.perf_counter() - t0)
    y_cold = np.array([r.outputs for r in cold])
    rows.append(("cold loop, one process", n_cold, rate, sum(r.converged for r in cold), "-"))
    with tempfile.TemporaryDirectory() as tmp:
        for label, workers, chained, d in (("cold, one task per row, pool of 2 workers", 2, False, cold_design),
                                           ("warm-chained, 1 worker", 1, True, design),
                                           ("warm-chained, 2 workers", 2, True, design)):
            if workers == 1 and args.skip_one_worker:
                continue
            loads.append(_load())
            with LocalExecutor(workers) as ex:
                rate, c, stats = _campaign(ex, d, fwd, args.forward, args.resolution, chained, tmp)
            info = "-" if stats is None else (f"{stats.chains} chains ({stats.splits} splits), {stats.chunks} chunks, "
                                              f"{stats.warm} warm / {stats.cold} cold starts")
            diff = np.nanmax(np.abs(c.outputs[:n_cold] - y_cold), axis=0)
            rows.append((label, d.n, rate, int(c.converged.sum()), info, diff[0], diff[1:].max()))
            print(f"  done: {label}: {rate:.2f} rows/s (load {loads[-1]} before)", flush=True)
    loads.append(_load())
    print(f"\nbench_campaign --chains, {started}; linear solver {default_backend()}; resolution {args.resolution}; "
          f"box {args.box}; {design.n} rows (cold phases: the first {n_cold}); seed {args.seed}")
    print(f"load average (1/5/15 min, `uptime`) before each phase and at the end: {' -> '.join(loads)}")
    print("(2-core machine shared with other engineers' jobs: compare the ratios within this table)\n")
    print("| way | rows | rows/s | vs cold loop | converged | chains | max abs diff vs cold: LVV mL; strain |")
    print("|---|---|---|---|---|---|---|")
    base = rows[0][2]
    for r in rows:
        diff = f"{r[5]:.1e}; {r[6]:.1e}" if len(r) > 5 else "reference"
        print(f"| {r[0]} | {r[1]} | {r[2]:.2f} | {r[2] / base:.1f}x | {r[3]}/{r[1]} | {r[4]} | {diff} |")
    return 0


def chain_profile(args) -> int:
    """Per-solve counts and time split of one warm chain in this process (see the module docstring)."""
    import statistics

    from lvcore.campaigns.runner import execute_warm_row
    from lvcore.execution.chains import continuation_order, solve_in_order
    from lvcore.mechanics import newton
    from lvcore.mechanics.linear import default_backend

    design = _design(args.box, args.rows, args.seed)
    fwd = make_forward(args.forward, design.space, args.resolution)
    U = design.space.to_unit(design.points)
    order = [int(i) for i in continuation_order(U)[:args.chain_profile]]
    keys = ("iterations", "tangents", "residuals", "seconds", "t_tangent", "t_factor", "t_solve", "t_line")
    point: dict = {}
    runs = []
    real_solve = newton.solve

    def counted_solve(system, opts=None, initial=None):  # every Newton solve of a point: warm, continuation, cold
        res = real_solve(system, opts, initial)
        for k in keys:
            point[k] = point.get(k, 0) + res.timings.get(k, 0)
        point["solves"] = point.get("solves", 0) + 1
        return res

    def solve(i, initial):
        point.clear()
        c0, t0 = time.process_time(), time.perf_counter()
        row, state = execute_warm_row(fwd, i, row_inputs(design, i), initial)
        runs.append((row.converged, time.perf_counter() - t0, time.process_time() - c0, dict(point)))
        return row, state

    newton.solve = counted_solve
    try:
        solve_in_order(order[:2], U[order[:2]], [], solve)  # compile
        runs.clear()
        load0, when = _load(), _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        c0, t0 = time.process_time(), time.perf_counter()
        solve_in_order(order, U[order], [], solve)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        newton.solve = real_solve
    n = len(runs)

    def mean(key):
        return sum(r[3].get(key, 0) for r in runs) / n

    parts = {"tangent assembly": mean("t_tangent"), "factorisation": mean("t_factor"),
             "back-substitutions": mean("t_solve"), "residuals (line search)": mean("t_line")}
    parts["Newton other"] = mean("seconds") - sum(parts.values())
    parts["outside Newton (case set-up, outputs)"] = sum(r[1] for r in runs) / n - mean("seconds")
    print(f"bench_campaign --chain-profile, {when}; linear solver {default_backend()}; resolution {args.resolution}; "
          f"box {args.box}; the first {n} points of the continuation order of {design.n} rows (seed {args.seed}), "
          f"one chain in one process (the campaign worker's path); load average (1/5/15 min) {load0} -> {_load()}")
    print(f"\n{n / wall:.2f} solves/s wall, {1e3 * wall / n:.1f} ms wall and {1e3 * cpu / n:.1f} ms CPU per solve; "
          f"median solve {1e3 * statistics.median(r[1] for r in runs):.1f} ms wall; "
          f"{sum(r[0] for r in runs)}/{n} converged\n")
    print(f"per solve: {mean('iterations'):.2f} Newton iterations, {mean('tangents'):.2f} tangents (= numeric "
          f"factorisations), {mean('residuals'):.2f} residual evaluations (line search), {mean('solves'):.2f} Newton "
          "solves (1 = the warm start converged; more: continuation or cold fallback)\n")
    print("| phase | ms per solve (wall) | share |\n|---|---|---|")
    total = sum(parts.values())
    for k, v in parts.items():
        print(f"| {k} | {1e3 * v:.1f} | {v / total:.0%} |")
    return 0


def throughput(workers: int, design: Design, forward: str, resolution: str) -> tuple[float, int, float]:
    fwd = make_forward(forward, design.space, resolution)
    with LocalExecutor(workers) as ex, tempfile.TemporaryDirectory() as tmp:
        rate, c, _ = _campaign(ex, design, fwd, forward, resolution, False, tmp)
    return rate, int(c.converged.sum()), float(np.nanmean(c.seconds))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--chains", action="store_true", help="warm-chained vs cold; else 1 vs 2 workers")
    p.add_argument("--chain-profile", type=int, default=0, metavar="N",
                   help="per-solve counts and time split of one warm chain of N points in this process")
    p.add_argument("--rows", type=int, default=None, help="design rows (default 1000 with --chains, else 24)")
    p.add_argument("--cold-rows", type=int, default=100, help="--chains: rows of the cold phases")
    p.add_argument("--box", choices=("moderate", "material"), default="moderate")
    p.add_argument("--skip-one-worker", action="store_true", help="--chains: no 1-worker chained phase")
    p.add_argument("--resolution", choices=("fast", "default"), default=None,
                   help="mesh (default: default with --chains, else fast)")
    p.add_argument("--forward", default=DEFAULT_FORWARD, help="registered forward name (default: simulator)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--repeats", type=int, default=2, help="alternate 1- and 2-worker runs this many times; best of each")
    args = p.parse_args(argv)
    if args.chain_profile:
        args.rows = args.rows or 1000
        args.resolution = args.resolution or "default"
        return chain_profile(args)
    if args.chains:
        args.rows = args.rows or 1000
        args.resolution = args.resolution or "default"
        return chains_table(args)
    args.rows = args.rows or 24
    args.resolution = args.resolution or "fast"
    design = _design("moderate", args.rows, args.seed)
    runs = {1: [], 2: []}
    for rep in range(args.repeats):  # alternate, so slow phases of the shared machine hit both
        for w in (1, 2):
            load = os.getloadavg()[0]
            runs[w].append(throughput(w, design, args.forward, args.resolution) + (load,))
            print(f"  run {rep + 1}, {w} worker(s): {runs[w][-1][0]:.3f} rows/s (load average before {load:.1f})", flush=True)
    best = {w: max(r, key=lambda t: t[0]) for w, r in runs.items()}
    print(f"forward {args.forward}, resolution {args.resolution}, {args.rows} rows, cold rows, "
          f"best of {args.repeats} alternating runs")
    print("(2-core machine shared with other engineers' jobs: ratios are noisy and bounded by the free CPU)")
    print("| workers | rows/s | converged | mean solve s | speed-up |\n|---|---|---|---|---|")
    for w, (rate, conv, secs, _) in best.items():
        print(f"| {w} | {rate:.3f} | {conv}/{args.rows} | {secs:.3f} | {rate / best[1][0]:.2f}x |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
