r"""Simulation-based calibration (Talts et al. 2018) of the whole calibration pipeline: ``lvcore study sbc``.

If data are simulated from parameters drawn from the prior, and the posterior
is computed correctly, the rank of the true value among L posterior draws is
uniform on ``{0, ..., L}``. This study checks that for the pipeline a user
runs, end to end, on SYNTHETIC subjects:

* **Subjects** (SYNTHETIC, from ``--seed``): θ = (a, b, af, bf) from the
  calibration prior (uniform on :data:`lvcore.core.space.THETA_BOUNDS`); the
  geometry from the bundled shape model, PC scores ``h ~ N(0, 1)`` truncated
  to ±2 (5 scores, the ``chapter`` emulator's box) and a scale ``s`` such that
  the reference cavity ``V_ref = s³ V_cav(h)`` is log-uniform in 40–200 mL;
  the ``chapter`` emulator's training conditions (EDP 8 mmHg, fibre angles
  −60°/60°, sliding base, ``default`` mesh). The EDP is fixed at 8 mmHg: the
  ``chapter`` emulator is trained at 8 mmHg only, so an EDP range of 4–20
  mmHg could not be drawn.
* **Truth by the FE simulator** (not the emulator): the data (LVV × s³ and the
  24 strains at 8 mmHg) by :func:`lvcore.mechanics.simulate.simulate`, the
  EDPVR (V0, V20, V30) by :func:`lvcore.inference.derived.fe_load_path`, the
  fibre stress at the fixed stretch 1.10 by
  :func:`lvcore.mechanics.stress.ho_fibre_stress`. A prior draw whose FE solve
  fails is redrawn (counted). Noise: σ_V = 5 mL on the LVV, σ_S = 0.03 on each
  strain, iid Gaussian.
* **Two routes through** ``lvcore calibrate`` (model iid, 2 chains,
  ``--derived-draws D``), in-process: ``mesh`` gives the subject's template
  mesh (the shape at scale s, a ``.vtu``; the command size-normalises and
  projects it), ``infer`` gives ``--geometry infer --reference-volume V`` with
  ``V = V_ref + N(0, 5 mL)``. The study layer may not import ``lvcore.cli``
  (the layers contract), so the sub-command runs through its own parser and
  handler (:mod:`lvcore.inference.cli`) with ``lvcore.cli.main``'s mapping of
  exceptions to exit codes (:func:`calibrate_in_process`; a test checks both
  agree).
* **Statistics** per route and quantity: the rank of the truth among the draws
  (draws below the truth; ties broken at random): a, b, af, bf and the fibre
  stress among L = 100 evenly thinned posterior draws (the stress is the HO
  law's closed form of each θ draw), V0, V20, V30 among the D derived FE
  draws (``*_derived.npz``, ``--derived-pressures 20,30``: the FE solves the
  ranks need; failed solves left out). A 10-bin rank histogram
  with the χ² test of uniformity (expected counts exact for each subject's
  L; no p-value below 5 expected per bin, i.e. under 50 subjects); the
  empirical coverage of the central 50 % and 90 % intervals from the ranks
  (inside when ``(rank + 0.5)/(L + 1)`` lies in ``[(1 − level)/2,
  1 − (1 − level)/2]``) with a Wilson 95 % CI, and beside it the coverage a
  perfectly calibrated posterior gets with the same L (``nominal_*_at_L``: for
  L = 20 it is 90.5 % and 52.4 %, not 90 % and 50 %); for V20 and V30 the
  median over subjects of ``(q95 − q05)/truth``; for V0, V20, V30 the median
  over subjects of ``|median − truth|/truth``. Runs exiting 0 (fine) or 4
  (ran, results flagged) enter the statistics (``all_runs``: every run that
  left a posterior, exit 1 included); the share exiting 4 and the flag kinds
  are reported, other exit codes are counted with their reason.

**Resumable, in pieces.** ``lvcore study sbc --piece K/N`` (or ``--start``/
``--stop``) writes one JSON line per finished subject to
``WORKDIR/subjects_<start>-<stop>.jsonl``; a rerun skips finished subjects (a
killed run loses the subject in flight; a half-written last line is cut off).
Two pieces run at the same time in two processes. Subject ``i``'s draws depend
only on ``(seed, i)``. ``lvcore study sbc --summarise --workdir W --out
DIR/<result file>`` builds the result from whatever is finished
(:func:`summarise`), with the per-subject records in the JSON and in
``sbc_subjects.csv`` beside it.

Caveats the numbers carry: the geometry of the draws is not the ``infer``
route's prior (its scale is log-uniform on 0.5–1.8, here V_ref is
log-uniform on 40–200 mL), the shape-model subjects get the default
representation-error floor (extra variance for a shape the model
represents exactly), and the emulator differs from the FE truth; SBC
measures the pipeline with all of these, as a user runs it. In the ``mesh``
route V0 is fixed by the given mesh (no posterior spread), so its rank is 0
or D and its coverage is near 0 however small the error; the median relative
error of V0, V20 and V30 (``median_abs_rel_error``) says how far off they are.

**Modules.** This one holds the summary (:data:`RESULT_FILE`), the saved results'
tables and figures and the command line; the rank statistics (pure) are in
:mod:`lvcore.studies.sbc_stats`, the design, the subjects, the routes through
``lvcore calibrate`` and the resumable work folder in
:mod:`lvcore.studies.sbc_runner`. Their names are importable from here too.
"""
from __future__ import annotations

