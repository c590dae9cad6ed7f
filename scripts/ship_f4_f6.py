"""Regenerate the bundled results of the F4/F5 (realistic operators) and F6 (BO on a known mismatch) studies.

One command (from the repository root; resumable: rerun it after a kill)::

    nice python scripts/ship_f4_f6.py --work /tmp/f4_f6_ship --workers 2 --patients 21 --resolution fast

(the shipped run's settings: 21 patients drawn, of which 20 fitted; the ``fast`` mesh on a loaded machine).

It runs, into ``--work``:

* ``lvcore study operators-realistic`` (``--patients`` SYNTHETIC patients, default 24, seed 2604:
  realistic imitation operators, their fitted geometries cached in ``WORK/operators-realistic/cohort``,
  SQP refits in ``WORK/operators-realistic/refits``);
* ``lvcore study bo-mismatch`` (volunteers HV1-HV3 by default, kinds angles/sheet/base, a reduced
  30 + 30 budget per run),

then copies the small result files into the bundled studies folder (``assets/studies/``):
``operators_realistic.json``, ``operators_realistic_fits.csv``, ``bo_mismatch.json`` and
``bo_mismatch_runs.csv`` (no state, geometries or figures). ``--copy-only`` runs nothing and copies
what is finished; ``--skip-operators`` / ``--skip-bo`` run one study only.
"""
from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

#: Study sub-folder of --work -> files copied into the bundled studies folder.
FILES = {"operators-realistic": ("operators_realistic.json", "operators_realistic_fits.csv"),
         "bo-mismatch": ("bo_mismatch.json", "bo_mismatch_runs.csv")}


def copy_results(work: Path, dest: Path) -> list[Path]:
    """Copy the finished result files under ``work`` into ``dest``."""
    copied = []
    for sub, names in FILES.items():
        if not (work / sub / names[0]).is_file():
            continue
        dest.mkdir(parents=True, exist_ok=True)
        for n in names:
            if (work / sub / n).is_file():
                shutil.copy2(work / sub / n, dest / n)
                copied.append(dest / n)
    return copied


def main(argv=None) -> int:
    from lvcore.geometry import operator_model as om
    from lvcore.studies import bo_mismatch

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--work", type=Path, required=True, help="where the studies run (state files, geometries)")
    p.add_argument("--dest", type=Path, default=None, help="default: the bundled assets' studies/ folder")
    p.add_argument("--patients", type=int, default=om.DEFAULT_PATIENTS,
                   help=f"SYNTHETIC patients of the realistic operator study (default {om.DEFAULT_PATIENTS})")
    p.add_argument("--seed", type=int, default=om.DEFAULT_SEED, help=f"their seed (default {om.DEFAULT_SEED})")
    p.add_argument("--volunteers", default=",".join(bo_mismatch.DEFAULT_VOLUNTEERS))
    p.add_argument("--kinds", default=",".join(bo_mismatch.KINDS))
    p.add_argument("--bo-initial", type=int, default=bo_mismatch.DEFAULT_INITIAL)
    p.add_argument("--bo-iterations", type=int, default=bo_mismatch.DEFAULT_ITERATIONS)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--resolution", default="default", help="simulator mesh preset of both studies (default 'default')")
    p.add_argument("--all-mains", action="store_true", help="operators-realistic: every operator as the main one")
    p.add_argument("--skip-operators", action="store_true")
    p.add_argument("--skip-bo", action="store_true")
    p.add_argument("--copy-only", action="store_true", help="run nothing; copy what is finished in --work")
    args = p.parse_args(argv)

    from lvcore.studies import operators_realistic
    from lvcore.studies.results import bundled_studies_dir

    dest = args.dest or bundled_studies_dir()
    if not args.copy_only and not args.skip_operators:
        res = operators_realistic.run_study(args.patients, args.seed, out=args.work / "operators-realistic",
                                            workers=args.workers, resolution=args.resolution, progress=True,
                                            log=print, all_mains=args.all_mains)
        print(operators_realistic.format_findings(res))
    if not args.copy_only and not args.skip_bo:
        res = bo_mismatch.run_study(args.volunteers.split(","), args.kinds.split(","), out=args.work / "bo-mismatch",
                                    n_initial=args.bo_initial, n_iterations=args.bo_iterations, workers=args.workers,
                                    resolution=args.resolution, progress=True, log=print)
        print(bo_mismatch.format_findings(res))
    for c in copy_results(args.work, dest):
        print(f"wrote {c} ({c.stat().st_size / 1024:.0f} KiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
