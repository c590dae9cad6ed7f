"""The findings' deciding tests and their rows: F1–F3 per mismatch dose and in the direct replication, F5 on the
operator studies, F6 on the fibre-angle BOs; the findings table (:func:`verdicts`) and the per-dose table
(:func:`dose_rows`).

Part of :mod:`lvcore.studies.findings` (the study; its docstring states the rule).
"""
from __future__ import annotations

import numpy as np

from lvcore.domain.conditions import SIGMA_S
from lvcore.studies.findings_rule import (BO_THETA_BOX, BOUND_TOL, CLAIMS, F1_COLUMN, F1_INFLATION, F2_BAND,
                                          F5_SHARE, MIN_CHAINS, N_MIN, RHAT_SHARE_MAX, TESTABLE_RMS, call, cluster_boot,
                                          combine, dose_range, fmt_ci)
from lvcore.studies.registry import STUDIES

#: The result file of each study the findings read (study module -> file), from the registry.
SOURCES = {STUDIES[n].module: STUDIES[n].result_file for n in STUDIES["findings"].inputs}


def _chains(row: dict, result: dict) -> int:
    smp = (result.get("check") or {}).get("sampler") if row.get("checked") else result.get("sampler")
    return int((smp or {}).get("num_chains", 0))


def _iid_inflation(per_unit: dict) -> dict:
    """Unit -> its data sets' iid σ_S / :data:`SIGMA_S` (fits without one left out): F1's values."""
    return {u: np.asarray([x for x in d["iid_sigma_s"] if x is not None]) / SIGMA_S for u, d in per_unit.items()}


def _real_lv_units(result: dict) -> dict:
    """The real LV's per-data-set values (``result["real_lv"]``) by (source, dose, sampler budget text): a sixth
    unit beside the volunteers for a sensitivity CI (``f1_with_real_lv``); never in a verdict (one geometry, its
    own subject emulator)."""
    from lvcore.studies.mismatch import budget_text

    rl = result.get("real_lv") or {}
    budget = budget_text(rl.get("sampler"))
    return {(r["source"], r["dose"], budget): r["per_volunteer"] for r in rl.get("rows", []) if r.get("per_volunteer")}


