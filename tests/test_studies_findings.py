"""Findings F1, F2, F3, F5, F6: the symmetric verdict rule on made-up study results (reproduced / not shown /
refuted), and which doses may decide (cited range, size, chains, R-hat, resampled unit)."""
import numpy as np
import pytest

from lvcore.studies import findings as fd
from lvcore.studies import mismatch as mm


def test_call_and_combine_are_symmetric():
    assert fd.call([1.6, 2.0], 1.5) == "for" and fd.call([1.1, 1.4], 1.5) == "against"
    assert fd.call([1.4, 1.6], 1.5) == "open"
    assert fd.call([-0.2, -0.1], 0.0, above=False) == "for" and fd.call([0.1, 0.2], 0.0, above=False) == "against"
    flip = {"for": "against", "against": "for", "open": "open"}
    swap = {"reproduced": "refuted", "refuted": "reproduced", "not shown": "not shown"}
    for calls in (["for"], ["for", "open"], ["against"], ["for", "against"], [], ["open"], ["against", "open", None]):
        v = fd.combine(calls)
        assert v in fd.VERDICTS
        assert fd.combine([flip.get(c) for c in calls]) == swap[v], calls  # swapping for/against swaps verdicts
    assert fd.combine(["for", "against"]) == "not shown" and fd.combine([]) == "not shown"


def test_dose_range_labels_need_a_citation():
    assert fd.dose_range("angles", 15.0)[0] == "realistic" and "Harrington" in fd.dose_range("angles", 15.0)[1]
    assert fd.dose_range("angles", 45.0)[0] == "stress test"
    assert fd.dose_range("base", 1.0)[0] == "realistic"
    for source in ("heterogeneity", "pericardium", "dispersion", "sheet"):
        if fd.PHYSIOLOGICAL_RANGES[source]["max"] is None:
            assert fd.dose_range(source, 0.01)[0] == "uncited"
    assert all(r["cite"] for r in fd.PHYSIOLOGICAL_RANGES.values() if r["max"] is not None)
    assert fd.TESTABLE_RMS == pytest.approx(0.03 * np.sqrt(1.25))


def _study(source, dose, *, rms, iid_sigma, disc_sigma=0.03, errs=(0.01, 0.02, 0.01), n_vol=6, chains=2,
           rhat=1.01, per_volunteer=True, seed=0):
    """A mismatch result of one dose over ``n_vol`` volunteers × 20 seeds (made-up per-data-set metrics)."""
    rng = np.random.default_rng(seed)
    per_vol = {}
    for i in range(n_vol):
        rec = {}
        for m, e in zip(mm.MODELS, errs):
            rec[m] = {"coverage": list(rng.uniform(0.5, 1, 20)), "output_error": list(abs(e + 0.001 * rng.standard_normal(20))),
                      "min_ess": list(rng.uniform(200, 300, 20)), "max_rhat": [rhat] * 20}
        rec["iid"]["sigma_s"] = list(iid_sigma + 0.001 * rng.standard_normal(20))
        rec["discrepancy"]["sigma_s"] = list(disc_sigma + 0.001 * rng.standard_normal(20))
        per_vol[f"HV{i + 1}"] = rec
    rms_rec = {"mean": rms, "min": rms, "max": rms, "by_volunteer": {f"HV{i + 1}": rms for i in range(n_vol)}}
    rows = mm.summarise({(source, dose): per_vol}, {(source, dose): rms_rec})
    if not per_volunteer:
        rows = [{k: v for k, v in r.items() if k != "per_volunteer"} for r in rows]
    return {"volunteers": list(per_vol), "seeds_per_dose": 20, "rows": rows,
            "sampler": {"num_chains": chains, "num_warmup": 300, "num_samples": 300}}


def _verdict(res, finding):
    return next(r for r in (fd._mismatch_row(f, fd.mismatch_dose_tests(res)) for f in ("F1", "F2", "F3"))
                if r["finding"] == finding)


def test_a_realistic_large_converged_dose_with_per_volunteer_values_decides_both_ways():
    big = _study("base", 1.0, rms=0.05, iid_sigma=0.06, disc_sigma=0.031, errs=(0.01, 0.03, 0.011))
    t = fd.mismatch_dose_tests(big)[0]
    assert t["deciding"] and t["unit"] == "volunteers" and t["n_units"] == 6
    assert _verdict(big, "F1")["verdict"] == "reproduced" and _verdict(big, "F2")["verdict"] == "reproduced"
    assert _verdict(big, "F3")["verdict"] == "reproduced"
    flat = _study("base", 1.0, rms=0.05, iid_sigma=0.033, errs=(0.02, 0.01, 0.02))
    assert _verdict(flat, "F1")["verdict"] == "refuted" and _verdict(flat, "F3")["verdict"] == "refuted"
    assert _verdict(flat, "F2")["verdict"] == "not shown"  # untestable where iid does not inflate σ_S


@pytest.mark.parametrize("kw, reason", [
    ({"per_volunteer": False}, "no per-volunteer values"),
    ({"chains": 1}, "fewer than 2 chains"),
    ({"rhat": 1.2}, "R-hat > 1.05"),
    ({"n_vol": 3}, "fewer than 5 volunteers"),
    ({"rms": 0.02}, "too small"),
])
def test_no_verdict_rests_on_a_dose_that_cannot_decide(kw, reason):
    args = {"rms": 0.05, "iid_sigma": 0.06, "errs": (0.01, 0.03, 0.011), **kw}
    res = _study("base", 1.0, **args)
    row = _verdict(res, "F1")
    assert row["verdict"] == "not shown" and reason in row["why"], row["why"]


def test_stress_tests_and_uncited_sources_are_kept_out_of_verdicts():
    for source, dose in (("angles", 45.0), ("heterogeneity", 1.2)):
        res = _study(source, dose, rms=0.05, iid_sigma=0.06)
        t = fd.mismatch_dose_tests(res)[0]
        assert t["calls"]["F1"] == "for" and not t["deciding"] and t["range"] in ("stress test", "uncited")
        assert _verdict(res, "F1")["verdict"] == "not shown"


def test_direct_replication_rows_decide_on_the_test_sets():
    def fd_result(iid_sigma, err_iid):
        sets = [{"set": i, "models": {
            "volume": {"rhat_max": 1.001, "abs_error_median": 0.010 + 0.0001 * i},
            "iid": {"rhat_max": 1.002, "abs_error_median": err_iid + 0.0001 * i,
                    "sigma_s": {"median": iid_sigma + 0.0005 * (i % 3)}},
            "discrepancy": {"rhat_max": 1.003, "abs_error_median": 0.010 + 0.0001 * i,
                            "sigma_s": {"median": 0.029 + 0.0005 * (i % 3)}}}} for i in range(12)]
        return {"sets": sets, "sampler": {"num_chains": 4, "num_warmup": 500, "num_samples": 1000}}

    rows = {r["finding"]: r for r in fd._replication_rows(fd_result(0.032, 0.006))}
    assert rows["F1 (direct replication)"]["verdict"] == "refuted" and rows["F3 (direct replication)"]["verdict"] == "refuted"
    assert rows["F2 (direct replication)"]["verdict"] == "not shown"
    assert rows["F1 (direct replication)"]["unit"] == "12 test sets"
    rows = {r["finding"]: r for r in fd._replication_rows(fd_result(0.065, 0.02))}
    assert all(r["verdict"] == "reproduced" for r in rows.values())
    one_chain = fd_result(0.065, 0.02)
    one_chain["sampler"]["num_chains"] = 1
    assert all(r["verdict"] == "not shown" for r in fd._replication_rows(one_chain))
