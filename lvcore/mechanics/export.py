"""Write simulation meshes and fields to VTU files (ParaView, PyVista, meshio).

Cells are 27-node hexahedra written as ``VTK_TRIQUADRATIC_HEXAHEDRON``
(meshio ``hexahedron27``); the template's local node order ``a + 3 b + 9 c``
is permuted to VTK's with :data:`lvcore.geometry.io.VTK_FROM_TEMPLATE`. The
points are the *reference* (early-diastolic) node positions; the
displacement to end diastole is the point field ``displacement`` (mm), so
ParaView's "Warp By Vector" shows the deformed LV.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from lvcore.exceptions import LVCoreError


def write_vtu(path, nodes, elements, *, displacement=None, point_data: Mapping[str, Any] | None = None,
              cell_data: Mapping[str, Any] | None = None, field_data: Mapping[str, Any] | None = None) -> Path:
    """Write a 27-node hexahedral mesh with fields as a VTU file.

    Parameters
    ----------
    path : str or Path
        Output file (``.vtu``).
    nodes : (n_nodes, 3) array
        Reference node positions (mm).
    elements : (n_elements, 27) int array
        Connectivity in the template's local order ``a + 3 b + 9 c``.
    displacement : (n_nodes, 3) array, optional
        Nodal displacement (mm), stored as point field ``displacement``.
    point_data : dict name -> (n_nodes, ...) array, optional
    cell_data : dict name -> (n_elements, ...) array, optional
        E.g. ``region`` (0..23) and ``fibre`` directions per element.
    field_data : dict name -> array, optional
        Whole-mesh values (e.g. ``pressure_kpa``).

    Returns
    -------
    Path of the written file.
    """
    import meshio

    from lvcore.geometry.io import VTK_FROM_TEMPLATE, as_q2_mesh

    path = Path(path)
    if path.suffix.lower() != ".vtu":
        raise LVCoreError(f"VTU export needs a path ending in .vtu, got '{path}'")
    nodes, elements = as_q2_mesh(nodes, elements)
    pdata = {}
    if displacement is not None:
        u = np.asarray(displacement, dtype=float)
        if u.shape != nodes.shape:
            raise ValueError(f"displacement must have shape {nodes.shape}, got {u.shape}")
        pdata["displacement"] = u
    for name, val in (point_data or {}).items():
        val = np.asarray(val)
        if val.shape[0] != nodes.shape[0]:
            raise ValueError(f"point field '{name}' has {val.shape[0]} rows, expected {nodes.shape[0]}")
        pdata[name] = val
    cdata = {}
    for name, val in (cell_data or {}).items():
        val = np.asarray(val)
        if val.shape[0] != elements.shape[0]:
            raise ValueError(f"cell field '{name}' has {val.shape[0]} rows, expected {elements.shape[0]}")
        cdata[name] = [val]
    fdata = {name: np.atleast_1d(np.asarray(val)) for name, val in (field_data or {}).items()}
    mesh = meshio.Mesh(points=nodes, cells=[("hexahedron27", elements[:, VTK_FROM_TEMPLATE])],
                       point_data=pdata, cell_data=cdata, field_data=fdata)
    path.parent.mkdir(parents=True, exist_ok=True)
    meshio.write(path, mesh, file_format="vtu")
    return path


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
