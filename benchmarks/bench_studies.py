"""Wall time of the optimisation studies on small budgets (the studies' speed targets in BENCHMARKS.md).

    OMP_NUM_THREADS=1 python benchmarks/bench_studies.py bo [--initial 30] [--iterations 30] [--workers 2]
    OMP_NUM_THREADS=1 python benchmarks/bench_studies.py operators [--patients SYNTHETIC-P01] [--workers 2]
    OMP_NUM_THREADS=1 python benchmarks/bench_studies.py gp [--initial 300] [--iterations 300] [--refit-every 10,20]
    OMP_NUM_THREADS=1 python benchmarks/bench_studies.py sqp-warm [--patients SYNTHETIC-P02] [--test op2]

``bo``: one volunteer (default SYNTHETIC-HV1) in both modes (fixed, free) with
a 30 + 30 budget through the same code path as ``lvcore study bo-fibres``
(target <= 3 min on 2 cores). ``operators``: every fit of one patient (3 main
operators x 4 test geometries = 12 SQP refits with adjoint gradients) as
``lvcore study operators`` runs them (target <= 5 min). Each run starts in a
fresh temporary folder, so nothing is resumed. The machine is shared: the
load average (1 min) before and after and the sparse linear solver are
printed with the result; compare numbers only at similar load. The CPU
seconds of the process and its workers do not depend on the load:
``cpu_s / workers`` estimates the wall time on idle cores (it ignores the
serial GP/acquisition part of BO, which runs while the workers wait).
``gp``: that serial part alone. The BO loop of the ``free`` mode (6 inputs)
runs on :class:`lvcore.testing.AnalyticForward` (microseconds per point), so
its CPU time is the GP fits and the acquisition search of one run of the
study at the given budget, once per ``--refit-every`` value. Sixteen runs
(8 volunteers x 2 modes) make the chapter's study; the 4-input mode costs
less.
``sqp-warm``: one SQP refit of the operator study (data from the patient's
first operator, refitted on ``--test``: another operator, ``pc5`` or
``pc10``) twice in this process, with the Newton warm start
(``SimulatorForward(warm_start=True)``, as the study runs) and cold; prints
CPU seconds, simulations and the difference of the two θ̂.
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported
os.environ.setdefault("LVCORE_NO_PNG", "1")  # time the study, not Chrome starting for PNG export


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("study", choices=("bo", "operators", "gp", "sqp-warm"))
    p.add_argument("--test", default="pc10", help="sqp-warm: test geometry (another operator's name, pc5 or pc10)")
    p.add_argument("--subject", default="SYNTHETIC-HV1")
    p.add_argument("--initial", type=int, default=30)
    p.add_argument("--iterations", type=int, default=30)
    p.add_argument("--patients", default="SYNTHETIC-P01")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--resolution", default="default")
    p.add_argument("--refit-every", default="20", help="gp: comma-separated values to compare (default 20)")
    p.add_argument("--out", default=None, help="keep the outputs here (default: a temporary folder)")
    args = p.parse_args(argv)

    from lvcore.mechanics.linear import available_backends

    import resource

    if args.study == "gp":
        return _bench_gp(args)
    if args.study == "sqp-warm":
        return _bench_sqp_warm(args)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or tmp
        if args.study == "bo":
            from lvcore.studies import bo_fibres

            entries = bo_fibres.run_study([args.subject], out=out, n_initial=args.initial,
                                          n_iterations=args.iterations, workers=args.workers,
                                          resolution=args.resolution)
            detail = {e["mode"]: {"seconds": e["seconds"], "evaluations": e["evaluations"],
                                  "failed": e["failed_evaluations"]["count"],
                                  "lvv_abs_error_ml": round(e["lvv_abs_error_ml"], 2)} for e in entries}
            what = f"bo-fibres {args.subject}, both modes, {args.initial} + {args.iterations}"
        else:
            from lvcore.studies import operators

            res = operators.run_study(args.patients.split(","), out=out, workers=args.workers,
                                      resolution=args.resolution)
            fits = res["fits"]
            detail = {"fits": len(fits), "converged": sum(f["converged"] for f in fits),
                      "simulations": res["meta"]["simulations"]}
            what = f"operators {args.patients} ({len(fits)} SQP refits)"
    wall = time.perf_counter() - t0
    # CPU seconds of this process and of its (finished) worker processes: independent of the machine's load
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = time.process_time() - cpu0 + children.ru_utime + children.ru_stime
    print(json.dumps({"study": what, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
                      "wall_on_idle_cores_estimate_s": round(cpu / max(1, args.workers), 1), "workers": args.workers,
                      "resolution": args.resolution, "linear_solver": available_backends()[0],
                      "load_avg_1min_before": round(load0, 2), "load_avg_1min_after": round(os.getloadavg()[0], 2),
                      "cpus": os.cpu_count(), "detail": detail}, indent=1))
    return 0


def _bench_sqp_warm(args) -> int:
    """One operator-study refit with and without the Newton warm start (same process, same data)."""
    import numpy as np

    from lvcore.domain.outputs import THETA_NAMES
    from lvcore.mechanics.forward import AdjointSimulatorForward, SimulatorForward
    from lvcore.mechanics.linear import available_backends
    from lvcore.optimise.sqp import OperatorLoss, refit_theta
    from lvcore.studies import operators as ops
    from lvcore.studies.operators import CachedForward

    patient = args.patients.split(",")[0]
    with tempfile.TemporaryDirectory() as tmp:
        geoms = ops.patient_geometries(patient, tmp)
        main = ops.operator_names(geoms)[0]
        name = ops.test_geometry_name(main, args.test, geoms)
        truth = np.array(ops.THETA_TRUE)
        y_star = SimulatorForward(geometry={"kind": "mesh", "path": geoms[main]["path"]},
                                  resolution=args.resolution)(dict(zip(THETA_NAMES, truth)))
        loss = OperatorLoss(y_star, geoms[main]["v_early_ml"], geoms[name]["v_early_ml"])
        rows = {}
        for warm in (True, False):
            fwd = CachedForward(AdjointSimulatorForward(geometry={"kind": "mesh", "path": geoms[name]["path"]},
                                                 resolution=args.resolution, warm_start=warm))
            load0 = os.getloadavg()[0]
            c0, t0 = time.process_time(), time.perf_counter()
            res = refit_theta(fwd, loss, truth)
            rows[warm] = (time.process_time() - c0, time.perf_counter() - t0, fwd.simulations, res, load0)
    print(f"operator-study SQP refit: {patient}, data from {main}, refitted on {args.test} ({name}), "
          f"{args.resolution} mesh, {available_backends()[0]}, one process")
    print("| Newton start | CPU s | wall s | simulations (value + adjoint) | SLSQP evaluations | loss | load before |")
    print("|---|---|---|---|---|---|---|")
    for warm, (cpu, wall, sims, res, l0) in rows.items():
        print(f"| {'warm' if warm else 'cold'} | {cpu:.1f} | {wall:.1f} | {sims} | {res.n_evaluations} | "
              f"{res.loss:.6g} | {l0:.1f} |")
    a, b = rows[True][3].theta, rows[False][3].theta
    print(f"theta_hat warm {np.round(a, 5).tolist()} vs cold {np.round(b, 5).tolist()}: "
          f"max relative difference {np.max(np.abs(a - b) / np.abs(b)):.2e}; "
          f"CPU ratio cold/warm {rows[False][0] / rows[True][0]:.2f}")
    return 0


def _bench_gp(args) -> int:
    """CPU time of the GP + acquisition loop of one free-mode BO run per --refit-every value."""
    import warnings

    import numpy as np
    from sklearn.exceptions import ConvergenceWarning

    from lvcore.testing.analytic import AnalyticForward
    from lvcore.optimise.bayesopt import bayesian_optimise
    from lvcore.studies import bo_fibres

    space = bo_fibres.bo_space("free")
    fwd = AnalyticForward(input_names=space.names)
    truth = {"a": 0.8, "b": 2.0, "af": 1.5, "bf": 4.0, "alpha_endo": -50.0, "alpha_epi": 55.0}
    measured = np.asarray(fwd(truth))
    rows = []
    for refit in (int(v) for v in args.refit_every.split(",")):
        load0 = os.getloadavg()[0]
        c0, t0 = time.process_time(), time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            res = bayesian_optimise(fwd, measured, space, n_initial=args.initial, n_iterations=args.iterations,
                                    seed=0, refit_every=refit)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        rows.append((refit, cpu, wall, res.f_best, load0, os.getloadavg()[0]))
    print(f"GP + acquisition of one free-mode BO run, {args.initial} + {args.iterations}, AnalyticForward "
          f"(OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')})")
    print("| refit every | CPU s | wall s | best objective | x16 runs, CPU min | load before/after |")
    print("|---|---|---|---|---|---|")
    for refit, cpu, wall, fbest, l0, l1 in rows:
        print(f"| {refit} | {cpu:.1f} | {wall:.1f} | {fbest:.3g} | {16 * cpu / 60:.1f} | {l0:.1f}/{l1:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
