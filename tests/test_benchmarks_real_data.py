"""The no-mesh route end to end on one small SYNTHETIC ellipsoid (benchmarks/real_data.py, one case).

A 40 mL ellipsoid (outside the shape model's 62-110 mL) simulated by the FE
simulator with the sliding base, calibrated with ``lvcore calibrate
--geometry infer --reference-volume`` and the 'chapter' emulator. The
criterion for the whole benchmark, per case: either all four true theta and
the subject's own V20 lie in their 90 % intervals, or the run exits with 4
(flagged); weak identification alone never exits 4.
"""
from __future__ import annotations

import json

import pytest
from repo_scripts import load_script

pytestmark = pytest.mark.slow


def _bench():
    return load_script("benchmarks/real_data.py")


def test_small_subject_is_covered_or_flagged(tmp_path):
    from lvcore.mechanics.simulate import simulate

    bench = _bench()
    s = (40.0 / bench.unit_volume_ml()) ** (1 / 3)
    theta = bench.THETAS[0]
    case = {"geometry": {**bench.ellipsoid(s), "resolution": "coarse"},
            "material": {"law": "holzapfel-ogden", **dict(zip(("a", "b", "af", "bf"), theta))},
            "fibres": {"alpha_endo": -60.0, "alpha_epi": 60.0}, "load": {"pressure": 8.0, "units": "mmHg"},
            "boundary": {"base": "sliding"}}
    r = simulate(case, raise_on_failure=True)
    sim = {"volume_ml": 40.0, "theta": list(theta), "scale": s, "converged": True,
           "outputs": [float(v) for v in r.outputs()],
           "reference_volume_ml": float(r.cavity_volume_mm3[0]) / 1000.0, **bench.true_edpvr(case, r)}
    assert sim["reference_volume_ml"] == pytest.approx(40.0, rel=0.02)
    assert sim["reference_volume_ml"] < sim["outputs"][0] < sim["v20_ml"] < sim["v30_ml"]
    rows = [row for row in bench.subject_rows([sim]) if not row["noisy"]]
    (res,) = bench.calibrate_all(rows, tmp_path, chains=2, warmup=200, samples=200, emulator="chapter",
                                 derived_draws=8)
    assert res["exit"] in (0, 4), res
    assert (res["covered"] and res["v_inside"]["V20"]) or res["exit"] == 4, res
    assert not any(f.startswith("IDENTIFIABILITY") for f in res["flags"])
    rec = json.loads((tmp_path / "runs" / rows[0]["subject"] / "out" / "summary.json").read_text())[0]
    post = rec["geometry"]["posterior"]
    # the reference volume is measured: the implied one matches it; the size is far from the shape model's
    assert post["implied_reference_volume_ml"]["median"] == pytest.approx(sim["reference_volume_ml"], abs=6.0)
    assert post["scale"]["q95"] < 0.95
    assert rec["conditions"]["base"] == "sliding" and rec["edp_mmhg"] == 8.0
    assert "flags" in rec and "verdict" in rec
    print(bench.table([res]))


def test_fisher_information_says_one_pressure_does_not_separate_a_from_b():
    """The data-limited evidence of benchmarks/real_data.py --steps fisher: with the geometry known and no model
    error, the benchmark's noise leaves log a and log b almost perfectly anti-correlated and a's Laplace
    q95/q05 far above 20; the noise would have to shrink about tenfold for 20."""
    bench = _bench()
    s = (120.0 / bench.unit_volume_ml()) ** (1 / 3)
    (r,) = bench.fisher_all([{"volume_ml": 120.0, "theta": list(bench.THETAS[0]), "scale": s}])
    assert r["corr_a_b"] < -0.95 and r["a_ratio"] > 1e3
    assert 0.02 < r["noise_factor_for_20"] < 0.3
    assert abs(r["weakest_direction"][0]) > 0.5 and abs(r["weakest_direction"][1]) > 0.5   # mostly (log a, log b)
