"""The information study's runs and summary (lvcore.studies.information_runner, information_summary), with a
stand-in calibration and FE truth: the data files, resuming, the statistics and the verdicts."""
import json
from pathlib import Path

import numpy as np
import pytest

from lvcore.domain.outputs import THETA_NAMES
from lvcore.exceptions import LVCoreError
from lvcore.inference.data import read_measured_csv
from lvcore.studies import information_runner as ir
from lvcore.studies import information_summary as isum

SETTINGS = {"seed": 0, "chains": 2, "warmup": 10, "samples": 10, "derived_draws": 10, "n_subjects": 2,
            "cohort_sizes": [], "state_pressures_mmhg": [8.0, 14.0, 20.0], "sigma_v_ml": 5.0, "sigma_s": 0.03}


def fake_truth(theta):
    """Outputs that grow with pressure (LVV 100 + 5 p mL, strains -0.01 p) and V0 80 mL."""
    return {"outputs": {f"{p:g}": [100.0 + 5 * p] + [-0.01 * p] * 24 for p in ir.TRUTH_PRESSURES_MMHG},
            "v0_ml": 80.0}


def fake_emulator(tmp_path) -> Path:
    d = tmp_path / "emu"
    d.mkdir()
    (d / "metadata.json").write_text(json.dumps({
        "name": "stand-in", "input_names": ["a", "b", "af", "bf", "edp"],
        "bounds": {"lower": [0.05, 0.5, 0.05, 0.5, 6.0], "upper": [10, 30, 10, 30, 30]},
        "test": {"lvv_rmse_ml": 0.7, "strain_rmse": 0.001}}))
    return d


class StandInCalibrate:
    """Writes a summary.json whose intervals narrow with the number of loaded states in the data file."""

    def __init__(self):
        self.calls = []

    def __call__(self, argv, log_path=None):
        self.calls.append(list(argv))
        data = Path(argv[argv.index("--data") + 1])
        n_states = len(read_measured_csv(data)[0].all_states())
        out = Path(argv[argv.index("--out") + 1])
        out.mkdir(parents=True, exist_ok=True)
        width = 4.0 / n_states           # a's q95/q05 = e^width
        rec = {"model": "iid", "converged": True, "flags": [],
               **{n: {"q05": 0.01, "median": 1.0, "q95": 100.0} for n in THETA_NAMES}}
        rec["a"] = {"q05": float(np.exp(-width / 2)) * 0.5, "median": 0.5, "q95": float(np.exp(width / 2)) * 0.5}
        rec["derived"] = {"edpvr": [{"pressure_mmhg": 20.0, "q05": 150.0, "median": 200.0, "q95": 250.0 - 10 * n_states},
                                    {"pressure_mmhg": 30.0, "q05": 160.0, "median": 250.0, "q95": 300.0}]}
        (out / "summary.json").write_text(json.dumps([rec]))
        return 0, ""


def test_state_data_file_has_one_row_per_loaded_state(tmp_path):
    subject = ir.make_state_subject(0, 3, truth_fn=fake_truth)
    assert subject["subject"] == "SYNTHETIC-INF-003"
    path = ir.write_state_data(subject, (8.0, 14.0, 20.0), tmp_path / "d.csv", reference_volume=True)
    (m,) = read_measured_csv(path)
    assert [s.edp_mmhg for s in m.all_states()] == [8.0, 14.0, 20.0]
    assert m.subject.startswith("SYNTHETIC")   # how calibrate labels it synthetic
    assert m.extras["reference_volume_ml"] == pytest.approx(subject["reference_volume_ml"], abs=1e-3)
    # the noise is added to the FE outputs at each state: sigma_V 5 mL, not the same draw twice
    lvv = [s.lvv_ml for s in m.all_states()]
    assert np.all(np.abs(np.array(lvv) - [140, 170, 200]) < 30) and len(set(lvv)) == 3


def test_theta_draws_are_reproducible_and_inside_the_emulator_box():
    draws = [ir.state_theta(0, i) for i in range(50)]
    assert draws[7] == ir.state_theta(0, 7)
    for d in draws:
        assert 0.05 < d["a"] < 10 and 0.5 < d["b"] < 30 and 0.05 < d["af"] < 10 and 0.5 < d["bf"] < 30


