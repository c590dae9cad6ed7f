"""CPU cost and ESS of the mismatch study's calibrations, per batch size and sampler budget.

    OMP_NUM_THREADS=1 nice python benchmarks/bench_mismatch.py [--batch 20,40] [--budgets 1x150+150,2x300+300]
        [--models volume,iid,discrepancy] [--repeats 1]

One compiled batch of ``--batch`` SYNTHETIC data sets (two volunteers' geometries,
the data the ``chapter`` emulator gives at their hidden θ plus an RMS 0.04 strain
offset that θ cannot absorb, plus noise), calibrated as
:func:`lvcore.studies.mismatch.fit_datasets` does, once per likelihood and
budget. Prints a table: the first run (compile included) and the median of
``--repeats`` further runs in CPU seconds of the process, CPU seconds per data
set, and the per-data-set minimum bulk ESS over θ and σ_S² (median and
smallest, ArviZ) and the share with R-hat > 1.05. The machine is shared: the
load average before and after is printed; CPU seconds do not depend on it much.
"""
from __future__ import annotations

import argparse
import os
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported


def _budget(text: str):
    chains, rest = text.split("x")
    warm, samples = rest.split("+")
    return int(chains), int(warm), int(samples)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--batch", default="40", help="comma-separated batch sizes (data sets per compiled run)")
    p.add_argument("--budgets", default="2x300+300", help="comma-separated CHAINSxWARMUP+SAMPLES")
    p.add_argument("--models", default="volume,iid,discrepancy")
    p.add_argument("--repeats", type=int, default=1, help="timed runs after the first (compile) run")
    p.add_argument("--volunteers", default="HV1,HV5")
    args = p.parse_args(argv)

    import jax
    import numpy as np

    from lvcore.emulator.forward import emulator_forward
    from lvcore.emulator.io import load_emulator
    from lvcore.inference import samplers
    from lvcore.domain.outputs import THETA_NAMES
    from lvcore.studies import mismatch as mm

    load0 = os.getloadavg()[0]
    emu = load_emulator("chapter")
    vols = mm.bundled_volunteers(args.volunteers.split(","))
    fwd = {v.name: emulator_forward(emu, v.h, name="chapter") for v in vols}
    offset = np.r_[0.0, 0.04 * (-1.0) ** (np.arange(24) % 6)]
    rows = []
    for batch in (int(b) for b in args.batch.split(",")):
        per = [vols[i % len(vols)] for i in range(batch)]
        z = [np.asarray(fwd[v.name](v.theta), dtype=float) for v in per]
        ys = np.stack([zi + offset + mm.noisy_copies(np.zeros(25), 1, 100 + i)[0] for i, zi in enumerate(z)])
        conds = np.stack([np.asarray(samplers.runtime_conditions(fwd[v.name])[1]["conditions"]) for v in per])
        truths = np.array([[v.theta[n] for n in THETA_NAMES] for v in per])
        for budget in args.budgets.split(","):
            chains, warm, samples = _budget(budget)
            cfg = samplers.SamplerConfig(num_warmup=warm, num_samples=samples, num_chains=chains)
            for m in args.models.split(","):
                times, res = [], None
                for r in range(1 + args.repeats):
                    t = time.process_time()
                    res = mm.fit_datasets(fwd[vols[0].name], ys, conds, truths, np.stack(z), config=cfg,
                                          keys=jax.random.split(jax.random.PRNGKey(r), batch), models=(m,))
                    times.append(time.process_time() - t)
                d = res[m]
                rhat = d.get("max_rhat")
                timed = float(np.median(times[1:])) if len(times) > 1 else float("nan")
                rows.append((batch, budget, m, times[0], timed, timed / batch, float(np.median(d["min_ess"])),
                             float(np.min(d["min_ess"])), float(np.mean(np.asarray(rhat) > 1.05)) if rhat is not None
                             else float("nan")))
                print("  done: " + _row_text(rows[-1]), flush=True)  # each row as it ends (a run cut short keeps it)
    print(f"\nload average (1 min) before {load0:.2f}, after {os.getloadavg()[0]:.2f}; "
          f"{os.cpu_count()} CPUs; CPU seconds of this process")
    print(HEADER)
    for r in rows:
        print(_row_text(r))
    return 0


HEADER = (f"{'batch':>5} {'budget':>12} {'likelihood':>12} {'first CPU-s':>11} {'median CPU-s':>12} "
          f"{'CPU-s/set':>9} {'ESS med':>8} {'ESS min':>8} {'Rhat>1.05':>9}")


def _row_text(r) -> str:
    return (f"{r[0]:>5} {r[1]:>12} {r[2]:>12} {r[3]:>11.1f} {r[4]:>12.1f} {r[5]:>9.2f} {r[6]:>8.0f} {r[7]:>8.0f} "
            f"{r[8]:>9.2f}")


if __name__ == "__main__":
    raise SystemExit(main())
