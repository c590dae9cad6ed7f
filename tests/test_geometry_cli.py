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


def _zero_volume_mesh(path):
    """SYNTHETIC: one degenerate tetrahedron (a, b, c, a) per boundary triangle of the default LV's hexahedra."""
    import meshio

    from lvcore.geometry.analytic import DEFAULT_LV
    from lvcore.geometry.template import DEFAULT_TEMPLATE
    from lvcore.geometry.volume_mesh import boundary_triangles

    nodes = DEFAULT_LV.nodes(DEFAULT_TEMPLATE)
    hexes = DEFAULT_TEMPLATE.elements[:, [0, 2, 8, 6, 18, 20, 26, 24]]
    tri, _ = boundary_triangles(nodes, np.zeros((0, 4), np.int64), hexes)
    meshio.write(path, meshio.Mesh(nodes, [("tetra", np.c_[tri, tri[:, 0]])]))
    return path


def test_fit_of_a_mesh_without_volume_is_refused_naming_the_file(tmp_path, capsys):
    """Tetrahedra that all have zero volume were an internal error (ZeroDivisionError, exit 3)."""
    import meshio

    path = _zero_volume_mesh(tmp_path / "collapsed.vtu")
    assert main(["geometry", "fit", "--mesh", str(path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "has no volume" in err and "internal error" not in err
    # a flat ring of 12 tetrahedra (every point on z = 0)
    t = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)
    pts = np.concatenate([np.c_[r * np.cos(t), r * np.sin(t), 0 * t] for r in (20.0, 30.0)])
    flat = tmp_path / "flat.vtu"
    meshio.write(flat, meshio.Mesh(pts, [("tetra", [[i, (i + 1) % 12, 12 + i, 12 + (i + 1) % 12]
                                                    for i in range(12)])]))
    assert main(["geometry", "fit", "--mesh", str(flat)]) == 2
    err = capsys.readouterr().err
    assert str(flat) in err and "has no volume" in err
