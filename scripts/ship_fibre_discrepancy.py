#!/usr/bin/env python
"""Run the fibre-discrepancy study once and ship a small JSON of its results for the report and the app.

The study (``lvcore study fibre-discrepancy``) fits 12 SYNTHETIC test sets
with three likelihoods by MCMC and takes minutes (BENCHMARKS.md), too long
for ``lvcore report``'s default run. This script runs it and writes
``assets/studies/fibre_discrepancy.json``: the study's JSON with the
per-draw error arrays (Fig 9.9) thinned to ``--keep`` draws per set and model
and floats rounded to 6 significant digits, so the file stays small. Everything in it is SYNTHETIC. Run from the
repository root::

    OMP_NUM_THREADS=1 python scripts/ship_fibre_discrepancy.py              # chapter budget, ~15 min
    OMP_NUM_THREADS=1 python scripts/ship_fibre_discrepancy.py --warmup 300 --samples 300

It also rewrites the generated block of ``docs/calibration.md`` (between
``fibre_discrepancy.DOCS_BEGIN`` and ``DOCS_END``) from the shipped JSON, so
the docs quote the shipped numbers (``--docs ''`` leaves the docs alone;
``--docs-only`` rewrites the block from the JSON already shipped, without running).

The full (unthinned) study output goes to ``--work`` (default
``build/study_fibre_discrepancy``).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads

pin_threads()  # before numpy is imported (lvcore.studies imports it)

from lvcore.studies._common import round_floats  # noqa: E402


def thin_result(result: dict, keep: int = 250) -> dict:
    """The study result with ``error_draws`` thinned to ``keep`` evenly spaced draws per set and model."""
    import numpy as np

    out = dict(result)
    n_sets = len(result["sets"])
    thinned = {}
    for m, draws in result["error_draws"].items():
        per_set = np.asarray(draws, dtype=float).reshape(n_sets, -1)
        idx = np.linspace(0, per_set.shape[1] - 1, min(keep, per_set.shape[1])).astype(int)
        thinned[m] = per_set[:, idx].ravel().tolist()
    out["error_draws"] = thinned
    out["error_draws_thinned_to_per_set"] = int(min(keep, per_set.shape[1]))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--warmup", type=int, default=500)
    p.add_argument("--samples", type=int, default=1000)
    p.add_argument("--chains", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--keep", type=int, default=250, help="error draws kept per set and model")
    p.add_argument("--work", default="build/study_fibre_discrepancy", help="full study output folder")
    p.add_argument("--dest", default=None, help="shipped JSON (default assets/studies/fibre_discrepancy.json)")
    p.add_argument("--docs", default="docs/calibration.md", help="docs file whose generated block to rewrite ('' none)")
    p.add_argument("--docs-only", action="store_true", help="only rewrite the docs block from the shipped JSON")
    args = p.parse_args(argv)
    if args.docs_only:
        from lvcore.studies.results import bundled_studies_dir

        src = Path(args.dest) if args.dest else bundled_studies_dir() / "fibre_discrepancy.json"
        update_docs(Path(args.docs), json.loads(src.read_text()))
        print(f"rewrote the fibre-discrepancy block of {args.docs} from {src}")
        return 0

    from lvcore.inference import samplers

    samplers.use_host_devices(args.chains)
    from lvcore.studies.results import bundled_studies_dir
    from lvcore.studies import fibre_discrepancy as fd

    cfg = samplers.SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains,
                                 seed=args.seed)
    t0 = time.perf_counter()
    res = fd.run_study(config=cfg, seed=args.seed, out=args.work,
                       progress=lambda msg, frac: print(msg, flush=True))
    small = round_floats(thin_result(res, args.keep))
    small["shipped"] = {"script": "scripts/ship_fibre_discrepancy.py", "argv": sys.argv[1:],
                        "wall_s": time.perf_counter() - t0, "date": time.strftime("%Y-%m-%d")}
    dest = Path(args.dest) if args.dest else bundled_studies_dir() / "fibre_discrepancy.json"
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(small, separators=(",", ":")))
    print(json.dumps(res["findings"], indent=1))
    print(f"wrote {dest} ({dest.stat().st_size / 1024:.0f} kB) in {time.perf_counter() - t0:.0f} s")
    if args.docs:
        update_docs(Path(args.docs), small)
        print(f"rewrote the fibre-discrepancy block of {args.docs}")
    return 0


def update_docs(path: Path, shipped: dict) -> None:
    """Replace the generated block of ``path`` by ``fibre_discrepancy.docs_markdown(shipped)``."""
    from lvcore.studies import fibre_discrepancy as fd

    text = path.read_text()
    if text.count(fd.DOCS_BEGIN) != 1 or text.count(fd.DOCS_END) != 1:
        raise SystemExit(f"{path}: expected one {fd.DOCS_BEGIN!r} ... {fd.DOCS_END!r} block")
    head, rest = text.split(fd.DOCS_BEGIN)
    _, tail = rest.split(fd.DOCS_END)
    path.write_text(f"{head}{fd.DOCS_BEGIN}\n{fd.docs_markdown(shipped)}\n{fd.DOCS_END}{tail}")


if __name__ == "__main__":
    sys.exit(main())
