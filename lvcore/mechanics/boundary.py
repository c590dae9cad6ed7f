"""Dirichlet boundary conditions as lists of fixed dofs (displacement held at zero).

* LV ``"clamped"``: every dof of the base-plane nodes.
* LV ``"sliding"``: the z dof of every base node (the base stays in its
  plane) plus the three in-plane rigid-body modes, removed by holding the
  *circumferential* displacement of three endocardial base nodes: y at
  phi = 0° and phi = 180° (y translation and rotation about z) and x at
  phi ≈ 90° (x translation). Radial motion stays free, so an axisymmetric
  inflation is not disturbed (an earlier version held x at phi = 0, which
  blocked the radial expansion of that node).
* Box: every dof of the nodes of each clamped face.
"""
from __future__ import annotations

import numpy as np

from lvcore.mechanics.mesh import FEMesh


def node_dofs(nodes) -> np.ndarray:
    """All three dofs of ``nodes``."""
    return (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).ravel()


def fixed_dofs(mesh: FEMesh, base: str | None = None, clamped_faces=()) -> np.ndarray:
    """Fixed dof numbers for an LV base condition or box clamped faces."""
    if mesh.kind == "lv":
        nodes = mesh.node_sets["base"]
        if base in (None, "clamped"):
            return node_dofs(nodes)
        if base == "sliding":
            tpl = mesh.template
            at_0 = int(tpl.node_index(0, 0, 0))
            at_180 = int(tpl.node_index(tpl.nc // 2, 0, 0))
            at_90 = int(tpl.node_index(round(tpl.nc / 4), 0, 0))
            return np.unique(np.concatenate([3 * nodes + 2, [3 * at_0 + 1, 3 * at_180 + 1, 3 * at_90]]))
        raise ValueError(f"LV base condition must be 'clamped' or 'sliding', got {base!r}")
    if not clamped_faces:
        raise ValueError("a box needs at least one clamped face (boundary.clamped_faces)")
    dofs = [node_dofs(mesh.node_sets[f]) for f in clamped_faces]
    return np.unique(np.concatenate(dofs))