def test_states_part_runs_each_pair_once_and_resumes(tmp_path):
    cal = StandInCalibrate()
    emu = fake_emulator(tmp_path)
    n = ir.run_states(SETTINGS, tmp_path / "w", emulator=str(emu), variants=["states-8", "states-8-20", "infer-8"],
                      say=lambda m: None, calibrate=cal, truth_fn=fake_truth)
    assert n == 6 and len(cal.calls) == 6
    mesh = [c for c in cal.calls if "infer" not in c]
    assert all(c[c.index("--emulator") + 1] == str(emu) for c in mesh)
    assert any("--geometry" in c and "infer" in c for c in cal.calls)
    # a rerun finds every pair done; a cut-off last line (a kill mid-write) is ignored and its pair rerun
    assert ir.run_states(SETTINGS, tmp_path / "w", emulator=str(emu), variants=["states-8", "states-8-20", "infer-8"],
                         say=lambda m: None, calibrate=cal, truth_fn=fake_truth) == 0
    runs = tmp_path / "w" / "runs_states.jsonl"
    runs.write_text(runs.read_text()[:-40])
    assert ir.run_states(SETTINGS, tmp_path / "w", emulator=str(emu), variants=["states-8", "states-8-20", "infer-8"],
                         say=lambda m: None, calibrate=cal, truth_fn=fake_truth) == 1
    settings = json.loads((tmp_path / "w" / "settings.json").read_text())
    assert settings["state_emulator"]["edp_box_mmhg"] == [6.0, 30.0]
    with pytest.raises(LVCoreError, match="other settings"):
        ir.run_states({**SETTINGS, "warmup": 11}, tmp_path / "w", emulator=str(emu), say=lambda m: None,
                      calibrate=cal, truth_fn=fake_truth)


def test_summary_measures_narrowing_coverage_and_widths(tmp_path):
    cal = StandInCalibrate()
    ir.run_states(SETTINGS, tmp_path, emulator=str(fake_emulator(tmp_path)),
                  variants=["states-8", "states-8-20", "states-8-14-20"], say=lambda m: None, calibrate=cal,
                  truth_fn=fake_truth)
    res = isum.summarise(tmp_path, tmp_path / "information.json")
    v = {x["key"]: x for x in res["variants"]}
    assert v["states-8"]["a_ratio"]["median"] == pytest.approx(np.exp(4.0))
    assert v["states-8-20"]["narrowing"]["median"] == pytest.approx(np.exp(4.0) / np.exp(2.0))
    assert v["states-8-14-20"]["narrowing"]["median"] == pytest.approx(np.exp(4.0) / np.exp(4.0 / 3))
    assert v["states-8"]["v20_width_ml"]["median"] == pytest.approx(90.0)
    assert v["states-8-20"]["v20_width_ml"]["median"] == pytest.approx(80.0)
    assert v["states-8"]["v30_width_ml"]["median"] == pytest.approx(140.0)
    # coverage: a's truth against its interval per subject, shares with Wilson intervals
    for x in res["variants"]:
        assert 0.0 <= x["coverage_90"]["a"] <= 1.0
        lo, hi = x["coverage_90_ci"]["a"]
        assert lo <= x["coverage_90"]["a"] <= hi
    assert res["synthetic"] and "SYNTHETIC" in res["label"]
    assert not res["complete"]          # 3 of 8 variants per subject
    verdicts = {d["claim"]: d for d in res["verdicts"]}
    two = next(d for c, d in verdicts.items() if c.startswith("two loaded states (8 + 20"))
    assert two["met"] is True and two["value"].startswith("7.39x")   # e^4 / e^2 = 7.39 >= 3
    assert json.loads((tmp_path / "information.json").read_text())["variants"]


