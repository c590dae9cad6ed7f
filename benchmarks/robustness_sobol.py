"""Robustness sweep: scrambled Sobol design over materials, fibre angles and EDP on the default LV.

Usage::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
        python benchmarks/robustness_sobol.py [--n 256] [--resolution default] [--seed 0] [--out results.csv]

a, b, af, bf log-uniform in [0.1, 10]; alpha_endo uniform in [-90, 0] deg,
alpha_epi in [0, 90] deg; EDP uniform in [4, 30] mmHg. Prints the converged
fraction, every failure with its reason, and timing quantiles.
"""
from __future__ import annotations

import argparse
import csv
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported


def design(n: int, seed: int):
    import numpy as np
    from scipy.stats import qmc

    u = qmc.Sobol(d=7, scramble=True, seed=seed).random(n)
    lo = np.array([np.log(0.1)] * 4 + [-90.0, 0.0, 4.0])
    hi = np.array([np.log(10.0)] * 4 + [0.0, 90.0, 30.0])
    x = lo + u * (hi - lo)
    x[:, :4] = np.exp(x[:, :4])
    return x


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=256)
    ap.add_argument("--resolution", default="default")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="optional CSV of every run")
    a = ap.parse_args(argv)
    import numpy as np

    from lvcore.mechanics.case import Case
    from lvcore.mechanics.simulate import simulate

    X = design(a.n, a.seed)
    rows, fails, times = [], [], []
    for i, (A, B, AF, BF, ae, ap_, edp) in enumerate(X):
        case = Case.default_lv({"a": A, "b": B, "af": AF, "bf": BF}, ae, ap_, edp, resolution=a.resolution)
        t0 = time.perf_counter()
        try:
            r = simulate(case)
            ok, msg = r.converged, r.message
            lvv = r.outputs()[0] if ok else float("nan")
            its = r.newton_iterations
        except Exception as exc:  # report, never hide
            ok, msg, lvv, its = False, f"{type(exc).__name__}: {exc}", float("nan"), -1
        dt = time.perf_counter() - t0
        times.append(dt)
        rows.append([i, A, B, AF, BF, ae, ap_, edp, ok, its, lvv, dt, msg])
        if not ok:
            fails.append(rows[-1])
        print(f"{i:4d} ok={ok} its={its:3d} t={dt:6.2f}s lvv={lvv:8.2f} {'' if ok else msg}", flush=True)
    n_ok = sum(r[8] for r in rows)
    t = np.array(times)
    print(f"\nconverged {n_ok}/{len(rows)} = {n_ok / len(rows):.1%}; time per solve median {np.median(t):.2f} s, "
          f"90% {np.quantile(t, 0.9):.2f} s, max {t.max():.2f} s (shared CPU)")
    for r in fails:
        print(f"FAILED #{r[0]}: a={r[1]:.3g} b={r[2]:.3g} af={r[3]:.3g} bf={r[4]:.3g} alpha=({r[5]:.1f},{r[6]:.1f}) "
              f"edp={r[7]:.1f} mmHg: {r[12]}")
    if a.out:
        with open(a.out, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["i", "a", "b", "af", "bf", "alpha_endo", "alpha_epi", "edp_mmhg", "converged", "newton_iterations",
                        "lvv_ml", "seconds", "message"])
            w.writerows(rows)


if __name__ == "__main__":
    main()
