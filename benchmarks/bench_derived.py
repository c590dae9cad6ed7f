"""Derived quantities on every bundled SYNTHETIC volunteer: is the measured point inside the EDPVR's band, and
what do the derived quantities cost next to the sampling?

    python benchmarks/bench_derived.py                       # 8 volunteers, iid, 2 chains, 100 derived draws
    python benchmarks/bench_derived.py --volunteers SYNTHETIC_HV2 --repeats 3

For each volunteer ``lvcore calibrate --volunteer NAME --model iid --chains 2 --derived-draws N`` runs in this
process (the sampler compiled once); the table gives the sampling wall time, the derived quantities' wall time
(the EDPVR of N posterior draws at 0-30 mmHg and the data's EDP, the stress, the ridge), their ratio, the path
that gave the EDPVR (``emulator``: the EDPVR emulator evaluated directly; ``fe``: FE load paths), the measured EDV
against the 99 % predictive interval of the volume at the EDP, the emulator-to-FE offset and the exit code. The
linear solver and the machine's load are printed with the table, and the median ratio over the runs after it.
``--fe`` forces the FE load path (``LVCORE_EDPVR_EMULATOR=none``) for a comparison.

A calibration through a subject emulator (its own mesh; its EDPVR emulator where it was built with one, the default,
lvcore.emulator.subject_edpvr):

    lvcore emulator build --geometry assets/volunteers/SYNTHETIC_HV3_geometry.vtu --out EMU   # --edpvr by default
    python benchmarks/bench_derived.py --subject-emulator EMU --data assets/volunteers/SYNTHETIC_HV3_measured.csv \
        --repeats 3            # and again with --fe

runs ``lvcore calibrate --emulator EMU --data CSV --model iid --chains 2 --derived-draws N`` and prints, first,
the subject emulator's build times and its EDPVR emulator's held-out errors per pressure (from their metadata).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported


def run_one(name: str, draws: int, out: Path, extrapolate: bool = False, subject: tuple | None = None) -> dict:
    """One calibration of the volunteer ``name`` (or, with ``subject`` = (emulator folder, data CSV), of the data
    through that subject emulator)."""
    import contextlib
    import io

    from lvcore.cli import main

    where = ["--volunteer", name] if subject is None else ["--emulator", str(subject[0]), "--data", str(subject[1])]
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = main(["calibrate", *where, "--model", "iid", "--chains", "2", "--derived-draws",
                     str(draws), "--out", str(out), "--json"] + (["--allow-extrapolation"] if extrapolate else []))
    if code == 2 and not extrapolate and subject is None:   # outside the emulator's box: run it flagged
        return run_one(name, draws, out, extrapolate=True)
    wall = time.perf_counter() - t0
    (rec,) = json.loads((out / "summary.json").read_text())
    d = rec["derived"]
    c = d["edpvr_check"]
    return {"volunteer": name + (" (--allow-extrapolation)" if extrapolate else ""), "exit": code, "wall_s": wall, "sampling_s": rec["wall_s"],
            "derived_s": d["seconds"]["total"], "fe_s": d["seconds"]["fe"], "n_draws": d["n_draws"],
            "path": d.get("path", "fe"), "emulator": d.get("emulator"), "path_reason": d.get("path_reason", ""),
            "measured": c["measured_edv_ml"], "band": c["predictive_99"], "inside": c["inside"],
            "offset": c["emulator_to_fe_offset_ml"]["median"], "flags": rec["flags"],
            "v20": [r for r in d["edpvr"] if r["pressure_mmhg"] == 20][0]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--volunteers", nargs="*", default=None, help="names (default: every bundled volunteer)")
    p.add_argument("--draws", type=int, default=100, help="--derived-draws (default 100)")
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--json", default=None, help="also write the rows to this file")
    p.add_argument("--fe", action="store_true", help="force the FE load path (default: the EDPVR emulator where it "
                                                     "covers the calibration)")
    p.add_argument("--subject-emulator", default=None, metavar="DIR",
                   help="calibrate --data through this subject emulator instead of the volunteers (default: none)")
    p.add_argument("--data", default=None, help="the measured CSV of --subject-emulator (default: none)")
    args = p.parse_args(argv)
    if (args.subject_emulator is None) != (args.data is None):
        p.error("--subject-emulator and --data go together")

    from lvcore.mechanics.linear import cholmod_mode, default_backend
    from lvcore.resources import bundled_volunteers

    names = args.volunteers or list(bundled_volunteers())
    subject = None
    if args.subject_emulator is not None:
        subject = (Path(args.subject_emulator).resolve(), Path(args.data).resolve())
        names = [f"{Path(args.data).stem} via {Path(args.subject_emulator).name}"]
        print(subject_build_report(subject[0]), flush=True)
    if args.fe:
        os.environ["LVCORE_EDPVR_EMULATOR"] = "none"
    print(f"# {time.strftime('%Y-%m-%d %H:%M')} {platform.node()} {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.2f}, linear solver {default_backend()} ({cholmod_mode() if default_backend() == 'cholmod' else '-'}), iid, 2 chains x (1000 + 1000), "
          f"{args.draws} derived draws", flush=True)
    print("| volunteer | exit | path | sampling (s) | derived (s) | derived / sampling | measured EDV (mL) | "
          "99 % predictive at EDP (mL) | inside | emulator-to-FE offset (mL) | V20 median [90 %] (mL) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            for k in range(args.repeats):
                r = run_one(name, args.draws, Path(tmp) / f"run_{len(rows)}", subject=subject)
                rows.append(r)
                v = r["v20"]
                print(f"| {r['volunteer']} | {r['exit']} | {r['path']} | {r['sampling_s']:.1f} | {r['derived_s']:.2f} | "
                      f"{r['derived_s'] / r['sampling_s']:.3f} | {r['measured']:.1f} | {r['band'][0]:.1f}-"
                      f"{r['band'][1]:.1f} | {'yes' if r['inside'] else 'NO'} | {r['offset']:+.2f} | "
                      f"{v['median']:.1f} [{v['q05']:.1f}, {v['q95']:.1f}] |", flush=True)
    import statistics

    ratios = [r["derived_s"] / r["sampling_s"] for r in rows]
    print(f"\nderived / sampling: median {statistics.median(ratios):.3f} (range {min(ratios):.3f}-{max(ratios):.3f}) "
          f"over {len(rows)} runs; paths {sorted({r['path'] for r in rows})}; load now {os.getloadavg()[0]:.2f}")
    reasons = sorted({r["path_reason"] for r in rows if r["path_reason"]})
    if reasons:
        print(f"FE path because: {reasons}")
    if len(rows) > 1:
        print(f"median sampling {statistics.median(r['sampling_s'] for r in rows):.1f} s, derived "
              f"{statistics.median(r['derived_s'] for r in rows):.2f} s")
    inside = sum(r["inside"] for r in rows)
    print(f"\nmeasured point inside the 99 % predictive band: {inside}/{len(rows)}; exit 4: "
          f"{sum(r['exit'] == 4 for r in rows)} ({sorted({f.split(':')[0] for r in rows for f in r['flags']})})")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


def subject_build_report(folder: Path) -> str:
    """A subject emulator's build times (s) and its EDPVR emulator's held-out errors per pressure, from metadata."""
    from lvcore.emulator import subject_edpvr

    meta = json.loads((folder / "metadata.json").read_text())
    sub = meta.get("subject", {})
    lines = [f"# subject emulator {folder.name}: seconds {sub.get('seconds')}, runs {sub.get('runs')}, "
             f"held-out LVV RMSE {meta.get('test', {}).get('lvv_rmse_ml')} mL"]
    try:
        e = subject_edpvr.load_subject_edpvr(folder / subject_edpvr.FOLDER)
    except Exception as err:  # noqa: BLE001 - reported
        return "\n".join(lines + [f"# no subject EDPVR emulator: {err}"])
    t, v0 = e.metadata["test"], float(e.metadata["subject"]["v0_ml"])
    lines.append(f"# subject EDPVR emulator '{e.name}': V0 {v0:.2f} mL, {t['n_paths']} held-out paths, "
                 f"{e.metadata['subject']['seconds']}, training {e.metadata['training']['seconds']} s")
    lines.append("| p (mmHg) | log V/V0 RMSE | max abs | volume RMSE (mL) | EDV/V0 <= 2.5 at 8 mmHg: log V/V0 RMSE | "
                 "fibre stretch RMSE |")
    lines.append("|---|---|---|---|---|---|")
    phys = t.get("log_volume_ratio_rmse_physiological")
    for k, p in enumerate(t["pressures_mmhg"]):
        lines.append(f"| {p:g} | {t['log_volume_ratio_rmse'][k]:.4f} | {t['log_volume_ratio_max_abs'][k]:.4f} | "
                     f"{t['volume_rmse_ml'][k]:.2f} | {'-' if phys is None else f'{phys[k]:.4f}'} | "
                     f"{t['fibre_stretch_rmse'][k]:.4f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
