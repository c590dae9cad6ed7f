"""Dirichlet boundary conditions as lists of fixed dofs (displacement held at zero).

* LV ``"clamped"``: every dof of the base-plane nodes.
* LV ``"sliding"``: the z dof of every base node (the base stays in its
  plane) plus the three in-plane rigid-body modes: x and y of the
  endocardial base node at phi = 0 and y of the one at phi = 180°.
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
            a = int(tpl.node_index(0, 0, 0))
            b = int(tpl.node_index(tpl.nc // 2, 0, 0))
            return np.unique(np.concatenate([3 * nodes + 2, [3 * a, 3 * a + 1, 3 * b + 1]]))
        raise ValueError(f"LV base condition must be 'clamped' or 'sliding', got {base!r}")
    if not clamped_faces:
        raise ValueError("a box needs at least one clamped face (boundary.clamped_faces)")
    dofs = [node_dofs(mesh.node_sets[f]) for f in clamped_faces]
    return np.unique(np.concatenate(dofs))