import json
import os
import platform
import sys
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from lvcore import cli_args
from lvcore.domain.conditions import SIGMA_S, SIGMA_V_ML
from lvcore.exceptions import LVCoreError
from lvcore.domain.outputs import DISPLAY_NAMES
from lvcore.studies import registry
from lvcore.studies._common import add_sampler_options, clean, round_floats, write_json_atomic
# the statistics (pure) and the runs live in their own modules; their names are this module's too
from lvcore.studies.sbc_runner import (ANGLES, BASE, CLI_DERIVED_PRESSURES_MMHG, DEFAULT_CHAINS,  # noqa: F401
                                       DEFAULT_DERIVED_DRAWS, DEFAULT_N_SUBJECTS, DEFAULT_SAMPLES, DEFAULT_THIN,
                                       DEFAULT_WARMUP, DEFAULT_WORKDIR, DERIVED_PRESSURES_MMHG, DERIVED_QUANTITIES,
                                       EDP_MMHG, EDP_NOTE, EMULATOR, H_TRUNCATION, MAX_REDRAWS, MODEL, N_PC,
                                       QUANTITIES, RECORD_VERSION, REFERENCE_VOLUME_SD_ML, RESOLUTION, ROUTES,
                                       STRESS_STRETCH, V_REF_RANGE_ML, WIDTH_QUANTITIES, Store, TruthFailure,
                                       calibrate_argv, calibrate_in_process, calibration_seed,
                                       check_emulator_conditions, default_settings, fibre_stress, first_solvable_draw,
                                       flag_kind, make_subject, noise_draw, piece_range, prior_draw, read_route_outputs,
                                       route_ranks, run_piece, run_route, run_subject, settings_key,
                                       simulate_truth, subject_name, write_subject_files)
from lvcore.studies.sbc_stats import (BAND_LEVEL, CI_LEVEL, LEVELS, MIN_EXPECTED_PER_BIN, N_BINS,  # noqa: F401
                                      inside_central, nominal_coverage, pit, quantity_summary, rank_chi2,
                                      rank_histogram, rank_of_truth, uniform_band, wilson_interval)

#: Result file of :func:`summarise` (the shipped run's is under ``assets/studies/``), read by :func:`load`.
RESULT_FILE = registry.result_file("sbc")
#: Per-subject records beside it.
SUBJECTS_FILE = "sbc_subjects.csv"
#: The commands that make the results (two pieces on two cores, then the summary).
COMMAND = ("lvcore study sbc --n-subjects 200 --seed 0 --piece 1/2 & lvcore study sbc --n-subjects 200 --seed 0 "
           f"--piece 2/2; lvcore study sbc --summarise --out DIR/{RESULT_FILE}")
UNITS = {"a": "kPa", "b": "-", "af": "kPa", "bf": "-", "V0": "mL", "V20": "mL", "V30": "mL", "fibre_stress": "kPa"}
LABELS = {**{q: DISPLAY_NAMES.get(q, q) for q in UNITS}, "fibre_stress": "σ_ff(λ=1.10)"}
SYNTHETIC_LABEL = "SYNTHETIC subjects (prior draws simulated by the FE model)"


# ============================================================================ the summary (the result file)
#: Exit codes of the runs whose ranks enter the statistics: 0 (fine) and 4 (ran, results flagged).
STATISTICS_EXIT_CODES = (0, 4)


def _ranks_of(records: Sequence[Mapping], route: str, quantity: str,
              exit_codes: Iterable[int] | None = STATISTICS_EXIT_CODES) -> tuple[list, list, list, list]:
    ranks, Ls, widths, errors = [], [], [], []
    codes = None if exit_codes is None else set(exit_codes)
    for r in records:
        rr = r["routes"].get(route)
        if rr is None or (codes is not None and rr["exit_code"] not in codes):
            continue
        pair = (rr.get("ranks") or {}).get(quantity)
        if pair is None:
            continue
        ranks.append(int(pair[0]))
        Ls.append(int(pair[1]))
        widths.append((rr.get("width_rel") or {}).get(quantity))
        errors.append((rr.get("median_rel_error") or {}).get(quantity))
    return ranks, Ls, widths, errors


