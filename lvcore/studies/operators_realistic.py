"""F4/F5 with a realistic operator model (issue 26 item 4): ``lvcore study operators-realistic``.

The first operator study (:mod:`lvcore.studies.operators`) used imitation
operators that differ mostly by smooth offsets. Here the operators are the
realistic ones of :mod:`lvcore.geometry.operator_model` — whole-slice choices
of the basal and apical slice drawn per patient, local trabecular inclusion,
per-slice breath-hold misregistration of the scan, partly realigned — on 20+
SYNTHETIC patients drawn from their own seed. Each stack is fitted like a
user's segmentation; then the same SQP refits as the first study run
(:func:`lvcore.studies.operators.run_study`: data simulated at θ̃ on the main
operator's geometry, θ refitted on each other operator's geometry and on the
5- and 10-PC reconstructions; FE simulator with adjoint gradients).

Reported, each with a 90 % percentile bootstrap CI over **patients** (the
independent units; a resample keeps a patient's 3 mains × 4 tests together):

* F4 — the chapter's Table 9.4: share of (patient, main) cases in which the
  10-PC (and 5-PC) reconstruction is closer to the main geometry than both
  other operators (mean squared node distance), and the same ranking in the
  forward strain error at θ̃ (Fig 9.11);
* F5 — share of comparisons in which the 5-/10-PC reconstruction is no
  worse than another operator in output space after the refit (Fig 9.14);
* the Mahalanobis distance of θ̂ from θ̃: the Laplace approximation is only
  valid for an interior mode, so fits with a parameter on a prior bound are
  flagged (``on_bound``) and left out of the Laplace median; both medians
  are reported.

The verdicts are data (``verdicts`` in the result file, :data:`RESULT_FILE`: finding,
chapter, value, CI, verdict reproduced / not reproduced / refuted, note),
read by the findings table through :func:`load`. Everything is SYNTHETIC.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from lvcore import cli_args
from lvcore.studies import operators, registry
from lvcore.studies._common import bootstrap_ci, clean, save_figure, write_json_atomic

#: Result file of :func:`write_outputs`, read by :func:`load`; the per-fit table next to it.
RESULT_FILE = registry.result_file("operators-realistic")
FITS_FILE = "operators_realistic_fits.csv"
#: The command that makes the results.
COMMAND = "lvcore study operators-realistic --out RESULTS"
#: Bootstrap resamples and the CI level.
N_BOOT, LEVEL = 2000, 0.9
#: Sub-folder of ``--out`` holding the SQP refits (``operators`` study layout: fits/, geometries/, its result file).
REFITS = "refits"
#: Keys of a fit kept in the shipped JSON.
FIT_KEYS = ("patient", "main_operator", "test_geometry", "converged", "theta_hat", "theta_abs_error",
            "strain_rmse_forward", "output_rmse_refit", "mahalanobis", "on_bound", "loss", "sqp_evaluations",
            "seconds", "message")
#: SLSQP's ftol of the refits: looser than the first study's 1e-10, which crawls along the flat ridges of loss
#: (9.11) (60-100 simulations a fit); F5 is measured in output space, where those ridges are flat.
SQP_TOL = 1e-9
#: A share "holds" when its CI lies above this (the chapter's claims are "in most cases" / "no worse than").
MAJORITY = 0.5
TITLES = {"fig_shares_ci": "F4/F5 with realistic operators: shares with 90 % bootstrap CIs over patients",
          "fig9_11_forward_strain_error": "Fig 9.11 (realistic operators): forward strain error at θ̃",
          "fig9_14_output_error": "Fig 9.14 (realistic operators): output-space error at θ̂",
          "fig_mahalanobis": "Mahalanobis distance of θ̂ from θ̃ (realistic operators)"}


# ----------------------------------------------------------------------------- statistics over patients
def _index(fits: Sequence[dict]) -> dict:
    return {(f["patient"], f["main_operator"], f["test_geometry"]): f for f in fits if "strain_rmse_forward" in f}


def share_over_patients(fits: Sequence[dict], operators_: Sequence[str], patients: Sequence[str], metric: str,
                        test: str, kind: str) -> float:
    """Share over ``patients`` (repeats allowed) of PC test ``test`` beating the operators in ``metric``.

    ``kind``: ``"beats_both"`` (per (patient, main) case: the PC is strictly
    better than both other operators) or ``"no_worse"`` (per comparison with
    one other operator: the PC is no worse). NaN when nothing is comparable.
    """
    by = _index(fits)
    hits = []
    for p in patients:
        for m in operators_:
            pc = by.get((p, m, test))
            others = [by[(p, m, o)] for o in operators_ if o != m and (p, m, o) in by]
            if pc is None or not others:
                continue
            if kind == "beats_both":
                hits.append(all(pc[metric] < o[metric] for o in others))
            else:
                hits += [pc[metric] <= o[metric] for o in others]
    return float(np.mean(hits)) if hits else float("nan")


def geometry_share(table: dict, patients: Sequence[str], k: int) -> float:
    """Table 9.4 over ``patients`` (repeats allowed): share of cases where k PCs beat both other operators."""
    rows = {(r["patient"], b["main"]): r for b in table["blocks"] for r in b["rows"]}
    hits = [rows[(p, b["main"])]["pca_mse"][str(k)] < min(rows[(p, b["main"])]["operator_mse"].values())
            for p in patients for b in table["blocks"] if (p, b["main"]) in rows]
    return float(np.mean(hits)) if hits else float("nan")


def group_median(fits: Sequence[dict], patients: Sequence[str], key: str, group: str, interior: bool = False) -> float:
    """Median of ``key`` over the fits of ``patients`` (repeats allowed) in test group ``group``.

    ``group``: ``operator``, ``pc5`` or ``pc10``; ``interior``: only fits with no parameter on a prior bound.
    """
    vals = []
    for p in patients:
        for f in fits:
            if f["patient"] != p or key not in f or operators._group(f) != group:
                continue
            if interior and f.get("on_bound"):
                continue
            vals.append(f[key])
    return float(np.median(vals)) if vals else float("nan")


def bootstrap(fits: Sequence[dict], operators_: Sequence[str], table: dict | None, n_boot: int = N_BOOT,
              seed: int = 0, level: float = LEVEL) -> dict:
    """Every F4/F5 quantity with its percentile bootstrap CI over patients (:func:`bootstrap_ci`)."""
    fits = [f for f in fits if "strain_rmse_forward" in f]
    patients = sorted({f["patient"] for f in fits})
    kw = dict(n_boot=n_boot, seed=seed, level=level)
    out: dict = {}
    if table is not None:
        out["geometry_node_mse"] = {f"pc{k}": {"share_beats_both": bootstrap_ci(
            patients, lambda ps, k=k: geometry_share(table, ps, k), **kw)} for k in operators.PC_TESTS}
    for metric in ("strain_rmse_forward", "output_rmse_refit"):
        out[metric] = {f"pc{k}": {kind_name: bootstrap_ci(
            patients, lambda ps, k=k, kind=kind: share_over_patients(fits, operators_, ps, metric, f"pc{k}", kind), **kw)
            for kind_name, kind in (("share_beats_both_operators", "beats_both"),
                                    ("share_no_worse_than_an_operator", "no_worse"))} for k in operators.PC_TESTS}
        out[metric]["median"] = {g: bootstrap_ci(patients, lambda ps, g=g: group_median(fits, ps, metric, g), **kw)
                                 for g in ("operator", "pc5", "pc10")}
    out["mahalanobis_all"] = {g: bootstrap_ci(patients, lambda ps, g=g: group_median(fits, ps, "mahalanobis", g), **kw)
                              for g in ("operator", "pc5", "pc10")}
    out["mahalanobis_interior"] = {
        g: bootstrap_ci(patients, lambda ps, g=g: group_median(fits, ps, "mahalanobis", g, interior=True), **kw)
        for g in ("operator", "pc5", "pc10")}
    return out


def _verdict(lo: float, hi: float, threshold: float = MAJORITY) -> str:
    if lo > threshold:
        return "reproduced"
    if hi < threshold:
        return "refuted"
    return "not reproduced"


def _ci_text(b: dict, pct: bool = True) -> str:
    f = (lambda v: f"{100 * v:.0f} %") if pct else (lambda v: f"{v:.3g}")
    return f"{f(b['value'])} [{f(b['ci'][0])}, {f(b['ci'][1])}]" if b.get("ci") else f(b["value"])


def verdicts(boot: dict, n_patients: int, n_fits: int) -> dict:
    """F4 and F5 as data: finding, chapter, value and CI, verdict (reproduced / not reproduced / refuted), note.

    The chapter's claims are read as "in most cases" (F4: 10 PCs beat both new
    operators in 94 % of cases) and "no worse than a new operator" (F5): a
    claim is *reproduced* when the 90 % CI of the share lies above 50 %,
    *refuted* when it lies below, otherwise *not reproduced* (the CI spans 50 %).
    """
    out = {}
    if "geometry_node_mse" in boot:
        g = boot["geometry_node_mse"]["pc10"]["share_beats_both"]
        s = boot["strain_rmse_forward"]["pc10"]["share_beats_both_operators"]
        out["F4"] = {
            "finding": "F4: a 10-PC reconstruction is closer to the main geometry than a new operator's segmentation "
                       "(Table 9.4)",
            "chapter": "10 PCs beat both new operators in 94 % of cases (5 PCs: 44 %)",
            "quantity": "share of (patient, main operator) cases in which 10 PCs beat both other operators in mean "
                        "squared node distance",
            "value": g["value"], "ci": g["ci"], "level": LEVEL,
            "verdict": _verdict(*(g["ci"] or [g["value"]] * 2)),
            "note": (f"realistic operators, {n_patients} SYNTHETIC patients; 5 PCs: "
                     f"{_ci_text(boot['geometry_node_mse']['pc5']['share_beats_both'])}. In forward strain error at "
                     f"θ̃ (Fig 9.11) 10 PCs beat both operators in {_ci_text(s)} of cases "
                     f"({_verdict(*(s['ci'] or [s['value']] * 2))} there)"),
        }
    p5 = boot["output_rmse_refit"]["pc5"]["share_no_worse_than_an_operator"]
    p10 = boot["output_rmse_refit"]["pc10"]["share_no_worse_than_an_operator"]
    lo = min((b["ci"] or [b["value"]] * 2)[0] for b in (p5, p10))
    hi = max((b["ci"] or [b["value"]] * 2)[1] for b in (p5, p10))
    out["F5"] = {
        "finding": "F5: refitting θ on a 5- or 10-PC reconstruction is no worse than on a new operator's geometry "
                   "(output space, Fig 9.14)",
        "chapter": "5/10 PCs 'at least as consistent as the new operators'",
        "quantity": "share of comparisons (patient, main, other operator) in which the PC refit's output RMSE at θ̂ "
                    "on the main geometry is no worse than the other operator's",
        "value": {"pc5": p5["value"], "pc10": p10["value"]}, "ci": {"pc5": p5["ci"], "pc10": p10["ci"]},
        "level": LEVEL,
        "verdict": "reproduced" if lo > MAJORITY else "refuted" if hi < MAJORITY else "not reproduced",
        "note": (f"realistic operators, {n_patients} SYNTHETIC patients, {n_fits} SQP refits; pc5 {_ci_text(p5)}, "
                 f"pc10 {_ci_text(p10)}; the first (offset) operator model gave 33 % and 47 %"),
    }
    return out


# ----------------------------------------------------------------------------- the study
def summarise(fits: Sequence[dict], operators_: Sequence[str], table: dict | None, meta: dict,
              n_boot: int = N_BOOT, seed: int = 0) -> dict:
    """The result (:data:`RESULT_FILE`): slim fits, the first study's findings, bootstrap CIs, verdicts, meta."""
    slim = [{k: f[k] for k in FIT_KEYS if k in f} for f in fits]
    for f in slim:
        if "theta_hat" in f:
            f["on_bound"] = operators.on_bound(f["theta_hat"])
    boot = bootstrap(slim, operators_, table, n_boot=n_boot, seed=seed)
    patients = sorted({f["patient"] for f in slim})
    return {"fits": slim, "findings": operators.findings(slim, operators_), "bootstrap": boot,
            "verdicts": verdicts(boot, len(patients), len(slim)),
            "geometry_table": None if table is None else {k: table[k] for k in ("share_beating_both",
                                                                                  "operator_mse_range", "n_cases")},
            "meta": {**meta, "n_boot": n_boot, "ci_level": LEVEL, "bootstrap_units": "patients"}}


