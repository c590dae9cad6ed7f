"""Epicardial Robin spring: the face stiffness against hand values, k = 0 is today's solve, and the thick
hemisphere with a spring against the 1-D radial solution."""
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from lvcore.mechanics import robin
from lvcore.mechanics.mesh import box_mesh
from lvcore.mechanics.simulate import build_mesh, build_system, simulate
from lvcore.mechanics.case import Case


def test_flat_face_forces_and_energy_by_hand():
    """A rigid translation u0 of the 2 x 3 mm top face of a box: full spring force k A u0, normal spring
    k A (u0·N) N, energy ½ k A |P u0|²; the stiffness is symmetric positive semidefinite."""
    m = box_mesh((2.0, 3.0, 1.0), (2, 3, 1))
    faces = m.surfaces["z1"]
    X = m.nodes[faces]
    u0 = np.array([0.3, -0.2, 0.5])
    U = np.broadcast_to(u0, X.shape)
    area, k = 6.0, 1.7
    for direction, Pu in (("full", u0), ("normal", np.array([0.0, 0.0, 0.5]))):
        K = robin.face_stiffness(X, k, direction)
        f = np.einsum("mij,mj->mi", K, U.reshape(len(faces), 27)).reshape(-1, 3)
        np.testing.assert_allclose(f.sum(axis=0), k * area * Pu, rtol=1e-12, atol=1e-12)
        assert robin.spring_energy(U, K) == pytest.approx(0.5 * k * area * Pu @ Pu, rel=1e-12)
        np.testing.assert_allclose(K, np.transpose(K, (0, 2, 1)), atol=1e-14)
        assert np.linalg.eigvalsh(K).min() > -1e-12
    with pytest.raises(ValueError, match="direction"):
        robin.face_stiffness(X, k, "tangential")


def test_epicardial_area_of_the_hemisphere():
    """½ k δ² × area for a uniform radial displacement δ of a hemisphere's epicardium (area 2πB²)."""
    B = 15.0
    case = Case.from_dict(_sphere_case(0.0, 1.0, "normal"))
    mesh = build_mesh(case)
    faces = mesh.surfaces["epicardium"]
    X = mesh.nodes[faces]
    radial = X / np.linalg.norm(X, axis=-1, keepdims=True)
    delta, k = 0.4, 2.0
    for direction in ("normal", "full"):
        K = robin.face_stiffness(X, k, direction)
        assert robin.spring_energy(delta * radial, K) == pytest.approx(0.5 * k * delta**2 * 2 * np.pi * B**2,
                                                                       rel=5e-4)  # measured 2.3e-4: the Q2 sphere


A, B, MU, P = 10.0, 15.0, 10.0, 3.5  # mm, mm, kPa, kPa


def _sphere_case(k, pressure=P, direction="normal", resolution=None):
    return {
        "geometry": {"kind": "ellipsoid", "endo": {"rs": A, "rl": A}, "epi": {"rs": B, "rl": B}, "base_z": 0.0,
                     "resolution": resolution or {"circumferential": 12, "longitudinal": 6, "transmural": 2}},
        "material": {"law": "neo-hookean", "mu": MU},
        "fibres": {"alpha_endo": 0, "alpha_epi": 0},
        "load": {"pressure": pressure, "units": "kPa"},
        "boundary": {"base": "sliding", "epicardial_spring": {"k": k, "direction": direction}},
    }


def radial_inner_radius(k, p=P):
    """Inner radius a of the incompressible neo-Hookean sphere with the spring on the outer surface.

    Equilibrium: p − p_o = ∫_a^b 2μ(λ² − λ⁻⁴)/r dr with the outer radius b³ = B³ − A³ + a³ and the
    spring's outer pressure p_o = k (b − B)(B/b)² (force −k (b − B) per reference area on the
    current area b²/B² times larger)."""
    def pressure(a):
        b = (B**3 - A**3 + a**3) ** (1 / 3)
        wall = quad(lambda r: 2 * MU * ((r / (r**3 - a**3 + A**3) ** (1 / 3)) ** 2
                                        - (r / (r**3 - a**3 + A**3) ** (1 / 3)) ** -4) / r, a, b,
                    epsabs=1e-12, epsrel=1e-12)[0]
        return wall + k * (b - B) * (B / b) ** 2

    return brentq(lambda a: pressure(a) - p, A, 1.6 * A, xtol=1e-12)


def test_zero_spring_is_todays_solve_bit_for_bit(fast_lv_case, fast_lv_result):
    d = fast_lv_case.to_dict()
    d["boundary"]["epicardial_spring"] = {"k": 0.0, "direction": "full"}
    r = simulate(d)
    np.testing.assert_array_equal(r.outputs(), fast_lv_result.outputs())
    assert build_system(Case.from_dict(d)).spring is None


@pytest.mark.slow
@pytest.mark.parametrize("k,direction", [(0.5, "normal"), (0.5, "full"), (2.0, "normal")])
def test_hemisphere_with_spring_matches_the_radial_solution(k, direction):
    """Thick hemisphere (sliding base = the sphere by symmetry) with a spring on the epicardium: cavity
    volume and apex against the 1-D radial solution; the spring holds it well below the free inflation."""
    r = simulate(_sphere_case(k, direction=direction))
    assert r.converged, r.message
    a, a_free = radial_inner_radius(k), radial_inner_radius(0.0)
    assert (a - A) < 0.9 * (a_free - A)  # the spring matters
    assert r.cavity_volume_mm3[1] == pytest.approx(2.0 / 3.0 * np.pi * a**3, rel=1e-3)
    assert r.apex_endocardium[2] == pytest.approx(-a, rel=5e-4)
    b = (B**3 - A**3 + a**3) ** (1 / 3)
    assert r.apex_epicardium[2] == pytest.approx(-b, rel=5e-4)
