"""Benchmark one calibration: wall time (compilation included), ESS and ESS/s per model and sampler.

    python benchmarks/bench_calibration.py                      # the real 'chapter' emulator
    python benchmarks/bench_calibration.py --forward analytic   # SYNTHETIC closed-form stand-in

Runs (4 chains x 1000 warm-up + 1000 draws by default): volume (NUTS), iid
(NUTS), discrepancy (HMC-within-Gibbs, Algorithm 4) and discrepancy (joint
NUTS). Data: one SYNTHETIC data set, forward(theta_ref) + noise (sigma_V = 5 mL,
sigma_S = 0.03) plus a smooth strain discrepancy, so model (iii) has work to do.
Set OMP_NUM_THREADS=1 etc.; targets (2 cores): iid <= 20 s, discrepancy <= 60 s.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--forward", default="emulator", choices=("emulator", "analytic"))
    p.add_argument("--emulator", default="chapter")
    p.add_argument("--h", default="0.5,-0.4,0.3,-0.2,0.1", help="PC scores bound into the emulator")
    p.add_argument("--chains", type=int, default=4)
    p.add_argument("--warmup", type=int, default=1000)
    p.add_argument("--samples", type=int, default=1000)
    p.add_argument("--chain-method", default="auto")
    p.add_argument("--runs", default="volume,iid,discrepancy,discrepancy-nuts")
    p.add_argument("--dense-mass", action="store_true", help="dense NUTS mass matrix (default: diagonal)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    from lvcore.inference.samplers import use_host_devices

    use_host_devices(args.chains)

    import numpy as np

    import lvcore  # noqa: F401
    from lvcore.exceptions import EmulatorError
    from lvcore.inference import diagnostics, kernels, samplers
    from lvcore.inference.coverage import simulate_data
    from lvcore.emulator.forward import load_emulator_forward
    from lvcore.testing.analytic import AnalyticForward

    h = [float(v) for v in args.h.split(",")]
    if args.forward == "analytic":
        forward = AnalyticForward()
    else:
        try:
            forward = load_emulator_forward(args.emulator, h)
        except EmulatorError as err:
            print(f"{err}\n(use --forward analytic for the SYNTHETIC closed-form stand-in)", file=sys.stderr)
            return 2
    theta = {"a": 0.6, "b": 5.0, "af": 1.5, "bf": 5.0}
    x = kernels.strain_grid()
    disc = 0.03 * np.cos(x[:, 0] - 1.0) + 0.02 * (x[:, 1] - 1.5) / 1.5
    y = simulate_data(forward, theta, np.random.default_rng(0), discrepancy=disc)
    cfg = samplers.SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains,
                                 chain_method=args.chain_method, dense_mass=args.dense_mass)
    rows = []
    for name in args.runs.split(","):
        model, sampler = (name, "auto") if name != "discrepancy-nuts" else ("discrepancy", "nuts")
        run = samplers.run_model(model, y, forward, cfg, sampler=sampler)
        conv = diagnostics.check_convergence(run)
        eps = diagnostics.ess_per_second(run)
        rows.append({"run": name, "sampler": run.method, "wall_s": round(run.wall_s, 1),
                     "min_ess_theta": round(eps["min"] * run.wall_s), "ess_per_s_min_theta": round(eps["min"], 1),
                     "max_rhat": round(conv.max_rhat, 3), "divergent": conv.n_divergent,
                     "mean_steps": float(np.mean(run.sample_stats["n_steps"]))})
        if not args.json:
            r = rows[-1]
            print(f"{name:18s} {r['sampler']:9s} wall {r['wall_s']:6.1f} s  min ESS(theta) {r['min_ess_theta']:6d}  "
                  f"ESS/s {r['ess_per_s_min_theta']:7.1f}  R-hat {r['max_rhat']:.3f}  div {r['divergent']}  "
                  f"steps/iter {r['mean_steps']:.0f}", flush=True)
    meta = {"forward": getattr(forward, "label", ""), "chains": args.chains, "warmup": args.warmup,
            "samples": args.samples, "dense_mass": args.dense_mass, "chain_method": getattr(samplers.resolve_chain_method(cfg), "__name__", samplers.resolve_chain_method(cfg)),
            "load_average": os.getloadavg(), "time": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
    if args.json:
        print(json.dumps({"meta": meta, "rows": rows}, indent=2))
    else:
        print(json.dumps(meta))
    return 0


if __name__ == "__main__":
    sys.exit(main())
