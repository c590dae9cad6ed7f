"""The findings' statistics: CIs resample the independent unit (volunteers, patients, test sets), fits on a bound
are left out, and docs/studies.md's generated blocks and quoted CIs are what the shipped JSON gives."""
import re
from pathlib import Path

import numpy as np
import pytest

from lvcore.studies import findings as fd
from lvcore.studies import mismatch as mm

DOCS = Path(__file__).resolve().parents[1] / "docs" / "studies.md"


def test_cluster_bootstrap_sees_the_spread_between_volunteers_that_pooling_hides():
    """Six volunteers whose iid σ_S differ (fixed mismatch patterns) with little noise each: the pooled
    data-set CI is narrow, the volunteer CI is as wide as the spread between volunteers."""
    rng = np.random.default_rng(0)
    per_vol = {}
    for i, level in enumerate((0.03, 0.033, 0.036, 0.045, 0.05, 0.06)):
        rec = {m: {"coverage": [1.0] * 20, "output_error": list(0.01 + 0.001 * rng.random(20)),
                   "min_ess": [300.0] * 20, "max_rhat": [1.0] * 20} for m in mm.MODELS}
        rec["iid"]["sigma_s"] = list(level + 0.0005 * rng.standard_normal(20))
        rec["discrepancy"]["sigma_s"] = list(0.03 + 0.0005 * rng.standard_normal(20))
        per_vol[f"HV{i + 1}"] = rec
    row = mm.summarise({("base", 1.0): per_vol}, {("base", 1.0): {"mean": 0.05, "by_volunteer": {}}})[0]
    assert set(row["per_volunteer"]) == set(per_vol) and len(row["per_volunteer"]["HV1"]["iid_sigma_s"]) == 20
    pooled = row["iid_sigma_s_inflation"]
    t = fd.mismatch_dose_tests({"rows": [row], "sampler": {"num_chains": 2}})[0]
    clustered = t["f1"]
    assert clustered["n"] == 6 and pooled["n"] == 120
    assert clustered["value"] == pytest.approx(pooled["value"], rel=1e-4)  # per-volunteer values: 5 digits
    width = lambda b: b["ci"][1] - b["ci"][0]  # noqa: E731
    assert width(clustered) > 1.5 * width(pooled)
    assert set(clustered["unit_values"]) == set(per_vol)


def _fits(n_patients=6, pc_better=True, bound_patient=None):
    ops = ("op1", "op2", "op3")
    out = []
    for p in range(n_patients):
        mains = ops if p == 0 else (ops[p % 3],)  # patient 0 has three mains: more cases, still one unit
        for m in mains:
            for g in [o for o in ops if o != m] + ["pc5", "pc10"]:
                pc = g.startswith("pc")
                rmse = (0.001 if pc_better else 0.003) if pc else 0.002
                theta = [0.6, 1.3, 1.0, 3.6]
                if bound_patient == p and pc:
                    theta = [0.05, 1.3, 1.0, 3.6]  # a on its lower bound
                out.append({"patient": f"P{p}", "main_operator": m, "test_geometry": g, "converged": True,
                            "output_rmse_refit": rmse, "theta_hat": theta})
    return {"fits": out}


def test_f5_resamples_patients_and_leaves_out_fits_on_a_bound():
    t = fd.f5_tests(_fits(), study="x")
    assert t["pc5"]["interior"]["n"] == 6 and t["pc5"]["call"] == "for"  # six patients, not the eight cases
    assert fd._f5_row(_fits(), "x", "operators.json")["verdict"] == "reproduced"
    assert fd._f5_row(_fits(pc_better=False), "x", "operators.json")["verdict"] == "refuted"
    t = fd.f5_tests(_fits(bound_patient=0), study="x")
    assert t["n_excluded"] == 6 and t["pc5"]["interior"]["n"] == 5 and t["pc5"]["all"]["n"] == 6
    t = fd.f5_tests(_fits(n_patients=4), study="x")
    assert t["pc5"]["call"] is None  # fewer than N_MIN patients: no call


