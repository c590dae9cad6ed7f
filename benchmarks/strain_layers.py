"""Mesh convergence of the four strain layers on the default LV at 8 mmHg (accuracy, not timing).

Usage::

    python benchmarks/strain_layers.py [--theta 0.18,2.60,3.34,2.73] [--resolutions fast default 6,2+1+1+2,2,5 ...]

Solves the default LV (clamped base, 8 mmHg) once per resolution and averages the same displacement over every
layer of :data:`lvcore.domain.outputs.STRAIN_LAYERS`; prints a markdown table of the region-mean strain of each
layer and the largest regional difference from the last (finest) resolution. A resolution is a preset name or
``NC,LEVELS,NT[,GP]`` with LEVELS ``a+b+c+d`` (element rows per short-axis level, graded) or one number.
"""
from __future__ import annotations

import argparse
import time


def _resolution(spec: str):
    from lvcore.mechanics.resolution import RESOLUTION_PRESETS, LVResolution

    if spec in RESOLUTION_PRESETS:
        return spec, RESOLUTION_PRESETS[spec]
    parts = spec.split(",")
    nc, nt = int(parts[0]), int(parts[2])
    gp = int(parts[3]) if len(parts) > 3 else 3
    levels = tuple(int(v) for v in parts[1].split("+"))
    res = (LVResolution.graded(nc, levels, nt, transmural_gauss_points=gp) if len(levels) > 1
           else LVResolution(nc, levels[0], nt))
    return res.case_dict(), res


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--theta", default="0.18,2.60,3.34,2.73", help="a, b, af, bf (default: %(default)s)")
    p.add_argument("--resolutions", nargs="+",
                   default=["fast", "default", "6,2+1+1+2,2,5", "6,2+1+1+2,3,5", "accurate", "12,4+2+2+4,4,5"],
                   help="resolutions, the finest last (default: %(default)s)")
    args = p.parse_args(argv)
    import numpy as np

    from lvcore.domain.outputs import STRAIN_LAYERS
    from lvcore.mechanics import observables as ob
    from lvcore.mechanics.case import Case
    from lvcore.mechanics.simulate import build_mesh, simulate

    theta = dict(zip(("a", "b", "af", "bf"), (float(v) for v in args.theta.split(","))))
    rows = []
    for spec in args.resolutions:
        geo_res, res = _resolution(spec)
        case = Case.from_dict({"geometry": {"kind": "default", "resolution": geo_res},
                               "material": {"law": "holzapfel-ogden", **theta},
                               "load": {"pressure": 8, "units": "mmHg"}})
        t0 = time.perf_counter()
        r = simulate(case, raise_on_failure=True)
        mesh, x = build_mesh(case), r.reference_nodes + r.displacement
        e = {L: np.asarray(ob.regional_strains(x, ob.strain_operator(mesh, L))) for L in STRAIN_LAYERS}
        rows.append((spec, res.describe(), e, time.perf_counter() - t0))
    finest = rows[-1][2]
    print("| resolution | " + " | ".join(f"{L}: mean, max Δ" for L in STRAIN_LAYERS) + " |")
    print("|---|" + "---|" * len(STRAIN_LAYERS))
    for spec, desc, e, _ in rows:
        cells = [f"{e[L].mean():+.4f}, {np.abs(e[L] - finest[L]).max():.4f}" for L in STRAIN_LAYERS]
        print(f"| {spec} ({desc}) | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
