"""Coverage of 90% credible intervals on SYNTHETIC data sets made without discrepancy.

    python benchmarks/coverage.py                       # iid model, 100 data sets, analytic stand-in
    python benchmarks/coverage.py --model discrepancy --n 50
    python benchmarks/coverage.py --forward emulator    # truths from the prior through the 'chapter' emulator

theta is drawn from its Table 9.1 prior, y = forward(theta) + noise
(sigma_V = 5 mL, sigma_S = 0.03); the fraction of central 90% intervals that
contain the truth should be about 0.90 (binomial sd printed).
"""
from __future__ import annotations

import argparse
import json
import sys

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", default="iid", choices=("volume", "iid", "discrepancy"))
    p.add_argument("--n", type=int, default=100, help="number of data sets (>= 50)")
    p.add_argument("--level", type=float, default=0.9)
    p.add_argument("--chains", type=int, default=2)
    p.add_argument("--warmup", type=int, default=500)
    p.add_argument("--samples", type=int, default=500)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--forward", default="analytic", choices=("analytic", "emulator"))
    p.add_argument("--emulator", default="chapter")
    args = p.parse_args(argv)

    import lvcore  # noqa: F401
    from lvcore.exceptions import EmulatorError
    from lvcore.inference import coverage, samplers
    from lvcore.emulator.forward import load_emulator_forward
    from lvcore.testing.analytic import AnalyticForward

    if args.forward == "analytic":
        forward = AnalyticForward()
    else:
        try:
            forward = load_emulator_forward(args.emulator, [0.5, -0.4, 0.3, -0.2, 0.1])
        except EmulatorError as err:
            print(err, file=sys.stderr)
            return 2
    cfg = samplers.SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains)
    res = coverage.coverage_study(forward, args.model, args.n, level=args.level, config=cfg, seed=args.seed)
    out = {"model": res.model, "forward": forward.label, "n_datasets": res.n_datasets, "level": res.level,
           "coverage_overall": round(res.overall, 3), "coverage_per_param": res.per_param,
           "binomial_sd": round(res.binomial_sd(), 3), "wall_s": round(res.wall_s, 1)}
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
