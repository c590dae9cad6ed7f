import numpy as np
import pytest

from lvcore.geometry.analytic import DEFAULT_LV, LAND_LV
from lvcore.geometry.measures import cavity_volume, node_mse_cm2
from lvcore.geometry.template import DEFAULT_TEMPLATE, LVTemplate, N_REGIONS, lagrange_q2_shape


def test_shape_functions_partition_of_unity_and_kronecker():
    xi = np.random.default_rng(0).uniform(-1, 1, (20, 3))
    N, dN = lagrange_q2_shape(xi, derivatives=True)
    assert np.allclose(N.sum(1), 1.0)
    assert np.allclose(dN.sum(1), 0.0)
    idx = np.arange(27)
    nodes = np.stack([idx % 3, (idx // 3) % 3, idx // 9], 1) - 1.0
    assert np.allclose(lagrange_q2_shape(nodes), np.eye(27))


def test_counts_and_unique_nodes():
    t = LVTemplate(6, 4, 1)
    assert t.n_nodes == (2 * 4) * 12 * 3 + 3
    assert t.elements.shape == (24, 27)
    assert set(np.unique(t.elements)) == set(range(t.n_nodes))


def test_positive_jacobian_on_default_lv():
    t = DEFAULT_TEMPLATE
    X = DEFAULT_LV.nodes(t)
    g = np.array([-0.7745966692, 0.0, 0.7745966692])
    xi = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    _, dN = lagrange_q2_shape(xi, derivatives=True)
    jac = np.einsum("qak,eai->eqik", dN, X[t.elements])
    assert (np.linalg.det(jac) > 0).all()


@pytest.mark.parametrize("geom", [LAND_LV, DEFAULT_LV])
def test_cavity_volume_converges_to_analytic(geom):
    errs = []
    for t in [LVTemplate(6, 4, 1), LVTemplate(12, 8, 1), LVTemplate(24, 16, 1)]:
        errs.append(abs(float(cavity_volume(geom.nodes(t), t)) / geom.cavity_volume_mm3() - 1))
    assert errs[-1] < 1e-4
    assert errs[0] > errs[1] > errs[2]


def test_default_lv_is_physiological():
    v_ml = DEFAULT_LV.cavity_volume_mm3() / 1000
    assert 70 <= v_ml <= 100


def test_regions_cover_24_and_evaluate_roundtrip():
    t = DEFAULT_TEMPLATE
    assert np.bincount(t.element_regions, minlength=N_REGIONS).min() > 0
    X = DEFAULT_LV.nodes(t)
    p = t.parametric_coords
    assert np.allclose(t.evaluate(X, p[:, 0], p[:, 1], p[:, 2]), X)
    assert node_mse_cm2(X, X) == 0.0


def test_region_order_is_level_major():
    assert LVTemplate.region_of(np.deg2rad(10.0), 0.01) == 0
    assert LVTemplate.region_of(np.deg2rad(70.0), 0.01) == 1
    assert LVTemplate.region_of(np.deg2rad(10.0), 0.3) == 6
    assert LVTemplate.region_of(np.deg2rad(350.0), 0.99) == 23


def test_graded_template_refines_base_and_apex_levels():
    t = LVTemplate.graded(6, (2, 1, 1, 2), 1)
    assert (t.n_long, t.level_elements) == (6, (2, 1, 1, 2))
    np.testing.assert_allclose(t.s_breaks, [0, 0.125, 0.25, 0.5, 0.75, 0.875, 1.0])
    # same topology as the uniform template with the same counts, other parametric rows
    u = LVTemplate(6, 6, 1)
    assert np.array_equal(t.elements, u.elements)
    rows = t.parametric_coords[t.grid_ijk[:, 1] == 1, 1]
    np.testing.assert_allclose(rows, 0.0625)  # mid-node row of the first (basal) element row
    # every element lies in one level: 2, 1, 1, 2 element rows of 6 elements
    levels = t.element_regions // 6
    assert np.bincount(levels).tolist() == [12, 6, 6, 12]
    # sampling a map and evaluating the isoparametric geometry round-trips
    X = t.nodes_from_map(DEFAULT_LV.position)
    p = t.parametric_coords
    np.testing.assert_allclose(t.evaluate(X, p[:, 0], p[:, 1], p[:, 2]), X, atol=1e-9)
    phi, s, tt = 0.0, 0.2, 0.0  # between node rows (s is mapped through the grading), on a node column
    assert np.linalg.norm(t.evaluate(X, phi, s, tt) - DEFAULT_LV.position(np.array([phi]), np.array([s]), np.array([tt]))[0]) < 0.2
    with pytest.raises(ValueError, match="level_elements"):
        LVTemplate(6, 5, 1, (2, 1, 1, 2))
