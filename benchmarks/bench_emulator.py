"""Emulator benchmarks: prediction speed and held-out accuracy.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_emulator.py [--emulator NAME_OR_DIR ...]

Speed: 100,000-row batch prediction (target <= 1 s) and single-row latency
after warm-up (target <= 1 ms), for ``Emulator.predict`` (with box checks) and
the pure ``Emulator.apply``. Without a trained emulator the timing uses an
untrained network of the largest architecture (9 -> 200 -> 200 -> 25): the
cost does not depend on the weights; such rows say "untrained (timing only)".

Subject-specific build (``--subject GEOMETRY``): ``lvcore emulator build
--geometry GEOMETRY`` end to end in a fresh process (start-up, geometry
fit, FE runs, training, held-out validation), ``--repeats`` times; prints
the wall time of each stage, the held-out LVV and strain RMSE (targets:
<= 3 min on 2 cores, <= 1 mL, <= 0.003), the load average before and after
and the linear solver::

    python benchmarks/bench_emulator.py --subject assets/volunteers/SYNTHETIC_HV3_geometry.vtu --repeats 3

Accuracy: for each emulator given, the metrics stored at training on its
held-out set (``test`` if present, else ``validation``): RMSE per output and
the 99th percentile of |error| (the worst 1 %), against the targets LVV RMSE
<= 1 mL, strain RMSE <= 0.003.
"""
from __future__ import annotations

import argparse
import os
import time
import warnings

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402

import lvcore  # noqa: E402,F401
from lvcore.emulator.model import Emulator  # noqa: E402
from lvcore.emulator.network import MLP  # noqa: E402
from lvcore.domain.outputs import OUTPUT_NAMES  # noqa: E402


def timing_emulator() -> Emulator:
    names = ("a", "b", "af", "bf", "h1", "h2", "h3", "h4", "h5")
    lower = np.array([0.05, 0.1, 0.05, 0.1, -3, -3, -3, -3, -3.0])
    upper = np.array([10, 30, 10, 30, 3, 3, 3, 3, 3.0])
    return Emulator(name="untrained (timing only)", input_names=names, lower=lower, upper=upper,
                    log_inputs=(True,) * 4 + (False,) * 5, x_mean=np.zeros(9), x_sd=np.ones(9),
                    y_mean=np.zeros(25), y_sd=np.ones(25), network=MLP(9, 25, (200, 200), seed=0))


def draw(emu: Emulator, n: int, seed: int = 0) -> np.ndarray:
    u = np.random.default_rng(seed).random((n, emu.dim))
    return emu.lower + u * (emu.upper - emu.lower)


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def speed(emu: Emulator) -> list[tuple[str, float, str]]:
    big = draw(emu, 100_000)
    one = draw(emu, 1)[0]
    named = dict(zip(emu.input_names, one))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        np.asarray(emu.predict(big)); np.asarray(emu.predict(one)); np.asarray(emu.predict(**named))  # warm-up / compile
        t_big = best_of(lambda: np.asarray(emu.predict(big)), 3)
        t_big_apply = best_of(lambda: emu.apply(big).block_until_ready(), 3)
        n = 2000
        t_one = best_of(lambda: [np.asarray(emu.predict(one)) for _ in range(n)], 3) / n
        t_named = best_of(lambda: [np.asarray(emu.predict(**named)) for _ in range(n)], 3) / n
        t_apply = best_of(lambda: [emu.apply(one).block_until_ready() for _ in range(n)], 3) / n
    return [
        ("predict, 100,000 rows", t_big, "<= 1 s"),
        ("apply, 100,000 rows", t_big_apply, "<= 1 s"),
        ("predict, 1 row (array)", t_one, "<= 1 ms"),
        ("predict, 1 row (keywords)", t_named, "<= 1 ms"),
        ("apply, 1 row", t_apply, "<= 1 ms"),
    ]


def accuracy_table(meta: dict) -> str:
    key = "test" if "test" in meta else "validation"
    m = meta[key]
    lines = [f"held-out set: '{key}' (n = {m['n']}); trained on {meta['training']['n_train']} runs",
             f"LVV RMSE {m['lvv_rmse_ml']:.3f} mL (target <= 1, aim 0.5), p99 |err| {m['lvv_p99_abs_ml']:.3f} mL; "
             f"strain RMSE {m['strain_rmse']:.4f} (target <= 0.003), p99 |err| {m['strain_p99_abs']:.4f}",
             "| output | RMSE | p99 abs err (worst 1 %) | max abs err |", "|---|---|---|---|"]
    for i, name in enumerate(OUTPUT_NAMES):
        unit = " mL" if i == 0 else ""
        lines.append(f"| {name} | {m['rmse'][i]:.4g}{unit} | {m['p99_abs'][i]:.4g}{unit} | {m['max_abs'][i]:.4g}{unit} |")
    if meta.get("spec_note"):
        lines.append(f"NOTE: {meta['spec_note']}")
    return "\n".join(lines)


