"""Land et al. (2015) benchmark problems 1 and 2: mesh-convergence tables.

Usage::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
        python benchmarks/land2015.py [--problem 1|2|both] [--p1 10,1,1 20,2,2] [--p2 6,8,2 12,8,2]

Prints markdown tables (dofs, results, Newton iterations, wall time) to be
pasted into docs/simulator.md. Reference values: problem 1 tip z in
[4.151, 4.185] mm (consensus ~4.17); problem 2 (Simula/FEniCS converged)
endocardial apex z = -26.612 mm, epicardial apex z = -28.279 mm, cavity
volume 10734 mm³.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

from lvcore.mechanics.verification import P1_TIP_POINT, P1_TIP_Z_RANGE_MM, P2_REF, problem1_case, problem2_case  # noqa: E402


def _timed(case):
    from lvcore.mechanics.simulate import simulate

    t0 = time.perf_counter()
    r = simulate(case)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = simulate(case)
    return r, first, time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default="both", choices=["1", "2", "both"])
    ap.add_argument("--p1", nargs="*", default=["10,1,1", "20,2,2", "30,3,3"])
    ap.add_argument("--p2", nargs="*", default=["6,8,2", "6,12,2", "6,16,3", "12,8,2"])
    a = ap.parse_args(argv)
    from lvcore.mechanics.linear import available_backends

    print(f"linear solver: {available_backends()[0]}; CPU shared with other jobs (times are indicative)\n")
    if a.problem in ("1", "both"):
        lo, hi = P1_TIP_Z_RANGE_MM
        print(f"Problem 1 (beam), tip {P1_TIP_POINT}: reference z in [{lo}, {hi}] mm\n")
        print("| elements (x,y,z) | dofs | tip x | tip y | tip z | Newton its | 1st run incl. compile (s) | warm (s) |")
        print("|---|---|---|---|---|---|---|---|")
        for s in a.p1:
            res = tuple(int(v) for v in s.split(","))
            r, first, warm = _timed(problem1_case(res))
            tip = r.probes[0] if r.converged else [float("nan")] * 3
            print(f"| {res} | {r.dofs} | {tip[0]:.4f} | {tip[1]:.4f} | {tip[2]:.4f} | {r.newton_iterations} "
                  f"| {first:.1f} | {warm:.1f} |", flush=True)
        print()
    if a.problem in ("2", "both"):
        print(f"Problem 2 (LV inflation): reference endo apex z {P2_REF['endo']}, epi apex z {P2_REF['epi']} mm, "
              f"volume {P2_REF['volume']:.0f} mm³\n")
        print("| elements (circ x long x trans, Gauss points through the wall) | dofs | endo apex z | epi apex z | volume (mm³) | vol. error "
              "| Newton its | steps | 1st run incl. compile (s) | warm (s) |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        from lvcore.mechanics.resolution import resolution_label

        for s in a.p2:
            r, first, warm = _timed(problem2_case(s))
            res = resolution_label(s)
            if r.converged:
                v = r.cavity_volume_mm3[1]
                print(f"| {res} | {r.dofs} | {r.apex_endocardium[2]:.3f} | {r.apex_epicardium[2]:.3f} | {v:.0f} "
                      f"| {(v - P2_REF['volume']) / P2_REF['volume']:+.2%} | {r.newton_iterations} | {r.load_steps} "
                      f"| {first:.1f} | {warm:.1f} |", flush=True)
            else:
                print(f"| {res} | {r.dofs} | failed: {r.message} |", flush=True)


if __name__ == "__main__":
    sys.exit(main())
