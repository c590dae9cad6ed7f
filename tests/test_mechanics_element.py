"""Consistency of the condensed mixed tangent with finite differences of the residuals."""
import numpy as np
import pytest
import scipy.sparse as sp

from lvcore.geometry.analytic import LAND_LV
from lvcore.mechanics import boundary, materials
from lvcore.mechanics.mesh import box_mesh, lv_mesh
from lvcore.mechanics.quadrature import gauss_hex
from lvcore.mechanics.simulate import build_frames
from lvcore.mechanics.case import FibreSpec
from lvcore.mechanics.system import DiscreteSystem


HO = materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6})


def _model(law, kappa):
    return materials.ConstitutiveModel(law, materials.MixedPenalty(kappa))


def _check_tangent(S, rng, scale=0.05):
    u = rng.normal(size=S.n_free) * scale
    p = rng.normal(size=(S.mesh.n_elements, 4)) * 0.5
    rhs, K, D, r_p = S.tangent(u, p, 0.7)
    d = rng.normal(size=S.n_free)
    dp = S.pressure_increment(d, D, np.zeros_like(r_p))  # keeps the constraint linearly satisfied
    h = 1e-6
    ru1, rp1, _, _ = S.residual(u + h * d, p + h * dp, 0.7)
    ru0, rp0, _, _ = S.residual(u - h * d, p - h * dp, 0.7)
    fd_u = (ru1 - ru0) / (2 * h)
    fd_p = (rp1 - rp0) / (2 * h)
    kd = K @ d
    assert np.linalg.norm(fd_u - kd) < 1e-6 * np.linalg.norm(kd)
    assert np.abs(fd_p).max() < 1e-6 * np.abs(D).max() * np.abs(d).max()


def test_lv_tangent_matches_finite_differences():
    m = lv_mesh(LAND_LV.position, (6, 4, 1), 5.0)
    frames = build_frames(m, FibreSpec(-60.0, 90.0, None))
    S = DiscreteSystem(m, _model(HO, 1e3), frames, "endocardium", 2.0, boundary.fixed_dofs(m, "sliding"))
    _check_tangent(S, np.random.default_rng(0))
    assert abs(K_sym := (S.tangent(np.zeros(S.n_free), S.zero_pressure(), 1.0)[1])).max() > 0
    assert abs(K_sym - K_sym.T).max() < 1e-9 * abs(K_sym).max()


def test_box_follower_tangent_matches_finite_differences():
    m = box_mesh((4.0, 1.0, 1.0), (3, 1, 1))
    xi, _ = gauss_hex(3)
    frames = build_frames(m, FibreSpec(0.0, 0.0, (1.0, 0.0, 0.0)))
    law = materials.Guccione.from_params({"C": 2, "bf": 8, "bt": 2, "bfs": 4})
    S = DiscreteSystem(m, _model(law, 2e3), frames, "z0", 0.5, boundary.fixed_dofs(m, clamped_faces=("x0",)))
    _check_tangent(S, np.random.default_rng(1), scale=0.02)


def test_zero_load_is_equilibrium_and_rigid_motion_is_stress_free():
    m = lv_mesh(LAND_LV.position, (6, 4, 1), 5.0)
    frames = build_frames(m, FibreSpec(-60.0, 90.0, None))
    S = DiscreteSystem(m, _model(HO, 1e3), frames, "endocardium", 2.0, [])
    r_u, r_p, mj, w = S.residual(np.zeros(S.n_free), S.zero_pressure(), 0.0)
    assert np.abs(r_u).max() < 1e-10 and np.abs(r_p).max() < 1e-12 and mj == pytest.approx(1.0)
    th = 0.3
    R = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1.0]])
    u = (m.nodes @ R.T - m.nodes + np.array([1.0, -2.0, 0.0])).ravel()
    r_u, r_p, mj, w = S.residual(u, S.zero_pressure(), 0.0)
    assert np.abs(r_u).max() < 1e-9 and abs(w) < 1e-9


def test_lv_tangent_with_mismatch_terms_matches_finite_differences():
    """Fibre dispersion, moved sheet terms, a random per-element stiffness field and an epicardial Robin
    spring: the tangent is still the derivative of the residual and stays symmetric."""
    m = lv_mesh(LAND_LV.position, (6, 4, 1), 5.0)
    frames = build_frames(m, FibreSpec(-60.0, 90.0, None))
    law = materials.HolzapfelOgden.from_params({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "as": 1.5, "bs": 3.0,
                                                "afs": 0.8, "bfs": 4.0, "kappa": 0.15})
    rng = np.random.default_rng(4)
    scale = np.ones((m.n_elements, len(law.keys)))
    scale[:, [0, 2]] = rng.uniform(0.5, 2.0, size=(m.n_elements, 2))
    for direction in ("normal", "full"):
        S = DiscreteSystem(m, _model(law, 1e3), frames, "endocardium", 2.0, boundary.fixed_dofs(m, "sliding"),
                           element_scale=scale, spring=("epicardium", 0.7, direction))
        _check_tangent(S, rng)
        K = S.tangent(np.zeros(S.n_free), S.zero_pressure(), 1.0)[1]
        assert abs(K - K.T).max() < 1e-9 * abs(K).max()


