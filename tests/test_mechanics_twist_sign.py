"""The fibre helix handedness and the apex twist sign (lvcore.mechanics.twist): analytic cases, then the FE
simulator against the sign derived by hand for passive inflation of a uniform helix."""
import dataclasses

import numpy as np
import pytest

from lvcore.mechanics.twist import apex_twist_deg, helix_handedness


def _helix(c: float, t=np.linspace(0.1, 6.0, 40)):
    """Points and unit tangents of the helix (cos t, sin t, c t): right-handed for c > 0."""
    x = np.stack([np.cos(t), np.sin(t), c * t], axis=1)
    f = np.stack([-np.sin(t), np.cos(t), np.full_like(t, c)], axis=1)
    return x, f / np.linalg.norm(f, axis=1, keepdims=True)


def test_handedness_of_analytic_helices_and_its_invariances():
    x, f = _helix(0.5)
    assert np.all(helix_handedness(f, x, centre=(0, 0, 0)) == 1)
    x, f = _helix(-0.5)
    assert np.all(helix_handedness(f, x, centre=(0, 0, 0)) == -1)
    # a direction, not a vector; and the axis may point either way: handedness is intrinsic
    assert np.all(helix_handedness(-f, x, centre=(0, 0, 0)) == -1)
    assert np.all(helix_handedness(f, x, axis=(0, 0, -1), centre=(0, 0, 0)) == -1)
    # a mirror image (z -> -z) flips it
    xm, fm = x * [1, 1, -1], f * [1, 1, -1]
    assert np.all(helix_handedness(fm, xm, centre=(0, 0, 0)) == 1)
    # purely circumferential or axial: neither
    t = np.linspace(0, 6, 20)
    ring = np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    assert np.all(helix_handedness(np.stack([-np.sin(t), np.cos(t), 0 * t], 1), ring, centre=(0, 0, 0)) == 0)


def test_twist_of_a_rigidly_rotated_apex_is_negative_seen_from_the_apex():
    """Rotate the apical band by +10° about +z (apex → base: counter-clockwise seen from the base), leave the
    base: seen from the apex that is clockwise, so the twist is −10°; translations do not count."""
    rng = np.random.default_rng(0)
    z = np.linspace(-80.0, 10.0, 19)
    phi = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    Z, P = np.meshgrid(z, phi, indexing="ij")
    x0 = np.stack([30 * np.cos(P), 30 * np.sin(P), Z], axis=-1).reshape(-1, 3)
    ang = np.deg2rad(np.where(x0[:, 2] < -50.0, 10.0, 0.0))
    x1 = np.stack([np.cos(ang) * x0[:, 0] - np.sin(ang) * x0[:, 1],
                   np.sin(ang) * x0[:, 0] + np.cos(ang) * x0[:, 1], x0[:, 2]], axis=1)
    u = x1 - x0 + rng.normal(0, 1) * np.array([1.0, -2.0, 0.5])  # plus a rigid translation
    assert apex_twist_deg(x0, u) == pytest.approx(-10.0, abs=1e-9)
    assert apex_twist_deg(x0, np.zeros_like(x0)) == 0.0
    with pytest.raises(ValueError, match="fraction"):
        apex_twist_deg(x0, u, fraction=0.8)


def _fast_case(alpha_endo, alpha_epi):
    from lvcore.mechanics.case import Case

    case = Case.default_lv({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}, resolution="fast")
    return dataclasses.replace(case, fibres=dataclasses.replace(case.fibres, alpha_endo_deg=alpha_endo,
                                                                alpha_epi_deg=alpha_epi))


def test_lvcore_alpha_sign_is_the_helix_handedness():
    """lvcore's α > 0 is a right-handed helix, so the default α_endo = −60° makes the subendocardium left-handed
    (the anatomical subendocardium is right-handed: lvcore's angles are the anatomical ones with the sign flipped)."""
    from lvcore.geometry.template import lagrange_q2_shape
    from lvcore.mechanics.simulate import build_frames, build_mesh

    for (ae, ap), want_endo, want_epi in (((-60.0, 60.0), -1, 1), ((60.0, -60.0), 1, -1), ((45.0, 45.0), 1, 1)):
        case = _fast_case(ae, ap)
        mesh = build_mesh(case)
        f = build_frames(mesh, case.fibres)[..., 0, :]
        xi, _ = mesh.quadrature
        N = lagrange_q2_shape(xi)
        x = np.einsum("qa,eai->eqi", N[0] if isinstance(N, tuple) else N, mesh.nodes[mesh.elements])
        t = (mesh.template.element_grid[:, 2][:, None] + 0.5 * (xi[None, :, 1] + 1.0)) / mesh.resolution[2]
        h = helix_handedness(f, x, centre=(0.0, 0.0, 0.0))
        assert np.mean(h[t < 0.2] == want_endo) == 1.0, (ae, ap)
        assert np.mean(h[t > 0.8] == want_epi) == 1.0, (ae, ap)


@pytest.fixture(scope="module")
def twists():
    from lvcore.mechanics.simulate import simulate

    out = {}
    for pair in ((45.0, 45.0), (-45.0, -45.0), (0.0, 0.0), (-60.0, 90.0)):
        r = simulate(_fast_case(*pair))
        assert r.converged, pair
        out[pair] = (apex_twist_deg(r.reference_nodes, r.displacement), r.cavity_volume_mm3[1])
    return out


def test_passive_inflation_twists_a_right_handed_helix_clockwise_seen_from_the_apex(twists):
    """Hand derivation (module docstring of lvcore.mechanics.twist): inflation shears the wall to lower the fibre
    strain, E_cl ∝ −sin α cos α, so a right-handed helix (α = +45°) twists the apex clockwise seen from the
    apex (negative) and its mirror (α = −45°) counter-clockwise; purely circumferential fibres do not twist."""
    t_right, v_right = twists[(45.0, 45.0)]
    t_left, v_left = twists[(-45.0, -45.0)]
    assert t_right < -1.0 and t_left > 1.0
    # the default LV is axisymmetric: the mirror fibre field gives the mirror twist and the same volume
    assert t_left == pytest.approx(-t_right, rel=1e-6)
    assert v_left == pytest.approx(v_right, rel=1e-9)
    assert abs(twists[(0.0, 0.0)][0]) < 1e-6


def test_default_angles_twist_sign_is_pinned(twists):
    """lvcore's default (−60°, 90°) twists the apex counter-clockwise seen from the apex in passive inflation
    (about +2.3° on the fast default LV at the population θ, EDP 8 mmHg); a flipped convention flips it."""
    assert 0.5 < twists[(-60.0, 90.0)][0] < 10.0