def mismatch_dose_tests(result: dict) -> list[dict]:
    """One record per mismatch dose (the check's row where it refitted the dose): whether it decides, and why.

    Each record: ``source``, ``dose``, ``budget``, ``chains``, ``strain_rms``, ``range`` (label) and
    ``range_reason``, ``testable``, ``rhat_share`` (per likelihood), ``ess_median`` (per likelihood),
    ``unit`` ("volunteers" with per-volunteer values, else "data sets"), ``n_units``, the estimates
    (``f1``, ``f2``, ``f3_disc``, ``f3_vol``: cluster-bootstrap CIs where the per-volunteer values are
    shipped, else the pooled CIs of the study), ``calls`` {F1, F2, F3}, ``deciding`` and ``why_not`` (the
    reasons it does not decide).
    """
    from lvcore.studies.mismatch import verdict_rows

    real = _real_lv_units(result)
    out = []
    for row in verdict_rows(result):
        m = (row.get("strain_rms_mismatch") or {}).get("mean") or 0.0
        label, reason = dose_range(row["source"], row["dose"])
        diag = row.get("diagnostics") or {}
        rhat = {k: d.get("share_rhat_over_1_05") for k, d in diag.items()}
        ess = {k: d.get("min_ess_median") for k, d in diag.items()}
        chains = _chains(row, result)
        pv = row.get("per_volunteer")
        if pv:
            f1 = cluster_boot(_iid_inflation(pv))
            f2 = cluster_boot({v: d["discrepancy_sigma_s"] for v, d in pv.items()})

            def gap(a, b):
                return {v: np.asarray(d["output_error"][a], dtype=float) - np.asarray(d["output_error"][b], dtype=float)
                        for v, d in pv.items()}
            f3d, f3v = cluster_boot(gap("iid", "discrepancy")), cluster_boot(gap("iid", "volume"))
            unit, n_units = "volunteers", len(pv)
            extra = real.get((row["source"], row["dose"], row.get("budget")))
            f1_real = cluster_boot(_iid_inflation({**pv, **extra})) if extra else None
        else:
            f1, f2 = row["iid_sigma_s_inflation"], row["discrepancy_sigma_s"]
            g = row["output_error_gap"]
            f3d, f3v = g["iid_minus_discrepancy"], g["iid_minus_volume"]
            unit, n_units = "data sets", int(row.get("n_datasets") or 0)
            f1_real = None
        why, keys = [], []
        if label != "realistic":
            why.append(label), keys.append(label)
        testable = m >= TESTABLE_RMS
        if not testable:
            why.append(f"strain RMS {m:.3f} < {TESTABLE_RMS:.3f}"), keys.append("too small to show the claim")
        if chains < MIN_CHAINS:
            why.append(f"{chains} chain"), keys.append(f"fewer than {MIN_CHAINS} chains")
        worst = max((v for v in rhat.values() if v is not None), default=None)
        if worst is None or worst > RHAT_SHARE_MAX:
            why.append("R-hat > 1.05 in " + (f"{100 * worst:.0f} %" if worst is not None else "an unknown share"))
            keys.append(f"R-hat > 1.05 in more than {100 * RHAT_SHARE_MAX:.0f} % of data sets")
        if unit != "volunteers":
            why.append("CI over data sets, not volunteers"), keys.append("no per-volunteer values shipped")
        elif n_units < N_MIN:
            why.append(f"{n_units} volunteers < {N_MIN}"), keys.append(f"fewer than {N_MIN} volunteers")
        c1 = call(f1["ci"], F1_INFLATION) if f1.get("ci") else None
        lo_b, hi_b = F2_BAND[0] * SIGMA_S, F2_BAND[1] * SIGMA_S
        c2 = None
        if c1 == "for" and f2.get("ci"):
            lo, hi = f2["ci"]
            c2 = "for" if lo_b <= lo and hi <= hi_b else "against" if (lo > hi_b or hi < lo_b) else "open"
        c3 = None
        if f3d.get("ci") and f3v.get("ci"):
            cs = (call(f3d["ci"], 0.0), call(f3v["ci"], 0.0))
            c3 = "against" if "against" in cs else "for" if cs == ("for", "for") else "open"
        out.append({"source": row["source"], "dose": row["dose"], "budget": row.get("budget"), "chains": chains,
                    "strain_rms": m, "range": label, "range_reason": reason, "testable": testable,
                    "rhat_share": rhat, "ess_median": ess, "unit": unit, "n_units": n_units,
                    "f1": f1, "f2": f2, "f3_disc": f3d, "f3_vol": f3v, "f1_with_real_lv": f1_real,
                    "calls": {"F1": c1, "F2": c2, "F3": c3},
                    "deciding": not why, "why_not": why, "why_keys": keys})
    return out


def _dose_name(t: dict) -> str:
    return f"{t['source']} {t['dose']:g} (strain RMS {t['strain_rms']:.3f}; {t['budget']})"


def _mismatch_row(finding: str, tests: list[dict]) -> dict:
    key = {"F1": "f1", "F2": "f2", "F3": "f3_disc"}[finding]
    fmt, unit = {"F1": (".2f", "×"), "F2": (".4f", ""), "F3": (".4f", "")}[finding]

    def est(t):
        if finding == "F3":
            return (f"iid − discrepancy {fmt_ci(t['f3_disc'], fmt)}, iid − volume {fmt_ci(t['f3_vol'], fmt)} at "
                    f"{_dose_name(t)}")
        return f"{fmt_ci(t[key], fmt, unit)} at {_dose_name(t)}"

    deciding = [t for t in tests if t["deciding"] and t["calls"][finding] is not None]
    verdict = combine(t["calls"][finding] for t in deciding)
    realistic = [t for t in tests if t["range"] == "realistic"]
    n_stress = sum(t["range"] != "realistic" for t in tests)
    if deciding:
        ci = "; ".join(f"{est(t)}: {t['calls'][finding]}" for t in deciding)
        why = f"{len(deciding)} deciding dose(s)"
    else:
        top = max(realistic, key=lambda t: t["strain_rms"]) if realistic else None
        ci = (f"largest realistic dose: {est(top)} (CI over {top['unit']})" if top else "no realistic dose")
        if finding == "F2" and not any(t["calls"]["F1"] == "for" for t in realistic):
            ci += "; untestable where iid does not inflate σ_S"
        counts = {}
        for t in realistic:
            for k in t["why_keys"]:
                counts[k] = counts.get(k, 0) + 1
        why = (f"no deciding dose; of {len(realistic)} realistic doses: "
               + "; ".join(f"{n} {k}" for k, n in counts.items()) if realistic else "no deciding dose: no realistic dose")
    cited = sorted({t["source"] for t in realistic})
    return {"finding": finding, "verdict": verdict, "ci": ci,
            "unit": "volunteers" if all(t["unit"] == "volunteers" for t in tests) else "data sets (pooled)",
            "doses": (f"realistic: {', '.join(cited) or 'none'} (strain RMS ≤ "
                      f"{max((t['strain_rms'] for t in realistic), default=0):.3f}); {n_stress} of {len(tests)} "
                      f"doses stress tests or uncited"),
            "source": SOURCES["mismatch"], "why": why}