def physiological_table(emu: Emulator) -> str | None:
    """Held-out accuracy restricted to runs with a physiological LVV (50-250 mL)."""
    from lvcore.emulator.io import load_validation
    from lvcore.emulator.training import metrics

    src = emu.metadata.get("_dir")
    val = load_validation(src) if src else None
    if val is None:
        return None
    keep = (val["outputs"][:, 0] >= 50) & (val["outputs"][:, 0] <= 250)
    if keep.sum() < 5:
        return None
    m = metrics(val["outputs"][keep], val["predictions"][keep])
    return (f"held-out runs with 50 <= LVV <= 250 mL ({int(keep.sum())} of {keep.size}): LVV RMSE {m['lvv_rmse_ml']:.3f} mL "
            f"(p99 {m['lvv_p99_abs_ml']:.3f}), strain RMSE {m['strain_rmse']:.4f} (p99 {m['strain_p99_abs']:.4f})")


def subject_build(args) -> int:
    """``lvcore emulator build`` end to end in a fresh process, ``args.repeats`` times."""
    import json
    import subprocess
    import sys
    import tempfile

    from lvcore.mechanics.linear import available_backends

    rows = []
    print(f"subject emulator from {args.subject}: linear solver {available_backends()[0]}, "
          f"{args.workers} worker(s), extra options {args.build_options or 'none'}", flush=True)
    print("| run | load before | total wall (CPU) | geometry | FE runs (solves/s) | training | held-out LVV RMSE | "
          "held-out strain RMSE | load after |\n|---|---|---|---|---|---|---|---|---|", flush=True)
    for k in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "emu")
            load0 = os.getloadavg()
            import resource

            cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            cmd = [sys.executable, "-m", "lvcore.cli", "emulator", "build", "--geometry", args.subject, "--out", out,
                   "--workers", str(args.workers), "--seed", str(args.seed + k), *args.build_options.split()]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
            load1 = os.getloadavg()
            if proc.returncode != 0:
                print(proc.stdout[-2000:], proc.stderr[-2000:])
                return proc.returncode
            meta = json.loads(open(os.path.join(out, "metadata.json")).read())
        sub, test = meta["subject"], meta["test"]
        sec, runs = sub["seconds"], sub["runs"]
        rows.append({"wall_s": wall, "cpu_s": cpu, "lvv": test["lvv_rmse_ml"], "strain": test["strain_rmse"], **sec})
        print(f"| {k + 1} | {load0[0]:.2f} | {wall:.1f} s ({cpu:.0f} CPU-s) | {sec['geometry']:.1f} s | {sec['simulations']:.1f} s "
              f"({runs['total'] / sec['simulations']:.1f}; {runs['converged']}/{runs['total']} converged) | "
              f"{sec['training']:.1f} s | {test['lvv_rmse_ml']:.3f} mL | {test['strain_rmse']:.4f} | {load1[0]:.2f} |",
              flush=True)
    med = {k: float(np.median([r[k] for r in rows])) for k in ("wall_s", "cpu_s", "lvv", "strain", "simulations",
                                                               "training")}
    print(f"median of {len(rows)}: total {med['wall_s']:.1f} s (target <= 180 s; {med['cpu_s']:.0f} CPU-s over all "
          f"processes), FE runs {med['simulations']:.1f} s, "
          f"training {med['training']:.1f} s; held-out LVV RMSE {med['lvv']:.3f} mL (target <= 1), strain RMSE "
          f"{med['strain']:.4f} (target <= 0.003); {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--emulator", nargs="*", default=[], help="emulator names or directories (default: bundled ones)")
    p.add_argument("--subject", default=None, metavar="GEOMETRY",
                   help="time `lvcore emulator build --geometry GEOMETRY` end to end instead")
    p.add_argument("--repeats", type=int, default=1, help="builds with --subject (seeds seed..seed+n-1)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--build-options", default="", help="more `lvcore emulator build` options, one string")
    args = p.parse_args(argv)
    if args.subject:
        return subject_build(args)
    from lvcore.emulator.io import available_emulators, load_emulator

    names = args.emulator or available_emulators()
    from lvcore.emulator.io import resolve_emulator_dir

    emus = []
    for n in names:
        emu = load_emulator(n)
        emu.metadata["_dir"] = str(resolve_emulator_dir(n))
        emus.append(emu)
    emus = emus or [timing_emulator()]
    import jax
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}; OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}; "
          "2-core machine shared with other jobs: timings are noisy (best of 3)")
    for emu in emus:
        print(f"\n## emulator '{emu.name}': {emu.dim} -> {list(emu.network.hidden)} -> 25")
        print("| operation | time | target |\n|---|---|---|")
        for label, t, target in speed(emu):
            shown = f"{t * 1e3:.3f} ms" if t < 0.1 else f"{t:.3f} s"
            print(f"| {label} | {shown} | {target} |")
        if emu.metadata.get("training"):
            print()
            print(accuracy_table(emu.metadata))
            phys = physiological_table(emu)
            if phys:
                print(phys)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
