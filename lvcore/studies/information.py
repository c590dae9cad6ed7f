r"""Information that pins the stiffness: ``lvcore study information`` (its saved result, tables and figures).

With one pressure, 24 strains and one volume the Holzapfel–Ogden parameters
a and b are fixed only as a combination: many (a, b) pairs fit the data
equally well, and a's 90 % interval stays wide. This study measures how much
extra information narrows it, on SYNTHETIC subjects, in two parts:

``states``
    K SYNTHETIC subjects on the simulator's default LV, θ drawn from the
    SYNTHETIC population of :mod:`lvcore.inference.cohort` (log θ ~
    N(log θ̃, Σ)), simulated by the FE simulator at 8, 14 and 20 mmHg
    (sliding base, fibres −60°/60°), noise σ_V = 5 mL and σ_S = 0.03 at each
    state. Each subject is calibrated with ``lvcore calibrate`` (iid
    likelihood; a subject emulator of that geometry with the EDP as an input
    over 6–30 mmHg) with one loaded state (8 mmHg), two (8 + 20) and three
    (8 + 14 + 20), each with and without ``--prior klotz`` (the Klotz et al.
    2006 single-beat EDPVR as a likelihood term on V20 and V30): 6 variants.
``cohort``
    SYNTHETIC cohorts of 8 and of 24 subjects
    (:func:`lvcore.inference.cohort.synthetic_cohort`; data from the
    ``chapter`` emulator at 8 mmHg, σ_V = 5 mL, σ_S = 0.03), each calibrated
    subject by subject (``separate``) and with ``lvcore calibrate
    --hierarchical`` (one joint posterior, log θᵢ ~ N(μ, Σ)): 4 variants.

Reported per variant: a's 90 % interval width as the ratio q95/q05 (median
over subjects), its narrowing against the reference variant (per subject the
reference's ratio over this one's; median), the coverage of the 90 %
intervals of a, b, af, bf and of all four at once (share of subjects, Wilson
95 % CI), the 90 % width of V30 (and V20) in mL with its coverage, the exit
codes and the share converged; and verdicts on the targets (two states at
least 3× narrower with every θ covered; the hierarchical fit at least 2×
narrower per subject with coverage in [0.8, 1.0]).

The runs are in :mod:`lvcore.studies.information_runner` (``lvcore study
information --part states|cohort``, resumable), the summary in
:mod:`lvcore.studies.information_summary` (``--summarise``); this module reads the result file (:data:`RESULT_FILE`)
and draws it: :func:`load`, :func:`tables`, :func:`figures`,
:func:`source_line`, as the Studies page (its Information tab) and
``lvcore report`` call them.
"""
from __future__ import annotations

import math
from typing import Mapping

from lvcore.studies import registry

#: The result file the runner's ``--summarise`` writes and :func:`load` reads (shipped under ``assets/studies/``).
RESULT_FILE = registry.result_file("information")
#: The commands that make the result: the two parts (resumable), then the summary.
COMMAND = ("lvcore study information --workdir build/information --part states; "
           "lvcore study information --workdir build/information --part cohort; "
           f"lvcore study information --summarise --workdir build/information --out assets/studies/{RESULT_FILE}")
SYNTHETIC_LABEL = "SYNTHETIC subjects (FE-simulated default LV; cohorts from the chapter emulator)"
#: The parts in order, with their titles.
PARTS = {"states": "loaded states (FE-simulated default LV)", "cohort": "cohorts (chapter emulator)"}
THETA = ("a", "b", "af", "bf")
MISSING_TEXT = "–"