def rotating_mains(patients: Sequence[str], operators_: Sequence[str]):
    """One main operator per patient, in turn (patient i: operator i mod 3): a balanced third of the chapter's design."""
    order = list(patients)
    return lambda p: [operators_[order.index(p) % len(operators_)]]


def run_study(n_patients: int | None = None, seed: int | None = None, *, out, workers: int = 1,
              scheduler: str | None = None, resolution: str = "default", forward_factory=None, progress: bool = False,
              shape_model=None, n_boot: int = N_BOOT, log=None, all_mains: bool = False,
              sqp_tol: float = SQP_TOL, collect_only: bool = False) -> dict:
    """Build the realistic operators' geometries, run the SQP refits and write the result file
    (:data:`RESULT_FILE`) under ``out``.

    ``all_mains``: every operator is the main one for every patient (the chapter's design, 12 refits per
    patient); default: one main per patient in turn (:func:`rotating_mains`, 4 refits per patient).
    ``collect_only``: run no refit, summarise those already in ``out/refits/fits`` (marked partial).

    Resumable: the fitted geometries are cached in ``out/cohort`` and every
    finished refit is kept in ``out/refits/fits`` (:func:`lvcore.studies.operators.run_study`).
    ``forward_factory(geometry_name)`` replaces the simulator (tests).
    """
    from lvcore.geometry import operator_model as om
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.studies.geometry_operators import operator_table

    n_patients = om.DEFAULT_PATIENTS if n_patients is None else int(n_patients)
    seed = om.DEFAULT_SEED if seed is None else int(seed)
    out = Path(out)
    t0 = time.perf_counter()
    sm = shape_model or load_shape_model()
    og = om.build_operator_geometries(n_patients, seed, cache_dir=out / "cohort", log=log)
    mains = None if all_mains else rotating_mains(og.patients, og.operators)
    res = operators.run_study(None, out=out / REFITS, workers=workers, scheduler=scheduler, resolution=resolution,
                              forward_factory=forward_factory, progress=progress, operator_geometries=og,
                              shape_model=sm, mains=mains, sqp_tol=sqp_tol, collect_only=collect_only)
    table = operator_table(og, sm, ks=operators.PC_TESTS)
    styles = {k: {"basal_slices": v["basal_slices"], "apical_slices": v["apical_slices"]} for k, v in og.fits.items()}
    meta = {"study": "operators-realistic",
            "label": "SYNTHETIC realistic-operator study (whole-slice choices, trabecular inclusion, breath-hold "
                     "misregistration; imitation operators on synthetic LVs)",
            "patients": list(og.patients), "operators": list(og.operators), "seed": seed,
            "n_patients_requested": n_patients, "left_out": og.meta.get("left_out", {}),
            "operator_model": og.meta.get("settings"), "slice_choices": styles,
            "design": ("every operator as the main one (12 refits per patient)" if all_mains else
                       "one main operator per patient in turn (patient i: operator i mod 3; 4 refits per patient); "
                       "Table 9.4 (node distance) uses every main"),
            "n_fits": len(res["fits"]), "complete_study": res["meta"]["complete_study"],
            "budget": res["meta"]["budget"], "sqp_tol": sqp_tol, "n_converged": int(sum(f["converged"] for f in res["fits"])),
            "refits": {k: res["meta"][k] for k in ("settings", "simulations", "fit_seconds_total", "workers",
                                                   "executor") if k in res["meta"]},
            "seconds_this_session": round(time.perf_counter() - t0, 1),
            "command": (f"lvcore study operators-realistic --patients {n_patients} --seed {seed} --resolution "
                        f"{resolution}" + (" --all-mains" if all_mains else "") + " --out RESULTS")}
    result = summarise(res["fits"], list(og.operators), table, meta, n_boot=n_boot)
    write_outputs(result, out)
    return result


