import json

import numpy as np
import pytest

from lvcore.exceptions import GeometryError
from lvcore.geometry.analytic import EllipsoidSurface, TruncatedEllipsoidLV
from lvcore.geometry.measures import node_mse_cm2
from lvcore.geometry.shape_model import fit_shape_model, load_shape_model
from lvcore.geometry.template import DEFAULT_TEMPLATE


@pytest.fixture(scope="module")
def geometries():
    rng = np.random.default_rng(0)
    out = []
    for _ in range(12):
        rs, rl, w = rng.uniform(20, 27), rng.uniform(55, 70), rng.uniform(7, 11)
        g = TruncatedEllipsoidLV(EllipsoidSurface(rs, rl, rs * rng.uniform(0.85, 1)),
                                 EllipsoidSurface(rs + w, rl + 0.7 * w, (rs + w) * rng.uniform(0.9, 1)), 5.0)
        out.append(g.nodes(DEFAULT_TEMPLATE) + rng.normal(0, 0.2, (DEFAULT_TEMPLATE.n_nodes, 3)))
    return np.array(out)


def test_all_modes_reconstruct_training_exactly(geometries):
    sm = fit_shape_model(geometries)
    assert sm.n_modes == len(geometries) - 1
    for g in geometries[:3]:
        assert node_mse_cm2(g, sm.reconstruct(sm.project(g))) < 1e-20
    # standardised scores over the training set: mean 0, unit variance
    H = sm.project(geometries)
    assert np.allclose(H.mean(0), 0, atol=1e-9)
    assert np.allclose(H.std(0, ddof=1), 1, atol=1e-9)
    assert np.isclose(sm.explained_variance_ratio.sum(), 1.0)
    # error decreases with k, mean reconstructs with no scores
    e = [sm.reconstruction_mse_cm2(geometries[0], k) for k in range(0, sm.n_modes + 1)]
    assert all(a >= b - 1e-15 for a, b in zip(e, e[1:]))
    assert np.allclose(sm.reconstruct([]), sm.mean) if False else np.allclose(sm.reconstruct(np.zeros(1)), sm.mean)
    # fewer scores = zeros for the rest
    h = sm.project(geometries[1], 3)
    assert np.allclose(sm.reconstruct(h), sm.reconstruct(np.r_[h, np.zeros(sm.n_modes - 3)]))


def test_save_load_no_pickle_and_sampling(geometries, tmp_path):
    sm = fit_shape_model(geometries, ids=[f"g{i}" for i in range(12)], label="SYNTHETIC test")
    path = sm.save(tmp_path / "m.json")
    meta = json.loads(path.read_text())
    assert meta["format"] == "lvcore.shape_model/1" and meta["train_ids"][0] == "g0"
    with np.load(tmp_path / "m.npz", allow_pickle=False) as z:
        assert set(z.files) == {"mean", "components", "std", "explained_variance_ratio"}
    sm2 = load_shape_model(path)
    assert np.allclose(sm2.reconstruct([1.0, -2.0]), sm.reconstruct([1.0, -2.0]), atol=1e-3)
    X = sm2.sample(np.random.default_rng(1), 4, n_modes=5)
    assert X.shape == (4, DEFAULT_TEMPLATE.n_nodes, 3)
    with pytest.raises(GeometryError, match="modes"):
        sm2.reconstruct(np.zeros(sm2.n_modes + 1))
    with pytest.raises(GeometryError, match="not found"):
        load_shape_model(tmp_path / "missing.json")


def test_bundled_model_holds_out_test_patients_and_reconstructs_its_training():
    from lvcore.geometry.cohort import ROLE_TRAIN, load_cohort

    sm = load_shape_model()
    cohort = load_cohort()
    assert "SYNTHETIC" in sm.label
    assert not any(("P0" in i or "HV" in i) for i in sm.train_ids)
    ids, train = cohort.select(ROLE_TRAIN)
    assert tuple(ids) == sm.train_ids and len(ids) >= 46
    # all modes: exact up to float32 storage
    assert node_mse_cm2(train[0], sm.reconstruct_nodes(train[0], sm.n_modes)) < 1e-8
    evr = np.cumsum(sm.explained_variance_ratio)
    assert 0.8 < evr[4] < 0.999 and evr[9] > evr[4]
    # a pca case geometry: DEFAULT shape-ish, base plane at z = 0
    g = sm.reconstruct([1.0, 0.5])
    assert np.allclose(g[DEFAULT_TEMPLATE.base_nodes, 2], 0.0, atol=1e-3)
