"""Finite-element meshes of quadratic (27-node) hexahedra for the simulator.

* LV meshes sample a parametric map ``position(phi, s, t) -> xyz`` (mm) at a
  resolution (:class:`LVResolution`: elements around, per short-axis level or
  evenly base to apex, through the wall, and the Gauss points through the
  wall) with :meth:`lvcore.geometry.template.LVTemplate.nodes_from_map`, so
  any LV geometry (analytic, fitted, PCA) is simulated at the simulator's own
  resolution.
* Box meshes discretise ``[0, Lx] x [0, Ly] x [0, Lz]`` (mm) with named faces
  ``x0, x1, y0, y1, z0, z1``.

Surface quads are stored with local order ``a + 3 b`` such that
``dX/da x dX/db`` points out of the solid (for the endocardium: into the
cavity).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lvcore.exceptions import GeometryError
from lvcore.geometry.template import LVTemplate
from lvcore.mechanics.quadrature import gauss_hex_points, reference_gradients
from lvcore.mechanics.resolution import BoxResolution, LVResolution

BOX_FACE_NAMES = ("x0", "x1", "y0", "y1", "z0", "z1")


@dataclass(frozen=True, eq=False)
class FEMesh:
    """A Q2 hexahedral mesh with named surfaces.

    Attributes
    ----------
    kind : "lv" or "box".
    nodes : (n_nodes, 3) reference positions (mm).
    elements : (n_el, 27) connectivity, local node ``a + 3 b + 9 c``.
    resolution : element counts (LV: circ, long, trans; box: x, y, z).
    surfaces : name -> (n_faces, 9) outward-oriented quadratic quads
        (LV: "endocardium", "epicardium", "base"; box: the six faces).
    node_sets : name -> node numbers (LV: "base"; box: the six faces).
    template : the LVTemplate (LV meshes) or None.
    base_z : base-plane height (mm) for LV meshes, else None.
    transmural_gauss_points : Gauss points through the wall (LV) or along y
        (box) per element; 3 in the other directions.
    """

    kind: str
    nodes: np.ndarray
    elements: np.ndarray
    resolution: tuple[int, int, int]
    surfaces: dict = field(default_factory=dict)
    node_sets: dict = field(default_factory=dict)
    template: LVTemplate | None = None
    base_z: float | None = None
    transmural_gauss_points: int = 3

    @property
    def quadrature(self):
        """(xi (q, 3), w (q,)) element quadrature rule of this mesh."""
        return gauss_hex_points(3, self.transmural_gauss_points)

    @property
    def n_nodes(self) -> int:
        return int(self.nodes.shape[0])

    @property
    def n_elements(self) -> int:
        return int(self.elements.shape[0])

    @property
    def n_dofs(self) -> int:
        return 3 * self.n_nodes

    def topology_key(self) -> tuple:
        """Hashable description of the topology (for caching compiled kernels)."""
        return (self.kind, self.resolution, self.template.level_elements if self.template else None,
                self.transmural_gauss_points)


def _check_elements(nodes, elements, what):
    _, _, det = reference_gradients(nodes, elements)
    if not np.all(np.isfinite(det)) or np.min(det) <= 0:
        bad = int(np.sum(~(det > 0)))
        raise GeometryError(
            f"{what}: {bad} quadrature points have a non-positive Jacobian (inverted or "
            "self-intersecting geometry); check the geometry or use a finer resolution"
        )


def lv_mesh(position, resolution, base_z: float) -> FEMesh:
    """Mesh an LV parametric map.

    Parameters
    ----------
    position : callable ``(phi, s, t) -> (n, 3)`` (mm).
    resolution : LVResolution, or (n_circ, n_long, n_trans) quadratic elements
        (n_long evenly spaced rows, 3 Gauss points through the wall).
    base_z : height of the (planar) base (mm).
    """
    if not isinstance(resolution, LVResolution):
        resolution = LVResolution(*(int(v) for v in resolution))
    nc, nl, nt = resolution.counts
    tpl = resolution.template()
    gp = resolution.transmural_gauss_points
    nodes = tpl.nodes_from_map(position)
    if not np.all(np.isfinite(nodes)):
        raise GeometryError("the LV position map returned non-finite coordinates")
    elements = tpl.elements
    _check_elements(nodes, elements, "LV mesh")
    return FEMesh(
        kind="lv",
        nodes=nodes,
        elements=elements,
        resolution=(nc, nl, nt),
        surfaces={"endocardium": tpl.endo_faces, "epicardium": _flip(tpl.epi_faces), "base": tpl.base_faces},
        node_sets={"base": tpl.base_nodes},
        template=tpl,
        base_z=float(base_z),
        transmural_gauss_points=gp,
    )


def _flip(faces):
    """Swap the local a, b directions of quads (reverses the normal)."""
    idx = np.arange(9).reshape(3, 3).T.ravel()  # new a + 3b <- old b + 3a
    return faces[:, idx]


def box_mesh(size, resolution) -> FEMesh:
    """Q2 mesh of the box ``[0, Lx] x [0, Ly] x [0, Lz]`` (mm) with ``resolution`` a BoxResolution or (nx, ny, nz)."""
    size = tuple(float(v) for v in size)
    if any(not (L > 0) for L in size):
        raise GeometryError(f"box size must be positive, got {size}")
    if not isinstance(resolution, BoxResolution):
        resolution = BoxResolution(*resolution)
    nx, ny, nz = resolution.xyz
    mx, my, mz = 2 * nx + 1, 2 * ny + 1, 2 * nz + 1
    xs = [np.linspace(0.0, L, m) for L, m in zip(size, (mx, my, mz))]

    def nid(i, j, k):
        return (k * my + j) * mx + i

    K, J, I = np.meshgrid(np.arange(mz), np.arange(my), np.arange(mx), indexing="ij")
    nodes = np.stack([xs[0][I.ravel()], xs[1][J.ravel()], xs[2][K.ravel()]], axis=1)
    loc = np.arange(27)
    a, b, c = loc % 3, (loc // 3) % 3, loc // 9
    ez, ey, ex = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    ex, ey, ez = ex.ravel(), ey.ravel(), ez.ravel()
    elements = nid(2 * ex[:, None] + a, 2 * ey[:, None] + b, 2 * ez[:, None] + c).astype(np.int64)

    q = np.arange(9)
    fa, fb = q % 3, q // 3
    surfaces, node_sets = {}, {}
    spec = {  # face: (fixed axis, value index, tangential axes, outward sign)
        "x0": (0, 0, (1, 2), -1), "x1": (0, mx - 1, (1, 2), +1),
        "y0": (1, 0, (2, 0), -1), "y1": (1, my - 1, (2, 0), +1),
        "z0": (2, 0, (0, 1), -1), "z1": (2, mz - 1, (0, 1), +1),
    }
    counts = (nx, ny, nz)
    for name, (ax, val, (t1, t2), sign) in spec.items():
        rows = []
        for e2 in range(counts[t2]):
            for e1 in range(counts[t1]):
                ijk = [None, None, None]
                ijk[ax] = np.full(9, val)
                ijk[t1] = 2 * e1 + fa
                ijk[t2] = 2 * e2 + fb
                rows.append(nid(*ijk))
        faces = np.asarray(rows, dtype=np.int64)
        # (t1, t2) is cyclic so dX/da x dX/db points along +axis; flip for the "0" faces
        if sign < 0:
            faces = _flip(faces)
        surfaces[name] = faces
        node_sets[name] = np.unique(faces)
    return FEMesh(kind="box", nodes=nodes, elements=elements, resolution=(nx, ny, nz),
                  surfaces=surfaces, node_sets=node_sets)
