#!/usr/bin/env python
"""Run the model–data mismatch dose–response study and ship its results for the app and the report.

Runs ``lvcore study mismatch`` (:func:`lvcore.studies.mismatch.run_study`,
resumable: a rerun with the same ``--work`` skips every recorded simulation
and fit) with the shipped settings below, then writes
``assets/studies/mismatch.json`` (the study's JSON, floats rounded to 6
significant digits, plus a ``shipped`` record: command, date, machine, load)
and rewrites the two generated blocks of ``docs/studies.md`` from it: the
per-dose table (:func:`lvcore.studies.mismatch.docs_markdown`) and the
findings table with verdicts (:func:`lvcore.studies.findings.docs_markdown`).
Everything in it is SYNTHETIC. From the repository root::

    nice python scripts/ship_mismatch.py                 # the shipped run (BENCHMARKS.md: its cost)
    python scripts/ship_mismatch.py --recorded-only      # ship what --work holds, starting no new fits
    python scripts/ship_mismatch.py --docs-only          # rewrite the docs blocks from the shipped JSON

The full study output goes to ``--work`` (default ``build/study_mismatch``). The
convergence check (``--check-doses``) refits the doses that decide the verdicts
on the same data sets at ``--check-chains`` × (``--check-warmup`` +
``--check-samples``); its fits sit beside the main run's in ``--work`` (the
file names carry the budget) and its rows go to the JSON's ``check``.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads

pin_threads()  # before numpy is imported (lvcore.studies imports it)

from lvcore.studies._common import round_floats  # noqa: E402

#: The shipped run's settings (see docs/studies.md for why these). ``check_*``: the convergence check, the doses
#: (``SOURCE=D1,D2;SOURCE=D``; '' for none; the shipped run: every dose) refitted on the same data sets at
#: >= 2 chains with per-volunteer values (``lvcore.studies.mismatch.verdict_rows`` puts them in place of the main
#: run's rows, so every CI the findings read resamples volunteers).
SHIP = {"volunteers": "HV1,HV2,HV3,HV4,HV5", "seeds": 20, "warmup": 150, "samples": 150, "chains": 1, "batch": 40,
        "seed": 0, "resolution": "default", "workers": 1,
        "check_doses": "angles=5,15,30,45;base=1;sheet=4,32;dispersion=0.025,0.05,0.1,0.2,0.333;"
                       "heterogeneity=0.2,0.4,0.8,1.2;pericardium=0.03,0.1,0.2,0.3",
        "check_chains": 2, "check_warmup": 300, "check_samples": 300, "check_batch": 20}


def replace_block(text: str, begin: str, end: str, body: str, path) -> str:
    """``text`` with the block between ``begin`` and ``end`` replaced by ``body``."""
    if text.count(begin) != 1 or text.count(end) != 1:
        raise SystemExit(f"{path}: expected one {begin!r} ... {end!r} block")
    head, rest = text.split(begin)
    tail = rest.split(end)[1]
    return f"{head}{begin}\n{body}\n{end}{tail}"


def findings_blocks(text: str, folder: Path, path) -> str:
    """``text`` (docs/studies.md at ``path``) with the findings prose and table blocks regenerated from the
    result files in ``folder`` (the bundled ones where it lacks some)."""
    from lvcore.studies import findings

    found = findings.load(folder)
    text = replace_block(text, findings.PROSE_BEGIN, findings.PROSE_END, findings.prose_markdown(found), path)
    return replace_block(text, findings.DOCS_BEGIN, findings.DOCS_END, findings.docs_markdown(found), path)


def update_docs(path: Path, dest: Path) -> None:
    """Rewrite docs/studies.md's mismatch block and the findings prose and table blocks from the shipped JSON in
    ``dest``'s folder."""
    from lvcore.studies import mismatch

    shipped = mismatch.load(dest.parent)
    text = path.read_text()
    text = replace_block(text, mismatch.DOCS_BEGIN, mismatch.DOCS_END, mismatch.docs_markdown(shipped), path)
    path.write_text(findings_blocks(text, dest.parent, path))


