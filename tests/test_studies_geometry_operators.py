import json

import numpy as np
import pytest

from lvcore.cli import main
from lvcore.geometry.cohort import OperatorGeometries
from lvcore.geometry.measures import node_mse_cm2
from lvcore.geometry.shape_model import fit_shape_model
from lvcore.studies.geometry_operators import format_table, operator_table


def test_table_on_bundled_synthetic_data_is_in_the_chapter_regime():
    t = operator_table()
    assert t["n_cases"] == 18 and len(t["blocks"]) == 3 and t["ks"] == [5, 6, 7, 8, 9, 10]
    lo, hi = t["operator_mse_range"]
    assert 0.001 < lo < 0.006 and 0.015 < hi < 0.06  # chapter: 0.003-0.03 cm^2
    share = [t["share_beating_both"][str(k)] for k in t["ks"]]
    assert share[-1] >= 0.8
    assert all(b >= a - 1e-12 for a, b in zip(share, share[1:])) or share[-1] >= share[0]
    # symmetric operator MSE: op1 vs op2 equals op2 vs op1
    b1, b2 = t["blocks"][0], t["blocks"][1]
    assert np.isclose(b1["rows"][2]["operator_mse"]["op2"], b2["rows"][2]["operator_mse"]["op1"])
    assert "SYNTHETIC" in format_table(t)


def test_table_logic_on_constructed_data():
    rng = np.random.default_rng(0)
    base = rng.normal(0, 10, (20, 1925, 3))
    sm = fit_shape_model(base[:15], ids=[f"t{i}" for i in range(15)])
    # operator geometries: a training-span geometry + operator-specific offsets
    main_geo = sm.reconstruct(np.r_[1.0, np.zeros(4)])
    nodes = np.stack([[main_geo + d for d in (0.0, 3.0, 5.0)] for _ in range(2)])
    og = OperatorGeometries(patients=("a", "b"), operators=("o1", "o2", "o3"), nodes=nodes, fits={}, meta={})
    t = operator_table(og, sm, ks=(1, 2))
    row = t["blocks"][0]["rows"][0]
    assert np.isclose(row["operator_mse"]["o2"], node_mse_cm2(nodes[0, 1], nodes[0, 0]))
    assert row["pca_mse"]["1"] < 1e-12 and row["first_k_beating_both"] == 1
    with pytest.raises(ValueError, match="hold them out"):
        operator_table(OperatorGeometries(("t0",), ("o1", "o2", "o3"), nodes[:1], {}, {}), sm)


def test_cli_json(capsys):
    assert main(["study", "geometry-operators", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["share_beating_both"]) == {"5", "6", "7", "8", "9", "10"}


def test_geometry_effect_size_normalises_like_calibrate():
    """Fig 9.10 feeds the emulator the size-normalised scores (as ``lvcore calibrate``): a patient's geometry
    scaled by 1.3 about the long axis' base point has the same scores and strains, and 1.3^3 times the LVV."""
    from lvcore.geometry.cohort import load_operator_geometries
    from lvcore.geometry.scaling import size_normalised_scores
    from lvcore.geometry.template import DEFAULT_TEMPLATE
    from lvcore.studies.geometry_operators import geometry_effect

    og = load_operator_geometries()
    x = og.nodes[0, 0]
    c = np.r_[0.0, 0.0, np.mean(x[DEFAULT_TEMPLATE.base_nodes, 2])]   # about the long axis at the base plane
    big = c + 1.3 * (x - c)
    two = OperatorGeometries(patients=("p", "p_big"), operators=og.operators[:1],
                             nodes=np.stack([[x], [big]]), fits={}, meta={})
    ge = geometry_effect(operator_geometries=two)
    r0, r1 = ge["rows"]
    sc = size_normalised_scores(x, 5)
    assert np.allclose([r0[f"h{i + 1}"] for i in range(5)], sc.h) and np.isclose(r0["scale"], sc.scale)
    assert np.allclose([r1[f"h{i + 1}"] for i in range(5)], sc.h, atol=1e-8)
    assert np.isclose(r1["scale"], 1.3 * sc.scale, rtol=1e-9)
    assert np.isclose(r1["lvv_ml"], 1.3 ** 3 * r0["lvv_ml"], rtol=1e-9)
    assert np.allclose([r1[f"strain_{k:02d}"] for k in range(1, 25)], [r0[f"strain_{k:02d}"] for k in range(1, 25)])
