"""F4/F5 with realistic operators: bound flags, bootstrap CIs over patients, verdicts, docs-vs-JSON, a small run."""
import json
from pathlib import Path

import numpy as np
import pytest

from lvcore.core.space import THETA_BOUNDS
from lvcore.studies import operators as ops
from lvcore.studies import operators_realistic as orl
from lvcore.studies._common import bootstrap_ci
from lvcore.studies.results import bundled_studies_dir

OPS = ("r1", "r2", "r3")
DOCS = Path(__file__).resolve().parents[1] / "docs" / "studies.md"


def fake_fits(n_patients, pc_better: float, seed=0):
    """Fits of ``n_patients`` where the PC errors are ``pc_better`` × the operators' (< 1: the PCs win)."""
    rng = np.random.default_rng(seed)
    fits = []
    for p in range(n_patients):
        for m in OPS:
            base = rng.uniform(0.001, 0.002)
            for t in [o for o in OPS if o != m] + ["pc5", "pc10"]:
                err = base * (pc_better if t.startswith("pc") else rng.uniform(0.9, 1.1))
                theta = [0.6, 1.3, 1.0, 3.6] if t != "pc5" or p % 2 else [THETA_BOUNDS["a"][0], 1.3, 1.0, 3.6]
                fits.append({"patient": f"P{p:02d}", "main_operator": m, "test_geometry": t, "converged": True,
                             "theta_hat": theta, "theta_abs_error": [0.0] * 4, "strain_rmse_forward": err,
                             "output_rmse_refit": err, "mahalanobis": 100.0 if theta[0] < 0.1 else 1.0})
    return fits


def test_on_bound_flags_parameters_on_the_prior_box():
    assert ops.on_bound([0.6, 1.3, 1.0, 3.6]) == []
    assert ops.on_bound([THETA_BOUNDS["a"][0], 1.3, 1.0, THETA_BOUNDS["bf"][1]]) == ["a", "bf"]
    assert ops.on_bound({"a": 0.05 * (1 + 5e-4), "b": 1.3, "af": 1.0, "bf": 3.6}) == ["a"]
    assert ops.on_bound([0.06, 1.3, 1.0, 3.6]) == []


def test_laplace_median_leaves_out_fits_on_a_bound():
    fits = fake_fits(4, 0.5)
    f = ops.findings(fits, OPS)
    assert f["n_on_bound"]["pc5"] == 2 * 3  # patients 0 and 2, every main
    assert f["median_mahalanobis_interior"]["pc5"] == pytest.approx(1.0)
    assert f["median_mahalanobis"]["pc5"] > 1.0  # the all-fits median is pulled up by the invalid Laplace values
    assert f["n_on_bound"]["operator"] == 0


def test_bootstrap_ci_over_units():
    vals = {"a": 1.0, "b": 2.0, "c": 3.0, "d": 10.0}
    b = bootstrap_ci(list(vals), lambda us: np.mean([vals[u] for u in us]), n_boot=4000, seed=1)
    assert b["value"] == pytest.approx(4.0) and b["n_units"] == 4
    assert 1.0 <= b["ci"][0] < 4.0 < b["ci"][1] <= 10.0
    assert bootstrap_ci(["a"], lambda us: 1.0)["ci"] is None


@pytest.mark.parametrize("factor, verdict", [(0.5, "reproduced"), (2.0, "refuted")])
def test_verdicts_follow_the_ci_of_the_share(factor, verdict):
    fits = fake_fits(20, factor)
    boot = orl.bootstrap(fits, OPS, None, n_boot=300)
    b = boot["output_rmse_refit"]["pc10"]["share_no_worse_than_an_operator"]
    assert b["value"] == (1.0 if factor < 1 else 0.0) and b["n_units"] == 20
    v = orl.verdicts(boot, 20, len(fits))
    assert "F4" not in v  # no geometry table given
    assert v["F5"]["verdict"] == verdict and v["F5"]["ci"]["pc10"] == b["ci"]


def test_mixed_shares_are_not_reproduced():
    fits = fake_fits(20, 0.5)
    # half the patients: the PCs lose
    for f in fits:
        if f["test_geometry"].startswith("pc") and int(f["patient"][1:]) % 2:
            f["output_rmse_refit"] *= 10
    v = orl.verdicts(orl.bootstrap(fits, OPS, None, n_boot=500), 20, len(fits))
    assert v["F5"]["verdict"] == "not reproduced"
    assert v["F5"]["ci"]["pc10"][0] < 0.5 < v["F5"]["ci"]["pc10"][1]


def test_small_run_with_a_stand_in_forward(tmp_path):
    from test_studies_operators import stand_in

    res = orl.run_study(2, 5, out=tmp_path, forward_factory=stand_in, n_boot=200, all_mains=True)
    data = orl.load(tmp_path)
    assert data["meta"]["patients"] == ["SYNTHETIC-R01", "SYNTHETIC-R02"] and len(data["fits"]) == 24  # all mains
    assert set(data["verdicts"]) == {"F4", "F5"}
    for v in data["verdicts"].values():
        assert {"finding", "chapter", "value", "ci", "verdict", "note"} <= set(v)
        assert v["verdict"] in ("reproduced", "not reproduced", "refuted")
    assert all("on_bound" in f for f in data["fits"])
    assert "SYNTHETIC" in orl.source_line(data) or "SYNTHETIC" in data["meta"]["label"]
    tabs = orl.tables(data)
    assert len(tabs["verdicts"]) == 2 and len(tabs["fits"]) == 24
    assert "fig_shares_ci" in orl.figures(data)
    assert (tmp_path / orl.FITS_FILE).is_file() and (tmp_path / "cohort" / "SYNTHETIC_operators.npz").is_file()
    # slice choices were drawn and recorded per patient and operator
    assert set(data["meta"]["slice_choices"]) == {f"SYNTHETIC-R0{i}/{o}" for i in (1, 2) for o in OPS}
    # a rerun reuses the geometries and the refits
    again = orl.run_study(2, 5, out=tmp_path, forward_factory=lambda g: pytest.fail("refitted"), n_boot=200,
                          all_mains=True)
    assert again["fits"] == res["fits"]
    # the default design: one main operator per patient in turn, on the cached geometries
    rot = orl.run_study(2, 5, out=tmp_path, forward_factory=stand_in, n_boot=200)
    assert {(f["patient"], f["main_operator"]) for f in rot["fits"]} == {("SYNTHETIC-R01", "r1"), ("SYNTHETIC-R02", "r2")}
    assert len(rot["fits"]) == 8 and rot["meta"]["n_fits"] == 8 and "one main operator" in rot["meta"]["design"]


def test_cli_rejects_a_bad_patient_count(tmp_path, capsys):
    from lvcore.cli import main

    with pytest.raises(SystemExit) as exc:  # argparse's own check of the option's type
        main(["study", "operators-realistic", "--patients", "0", "--out", str(tmp_path)])
    assert exc.value.code == 2 and "--patients" in capsys.readouterr().err


def test_docs_quote_the_shipped_verdicts():
    path = bundled_studies_dir() / orl.RESULT_FILE
    if not path.is_file():
        pytest.skip("operators_realistic.json not shipped yet")
    result = orl.load(bundled_studies_dir())
    assert orl.markdown_table(result) in DOCS.read_text()
    assert result["meta"]["n_patients_requested"] >= 20 and len(result["meta"]["patients"]) >= 20
    assert json.loads(path.read_text())["verdicts"]["F5"]["verdict"] in ("reproduced", "not reproduced", "refuted")
