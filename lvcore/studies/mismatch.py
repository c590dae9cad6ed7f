"""Model–data mismatch as a dose–response (issue 26, item 2): ``lvcore study mismatch``.

The chapter's findings on the likelihoods (F1: iid inflates σ_S about 2×;
F2: the discrepancy model's σ_S near the truth; F3: discrepancy ≈ volume <
iid in output error) depend on how far the data are from the model. Here the
SYNTHETIC data come from the FE simulator with one **mismatch source** at a
**dose** that the calibration model (the ``chapter`` emulator: HO law with
the population sheet terms, no dispersion, homogeneous, no pericardium,
angles (−60°, 60°), sliding base) does not have:

=================  ==========================================================  =====================
source             what the data-generating simulator changes                  dose
=================  ==========================================================  =====================
``angles``         both helix angles rotated: (−60 + d, 60 + d)                d in degrees
``base``           clamped instead of sliding base                             1 (one dose)
``sheet``          sheet and fibre-sheet stiffnesses ``as``, ``afs`` × d       multiplier d
``dispersion``     GOH fibre dispersion ``kappa`` = d                          κ in [0, 1/3]
``heterogeneity``  per-region multipliers exp(d·z) of a and af, z ~ N(0, 1)    log-sd d
                   with a fixed seed (the same field for every volunteer)
``pericardium``    epicardial Robin spring, normal direction, k = d            kPa/mm
=================  ==========================================================  =====================

For each volunteer (the bundled SYNTHETIC HV1–HV8, on the PCA geometry of
their recorded scores h, at their hidden θ) the simulator runs once without
mismatch (the *nominal* outputs) and once per (source, dose). The dose's
size is measured as the RMS over the 24 strains of (mismatched − nominal).
Each mismatched output gets ``seeds`` noise draws (σ_V = 5 mL, σ_S = 0.03)
and every data set is calibrated with the volume, iid and discrepancy
likelihoods on the emulator at the volunteer's h. Reported per (source,
dose), each with a percentile bootstrap CI over the data sets:

* the iid σ_S inflation (median posterior σ_S / 0.03, median over data sets);
* the discrepancy model's σ_S;
* the output error per likelihood: |η(θ_post, h) − η(θ_true, h)| over the
  24 strains, median over draws, median over data sets;
* the θ coverage per likelihood: the fraction of the 4 central 90 %
  intervals that cover the true θ;

and per source the smallest dose at which F1 (iid inflation ≥ 1.5 with the
CI above 1.2) and the F3 ordering (discrepancy and volume errors below iid's)
appear, or "does not appear up to RMS x".

**Resumable.** Each simulation result is written atomically to
``OUT/sims/<volunteer>__<source>__<dose>.json`` and each fit to
``OUT/fits/...json`` as soon as it finishes; a rerun with the same ``OUT``
skips what is there. Simulations run on the campaign executors (a local
process pool, or a Dask scheduler with ``--scheduler``), as campaigns do.
The full chapter-size run (6 sources × 4–5 doses × 8 volunteers × ≥ 20
seeds) is not done by default; see docs/studies.md for its cost.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from lvcore.conditions import CHAPTER_ANGLES, CHAPTER_EDP, SIGMA_S, SIGMA_V_ML
from lvcore.core.space import build_case
from lvcore.outputs import THETA_NAMES
from lvcore.studies._common import clean, write_json_atomic

MODELS = ("volume", "iid", "discrepancy")
#: The calibration model's fixed conditions (the ``chapter`` emulator).
MODEL_ANGLES = CHAPTER_ANGLES
MODEL_BASE = "sliding"
#: Doses per source for the full study (chosen to span strain RMS mismatch ~0.005-0.06; to be confirmed by
#: the full run: the RMS each dose gives is measured and reported, not assumed).
DEFAULT_DOSES = {
    "angles": (10.0, 20.0, 30.0, 45.0),
    "base": (1.0,),
    "sheet": (2.0, 4.0, 8.0, 16.0),
    "dispersion": (0.05, 0.1, 0.2, 0.3),
    "heterogeneity": (0.1, 0.2, 0.4, 0.8),
    "pericardium": (0.02, 0.05, 0.1, 0.2),
}
SOURCES = tuple(DEFAULT_DOSES)
#: Seed of the heterogeneity field (the same regional pattern at every dose and for every volunteer).
HETEROGENEITY_SEED = 26
#: F1 "appears": median iid inflation at least this, with the bootstrap CI's lower end above F1_CI_FLOOR.
F1_INFLATION, F1_CI_FLOOR = 1.5, 1.2


# ----------------------------------------------------------------------------
# the mismatched case (pure)
# ----------------------------------------------------------------------------
def mismatch_case(theta: dict, h: Sequence[float], source: str | None, dose: float, *,
                  resolution: str = "default") -> dict:
    """The simulator case of a volunteer (θ, PC scores h) with one mismatch ``source`` at ``dose``.

    ``source=None`` (or dose 0) is the calibration model's own condition: angles
    :data:`MODEL_ANGLES`, base :data:`MODEL_BASE`, population sheet terms.
    """
    inputs = {**{n: float(theta[n]) for n in THETA_NAMES}, "alpha_endo": MODEL_ANGLES[0],
              "alpha_epi": MODEL_ANGLES[1], "edp": CHAPTER_EDP,
              **{f"h{i + 1}": float(v) for i, v in enumerate(h)}}
    base = MODEL_BASE
    if source == "angles":
        inputs["alpha_endo"] += dose
        inputs["alpha_epi"] += dose
    if source == "base" and dose:
        base = "clamped"
    case = build_case(inputs, resolution=resolution, base=base)
    mat, bnd = case["material"], case["boundary"]
    if source == "sheet":
        from lvcore.units import HO_FIXED

        mat["as"], mat["afs"] = HO_FIXED["as"] * dose, HO_FIXED["afs"] * dose
    elif source == "dispersion":
        mat["kappa"] = float(dose)
    elif source == "heterogeneity" and dose:
        z = np.random.default_rng(HETEROGENEITY_SEED).standard_normal((2, 24))
        f = np.exp(float(dose) * z)
        mat["regional"] = {"a": f[0].tolist(), "af": f[1].tolist()}
    elif source == "pericardium" and dose:
        bnd["epicardial_spring"] = {"k": float(dose), "direction": "normal"}
    elif source not in (None, "angles", "base", "sheet", "dispersion", "heterogeneity", "pericardium"):
        raise ValueError(f"unknown mismatch source {source!r}; choose from {SOURCES}")
    return case


def _simulate_job(key: str, case: dict) -> dict:
    """Worker: simulate one case; failures are recorded, never raised."""
    from lvcore.core.forward import failure_reason
    from lvcore.mechanics.simulate import simulate

    t0 = time.perf_counter()
    try:
        r = simulate(case)
        if not r.converged:
            return {"key": key, "converged": False, "reason": r.message, "seconds": time.perf_counter() - t0}
        return {"key": key, "converged": True, "outputs": r.outputs().tolist(), "seconds": time.perf_counter() - t0}
    except Exception as err:  # noqa: BLE001 - a failed simulation is data
        return {"key": key, "converged": False, "reason": failure_reason(err), "seconds": time.perf_counter() - t0}


# ----------------------------------------------------------------------------
# volunteers
# ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Volunteer:
    """A SYNTHETIC volunteer: name, PC scores h (the emulator's geometry inputs) and hidden θ."""

    name: str
    h: tuple[float, ...]
    theta: dict


def bundled_volunteers(names: Sequence[str] | None = None) -> list[Volunteer]:
    """The bundled SYNTHETIC volunteers (all, or ``names`` such as ``HV1``) with their recorded h and θ."""
    from lvcore.resources import volunteer_truth, volunteers_dir

    meta = json.loads((volunteers_dir() / "SYNTHETIC_volunteers.json").read_text())
    out = []
    for v in meta["volunteers"]:
        short = v["subject"].split("-")[-1]
        if names and short not in names and v["subject"] not in names:
            continue
        truth = volunteer_truth(v["subject"])
        out.append(Volunteer(short, tuple(float(x) for x in v["pca_scores_h1_h5"]),
                             {n: truth[n] for n in THETA_NAMES}))
    if names and len(out) != len(set(names)):
        known = [v["subject"].split("-")[-1] for v in meta["volunteers"]]
        raise ValueError(f"unknown volunteer(s) in {list(names)}; bundled: {known}")
    return out


# ----------------------------------------------------------------------------
# steps: simulate, fit, summarise
# ----------------------------------------------------------------------------
def _key(vol: str, source: str | None, dose: float) -> str:
    return f"{vol}__{source or 'none'}__{dose:g}"


def simulate_all(volunteers, plan, out: Path, *, resolution="default", workers=1, scheduler=None,
                 progress: Callable | None = None, retry_failed: bool = False) -> dict:
    """Simulate every (volunteer, source, dose) of ``plan`` plus each volunteer's nominal case; resumable.

    Recorded results are reused; failed ones too, unless ``retry_failed``.
    Returns key -> record (``converged``, ``outputs`` or ``reason``).
    """
    sims = out / "sims"
    sims.mkdir(parents=True, exist_ok=True)
    jobs = {}
    for v in volunteers:
        for source, dose in [(None, 0.0)] + [(s, d) for s, ds in plan.items() for d in ds]:
            key = _key(v.name, source, dose)
            path = sims / f"{key}.json"
            if not path.is_file() or (retry_failed and not json.loads(path.read_text())["converged"]):
                jobs[key] = mismatch_case(v.theta, v.h, source, dose, resolution=resolution)
    if jobs:
        if workers == 1 and not scheduler:
            for i, (k, c) in enumerate(jobs.items()):
                write_json_atomic(sims / f"{k}.json", _simulate_job(k, c))
                if progress:
                    progress(f"simulated {k} ({i + 1}/{len(jobs)})")
        else:
            from lvcore.parallel import make_executor

            with make_executor(workers=workers, scheduler=scheduler) as ex:
                futures = [ex.submit(_simulate_job, k, c) for k, c in jobs.items()]
                for i, fut in enumerate(ex.as_completed(futures)):
                    rec = fut.result()
                    write_json_atomic(sims / f"{rec['key']}.json", rec)
                    if progress:
                        progress(f"simulated {rec['key']} ({i + 1}/{len(jobs)})")
    return {p.stem: json.loads(p.read_text()) for p in sims.glob("*.json")}


def _fit_one(forward, y, model: str, config, seed: int) -> dict:
    """Posterior draws of one likelihood for data sets ``y`` (n, 25) in one vmapped run."""
    import jax

    from lvcore.inference import coverage

    sites = list(THETA_NAMES) + {"volume": [], "iid": ["sigma_s2"], "discrepancy": ["sigma_s2"]}[model]
    keys = jax.random.split(jax.random.PRNGKey(seed), y.shape[0])
    draws = coverage.batched_posteriors(forward, model, y, keys, config, SIGMA_V_ML, sites=sites)
    eta = jax.jit(jax.vmap(jax.vmap(forward)))({n: draws[n] for n in THETA_NAMES})
    draws["eta"] = np.asarray(eta)
    return draws


def fit_doses(vol: Volunteer, zs: dict, forward, *, seeds: int, config, seed: int, noise_seeds: dict) -> dict:
    """Calibrate ``seeds`` noisy copies of each outputs vector in ``zs`` (key -> (25,)) with the three likelihoods.

    All data sets of one volunteer go through one vmapped, compiled run per
    likelihood (one compilation per volunteer and likelihood, not per dose).
    ``noise_seeds[key]`` seeds the noise of ``key``'s data sets. Returns key ->
    per-likelihood lists over its data sets: ``coverage`` (fraction of the 4
    central 90 % θ intervals covering the truth), ``output_error`` (median over
    draws of the mean |η(θ, h) − η(θ_true, h)| over the 24 strains) and ``sigma_s``
    (posterior median).
    """
    keys = list(zs)
    ys = np.concatenate([np.asarray(zs[k])[None, :] + np.r_[SIGMA_V_ML, np.full(24, SIGMA_S)]
                         * np.random.default_rng(noise_seeds[k]).standard_normal((seeds, 25)) for k in keys])
    truth = np.array([vol.theta[n] for n in THETA_NAMES])
    eta_true = np.asarray(forward(vol.theta), dtype=float)
    out = {k: {} for k in keys}
    for j, m in enumerate(MODELS):
        d = _fit_one(forward, ys, m, config, seed + 1 + j)
        th = np.stack([d[n] for n in THETA_NAMES], axis=-1)  # (n, draws, 4)
        lo, hi = np.quantile(th, [0.05, 0.95], axis=1)
        cov = np.mean((lo <= truth) & (truth <= hi), axis=1)
        err = np.median(np.abs(d["eta"][:, :, 1:] - eta_true[1:]).mean(axis=2), axis=1)
        sig = np.median(np.sqrt(d["sigma_s2"]), axis=1) if "sigma_s2" in d else None
        for i, k in enumerate(keys):
            sl = slice(i * seeds, (i + 1) * seeds)
            out[k][m] = {"coverage": cov[sl].tolist(), "output_error": err[sl].tolist(),
                         **({"sigma_s": sig[sl].tolist()} if sig is not None else {})}
    return out


def _boot(values, stat=np.median, n_boot: int = 2000, seed: int = 0, level: float = 0.9) -> dict:
    v = np.asarray(values, dtype=float)
    rng = np.random.default_rng(seed)
    boots = stat(v[rng.integers(0, v.size, size=(n_boot, v.size))], axis=1)
    lo, hi = np.quantile(boots, [(1 - level) / 2, (1 + level) / 2])
    return {"value": float(stat(v)), "ci": [float(lo), float(hi)], "n": int(v.size)}


def summarise(fits_by_dose: dict, rms_by_dose: dict) -> list[dict]:
    """Per (source, dose): the bootstrap summaries of the pooled per-data-set metrics."""
    rows = []
    for (source, dose), per_vol in fits_by_dose.items():
        pool = {m: {k: [] for k in ("coverage", "output_error", "sigma_s")} for m in MODELS}
        for rec in per_vol.values():
            for m in MODELS:
                for k in pool[m]:
                    pool[m][k].extend(rec[m].get(k, []))
        row = {"source": source, "dose": dose, "strain_rms_mismatch": rms_by_dose[(source, dose)],
               "iid_sigma_s_inflation": _boot(np.asarray(pool["iid"]["sigma_s"]) / SIGMA_S),
               "discrepancy_sigma_s": _boot(pool["discrepancy"]["sigma_s"]),
               "output_error": {m: _boot(pool[m]["output_error"]) for m in MODELS},
               "theta_coverage": {m: _boot(pool[m]["coverage"], stat=np.mean) for m in MODELS}}
        e = row["output_error"]
        row["f1"] = bool(row["iid_sigma_s_inflation"]["value"] >= F1_INFLATION
                         and row["iid_sigma_s_inflation"]["ci"][0] > F1_CI_FLOOR)
        row["f3"] = bool(e["discrepancy"]["value"] < e["iid"]["value"] and e["volume"]["value"] < e["iid"]["value"])
        rows.append(row)
    return rows


def appearance(rows: list[dict]) -> dict:
    """Per source: the smallest dose (and its strain RMS) where F1 / the F3 ordering appear."""
    out = {}
    for source in dict.fromkeys(r["source"] for r in rows):
        rs = sorted((r for r in rows if r["source"] == source), key=lambda r: r["strain_rms_mismatch"]["mean"])
        top = rs[-1]["strain_rms_mismatch"]["mean"] if rs else float("nan")
        out[source] = {}
        for f in ("f1", "f3"):
            hit = next((r for r in rs if r[f]), None)
            out[source][f] = ({"dose": hit["dose"], "strain_rms": hit["strain_rms_mismatch"]["mean"]} if hit else
                              f"does not appear up to RMS {top:.3g}")
    return out


def run_study(*, sources: Sequence[str] = SOURCES, doses: dict | None = None, volunteers: Sequence[str] | None = None,
              seeds: int = 20, config=None, seed: int = 0, resolution: str = "default", emulator: str = "chapter",
              workers: int = 1, scheduler: str | None = None, out: str | Path = "study_mismatch",
              progress: Callable | None = None, retry_failed: bool = False) -> dict:
    """Run (or resume) the study under ``out``; returns the result (also written to ``out/mismatch.json``)."""
    from lvcore.emulator.forward import load_emulator_forward
    from lvcore.inference import samplers

    t0 = time.perf_counter()
    out = Path(out)
    config = config or samplers.SamplerConfig()
    plan = {s: tuple(float(d) for d in (doses or {}).get(s, DEFAULT_DOSES[s])) for s in sources}
    bad = sorted(set(plan) - set(SOURCES))
    if bad:
        raise ValueError(f"unknown mismatch source(s) {bad}; choose from {SOURCES}")
    vols = bundled_volunteers(volunteers)
    sims = simulate_all(vols, plan, out, resolution=resolution, workers=workers, scheduler=scheduler,
                        progress=progress, retry_failed=retry_failed)
    t_sim = time.perf_counter() - t0
    fits, rms, failed = {}, {}, []
    tag = f"s{seeds}_w{config.num_warmup}_n{config.num_samples}_c{config.num_chains}"
    for v in vols:
        nominal = sims[_key(v.name, None, 0.0)]
        if not nominal["converged"]:
            failed.append({"key": _key(v.name, None, 0.0), "reason": nominal["reason"]})
            continue
        todo, done = {}, {}
        for source, ds in plan.items():
            for dose in ds:
                key = _key(v.name, source, dose)
                rec = sims[key]
                if not rec["converged"]:
                    failed.append({"key": key, "reason": rec["reason"]})
                    continue
                z = np.asarray(rec["outputs"])
                rms.setdefault((source, dose), []).append(
                    float(np.sqrt(np.mean((z[1:] - np.asarray(nominal["outputs"])[1:]) ** 2))))
                path = out / "fits" / f"{key}__{tag}.json"
                if path.is_file():
                    done[(source, dose)] = json.loads(path.read_text())
                else:
                    todo[(source, dose)] = z
        if todo:
            if progress:
                progress(f"calibrating {v.name}: {len(todo)} dose(s) x {seeds} data sets x {len(MODELS)} likelihoods")
            forward = load_emulator_forward(emulator, v.h)
            noise = {sd: seed + 1000 * SOURCES.index(sd[0]) + 17 * plan[sd[0]].index(sd[1]) + 7919 * vols.index(v)
                     for sd in todo}
            new = fit_doses(v, todo, forward, seeds=seeds, config=config, seed=seed + 31 * vols.index(v),
                            noise_seeds=noise)
            for sd, fit in new.items():
                fit = clean(fit)
                write_json_atomic(out / "fits" / f"{_key(v.name, *sd)}__{tag}.json", fit)
                done[sd] = fit
        for sd, fit in done.items():
            fits.setdefault(sd, {})[v.name] = fit
    t_fit = time.perf_counter() - t0 - t_sim
    rms_s = {k: {"mean": float(np.mean(r)), "min": float(np.min(r)), "max": float(np.max(r))} for k, r in rms.items()}
    rows = summarise(fits, rms_s)
    result = {
        "study": "mismatch", "synthetic": True,
        "emulator": emulator, "resolution": resolution,
        "model_conditions": {"angles": list(MODEL_ANGLES), "base": MODEL_BASE},
        "volunteers": [v.name for v in vols], "seeds_per_dose": seeds,
        "doses": {s: list(d) for s, d in plan.items()},
        "sampler": {"num_warmup": config.num_warmup, "num_samples": config.num_samples,
                    "num_chains": config.num_chains},
        "noise": {"sigma_v_ml": SIGMA_V_ML, "sigma_s": SIGMA_S},
        "rows": rows, "appearance": appearance(rows), "failed": failed,
        "timings_s": {"simulate": t_sim, "calibrate": t_fit, "total": time.perf_counter() - t0},
    }
    write_json_atomic(out / "mismatch.json", clean(result))
    return result


# ----------------------------------------------------------------------------
# CLI
# ----------------------------------------------------------------------------
def add_study_parser(study_subparsers) -> None:
    """``lvcore study mismatch``."""
    p = study_subparsers.add_parser("mismatch", help="model-data mismatch dose-response (issue 26): sigma_S "
                                                     "inflation, output error and theta coverage per likelihood")
    p.add_argument("--out", default="study_mismatch", help="output (and resume) folder")
    p.add_argument("--sources", default=",".join(SOURCES), help=f"comma-separated, from {','.join(SOURCES)}")
    p.add_argument("--doses", action="append", default=[], metavar="SOURCE=D1,D2",
                   help="doses of one source (repeatable); default DEFAULT_DOSES")
    p.add_argument("--volunteers", default=None, help="e.g. HV1,HV2 (default all bundled)")
    p.add_argument("--seeds", type=int, default=20, help="noise seeds per dose and volunteer")
    p.add_argument("--warmup", type=int, default=500, help="warm-up iterations per chain (default 500)")
    p.add_argument("--samples", type=int, default=500, help="draws kept per chain (default 500)")
    p.add_argument("--chains", type=int, default=2, help="MCMC chains (default 2)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--resolution", default="default", help="simulator mesh preset (default 'default')")
    p.add_argument("--emulator", default="chapter", help="emulator of the calibrations (default chapter)")
    p.add_argument("--workers", type=int, default=1, help="local simulation workers")
    p.add_argument("--scheduler", default=None,
                   help="tcp://HOST:PORT of a Dask scheduler for the simulations (default: none, local workers)")
    p.add_argument("--retry-failed", action="store_true", help="run recorded failed simulations again")
    p.add_argument("--json", action="store_true", help="print the findings as JSON")
    p.set_defaults(func=_cli)


def _parse_doses(items, sources) -> dict:
    """``["dispersion=0.1,0.2", ...]`` -> ``{"dispersion": (0.1, 0.2)}`` (ValueError naming the bad item)."""
    doses = {}
    for item in items:
        name, _, vals = item.partition("=")
        if name not in sources or not vals:
            raise ValueError(f"--doses {item!r}: expected SOURCE=D1,D2 with SOURCE one of {','.join(sources)}")
        try:
            doses[name] = tuple(float(x) for x in vals.split(","))
        except ValueError:
            raise ValueError(f"--doses {item!r}: doses must be numbers") from None
    return doses


def _cli(args) -> int:
    import sys

    from lvcore.inference import samplers

    sources = tuple(s for s in args.sources.split(",") if s)
    unknown = sorted(set(sources) - set(SOURCES))
    if unknown:
        print(f"lvcore study mismatch: --sources: unknown {unknown}; choose from {','.join(SOURCES)}", file=sys.stderr)
        return 2
    try:
        doses = _parse_doses(args.doses, sources)
        vols = args.volunteers.split(",") if args.volunteers else None
        if vols:
            bundled_volunteers(vols)
    except ValueError as err:  # bad options: a clear message, exit 2
        print(f"lvcore study mismatch: {err}", file=sys.stderr)
        return 2
    samplers.use_host_devices(args.chains)
    cfg = samplers.SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains,
                                 seed=args.seed)
    res = run_study(sources=sources, doses=doses, volunteers=vols, seeds=args.seeds, config=cfg, seed=args.seed,
                    resolution=args.resolution, emulator=args.emulator, workers=args.workers,
                    scheduler=args.scheduler, out=args.out, retry_failed=args.retry_failed,
                    progress=None if args.json else (lambda msg: print(msg, flush=True)))
    brief = {"appearance": res["appearance"], "failed": res["failed"], "timings_s": res["timings_s"]}
    print(json.dumps(brief, indent=2))
    if not args.json:
        print(f"wrote {args.out}/mismatch.json")
    return 0


__all__ = ["SOURCES", "DEFAULT_DOSES", "mismatch_case", "bundled_volunteers", "simulate_all", "fit_doses", "run_study",
           "summarise", "appearance"]
