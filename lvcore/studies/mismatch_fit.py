"""The mismatch study's fits and their summary: noisy data sets per dose, the three likelihoods' calibrations in
one compiled sampler, the sampler diagnostics, and the per-dose bootstrap summaries (F1 and the F3 ordering).

Part of :mod:`lvcore.studies.mismatch` (the study).
"""
from __future__ import annotations

import zlib
from typing import Sequence

import numpy as np

from lvcore.domain.conditions import SIGMA_S, SIGMA_V_ML
from lvcore.domain.outputs import THETA_NAMES
from lvcore.studies._common import percentile_bootstrap
from lvcore.studies.mismatch_sim import SOURCES

MODELS = ("volume", "iid", "discrepancy")
#: F1 "appears": median iid inflation at least this, with the bootstrap CI's lower end above F1_CI_FLOOR.
F1_INFLATION, F1_CI_FLOOR = 1.5, 1.2


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


def sampler_text(result: dict) -> str:
    """A result's sampler as ``chains chain(s) × (warm-up warm-up + draws draws)``."""
    smp = result.get("sampler") or {}
    return (f"{smp.get('num_chains', '?')} chain(s) × ({smp.get('num_warmup', '?')} warm-up + "
            f"{smp.get('num_samples', '?')} draws)")


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


def promote_check(result: dict) -> dict:
    """``result`` with its convergence check as the study's run, when the check refitted every dose of the main
    run on the same data sets: the check's rows, sampler, appearance, cost and gaps replace the main run's, and the
    main run is dropped, its budget and worst split R-hat share kept under ``superseded``. So every shipped fit has
    the check's chains. A result without a complete check is returned unchanged.
    """
    check = result.get("check") or {}
    main = {(r["source"], r["dose"]) for r in result.get("rows", [])}
    if not check.get("rows") or main - {(r["source"], r["dose"]) for r in check["rows"]}:
        return result
    shares = [d.get("share_rhat_over_1_05") for r in result["rows"] for d in (r.get("diagnostics") or {}).values()]
    shares = [x for x in shares if x is not None]
    out = {k: v for k, v in result.items() if k not in ("check", "carried_over")}
    out.update(rows=check["rows"], sampler=check["sampler"], doses=check.get("doses", result.get("doses")),
               appearance=check.get("appearance", result.get("appearance")), fit_cost=check.get("fit_cost"),
               failed=check.get("failed", []), not_fitted=check.get("not_fitted", []),
               complete=not check.get("failed") and not check.get("not_fitted"),
               superseded={"sampler": result.get("sampler"), "rows": len(result.get("rows", [])),
                           "max_share_rhat_over_1_05": max(shares) if shares else None,
                           "why": "every dose was refitted on the same data sets at the check's budget"})
    return out


def verdict_rows_by_dose(result: dict) -> dict:
    """:func:`verdict_rows` keyed by ``(source, dose)``."""
    return {(r["source"], r["dose"]): r for r in verdict_rows(result)}


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


__all__ = ["MODELS", "F1_INFLATION", "F1_CI_FLOOR", "unit_seed", "noisy_copies", "fit_datasets", "summarise",
           "PER_VOLUNTEER_DIGITS", "per_volunteer_values", "appearance", "sampler_text", "budget_text",
           "verdict_rows", "verdict_rows_by_dose", "promote_check", "BATCH", "fit_cost"]
