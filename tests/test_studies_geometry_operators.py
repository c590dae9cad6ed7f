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