def test_upper_triangle_tangent_is_the_upper_triangle_of_the_tangent():
    """What Newton hands CHOLMOD: the same matrix from half the entries, with a Robin spring and on a mesh
    whose collapsed apex repeats a node inside an element (an off-diagonal element entry on a diagonal slot)."""
    m = lv_mesh(LAND_LV.position, (6, 4, 1), 5.0)
    assert any(len(set(e)) < 27 for e in m.elements.tolist())
    frames = build_frames(m, FibreSpec(-60.0, 90.0, None))
    S = DiscreteSystem(m, _model(HO, 1e3), frames, "endocardium", 2.0, boundary.fixed_dofs(m, "sliding"),
                       spring=("epicardium", 0.7, "normal"))
    rng = np.random.default_rng(5)
    u, p = rng.normal(size=S.n_free) * 0.05, rng.normal(size=(m.n_elements, 4))
    rhs, K, D, r_p = S.tangent(u, p, 0.8)
    rhs_t, U, D_t, r_p_t = S.tangent(u, p, 0.8, triangle=True)
    assert U.nnz == (K.nnz + S.n_free) // 2
    upper = sp.triu(K).tocsr()
    assert abs(U - upper).max() < 1e-12 * abs(K).max()
    np.testing.assert_array_equal(rhs_t, rhs)
    np.testing.assert_array_equal(D_t, D)
    box = box_mesh((4.0, 1.0, 1.0), (3, 1, 1))
    follower = DiscreteSystem(box, _model(HO, 1e3), build_frames(box, FibreSpec(0.0, 0.0, (1.0, 0.0, 0.0))), "z0",
                              0.5, boundary.fixed_dofs(box, clamped_faces=("x0",)))
    with pytest.raises(ValueError, match="only a symmetric tangent"):
        follower.tangent(np.zeros(follower.n_free), follower.zero_pressure(), 1.0, triangle=True)


def test_unit_scale_and_zero_spring_leave_the_system_bit_for_bit_unchanged():
    m = lv_mesh(LAND_LV.position, (6, 4, 1), 5.0)
    frames = build_frames(m, FibreSpec(-60.0, 90.0, None))
    fixed = boundary.fixed_dofs(m, "sliding")
    S0 = DiscreteSystem(m, _model(HO, 1e3), frames, "endocardium", 2.0, fixed)
    S1 = DiscreteSystem(m, _model(HO, 1e3), frames, "endocardium", 2.0, fixed,
                        element_scale=np.ones((m.n_elements, len(HO.keys))), spring=("epicardium", 0.0, "normal"))
    assert S1.spring is None and S1.pattern is S0.pattern
    rng = np.random.default_rng(2)
    u, p = rng.normal(size=S0.n_free) * 0.05, rng.normal(size=(m.n_elements, 4))
    for a, b in zip(S0.residual(u, p, 0.6), S1.residual(u, p, 0.6)):
        np.testing.assert_array_equal(a, b)
    t0, t1 = S0.tangent(u, p, 0.6), S1.tangent(u, p, 0.6)
    np.testing.assert_array_equal(t0[0], t1[0])
    np.testing.assert_array_equal(t0[1].data, t1[1].data)


def test_load_norm_is_the_external_load_at_the_reference_state_and_shared_by_model_copies():
    """Newton's force scale: ‖f_ext‖ on the free dofs (the residual at zero displacement and pressure, whose
    internal part vanishes in the stress-free reference) for the pressure potential and a follower load."""
    m = lv_mesh(LAND_LV.position, (6, 4, 1), 5.0)
    frames = build_frames(m, FibreSpec(-60.0, 90.0, None))
    S = DiscreteSystem(m, _model(HO, 1e3), frames, "endocardium", 2.0, boundary.fixed_dofs(m, "clamped"))
    r1 = S.residual(np.zeros(S.n_free), S.zero_pressure(), 1.0)[0]
    assert S.load_norm() == pytest.approx(np.linalg.norm(r1), rel=1e-12) and S.load_norm() > 0
    stiffer = S.with_model(_model(materials.HolzapfelOgden.from_params({"a": 5.0, "b": 2.0, "af": 9.0, "bf": 1.0}), 1e4))
    assert stiffer.load_norm() == S.load_norm() and stiffer._shared is S._shared
    mb = box_mesh((2.0, 1.0, 1.0), (2, 1, 1))
    law = materials.Guccione.from_params({"C": 2, "bf": 8, "bt": 2, "bfs": 4})
    B = DiscreteSystem(mb, _model(law, 2e3), build_frames(mb, FibreSpec(0.0, 0.0, (1.0, 0.0, 0.0))), "z0", 0.5,
                       boundary.fixed_dofs(mb, clamped_faces=("x0",)))
    rb = B.residual(np.zeros(B.n_free), B.zero_pressure(), 1.0)[0]
    assert B.load_norm() == pytest.approx(np.linalg.norm(rb), rel=1e-12) and B.load_norm() > 0


def test_constitutive_model_as_arrays_gives_float64_scalars():
    m = _model(HO, 1e3).as_arrays()
    leaves = [m.kappa] + [getattr(m.material, k) for k in ("a", "b", "a_f", "b_f", "kappa_f")]
    assert all(np.asarray(v).dtype == np.float64 and np.ndim(v) == 0 for v in leaves)
