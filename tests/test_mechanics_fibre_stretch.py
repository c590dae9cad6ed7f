"""Mean end-diastolic fibre stretch (lvcore.mechanics.fibre_stretch): reference state, homogeneous deformations
of the real LV mesh against |A f0| from independently built frames, and real solves of the default case."""
import dataclasses
import json

import numpy as np
import pytest

from lvcore import resources
from lvcore.mechanics import fibres
from lvcore.mechanics.case import Case
from lvcore.mechanics.fibre_stretch import mean_fibre_stretch
from lvcore.mechanics.quadrature import reference_gradients
from lvcore.mechanics.simulate import build_mesh, simulate


def _default_case(pressure_mmhg=None, resolution=None) -> Case:
    """assets/cases/default_lv.json, optionally at another pressure (mmHg) or resolution preset."""
    d = json.loads(resources.example_cases()["default_lv.json"].read_text())
    if pressure_mmhg is not None:
        d["load"] = {"pressure": pressure_mmhg, "units": "mmHg"}
    if resolution is not None:
        d["geometry"]["resolution"] = resolution
    return Case.from_dict(d)


@pytest.fixture(scope="module")
def unloaded():
    """The default case (default resolution) at zero pressure and its (zero-load) result."""
    case = _default_case(pressure_mmhg=0.0)
    return case, simulate(case, raise_on_failure=True)


@pytest.fixture(scope="module")
def fast_solves():
    """Solves of the default case at the 'fast' resolution at 4 and 8 mmHg."""
    out = {}
    for p in (4.0, 8.0):
        case = _default_case(pressure_mmhg=p, resolution="fast")
        out[p] = (case, simulate(case, raise_on_failure=True))
    return out


def test_zero_displacement_gives_exactly_one(unloaded):
    case, result = unloaded
    assert not np.any(result.displacement)
    assert mean_fibre_stretch(case, result) == 1.0
    assert mean_fibre_stretch(case.to_dict(), result) == 1.0  # the case as its dict form too


def _expected_mean(case, A):
    """Σ w |A f0| / Σ w with f0 from rule_based_frames at the mesh's Gauss points (built here, not by lvcore)."""
    mesh = build_mesh(case)
    xi, w = mesh.quadrature
    t = (mesh.template.element_grid[:, 2][:, None] + 0.5 * (xi[None, :, 1] + 1.0)) / mesh.resolution[2]
    frames, _ = fibres.rule_based_frames(mesh.nodes, mesh.elements, xi, t, case.fibres.alpha_endo_deg,
                                         case.fibres.alpha_epi_deg)
    _, wdet, _ = reference_gradients(mesh.nodes, mesh.elements, points=(xi, w))
    f0 = frames[..., 0, :]
    lam = np.linalg.norm(f0 @ A.T, axis=-1)  # |A f0| at every point
    return float(np.sum(wdet * lam) / np.sum(wdet))


def _rotation(axis, angle):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


@pytest.mark.parametrize("name, A", [
    ("stretch x", np.diag([1.1, 1.0, 1.0])),
    ("shear xy", np.array([[1.0, 0.3, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])),  # not symmetric: F vs Fᵀ
    ("general", np.array([[1.05, 0.1, -0.2], [0.04, 0.95, 0.15], [0.1, -0.05, 1.2]])),
    ("rotation", _rotation((1.0, -2.0, 0.5), 0.7)),
])
def test_homogeneous_deformation_matches_analytic_mean(unloaded, name, A):
    """x = A X on the real default LV mesh: the Q2 field is exact, so the mean is Σ w |A f0| / Σ w."""
    case, result = unloaded
    X = result.reference_nodes
    moved = dataclasses.replace(result, displacement=X @ A.T - X)
    got = mean_fibre_stretch(case, moved)
    expected = _expected_mean(case, A)
    assert got == pytest.approx(expected, rel=1e-12)
    if name == "rotation":
        assert got == pytest.approx(1.0, abs=1e-12)
    else:  # the transposed map gives a different mean: the test tells F from Fᵀ (not for the diagonal A)
        assert name == "stretch x" or abs(_expected_mean(case, A.T) - expected) > 1e-3


def test_real_solve_in_range_and_increasing_with_pressure(fast_solves):
    (c4, r4), (c8, r8) = fast_solves[4.0], fast_solves[8.0]
    m4, m8 = mean_fibre_stretch(c4, r4), mean_fibre_stretch(c8, r8)
    assert 1.0 < m4 < m8 < 1.3


def test_refuses_a_result_of_another_mesh_or_a_failed_solve(unloaded, fast_solves):
    from lvcore.exceptions import SolverError

    case, result = unloaded
    with pytest.raises(ValueError, match="mesh differs"):
        mean_fibre_stretch(case, fast_solves[8.0][1])
    with pytest.raises(SolverError, match="did not converge"):
        mean_fibre_stretch(case, dataclasses.replace(result, converged=False, displacement=None, message="x"))
