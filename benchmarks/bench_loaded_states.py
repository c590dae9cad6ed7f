"""Several loaded states and the Klotz prior on one SYNTHETIC subject simulated by the FE simulator.

    python benchmarks/bench_loaded_states.py                     # the full measurement (FE truth, 2 x (500 + 500))
    python benchmarks/bench_loaded_states.py --quick             # the CI version: emulator data, a small budget

The SYNTHETIC subject is the simulator's default LV (``{"kind": "default"}``) at the typical heart's material
(:data:`lvcore.domain.conditions.SIMULATOR_DEFAULT_THETA`: a 0.18 kPa, b 2.60, af 3.34 kPa, bf 2.73), sliding base,
fibres -60/60 deg, simulated by the FE simulator at 8, 14, 20 and 30 mmHg; its measurements are the FE LVV and
24 strains plus noise (sigma_V 5 mL, sigma_S 0.03, seeded). Each row runs ``lvcore calibrate`` in this process
(iid model, ``--derived-draws 0``) and reports a's 90 % interval (q05, q95, their ratio), whether each true
theta lies inside its 90 % interval, and the model's V20 interval against the FE V20:

* route ``mesh``: a subject emulator of that geometry with EDP as an input over 6-30 mmHg (built here with
  ``lvcore emulator build --geometry default --inputs theta,edp --bound edp=6,30 --bound b=0.5,30 --bound
  bf=0.5,30 --prior none --n-train 800`` unless ``--emulator`` names one): 8 mmHg alone, 8 + 20 mmHg, and 8 mmHg
  with ``--prior klotz``;
* route ``infer`` (``--geometry infer --reference-volume`` the FE V0): the bundled ``angles`` emulator, whose
  EDP box is 6-14 mmHg, so its second state is 14 mmHg (20 mmHg would be an extrapolation, refused).

``--quick`` replaces the FE truth by the ``angles`` emulator's own outputs at 8 and 14 mmHg (mean geometry) and
runs 2 chains x (40 + 40): it checks that the script and the route work, not the numbers.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

ROOT = Path(__file__).resolve().parents[1]
SIGMA_V_ML, SIGMA_S = 5.0, 0.03
ANGLES = (-60.0, 60.0)
PRESSURES = (8.0, 14.0, 20.0, 30.0)
BUILD_ARGS = ["--geometry", "default", "--inputs", "theta,edp", "--bound", "edp=6,30", "--bound", "b=0.5,30",
              "--bound", "bf=0.5,30", "--prior", "none", "--n-train", "800", "--workers", "2", "--seed", "0"]


def fe_truth(theta: dict) -> dict:
    """FE outputs of the SYNTHETIC subject at :data:`PRESSURES` and its reference volume V0 (mL)."""
    from lvcore.mechanics.case_inputs import build_case
    from lvcore.mechanics.simulate import simulate

    out, v0 = {}, None
    for p in PRESSURES:
        case = build_case({**theta, "edp": p, "alpha_endo": ANGLES[0], "alpha_epi": ANGLES[1]},
                          geometry={"kind": "default", "resolution": "default"}, base="sliding")
        r = simulate(case, raise_on_failure=True)
        out[p] = [float(v) for v in r.outputs()]
        v0 = float(r.cavity_volume_mm3[0]) / 1000.0
    return {"outputs": out, "v0_ml": v0}


def noisy(y, rng):
    import numpy as np

    y = np.array(y, dtype=float)
    y[0] += SIGMA_V_ML * rng.standard_normal()
    y[1:] += SIGMA_S * rng.standard_normal(24)
    return y


def write_csv(path: Path, states: dict, strains_at=None, extra: dict | None = None) -> Path:
    """One row per loaded state (``states``: pressure -> 25 values); strains only at ``strains_at`` pressures."""
    from lvcore.domain.outputs import OUTPUT_COLUMNS

    cols = ["subject", "edp_mmhg", *OUTPUT_COLUMNS, *(extra or {})]
    lines = [",".join(cols)]
    for p, y in states.items():
        vals = [f"{y[0]:.6g}"] + [f"{v:.6g}" if (strains_at is None or p in strains_at) else "" for v in y[1:]]
        lines.append(",".join(["SYNTHETIC_S1", f"{p:g}", *vals, *(f"{v:g}" for v in (extra or {}).values())]))
    path.write_text("\n".join(lines) + "\n")
    return path


def v20_posterior(out: Path, emulator, geometry_infer: bool):
    """The model's V20 at every posterior draw (a numpy array, mL; None without a posterior): the Klotz prior's
    record, or the emulator at 20 mmHg."""
    import arviz as az
    import jax
    import numpy as np

    from lvcore.emulator.forward import emulator_forward
    from lvcore.domain.outputs import EDP_NAME

    idata = az.from_netcdf(next(out.glob("*_iid.nc")))
    post = idata.posterior
    if "klotz_volumes" in post:
        return np.asarray(post["klotz_volumes"])[..., 0].reshape(-1)
    if geometry_infer or EDP_NAME not in emulator.input_names:
        return None
    lo, hi = float(emulator.lower[list(emulator.input_names).index(EDP_NAME)]), \
        float(emulator.upper[list(emulator.input_names).index(EDP_NAME)])
    if not lo <= 20.0 <= hi:
        return None
    fw = emulator_forward(emulator, [], edp_mmhg=20.0, alpha_endo=ANGLES[0], alpha_epi=ANGLES[1])
    flat = {n: np.asarray(post[n]).reshape(-1) for n in ("a", "b", "af", "bf")}
    return np.asarray(jax.jit(jax.vmap(lambda q: fw(q)[0]))(flat))


def calibrate_row(label: str, data: Path, out: Path, emulator_arg: str, geometry: list, truth: dict,
                  v20_true: float | None, chains: int, warmup: int, samples: int, extra: list | None = None) -> dict:
    import numpy as np

    from lvcore.cli import main
    from lvcore.emulator import load_emulator

    emu = load_emulator(emulator_arg)
    # the FE truth's fibre angles, for an emulator that takes them (a subject emulator has them fixed at -60/60)
    angles = ["--alpha-endo", f"{ANGLES[0]:g}", "--alpha-epi", f"{ANGLES[1]:g}"] if "alpha_endo" in emu.input_names \
        else []
    args = ["calibrate", "--data", str(data), *geometry, "--emulator", emulator_arg, "--model", "iid",
            "--chains", str(chains), "--warmup", str(warmup), "--samples", str(samples), "--derived-draws", "0",
            *angles, "--out", str(out), "--json", *(extra or [])]
    t0 = time.perf_counter()
    buf_out, buf_err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(buf_out), contextlib.redirect_stderr(buf_err):
        code = main(args)
    wall = time.perf_counter() - t0
    if code == 2:
        raise SystemExit(f"{label}: lvcore calibrate refused the input: {buf_err.getvalue()[-2000:]}")
    (rec,) = json.loads((out / "summary.json").read_text())
    a = rec["a"]
    covered = {n: bool(rec[n]["q05"] <= truth[n] <= rec[n]["q95"]) for n in ("a", "b", "af", "bf")}
    v20 = v20_posterior(out, emu, "--geometry" in geometry and "infer" in geometry)
    row = {"row": label, "exit": code, "wall_s": wall, "a_q05": a["q05"], "a_q95": a["q95"],
           "a_ratio": a["q95"] / a["q05"], "covered": covered, "converged": rec["converged"],
           "states": [s["edp_mmhg"] for s in rec.get("loaded_states", [])] or [rec["edp_mmhg"]],
           "prior": (rec.get("prior") or {}).get("name", "none"), "v20_true": v20_true}
    if v20 is not None:
        row.update({"v20_q05": float(np.quantile(v20, 0.05)), "v20_q95": float(np.quantile(v20, 0.95))})
    return row


def ensure_emulator(path: Path) -> Path:
    if (path / "metadata.json").is_file():
        return path
    cmd = [sys.executable, "-m", "lvcore.cli", "emulator", "build", *BUILD_ARGS, "--out", str(path)]
    print("building the subject emulator:", " ".join(cmd[2:]), flush=True)
    subprocess.run(cmd, check=True)
    return path


def run(out_dir: Path, *, quick: bool, emulator: str | None, chains: int, warmup: int, samples: int,
        seed: int = 0, theta: dict | None = None, routes=("mesh", "infer")) -> list[dict]:
    import numpy as np

    from lvcore.domain.conditions import SIMULATOR_DEFAULT_THETA

    out_dir.mkdir(parents=True, exist_ok=True)
    theta = dict(theta or SIMULATOR_DEFAULT_THETA)
    rng = np.random.default_rng(seed)
    rows = []
    if quick:
        from lvcore.emulator.forward import load_emulator_forward

        truth = {p: np.asarray(load_emulator_forward("angles", np.zeros(5), edp_mmhg=p, alpha_endo=ANGLES[0],
                                                     alpha_epi=ANGLES[1])(theta)) for p in (8.0, 14.0)}
        ys = {p: noisy(y, rng) for p, y in truth.items()}
        for label, states in (("quick: 8 mmHg", {8.0: ys[8.0]}), ("quick: 8 + 14 mmHg", ys)):
            d = write_csv(out_dir / f"{len(states)}.csv", states)
            rows.append(calibrate_row(label, d, out_dir / f"q{len(states)}", "angles", ["--geometry", "mean"], theta,
                                      None, chains, warmup, samples))
        return rows
    cache = out_dir / "fe_truth.json"   # the FE solves of this SYNTHETIC subject, kept between runs
    fe = json.loads(cache.read_text()) if cache.is_file() else fe_truth(theta)
    cache.write_text(json.dumps(fe))
    fe["outputs"] = {float(p): y for p, y in fe["outputs"].items()}
    ys = {p: noisy(y, rng) for p, y in fe["outputs"].items()}
    v20 = fe["outputs"][20.0][0]
    print(f"SYNTHETIC subject (FE): V0 {fe['v0_ml']:.1f} mL, LVV " +
          ", ".join(f"{p:g} mmHg {y[0]:.1f}" for p, y in fe["outputs"].items()) + " mL", flush=True)
    emu = str(ensure_emulator(Path(emulator) if emulator else ROOT / "build" / "loaded_states" / "emulator_edp30"))
    mesh = []   # subject emulator: its geometry is bound in
    cases = [("mesh: 8 mmHg", {8.0: ys[8.0]}, emu, mesh, []),
             ("mesh: 8 + 20 mmHg", {8.0: ys[8.0], 20.0: ys[20.0]}, emu, mesh, []),
             ("mesh: 8 mmHg, --prior klotz", {8.0: ys[8.0]}, emu, mesh, ["--prior", "klotz"]),
             ("infer: 8 mmHg", {8.0: ys[8.0]}, "angles", ["--geometry", "infer"], []),
             ("infer: 8 + 14 mmHg", {8.0: ys[8.0], 14.0: ys[14.0]}, "angles", ["--geometry", "infer"], [])]
    for k, (label, states, e, geometry, extra) in enumerate(cases):
        if label.split(":")[0] not in routes:
            continue
        ex = {"reference_volume_ml": round(fe["v0_ml"], 2)} if "infer" in geometry else None
        d = write_csv(out_dir / f"case{k}.csv", states, extra=ex)
        row = calibrate_row(label, d, out_dir / f"case{k}", e, geometry, theta, v20, chains, warmup, samples, extra)
        print(fmt(row), flush=True)
        rows.append(row)
    return rows


def fmt(r: dict) -> str:
    cov = "".join("✓" if r["covered"][n] else "✗" for n in ("a", "b", "af", "bf"))
    v20 = f"{r['v20_q05']:.0f}-{r['v20_q95']:.0f}" if "v20_q05" in r else "–"
    truth = f"{r['v20_true']:.0f}" if r.get("v20_true") is not None else "–"
    return (f"| {r['row']} | {r['a_q05']:.3g}-{r['a_q95']:.3g} | {r['a_ratio']:.1f} | {cov} | {v20} | {truth} | "
            f"{'yes' if r['converged'] else 'no'} | {r['exit']} | {r['wall_s']:.0f} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="the CI version (emulator data, small budget)")
    p.add_argument("--emulator", default=None, help="subject emulator directory (default: build one under build/)")
    p.add_argument("--chains", type=int, default=2, help="chains (default 2)")
    p.add_argument("--warmup", type=int, default=500, help="warm-up per chain (default 500; --quick 40)")
    p.add_argument("--samples", type=int, default=500, help="draws per chain (default 500; --quick 40)")
    p.add_argument("--out", default=str(ROOT / "build" / "loaded_states" / "bench"), help="working folder")
    p.add_argument("--json", default=None, help="also write the rows to this file")
    p.add_argument("--theta", default=None, metavar="A,B,AF,BF",
                   help="the SYNTHETIC subject's theta (default the typical heart 0.18,2.60,3.34,2.73)")
    p.add_argument("--routes", default="mesh,infer", help="routes to run (default mesh,infer)")
    args = p.parse_args(argv)
    theta = None if args.theta is None else dict(zip(("a", "b", "af", "bf"), map(float, args.theta.split(","))))
    if args.quick:
        args.warmup, args.samples = min(args.warmup, 40), min(args.samples, 40)
    from lvcore.inference.samplers import use_host_devices
    from lvcore.mechanics.linear import default_backend

    use_host_devices(args.chains)
    load0 = os.getloadavg()[0]
    rows = run(Path(args.out), quick=args.quick, emulator=args.emulator, chains=args.chains, warmup=args.warmup,
               samples=args.samples, theta=theta, routes=tuple(args.routes.split(",")))
    print(f"\nmachine {platform.node()} ({os.cpu_count()} cores), linear solver {default_backend()}, load "
          f"{load0:.1f} -> {os.getloadavg()[0]:.1f}; {args.chains} chains x ({args.warmup} + {args.samples}), iid; "
          f"SYNTHETIC subject, theta {theta or 'typical heart (0.18, 2.60, 3.34, 2.73)'}")
    print("| row | a 90 % | a q95/q05 | a b af bf covered | V20 90 % (mL) | FE V20 (mL) | converged | exit | wall (s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(fmt(r))
    by = {r["row"]: r for r in rows}
    for one, two in (("mesh: 8 mmHg", "mesh: 8 + 20 mmHg"), ("infer: 8 mmHg", "infer: 8 + 14 mmHg"),
                     ("quick: 8 mmHg", "quick: 8 + 14 mmHg")):
        if one in by and two in by:
            print(f"{two}: a's interval {by[one]['a_ratio'] / by[two]['a_ratio']:.1f}x narrower (ratio q95/q05) "
                  f"than {one}; all four theta covered: {all(by[two]['covered'].values())}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