def _stats(values) -> dict:
    v = np.asarray([x for x in values if x is not None], float)
    if not v.size:
        return {"n": 0}
    return {"n": int(v.size), "median": float(np.median(v)), "mean": float(v.mean()), "min": float(v.min()),
            "max": float(v.max()), "total": float(v.sum())}


def route_summary(records: Sequence[Mapping], route: str) -> dict:
    """Per quantity the :func:`quantity_summary`, and the route's exit codes, flag kinds and cost."""
    runs = [r["routes"][route] for r in records if route in r["routes"]]
    out: dict = {}
    for q in QUANTITIES:
        ranks, Ls, widths, errors = _ranks_of(records, route, q)
        out[q] = quantity_summary(ranks, Ls, widths if q in WIDTH_QUANTITIES else None)
        if q in DERIVED_QUANTITIES:
            e = np.abs([v for v in errors if v is not None])
            out[q]["median_abs_rel_error"] = float(np.median(e)) if e.size else None
        # every run that left a posterior, exit 1 (not converged) included: what the selection above changes
        ranks, Ls, _, _ = _ranks_of(records, route, q, exit_codes=None)
        every = quantity_summary(ranks, Ls)
        out[q]["all_runs"] = {k: every[k] for k in ("n", "coverage_90", "coverage_50", "rank_chi2_p")}
    codes: dict[str, int] = {}
    for rr in runs:
        codes[str(rr["exit_code"])] = codes.get(str(rr["exit_code"]), 0) + 1
    flagged = [rr for rr in runs if rr["exit_code"] == 4]
    reasons: dict[str, int] = {}
    for rr in flagged:
        for kind in rr.get("flag_kinds") or ["none recorded"]:
            reasons[kind] = reasons.get(kind, 0) + 1
    errors: dict[str, int] = {}
    for rr in runs:
        if rr["exit_code"] not in (0, 4):
            key = f"exit {rr['exit_code']}: {(rr.get('error') or 'no message')[:160]}"
            errors[key] = errors.get(key, 0) + 1
    out.update({
        "n_runs": len(runs), "exit_codes": codes,
        "exit4_share": len(flagged) / len(runs) if runs else None,
        "exit4_share_ci": list(wilson_interval(len(flagged), len(runs))) if runs else None,
        "exit4_reasons": dict(sorted(reasons.items(), key=lambda kv: -kv[1])),
        "errors": errors,
        "derived_failed_draws": int(sum(rr.get("derived_failed") or 0 for rr in runs)),
        "cost": {"seconds_per_subject": _stats(rr["seconds"] for rr in runs),
                 "cpu_seconds_per_subject": _stats(rr.get("cpu_seconds") for rr in runs)},
    })
    return out


def compact_subject(rec: Mapping) -> dict:
    """One subject's record as shipped: truths, ranks, exit codes, flag kinds, seconds."""
    return {"index": rec["index"], "h": rec["h"], "scale": rec["scale"], "v_ref_ml": rec["v_ref_ml"],
            "reference_volume_ml": rec["reference_volume_ml"], "truth": rec["truth"], "redraws": rec["redraws"],
            "seconds": rec["seconds"], "cpu_seconds": rec.get("cpu_seconds"), "truth_seconds": rec.get("truth_seconds"),
            "routes": {r: {"exit_code": v["exit_code"], "flag_kinds": v.get("flag_kinds", []), "ranks": v["ranks"],
                           "width_rel": v.get("width_rel", {}), "median_rel_error": v.get("median_rel_error", {}),
                           "seconds": v["seconds"],
                           "cpu_seconds": v.get("cpu_seconds"),
                           **({"error": v["error"]} if v.get("error") else {})}
                       for r, v in rec["routes"].items()}}