TITLES = {
    "fig_information_a_ratio": "Information study: width of a's 90 % interval (q95/q05) per SYNTHETIC subject and "
                               "variant",
    "fig_information_v30_width": "Information study: width of V30's 90 % interval (mL) per SYNTHETIC subject and "
                                 "variant",
    "table_information_variants": "Information study: a's interval width, its narrowing, coverage of the 90 % "
                                  "intervals and V30's width per variant (SYNTHETIC subjects)",
    "verdicts": "Information study: verdicts on the targets (SYNTHETIC subjects)",
    "runs": "Information study: one row per SYNTHETIC subject and variant",
}
#: Why an item can be missing from a result.
MISSING = {"fig_information_v30_width": "no variant of the result has V30 intervals (derived draws not computed)"}


def load(folder) -> dict:
    """The result (:data:`RESULT_FILE`) in ``folder``, with ``folder`` added.

    Raises
    ------
    LVCoreError
        The file is missing, not a regular file, too large, not UTF-8 text or not JSON (naming it), or JSON that is
        not this study's result (no ``variants`` list).

    Examples
    --------
    >>> from lvcore.studies import information
    >>> from lvcore.studies.results import bundled_studies_dir
    >>> result = information.load(bundled_studies_dir())
    >>> result["synthetic"], sorted({v["part"] for v in result["variants"]})
    (True, ['cohort', 'states'])
    >>> next(v["label"] for v in result["variants"] if v["key"] == "states-8-20")
    '8 + 20 mmHg'
    """
    from pathlib import Path

    from lvcore.exceptions import LVCoreError
    from lvcore.studies.results import read_json

    path = Path(folder) / RESULT_FILE
    result = read_json(path)  # LVCoreError naming the file: missing, too large, not text, not JSON
    if (not isinstance(result, dict) or not isinstance(result.get("variants"), list)
            or result.get("study", "information") != "information"):
        raise LVCoreError(f"study results '{path}' are not the information study's result (no 'variants' list); "
                          f"make it with {COMMAND}")
    return {**result, "folder": str(folder)}


# ============================================================================ text of the numbers
def _num(v, fmt: str = ".3g") -> str:
    return MISSING_TEXT if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(float(v), fmt)


def _pct(v) -> str:
    return MISSING_TEXT if v is None else f"{100 * float(v):.0f} %"


def _pct_ci(v, ci) -> str:
    if v is None:
        return MISSING_TEXT
    if not ci or None in ci:
        return _pct(v)
    return f"{_pct(v)} [{100 * ci[0]:.0f}, {100 * ci[1]:.0f}]"


def _range(stats, fmt: str = ".3g", unit: str = "") -> str:
    """``median [min–max]`` of a ``{"median", "min", "max"}`` block; "–" when absent."""
    if not stats or stats.get("median") is None:
        return MISSING_TEXT
    text = f"{_num(stats['median'], fmt)}{unit}"
    if stats.get("min") is not None and stats.get("max") is not None:
        text += f" [{_num(stats['min'], fmt)}–{_num(stats['max'], fmt)}]"
    return text


def _yes_no(v) -> str:
    return MISSING_TEXT if v is None else ("yes" if v else "no")


def _no_missing(frame):
    """``frame`` with "–" for a missing cell (a column with one is shown as text, numbers with 4 significant
    digits), never None or NaN."""
    import pandas as pd

    out = frame.copy()
    for col in out.columns:
        if out[col].isna().any():
            out[col] = [MISSING_TEXT if pd.isna(v) else (f"{v:.4g}" if isinstance(v, float) else str(v))
                        for v in out[col]]
    return out


# ============================================================================ variants and runs
def variant_labels(result: Mapping) -> dict:
    """Variant key -> its label on axes and in tables: the result's label, with the prior (Klotz) or the method
    (separate, hierarchical) added where the label does not say it; unique (the key added to a repeated one)."""
    out = {}
    for v in result.get("variants", []):
        label = str(v.get("label") or v["key"])
        if v.get("prior") not in (None, "none") and str(v["prior"]).lower() not in label.lower():
            label += f", {str(v['prior']).capitalize()} prior"
        if v.get("part") == "cohort" and v.get("method") and str(v["method"]).lower() not in label.lower():
            label += f", {v['method']}"
        out[v["key"]] = label
    seen = list(out.values())
    return {k: (f"{lab} ({k})" if seen.count(lab) > 1 else lab) for k, lab in out.items()}


