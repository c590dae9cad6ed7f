"""Regenerate the bundled study results (``studies/`` under the bundled assets) shown by the app's Studies page.

    python scripts/ship_studies.py --work /tmp/studies_ship --bo-initial 30 --bo-iterations 30 --workers 2
    python scripts/ship_studies.py --work /tmp/studies_ship --patients SYNTHETIC-P01,SYNTHETIC-P02 --skip-bo
    python scripts/ship_studies.py --work /tmp/studies_ship --copy-only      # copy finished results, run nothing

Runs ``lvcore study bo-fibres`` and ``lvcore study operators`` into ``--work``
(both resume from their state files, so a killed run can be restarted with
the same command) and copies the small result files (JSON/CSV; no state, no
geometries, no figures) into ``assets/studies/`` (flat, where
``lvcore report`` and the app look; ``tables.csv`` becomes
``bo_fibres_tables.csv``). The JSON metadata records the budget
actually run: a reduced budget is labelled as such and is not the chapter's
full run (300 + 300 BO evaluations, all 6 operator patients).
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

#: Source file in the run's folder -> name in the bundled (flat) studies folder, where reports look for them.
BO_FILES = {"bo_fibres.json": "bo_fibres.json", "bo_fibres_meta.json": "bo_fibres_meta.json",
            "tables.csv": "bo_fibres_tables.csv"}
OP_FILES = {"operators.json": "operators.json", "operators_fits.csv": "operators_fits.csv",
            "rss_surfaces_simulator.json": "rss_surfaces_simulator.json"}  # per-fit rss_surfaces.json: ~10 KiB a fit


def copy_results(work: Path, dest: Path) -> list[Path]:
    """Copy the finished results under ``work`` into ``dest`` (the bundled studies folder)."""
    copied = []
    for sub, names in (("bo-fibres", BO_FILES), ("operators", OP_FILES)):
        src = work / sub
        if not (src / next(iter(names))).is_file():
            continue
        dest.mkdir(parents=True, exist_ok=True)
        for n, target in names.items():
            if (src / n).is_file():
                shutil.copy2(src / n, dest / target)
                copied.append(dest / target)
    return copied


def example_surface(op_dir: Path, n: int, resolution: str, workers: int) -> None:
    """Fig 9.13 on the simulator for the first finished operator fit -> rss_surfaces_simulator.json."""
    from lvcore.studies import operators
    from lvcore.studies._common import clean, write_json_atomic

    fits = sorted((op_dir / "fits").glob("*.json"))
    if not fits:
        print("no finished operator fit for the example surface")
        return
    fit = json.loads(fits[0].read_text())["fit"]
    geoms = operators.patient_geometries(fit["patient"], op_dir / "geometries")
    y_star = fit.get("y_star") or operators._data_task(fit["patient"], fit["main_operator"], geoms, resolution, None)
    rec = operators.surface_for_fit(fit, geoms, y_star, n, resolution=resolution, workers=workers)
    write_json_atomic(op_dir / "rss_surfaces_simulator.json", clean([rec]))
    print(f"example surface for {fit['patient']} main {fit['main_operator']} test {fit['test_geometry']}: "
          f"{6 * n * n} simulations")


def refresh(work: Path) -> None:
    """Re-write the summaries (findings, tables, figures) of finished runs with this version of lvcore."""
    from lvcore.studies import bo_fibres, operators

    bo = work / "bo-fibres"
    if (bo / "bo_fibres.json").is_file():
        entries = json.loads((bo / "bo_fibres.json").read_text())
        meta = json.loads((bo / "bo_fibres_meta.json").read_text()) if (bo / "bo_fibres_meta.json").is_file() else {}
        settings = meta.get("settings") or {"n_initial": entries[0]["n_initial"], "n_iterations": entries[0]["n_iterations"]}
        bo_fibres.write_outputs(entries, bo, settings)
    op = work / "operators"
    if (op / "operators.json").is_file():
        data = json.loads((op / "operators.json").read_text())
        surfaces = {(s["patient"], s["main_operator"], s["test_geometry"]): s
                    for s in (json.loads((op / "rss_surfaces.json").read_text()) if (op / "rss_surfaces.json").is_file() else [])}
        fits = []
        for f in data["fits"]:
            s = surfaces.get((f["patient"], f["main_operator"], f["test_geometry"]))
            fits.append({**f, **({"rss_surface": {k: s[k] for k in ("method", "pairs")}} if s else {})})
        data["fits"] = fits
        data["findings"] = operators.findings(fits, data["meta"]["operators"])
        operators.write_outputs(data, op)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--work", type=Path, required=True, help="where the studies run (state files, geometries)")
    p.add_argument("--dest", type=Path, default=None, help="default: the bundled assets' studies/ folder")
    p.add_argument("--subjects", default=None, help="BO volunteers (default all 8)")
    p.add_argument("--bo-initial", type=int, default=300)
    p.add_argument("--bo-iterations", type=int, default=300)
    p.add_argument("--patients", default=None, help="operator-study patients (default all 6)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--resolution", default="default")
    p.add_argument("--skip-bo", action="store_true")
    p.add_argument("--skip-operators", action="store_true")
    p.add_argument("--copy-only", action="store_true", help="run nothing; copy what is finished in --work")
    p.add_argument("--example-surface", type=int, default=0,
                   help="N > 0: a simulator loss surface (N x N per pair) for the first finished operator fit")
    args = p.parse_args(argv)

    from lvcore.studies import bo_fibres, operators
    from lvcore.studies.results import bundled_studies_dir

    dest = args.dest or bundled_studies_dir()
    if not args.copy_only and not args.skip_bo:
        subjects = args.subjects.split(",") if args.subjects else None
        bo_fibres.run_study(subjects, out=args.work / "bo-fibres", n_initial=args.bo_initial,
                            n_iterations=args.bo_iterations, workers=args.workers, resolution=args.resolution,
                            progress=True, log=print)
    if not args.copy_only and not args.skip_operators:
        patients = args.patients.split(",") if args.patients else None
        res = operators.run_study(patients, out=args.work / "operators", workers=args.workers,
                                  resolution=args.resolution, progress=True)
        print(operators.format_findings(res["findings"]))
    if args.example_surface:
        example_surface(args.work / "operators", args.example_surface, args.resolution, args.workers)
    refresh(args.work)
    copied = copy_results(args.work, dest)
    for c in copied:
        print(f"wrote {c} ({c.stat().st_size / 1024:.0f} KiB)")
    meta = dest / "bo_fibres_meta.json"
    if meta.is_file():
        print("bo-fibres budget:", json.loads(meta.read_text())["budget"]["label"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