# ----------------------------------------------------------------------------
# F1-F3: the direct replication (the chapter's 12 angle sets)
# ----------------------------------------------------------------------------
def replication_tests(fd: dict) -> dict:
    """F1-F3 on the fibre-discrepancy study: each of its test sets is a unit (one geometry, as the chapter)."""
    sets = fd.get("sets") or []
    units = {f"set{s['set']}": s for s in sets}
    iid = cluster_boot({k: [s["models"]["iid"]["sigma_s"]["median"] / SIGMA_S] for k, s in units.items()})
    disc = cluster_boot({k: [s["models"]["discrepancy"]["sigma_s"]["median"]] for k, s in units.items()})

    def gap(a, b):
        return cluster_boot({k: [s["models"][a]["abs_error_median"] - s["models"][b]["abs_error_median"]]
                             for k, s in units.items()})
    g_d, g_v = gap("iid", "discrepancy"), gap("iid", "volume")
    rhat = {m: float(np.mean([s["models"][m]["rhat_max"] > 1.05 for s in sets])) if sets else None
            for m in ("volume", "iid", "discrepancy")}
    chains = int((fd.get("sampler") or {}).get("num_chains", 0))
    why = []
    if chains < MIN_CHAINS:
        why.append(f"{chains} chain")
    if max((v for v in rhat.values() if v is not None), default=1.0) > RHAT_SHARE_MAX:
        why.append("R-hat > 1.05")
    if len(sets) < N_MIN:
        why.append(f"{len(sets)} sets < {N_MIN}")
    c1 = call(iid["ci"], F1_INFLATION) if iid["ci"] else None
    c2 = None
    if c1 == "for" and disc["ci"]:
        lo, hi = disc["ci"]
        lo_b, hi_b = F2_BAND[0] * SIGMA_S, F2_BAND[1] * SIGMA_S
        c2 = "for" if lo_b <= lo and hi <= hi_b else "against" if (lo > hi_b or hi < lo_b) else "open"
    cs = (call(g_d["ci"], 0.0), call(g_v["ci"], 0.0)) if g_d["ci"] and g_v["ci"] else None
    c3 = None if cs is None else "against" if "against" in cs else "for" if cs == ("for", "for") else "open"
    return {"f1": iid, "f2": disc, "f3_disc": g_d, "f3_vol": g_v, "rhat_share": rhat, "chains": chains,
            "n_sets": len(sets), "calls": {"F1": c1, "F2": c2, "F3": c3}, "deciding": not why, "why_not": why,
            "sampler": fd.get("sampler") or {}}


def _replication_rows(fd: dict | None) -> list[dict]:
    if not fd:
        return []
    t = replication_tests(fd)
    smp = t["sampler"]
    conv = (f"{smp.get('num_chains', '?')} × ({smp.get('num_warmup', '?')} + {smp.get('num_samples', '?')}); "
            "share of sets with R-hat > 1.05 volume / iid / discrepancy "
            + " / ".join(f"{100 * t['rhat_share'][m]:.0f} %" for m in ("volume", "iid", "discrepancy")))
    dose = ("the chapter's design: angles (−60°, 90°), (−30°, 60°), (0°, 90°) × 4 θ against the emulator's "
            "(−60°, 60°), one SYNTHETIC geometry")
    ests = {"F1": f"{F1_COLUMN} {fmt_ci(t['f1'], '.2f', '×')}",
            "F2": f"discrepancy σ_S {fmt_ci(t['f2'], '.4f')}" + ("" if t["calls"]["F1"] == "for" else
                                                             "; untestable where iid does not inflate σ_S"),
            "F3": (f"iid − discrepancy {fmt_ci(t['f3_disc'], '.4f')}, iid − volume {fmt_ci(t['f3_vol'], '.4f')} "
                   "(per-set median |η error|)")}
    rows = []
    for f in ("F1", "F2", "F3"):
        c = t["calls"][f]
        verdict = combine([c]) if t["deciding"] else "not shown"
        rows.append({"finding": f"{f} (direct replication)", "verdict": verdict,
                     "ci": ests[f] + (f": {c}" if c else ""), "unit": f"{t['n_sets']} test sets",
                     "doses": dose + "; " + conv, "source": SOURCES["fibre_discrepancy"],
                     "why": ("; ".join(t["why_not"]) if not t["deciding"] else "deciding" if c is not None
                             else "untestable: F1 is not for")})
    return rows