def summarise_records(records: Sequence[Mapping], settings: Mapping | None = None,
                      n_planned: int | None = None) -> dict:
    """The study's result (:data:`RESULT_FILE`) from subject records (:meth:`Store.records`)."""
    if not records:
        raise LVCoreError("no finished SBC subjects to summarise; run `lvcore study sbc --piece ...` first")
    keys = {json.dumps(r.get("settings_key"), sort_keys=True) for r in records}
    if len(keys) > 1:
        raise LVCoreError(f"the records come from {len(keys)} different settings; summarise one work folder")
    key = settings or records[0].get("settings_key") or {}
    routes = [r for r in ROUTES if any(r in rec["routes"] for rec in records)]
    redraw_reasons: dict[str, int] = {}
    for rec in records:
        for why in rec.get("redraw_reasons") or []:
            short = why.split(":", 1)[0][:120]
            redraw_reasons[short] = redraw_reasons.get(short, 0) + 1
    per_route = {r: route_summary(records, r) for r in routes}
    n = len(records)
    indices = [int(r["index"]) for r in records]
    result = {
        "study": "sbc",
        "synthetic": True,
        "label": SYNTHETIC_LABEL,
        "n_subjects": n,
        "n_subjects_planned": int(n_planned) if n_planned else None,
        "complete": bool(n_planned) and n >= int(n_planned),
        "subject_indices": {"min": min(indices), "max": max(indices)},
        "quantities": list(QUANTITIES),
        "units": UNITS,
        "settings": {
            **{k: key.get(k) for k in ("seed", "warmup", "samples", "chains", "derived_draws", "derived_pressures",
                                        "thin", "allow_extrapolation")},
            "L_theta": key.get("thin"), "L_derived": key.get("derived_draws"),
            "model": MODEL, "emulator": EMULATOR, "routes": routes,
            "noise": {"sigma_v_ml": SIGMA_V_ML, "sigma_s": SIGMA_S, "reference_volume_sd_ml": REFERENCE_VOLUME_SD_ML},
            "edp_mmhg": EDP_MMHG, "edp_note": EDP_NOTE, "angles_deg": list(ANGLES), "base": BASE,
            "resolution": RESOLUTION, "volume_range_ml": list(V_REF_RANGE_ML), "volume_prior": "log-uniform",
            "pc_scores": {"n": N_PC, "prior": "N(0, 1) truncated", "truncation": H_TRUNCATION},
            "theta_prior": "uniform on lvcore.core.space.THETA_BOUNDS",
            "stress_stretch": STRESS_STRETCH, "levels": list(LEVELS), "n_bins": N_BINS, "ci_level": CI_LEVEL,
            "band_level": BAND_LEVEL,
            "ranks": "a, b, af, bf and the fibre stress among L_theta thinned posterior draws; V0, V20, V30 among "
                     "the derived FE draws (failed solves left out); runs exiting 0 or 4 only (all_runs: every run "
                     "that left a posterior, exit 1 included)",
            "statistics_exit_codes": list(STATISTICS_EXIT_CODES),
        },
        "truth_generation": {"simulator": f"FE ({RESOLUTION} mesh, {BASE} base, angles {ANGLES}, EDP {EDP_MMHG:g} "
                                          "mmHg)",
                             "redrawn": int(sum(r.get("redraws", 0) for r in records)),
                             "redraw_reasons": redraw_reasons},
        "routes": per_route,
        "exit4_share": {r: per_route[r]["exit4_share"] for r in routes},
        "exit4_reasons": {r: per_route[r]["exit4_reasons"] for r in routes},
        "cost": {
            "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(),
                        "python": platform.python_version()},
            "seconds_per_subject": _stats(r["seconds"] for r in records),
            "cpu_seconds_per_subject": _stats(r.get("cpu_seconds") for r in records),
            "load_average": _stats(r.get("load_average") for r in records),
            "truth_seconds_per_subject": _stats(r.get("truth_seconds") for r in records),
            "seconds_per_route": {r: per_route[r]["cost"]["seconds_per_subject"] for r in routes},
            "total_s": float(sum(r["seconds"] for r in records)),
            "note": "wall seconds inside the study process, summed over subjects (pieces in parallel overlap); "
                    "CPU seconds of the process (all its threads); load_average: the machine's 1-minute load "
                    "when each subject finished (a shared machine stretches the wall time)",
        },
        "notes": [
            "SYNTHETIC: every subject is a prior draw simulated by the FE model; no patient data.",
            EDP_NOTE,
            "the geometry of the draws is not the infer route's prior (scale log-uniform on 0.5-1.8 there; here "
            "V_ref log-uniform on 40-200 mL, h truncated N(0, 1) as there)",
            "the calibrations use the command's defaults, among them the representation-error floor, which adds "
            "variance for a subject that is exactly a shape-model shape (expect over-coverage from it)",
            "mesh route: V0 is fixed by the given mesh (every derived draw has the same V0), so its rank is 0 or "
            "L and its coverage is near 0 however small the error: read V0's median_abs_rel_error (how well the "
            "size-normalised projection of the mesh reproduces the true V0)",
            "coverage from ranks: inside the central interval when (rank + 0.5)/(L + 1) lies in [(1 - level)/2, "
            "1 - (1 - level)/2]; nominal_*_at_L is what a calibrated posterior gets with the same L",
        ],
        "subjects": [compact_subject(r) for r in records],
    }
    return round_floats(clean(result), 6)