def carry_over(res: dict, path: Path, part: str = "main") -> None:
    """Fill ``res``'s not-fitted doses with the rows of an earlier shipped result at ``path`` (in place).

    Only an earlier run of the same design qualifies (volunteers, seeds per dose, sampler budget): its rows
    are what this run would compute for those doses (the data sets and chains of a dose depend only on its key,
    :func:`lvcore.studies.mismatch.unit_seed`). Each carried row gets ``carried_over`` (the earlier run's
    date); ``res["carried_over"]`` says from which command. ``part="check"``: ``res`` is the convergence check,
    filled from the earlier result's ``check`` (same check budget), so a check that refits some doses anew keeps
    the earlier check's rows of the others. An earlier ship whose check was promoted to its run
    (:func:`lvcore.studies.mismatch.promote_check`) fills the check from its rows and the main run not at all.
    """
    from lvcore.studies import mismatch

    top = json.loads(path.read_text())
    if top.get("superseded"):  # a promoted ship: its rows are a check of every dose, its main run was not shipped
        if part == "main":
            return
        old = top
    else:
        old = top if part == "main" else (top.get("check") or {})
    keys = ("num_warmup", "num_samples", "num_chains")
    volunteers = top.get("volunteers")
    if (volunteers != res.get("volunteers", volunteers) or top.get("seeds_per_dose") != res.get("seeds_per_dose",
                                                                                                  top.get("seeds_per_dose"))
            or any(old.get("sampler", {}).get(k) != res["sampler"][k] for k in keys)):
        raise SystemExit(f"--carry-from {path}: another design (volunteers, seeds or sampler budget differ)")
    missing = {(u["source"], u["dose"]) for u in res["not_fitted"]}
    carried = [{**r, "carried_over": top.get("shipped", {}).get("date", "?")} for r in old.get("rows", [])
               if (r["source"], r["dose"]) in missing]
    got = {(r["source"], r["dose"]) for r in carried}
    if part == "check" and not got:
        return
    # a dose fitted for some volunteers only is replaced by the earlier complete row, not shipped twice
    kept = [r for r in res["rows"] if (r["source"], r["dose"]) not in got]
    res["rows"] = sorted(kept + carried, key=lambda r: (mismatch.SOURCES.index(r["source"]), r["dose"]))
    res["not_fitted"] = [u for u in res["not_fitted"] if (u["source"], u["dose"]) not in got]
    res["appearance"] = mismatch.appearance(res["rows"])
    if part == "main":
        res["complete"] = not res["not_fitted"] and not res["failed"]
    res["carried_over"] = {"command": top.get("shipped", {}).get("command"), "date": top.get("shipped", {}).get("date"),
                           "doses": [{"source": s, "dose": d} for s, d in sorted(got)]}