# ----------------------------------------------------------------------------
# F5: PC refits vs operators, resampled over patients, fits on a bound left out
# ----------------------------------------------------------------------------
def f5_tests(result: dict | None, *, study: str) -> dict | None:
    """F5 per PC count from a study's fits: comparisons with both fits converged and interior, over patients.

    Returns ``{"pc5": {...}, "pc10": {...}, "n_fits", "n_excluded"}`` with, per PC count, ``all`` (every
    converged fit) and ``interior`` (fits on a bound left out) cluster bootstraps over patients of the share
    of comparisons no worse, and the call of the interior one.
    """
    from lvcore.studies.operators import on_bound

    if not result:
        return None
    fits = [f for f in result.get("fits", []) if f.get("output_rmse_refit") is not None and f.get("converged", True)]
    if not fits:
        return None
    by = {(f["patient"], f["main_operator"], f["test_geometry"]): f for f in fits}
    ops = sorted({f["test_geometry"] for f in fits if not f["test_geometry"].startswith("pc")}
                 | {f["main_operator"] for f in fits})

    def bound(f):
        return f.get("on_bound") if f.get("on_bound") is not None else on_bound(f["theta_hat"])

    out = {"n_fits": len(fits), "n_excluded": sum(bool(bound(f)) for f in fits), "study": study}
    for pc in ("pc5", "pc10"):
        res = {}
        for mode in ("all", "interior"):
            per_patient = {}
            for (p, m, t), f in by.items():
                if t != pc or (mode == "interior" and bound(f)):
                    continue
                for o in ops:
                    g = by.get((p, m, o))
                    if o == m or g is None or (mode == "interior" and bound(g)):
                        continue
                    per_patient.setdefault(p, []).append(float(f["output_rmse_refit"] <= g["output_rmse_refit"]))
            res[mode] = cluster_boot(per_patient, stat=np.mean) if per_patient else None
        b = res["interior"]
        res["call"] = call(b["ci"], F5_SHARE) if b and b["ci"] and b["n"] >= N_MIN else None
        out[pc] = res
    return out


def _f5_row(result: dict | None, label: str, source: str) -> dict | None:
    t = f5_tests(result, study=label)
    if t is None:
        return None
    calls = [t[pc]["call"] for pc in ("pc5", "pc10") if t[pc]["call"]]
    parts = []
    for pc in ("pc5", "pc10"):
        a, b = t[pc]["all"], t[pc]["interior"]
        if b:
            parts.append(f"{pc} no worse in {_pct(b)} of comparisons (interior fits, {b['n']} patients"
                         f"{': ' + t[pc]['call'] if t[pc]['call'] else ''}; all fits {_pct(a)})")
    n_pat = max((t[pc]["interior"] or {}).get("n", 0) for pc in ("pc5", "pc10"))
    return {"finding": f"F5 ({label})", "verdict": combine(calls), "ci": "; ".join(parts),
            "unit": f"{n_pat} patients", "doses": "n/a: the mismatch is the operators' geometry",
            "source": source, "why": (f"{t['n_excluded']} of {t['n_fits']} fits on a bound left out"
                                      + ("" if calls else f"; fewer than {N_MIN} patients with interior fits"))}


def _pct(b: dict | None) -> str:
    if not b:
        return "n/a"
    return (f"{100 * b['value']:.0f} % [{100 * b['ci'][0]:.0f}, {100 * b['ci'][1]:.0f}]" if b.get("ci")
            else f"{100 * b['value']:.0f} %")