def summarise(workdir, out=None) -> dict:
    """Build the result from whatever ``workdir`` holds; write it to ``out`` (a ``.json`` path, default
    the result file under ``workdir``) with ``sbc_subjects.csv`` beside it."""
    store = Store(workdir)
    if not store.root.is_dir():
        raise LVCoreError(f"--workdir {workdir}: no such folder; run `lvcore study sbc --workdir {workdir} ...` "
                          "first")
    meta = store.settings() or {}
    records = store.records()
    for rec in records:   # errors recorded before they named WORKDIR: the work folder's path is the machine's
        for rr in (rec.get("routes") or {}).values():
            for path in sorted({str(store.root.resolve()), str(store.root)}, key=len, reverse=True):
                if rr.get("error") and path in rr["error"]:
                    rr["error"] = rr["error"].replace(path, "WORKDIR")
    result = summarise_records(records, meta.get("key"), meta.get("n_subjects"))
    out = Path(out) if out is not None else store.root / RESULT_FILE
    write_json_atomic(out, result)
    subjects_table(result).to_csv(out.parent / SUBJECTS_FILE, index=False, float_format="%.6g")
    return result


def subjects_table(result: Mapping):
    """One row per subject and route: truths, exit code, flag kinds, ranks (``rank_<q>``, ``L_<q>``)."""
    import pandas as pd

    rows = []
    for s in result["subjects"]:
        base = {"index": s["index"], "scale": s["scale"], "v_ref_ml": s["v_ref_ml"],
                "reference_volume_ml": s["reference_volume_ml"], "redraws": s["redraws"],
                **{f"h{k + 1}": v for k, v in enumerate(s["h"])},
                **{f"truth_{q}": s["truth"].get(q) for q in QUANTITIES}}
        for route, rr in s["routes"].items():
            row = {**base, "route": route, "exit_code": rr["exit_code"], "flag_kinds": " ".join(rr["flag_kinds"]),
                   "seconds": rr["seconds"], "error": rr.get("error", "")}
            for q in QUANTITIES:
                pair = rr["ranks"].get(q)
                row[f"rank_{q}"], row[f"L_{q}"] = (pair if pair is not None else (None, None))
            for q in WIDTH_QUANTITIES:
                row[f"width_rel_{q}"] = rr.get("width_rel", {}).get(q)
            rows.append(row)
    return pd.DataFrame(rows)


# ============================================================================ saved results: load, tables, figures
TITLES = {
    "fig_sbc_rank_histograms": "SBC: rank histograms of the truth per quantity and route, with the uniform band",
    "fig_sbc_coverage": "SBC: coverage of the central 50 % and 90 % intervals with Wilson 95 % CIs",
    "table_sbc_summary": "SBC: coverage, χ² p-value of the rank histogram and relative widths per route",
}
MISSING: dict = {}


def load(folder) -> dict:
    """The result file (:data:`RESULT_FILE`) of a result folder (or the bundled one), with ``folder``.

    Examples
    --------
    The bundled (SYNTHETIC) result:

    >>> from lvcore.studies import sbc
    >>> from lvcore.studies.results import bundled_studies_dir
    >>> result = sbc.load(bundled_studies_dir())
    >>> sorted(result["routes"])                 # each subject calibrated with its mesh and with --geometry infer
    ['infer', 'mesh']
    >>> 0 < result["n_subjects"] <= result["n_subjects_planned"]
    True
    """
    from lvcore.studies.results import read_result

    return read_result(folder, RESULT_FILE)


def _runs_text(result: Mapping) -> str:
    s = result.get("settings", {})
    return (f"{s.get('chains')} chains × ({s.get('warmup')} + {s.get('samples')}), L = {s.get('L_theta')} θ draws, "
            f"{s.get('L_derived')} derived FE draws")


def _n_text(result: Mapping) -> str:
    n, planned = result.get("n_subjects"), result.get("n_subjects_planned")
    if planned and n < planned:
        return f"{n} of {planned} SYNTHETIC subjects (incomplete)"
    return f"{n} SYNTHETIC subjects"


def source_line(result: Mapping) -> str:
    """Where the numbers come from, in one line."""
    from lvcore.studies.results import source_label

    return (f"{RESULT_FILE} ({source_label(result['folder'])}); {_n_text(result)}; `lvcore calibrate` iid, "
            f"{_runs_text(result)}; truth by the FE simulator")