def test_a_narrowing_verdict_rule_is_the_same_threshold_either_way():
    base = {"a_ratio": None, "coverage_90": {"a": 1.0, "b": 1.0, "af": 1.0, "bf": 1.0, "all4": 1.0},
            "v20_width_ml": None, "v30_width_ml": None}
    for m, met in ((2.99, False), (3.0, True), (3.01, True)):
        out = isum.verdicts({"states-8-20": {**base, "narrowing": {"median": m, "min": m, "max": m, "n": 3}}})
        assert out[0]["met"] is met


def test_hierarchical_record_expands_to_one_run_per_subject():
    q = {c: {n: 1.0 for n in THETA_NAMES} for c in ("q05", "median", "q95")}
    rec = {"part": "cohort", "variant": "cohort4-hierarchical", "subject": "cohort of 4", "cohort_size": 4, "exit": 0,
           "converged": True, "subjects": {f"S{i}": {**q, "truth": {n: 1.0 for n in THETA_NAMES}} for i in range(4)}}
    runs = isum.expand_runs([rec])
    assert [r["subject"] for r in runs] == ["S0", "S1", "S2", "S3"]
    assert all(r["variant"] == "cohort4-hierarchical" for r in runs)


def test_infer_variants_through_edpvr_need_no_state_emulator_and_pin_no_angles(tmp_path):
    """The edpvr route's variants: ``--emulator edpvr --geometry infer`` without angle options (its angles are
    fixed), narrowing against its own one-state variant, and no state emulator built for them."""
    cal = StandInCalibrate()
    n = ir.run_states(SETTINGS, tmp_path / "w", variants=["infer-edpvr-8", "infer-edpvr-8-20"], say=lambda m: None,
                      calibrate=cal, truth_fn=fake_truth)
    assert n == 4 and not (tmp_path / "w" / ir.STATE_EMULATOR_DIR).exists()
    for c in cal.calls:
        assert c[c.index("--emulator") + 1] == "edpvr" and "--alpha-endo" not in c
    assert ir.variant_reference("infer-edpvr-8-20") == "infer-edpvr-8" and ir.variant_reference("infer-8-14") == "infer-8"
    res = isum.summarise(tmp_path / "w")
    v = {x["key"]: x for x in res["variants"]}["infer-edpvr-8-20"]
    assert v["reference"] == "infer-edpvr-8" and v["emulator"] == "edpvr"
    assert v["narrowing"]["median"] == pytest.approx(np.exp(4.0 - 2.0))   # the stand-in: e^4 -> e^2


def test_a_shipped_result_is_taken_over_and_summarised_again_unchanged(tmp_path):
    """--import-summary: the shipped result's runs become the work folder's records (a joint posterior one record
    again), and the summary of them equals the shipped one, cost included; a second import adds nothing; a
    result made with other settings is refused."""
    from lvcore.studies.results import bundled_studies_dir

    shipped = json.loads((bundled_studies_dir() / "information.json").read_text())
    settings = {**{k: shipped["settings"][k] for k in ("seed", "chains", "warmup", "samples", "derived_draws",
                                                       "n_subjects", "cohort_sizes")},
                "state_pressures_mmhg": [8.0, 14.0, 20.0], "sigma_v_ml": 5.0, "sigma_s": 0.03}
    n = ir.import_summary(shipped, settings, tmp_path / "w", "information.json")
    assert n == shipped["n_records"]
    assert ir.import_summary(shipped, settings, tmp_path / "w", "information.json") == 0
    res = isum.summarise(tmp_path / "w")
    old = {v["key"]: v for v in shipped["variants"]}
    new = {v["key"]: v for v in res["variants"]}
    for key, v in old.items():
        for field in ("a_ratio", "narrowing", "coverage_90", "v20_width_ml", "v30_width_ml", "exit_codes",
                      "mu_covered", "diagnostics"):
            assert new[key].get(field) == v.get(field), (key, field)
    assert res["cost"]["cpu_s_total"] == pytest.approx(shipped["cost"]["cpu_s_total"])
    assert len(res["runs"]) == len(shipped["runs"])
    with pytest.raises(LVCoreError, match="other settings"):
        ir.import_summary(shipped, {**settings, "warmup": 7}, tmp_path / "w2", "information.json")
