"""Reproducible campaigns: one design run straight, killed and resumed, and cold, row by row.

    OMP_NUM_THREADS=1 nice .venv/bin/python benchmarks/bench_campaign_reproducible.py [--rows 800] [--workers 1]
        [--resume-workers 2]

Runs a Sobol design over the ``material`` space on the ``fast`` mesh three ways, each through the CLI in a
process of its own (as a user runs it):

1. straight: ``lvcore campaign run`` (warm-started continuation chains, the default);
2. killed and resumed: the same command, SIGKILLed (with its workers) once ``--kill-at`` of the rows are
   committed, then ``lvcore campaign resume`` (on ``--resume-workers`` workers: other chains, other seeds);
3. cold: ``lvcore campaign run --cold`` (every row solved on its own from zero load).

and prints a table: per way, the wall time, the converged rows, the rows that started warm, the rows
solved cold (chain heads and the simulator's soft corner, ``lvcore.mechanics.forward.soft_corner``), the rows
re-solved cold (a suspect warm result, see ``lvcore.mechanics.forward.solve_warm``), and the largest
difference of each row from the cold run,
relative (``|Δ| / max(|y|, 1e-3)``) in LVV and in the 24 strains, with the number of rows off by more than
1e-6. The row order (``run``, ``chain``, ``chain_position``) and seeds (``seed_row``) are read from the
stores. Results: BENCHMARKS.md ("Reproducible campaigns").
"""
from __future__ import annotations

import argparse
import datetime as _dt
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lvcore.campaigns.designs import make_design, save_design  # noqa: E402
from lvcore.campaigns.space import get_space  # noqa: E402
from lvcore.campaigns.store import PENDING, START_COLD, START_RESOLVED, START_WARM, read_store  # noqa: E402
from lvcore.exceptions import CampaignError  # noqa: E402

LVCORE = [sys.executable, "-m", "lvcore.cli"]


def _load() -> str:
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


def _run(args: list[str]) -> float:
    t0 = time.perf_counter()
    res = subprocess.run(LVCORE + args, capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"lvcore {' '.join(args)} failed ({res.returncode}):\n{res.stderr[-3000:]}")
    return time.perf_counter() - t0


def _killed_and_resumed(design: Path, store: Path, workers: int, kill_at: int, resume_workers: int
                        ) -> tuple[float, int]:
    """Run, SIGKILL the campaign and its workers once ``kill_at`` rows are committed, resume; (wall s, rows at kill)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(LVCORE + ["campaign", "run", str(design), "--out", str(store), "--workers", str(workers),
                                      "--resolution", "fast", "--no-progress"],
                            start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    done = 0
    while proc.poll() is None:
        if store.exists():
            try:
                done = int(np.sum(read_store(store).state != PENDING))
            except CampaignError:
                done = 0
            if done >= kill_at:
                break
        time.sleep(0.2)
    if proc.poll() is not None:
        raise SystemExit(f"the campaign ended before the kill: {proc.stderr.read().decode()[-2000:]}")
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    at_kill = int(np.sum(read_store(store).state != PENDING))
    _run(["campaign", "resume", str(store), "--workers", str(resume_workers), "--no-progress"])
    return time.perf_counter() - t0, at_kill


def _diff(y: np.ndarray, ref: np.ndarray) -> tuple[float, float, int]:
    """Largest relative difference of LVV and of the strains, and the rows off by more than 1e-6."""
    rel = np.abs(y - ref) / np.maximum(np.abs(ref), 1e-3)
    rel = np.where(np.isnan(y) & np.isnan(ref), 0.0, rel)  # a row failed both ways agrees
    rel = np.nan_to_num(rel, nan=np.inf)
    return float(rel[:, 0].max()), float(rel[:, 1:].max()), int(np.sum(rel.max(axis=1) > 1e-6))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rows", type=int, default=800, help="design rows (default 800)")
    p.add_argument("--seed", type=int, default=1, help="Sobol seed of the design (default 1)")
    p.add_argument("--workers", type=int, default=1, help="campaign workers (default 1)")
    p.add_argument("--resume-workers", type=int, default=None,
                   help="workers of the resume after the kill (default: --workers)")
    p.add_argument("--kill-at", type=float, default=0.5, help="kill once this share of rows is committed (default 0.5)")
    p.add_argument("--workdir", default=None, help="keep the stores here (default: a temporary folder)")
    args = p.parse_args(argv)
    from lvcore.mechanics.linear import default_backend

    started = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.workdir or tmp)
        work.mkdir(parents=True, exist_ok=True)
        design = make_design(get_space("material"), "sobol", args.rows, seed=args.seed)
        dpath = save_design(design, work / "design.csv")
        stores = {k: work / f"{k}.h5" for k in ("straight", "killed", "cold")}
        for s in stores.values():
            s.unlink(missing_ok=True)
        w = str(args.workers)
        walls, loads, note = {}, {}, {}
        loads["straight"] = _load()
        walls["straight"] = _run(["campaign", "run", str(dpath), "--out", str(stores["straight"]), "--workers", w,
                                  "--resolution", "fast", "--no-progress"])
        print(f"  straight: {walls['straight']:.0f} s", flush=True)
        loads["killed"] = _load()
        rw = args.resume_workers or args.workers
        walls["killed"], at_kill = _killed_and_resumed(dpath, stores["killed"], args.workers,
                                                        max(1, int(args.kill_at * args.rows)), rw)
        note["killed"] = f"killed at {at_kill} rows committed, then resumed on {rw} worker(s)"
        print(f"  killed + resumed: {walls['killed']:.0f} s ({note['killed']})", flush=True)
        loads["cold"] = _load()
        walls["cold"] = _run(["campaign", "run", str(dpath), "--out", str(stores["cold"]), "--workers", w, "--cold",
                              "--resolution", "fast", "--no-progress"])
        print(f"  cold: {walls['cold']:.0f} s", flush=True)
        c = {k: read_store(s) for k, s in stores.items()}
    ref = c["cold"].outputs
    print(f"\nbench_campaign_reproducible, {started}; linear solver {default_backend()}; resolution fast; "
          f"material space, Sobol seed {args.seed}, {args.rows} rows; {args.workers} worker(s); "
          f"load average (1/5/15 min) before each way: " + "; ".join(f"{k} {v}" for k, v in loads.items()))
    print("\n| way | wall s | converged | warm starts | cold | re-solved cold | runs | max rel diff vs cold: LVV "
          "| strains | rows > 1e-6 |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for k in ("straight", "killed", "cold"):
        s = c[k]
        lvv, strain, n_off = _diff(s.outputs, ref)
        runs = len(set(s.run[s.run >= 0].tolist()))
        label = {"straight": "straight (chained)", "killed": f"killed + resumed (chained; {note.get('killed')})",
                 "cold": "cold (`--cold`)"}[k]
        diff = ("reference", "reference", "-") if k == "cold" else (f"{lvv:.1e}", f"{strain:.1e}", str(n_off))
        print(f"| {label} | {walls[k]:.0f} | {int(s.converged.sum())}/{args.rows} | {int(np.sum(s.start == START_WARM))} "
              f"| {int(np.sum(s.start == START_COLD))} | {int(np.sum(s.start == START_RESOLVED))} | {runs} | {diff[0]} | {diff[1]} | {diff[2]} |")
    bad = [k for k in ("straight", "killed") if _diff(c[k].outputs, ref)[2]]
    print("\nevery row within 1e-6 relative of the cold run" if not bad else f"\nrows differ: {', '.join(bad)}")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
