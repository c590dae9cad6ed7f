import numpy as np

from lvcore.geometry.cohort import (OPERATORS, ROLE_OPERATOR, ROLE_TRAIN, ROLE_VOLUNTEER, VOLUME_RANGE_ML,
                                    contour_stack, load_cohort, load_operator_geometries, sample_lv)
from lvcore.geometry.contours import read_contours
from lvcore.geometry.fitting import fit_contours
from lvcore.geometry.measures import node_mse_cm2


def test_sampled_lv_is_physiological_and_fits_back():
    rng = np.random.default_rng(5)
    lv = sample_lv(rng)
    v = lv.cavity_volume_ml()
    assert VOLUME_RANGE_ML[0] <= v <= VOLUME_RANGE_ML[1]
    assert 7.0 <= lv.wall * (1 - abs(lv.wall_sep)) and lv.wall * (1 + abs(lv.wall_sep)) <= 13.0
    st = contour_stack(lv, rng=rng, patient="T1")
    assert st.synthetic and st.label.startswith("SYNTHETIC")
    r = fit_contours(st)
    assert r.residual_mean_mm < 0.3
    assert abs(r.cavity_volume_ml / v - 1) < 0.06  # reference-operator noise included


def test_bundled_cohort_and_operator_assets():
    c = load_cohort()
    assert len(c.ids) >= 60 and all(i.startswith("SYNTHETIC") for i in c.ids)
    assert c.roles.count(ROLE_OPERATOR) == 6 and c.roles.count(ROLE_VOLUNTEER) == 8
    assert c.roles.count(ROLE_TRAIN) >= 46
    true = np.array([r["true_cavity_volume_ml"] for r in c.meta["records"]])
    fitted = np.array([r["fit"]["cavity_volume_ml"] for r in c.meta["records"]])
    assert VOLUME_RANGE_ML[0] <= true.min() and true.max() <= VOLUME_RANGE_ML[1]
    rel = fitted / true - 1  # segmentation noise of the reference operator, no bias
    assert abs(rel.mean()) < 0.01 and rel.std() < 0.05
    og = load_operator_geometries()
    assert og.nodes.shape[:2] == (6, 3) and og.operators == tuple(o.name for o in OPERATORS)
    # the stored contour stacks refit to the stored geometries (same pipeline as a user's)
    st = read_contours(og.contour_path("SYNTHETIC-P02", "op2"))
    r = fit_contours(st)
    assert node_mse_cm2(r.nodes, og.nodes[1, 1]) < 1e-6
    assert og.fits["SYNTHETIC-P01/op1"]["motion_error_mm"] > 0


def test_operator_errors_move_the_geometry_as_intended():
    from dataclasses import replace

    from lvcore.geometry.cohort import OperatorStyle, random_pose

    rng = np.random.default_rng(11)
    lv, pose = sample_lv(rng), random_pose(rng)
    clean = OperatorStyle("clean", noise_mm=0.0, shift_mm=0.0)
    ref = fit_contours(contour_stack(lv, clean, 0, pose=pose, jitter=0.0))
    dropped = fit_contours(contour_stack(lv, replace(clean, basal_slices=-1), 0, pose=pose, jitter=0.0))
    assert abs(ref.length_mm - dropped.length_mm - 10.0) < 1.5  # one 10 mm slice fewer
    assert node_mse_cm2(ref.nodes, dropped.nodes) > 0.1
    wide = fit_contours(contour_stack(lv, replace(clean, endo_bias_mm=1.0), 0, pose=pose, jitter=0.0))
    assert wide.cavity_volume_ml > ref.cavity_volume_ml * 1.03  # border through the trabeculae: larger cavity
    moved = fit_contours(contour_stack(lv, replace(clean, motion_error_mm=3.5), 0, pose=pose, jitter=0.0))
    assert 0.01 < node_mse_cm2(ref.nodes, moved.nodes) < 0.08