# ----------------------------------------------------------------------------- results interface
def load(folder) -> dict:
    """The results of an ``operators-realistic`` ``--out`` folder (or the bundled one): the JSON plus ``folder``.

    Examples
    --------
    The bundled (SYNTHETIC) result:

    >>> from lvcore.studies import operators_realistic
    >>> from lvcore.studies.results import bundled_studies_dir
    >>> result = operators_realistic.load(bundled_studies_dir())
    >>> result["meta"]["operators"]              # doctest: +ELLIPSIS
    [...]
    >>> len(result["fits"]) == result["meta"]["n_fits"]
    True
    """
    from lvcore.studies.results import read_result

    return read_result(folder, RESULT_FILE)


def source_line(result: dict) -> str:
    from lvcore.studies.results import source_label

    m = result.get("meta", {})
    return (f"{RESULT_FILE} ({source_label(result['folder'])}); {len(m.get('patients', []))} SYNTHETIC patients × "
            f"{len(m.get('operators', []))} realistic operators, {m.get('n_fits', 0)} SQP refits "
            f"({m.get('refits', {}).get('settings', {}).get('resolution', '?')} mesh); CIs: "
            f"{m.get('n_boot', N_BOOT)} bootstrap resamples over patients")


def verdict_rows(result: dict) -> list[dict]:
    """One row per verdict: finding, chapter, value with CI (text), verdict, note."""
    rows = []
    for key, v in result.get("verdicts", {}).items():
        if isinstance(v["value"], dict):
            val = "; ".join(f"{k} {100 * x:.0f} % [{100 * v['ci'][k][0]:.0f}, {100 * v['ci'][k][1]:.0f}]"
                            if v["ci"][k] else f"{k} {100 * x:.0f} %" for k, x in v["value"].items())
        else:
            val = (f"{100 * v['value']:.0f} % [{100 * v['ci'][0]:.0f}, {100 * v['ci'][1]:.0f}]" if v["ci"]
                   else f"{100 * v['value']:.0f} %")
        rows.append({"finding": key, "claim": v["finding"].split(": ", 1)[-1], "chapter": v["chapter"],
                     "here (90 % CI)": val, "verdict": v["verdict"], "note": v["note"]})
    return rows


