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
import zlib
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from lvcore.conditions import CHAPTER_ANGLES, CHAPTER_EDP, SIGMA_S, SIGMA_V_ML
from lvcore.core.space import build_case
from lvcore.outputs import THETA_NAMES
from lvcore.studies._common import clean, percentile_bootstrap, write_json_atomic

MODELS = ("volume", "iid", "discrepancy")
#: The calibration model's fixed conditions (the ``chapter`` emulator).
MODEL_ANGLES = CHAPTER_ANGLES
MODEL_BASE = "sliding"
#: Doses per source, chosen from a simulation-only pass (``--simulate-only``, HV1 and HV5, docs/studies.md) to
#: span a strain RMS mismatch of about 0.005-0.06 where the physics reaches it: the angle rotation peaks near
#: 0.017 (30°) and falls beyond; the sheet terms stay below 0.002 even at 32x (a null control, two doses);
#: heterogeneity 1.6 is refused by the case's multiplier bounds [0.01, 100] (1.2 gives 0.045); dispersion
#: reaches 0.03-0.11 at kappa = 1/3 depending on the volunteer; the pericardial spring saturates near 0.21.
DEFAULT_DOSES = {
    "angles": (5.0, 15.0, 30.0, 45.0),
    "base": (1.0,),
    "sheet": (4.0, 32.0),
    "dispersion": (0.025, 0.05, 0.1, 0.2, 0.333),
    "heterogeneity": (0.2, 0.4, 0.8, 1.2),
    "pericardium": (0.03, 0.1, 0.2, 0.3),
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


def unit_seed(key: str, seed: int = 0) -> int:
    """A seed of one (volunteer, source, dose) from its key: its data sets and chains do not depend on which
    other doses are run, nor on how they are batched (resumed runs give the same numbers)."""
    return (zlib.crc32(key.encode()) + 7919 * int(seed)) % (2**31 - 1)


def noisy_copies(z, seeds: int, noise_seed: int) -> np.ndarray:
    """``seeds`` data sets (seeds, 25): the outputs ``z`` plus noise (σ_V = 5 mL, σ_S = 0.03)."""
    return np.asarray(z, dtype=float)[None, :] + np.r_[SIGMA_V_ML, np.full(24, SIGMA_S)] \
        * np.random.default_rng(noise_seed).standard_normal((seeds, 25))


def _diagnostics(draws: dict, names) -> tuple[np.ndarray, np.ndarray | None]:
    """Per data set: the smallest bulk ESS over ``names`` and the largest rank-normalised split R-hat, by ArviZ
    (with one chain, the R-hat of its two halves).

    ``draws[name]``: (n_datasets, chains, samples).
    """
    import arviz as az

    arrays = {n: np.moveaxis(np.asarray(draws[n]), 0, -1) for n in names}  # (chains, samples, n_datasets)
    ds = az.convert_to_dataset(arrays)
    ess = np.min(np.stack([np.asarray(az.ess(ds, method="bulk")[n]) for n in names]), axis=0)
    chains, samples = arrays[names[0]].shape[:2]
    if chains < 2:  # one chain: R-hat of its two halves (split R-hat), as ArviZ needs two chains
        if samples < 8:
            return ess, None
        half = samples // 2
        ds = az.convert_to_dataset({n: a[:, :2 * half].reshape((2, half) + a.shape[2:]) for n, a in arrays.items()})
    rhat = np.max(np.stack([np.asarray(az.rhat(ds)[n]) for n in names]), axis=0)
    return ess, rhat


#: The jitted η-at-every-draw function of the last forward model (reused by the next batch: no recompilation).
_ETA: dict = {}


def fit_datasets(forward, ys, conditions, truths, eta_trues, *, config, keys, models=MODELS) -> dict:
    """Calibrate the data sets ``ys`` (n, 25) with the three likelihoods in one vmapped run each.

    Parameters
    ----------
    forward : lvcore.emulator.forward.EmulatorForward
        The emulator; each data set's geometry comes from ``conditions``.
    ys : ndarray, shape (n, 25)
    conditions : ndarray, shape (n, k), optional
        Each data set's run-time conditions (its volunteer's PC scores,
        :func:`lvcore.inference.samplers.runtime_conditions`): data sets of
        every volunteer share one compiled sampler. None: ``forward`` as given
        (any traceable forward model).
    truths : ndarray, shape (n, 4)
        True θ of each data set.
    eta_trues : ndarray, shape (n, 25)
        The emulator at the true θ and the data set's geometry.
    config : SamplerConfig
    keys : jax PRNG keys, shape (n, 2)
    models : sequence of str
        Likelihoods to run (default all three).

    Returns
    -------
    dict
        Per likelihood, arrays over the data sets: ``coverage`` (fraction of the
        4 central 90 % θ intervals covering the truth), ``output_error`` (median
        over draws of the mean |η(θ, h) − η(θ_true, h)| over the 24 strains),
        ``sigma_s`` (posterior median; iid and discrepancy), ``min_ess`` (the
        smallest bulk ESS over θ and σ_S², ArviZ) and ``max_rhat`` (the largest
        R-hat; with one chain, of its two halves).
    """
    import jax

    from lvcore.inference import coverage, samplers

    cached = _ETA.get((id(forward), conditions is None))
    if cached is not None and cached[0] is forward:
        eta_fn = cached[1]
    elif conditions is None:  # one geometry, compiled into the forward model (any traceable forward model)
        eta_fn = jax.jit(jax.vmap(lambda p, c: jax.vmap(forward)(p)))
    else:
        template, _ = samplers.runtime_conditions(forward)
        eta_fn = jax.jit(jax.vmap(lambda p, c: jax.vmap(template.bind({"conditions": c}))(p)))
    _ETA.clear()
    _ETA[(id(forward), conditions is None)] = (forward, eta_fn)
    if conditions is None:
        conditions, cond_arg = np.zeros((ys.shape[0], 0)), None
    else:
        cond_arg = conditions = np.asarray(conditions, dtype=float)
    truths, eta_trues = np.asarray(truths, dtype=float), np.asarray(eta_trues, dtype=float)
    out = {}
    for m in models:
        j = MODELS.index(m)
        sites = list(THETA_NAMES) + (["sigma_s2"] if m != "volume" else [])
        mkeys = jax.vmap(lambda k: jax.random.fold_in(k, j))(keys)
        d = coverage.batched_posteriors(forward, m, ys, mkeys, config, SIGMA_V_ML, sites=sites, group_by_chain=True,
                                        conditions=cond_arg)
        ess, rhat = _diagnostics(d, sites)
        n = ys.shape[0]
        flat = {k: np.asarray(v).reshape(n, -1) for k, v in d.items()}
        th = np.stack([flat[k] for k in THETA_NAMES], axis=-1)  # (n, draws, 4)
        lo, hi = np.quantile(th, [0.05, 0.95], axis=1)
        cov = np.mean((lo <= truths) & (truths <= hi), axis=1)
        eta = np.asarray(eta_fn({k: flat[k] for k in THETA_NAMES}, conditions))
        err = np.median(np.abs(eta[:, :, 1:] - eta_trues[:, None, 1:]).mean(axis=2), axis=1)
        out[m] = {"coverage": cov, "output_error": err, "min_ess": ess,
                  **({"max_rhat": rhat} if rhat is not None else {}),
                  **({"sigma_s": np.median(np.sqrt(flat["sigma_s2"]), axis=1)} if m != "volume" else {})}
    return out


def _boot(values, stat=np.median, n_boot: int = 2000, seed: int = 0, level: float = 0.9) -> dict:
    return percentile_bootstrap(values, stat, n_boot=n_boot, seed=seed, level=level)


def summarise(fits_by_dose: dict, rms_by_dose: dict) -> list[dict]:
    """Per (source, dose): the bootstrap summaries of the pooled per-data-set metrics.

    ``output_error_gap``: the paired differences iid − discrepancy and
    iid − volume of each data set's output error (median, bootstrap CI):
    the F3 ordering appears when both CIs lie above 0. ``diagnostics``: per
    likelihood, the median and smallest per-data-set minimum bulk ESS and the
    share of data sets with R-hat > 1.05.
    """
    rows = []
    keys = ("coverage", "output_error", "sigma_s", "min_ess", "max_rhat")
    for (source, dose), per_vol in fits_by_dose.items():
        pool = {m: {k: [] for k in keys} for m in MODELS}
        for rec in per_vol.values():
            for m in MODELS:
                for k in keys:
                    pool[m][k].extend(rec[m].get(k, []))
        err = {m: np.asarray(pool[m]["output_error"], dtype=float) for m in MODELS}
        row = {"source": source, "dose": dose, "strain_rms_mismatch": rms_by_dose[(source, dose)],
               "n_datasets": int(err["iid"].size),
               "iid_sigma_s_inflation": _boot(np.asarray(pool["iid"]["sigma_s"]) / SIGMA_S),
               "discrepancy_sigma_s": _boot(pool["discrepancy"]["sigma_s"]),
               "output_error": {m: _boot(pool[m]["output_error"]) for m in MODELS},
               "output_error_gap": {"iid_minus_discrepancy": _boot(err["iid"] - err["discrepancy"]),
                                    "iid_minus_volume": _boot(err["iid"] - err["volume"])},
               "theta_coverage": {m: _boot(pool[m]["coverage"], stat=np.mean) for m in MODELS}}
        diag = {}
        for m in MODELS:
            ess, rhat = pool[m]["min_ess"], pool[m]["max_rhat"]
            if ess:
                diag[m] = {"min_ess_median": float(np.median(ess)), "min_ess_min": float(np.min(ess)),
                           "share_rhat_over_1_05": (float(np.mean(np.asarray(rhat) > 1.05)) if rhat else None)}
        if diag:
            row["diagnostics"] = diag
        row["per_volunteer"] = per_volunteer_values(per_vol, rms_by_dose[(source, dose)].get("by_volunteer"))
        gap = row["output_error_gap"]
        row["f1"] = bool(row["iid_sigma_s_inflation"]["value"] >= F1_INFLATION
                         and row["iid_sigma_s_inflation"]["ci"][0] > F1_CI_FLOOR)
        row["f3"] = bool(gap["iid_minus_discrepancy"]["ci"][0] > 0 and gap["iid_minus_volume"]["ci"][0] > 0)
        rows.append(row)
    rows.sort(key=lambda r: (SOURCES.index(r["source"]) if r["source"] in SOURCES else 99, r["dose"]))
    return rows


#: Per-data-set metrics shipped per volunteer (``row["per_volunteer"]``), rounded to this many significant digits.
PER_VOLUNTEER_DIGITS = 5


def _sig(values, digits: int = PER_VOLUNTEER_DIGITS) -> list:
    return [None if not np.isfinite(v) else float(f"{v:.{digits}g}") for v in np.asarray(values, dtype=float)]


def per_volunteer_values(per_vol: dict, rms_by_volunteer: dict | None = None) -> dict:
    """Each volunteer's per-data-set values at one dose, for a cluster bootstrap over volunteers.

    The volunteer is the independent unit: its noise seeds share one mismatch pattern, so a CI that resamples
    data sets covers the measurement noise around a few fixed patterns only. Per volunteer: ``strain_rms`` (the
    dose's size on that volunteer, when known), and per data set (lists over the noise seeds, same order):
    ``iid_sigma_s`` and ``discrepancy_sigma_s`` (posterior medians), ``output_error`` per likelihood, and
    ``max_rhat`` per likelihood (the largest split R-hat over θ and σ_S²; with one chain, of its two halves).
    """
    out = {}
    for vol, rec in sorted(per_vol.items()):
        v = {"strain_rms": (rms_by_volunteer or {}).get(vol),
             "iid_sigma_s": _sig(rec["iid"].get("sigma_s", [])),
             "discrepancy_sigma_s": _sig(rec["discrepancy"].get("sigma_s", [])),
             "output_error": {m: _sig(rec[m].get("output_error", [])) for m in MODELS},
             "max_rhat": {m: _sig(rec[m]["max_rhat"]) for m in MODELS if rec[m].get("max_rhat") is not None}}
        out[vol] = v
    return out


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


def budget_text(sampler: dict | None) -> str:
    """A sampler budget as ``chains × (warm-up + draws)``, e.g. ``2 × (300 + 300)``."""
    smp = sampler or {}
    return f"{smp.get('num_chains', '?')} × ({smp.get('num_warmup', '?')} + {smp.get('num_samples', '?')})"


def verdict_rows(result: dict) -> list[dict]:
    """The rows the findings are decided on: the main run's rows, with the rows of the convergence check
    (``result["check"]``: the same data sets refitted at a larger sampler budget, for the doses that decide the
    verdicts) in place of the main run's for those doses. Each row carries ``budget`` (its sampler budget, text)
    and ``checked`` (True when it comes from the check).
    """
    main = budget_text(result.get("sampler"))
    check = result.get("check") or {}
    by_dose = {(r["source"], r["dose"]): r for r in check.get("rows", [])}
    cb = budget_text(check.get("sampler"))
    return [({**by_dose[(r["source"], r["dose"])], "budget": cb, "checked": True}
             if (r["source"], r["dose"]) in by_dose else {**r, "budget": main, "checked": False})
            for r in result.get("rows", [])]


def strain_rms(z, nominal) -> float:
    """The size of a dose: RMS over the 24 strains of the mismatched minus the nominal outputs."""
    return float(np.sqrt(np.mean((np.asarray(z)[1:] - np.asarray(nominal)[1:]) ** 2)))


def measured_doses(sims: dict, volunteers, plan: dict) -> dict:
    """``(source, dose) -> {"mean", "min", "max", "n", "failed", "by_volunteer"}`` of the strain RMS over the
    volunteers (``by_volunteer``: volunteer name -> its strain RMS)."""
    out = {}
    for source, ds in plan.items():
        for dose in ds:
            vals, names, failed = [], [], 0
            for v in volunteers:
                nom, rec = sims.get(_key(v.name, None, 0.0)), sims.get(_key(v.name, source, dose))
                if nom and rec and nom["converged"] and rec["converged"]:
                    vals.append(strain_rms(rec["outputs"], nom["outputs"]))
                    names.append(v.name)
                else:
                    failed += 1
            out[(source, dose)] = ({"mean": float(np.mean(vals)), "min": float(np.min(vals)),
                                    "max": float(np.max(vals)), "n": len(vals), "failed": failed,
                                    "by_volunteer": dict(zip(names, map(float, vals)))} if vals
                                   else {"mean": None, "min": None, "max": None, "n": 0, "failed": failed})
    return out


#: Data sets per compiled MCMC batch: every batch has this size (the last is padded), so one program serves all.
BATCH = 40


def fit_cost(costs: Sequence[dict]) -> dict | None:
    """The CPU cost of the MCMC batches behind some fits, from each fit's ``batch_cost`` record.

    ``costs``: one record per (volunteer, source, dose) fit, ``{"cpu_s", "wall_s", "datasets", "units"}`` of the
    batch it came from (a batch of ``units`` fits records the same cost in each). Returns ``cpu_s`` (the sum over
    batches, compilation and padding included), ``batches``, and the median CPU seconds per data set (the three
    likelihoods together) over the batches; None when no fit records its cost (fits of an older run).
    """
    if not costs:
        return None
    share = [c["cpu_s"] / c["units"] for c in costs]
    per_set = [c["cpu_s"] / c["datasets"] for c in costs]
    return {"cpu_s": float(np.sum(share)), "batches": float(np.sum([1.0 / c["units"] for c in costs])),
            "fits_with_cost": len(costs), "cpu_s_per_dataset_median": float(np.median(per_set)),
            "cpu_s_per_dataset_range": [float(np.min(per_set)), float(np.max(per_set))]}


def run_study(*, sources: Sequence[str] = SOURCES, doses: dict | None = None, volunteers: Sequence[str] | None = None,
              seeds: int = 20, config=None, seed: int = 0, resolution: str = "default", emulator: str = "chapter",
              workers: int = 1, scheduler: str | None = None, out: str | Path = "study_mismatch",
              progress: Callable | None = None, retry_failed: bool = False, simulate_only: bool = False,
              batch: int = BATCH, recorded_only: bool = False, result_file: str = "mismatch.json") -> dict:
    """Run (or resume) the study under ``out``; returns the result (also written to ``out/<result_file>``).

    Every data set of every volunteer and dose goes through one compiled
    sampler per likelihood, in batches of ``batch`` data sets (the
    volunteers' PC scores are run-time arguments); each (volunteer, source,
    dose)'s fits are written as soon as its batch finishes. With
    ``simulate_only`` only the simulations run and the measured strain RMS
    of each dose is returned (``doses_measured``) and written to ``out/doses.json``.
    With ``recorded_only`` no new fits start: the result summarises the doses
    whose fits are recorded and lists the others under ``not_fitted``.
    ``fit_cost`` sums the CPU seconds of the MCMC batches behind the fits
    (each fit file records its batch's cost; a padded batch counts in full).
    """
    from lvcore.emulator.forward import emulator_forward
    from lvcore.emulator.io import load_emulator
    from lvcore.inference import samplers

    t0 = time.perf_counter()
    out = Path(out)
    # Algorithm 4 as the chapter writes it, whatever the caller's config: the shipped results were made with it,
    # and a resumed study must not mix samplers (its recorded fits are keyed by budget, not by sampler)
    config = dataclasses.replace(config or samplers.SamplerConfig(), discrepancy_block="chapter")
    plan = {s: tuple(float(d) for d in (doses or {}).get(s, DEFAULT_DOSES[s])) for s in sources}
    bad = sorted(set(plan) - set(SOURCES))
    if bad:
        raise ValueError(f"unknown mismatch source(s) {bad}; choose from {SOURCES}")
    vols = bundled_volunteers(volunteers)
    sims = simulate_all(vols, plan, out, resolution=resolution, workers=workers, scheduler=scheduler,
                        progress=progress, retry_failed=retry_failed)
    t_sim = time.perf_counter() - t0
    rms = measured_doses(sims, vols, plan)
    measured = [{"source": s, "dose": d, "strain_rms_mismatch": r} for (s, d), r in rms.items()]
    if simulate_only:
        res = {"study": "mismatch", "synthetic": True, "volunteers": [v.name for v in vols], "resolution": resolution,
               "doses_measured": measured, "timings_s": {"simulate": t_sim}}
        write_json_atomic(out / "doses.json", clean(res))
        return res
    fits, failed, todo = {}, [], []
    tag = f"s{seeds}_w{config.num_warmup}_n{config.num_samples}_c{config.num_chains}"
    for v in vols:
        nominal = sims[_key(v.name, None, 0.0)]
        if not nominal["converged"]:
            failed.append({"key": _key(v.name, None, 0.0), "reason": nominal["reason"]})
            continue
        for source, ds in plan.items():
            for dose in ds:
                key = _key(v.name, source, dose)
                rec = sims[key]
                if not rec["converged"]:
                    failed.append({"key": key, "reason": rec["reason"]})
                    continue
                path = out / "fits" / f"{key}__{tag}.json"
                if path.is_file():
                    fits.setdefault((source, dose), {})[v.name] = json.loads(path.read_text())
                else:
                    todo.append((v, source, dose, key, np.asarray(rec["outputs"], dtype=float)))
    not_fitted = [{"volunteer": u[0].name, "source": u[1], "dose": u[2]} for u in todo] if recorded_only else []
    if todo and not recorded_only:
        import jax

        emu = load_emulator(emulator)
        fwd = {v.name: emulator_forward(emu, v.h, name=emulator) for v in vols}
        cond = {n: np.asarray(samplers.runtime_conditions(f)[1]["conditions"]) for n, f in fwd.items()}
        per = max(1, batch // seeds)  # (volunteer, source, dose) units per batch
        for b in range(0, len(todo), per):
            units = todo[b:b + per]
            padded = units + [units[0]] * (per - len(units))  # same shape every batch: no recompilation
            ys, cs, th, et, ks = [], [], [], [], []
            for v, source, dose, key, z in padded:
                us = unit_seed(key, seed)
                ys.append(noisy_copies(z, seeds, us))
                cs.append(np.repeat(cond[v.name][None, :], seeds, axis=0))
                th.append(np.repeat(np.array([[v.theta[n] for n in THETA_NAMES]]), seeds, axis=0))
                et.append(np.repeat(np.asarray(fwd[v.name](v.theta), dtype=float)[None, :], seeds, axis=0))
                ks.append(jax.random.split(jax.random.PRNGKey(us), seeds))
            if progress:
                progress(f"calibrating {', '.join(u[3] for u in units)}: {len(units) * seeds} data sets x "
                         f"{len(MODELS)} likelihoods ({b + len(units)}/{len(todo)})")
            cpu0, wall0 = time.process_time(), time.perf_counter()
            res = fit_datasets(fwd[vols[0].name], np.concatenate(ys), np.concatenate(cs), np.concatenate(th),
                               np.concatenate(et), config=config, keys=np.concatenate(ks))
            cost = {"cpu_s": time.process_time() - cpu0, "wall_s": time.perf_counter() - wall0,
                    "datasets": len(padded) * seeds, "units": len(units)}
            if progress:
                progress(f"  batch done: {cost['cpu_s']:.0f} CPU-s, {cost['wall_s']:.0f} s wall for "
                         f"{cost['datasets']} data sets x {len(MODELS)} likelihoods")
            for i, (v, source, dose, key, _) in enumerate(units):
                sl = slice(i * seeds, (i + 1) * seeds)
                fit = clean({**{m: {k: np.asarray(a)[sl] for k, a in r.items()} for m, r in res.items()},
                             "batch_cost": cost})
                write_json_atomic(out / "fits" / f"{key}__{tag}.json", fit)
                fits.setdefault((source, dose), {})[v.name] = fit
    t_fit = time.perf_counter() - t0 - t_sim
    rows = summarise({k: fits[k] for k in rms if k in fits}, rms)
    costs = [f["batch_cost"] for per in fits.values() for f in per.values() if "batch_cost" in f]
    result = {
        "study": "mismatch", "synthetic": True,
        "emulator": emulator, "resolution": resolution,
        "model_conditions": {"angles": list(MODEL_ANGLES), "base": MODEL_BASE},
        "volunteers": [v.name for v in vols], "seeds_per_dose": seeds,
        "doses": {s: list(d) for s, d in plan.items()},
        "doses_measured": measured,
        "sampler": {"num_warmup": config.num_warmup, "num_samples": config.num_samples,
                    "num_chains": config.num_chains, "batch": batch},
        "noise": {"sigma_v_ml": SIGMA_V_ML, "sigma_s": SIGMA_S},
        "rows": rows, "appearance": appearance(rows), "failed": failed, "not_fitted": not_fitted,
        "complete": not not_fitted and not failed,
        "timings_s": {"simulate": t_sim, "calibrate": t_fit, "total": time.perf_counter() - t0},
        "fit_cost": fit_cost(costs),
    }
    write_json_atomic(out / result_file, clean(result))
    return result


# ----------------------------------------------------------------------------
# results: load, tables, figures (the Studies page, lvcore report and the docs read these)
# ----------------------------------------------------------------------------
#: Result file of :func:`run_study` (and the shipped ``assets/studies/mismatch.json``), read by :func:`load`.
RESULT_FILE = "mismatch.json"
#: The command that makes the results.
COMMAND = "python scripts/ship_mismatch.py (or lvcore study mismatch --out RESULTS)"
#: Figures and tables :func:`figures` draws, with their titles.
TITLES = {"fig_mismatch_sigma_s_inflation": "Mismatch dose–response: iid σ_S inflation vs strain RMS mismatch",
          "fig_mismatch_discrepancy_sigma_s": "Mismatch dose–response: the discrepancy model's σ_S vs mismatch",
          "fig_mismatch_output_error": "Mismatch dose–response: output error per likelihood vs dose",
          "table_mismatch_doses": "Mismatch dose–response: per source and dose, with 90 % bootstrap CIs"}
#: Why a figure can be missing.
MISSING = {n: "the results hold no fitted doses (a --simulate-only run)" for n in TITLES}
#: Display names of the sources.
SOURCE_LABELS = {"angles": "fibre angles (°)", "base": "clamped base", "sheet": "sheet terms (× as, afs)",
                 "dispersion": "dispersion κ", "heterogeneity": "heterogeneity (log-sd)",
                 "pericardium": "pericardium k (kPa/mm)"}


def load(folder) -> dict:
    """The results of a mismatch ``--out`` folder (or the bundled one): ``mismatch.json`` plus ``folder``."""
    from lvcore.studies.results import read_json

    data = read_json(Path(folder) / RESULT_FILE)
    if not isinstance(data, dict) or data.get("study") != "mismatch" or "rows" not in data:
        raise ValueError(f"{Path(folder) / RESULT_FILE} is not the output of lvcore study mismatch")
    data["folder"] = str(folder)
    return data


def _sampler_text(result: dict) -> str:
    smp = result.get("sampler") or {}
    return (f"{smp.get('num_chains', '?')} chain(s) × ({smp.get('num_warmup', '?')} warm-up + "
            f"{smp.get('num_samples', '?')} draws)")


def source_line(result: dict) -> str:
    """Where the numbers come from, as one readable line."""
    from lvcore.studies.results import source_label

    vols = result.get("volunteers", [])
    return (f"{RESULT_FILE} ({source_label(result['folder'])}); SYNTHETIC data from the FE simulator "
            f"({result.get('resolution', '?')} mesh), {len(vols)} volunteer(s) ({', '.join(vols)}) × "
            f"{result.get('seeds_per_dose', '?')} noise seeds per dose; calibrated on the "
            f"{result.get('emulator', '?')} emulator; sampler {_sampler_text(result)}")


def _dose_label(source: str, dose: float) -> str:
    return "clamped base" if source == "base" else f"{source} {dose:g}"


def tables(result: dict) -> dict:
    """The data behind each figure (by figure name): one row per (source, dose[, likelihood])."""
    import pandas as pd

    rows = result.get("rows", [])
    if not rows:
        return {}
    infl, disc, err, flat = [], [], [], []
    for r in rows:
        x = r["strain_rms_mismatch"]["mean"]
        base = {"panel": SOURCE_LABELS.get(r["source"], r["source"]), "source": r["source"], "dose": r["dose"],
                "x": x, "label": _dose_label(r["source"], r["dose"])}
        i, d = r["iid_sigma_s_inflation"], r["discrepancy_sigma_s"]
        infl.append({**base, "series": SOURCE_LABELS.get(r["source"], r["source"]), "value": i["value"],
                     "lo": i["ci"][0], "hi": i["ci"][1]})
        disc.append({**base, "series": SOURCE_LABELS.get(r["source"], r["source"]), "value": d["value"],
                     "lo": d["ci"][0], "hi": d["ci"][1]})
        for m in MODELS:
            e = r["output_error"][m]
            err.append({**base, "series": m, "value": e["value"], "lo": e["ci"][0], "hi": e["ci"][1]})
        c = r["theta_coverage"]
        flat.append({"source": r["source"], "dose": r["dose"], "strain RMS": x,
                     "data sets": r.get("n_datasets", i["n"]),
                     "iid σ_S/0.03": i["value"], "iid CI": f"[{i['ci'][0]:.2f}, {i['ci'][1]:.2f}]",
                     "discrepancy σ_S": d["value"], "disc. CI": f"[{d['ci'][0]:.3f}, {d['ci'][1]:.3f}]",
                     **{f"error {m}": r["output_error"][m]["value"] for m in MODELS},
                     **{f"coverage {m}": c[m]["value"] for m in MODELS},
                     "F1": r["f1"], "F3": r["f3"]})
    return {"fig_mismatch_sigma_s_inflation": pd.DataFrame(infl),
            "fig_mismatch_discrepancy_sigma_s": pd.DataFrame(disc),
            "fig_mismatch_output_error": pd.DataFrame(err),
            "table_mismatch_doses": pd.DataFrame(flat)}


def figures(result: dict) -> dict:
    """The study's figures by name (see :data:`TITLES`); none when the results hold no fitted doses."""
    from lvcore.viz.report_figures import table_figure
    from lvcore.viz.study_figures import dose_response_figure

    tabs = tables(result)
    if not tabs:
        return {}
    n = f"{len(result.get('volunteers', []))} volunteer(s) × {result.get('seeds_per_dose')} seeds per dose"
    xt = "strain RMS mismatch of the dose (mismatched − nominal simulator outputs, 24 strains)"
    out = {"fig_mismatch_sigma_s_inflation": dose_response_figure(
        tabs["fig_mismatch_sigma_s_inflation"].to_dict("records"),
        title=f"SYNTHETIC mismatch dose–response ({n}): iid posterior median σ_S / 0.03, median over data sets, "
              "90 % bootstrap CI band; F1 (chapter) ≈ 2×",
        xaxis_title=xt, yaxis_title="iid σ_S inflation (σ_S / 0.03)", refs=((1.0, "no inflation"),
                                                                            (2.0, "chapter ≈ 2×")))}
    out["fig_mismatch_discrepancy_sigma_s"] = dose_response_figure(
        tabs["fig_mismatch_discrepancy_sigma_s"].to_dict("records"),
        title=f"SYNTHETIC mismatch dose–response ({n}): discrepancy model's posterior median σ_S, 90 % bootstrap "
              "CI band; truth 0.03, chapter 0.024 (F2)",
        xaxis_title=xt, yaxis_title="discrepancy σ_S (strain)", refs=((SIGMA_S, "truth 0.03"),))
    panels = list(dict.fromkeys(tabs["fig_mismatch_output_error"]["panel"]))
    out["fig_mismatch_output_error"] = dose_response_figure(
        tabs["fig_mismatch_output_error"].to_dict("records"), panels=panels,
        title=f"SYNTHETIC mismatch dose–response ({n}): output error |η(θ_post, h) − η(θ̃, h)| per likelihood, "
              "median over data sets, 90 % bootstrap CI band (F3: discrepancy ≈ volume < iid)",
        xaxis_title="strain RMS mismatch", yaxis_title="output error (strain)")
    out["table_mismatch_doses"] = table_figure(tabs["table_mismatch_doses"],
                                               title=f"SYNTHETIC mismatch study ({n}): per source and dose")
    return out


#: Markers of the block of docs/studies.md written by :func:`docs_markdown` (a test compares the two).
DOCS_BEGIN = "<!-- mismatch shipped numbers: begin (generated by lvcore.studies.mismatch.docs_markdown) -->"
DOCS_END = "<!-- mismatch shipped numbers: end -->"


def _ci(b: dict, fmt: str = ".2f") -> str:
    return f"{b['value']:{fmt}} [{b['ci'][0]:{fmt}}, {b['ci'][1]:{fmt}}]"


def _dose_cell(row: dict) -> str:
    return f"{row['dose']:g}" + (" †" if row.get("carried_over") else "")


def _cost_text(cost: dict | None) -> str:
    if not cost:
        return "cost not recorded"
    lo, hi = cost["cpu_s_per_dataset_range"]
    return (f"MCMC of the {cost['fits_with_cost']} dose fits recorded in the work folder: {cost['cpu_s'] / 60:.1f} "
            f"CPU-min in {cost['batches']:.0f} batches (compilation and padding included), median {cost['cpu_s_per_dataset_median']:.2f} CPU-s per data set × 3 likelihoods "
            f"[{lo:.2f}, {hi:.2f}]")


def _diag_cell(d: dict, key: str, fmt: str) -> str:
    return " / ".join("—" if d.get(m, {}).get(key) is None else fmt.format(d[m][key]) for m in MODELS)


def _check_markdown(result: dict) -> list[str]:
    """The convergence check's block of :func:`docs_markdown`: each checked dose at both budgets."""
    check = result.get("check")
    if not check:
        return []
    if not check.get("rows"):
        return ["", f"**Convergence check** ({budget_text(check.get('sampler'))} on "
                + ", ".join(_dose_label(u["source"], u["dose"]) for u in check.get("not_fitted", []))
                + "): not fitted in this shipped run; the findings use the main run's budget."]
    main = {(r["source"], r["dose"]): r for r in result["rows"]}
    lines = ["", f"**Convergence check.** The doses that decide the verdicts, refitted on the same data sets (same "
             f"noise seeds) with {budget_text(check.get('sampler'))} instead of "
             f"{budget_text(result.get('sampler'))}; the findings below use these rows "
             f"(`lvcore.studies.mismatch.verdict_rows`). MCMC: {_cost_text(check.get('fit_cost'))}."
             + (" Not fitted: " + ", ".join(_dose_label(u["source"], u["dose"]) for u in check["not_fitted"]) + "."
                if check.get("not_fitted") else ""), "",
             "| source | dose | sampler | iid σ_S / 0.03 [90 % CI] | discrepancy σ_S [90 % CI] | "
             "iid − discrepancy error [90 % CI] | iid − volume error [90 % CI] | ESS median | "
             "share R-hat > 1.05 | F1 | F3 |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    yes = {True: "yes", False: "no"}
    for c in check["rows"]:
        for r, smp in ((main.get((c["source"], c["dose"])), result.get("sampler")), (c, check.get("sampler"))):
            if r is None:
                continue
            g, d = r["output_error_gap"], r.get("diagnostics", {})
            lines.append(f"| {r['source']} | {r['dose']:g} | {budget_text(smp)} | {_ci(r['iid_sigma_s_inflation'])} | "
                         f"{_ci(r['discrepancy_sigma_s'], '.4f')} | {_ci(g['iid_minus_discrepancy'], '.4f')} | "
                         f"{_ci(g['iid_minus_volume'], '.4f')} | {_diag_cell(d, 'min_ess_median', '{:.0f}')} | "
                         f"{_diag_cell(d, 'share_rhat_over_1_05', '{:.2f}')} | {yes[r['f1']]} | {yes[r['f3']]} |")
    return lines


def docs_markdown(result: dict) -> str:
    """The docs' text of a shipped result: the run, the dose table, and the per-dose metrics with CIs.

    docs/studies.md quotes the shipped run through this text only (between
    :data:`DOCS_BEGIN` and :data:`DOCS_END`); a test checks it equals this
    function's output for the shipped JSON. The findings table with verdicts
    is :func:`lvcore.studies.findings.docs_markdown`.
    """
    shipped = result.get("shipped", {})
    lines = [f"Shipped run: {len(result['volunteers'])} SYNTHETIC volunteer(s) ({', '.join(result['volunteers'])}) × "
             f"{result['seeds_per_dose']} noise seeds per dose, {result.get('resolution')} mesh, "
             f"{result.get('emulator')} emulator, sampler {_sampler_text(result)} per data set; "
             f"{sum(r.get('n_datasets', 0) for r in result['rows'])} data sets × 3 likelihoods fitted"
             + (f" ({_cost_text(result['fit_cost'])})" if result.get("fit_cost") else "")
             + (f" (shipped by `{shipped['command']}`, {shipped.get('date', '')}; the run's cost is in "
                "BENCHMARKS.md)" if shipped.get("command") else "") + "."]
    co = result.get("carried_over")
    if co:
        lines += ["", f"**Carried over (†):** {len(co['doses'])} doses (" + ", ".join(
            _dose_label(d["source"], d["dose"]) for d in co["doses"]) + f") are the rows of the {co.get('date')} "
            f"run of the same design (`{co.get('command')}`), not refitted in this one; a dose's data sets and chain "
            "seeds depend only on its key, so a full run of the "
            "command above recomputes the same data sets."]
    nf = result.get("not_fitted") or []
    if nf:
        lines += ["", f"**Incomplete:** {len(nf)} (volunteer, source, dose) of the planned run are not fitted in "
                  "this shipped run (" + ", ".join(f"{u['source']} {u['dose']:g}" for u in nf) + "); the same "
                  "command without `--recorded-only` (and `--carry-from`) resumes the study and fits them."]
    lines += ["",
             "| source | dose | strain RMS mismatch (mean [min, max] over volunteers) | iid σ_S / 0.03 [90 % CI] | "
             "discrepancy σ_S [90 % CI] | output error volume / iid / discrepancy | "
             "iid − discrepancy error [90 % CI] | θ coverage volume / iid / discrepancy | F1 | F3 |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    yes = {True: "yes", False: "no"}
    for r in result["rows"]:
        m, e, c = r["strain_rms_mismatch"], r["output_error"], r["theta_coverage"]
        lines.append(f"| {r['source']} | {_dose_cell(r)} | {m['mean']:.4f} [{m['min']:.4f}, {m['max']:.4f}] | "
                     f"{_ci(r['iid_sigma_s_inflation'])} | {_ci(r['discrepancy_sigma_s'], '.4f')} | "
                     + " / ".join(f"{e[k]['value']:.4f}" for k in MODELS) + " | "
                     f"{_ci(r['output_error_gap']['iid_minus_discrepancy'], '.4f')} | "
                     + " / ".join(f"{c[k]['value']:.2f}" for k in MODELS) + f" | {yes[r['f1']]} | {yes[r['f3']]} |")
    if any("diagnostics" in r for r in result["rows"]):
        lines += ["", "Sampler checks per dose (ArviZ; per data set the smallest bulk ESS over θ and σ_S², and the "
                  "largest split R-hat): median over data sets of that ESS, its minimum, and the share of data sets "
                  "with R-hat > 1.05, volume / iid / discrepancy.", "",
                  "| source | dose | ESS, median | ESS, minimum | share R-hat > 1.05 |", "|---|---|---|---|---|"]
        for r in result["rows"]:
            d = r.get("diagnostics", {})
            cell = [" / ".join(("—" if d.get(m, {}).get(k) is None else f.format(d[m][k])) for m in MODELS)
                    for k, f in (("min_ess_median", "{:.0f}"), ("min_ess_min", "{:.0f}"),
                                 ("share_rhat_over_1_05", "{:.2f}"))]
            lines.append(f"| {r['source']} | {_dose_cell(r)} | {cell[0]} | {cell[1]} | {cell[2]} |")
    lines += _check_markdown(result)
    lines += ["", "| source | F1 appears (dose, strain RMS) | F3 ordering appears (dose, strain RMS) |", "|---|---|---|"]
    for source, a in result["appearance"].items():
        cell = [x if isinstance(x, str) else f"dose {x['dose']:g}, RMS {x['strain_rms']:.4f}"
                for x in (a["f1"], a["f3"])]
        lines.append(f"| {source} | {cell[0]} | {cell[1]} |")
    return "\n".join(lines)


# ----------------------------------------------------------------------------
# CLI
# ----------------------------------------------------------------------------
def add_study_parser(study_subparsers) -> None:
    """``lvcore study mismatch``."""
    p = study_subparsers.add_parser("mismatch", help="model-data mismatch as a dose-response: sigma_S "
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
    p.add_argument("--simulate-only", action="store_true",
                   help="only simulate and print the measured strain RMS of each dose (OUT/doses.json); no fits")
    p.add_argument("--recorded-only", action="store_true",
                   help="start no new fits: summarise the recorded ones and list the rest as not fitted")
    p.add_argument("--batch", type=int, default=BATCH,
                   help=f"data sets per compiled MCMC batch (default {BATCH}; the last batch is padded)")
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
    for opt, val in (("--seeds", args.seeds), ("--warmup", args.warmup), ("--samples", args.samples),
                     ("--chains", args.chains), ("--batch", args.batch), ("--workers", args.workers)):
        if val < 1:
            print(f"lvcore study mismatch: {opt} {val}: give a positive integer", file=sys.stderr)
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
                    simulate_only=args.simulate_only, batch=args.batch, recorded_only=args.recorded_only,
                    progress=None if args.json else (lambda msg: print(msg, flush=True)))
    if args.simulate_only:
        for r in res["doses_measured"]:
            m = r["strain_rms_mismatch"]
            size = "all failed" if m["mean"] is None else f"{m['mean']:.4f} [{m['min']:.4f}, {m['max']:.4f}]"
            print(f"{r['source']:>14} {r['dose']:>8g}  strain RMS {size}  ({m['n']} ok, {m['failed']} failed)")
        print(f"wrote {args.out}/doses.json")
        return 0
    brief = {"appearance": res["appearance"], "failed": res["failed"], "timings_s": res["timings_s"]}
    print(json.dumps(brief, indent=2))
    if not args.json:
        print(f"wrote {args.out}/mismatch.json")
    return 0


__all__ = ["SOURCES", "DEFAULT_DOSES", "mismatch_case", "bundled_volunteers", "simulate_all", "fit_datasets", "run_study",
           "summarise", "per_volunteer_values", "appearance", "measured_doses", "strain_rms", "RESULT_FILE", "COMMAND", "TITLES", "load",
           "source_line", "tables", "figures", "docs_markdown", "DOCS_BEGIN", "DOCS_END"]