def tables(result: Mapping) -> dict:
    """The data behind each figure, and the per-subject table."""
    import pandas as pd

    routes = result["settings"]["routes"]
    rows_h, rows_c, rows_t = [], [], []
    for route in routes:
        rs = result["routes"][route]
        for q in result["quantities"]:
            s = rs[q]
            for b, (o, e) in enumerate(zip(s["rank_histogram"], s["rank_histogram_expected"])):
                rows_h.append({"route": route, "quantity": q, "bin": b + 1, "count": o, "expected": e,
                               "band_lo": s["rank_band"]["lo"][b], "band_hi": s["rank_band"]["hi"][b]})
            for level in ("50", "90"):
                ci = s.get(f"coverage_{level}_ci") or [None, None]
                rows_c.append({"route": route, "quantity": q, "level": int(level),
                               "coverage": s.get(f"coverage_{level}"),
                               "lo": ci[0], "hi": ci[1], "nominal_at_L": s.get(f"nominal_{level}_at_L"), "n": s["n"]})
            rows_t.append({"route": route, "quantity": LABELS.get(q, q), "n": s["n"],
                           "coverage 90 %": _pct_ci(s.get("coverage_90"), s.get("coverage_90_ci")),
                           "coverage 50 %": _pct_ci(s.get("coverage_50"), s.get("coverage_50_ci")),
                           "nominal at L": _pct(s.get("nominal_90_at_L")) + " / " + _pct(s.get("nominal_50_at_L")),
                           "χ² p": "" if s.get("rank_chi2_p") is None else f"{s['rank_chi2_p']:.3g}",
                           "median (q95−q05)/truth": ("" if s.get("median_width_rel") is None
                                                      else f"{s['median_width_rel']:.3f}"),
                           "median |median−truth|/truth": ("" if s.get("median_abs_rel_error") is None
                                                           else f"{s['median_abs_rel_error']:.3f}")})
    out = {"fig_sbc_rank_histograms": pd.DataFrame(rows_h), "fig_sbc_coverage": pd.DataFrame(rows_c),
           "table_sbc_summary": pd.DataFrame(rows_t)}
    rows_r = []
    for r in routes:
        rs = result["routes"][r]
        cost = rs["cost"]
        rows_r.append({"route": r, "runs": rs["n_runs"],
                       "exit codes": ", ".join(f"{k}: {v}" for k, v in sorted(rs["exit_codes"].items())),
                       "share exit 4": _pct(rs["exit4_share"]),
                       "flag kinds (exit 4)": ", ".join(f"{k} {v}" for k, v in rs["exit4_reasons"].items()),
                       "median s per subject": cost["seconds_per_subject"].get("median"),
                       "median CPU-s per subject": (cost.get("cpu_seconds_per_subject") or {}).get("median")})
    out["runs"] = pd.DataFrame(rows_r)
    return out


def _pct(v) -> str:
    return "" if v is None else f"{100 * v:.0f} %"


def _pct_ci(v, ci) -> str:
    if v is None:
        return ""
    return f"{100 * v:.0f} % [{100 * ci[0]:.0f}, {100 * ci[1]:.0f}]" if ci else f"{100 * v:.0f} %"


def captions(result: Mapping) -> dict:
    n = _n_text(result)
    return {"fig_sbc_rank_histograms": f"{n}; grey: the central {BAND_LEVEL:.0%} range of each bin's count under "
                                       "uniform ranks",
            "fig_sbc_coverage": f"{n}; dotted: the coverage a calibrated posterior gets with the same L"}


def figures(result: Mapping) -> dict:
    """The study's figures by name (:data:`TITLES`)."""
    from lvcore.viz.report_figures import table_figure
    from lvcore.viz.study_figures import sbc_coverage_figure, sbc_rank_histogram_figure

    tabs = tables(result)
    tag = _n_text(result)
    return {
        "fig_sbc_rank_histograms": sbc_rank_histogram_figure(
            tabs["fig_sbc_rank_histograms"].to_dict("records"), labels=LABELS,
            title=f"SBC — {tag}: rank of the truth among the posterior draws<br>"
                  f"<sup>10 bins; grey: {BAND_LEVEL:.0%} range of a bin's count under uniform ranks</sup>"),
        "fig_sbc_coverage": sbc_coverage_figure(
            tabs["fig_sbc_coverage"].to_dict("records"), labels=LABELS,
            title=f"SBC — {tag}: coverage of the central intervals (Wilson 95 % CI)"),
        "table_sbc_summary": table_figure(tabs["table_sbc_summary"],
                                          title=f"SBC ({tag}): coverage, rank uniformity and widths"),
    }


#: Markers of the block of docs/real_data.md written by :func:`docs_markdown` (a test compares the two).
DOCS_BEGIN = "<!-- sbc table: begin (generated by lvcore.studies.sbc.docs_markdown) -->"
DOCS_END = "<!-- sbc table: end -->"


