"""Ship F6 with the regularised BO objective beside the chapter's: ``bo_mismatch.json``'s ``posterior`` part.

The chapter's BO objective (a standardised RSS) has no term that keeps a fit off the box's edge, and on the
SYNTHETIC volunteers most of its fixed- and free-angle fits end there whatever the budget
(``benchmarks/bo_fit_vs_truth.py``), so the findings' rule (fits on a bound left out) leaves F6 untested. This
runs ``lvcore study bo-mismatch --objective posterior`` (the noise model's χ² plus a weakly informative prior,
:func:`lvcore.studies.bo_fibres.posterior_objective`) on the bundled volunteers HV1-HV8 and the real LV (its mesh,
data simulated on it at the volunteers' median θ), with the ``angles`` mismatch, and ships the result inside
``assets/studies/bo_mismatch.json`` under ``posterior`` (the chapter-objective run there is kept). Then it
rewrites docs/studies.md's regularised-F6 block and the findings blocks.

Resumable: every BO evaluation is in ``--work``'s state files. ``--docs-only`` rewrites the docs from the
shipped JSON.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

from ship_mismatch import findings_blocks, replace_block  # noqa: E402

VOLUNTEERS = "HV1,HV2,HV3,HV4,HV5,HV6,HV7,HV8,REAL-LV"


def update_docs(docs: Path, dest: Path) -> None:
    """docs/studies.md's regularised-F6 block and the findings prose and table, from the JSON in ``dest``."""
    from lvcore.studies import bo_mismatch

    shipped = json.loads(dest.read_text())
    text = replace_block(docs.read_text(), bo_mismatch.DOCS_BEGIN, bo_mismatch.DOCS_END,
                         bo_mismatch.posterior_markdown(shipped), docs)
    docs.write_text(findings_blocks(text, dest.parent, docs))


def main(argv=None) -> int:
    from lvcore.studies import bo_mismatch
    from lvcore.studies._common import clean, round_floats, write_json_atomic

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", default="build/f6_regularised", help="study output and resume folder "
                                                                  "(default build/f6_regularised)")
    p.add_argument("--volunteers", default=VOLUNTEERS, help=f"default {VOLUNTEERS}")
    p.add_argument("--kinds", default="angles", help="mismatch kinds (default angles: the one free angles can absorb)")
    p.add_argument("--initial", type=int, default=200, help="BO initial design per run (default 200)")
    p.add_argument("--iterations", type=int, default=200, help="BO iterations per run (default 200)")
    p.add_argument("--resolution", default="fast", help="simulator mesh preset (default fast, as the chapter "
                                                       "objective's shipped run)")
    p.add_argument("--workers", type=int, default=2, help="local simulator workers (default 2)")
    p.add_argument("--dest", default=str(ROOT / "assets" / "studies" / bo_mismatch.RESULT_FILE),
                   help="the shipped bo_mismatch.json to add the run to (default the bundled one)")
    p.add_argument("--docs", default=str(ROOT / "docs" / "studies.md"), help="docs file to rewrite ('' none)")
    p.add_argument("--docs-only", action="store_true", help="only rewrite the docs from the shipped JSON")
    args = p.parse_args(argv)
    dest = Path(args.dest)
    if not args.docs_only:
        t0 = time.perf_counter()
        res = bo_mismatch.run_study(args.volunteers.split(","), args.kinds.split(","), out=Path(args.work),
                                    n_initial=args.initial, n_iterations=args.iterations, workers=args.workers,
                                    resolution=args.resolution, objective="posterior", log=print)
        res.pop("folder", None)
        command = (f"python scripts/ship_f6_regularised.py --volunteers {args.volunteers} --kinds {args.kinds} "
                   f"--initial {args.initial} --iterations {args.iterations} --resolution {args.resolution}")
        res["meta"]["shipped"] = {"command": command,  # no machine path: --work, --dest and --docs are left out
                                  "date": time.strftime("%Y-%m-%d"),
                                  "wall_s_this_session": round(time.perf_counter() - t0, 1)}
        shipped = json.loads(dest.read_text())
        shipped[bo_mismatch.POSTERIOR_KEY] = round_floats(clean(res), 6)
        write_json_atomic(dest, shipped)
        print(f"wrote {dest} ({bo_mismatch.POSTERIOR_KEY}: {len(res['runs'])} runs)")
    if args.docs:
        update_docs(Path(args.docs), dest)
        print(f"rewrote {args.docs}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
