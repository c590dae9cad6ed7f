"""Benchmark the hierarchical calibration of a SYNTHETIC cohort (``lvcore calibrate --hierarchical``).

    nice python benchmarks/bench_hierarchical.py                       # 24 subjects, then a two-group cohort
    nice python benchmarks/bench_hierarchical.py --n 8 --warmup 300    # a smaller run
    nice python benchmarks/bench_hierarchical.py --states 8,20         # two loaded states per subject (edpvr)

1. One group: a SYNTHETIC cohort of ``--n`` subjects (``lvcore.inference.cohort.synthetic_cohort``: log theta ~
   N(mu, Sigma) inside Table 9.1's box, PC scores and scale per subject, data from the ``chapter`` emulator with
   sigma_V = 5 mL, sigma_S = 0.03), calibrated through the CLI in a child process (joint NUTS plus the separate fits);
   timed (wall and process CPU, the load average), then checked: do mu's 90 % intervals cover the true mu (all 4
   of log theta), is the median narrowing of the subjects' a intervals against separate fits >= 2x, is the
   coverage of the subjects' 90 % intervals in [0.8, 1.0] (per parameter)?
2. Two groups (``--n`` subjects, half each, group B's population a twice group A's): does the 90 % interval of
   the difference in mu_a exclude 0?

``--states 8,20`` measures every subject at each of these pressures (its data, and the calibration, through an
emulator with an EDP input: ``--emulator``, default ``edpvr`` then, the EDPVR emulator composed with ``chapter``).

Prints one JSON record (``--out FILE`` also writes it). Pin threads (the script does) and run niced on a shared
machine; the timings then depend on the load, which is recorded.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()


def _calibrate(csv: Path, out: Path, args) -> tuple[int, dict, dict]:
    """``lvcore calibrate --hierarchical`` on one cohort in a child process of its own (a process keeps memory
    mappings of every program it compiled: two two-state cohorts in one process passed the kernel's limit)."""
    import resource
    import subprocess

    t0, c0, load0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN), os.getloadavg()[0]
    code = subprocess.call([sys.executable, "-m", "lvcore.cli", "calibrate", "--data", str(csv), "--hierarchical",
                            "--model", "iid", "--chains", str(args.chains), "--warmup", str(args.warmup),
                            "--samples", str(args.samples), "--seed", str(args.seed), "--emulator", args.emulator,
                            "--out", str(out)])
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    timing = {"wall_s": round(time.perf_counter() - t0, 1),
              "cpu_s": round(c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime, 1),
              "load_start": round(load0, 1), "load_end": round(os.getloadavg()[0], 1)}
    rec = json.loads((out / "summary.json").read_text())["hierarchical"]
    return code, rec, timing


def _checks(rec: dict, truth: dict) -> dict:
    import numpy as np

    names = truth["theta_names"]
    mu = rec["population"]["groups"]["all"]["mu_log"]
    true_mu = truth["mu_log"]["A"]
    mu_cover = {k: bool(mu[k]["q05"] <= true_mu[j] <= mu[k]["q95"]) for j, k in enumerate(names)}
    cover = {}
    for j, k in enumerate(names):
        hits = [rec["subjects"][s][k]["q05"] <= th[j] <= rec["subjects"][s][k]["q95"]
                for s, th in truth["theta"].items()]
        cover[k] = float(np.mean(hits))
    sep_cover = {}
    for j, k in enumerate(names):
        hits = [rec["separate"][s][k]["q05"] <= th[j] <= rec["separate"][s][k]["q95"]
                for s, th in truth["theta"].items()]
        sep_cover[k] = float(np.mean(hits))
    narrowing = rec["shrinkage"]["median_narrowing"]
    return {"mu_covered": mu_cover, "mu_all_covered": all(mu_cover.values()),
            "mu_log": {k: [round(mu[k]["q05"], 3), round(mu[k]["median"], 3), round(mu[k]["q95"], 3)] for k in names},
            "mu_true": dict(zip(names, [round(v, 3) for v in true_mu])),
            "sd_log": {k: [round(v["q05"], 3), round(v["median"], 3), round(v["q95"], 3)]
                       for k, v in rec["population"]["sd"].items()},
            "sd_true": dict(zip(names, [round(float(np.sqrt(truth["cov_log"][j][j])), 3) for j in range(4)])),
            "median_narrowing": {k: None if v is None else round(v, 2) for k, v in narrowing.items()},
            "narrowing_a_ge_2": bool(narrowing["a"] is not None and narrowing["a"] >= 2.0),
            "subject_coverage": cover, "separate_coverage": sep_cover,
            "subject_coverage_ok": all(0.8 <= v <= 1.0 for v in cover.values()),
            "diagnostics": {lv: {k: d[k] for k in ("max_rhat", "min_ess_bulk", "n_divergent", "converged")}
                            for lv, d in rec["diagnostics"].items()}}


