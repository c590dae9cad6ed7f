"""Held-out accuracy of a subject emulator against the number of training FE runs.

    nice -n 15 python benchmarks/emulator_ntrain_study.py simulate --work DIR [--subject GEOMETRY]
    nice -n 15 python benchmarks/emulator_ntrain_study.py train --work DIR --n-train 256 384 512

``simulate`` runs two scrambled Sobol designs over the subject prior box (``lvcore emulator build``'s
space, default mesh, sliding base) on the subject's geometry, resumably (``DIR/pool_*.npz`` are the
build's checkpoint files): a training pool (``--pool-train`` points, seed 0) and an independent
validation/test pool (``--pool-test`` points, seed 1; its first ``--n-valid`` rows validate, the rest
are the held-out test). ``train`` trains the subject recipe (:func:`lvcore.emulator.subject.default_training_config`)
on the first ``n`` rows of the training pool for each ``--n-train`` and prints the held-out LVV and strain
RMSE on the test rows, which no training saw. Per-row solver seconds of each pool are printed too
(fewer runs are farther apart, so warm starts help less).
"""
from __future__ import annotations

import argparse
import os
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402

SUBJECT = "assets/volunteers/SYNTHETIC_HV3_geometry.vtu"


def _pools(args):
    from lvcore.campaigns.designs import make_design
    from lvcore.emulator.subject import subject_space

    space = subject_space(("theta",))
    return space, {"train": make_design(space, "sobol", args.pool_train, 0).points,
                   "test": make_design(space, "sobol", args.pool_test, 1).points}


def simulate(args) -> int:
    from lvcore.emulator.subject import resolve_subject_geometry, simulate_rows
    from lvcore.geometry.io import write_template_mesh

    os.makedirs(args.work, exist_ok=True)
    geo = resolve_subject_geometry(args.subject)
    path = os.path.join(args.work, "geometry.vtu")
    write_template_mesh(path, geo.nodes)
    section = {"kind": "mesh", "path": os.path.abspath(path)}
    space, pools = _pools(args)
    for key, x in pools.items():
        t0 = time.perf_counter()
        runs = simulate_rows(space, x, section, workers=args.workers, checkpoint=os.path.join(args.work, f"pool_{key}.npz"),
                             chunk=args.chunk, progress=lambda d, n: print(f"  {key}: {d}/{n} {time.strftime('%H:%M:%S')}",
                                                                           flush=True))
        np.savez(os.path.join(args.work, f"done_{key}.npz"), inputs=x, outputs=runs.outputs, converged=runs.converged,
                 seconds=runs.seconds)
        print(f"{key}: {runs.converged.sum()}/{len(x)} converged, {time.perf_counter() - t0:.1f} s wall, "
              f"{runs.seconds.sum():.1f} solver-s", flush=True)
    return 0


def train(args) -> int:
    from lvcore.emulator.subject import default_training_config, subject_space
    from lvcore.emulator.training import metrics, train_emulator

    space = subject_space(("theta",))
    tr = np.load(os.path.join(args.work, "done_train.npz"))
    te = np.load(os.path.join(args.work, "done_test.npz"))
    xv, yv, okv = te["inputs"][:args.n_valid], te["outputs"][:args.n_valid], te["converged"][:args.n_valid]
    xt, yt, okt = te["inputs"][args.n_valid:], te["outputs"][args.n_valid:], te["converged"][args.n_valid:]
    print("| n_train | seed | valid | test | held-out LVV RMSE (mL) | strain RMSE | LVV p99 | training s |")
    print("|---|---|---|---|---|---|---|---|")
    for n in args.n_train:
        for seed in args.seeds:
            x, y, ok = tr["inputs"][:n], tr["outputs"][:n], tr["converged"][:n]
            cfg = default_training_config(seed)
            if args.set:
                import ast
                from dataclasses import replace
                cfg = replace(cfg, **{k: ast.literal_eval(v) for k, v in (kv.split("=", 1) for kv in args.set)})
            t0 = time.perf_counter()
            emu = train_emulator(x[ok], y[ok], xv[okv], yv[okv], input_names=space.names, name="study",
                                 lower=space.lower, upper=space.upper, fixed=space.fixed_dict(), config=cfg)
            dt = time.perf_counter() - t0
            m = metrics(yt[okt], np.asarray(emu.apply(xt[okt])))
            print(f"| {n} | {seed} | {okv.sum()} | {okt.sum()} | {m['lvv_rmse_ml']:.3f} | {m['strain_rmse']:.4f} | "
                  f"{m['lvv_p99_abs_ml']:.3f} | {dt:.1f} |", flush=True)
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("phase", choices=("simulate", "train"))
    p.add_argument("--work", required=True)
    p.add_argument("--subject", default=SUBJECT)
    p.add_argument("--pool-train", type=int, default=512)
    p.add_argument("--pool-test", type=int, default=256)
    p.add_argument("--n-valid", type=int, default=56)
    p.add_argument("--n-train", type=int, nargs="*", default=[256, 384, 512])
    p.add_argument("--seeds", type=int, nargs="*", default=[0])
    p.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE",
                   help="TrainingConfig fields other than the subject recipe's, e.g. lbfgs_iterations=3000")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--chunk", type=int, default=32)
    args = p.parse_args(argv)
    return simulate(args) if args.phase == "simulate" else train(args)


if __name__ == "__main__":
    raise SystemExit(main())