def test_f6_counts_volunteers_and_leaves_out_fits_on_the_box_edge():
    def pair(cut, free_alpha=-45.0, theta=None):
        th = theta or {"a": 1.0, "b": 2.0, "af": 1.5, "bf": 3.0}
        return ({"lvv_abs_error_ml": 8.0, "theta": th},
                {"lvv_abs_error_ml": 8.0 - cut, "theta": th, "alpha_endo": free_alpha, "alpha_epi": 45.0})
    pairs = {f"V{i}": pair(2.0 + 0.1 * i) for i in range(6)}
    t = fd.f6_tests(pairs)
    assert t["call"] == "for" and t["n_interior"] == 6
    pairs["V0"] = pair(2.0, free_alpha=-90.0)  # the free angle on its bound
    t = fd.f6_tests(pairs)
    assert t["excluded"] == ["V0"] and t["n_interior"] == 5 and t["call"] == "for"
    pairs["V1"] = pair(2.0, theta={"a": 0.1, "b": 2.0, "af": 1.5, "bf": 3.0})  # a stiffness on the BO box
    t = fd.f6_tests(pairs)
    assert t["n_interior"] == 4 and t["call"] is None and t["all"]["n"] == 6
    assert fd.bo_on_bound({"a": 10.0, "b": 2.0}) == ["a"] and fd.bo_on_bound({"a": 5.0}, -30.0, 90.0, True) == ["alpha_epi"]


@pytest.fixture(scope="module")
def shipped():
    return fd.load()


def test_shipped_findings_table(shipped):
    rows = fd.verdicts(shipped)
    assert {r["verdict"] for r in rows} <= set(fd.VERDICTS)
    names = [r["finding"] for r in rows]
    assert names[:3] == ["F1", "F2", "F3"]
    assert {"F1 (direct replication)", "F2 (direct replication)", "F3 (direct replication)"} <= set(names)
    rep = {r["finding"]: r for r in rows}
    assert rep["F1 (direct replication)"]["source"] == "fibre_discrepancy.json"
    assert rep["F5 (first operator model)"]["unit"].endswith("patients")
    # every decided row says what decided it; none rests on pooled data sets, one chain or a stress test
    for t in fd.mismatch_dose_tests(shipped["mismatch"]):
        if t["deciding"]:
            assert t["range"] == "realistic" and t["chains"] >= 2 and t["unit"] == "volunteers"
    for r in rows:
        if r["verdict"] != "not shown":
            assert "pooled" not in r["unit"] and "chain" not in r["why"]
    assert set(fd.tables(shipped)) == set(fd.TITLES)


def _block(text, begin, end):
    assert text.count(begin) == 1 and text.count(end) == 1, begin
    return text.split(begin)[1].split(end)[0].strip()


def test_docs_blocks_are_the_shipped_json(shipped):
    doc = DOCS.read_text()
    assert _block(doc, fd.DOCS_BEGIN, fd.DOCS_END) == fd.docs_markdown(shipped).strip(), \
        "run python scripts/ship_mismatch.py --docs-only"
    assert _block(doc, fd.PROSE_BEGIN, fd.PROSE_END) == fd.prose_markdown(shipped).strip(), \
        "run python scripts/ship_mismatch.py --docs-only"


def test_prose_quotes_the_volunteer_ci_where_per_volunteer_values_are_shipped(shipped):
    """A dose whose row ships per-volunteer values is read with its cluster-bootstrap CI (marked ᵛ) and named in
    the CI bullet; the others keep the pooled CI over data sets."""
    import copy

    rng = np.random.default_rng(1)
    per_vol = {}
    for i, level in enumerate((0.036, 0.04, 0.045, 0.05, 0.055)):
        rec = {m: {"coverage": [1.0] * 20, "output_error": list(0.01 + 0.001 * rng.random(20)),
                   "min_ess": [300.0] * 20, "max_rhat": [1.0] * 20} for m in mm.MODELS}
        rec["iid"]["sigma_s"] = list(level + 0.0005 * rng.standard_normal(20))
        rec["discrepancy"]["sigma_s"] = list(0.03 + 0.0005 * rng.standard_normal(20))
        per_vol[f"HV{i + 1}"] = rec
    base = mm.summarise({("base", 1.0): per_vol}, {("base", 1.0): {"mean": 0.03, "min": 0.02, "max": 0.04,
                                                                     "by_volunteer": {}}})[0]
    res = copy.deepcopy(shipped)
    res["mismatch"].pop("check", None)   # the main run's rows only, none with per-volunteer values but base's
    res["mismatch"]["rows"] = [base if (r["source"], r["dose"]) == ("base", 1.0) else
                               {k: v for k, v in r.items() if k != "per_volunteer"} for r in res["mismatch"]["rows"]]
    text = fd.prose_markdown(res)
    t = next(t for t in fd.mismatch_dose_tests(res["mismatch"]) if t["source"] == "base")
    assert t["unit"] == "volunteers" and t["f1"]["ci"] != base["iid_sigma_s_inflation"]["ci"]
    line = next(x for x in text.splitlines() if x.startswith("* The clamped base"))
    assert f"[{t['f1']['ci'][0]:.2f}, {t['f1']['ci'][1]:.2f}]ᵛ" in line
    assert "per-volunteer values shipped for 1 of" in text and ": base 1)" in text
    assert "ᵛ" not in next(x for x in text.splitlines() if x.startswith("* Heterogeneity"))