def ship(work, result: dict, folder) -> Path:
    """The report's result file (:mod:`lvcore.studies.cohort`) from a finished run in ``work``: the one-group
    cohort's summary (without the per-subject geometry records), its truth, the two-group difference in mu_a and
    the run's settings and checks."""
    from lvcore.studies.registry import result_file

    work = Path(work)
    rec = json.loads((work / "one_group" / "out" / "summary.json").read_text())["hierarchical"]
    rec.pop("geometry", None)
    rec["data_file"] = "cohort.csv (SYNTHETIC, benchmarks/bench_hierarchical.py)"
    out = {"label": "SYNTHETIC", "hierarchical": rec,
           "truth": json.loads((work / "one_group" / "truth.json").read_text()),
           "two_groups": result.get("two_groups"),
           "meta": {k: result[k] for k in ("n", "chains", "warmup", "samples", "seed")}
           | {"command": "nice python benchmarks/bench_hierarchical.py --ship assets/studies",
              "checks": {k: v for k, v in result["one_group"].items() if k not in ("diagnostics",)}}}
    path = Path(folder) / result_file("cohort")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1))
    return path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=24, help="subjects per cohort (default 24)")
    p.add_argument("--chains", type=int, default=2, help="chains (default 2)")
    p.add_argument("--warmup", type=int, default=500, help="warm-up per chain (default 500)")
    p.add_argument("--samples", type=int, default=500, help="draws per chain (default 500)")
    p.add_argument("--seed", type=int, default=0, help="cohort and sampler seed (default 0)")
    p.add_argument("--skip-groups", action="store_true", help="only the one-group cohort")
    p.add_argument("--states", default="", help="loaded states per subject, mmHg, e.g. 8,20 (default: one state at "
                                                 "the emulator's fixed EDP)")
    p.add_argument("--emulator", default=None, help="the emulator of the data and the calibration (default chapter; "
                                                     "edpvr with --states)")
    p.add_argument("--workdir", default=None, help="folder for the cohorts and outputs (default: a temporary one)")
    p.add_argument("--out", default=None, help="also write the JSON record here")
    p.add_argument("--ship", default=None, metavar="FOLDER",
                   help="write the report's result file (cohort.json, lvcore.studies.cohort) into FOLDER, e.g. "
                        "assets/studies (default: none)")
    args = p.parse_args(argv)
    states = tuple(float(v) for v in args.states.split(",") if v.strip())
    args.emulator = args.emulator or ("edpvr" if states else "chapter")

    from lvcore.emulator.io import load_emulator
    from lvcore.inference import cohort as co

    work = Path(args.workdir or tempfile.mkdtemp(prefix="bench_hier_"))
    emulator = load_emulator(args.emulator)
    result = {"label": "SYNTHETIC", "n": args.n, "chains": args.chains, "warmup": args.warmup,
              "samples": args.samples, "seed": args.seed, "cpus": os.cpu_count(), "emulator": args.emulator,
              "states_mmhg": list(states)}
    csv = co.write_cohort(co.synthetic_cohort(args.n, emulator, seed=args.seed, edp_mmhg=states), work / "one_group")
    code, rec, timing = _calibrate(csv, work / "one_group" / "out", args)
    truth = json.loads((csv.parent / "truth.json").read_text())
    result["one_group"] = {"exit": code, **timing, "joint_wall_s": round(rec["wall_s"], 1), **_checks(rec, truth)}
    print(json.dumps(result["one_group"]), file=sys.stderr)
    if not args.skip_groups:
        csv2 = co.write_cohort(co.synthetic_cohort(args.n, emulator, seed=args.seed + 1, n_groups=2, edp_mmhg=states),
                               work / "two_groups")
        code2, rec2, timing2 = _calibrate(csv2, work / "two_groups" / "out", args)
        d = rec2["population"]["differences"]["B - A"]["a"]
        result["two_groups"] = {"exit": code2, **timing2, "true_ratio_a": 2.0,
                                "ratio_a": [round(d["ratio"][k], 3) for k in ("q05", "median", "q95")],
                                "detected": d["excludes_zero"], "flags": rec2.get("flags", []),
                                "ratio_a_separate": [round(rec2["population"]["differences_separate"]["B - A"]["a"]
                                                           ["ratio"][k], 3) for k in ("q05", "median", "q95")],
                                "others_exclude_zero": {k: v["excludes_zero"] for k, v in
                                                        rec2["population"]["differences"]["B - A"].items() if k != "a"}}
    text = json.dumps(result, indent=1)
    print(text)
    if args.ship:
        ship(work, result, args.ship)
    if args.out:
        Path(args.out).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