def docs_markdown(result: Mapping) -> str:
    """The docs' SBC table of a result: per route and quantity the coverage of the 90 % and 50 % intervals (Wilson
    95 % CI), the rank histogram's χ² p-value and the median relative 90 % width, then each route's exit codes
    (docs/real_data.md quotes it between :data:`DOCS_BEGIN` and :data:`DOCS_END`; ``lvcore study sbc --summarise
    --docs FILE`` rewrites the block)."""
    tab = tables(result)["table_sbc_summary"]
    cols = ["route", "quantity", "n", "coverage 90 %", "coverage 50 %", "χ² p", "median (q95−q05)/truth"]
    lines = [f"{_n_text(result)}; {_runs_text(result)}.", "", "| " + " | ".join(cols) + " |",
             "|" + "---|" * len(cols)]
    # the mesh route's V0 is the given mesh's own, the same in every draw: its rank says nothing (module docstring)
    lines += ["| " + " | ".join(str(r[c]) for c in cols) + " |" for r in tab.to_dict("records")
              if not (r["route"] == "mesh" and r["quantity"] == LABELS.get("V0", "V0"))]
    lines += ["", "The mesh route's V0 is the given mesh's own (every draw has it), so it is not ranked here."]
    for route in result["settings"]["routes"]:
        rs = result["routes"][route]
        reasons = ", ".join(f"{k} {v}" for k, v in rs["exit4_reasons"].items()) or "none"
        lines.append(f"* {route}: {rs['n_runs']} runs, exit codes "
                     f"{', '.join(f'{k}: {v}' for k, v in sorted(rs['exit_codes'].items()))}; exit 4 "
                     f"{_pct(rs['exit4_share'])} ({reasons}).")
    return "\n".join(lines)


def rewrite_docs(result: Mapping, path) -> bool:
    """Replace the generated block of the Markdown file ``path`` by :func:`docs_markdown`; False without markers."""
    from lvcore.studies.findings_docs import rewrite_docs as replace_block

    path = Path(path)
    text = path.read_text(encoding="utf-8")
    if DOCS_BEGIN not in text or DOCS_END not in text:
        return False
    path.write_text(replace_block(text, docs_markdown(result), DOCS_BEGIN, DOCS_END), encoding="utf-8")
    return True


def format_summary(result: Mapping) -> str:
    """A few plain lines: per route the coverage of every quantity and the exit-4 share."""
    lines = [f"SBC of `lvcore calibrate` on {_n_text(result)} ({_runs_text(result)})"]
    for route in result["settings"]["routes"]:
        rs = result["routes"][route]
        parts = [f"{q} {_pct(rs[q].get('coverage_90')) or '-'}/{_pct(rs[q].get('coverage_50')) or '-'}"
                 + (f" (p {rs[q]['rank_chi2_p']:.2g})" if rs[q].get("rank_chi2_p") is not None else "")
                 for q in result["quantities"]]
        lines.append(f"  {route}: coverage 90/50 (χ² p): " + ", ".join(parts))
        lines.append(f"  {route}: exit codes {rs['exit_codes']}, exit 4 {_pct(rs['exit4_share'])} "
                     f"({rs['exit4_reasons']}); median {rs['cost']['seconds_per_subject'].get('median', 0):.0f} s "
                     "per subject")
    return "\n".join(lines)


