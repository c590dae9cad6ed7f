"""Write simulation results to VTU files (ParaView, PyVista, meshio).

The file is written by :func:`lvcore.geometry.io.write_vtu`, lvcore's one VTU
writer. Cells are 27-node hexahedra written as ``VTK_TRIQUADRATIC_HEXAHEDRON``
(meshio ``hexahedron27``); the template's local node order ``a + 3 b + 9 c``
is permuted to VTK's with :data:`lvcore.geometry.io.VTK_FROM_TEMPLATE`. The
points are the *reference* (early-diastolic) node positions; the
displacement to end diastole is the point field ``displacement`` (mm), so
ParaView's "Warp By Vector" shows the deformed LV.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lvcore.exceptions import LVCoreError
from lvcore.geometry.io import write_vtu


def result_fields(result, case=None) -> dict:
    """Cell fields of a simulation mesh for export and pictures.

    Parameters
    ----------
    result : lvcore.mechanics.simulate.SimulationResult
    case : lvcore.mechanics.case.Case, optional
        The simulated case; needed for the strain ``region`` of each element
        (LV meshes) and the ``fibre`` direction at each element centre.

    Returns
    -------
    dict name -> (n_elements, ...) array (empty without ``case``).
    """
    if case is None:
        return {}
    from lvcore.mechanics.simulate import build_frames, build_mesh

    mesh = build_mesh(case)
    if mesh.elements.shape != np.shape(result.elements) or not np.array_equal(mesh.elements, result.elements):
        raise LVCoreError("the case does not match the result's mesh (different geometry or resolution)")
    fields = {}
    if mesh.template is not None:
        fields["region"] = mesh.template.element_regions.astype(np.int32)
    frames = build_frames(mesh, case.fibres)  # (n_el, 27 Gauss points, 3 rows f0 s0 n0, 3)
    fields["fibre"] = frames[:, 13, 0, :]  # Gauss point 13 of the 3x3x3 rule is the element centre
    return fields


def export_result(result, path, case=None) -> Path:
    """Write a simulation result to VTU: reference mesh, ``displacement`` (mm), cell fields.

    Parameters
    ----------
    result : lvcore.mechanics.simulate.SimulationResult
        A failed solve (``converged`` False) writes the reference mesh only.
    path : str or Path
        Output ``.vtu`` file.
    case : Case, optional
        Adds ``region`` (0..23, LV meshes) and ``fibre`` cell fields, and the
        load as field data.

    Returns
    -------
    Path of the written file.
    """
    field_data = {"converged": np.array([int(bool(result.converged))])}
    if case is not None:
        field_data["pressure_kpa"] = np.array([float(case.load.pressure_kpa)])
    return write_vtu(path, result.reference_nodes, result.elements, displacement=result.displacement,
                     cell_data=result_fields(result, case), field_data=field_data)


def result_vtu_bytes(result, case=None) -> bytes:
    """The VTU file of :func:`export_result` as bytes (for downloads)."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = export_result(result, Path(tmp) / "result.vtu", case)
        return path.read_bytes()
