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

    from lvcore.geometry.io import VTK_FROM_TEMPLATE

    path = Path(path)
    if path.suffix.lower() != ".vtu":
        raise LVCoreError(f"VTU export needs a path ending in .vtu, got '{path}'")
    nodes = np.asarray(nodes, dtype=float)
    elements = np.asarray(elements, dtype=np.int64)
    if nodes.ndim != 2 or nodes.shape[1] != 3:
        raise ValueError(f"nodes must have shape (n, 3), got {nodes.shape}")
    if elements.ndim != 2 or elements.shape[1] != 27:
        raise ValueError(f"elements must have shape (n_elements, 27), got {elements.shape}")
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
