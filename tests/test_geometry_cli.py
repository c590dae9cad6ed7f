import json
from pathlib import Path

import numpy as np

from lvcore.cli import main
from lvcore.geometry.io import read_template_mesh

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "contours" / "SYNTHETIC_example_contours.json"


def test_fit_info_compare_project_pca(tmp_path, capsys):
    out = tmp_path / "fit.vtu"
    assert main(["geometry", "fit", str(EXAMPLE), "--out", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["residual_mean_mm"] < 0.5 and 50 < s["cavity_volume_ml"] < 120
    nodes = read_template_mesh(out)
    assert main(["geometry", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert abs(info["cavity_volume_ml"] - s["cavity_volume_ml"]) < 1e-6 and info["wall_volume_ml"] > 40
    assert main(["geometry", "compare", str(out), str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["node_mse_cm2"] == 0.0
    assert main(["geometry", "project", str(out), "--modes", "5", "--json"]) == 0
    proj = json.loads(capsys.readouterr().out)
    assert len(proj["scores"]) == 5 and proj["reconstruction_mse_cm2"] < 0.05
    rec = tmp_path / "rec.vtu"
    assert main(["geometry", "pca", *map(str, proj["scores"]), "--out", str(rec)]) == 0
    capsys.readouterr()
    assert np.mean(np.sum((read_template_mesh(rec) - nodes) ** 2, 1)) / 100 < 0.05


def test_fit_bad_input_is_a_clean_error(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("")
    assert main(["geometry", "fit", str(bad), "--out", str(tmp_path / "x.vtu")]) == 2
    assert "empty" in capsys.readouterr().err
    assert main(["geometry", "fit"]) == 2


def test_fitted_mesh_runs_in_the_simulator(tmp_path):
    import lvcore

    out = tmp_path / "fit.vtu"
    assert main(["geometry", "fit", str(EXAMPLE), "--out", str(out)]) == 0
    case = {"geometry": {"kind": "mesh", "path": str(out), "resolution": "fast"},
            "material": {"law": "holzapfel-ogden", "a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6},
            "load": {"pressure": 8, "units": "mmHg"}}
    y = lvcore.simulate(case).outputs()
    assert len(y) == 25 and y[0] > 60.0 and np.all(np.asarray(y[1:]) < 0)