# ============================================================================ command line
def add_study_parser(study_subparsers) -> None:
    """``lvcore study sbc``."""
    p = study_subparsers.add_parser(
        "sbc", help="simulation-based calibration of `lvcore calibrate` on SYNTHETIC prior draws (FE truth)",
        description="Simulation-based calibration (Talts et al. 2018) of the calibration pipeline: SYNTHETIC "
                    "subjects drawn from the prior, truth by the FE simulator, each calibrated by `lvcore "
                    "calibrate` with a mesh and with --geometry infer. Runs in resumable pieces; --summarise "
                    f"builds {RESULT_FILE} from what is finished.")
    p.add_argument("--n-subjects", type=cli_args.int_in(1, 100_000), default=DEFAULT_N_SUBJECTS,
                   help=f"subjects of the whole study (default {DEFAULT_N_SUBJECTS})")
    p.add_argument("--seed", type=cli_args.seed, default=0, help="seed of the subjects and noise (default 0)")
    p.add_argument("--piece", default=None, metavar="K/N",
                   help="run the K-th of N near-equal parts of the subjects (e.g. 1/2 and 2/2 in two processes; "
                        "default: all of them, or --start/--stop)")
    p.add_argument("--start", type=cli_args.int_in(0), default=None, help="first subject index (default 0)")
    p.add_argument("--stop", type=cli_args.int_in(0), default=None,
                   help="one past the last subject index (default --n-subjects)")
    p.add_argument("--workdir", type=cli_args.output_dir, default=DEFAULT_WORKDIR,
                   help=f"work folder with the per-subject records (default {DEFAULT_WORKDIR}); a rerun resumes")
    add_sampler_options(p, chains=DEFAULT_CHAINS, warmup=DEFAULT_WARMUP, samples=DEFAULT_SAMPLES)
    p.add_argument("--derived-draws", type=cli_args.int_in(2, 2000), default=DEFAULT_DERIVED_DRAWS,
                   help=f"posterior draws behind the derived FE volumes (default {DEFAULT_DERIVED_DRAWS})")
    p.add_argument("--thin", type=cli_args.int_in(2, 100_000), default=DEFAULT_THIN,
                   help=f"L: posterior draws the θ ranks are taken among (default {DEFAULT_THIN})")
    p.add_argument("--routes", default=",".join(ROUTES), help=f"comma-separated routes (default {','.join(ROUTES)})")
    p.add_argument("--allow-extrapolation", action="store_true",
                   help="pass --allow-extrapolation to `lvcore calibrate` (default: not; a mesh projected outside "
                        "the emulator's box is then refused, exit 2, and counted)")
    p.add_argument("--keep-runs", action="store_true",
                   help="keep each subject's files and calibration output under WORKDIR/runs (default: removed)")
    p.add_argument("--import-summary", type=Path, default=None, metavar="SBC_JSON",
                   help="before running, take over the subjects of an earlier summary made with the same settings "
                        f"(e.g. the shipped {RESULT_FILE}), so that a lost work folder resumes where that summary "
                        "stopped (default: none)")
    p.add_argument("--summarise", action="store_true",
                   help="build the result from the finished subjects in --workdir instead of running any")
    p.add_argument("--out", type=cli_args.output_file, default=None,
                   help=f"with --summarise: the result file (default WORKDIR/{RESULT_FILE}); {SUBJECTS_FILE} beside it")
    p.add_argument("--docs", type=Path, default=None, metavar="MARKDOWN",
                   help="with --summarise: also rewrite the generated SBC table of this Markdown file (e.g. "
                        "docs/real_data.md; default: none)")
    p.add_argument("--json", action="store_true", help="print the result (--summarise) or the piece as JSON")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    if args.summarise:
        res = summarise(args.workdir, args.out)
        out = args.out or Path(args.workdir) / RESULT_FILE
        if args.json:
            print(json.dumps({k: v for k, v in res.items() if k != "subjects"}, indent=1))
        else:
            print(format_summary(res))
            print(f"wrote {out} and {Path(out).parent / SUBJECTS_FILE}")
        if args.docs is not None:
            if not rewrite_docs(res, args.docs):
                raise LVCoreError(f"--docs {args.docs}: no generated SBC block ({DOCS_BEGIN} ... {DOCS_END}) in it")
            print(f"rewrote the SBC table of {args.docs}")
        return 0
    routes = [r.strip() for r in str(args.routes).split(",") if r.strip()]
    bad = [r for r in routes if r not in ROUTES]
    if bad or not routes:
        raise LVCoreError(f"--routes {args.routes}: choose from {', '.join(ROUTES)}")
    from lvcore.execution.restart import restart_when_mappings_high
    from lvcore.inference import samplers

    samplers.use_host_devices(args.chains)
    check_emulator_conditions()
    start, stop = piece_range(args.n_subjects, args.piece, args.start, args.stop)
    settings = default_settings(seed=args.seed, warmup=args.warmup, samples=args.samples, chains=args.chains,
                                derived_draws=args.derived_draws, thin=args.thin, routes=routes,
                                allow_extrapolation=bool(args.allow_extrapolation))
    if args.import_summary is not None:
        from lvcore.studies.results import read_json

        n = Store(args.workdir).import_summary(read_json(args.import_summary), settings, str(args.import_summary))
        if not args.json:
            print(f"imported {n} finished subjects from {args.import_summary}", flush=True)
    res = run_piece(start, stop, settings, args.workdir, n_subjects=args.n_subjects,
                    log=None if args.json else (lambda m: print(m, flush=True)), keep_runs=args.keep_runs,
                    between=lambda: restart_when_mappings_high(lambda m: print(m, file=sys.stderr, flush=True)))
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        print(f"piece done: {res['ran']} subjects in {res['seconds']:.0f} s; summarise with `lvcore study sbc "
              f"--summarise --workdir {args.workdir} --out DIR/{RESULT_FILE}`")
    return 0


__all__ = ["DOCS_BEGIN", "DOCS_END", "docs_markdown", "rewrite_docs", "RESULT_FILE", "SUBJECTS_FILE", "QUANTITIES", "ROUTES", "rank_of_truth", "pit", "inside_central",
           "nominal_coverage", "wilson_interval", "rank_histogram", "rank_chi2", "uniform_band", "quantity_summary",
           "flag_kind", "prior_draw", "noise_draw", "simulate_truth", "make_subject", "write_subject_files",
           "calibrate_argv", "calibrate_in_process", "read_route_outputs", "route_ranks", "run_route",
           "run_subject", "Store", "piece_range", "run_piece", "summarise_records", "summarise", "load", "tables",
           "figures", "source_line", "captions", "format_summary", "add_study_parser", "check_emulator_conditions"]
