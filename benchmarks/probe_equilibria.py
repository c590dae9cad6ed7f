"""Where is the equilibrium not unique? Each row of a design started six ways at full load, against its cold solve.

    OMP_NUM_THREADS=1 nice .venv/bin/python benchmarks/probe_equilibria.py [--design sobol800|ci] [--rows soft|edge]

The measurement behind the simulator's soft corner (``lvcore.mechanics.forward.SOFT_CORNER_KPA``, where
warm starts are not used). ``material`` space, default LV, ``fast`` mesh. For each selected row: its cold
solve (the reference), then warm-only Newton solves at full load (no continuation, no cold fallback) from

* the cold states of its three nearest rows (in the design's unit cube),
* the spline prediction from its 30 nearest rows' cold states (``lvcore.execution.chains.predicted_state``,
  what a campaign chain starts from),
* that prediction plus Gaussian noise of 1 % and 5 % of the displacements' RMS (seed 0).

A converged warm solve more than 1e-6 relative (``|Δ| / max(|y|, 1e-3)``, LVV and 24 strains) from the
cold solve is another equilibrium. Rows: ``--design sobol800`` the 800-row Sobol design (seed 1) of
``benchmarks/bench_campaign_reproducible.py``; ``ci`` the 120-row design of
``tests/test_campaign_reproducible.py``. ``--rows soft``: a and af both below 0.6 kPa; ``edge``: one below
0.15 kPa and the other above 0.6 (every second such row). Prints the rows with another equilibrium and,
per band of max(a, af), the rows, converged warm starts, other equilibria and the largest difference of
the warm starts that found the cold one. Results: docs/reliability.md ("Reproducible campaigns").
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

BANDS = ((0.0, 0.2), (0.2, 0.3), (0.3, 0.6), (0.6, np.inf))


def _design(name: str) -> np.ndarray:
    from lvcore.campaigns.designs import make_design
    from lvcore.campaigns.space import get_space

    if name == "sobol800":
        return make_design(get_space("material"), "sobol", 800, seed=1).points
    import test_campaign_reproducible as t

    return np.vstack([t._sobol(t.SOFT_BOX, t.N_SOFT), t._sobol(t.MODERATE_BOX, t.N_ROWS - t.N_SOFT)])


def _rel(y: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(y - ref) / np.maximum(np.abs(ref), 1e-3)))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--design", choices=("sobol800", "ci"), default="sobol800", help="rows (default sobol800)")
    p.add_argument("--rows", choices=("soft", "edge"), default="soft", help="which rows to probe (default soft)")
    args = p.parse_args(argv)
    from lvcore.campaigns.space import get_space
    from lvcore.execution.chains import Seed, SeedPool, predicted_state
    from lvcore.mechanics import forward as F
    from lvcore.mechanics.linear import default_backend
    from lvcore.mechanics.simulate import simulate

    t0 = time.perf_counter()
    pts = _design(args.design)
    space = get_space("material")
    U = space.to_unit(pts)
    lo, hi = np.minimum(pts[:, 0], pts[:, 2]), np.maximum(pts[:, 0], pts[:, 2])
    todo = np.flatnonzero(hi < 0.6) if args.rows == "soft" else np.flatnonzero((lo < 0.15) & (hi >= 0.6))[::2]
    near = {int(i): np.argsort(np.linalg.norm(U - U[i], axis=1))[:31] for i in todo}
    fwd = F.SimulatorForward(input_names=space.names, conditions=space.fixed_dict(), resolution="fast",
                             base=space.base)
    cases = [fwd.case(dict(zip(space.names, x))) for x in pts]
    cold = {}
    for j in sorted(set(np.concatenate(list(near.values())).tolist())):
        r = simulate(cases[j])
        cold[j] = (r.outputs(), F._as_warm(r, F.case_values(cases[j]))._replace(tangent=None)) if r.converged \
            else (np.full(25, np.nan), None)
    opts = F._warm_only_options()
    rng = np.random.default_rng(0)
    found: dict[int, list] = {}
    for i in todo:
        nb = [int(j) for j in near[int(i)][1:] if cold[int(j)][1] is not None]
        pred = predicted_state(U[i], SeedPool([Seed(U[j], cold[j][1], j) for j in nb]))
        rms = np.linalg.norm(pred.u) / np.sqrt(pred.u.size)
        starts = [cold[j][1] for j in nb[:3]] + [pred] + \
                 [pred._replace(u=pred.u + eps * rms * rng.standard_normal(pred.u.size)) for eps in (0.01, 0.05)]
        found[int(i)] = []
        for st in starts:
            r = simulate(cases[i], options=opts, initial=st)
            if r.converged and np.all(np.isfinite(cold[int(i)][0])):
                found[int(i)].append(_rel(r.outputs(), cold[int(i)][0]))
    other = {i: d for i, d in found.items() if any(x > 1e-6 for x in d)}
    print(f"probe_equilibria, design {args.design}, rows {args.rows}: {len(todo)} rows, {len(cold)} cold solves, "
          f"linear solver {default_backend()}, {time.perf_counter() - t0:.0f} s")
    print("\nrows with another equilibrium (a, b, af, bf; largest relative difference):")
    for i, d in other.items():
        print(f"  row {i}: {np.round(pts[i], 4).tolist()}; {max(d):.2g}")
    print("\n| max(a, af) kPa | rows | converged warm starts | other equilibria | rows with one | largest diff. of the rest |")
    print("|---|---|---|---|---|---|")
    for b0, b1 in BANDS:
        rows = [i for i in found if b0 <= hi[i] < b1]
        diffs = [x for i in rows for x in found[i]]
        same = [x for x in diffs if x <= 1e-6]
        print(f"| [{b0}, {b1}) | {len(rows)} | {len(diffs)} | {len(diffs) - len(same)} | "
              f"{sum(i in other for i in rows)} | {max(same):.1e} |" if same else
              f"| [{b0}, {b1}) | {len(rows)} | {len(diffs)} | {len(diffs) - len(same)} | "
              f"{sum(i in other for i in rows)} | - |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