def tables(result: dict) -> dict:
    """``verdicts``, ``fits`` (one row per fit) and the figures' data."""
    import pandas as pd

    out = {"verdicts": pd.DataFrame(verdict_rows(result))}
    fits = result.get("fits", [])
    if fits:
        out["fits"] = operators.fits_frame(fits)
        out.update({k: v for k, v in operators.tables({"fits": fits}).items() if k in TITLES})
    out["fig_shares_ci"] = pd.DataFrame(_share_rows(result))
    return out


def _share_rows(result: dict) -> list[dict]:
    b = result.get("bootstrap", {})
    rows = []
    specs = [("geometry_node_mse", "share_beats_both", "node distance: beats both (F4)"),
             ("strain_rmse_forward", "share_beats_both_operators", "strain at θ̃: beats both (Fig 9.11)"),
             ("output_rmse_refit", "share_no_worse_than_an_operator", "output at θ̂: no worse (F5)")]
    for block, key, label in specs:
        for k in operators.PC_TESTS:
            e = b.get(block, {}).get(f"pc{k}", {}).get(key)
            if e:
                rows.append({"quantity": label, "test": f"pc{k}", "value": e["value"],
                             "lo": (e["ci"] or [None, None])[0], "hi": (e["ci"] or [None, None])[1]})
    return rows


