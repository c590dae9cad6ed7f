"""How well do the shipped fibre-angle BO fits fit, against the SYNTHETIC volunteers' own truth?

    python benchmarks/bo_fit_vs_truth.py          # the shipped assets/studies/bo_fibres.json

For each volunteer and mode (fixed angles, free angles) it prints the likelihood-weighted residual sum of squares
``chi2 = (r_V / sigma_V)^2 + sum_i (r_i / sigma_S)^2`` (sigma_V = 5 mL, sigma_S = 0.03, the volunteers' noise
levels) at the BO's best point (its recorded LVV and 24 strain residuals) and at the volunteer's hidden truth
(hidden theta and angles: the residual there is the data's noise, recorded with the volunteer), the LVV error of
each, and whether the best point has a parameter on the box's bound (the findings' rule,
:data:`lvcore.studies.findings_rule.BOUND_TOL`).

The question it answers: are the fits that end on a bound a budget artefact? If the recorded best point already
fits the data about as well as the truth does (chi2 within a few units, the spread of a chi2 with 25 degrees of
freedom being about 7), a larger budget can only move along a valley the data do not resolve; where in it the
optimum lands, a bound included, is set by the noise. Nothing is simulated; the volunteers are SYNTHETIC.
"""
from __future__ import annotations

import json
import sys

import numpy as np

from lvcore.domain.conditions import SIGMA_S, SIGMA_V_ML


def fit_vs_truth(entries, truth: dict) -> list[dict]:
    """One record per BO entry: ``subject``, ``mode``, ``chi2_best``, ``chi2_truth``, ``lvv_error_best_ml``,
    ``lvv_error_truth_ml``, ``on_bound`` (the parameters on the box's bound)."""
    from lvcore.studies.findings_rule import BO_THETA_BOX, BOUND_TOL
    from lvcore.core.space import ANGLE_BOUNDS

    w = np.r_[1.0 / SIGMA_V_ML ** 2, np.full(24, 1.0 / SIGMA_S ** 2)]
    out = []
    for e in entries:
        t = truth[e["subject"]]
        noise = np.asarray(t["noise"], float)
        res = np.r_[e["lvv_model_ml"] - e["lvv_measured_ml"], e["strain_residuals"]]
        box = {**{k: BO_THETA_BOX for k in e["theta"]}, **ANGLE_BOUNDS}
        vals = {**e["theta"], "alpha_endo": e["alpha_endo"], "alpha_epi": e["alpha_epi"]}
        keys = list(e["theta"]) + (["alpha_endo", "alpha_epi"] if e["mode"] == "free" else [])
        on = [k for k in keys if min(abs(vals[k] - box[k][0]), abs(vals[k] - box[k][1]))
              <= BOUND_TOL * (box[k][1] - box[k][0])]
        out.append({"subject": e["subject"], "mode": e["mode"], "chi2_best": float(np.sum(w * res ** 2)),
                    "chi2_truth": float(np.sum(w * noise ** 2)), "lvv_error_best_ml": float(abs(res[0])),
                    "lvv_error_truth_ml": float(abs(noise[0])), "on_bound": on})
    return out


def main() -> int:
    from lvcore.resources import asset_path

    entries = json.loads(asset_path("studies", "bo_fibres.json").read_text())
    truth = {v["subject"]: v for v in json.loads(asset_path("volunteers", "truth", "SYNTHETIC_volunteers_truth.json")
                                                   .read_text())["volunteers"]}
    rows = fit_vs_truth(entries, truth)
    print("| volunteer (SYNTHETIC) | mode | chi2 at the BO's best | chi2 at the truth | LVV error best / truth (mL) "
          "| on a bound |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['subject']} | {r['mode']} | {r['chi2_best']:.1f} | {r['chi2_truth']:.1f} | "
              f"{r['lvv_error_best_ml']:.1f} / {r['lvv_error_truth_ml']:.1f} | {', '.join(r['on_bound']) or '-'} |")
    below = sum(r["chi2_best"] < r["chi2_truth"] for r in rows)
    gap = [r["chi2_best"] - r["chi2_truth"] for r in rows]
    print(f"\n{below} of {len(rows)} fits have a lower chi2 than the truth; chi2(best) - chi2(truth) spans "
          f"{min(gap):+.1f} to {max(gap):+.1f}; {sum(bool(r['on_bound']) for r in rows)} fits have a parameter on a bound")
    return 0


if __name__ == "__main__":
    sys.exit(main())