def real_lv_section(args, samplers) -> dict:
    """The real LV beside the volunteers: ``--real-lv-doses`` FE-simulated on the shipped real LV mesh and fitted
    through its subject emulator at the convergence check's budget (recorded fits only without
    ``--real-lv-emulator``); the JSON's ``real_lv`` (rows, sampler, θ, the emulator's conditions)."""
    from lvcore.studies import mismatch

    plan = mismatch._parse_doses(args.real_lv_doses.split(";"), mismatch.SOURCES)
    cfg = samplers.SamplerConfig(num_warmup=args.check_warmup, num_samples=args.check_samples,
                                 num_chains=args.check_chains, seed=args.seed)
    emus = {mismatch.REAL_LV: args.real_lv_emulator} if args.real_lv_emulator else {}
    rl = mismatch.run_study(sources=tuple(plan), doses=plan, volunteers=[mismatch.REAL_LV], seeds=args.seeds,
                            config=cfg, seed=args.seed, resolution=args.resolution, workers=args.workers,
                            out=args.work, batch=args.check_batch, recorded_only=not emus, subject_emulators=emus,
                            result_file="mismatch_real_lv.json",
                            progress=lambda m: print(time.strftime("%H:%M:%S"), "real LV:", m, flush=True))
    out = {k: rl[k] for k in ("sampler", "doses", "rows", "failed", "not_fitted", "fit_cost", "seeds_per_dose")
           if k in rl}
    out["theta"] = dict(mismatch.REAL_LV_THETA)
    out["emulator_note"] = mismatch.model_conditions_text()
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for k, v in SHIP.items():
        p.add_argument(f"--{k.replace('_', '-')}", type=type(v), default=v, help=f"default {v!r}")
    p.add_argument("--work", default="build/study_mismatch", help="full study output (and resume) folder")
    p.add_argument("--dest", default=None, help="shipped JSON (default assets/studies/mismatch.json)")
    p.add_argument("--docs", default="docs/studies.md", help="docs file whose generated blocks to rewrite ('' none)")
    p.add_argument("--docs-only", action="store_true", help="only rewrite the docs blocks from the shipped JSON")
    p.add_argument("--recorded-only", action="store_true",
                   help="start no new fits: ship what --work holds (the JSON lists the doses not fitted)")
    p.add_argument("--carry-from", default="",
                   help="with --recorded-only: a previously shipped mismatch.json whose rows fill the main run's "
                        "and the convergence check's doses not fitted in --work (same volunteers, seeds and sampler "
                        "budget; marked carried_over in the JSON and the docs)")
    p.add_argument("--real-lv-doses", default="angles=5,15,30;base=1;heterogeneity=0.4",
                   help="the doses run on the real LV beside the volunteers, at the check's budget, shipped as the "
                        "JSON's real_lv ('' none; default %(default)r)")
    p.add_argument("--keep-main-run", action="store_true",
                   help="ship the main run beside a convergence check that refitted every dose (default: the check "
                        "becomes the shipped run and the main run is recorded as superseded)")
    p.add_argument("--real-lv-emulator", default="",
                   help="the real LV's subject emulator (sliding base, inner half, (-60, 60) deg, 8 mmHg; "
                        "lvcore emulator build --geometry <real LV template> ...); without it only the real LV's fits "
                        "recorded in --work are shipped (default none)")
    args = p.parse_args(argv)
    from lvcore.studies.results import bundled_studies_dir

    dest = Path(args.dest) if args.dest else bundled_studies_dir() / "mismatch.json"
    if args.docs_only:
        update_docs(Path(args.docs), dest)
        print(f"rewrote the generated blocks of {args.docs} from {dest}")
        return 0
    from lvcore.inference import samplers
    from lvcore.studies import mismatch

    samplers.use_host_devices(1)
    cfg = samplers.SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains,
                                 seed=args.seed)
    load_before = os.getloadavg()
    t0 = time.time()
    res = mismatch.run_study(volunteers=args.volunteers.split(","), seeds=args.seeds, config=cfg, seed=args.seed,
                             resolution=args.resolution, workers=args.workers, out=args.work, batch=args.batch,
                             recorded_only=args.recorded_only,
                             progress=lambda m: print(time.strftime("%H:%M:%S"), m, flush=True))
    if args.carry_from:
        if not args.recorded_only:
            raise SystemExit("--carry-from needs --recorded-only (a full run fits every dose itself)")
        carry_over(res, Path(args.carry_from))
    if args.check_doses:
        plan = mismatch._parse_doses(args.check_doses.split(";"), mismatch.SOURCES)
        ccfg = samplers.SamplerConfig(num_warmup=args.check_warmup, num_samples=args.check_samples,
                                      num_chains=args.check_chains, seed=args.seed)
        chk = mismatch.run_study(sources=tuple(plan), doses=plan, volunteers=args.volunteers.split(","),
                                 seeds=args.seeds, config=ccfg, seed=args.seed, resolution=args.resolution,
                                 workers=args.workers, out=args.work, batch=args.check_batch,
                                 recorded_only=args.recorded_only, result_file="mismatch_check.json",
                                 progress=lambda m: print(time.strftime("%H:%M:%S"), "check:", m, flush=True))
        res["check"] = {k: chk[k] for k in ("sampler", "doses", "rows", "appearance", "failed", "not_fitted",
                                            "fit_cost")}
        if args.carry_from:
            carry_over(res["check"], Path(args.carry_from), part="check")
    if args.real_lv_doses:
        res["real_lv"] = real_lv_section(args, samplers)
    if not args.keep_main_run:
        res = mismatch.promote_check(res)  # a check of every dose becomes the run; the main run is superseded
    cmd = "python scripts/ship_mismatch.py " + " ".join(f"--{k.replace('_', '-')} {shlex.quote(str(getattr(args, k)))}"
                                                        for k in SHIP) + (" --recorded-only" if args.recorded_only else "") \
        + (f" --carry-from {shlex.quote(Path(args.carry_from).name)}" if args.carry_from else "") \
        + f" --real-lv-doses {shlex.quote(args.real_lv_doses)}"  # no build-machine folder
    res.pop("folder", None)
    res["shipped"] = {"script": "scripts/ship_mismatch.py", "command": cmd, "date": time.strftime("%Y-%m-%d"),
                      "machine": f"{platform.machine()}, {os.cpu_count()} CPUs (shared)",
                      "load_before": [round(x, 2) for x in load_before],
                      "load_after": [round(x, 2) for x in os.getloadavg()],
                      "wall_s_this_invocation": round(time.time() - t0, 1),
                      "cpu_s_this_process": round(time.process_time(), 1)}
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(round_floats(res), indent=1))
    print(f"wrote {dest} ({dest.stat().st_size / 1024:.0f} KiB)")
    if args.docs:
        update_docs(Path(args.docs), dest)
        print(f"rewrote the generated blocks of {args.docs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