# ----------------------------------------------------------------------------
# F6: fixed vs free angles, per volunteer, fits on the box edge left out
# ----------------------------------------------------------------------------
def bo_on_bound(theta: dict, alpha_endo=None, alpha_epi=None, free: bool = False) -> list[str]:
    """Names of the BO fit's parameters on its box: θ in [0.1, 10], and when ``free`` the angles' bounds."""
    from lvcore.core.space import ANGLE_BOUNDS

    lo, hi = BO_THETA_BOX
    hit = [n for n, v in (theta or {}).items()
           if abs(v - lo) <= BOUND_TOL * abs(lo) or abs(v - hi) <= BOUND_TOL * abs(hi)]
    if free:
        for n, v in (("alpha_endo", alpha_endo), ("alpha_epi", alpha_epi)):
            if v is None:
                continue
            a, b = ANGLE_BOUNDS[n]
            if min(abs(v - a), abs(v - b)) <= BOUND_TOL * 90.0:
                hit.append(n)
    return hit


def f6_tests(pairs: dict) -> dict:
    """F6 from ``{volunteer: (fixed_fit, free_fit)}`` (each a dict with ``lvv_abs_error_ml``, ``theta`` and the
    angles): the mean LVV error fixed − free over the volunteers whose fits are both interior, bootstrapped over
    volunteers, and the same over all volunteers for comparison."""
    def diffs(only_interior):
        out = {}
        for v, (fx, fr) in pairs.items():
            if fx.get("lvv_abs_error_ml") is None or fr.get("lvv_abs_error_ml") is None:
                continue
            if only_interior and (bo_on_bound(fx.get("theta"))
                                  or bo_on_bound(fr.get("theta"), fr.get("alpha_endo"), fr.get("alpha_epi"), True)):
                continue
            out[v] = [fx["lvv_abs_error_ml"] - fr["lvv_abs_error_ml"]]
        return out
    d_all, d_int = diffs(False), diffs(True)
    b_all = cluster_boot(d_all, stat=np.mean) if d_all else None
    b_int = cluster_boot(d_int, stat=np.mean) if d_int else None
    c = None  # the claim is fixed − free > 0, strictly
    if b_int and b_int["ci"] and b_int["n"] >= N_MIN:
        lo, hi = b_int["ci"]
        c = "for" if lo > 0 else "against" if hi < 0 else "open"
    return {"all": b_all, "interior": b_int, "call": c, "n_all": len(d_all), "n_interior": len(d_int),
            "excluded": sorted(set(d_all) - set(d_int))}


def _f6_text(t: dict) -> str:
    b, a = t["interior"], t["all"]
    inner = (f"LVV error cut (fixed − free) {fmt_ci(b, '.2f', ' mL')} over {t['n_interior']} volunteers with "
             "interior fits" if b else "no volunteer with both fits interior")
    return inner + (f" (all {t['n_all']}: {fmt_ci(a, '.2f', ' mL')})" if a else "")


