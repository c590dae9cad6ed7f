"""``lvcore calibrate --data cohort.csv --hierarchical``: one joint posterior for a cohort.

Reads the cohort (:func:`lvcore.inference.cohort.read_cohort`: refuses a cohort of one, a subject whose
geometry cannot be read, a state without its pressure or two states at one pressure, naming the row and the
column; exit 2), sets up every subject as ``lvcore calibrate`` does (:func:`lvcore.inference.request.build_request`
through :func:`lvcore.inference.cli._request`), samples the hierarchical model
(:mod:`lvcore.inference.hierarchical`) with a progress bar, fits every subject separately with the same
likelihood for the shrinkage, and writes ``summary.json`` (section ``hierarchical``) and ``hierarchical.nc``.
Exit 0, 1 when a level misses its R-hat/ESS thresholds, 4 (flagged) when the joint sampler diverged or the joint
posterior and the separate fits disagree on a group difference (CONSISTENCY).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from lvcore.domain.outputs import THETA_NAMES

#: Shares of the kernel's memory-mapping limit past which the separate fits let go of their compiled programs, and
#: past which they stop (:func:`separate_fits`).
MAPPING_SHARE_RELEASE = 0.5
MAPPING_SHARE_LIMIT = 0.8
#: Options of ``lvcore calibrate`` a hierarchical run does not take, with what to do instead.
REFUSED = (("volunteer", "--volunteer is one bundled subject; give a cohort CSV with --data"),
           ("subject", "--subject picks one row; a hierarchical calibration uses every subject of the cohort"))


def check_hierarchical_options(args) -> str:
    """The likelihood of a hierarchical run (``--model``: volume or iid), refusing options it does not take."""
    from lvcore.exceptions import DataError
    from lvcore.inference.hierarchical import LIKELIHOODS

    for attr, why in REFUSED:
        if getattr(args, attr, None) is not None:
            raise DataError(f"--hierarchical: {why}")
    if args.data is None:
        raise DataError("--hierarchical needs --data COHORT.csv (subject, [group], [geometry], lvv_ml, strain_01 ..)")
    if args.angles == "infer":
        raise DataError("--hierarchical: --angles infer is not supported; the fibre angles stay at the emulator's")
    if args.sampler == "hmc_gibbs":
        raise DataError("--hierarchical samples with NUTS; leave --sampler at auto or nuts")
    model = args.model.strip()
    if model not in LIKELIHOODS:
        raise DataError(f"--hierarchical --model {model}: choose one of {', '.join(LIKELIHOODS)} (the discrepancy "
                        "model's GP belongs to one subject and is not pooled)")
    if args.chains < 2:
        raise DataError("--hierarchical needs --chains >= 2 (R-hat compares chains)")
    return model


def prepare_cohort(args):
    """The cohort and one :class:`~lvcore.inference.hierarchical.CohortMember` per subject (exit 2 on bad input)."""
    from lvcore.emulator.forward import load_emulator_forward
    from lvcore.exceptions import LVCoreError
    from lvcore.inference import cohort as co
    from lvcore.inference import guards, plausibility
    from lvcore.inference.cli import DEFAULT_EMULATOR, _measure_options, _request
    from lvcore.inference.hierarchical import CohortMember
    from lvcore.inference.request import INFER
    from lvcore.domain.outputs import is_pc_name

    name = args.emulator or DEFAULT_EMULATOR
    emulator = load_emulator_forward(name, np.zeros(16)).emulator
    if getattr(emulator, "is_subject", False):
        from lvcore.exceptions import DataError

        raise DataError(f"--emulator {name} is subject-specific (one geometry bound in); a cohort needs a "
                        "shape-model emulator such as 'chapter'")
    cohort = co.read_cohort(args.data)
    guards.check_conditions(emulator, args.edp, args.alpha_endo, args.alpha_epi)
    n_pc = sum(1 for n in emulator.input_names if is_pc_name(n))
    representation = None
    if args.representation_error == "floor":
        from lvcore.inference.representation_error import load_representation_error

        representation = load_representation_error(n_pc)
    sigma_ref = plausibility.DEFAULT_SIGMA_REF if args.strain_noise is None else float(args.strain_noise)
    groups = cohort.groups or ["all"]
    members, requests = [], {}
    fname = Path(args.data).name
    cli_measures, cli_sds = _measure_options(args, str(args.geometry).strip().lower() == INFER)
    for row in cohort.rows:
        s = row.subject
        geometry = co.resolve_subject_geometry(cohort, s, args.geometry, n_pc=n_pc, units=args.geometry_units)
        label = (f"{fname} line {cohort.where.get(s, '?')}, column geometry" if s in cohort.geometry
                 else f"--geometry {args.geometry}")
        try:
            q = _request(args, emulator, name, row, geometry, label, cli_measures if geometry == INFER else {},
                         cli_sds if geometry == INFER else {}, representation=representation, sigma_ref=sigma_ref)
        except LVCoreError as err:
            raise type(err)(f"subject '{s[:80]}' ({fname} line {cohort.where.get(s, '?')}): {err}") from None
        requests[s] = q
        members.append(CohortMember(s, np.asarray(q.y, float), q.forward,
                                    groups.index(cohort.group[s]) if cohort.group else 0))
    return cohort, name, members, requests, groups


def separate_fits(members, likelihood: str, config, sigma_v: float, progress=None) -> dict:
    """Subject -> theta's q05/median/q95 from its own calibration (same likelihood and sampler settings, the
    single-subject prior of Table 9.1), the reference of the shrinkage.

    Every fit compiles its own programs, and XLA keeps memory mappings of each even after JAX's caches are cleared
    (:mod:`lvcore.execution.restart`): a process ran out of them (LLVM "Cannot allocate memory", then a segfault)
    in its second cohort of 24 two-state subjects, at about 1,100 mappings a fit (BENCHMARKS.md row 64). So the
    programs are let go once the process passes :data:`MAPPING_SHARE_RELEASE` of the kernel's limit (not before:
    subjects that share one compiled sampler would each compile it again), and the fits stop, with a warning,
    past :data:`MAPPING_SHARE_LIMIT`; the subjects fitted so far are returned (the shrinkage is then over them,
    and the group check is left out)."""
    from lvcore.execution.restart import mapping_share
    from lvcore.inference.calibrate import calibrate, release_compiled_programs

    out = {}
    for k, m in enumerate(members):
        share = mapping_share()
        if share is not None and share > MAPPING_SHARE_RELEASE:
            release_compiled_programs()
            share = mapping_share()
        if share is not None and share > MAPPING_SHARE_LIMIT:
            print(f"lvcore: warning: separate fits stopped after {k} of {len(members)} subjects: this process "
                  f"holds {share:.0%} of the kernel's memory-mapping limit (compiled programs); the shrinkage is "
                  "over the subjects fitted, the group check left out; calibrate fewer subjects per run for all "
                  "of them", file=sys.stderr)
            break
        if progress is not None:
            progress(f"separate fit {k + 1}/{len(members)}: {m.subject}")
        res = calibrate(m.y, m.forward, likelihood, config=config, sigma_v=sigma_v, max_rounds=1)
        out[m.subject] = {n: {c: float(res.summary.loc[n, c]) for c in ("q05", "median", "q95")} for n in THETA_NAMES}
        out[m.subject]["converged"] = bool(res.convergence.converged)
    return out


def cohort_args(data, out, **options):
    """``lvcore calibrate --hierarchical``'s options as the command line parses them (its defaults), for a front
    end that is not the command line (the app): ``options`` by their destination names, e.g. ``warmup=300``,
    ``geometry="mean"``."""
    import argparse

    from lvcore.inference.cli import register

    parser = argparse.ArgumentParser(prog="lvcore")
    register(parser.add_subparsers())
    argv = ["calibrate", "--data", str(data), "--hierarchical", "--out", str(out)]
    for k, v in options.items():
        if v is not None:
            argv += [f"--{k.replace('_', '-')}", str(v)]
    return parser.parse_args(argv)


def cohort_warnings(cohort) -> list[str]:
    """What a hierarchical calibration of ``cohort`` should tell its user before trusting the joint posterior.

    A cohort that mixes subjects with one loaded state and subjects with several: on a SYNTHETIC cohort of 24 (six
    at 8 + 20 mmHg, 18 at 8 mmHg) the joint posterior was confident and wrong (a's 90 % intervals covered the truth
    in 7-9 of 24 subjects against 24 of 24 for separate fits; BENCHMARKS.md row 64).
    """
    counts = {r.subject: r.n_states for r in cohort.rows}
    many = sorted(s for s, n in counts.items() if n > 1)
    if many and len(many) < len(counts):
        return [f"{len(many)} of {len(counts)} subjects have several loaded states and the others one: on a "
                "SYNTHETIC cohort mixed like this the joint posterior was confident and wrong (a covered in 7-9 of "
                "24 subjects, 24 of 24 for separate fits); compare each subject's joint interval with its separate "
                "fit (summary.json: subjects, separate) before using it"]
    return []


def calibrate_cohort(args, say=print, progress_bar: bool = True) -> dict:
    """Read the cohort, sample the joint posterior, fit each subject alone and write ``summary.json`` and
    ``hierarchical.nc`` to ``args.out``; return summary.json's ``hierarchical`` section."""
    from lvcore.inference import hierarchical as hi
    from lvcore.inference.samplers import SamplerConfig

    likelihood = check_hierarchical_options(args)
    cohort, name, members, requests, groups = prepare_cohort(args)
    warnings = cohort_warnings(cohort)
    for w in dict.fromkeys([*warnings, *(w for q in requests.values() for w in q.warnings)]):
        print(f"lvcore: warning: {w}", file=sys.stderr)
    config = SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains, seed=args.seed)
    say(f"joint NUTS over {len(members)} subjects ({likelihood} likelihood, {name} emulator, "
        f"{args.chains} x ({args.warmup} + {args.samples})); progress on stderr")
    run = hi.run_hierarchical(members, groups=tuple(groups), likelihood=likelihood, config=config,
                              sigma_v=args.sigma_v, progress_bar=progress_bar)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    extra = {"data_file": str(args.data), "emulator": name,
             "synthetic": all("SYNTHETIC" in s.upper() for s in cohort.subjects),
             "geometry": {s: dict(q.geometry_record) for s, q in requests.items()}, "warnings": warnings}
    rec = {**hi.summarise(run), **extra, "separate_fits": "running"}
    _write_netcdf(run, out / "hierarchical.nc", rec)   # kept if the separate fits fail or are stopped
    (out / "summary.json").write_text(json.dumps({"hierarchical": rec}, indent=2, default=_plain))
    say(f"joint posterior in {run.wall_s:.1f} s (written to {out}); separate fits for the shrinkage")
    separate = separate_fits(members, likelihood, config, args.sigma_v, progress=say)
    rec["separate_fits"] = f"{len(separate)} of {len(members)}"
    if separate:
        hi.with_separate(rec, run, separate)
    (out / "summary.json").write_text(json.dumps({"hierarchical": rec}, indent=2, default=_plain))
    return rec


