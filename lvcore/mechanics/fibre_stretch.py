"""End-diastolic fibre stretch of a solved case: ``mean_fibre_stretch(case, result)``.

The fibre stretch at a material point is ``λ_f = |F f0| / |f0|`` (-), with
``F = I + ∇_X u`` the deformation gradient from the reference
(early-diastolic) configuration to the loaded state of a converged
:func:`lvcore.mechanics.simulate.simulate` result and ``f0`` the case's fibre
direction (rule-based for an LV, :mod:`lvcore.mechanics.fibres`). The mean is
over the whole wall with the simulator's own quadrature rule
(``mesh.quadrature``: 3 × 5 × 3 Gauss points per element at the default
resolution), weighted by reference volume (quadrature weight × det(∂X/∂ξ), mm³).

Everything that does not depend on the displacement (reference inverse
Jacobians, shape-function gradients, weights and the fibre frames at the
Gauss points) is read from the case's :class:`~lvcore.mechanics.simulate.PreparedCase`
(cached per process by :func:`~lvcore.mechanics.simulate.prepare_case`, a cache
hit after the solve), so a call costs well under a millisecond at the default
resolution (NumPy; no compilation).

This module imports :mod:`lvcore.mechanics.simulate` (which imports
:mod:`lvcore.mechanics.observables`), so it is not part of ``observables``.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from lvcore.exceptions import SolverError
from lvcore.mechanics.case import Case
from lvcore.mechanics.simulate import prepare_case
from lvcore.mechanics.system import DiscreteSystem


def fibre_stretch_field(system: DiscreteSystem, displacement) -> tuple[np.ndarray, np.ndarray]:
    """Fibre stretch at every Gauss point of a system's mesh, and the points' volume weights.

    Parameters
    ----------
    system : DiscreteSystem
        The discrete system of the case (its mesh, quadrature data and fibre frames).
    displacement : (n_nodes, 3) or (3 n_nodes,) array
        Nodal displacements (mm) from the reference configuration.

    Returns
    -------
    stretch : (n_el, n_q) array
        ``λ_f = |F f0| / |f0|`` (-), ``F = I + ∇_X u`` at each Gauss point.
    weights : (n_el, n_q) array
        Quadrature weight × reference det(∂X/∂ξ) (mm³); they sum to the wall volume.
    """
    data = system.data
    elements = np.asarray(data["elements"])
    u = np.asarray(displacement, dtype=float).reshape(-1, 3)
    if u.shape[0] != system.mesh.n_nodes:
        raise ValueError(f"displacement has {u.shape[0]} nodes, the mesh {system.mesh.n_nodes}")
    f0 = np.asarray(data["frames"])[..., 0, :]  # (e, q, 3)
    Jinv = np.asarray(data["Jinv"])  # (e, q, K, J) = ∂ξ_K/∂X_J
    dNdxi = np.asarray(data["dNdxi"])  # (q, a, K)
    # (∇u f0)_i = Σ_a u_ai (∂N_a/∂X · f0), ∂N_a/∂X_J = Σ_K ∂N_a/∂ξ_K ∂ξ_K/∂X_J
    g = np.einsum("qaK,eqK->eqa", dNdxi, np.einsum("eqKJ,eqJ->eqK", Jinv, f0))
    Ff0 = f0 + np.einsum("eai,eqa->eqi", u[elements], g)
    return np.linalg.norm(Ff0, axis=-1) / np.linalg.norm(f0, axis=-1), np.asarray(system.wdet)


def mean_fibre_stretch(case, result) -> float:
    """Volume-weighted mean fibre stretch (-) over the wall of a converged solve of ``case``.

    ``Σ w λ_f / Σ w`` over all Gauss points of all elements (:func:`fibre_stretch_field`; weights = reference
    det(∂X/∂ξ) × quadrature weight), with ``λ_f = |F f0|`` the stretch along the rule-based fibre direction from
    the reference (early-diastolic) to the loaded (end-diastolic) state. Exactly 1 at zero displacement.

    Parameters
    ----------
    case : lvcore.mechanics.case.Case or dict
        The case that was solved (its geometry, resolution and fibres define the mesh and the fibre frames;
        its material parameters do not matter).
    result : lvcore.mechanics.simulate.SimulationResult
        ``simulate(case)``: reads ``displacement`` (n_nodes, 3) (mm), ``reference_nodes`` and ``elements``.

    Returns
    -------
    float

    Raises
    ------
    SolverError
        If the solve did not converge (no displacement).
    ValueError
        If ``result`` is not a solve of this case's mesh.
    """
    if not result.converged or result.displacement is None:
        raise SolverError(f"simulation did not converge: {result.message}")
    prep = prepare_case(Case.from_dict(case) if isinstance(case, Mapping) else case)
    mesh = prep.mesh
    if not (np.array_equal(result.reference_nodes, mesh.nodes) and np.array_equal(result.elements, mesh.elements)):
        raise ValueError("result is not a solve of this case: its reference mesh differs from the case's mesh")
    stretch, w = fibre_stretch_field(prep.system, result.displacement)
    # 1 + mean(λ − 1): exactly 1 when every λ is (zero displacement), and no cancellation near 1
    return float(1.0 + np.sum(w * (stretch - 1.0)) / np.sum(w))


__all__ = ["mean_fibre_stretch", "fibre_stretch_field"]
