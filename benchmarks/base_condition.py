"""Base boundary condition study: ``clamped`` vs ``sliding`` on the default LV.

Runs the default LV (lvcore's ``default`` mesh) at the chapter's conditions
(fibre angles -60/60 deg, EDP 8 mmHg) for a few material points, once with the
base clamped (every dof of the base nodes held) and once sliding (the base
stays in its plane, in-plane rigid modes removed; see
:mod:`lvcore.mechanics.boundary`), and prints how the 25 outputs differ.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/base_condition.py [--resolution default] [--json OUT.json]

Printed per material point: LVV under each condition, the mean and max
absolute strain difference, the difference per short-axis level, the
correlation of the two 24-strain patterns and the correlation of their
24-strain patterns without the basal level, and the spread (sd) of each pattern.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402

#: Material points (kPa, -, kPa, -): the reference point, a stiffer matrix, a stiffer fibre direction.
THETAS = {
    "reference": {"a": 0.60, "b": 1.30, "af": 1.00, "bf": 3.60},
    "stiff matrix": {"a": 2.00, "b": 5.00, "af": 1.00, "bf": 3.60},
    "stiff fibres": {"a": 0.30, "b": 1.00, "af": 3.00, "bf": 10.0},
}


def run_one(theta, base, resolution):
    from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP
    from lvcore.mechanics.case import Case
    from lvcore.mechanics.simulate import simulate

    case = Case.default_lv(theta=theta, alpha_endo_deg=CHAPTER_ANGLES[0], alpha_epi_deg=CHAPTER_ANGLES[1],
                           edp_mmhg=CHAPTER_EDP, resolution=resolution)
    d = case.to_dict() if hasattr(case, "to_dict") else None
    if d is None:
        raise SystemExit("Case.to_dict is missing; cannot switch the base condition")
    d["boundary"] = {"base": base}
    t0 = time.perf_counter()
    res = simulate(Case.from_dict(d), raise_on_failure=True)
    return res.outputs(), time.perf_counter() - t0


def compare(y_c, y_s) -> dict:
    """Differences between the clamped (y_c) and sliding (y_s) outputs."""
    ec, es = y_c[1:], y_s[1:]
    d = es - ec
    per_level = [float(np.mean(np.abs(d[6 * k:6 * k + 6]))) for k in range(4)]
    dc, ds = ec - ec.mean(), es - es.mean()
    return {
        "lvv_clamped_ml": float(y_c[0]), "lvv_sliding_ml": float(y_s[0]),
        "lvv_change_pct": float(100 * (y_s[0] - y_c[0]) / y_c[0]),
        "mean_strain_clamped": float(ec.mean()), "mean_strain_sliding": float(es.mean()),
        "mean_abs_diff": float(np.mean(np.abs(d))), "max_abs_diff": float(np.max(np.abs(d))),
        "max_abs_diff_region": int(np.argmax(np.abs(d))),
        "mean_abs_diff_per_level": per_level,
        "pattern_corr": float(np.corrcoef(ec, es)[0, 1]),
        "corr_below_base_level": float(np.corrcoef(ec[6:], es[6:])[0, 1]),
        "pattern_sd_clamped": float(dc.std()), "pattern_sd_sliding": float(ds.std()),
        "strain_clamped": ec.tolist(), "strain_sliding": es.tolist(),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", default="default")
    ap.add_argument("--thetas", nargs="*", default=list(THETAS), choices=list(THETAS))
    ap.add_argument("--json", default=None, help="also write the raw numbers here")
    args = ap.parse_args(argv)
    rows = {}
    for name in args.thetas:
        y_c, t_c = run_one(THETAS[name], "clamped", args.resolution)
        y_s, t_s = run_one(THETAS[name], "sliding", args.resolution)
        rows[name] = {**compare(y_c, y_s), "seconds": [t_c, t_s], "theta": THETAS[name]}
        print(f"done {name} ({t_c:.0f} s + {t_s:.0f} s)", file=sys.stderr, flush=True)
    print(f"Base condition, default LV ({args.resolution} mesh), angles -60/60 deg, EDP 8 mmHg\n")
    print("| theta | LVV clamped (mL) | LVV sliding (mL) | ΔLVV | mean E_cc clamped | mean E_cc sliding | "
          "mean abs ΔE | max abs ΔE (region) | mean abs ΔE per level (base→apex) | corr (24) | corr (levels 2-4) | "
          "pattern sd clamped / sliding |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, r in rows.items():
        lv = " / ".join(f"{v:.4f}" for v in r["mean_abs_diff_per_level"])
        print(f"| {name} | {r['lvv_clamped_ml']:.2f} | {r['lvv_sliding_ml']:.2f} | {r['lvv_change_pct']:+.2f} % | "
              f"{r['mean_strain_clamped']:.4f} | {r['mean_strain_sliding']:.4f} | {r['mean_abs_diff']:.4f} | "
              f"{r['max_abs_diff']:.4f} (r{r['max_abs_diff_region'] + 1}) | {lv} | {r['pattern_corr']:.3f} | "
              f"{r['corr_below_base_level']:.3f} | {r['pattern_sd_clamped']:.4f} / {r['pattern_sd_sliding']:.4f} |")
    shown = "reference" if "reference" in rows else next(iter(rows))
    r = rows[shown]
    print(f"\nPer-region strains ({shown} theta), level x sector, clamped | sliding:")
    for k in range(4):
        c = " ".join(f"{v:+.4f}" for v in r["strain_clamped"][6 * k:6 * k + 6])
        s = " ".join(f"{v:+.4f}" for v in r["strain_sliding"][6 * k:6 * k + 6])
        print(f"  L{k + 1}: {c} | {s}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