def run_hierarchical_calibrate(args) -> int:
    """``lvcore calibrate --hierarchical``: the exit code (0, 1 not converged, 4 flagged)."""
    from lvcore.inference.cli import EXIT_FLAGGED

    rec = calibrate_cohort(args, say=(lambda msg: None) if args.json else print, progress_bar=not args.json)
    if args.json:
        print(json.dumps({"hierarchical": rec}, indent=2, default=_plain))
    else:
        for line in text_report(rec):
            print(line)
        print(f"\nwrote {args.out}/summary.json and {args.out}/hierarchical.nc")
    if not rec["converged"]:
        return 1
    flagged = rec["diagnostics"]["population"]["n_divergent"] > 0 or bool(rec.get("flags"))
    return EXIT_FLAGGED if flagged else 0


def _plain(v):
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return str(v)


def _write_netcdf(run, path: Path, rec: dict) -> None:
    import arviz as az

    from lvcore.inference.diagnostics import save_netcdf

    s = run.samples
    post = {"mu": s["mu"], "tau": s["tau"], "corr": s["corr"], "log_theta": s["log_theta"]}
    if "sigma_s2" in s:
        post["sigma_s2"] = s["sigma_s2"]
    dims = {"mu": ["group", "theta"], "tau": ["theta"], "corr": ["theta", "theta_"],
            "log_theta": ["subject", "theta"], "sigma_s2": ["subject"]}
    idata = az.from_dict(posterior=post, sample_stats={"diverging": run.stats["diverging"]},
                         coords={"group": list(run.groups), "theta": list(THETA_NAMES), "theta_": list(THETA_NAMES),
                                 "subject": list(run.subjects)}, dims=dims,
                         attrs={"kind": "hierarchical", "likelihood": run.likelihood, "data_file": rec["data_file"],
                                "emulator": rec["emulator"], "synthetic": int(rec["synthetic"])})
    save_netcdf(idata, path)