def _f6_rows(bo_mismatch: dict | None, bo_fibres: dict | None) -> list[dict]:
    from lvcore.studies.bo_mismatch import KINDS, POSTERIOR_KEY

    rows = []
    parts = [(bo_mismatch, "")] + ([(bo_mismatch[POSTERIOR_KEY], "; regularised BO")]
                                   if bo_mismatch and bo_mismatch.get(POSTERIOR_KEY) else [])
    for part, label in parts:
        if not part or not part.get("runs"):
            continue
        for kind in dict.fromkeys(r["kind"] for r in part["runs"]):
            pairs = {r["volunteer"]: (r["fixed"], r["free"]) for r in part["runs"]
                     if r["kind"] == kind and r.get("fixed") and r.get("free")}
            t = f6_tests(pairs)
            absorb = KINDS.get(kind, {}).get("absorbable")
            why = ([f"left out (a fit on the box edge): {', '.join(t['excluded'])}"] if t["excluded"] else [])
            if t["call"] is None:
                why.append(f"fewer than {N_MIN} volunteers with interior fits")
            rows.append({"finding": f"F6 (known mismatch: {kind}" + ("" if absorb else ", angles cannot absorb")
                         + label + ")", "verdict": combine([t["call"]]),
                         "ci": _f6_text(t) + (f": {t['call']}" if t["call"] else ""),
                         "unit": f"{t['n_interior']} volunteers",
                         "doses": KINDS.get(kind, {}).get("what", kind) + (
                             f"; {part['meta']['budget']['label']}; a weakly informative prior (not the chapter's "
                             "objective)" if label else ""),
                         "source": SOURCES["bo_mismatch"], "why": "; ".join(why) or "deciding"})
    if bo_fibres:
        entries = bo_fibres["entries"] if isinstance(bo_fibres, dict) else bo_fibres
        by = {(e["subject"], e["mode"]): e for e in entries}
        pairs = {s: (by[(s, "fixed")], by[(s, "free")]) for s, _ in by if (s, "fixed") in by and (s, "free") in by}
        t = f6_tests(pairs)
        why = ([f"left out (a fit on the box edge): {len(t['excluded'])} of {t['n_all']}"] if t["excluded"] else [])
        if t["call"] is None:
            why.append(f"fewer than {N_MIN} volunteers with interior fits")
        rows.append({"finding": "F6 (bundled volunteers)", "verdict": combine([t["call"]]),
                     "ci": _f6_text(t) + (f": {t['call']}" if t["call"] else ""),
                     "unit": f"{t['n_interior']} volunteers",
                     "doses": "hidden angles of the bundled volunteers (no designed mismatch)",
                     "source": SOURCES["bo_fibres"], "why": "; ".join(why) or "deciding"})
    return rows


# ----------------------------------------------------------------------------
# the table
# ----------------------------------------------------------------------------
COLUMNS = ("finding", "claim", "verdict", "ci", "unit", "doses", "source", "why")


def verdicts(result: dict) -> list[dict]:
    """One row per finding and source: ``finding``, ``claim``, ``verdict``, ``ci`` (estimate [90 % CI] and the
    call of each deciding test), ``unit`` (what the CI resamples), ``doses`` (range and convergence),
    ``source`` (the result file) and ``why`` (what decides, or why nothing does)."""
    rows = []
    tests = mismatch_dose_tests(result["mismatch"])
    rows += [_mismatch_row(f, tests) for f in ("F1", "F2", "F3")]
    rows += _replication_rows(result.get("fibre_discrepancy"))
    for r in (_f5_row(result.get("operators_realistic"), "realistic operators", SOURCES["operators_realistic"]),
              _f5_row(result.get("operators"), "first operator model", SOURCES["operators"])):
        if r:
            rows.append(r)
    rows += _f6_rows(result.get("bo_mismatch"), result.get("bo_fibres"))
    return [{"finding": r["finding"], "claim": CLAIMS[r["finding"].split(" ")[0]],
             **{k: r[k] for k in COLUMNS if k not in ("finding", "claim")}} for r in rows]


def dose_rows(result: dict) -> list[dict]:
    """The per-dose table: range, convergence, resampled unit and each finding's call at each dose."""
    out = []
    for t in mismatch_dose_tests(result["mismatch"]):
        rh = t["rhat_share"]
        out.append({"source": t["source"], "dose": t["dose"], "strain RMS": round(t["strain_rms"], 4),
                    "range": t["range"], "sampler": t["budget"],
                    "R-hat > 1.05 (volume / iid / discrepancy)": " / ".join(
                        "n/a" if rh.get(m) is None else f"{100 * rh[m]:.0f} %" for m in ("volume", "iid", "discrepancy")),
                    "ESS median": " / ".join("n/a" if t["ess_median"].get(m) is None else f"{t['ess_median'][m]:.0f}"
                                             for m in ("volume", "iid", "discrepancy")),
                    "CI over": f"{t['n_units']} {t['unit']}",
                    F1_COLUMN: fmt_ci(t["f1"], ".2f"),
                    "F1 with the real LV as a unit (sensitivity)": (fmt_ci(t["f1_with_real_lv"], ".2f")
                                                                    if t["f1_with_real_lv"] else "–"),
                    "calls F1 / F2 / F3": " / ".join(t["calls"][f] or "–" for f in ("F1", "F2", "F3")),
                    "deciding": "yes" if t["deciding"] else "no: " + "; ".join(t["why_not"])})
    return out


__all__ = ["SOURCES", "COLUMNS", "mismatch_dose_tests", "replication_tests", "f5_tests", "bo_on_bound", "f6_tests",
           "verdicts", "dose_rows"]