def _states_text(v: Mapping) -> str:
    states = v.get("states_mmhg")
    if not states:
        return MISSING_TEXT
    return " + ".join(f"{float(p):g}" for p in states)


def _population_text(v: Mapping) -> str:
    """μ covered and the population's diagnostics of a hierarchical variant; "–" otherwise."""
    mu, diag = v.get("mu_covered"), (v.get("diagnostics") or {}).get("population")
    if not mu and not diag:
        return MISSING_TEXT
    parts = []
    if mu:
        parts.append("μ covered: " + ", ".join(f"{k} {_yes_no(c)}" for k, c in mu.items()))
    if diag:
        parts.append(f"R̂ ≤ {_num(diag.get('max_rhat'), '.3f')}, ESS ≥ {_num(diag.get('min_ess_bulk'), '.0f')}, "
                     f"{diag.get('n_divergent', MISSING_TEXT)} divergent")
    return "; ".join(parts)


def variant_rows(result: Mapping) -> list[dict]:
    """One row per variant (text): part, label, states, route, prior, method, runs, a's width and narrowing, coverage of
    a, b, af, bf and all four with Wilson CIs, V30's width and coverage, exit codes, share converged."""
    labels = variant_labels(result)
    rows = []
    for v in result.get("variants", []):
        cov, ci = v.get("coverage_90") or {}, v.get("coverage_90_ci") or {}
        ref = v.get("reference")
        row = {"part": v.get("part", MISSING_TEXT), "variant": labels[v["key"]],
               "states (mmHg)": _states_text(v), "route": v.get("route") or MISSING_TEXT,
               "prior": v.get("prior") or MISSING_TEXT,
               "method": v.get("method") or MISSING_TEXT,
               "subjects": (f"{v.get('n_calibrated', MISSING_TEXT)} of {v.get('n_runs', MISSING_TEXT)}"
                            + (f" (cohort of {v['cohort_size']})" if v.get("cohort_size") else "")),
               "a q95/q05: median [min–max]": _range(v.get("a_ratio")),
               "narrowing vs reference: median [min–max]": (_range(v.get("narrowing"), ".3g", "×")
                                                             if ref != v["key"] else "reference"),
               "reference": labels.get(ref, ref or MISSING_TEXT)}
        for k in (*THETA, "all4"):
            row[f"coverage {'all four' if k == 'all4' else k}"] = _pct_ci(cov.get(k), ci.get(k))
        row.update({"V30 90 % width (mL): median [min–max]": _range(v.get("v30_width_ml"), ".3g"),
                    "V30 coverage": _pct(v.get("v30_coverage_90")),
                    "exit codes": ", ".join(f"{c}: {n}" for c, n in sorted((v.get("exit_codes") or {}).items()))
                                  or MISSING_TEXT,
                    "converged": _pct(v.get("converged_share")),
                    "population (hierarchical)": _population_text(v)})
        rows.append(row)
    return rows


def verdict_rows(result: Mapping) -> list[dict]:
    """One row per verdict: claim, target, value, met ("yes", "no" or "not shown"), note."""
    return [{"claim": v.get("claim", MISSING_TEXT), "target": v.get("target") or MISSING_TEXT,
             "value": v.get("value") or MISSING_TEXT,
             "met": "not shown" if v.get("met") is None else ("yes" if v["met"] else "no"),
             "note": v.get("note") or MISSING_TEXT} for v in result.get("verdicts", [])]


def _quantile(run: Mapping, level: str, q: str):
    return (run.get(level) or {}).get(q)


def covered(run: Mapping, q: str):
    """Whether ``q``'s truth lies in one run's 90 % interval; None without the interval or the truth."""
    lo, hi, truth = _quantile(run, "q05", q), _quantile(run, "q95", q), (run.get("truth") or {}).get(q)
    return None if None in (lo, hi, truth) else bool(lo <= truth <= hi)