def _ratios(diffs: dict) -> str:
    """``a 3.27 [1.62, 9.46] *, b ...``: each parameter's ratio, its 90 % interval, * where it excludes 1."""
    return ", ".join(f"{k} {v['ratio']['median']:.2f} [{v['ratio']['q05']:.2f}, {v['ratio']['q95']:.2f}]"
                     + (" *" if v["excludes_zero"] else "") for k, v in diffs.items())


def text_report(rec: dict) -> list[str]:
    """The printed summary: population per group, differences, sds, subjects with shrinkage, diagnostics."""
    pop, lines = rec["population"], []
    for g, grp in pop["groups"].items():
        lines.append(f"\npopulation median theta, group {g} ({grp['n_subjects']} subjects), median [90 %]: " + ", ".join(
            f"{k} {q['median']:.3g} [{q['q05']:.3g}, {q['q95']:.3g}]" for k, q in grp["median_theta"].items()))
    lines.append("population sd of log theta: " + ", ".join(
        f"{k} {q['median']:.2f} [{q['q05']:.2f}, {q['q95']:.2f}]" for k, q in pop["sd"].items()))
    for pair, d in pop["differences"].items():
        lines.append(f"difference of group means {pair} (ratio, median [90 %]): " + _ratios(d)
                     + "  (* interval excludes no difference)")
    for pair, d in pop.get("differences_separate", {}).items():
        lines.append(f"the same from the separate fits, subjects resampled {pair} (ratio of mean log medians "
                     "[90 %]): " + _ratios(d))
    lines.extend(rec.get("flags") or [])
    shr = rec.get("shrinkage", {}).get("per_subject", {})
    lines.append("\nsubject: a median [90 %] joint | separate, shrinkage of the a interval")
    for s, q in rec["subjects"].items():
        sep = rec.get("separate", {}).get(s)
        tail = "" if sep is None else (f" | {sep['a']['median']:.3g} [{sep['a']['q05']:.3g}, {sep['a']['q95']:.3g}], "
                                       f"{shr[s]['a']['shrinkage']:.2f}")
        lines.append(f"  {s}: {q['a']['median']:.3g} [{q['a']['q05']:.3g}, {q['a']['q95']:.3g}]{tail}")
    if rec.get("shrinkage"):
        lines.append("median narrowing (separate width / joint width): " + ", ".join(
            f"{k} {v:.2f}x" for k, v in rec["shrinkage"]["median_narrowing"].items() if v is not None))
    for level, d in rec["diagnostics"].items():
        lines.append(f"{level} level: {'converged' if d['converged'] else 'NOT CONVERGED'}: max R-hat "
                     f"{d['max_rhat']:.3f}, min bulk ESS {d['min_ess_bulk']:.0f}, {d['n_divergent']} divergent (joint)"
                     + (f"; failing: {', '.join(d['failing'])}" if d["failing"] else ""))
    return lines


__all__ = ["run_hierarchical_calibrate", "calibrate_cohort", "cohort_args", "check_hierarchical_options", "prepare_cohort", "separate_fits",
           "text_report"]