CI = re.compile(r"-?\d+\.\d+\s*×?\s*\[-?\d+\.\d+,\s*-?\d+\.\d+\]")


def test_cis_quoted_in_the_hand_written_prose_are_in_the_generated_blocks(shipped):
    """The mismatch and findings sections of docs/studies.md may quote a CI in hand-written prose only if the
    generated blocks (hence the shipped JSON) give it; stale copies fail here."""
    doc = DOCS.read_text()
    start = doc.index("## Model–data mismatch dose–response")
    stop = doc.index("## F4/F5 with realistic operators")
    section = doc[start:stop]
    generated = " ".join([mm.docs_markdown(shipped["mismatch"]), fd.prose_markdown(shipped), fd.docs_markdown(shipped)])
    hand = section
    for begin, end in ((mm.DOCS_BEGIN, mm.DOCS_END), (fd.PROSE_BEGIN, fd.PROSE_END), (fd.DOCS_BEGIN, fd.DOCS_END)):
        hand = hand.split(begin)[0] + hand.split(end)[1]
    norm = lambda s: re.sub(r"\s+", " ", s.replace("×", "× ").replace("−", "-")).replace("× ", "×")  # noqa: E731
    quoted = [norm(m) for m in CI.findall(hand)]
    missing = [q for q in quoted if q not in norm(generated)]
    assert not missing, f"hand-written CIs not in the generated blocks: {missing}"
    for stale in ("1.71× [1.66, 1.81]", "1 volunteer (HV1)", "[1.32, 1.47]", "0.0108 [0.0082, 0.0126]"):
        assert stale not in section


@pytest.mark.parametrize("stat", [np.median, np.mean])
def test_vectorised_cluster_bootstrap_equals_the_loop_over_resamples(stat):
    """The pooled median/mean bootstrap is vectorised (the shipped mismatch rows have 100 values in 5 units at
    179 CIs a page render); it must give the loop's resamples' CI: the median exactly (ties included), the
    mean to rounding."""
    from lvcore.studies._common import bootstrap_ci
    from lvcore.studies.findings_rule import cluster_boot

    rng = np.random.default_rng(7)
    for trial in range(40):
        units = {f"u{i}": list(np.round(rng.normal(size=rng.integers(1, 25)), 1)) for i in range(rng.integers(1, 7))}
        fast = cluster_boot(units, stat=stat, n_boot=300, seed=trial)
        vals = {k: np.asarray(v) for k, v in units.items()}
        slow = bootstrap_ci(list(vals), lambda names: float(stat(np.concatenate([vals[k] for k in names]))),
                            n_boot=300, seed=trial)
        assert fast["value"] == slow["value"] and fast["n"] == slow["n_units"]
        if slow["ci"] is None:
            assert fast["ci"] is None
        elif stat is np.median:
            assert fast["ci"] == slow["ci"]
        else:
            assert fast["ci"] == pytest.approx(slow["ci"], rel=1e-12, abs=1e-14)


def test_the_real_lv_is_a_sixth_unit_in_a_sensitivity_ci_only(shipped):
    """Where the real LV was fitted at a volunteers' dose and budget, F1's CI is also given with it as one more
    unit (its values come from its own subject emulator); the calls and verdicts use the volunteers only."""
    mm_result = shipped["mismatch"]
    real = {(r["source"], r["dose"]) for r in mm_result["real_lv"]["rows"]}
    tests = fd.mismatch_dose_tests(mm_result)
    with_real = [t for t in tests if t["f1_with_real_lv"]]
    assert {(t["source"], t["dose"]) for t in with_real} == real
    for t in with_real:
        assert t["f1_with_real_lv"]["n"] == t["n_units"] + 1 and "REAL-LV" in t["f1_with_real_lv"]["unit_values"]
        assert "REAL-LV" not in t["f1"]["unit_values"]
    without = {**mm_result, "real_lv": None}
    assert [t["calls"] for t in fd.mismatch_dose_tests(without)] == [t["calls"] for t in tests]
    assert "With the real LV as one more unit (6 units;" in fd.prose_markdown(shipped)
