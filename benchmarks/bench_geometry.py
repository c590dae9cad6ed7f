"""Geometry benchmarks: template fitting time per contour stack and the cohort build time.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_geometry.py [--stacks 12] [--cohort]

* Fitting: the bundled SYNTHETIC operator stacks (18 files) plus freshly generated
  synthetic stacks are fitted with :func:`lvcore.geometry.fitting.fit_contours`
  after one warm-up fit (imports). Target: <= 2 s per stack (max).
* ``--cohort``: times ``scripts/build_cohort.py`` end to end into a temporary
  directory (80 fits + PCA). Target: <= 10 min.

The machine is shared; the load average is printed with the result.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402

import lvcore  # noqa: E402,F401
from lvcore.geometry.cohort import COHORT_DIR, REFERENCE_OPERATOR, contour_stack, sample_lv  # noqa: E402
from lvcore.geometry.contours import read_contours  # noqa: E402
from lvcore.geometry.fitting import fit_contours  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--stacks", type=int, default=12, help="extra generated stacks to fit")
    ap.add_argument("--cohort", action="store_true", help="also time the full cohort build")
    args = ap.parse_args(argv)
    stacks = [read_contours(p) for p in sorted((COHORT_DIR / "contours").glob("*.json"))]
    rng = np.random.default_rng(7)
    stacks += [contour_stack(sample_lv(rng), REFERENCE_OPERATOR, rng, patient=f"B{i}") for i in range(args.stacks)]
    fit_contours(stacks[0])  # warm-up
    times, res = [], []
    for st in stacks:
        t = time.perf_counter()
        r = fit_contours(st)
        times.append(time.perf_counter() - t)
        res.append((r.residual_mean_mm, r.residual_max_mm))
    res = np.array(res)
    print(f"fit_contours: {len(stacks)} stacks, mean {np.mean(times):.3f} s, max {np.max(times):.3f} s per stack "
          f"(target <= 2 s); residual mean of means {res[:, 0].mean():.3f} mm, worst max {res[:, 1].max():.3f} mm; "
          f"load average {os.getloadavg()[0]:.2f}")
    ok = np.max(times) <= 2.0
    if args.cohort:
        with tempfile.TemporaryDirectory() as d:
            t = time.perf_counter()
            subprocess.run([sys.executable, str(ROOT / "scripts" / "build_cohort.py"), "--out", d], check=True,
                           stdout=subprocess.DEVNULL)
            dt = time.perf_counter() - t
        print(f"build_cohort.py: {dt:.0f} s (target <= 600 s); load average {os.getloadavg()[0]:.2f}")
        ok = ok and dt <= 600
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
