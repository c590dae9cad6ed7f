"""Tetrahedral meshes of analytic LV geometries with gmsh (tests, worked examples, SYNTHETIC subjects).

:func:`ellipsoid_tet_mesh` meshes a :class:`~lvcore.geometry.analytic.TruncatedEllipsoidLV`
(both surfaces full ellipsoids cut by the base plane, as in Land et al. 2015,
problem 2) with linear tetrahedra: the OpenCASCADE kernel builds the outer
ellipsoid minus the inner one, cut by the half-space above ``base_z``. gmsh
(the PyPI wheel, optional extra ``lvcore[mesh]``) is imported on use only.
All lengths in mm.
"""
from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from lvcore.exceptions import GeometryError


@contextlib.contextmanager
def gmsh_model(name: str):
    """A new gmsh model ``name``, terminal output off; yields the ``gmsh`` module.

    gmsh is initialised for the model and finalised after it unless it was
    initialised already (then only the model is removed), so callers nest.

    Raises
    ------
    GeometryError
        When gmsh is not installed (naming the package to install).
    """
    try:
        import gmsh
    except ImportError as err:  # pragma: no cover - depends on the install
        raise GeometryError(f"meshing needs gmsh (pip install gmsh, or lvcore[mesh]): {err}") from None
    initialised_here = not gmsh.isInitialized()
    if initialised_here:
        gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(name)
        yield gmsh
    finally:
        gmsh.model.remove() if gmsh.isInitialized() else None
        if initialised_here:
            gmsh.finalize()


def ellipsoid_tet_mesh(lv, size_mm: float, path=None, rotation=None, shift=None, order: int = 1):
    """Mesh a truncated-ellipsoid LV with tetrahedra.

    Parameters
    ----------
    lv : TruncatedEllipsoidLV
        Geometry (mm); its apex is on −z and its base plane at ``z = lv.base_z``.
    size_mm : float
        Target element size (mm).
    path : str or Path, optional
        Also write the mesh here (any format meshio writes; ``.msh`` is written
        by gmsh itself, format 4.1).
    rotation : (3, 3) array, optional
        Rotate the mesh (``x -> R x``), e.g. to test that the fit finds the axis.
    shift : (3,) array, optional
        Translate the mesh after rotating it (mm).
    order : {1, 2}
        Element order (2 gives 10-node tetrahedra).

    Returns
    -------
    meshio.Mesh
        Points (mm) and one ``tetra`` (or ``tetra10``) block.
    """
    import meshio

    if not size_mm > 0:
        raise GeometryError(f"element size must be positive, got {size_mm}")
    e, p = lv.endo, lv.epi
    zb = float(lv.base_z)
    big = 4.0 * max(p.rs, p.ry or p.rs, p.rl)
    with gmsh_model("lv") as gmsh:
        occ = gmsh.model.occ

        def ellipsoid(s):
            tag = occ.addSphere(0, 0, 0, 1.0)
            occ.dilate([(3, tag)], 0, 0, 0, s.rs, s.ry if s.ry is not None else s.rs, s.rl)
            return tag

        outer, inner = ellipsoid(p), ellipsoid(e)
        shell, _ = occ.cut([(3, outer)], [(3, inner)])
        box = occ.addBox(-big, -big, zb, 2 * big, 2 * big, big)
        wall, _ = occ.cut(shell, [(3, box)])
        occ.synchronize()
        if len(wall) != 1:
            raise GeometryError(f"gmsh produced {len(wall)} volumes for the truncated ellipsoid, expected 1")
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * size_mm)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size_mm)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.mesh.generate(3)
        if order == 2:
            gmsh.model.mesh.setOrder(2)
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        etype = 4 if order == 1 else 11
        _, enodes = gmsh.model.mesh.getElementsByType(etype)
    # gmsh tetra10 edge order (01, 12, 20, 30, 32, 31) -> VTK/meshio (01, 12, 20, 30, 31, 32)
    pts, cells = gmsh_cells(node_tags, coords, enodes, 4 if order == 1 else 10,
                            None if order == 1 else [0, 1, 2, 3, 4, 5, 6, 7, 9, 8])
    if rotation is not None:
        pts = pts @ np.asarray(rotation, float).T
    if shift is not None:
        pts = pts + np.asarray(shift, float)
    mesh = meshio.Mesh(pts, [("tetra" if order == 1 else "tetra10", cells)])
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fmt = {".msh": "gmsh"}.get(path.suffix.lower())
        if fmt:
            meshio.write(path, mesh, file_format="gmsh", binary=False)
        else:
            meshio.write(path, mesh)
    return mesh


__all__ = ["ellipsoid_tet_mesh", "gmsh_cells", "gmsh_model"]


def gmsh_cells(node_tags, coords, element_nodes, nodes_per_cell: int, reorder=None) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 3) and cells (m, ``nodes_per_cell``) from gmsh's node tags and element node tags, keeping only
    the nodes the cells use (0-based, compact); ``reorder`` permutes each cell's nodes (e.g. gmsh -> VTK order)."""
    pts = np.asarray(coords, float).reshape(-1, 3)
    index = np.full(int(np.max(node_tags)) + 1, -1, dtype=np.int64)
    index[np.asarray(node_tags, dtype=np.int64)] = np.arange(len(node_tags))
    cells = index[np.asarray(element_nodes, dtype=np.int64)].reshape(-1, nodes_per_cell)
    if reorder is not None:
        cells = cells[:, reorder]
    used = np.unique(cells)
    remap = np.full(len(pts), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return pts[used], remap[cells]