def figures(result: dict) -> dict:
    """The shares with their CIs, and the first study's violins (Figs 9.11, 9.14, Mahalanobis) on these fits."""
    from lvcore.viz.study_figures import ci_dots

    out = {}
    rows = _share_rows(result)
    if rows:
        out["fig_shares_ci"] = ci_dots(rows, reference=MAJORITY,
                                       title=f"{TITLES['fig_shares_ci']} (SYNTHETIC patients)")
    fits = result.get("fits", [])
    if fits:
        figs = operators.figures({"fits": fits})
        for name in ("fig9_11_forward_strain_error", "fig9_14_output_error", "fig_mahalanobis"):
            if name in figs:
                figs[name].update_layout(title=f"{TITLES[name]} — SYNTHETIC patients")
                out[name] = figs[name]
    return out


def write_outputs(result: dict, out) -> dict:
    """The result file (:data:`RESULT_FILE`), ``operators_realistic_fits.csv`` and the figures (HTML; PNG when kaleido works)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": str(write_json_atomic(out / RESULT_FILE, clean(result)))}
    if result.get("fits"):
        operators.fits_frame(result["fits"]).to_csv(out / FITS_FILE, index=False)
        paths["csv"] = str(out / FITS_FILE)
    for name, fig in figures({**result, "folder": str(out)}).items():
        paths[name] = save_figure(fig, out / name)
    return paths


def format_findings(result: dict) -> str:
    lines = [f"{r['finding']}: {r['here (90 % CI)']} -> {r['verdict']} (chapter: {r['chapter']})"
             for r in verdict_rows(result)]
    f = result.get("findings", {})
    if "median_mahalanobis_interior" in f:
        lines.append("median Mahalanobis (Laplace): all fits " + ", ".join(
            f"{k} {v:.2f}" for k, v in f["median_mahalanobis"].items()) + "; interior only " + ", ".join(
            f"{k} {'n/a' if v is None else f'{v:.2f}'} ({f['n_on_bound'][k]} on a bound)"
            for k, v in f["median_mahalanobis_interior"].items()))
    return "\n".join(lines)


def markdown_table(result: dict) -> str:
    """The verdicts as the Markdown table docs/studies.md quotes (tests compare the two)."""
    lines = ["| finding | chapter | here (90 % CI over patients) | verdict |", "|---|---|---|---|"]
    for r in verdict_rows(result):
        lines.append(f"| {r['finding']}: {r['claim']} | {r['chapter']} | {r['here (90 % CI)']} | **{r['verdict']}** |")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- CLI
def add_study_parser(study_subparsers) -> None:
    """``lvcore study operators-realistic``."""
    from lvcore.geometry import operator_model as om

    p = study_subparsers.add_parser(
        "operators-realistic", help="findings F4/F5 with realistic imitation operators (whole-slice "
                                    "choices, trabeculae, breath-hold shifts) on 20+ SYNTHETIC patients, bootstrap CIs")
    p.add_argument("--patients", type=cli_args.int_in(2, 200), default=om.DEFAULT_PATIENTS,
                   help=f"SYNTHETIC patients to draw (default {om.DEFAULT_PATIENTS})")
    p.add_argument("--seed", type=cli_args.seed, default=om.DEFAULT_SEED,
                   help=f"seed of the patients and operators (default {om.DEFAULT_SEED})")
    p.add_argument("--workers", type=cli_args.workers, default=1, help="local worker processes (default 1)")
    p.add_argument("--scheduler", default=None, help="tcp://HOST:PORT of a Dask scheduler (default: none)")
    p.add_argument("--resolution", default="default", help="simulator mesh preset (default 'default')")
    p.add_argument("--all-mains", action="store_true",
                   help="every operator as the main one for every patient (12 refits per patient; default: one main "
                        "per patient in turn, 4 refits)")
    p.add_argument("--collect-only", action="store_true",
                   help="run no refit: summarise the refits already saved in OUT/refits/fits (an interrupted run)")
    p.add_argument("--json", action="store_true", help="print the verdicts as JSON")
    p.add_argument("--out", type=cli_args.output_dir, required=True,
                   help="output folder (geometries cached in OUT/cohort, refits in OUT/refits/fits for resuming)")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    res = run_study(args.patients, args.seed, out=args.out, workers=args.workers, scheduler=args.scheduler,
                    resolution=args.resolution, progress=not args.json, log=None if args.json else print,
                    all_mains=args.all_mains, collect_only=args.collect_only)
    if args.json:
        print(json.dumps(clean({"verdicts": res["verdicts"], "meta": res["meta"]}), indent=1))
    else:
        print(format_findings(res))
        print(f"wrote {args.out}/{RESULT_FILE}, {FITS_FILE} and figures")
    return 0
