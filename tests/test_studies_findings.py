"""Findings F1, F2, F3, F5, F6: the verdict rules on made-up study results (reproduced / not reproduced / refuted)."""
from lvcore.studies import findings as fd


def test_mismatch_verdicts_reproduced_not_reproduced_refuted(mismatch_result):
    rows = mismatch_result()["rows"]
    assert fd.f1_verdict(rows)["verdict"] == "reproduced" and "strain RMS 0.060" in fd.f1_verdict(rows)["dose"]
    f2 = fd.f2_verdict(rows)
    assert f2["verdict"] == "reproduced" and "dispersion 3" in f2["dose"]
    assert fd.f3_verdict(rows)["verdict"] == "reproduced"
    low = mismatch_result(doses=((0.01, 0.031, 0.008), (0.055, 0.033, 0.008)))["rows"]  # realistic dose, no inflation
    assert fd.f1_verdict(low)["verdict"] == "refuted" and "does not appear up to strain RMS 0.055" in fd.f1_verdict(low)["dose"]
    assert fd.f2_verdict(low)["verdict"] == "not reproduced" and "untestable" in fd.f2_verdict(low)["ci"]
    assert fd.f3_verdict(low)["verdict"] == "refuted"  # iid beats both at the realistic dose
    small = mismatch_result(doses=((0.01, 0.031, 0.01), (0.02, 0.032, 0.01)))["rows"]  # never reaches 0.05
    assert fd.f1_verdict(small)["verdict"] == "not reproduced" and fd.f3_verdict(small)["verdict"] == "not reproduced"


def test_f5_f6_verdicts_from_operators_and_bo_results():
    bo = {"entries": [{"subject": f"S{i}", "mode": m, "lvv_abs_error_ml": (10.0 if m == "fixed" else 2.0 + 0.1 * i)}
                      for i in range(8) for m in ("fixed", "free")]}
    assert fd.f6_verdict(bo)["verdict"] == "reproduced" and "8/8" in fd.f6_verdict(bo)["ci"]
    worse = {"entries": [{**e, "lvv_abs_error_ml": 20.0 - e["lvv_abs_error_ml"]} for e in bo["entries"]]}
    assert fd.f6_verdict(worse)["verdict"] == "refuted"
    ops = ("op1", "op2", "op3")
    fits = [{"patient": p, "main_operator": m, "test_geometry": g,
             "output_rmse_refit": {"pc5": 0.001, "pc10": 0.001}.get(g, 0.002)}
            for p in ("P1", "P2", "P3") for m in ops for g in [o for o in ops if o != m] + ["pc5", "pc10"]]
    assert fd.f5_verdict({"fits": fits})["verdict"] == "reproduced"
    fits = [{**f, "output_rmse_refit": 0.003 if f["test_geometry"].startswith("pc") else 0.002} for f in fits]
    assert fd.f5_verdict({"fits": fits})["verdict"] == "refuted"


def test_f1_to_f3_use_the_convergence_checks_rows(mismatch_result):
    """Where the check refitted a dose at a larger budget, F1-F3 are decided on the check's row (and say so)."""
    res = mismatch_result()
    base = {"mismatch": res, "operators": None, "bo_fibres": None, "operators_realistic": None, "bo_mismatch": None}
    assert fd.verdicts(base)[0]["verdict"] == "reproduced"
    no_f1 = dict(res["rows"][2], iid_sigma_s_inflation={"value": 1.1, "ci": [1.0, 1.2], "n": 20}, f1=False)
    checked = {**res, "check": {"sampler": {"num_chains": 2, "num_warmup": 300, "num_samples": 300},
                                "rows": [no_f1]}}
    f1 = fd.verdicts({**base, "mismatch": checked})[0]
    assert f1["verdict"] == "refuted" and "2 × (300 + 300)" in f1["ci"]  # the realistic dose, CI below 1.5