def a_ratio(run: Mapping):
    """a's q95/q05 of one run; None without a posterior of a."""
    lo, hi = _quantile(run, "q05", "a"), _quantile(run, "q95", "a")
    return None if lo is None or hi is None or lo <= 0 else float(hi) / float(lo)


def width(run: Mapping, q: str = "V30"):
    """The 90 % width q95 − q05 of ``q`` in one run (mL for V20, V30); None when absent."""
    lo, hi = _quantile(run, "q05", q), _quantile(run, "q95", q)
    return None if lo is None or hi is None else float(hi) - float(lo)


def run_rows(result: Mapping) -> list[dict]:
    """One row per run: variant, subject, exit, converged, wall s, a's truth and interval, coverage of θ, V20 and
    V30 widths and coverage (None where absent)."""
    labels = variant_labels(result)
    part = {v["key"]: v.get("part") for v in result.get("variants", [])}
    rows = []
    for r in result.get("runs", []):
        row = {"part": part.get(r["variant"]), "variant": labels.get(r["variant"], r["variant"]),
               "subject": r.get("subject"), "exit": r.get("exit"), "converged": _yes_no(r.get("converged")),
               "wall s": r.get("wall_s"), "a truth": (r.get("truth") or {}).get("a"),
               **{f"a {c}": _quantile(r, c, "a") for c in ("q05", "median", "q95")}, "a q95/q05": a_ratio(r)}
        row.update({f"{k} covered": _yes_no(covered(r, k)) for k in THETA})
        for q in ("V20", "V30"):
            row.update({f"{q} truth (mL)": (r.get("truth") or {}).get(q), f"{q} 90 % width (mL)": width(r, q),
                        f"{q} covered": _yes_no(covered(r, q))})
        rows.append(row)
    return rows


def per_subject_rows(result: Mapping, value) -> list[dict]:
    """The rows of a per-variant figure: ``value(run)`` per run (None: left out), with the run's panel (part),
    variant label, colour group (the prior in the states part, the method in the cohort part) and subject."""
    labels = variant_labels(result)
    variants = {v["key"]: v for v in result.get("variants", [])}
    order = {k: i for i, k in enumerate(variants)}
    rows = []
    for r in sorted(result.get("runs", []), key=lambda r: order.get(r["variant"], len(order))):
        v = variants.get(r["variant"], {})
        y = value(r)
        if y is None:
            continue
        series = (f"{v.get('method')} fits" if v.get("part") == "cohort" else
                  ("no prior" if v.get("prior") in (None, "none") else f"{str(v['prior']).capitalize()} prior")
                  + (", --geometry infer" if v.get("route") == "infer" else "")
                  + (f" ({v['emulator']})" if v.get("emulator") else ""))
        rows.append({"panel": v.get("part", "other"), "variant": labels.get(r["variant"], r["variant"]),
                     "series": series, "subject": r.get("subject"), "value": y})
    return rows


# ============================================================================ the study interface
def _n_text(result: Mapping) -> str:
    s = result.get("settings", {})
    sizes = " and ".join(str(n) for n in s.get("cohort_sizes") or [])
    n = s.get("n_state_subjects", s.get("n_subjects", MISSING_TEXT))
    text = f"{n} SYNTHETIC state subjects" + (f", SYNTHETIC cohorts of {sizes}" if sizes else "")
    return text if result.get("complete", True) else text + f" ({incomplete_text(result)})"


def incomplete_text(result: Mapping) -> str:
    """What an incomplete result holds, e.g. ``incomplete: 40 of 96 planned runs done``."""
    done, planned = result.get("n_records"), result.get("n_planned")
    if done is not None and planned:
        return f"incomplete: {done} of {planned} planned runs done"
    return "incomplete: not every planned run done"


def source_line(result: Mapping) -> str:
    """Where the numbers come from, in one line."""
    from lvcore.studies.results import source_label

    s = result.get("settings", {})
    return (f"{RESULT_FILE} ({source_label(result['folder'])}); {result.get('label', SYNTHETIC_LABEL)}; "
            f"{_n_text(result)}; `lvcore calibrate` iid, {s.get('chains', '?')} chains × "
            f"({s.get('warmup', '?')} + {s.get('samples', '?')})"
            + (f", noise σ_V {s['sigma_v_ml']:g} mL, σ_S {s['sigma_s']:g}" if s.get("sigma_v_ml") and s.get("sigma_s")
               else ""))


def tables(result: Mapping) -> dict:
    """The tables by name (:data:`TITLES`; "–" where a value is missing), and each figure's data."""
    import pandas as pd

    out = {"table_information_variants": pd.DataFrame(variant_rows(result)),
           "verdicts": pd.DataFrame(verdict_rows(result), columns=["claim", "target", "value", "met", "note"]),
           "runs": pd.DataFrame(run_rows(result)),
           "fig_information_a_ratio": pd.DataFrame(per_subject_rows(result, a_ratio),
                                                   columns=["panel", "variant", "series", "subject", "value"]),
           "fig_information_v30_width": pd.DataFrame(per_subject_rows(result, width),
                                                     columns=["panel", "variant", "series", "subject", "value"])}
    for name in ("fig_information_a_ratio", "fig_information_v30_width"):
        out[name] = out[name].rename(columns={"panel": "part", "value": "a q95/q05" if "ratio" in name else
                                              "V30 90 % width (mL)"})
    return {k: _no_missing(v) for k, v in out.items()}


def captions(result: Mapping) -> dict:
    """A note under each figure of the report."""
    return {"fig_information_a_ratio": "A marker per SYNTHETIC subject, a bar at the median over subjects; log "
                                       "scale. Narrowing is the reference variant's q95/q05 over this variant's, "
                                       "per subject.",
            "fig_information_v30_width": "A marker per SYNTHETIC subject, a bar at the median over subjects; "
                                         "variants without V30 intervals are left out."}


def figures(result: Mapping) -> dict:
    """The study's figures by name (:data:`TITLES`); ``fig_information_v30_width`` only where some run has V30."""
    from lvcore.viz.information_figures import per_variant_figure
    from lvcore.viz.report_figures import table_figure

    tag = _n_text(result)
    out = {"fig_information_a_ratio": per_variant_figure(
        per_subject_rows(result, a_ratio), panels=list(PARTS), panel_titles=PARTS, log_y=True,
        yaxis_title="a: q95 / q05 (log scale)",
        title=f"{TITLES['fig_information_a_ratio']}<br><sup>{tag}</sup>")}
    v30 = per_subject_rows(result, width)
    if v30:
        out["fig_information_v30_width"] = per_variant_figure(
            v30, panels=list(PARTS), panel_titles=PARTS, yaxis_title="V30: q95 − q05 (mL)",
            title=f"{TITLES['fig_information_v30_width']}<br><sup>{tag}</sup>")
    tabs = tables(result)
    for name in ("table_information_variants", "verdicts", "runs"):
        out[name] = table_figure(tabs[name], title=f"{TITLES[name]}<br><sup>{tag}</sup>")
    return out


# ============================================================================ command line
def add_study_parser(study_subparsers) -> None:
    """``lvcore study information`` (the runner's parser, :mod:`lvcore.studies.information_runner`)."""
    from lvcore.studies.information_runner import add_parser as _add

    _add(study_subparsers)


__all__ = ["RESULT_FILE", "COMMAND", "SYNTHETIC_LABEL", "TITLES", "MISSING", "PARTS", "load", "source_line",
           "tables", "figures", "captions", "incomplete_text", "variant_labels", "variant_rows", "verdict_rows",
           "run_rows", "per_subject_rows", "a_ratio", "covered", "width", "add_study_parser"]
