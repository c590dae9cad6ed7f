"""The fixed-topology LV template: structured 27-node (quadratic) hexahedra.

Every LV geometry in lvcore (the default LV, analytic ellipsoids, fitted
segmentations, PCA reconstructions) is a set of node positions on one
template, so that geometries can be compared node by node and reduced by PCA.

Topology
--------
A template is defined by its element counts ``(n_circ, n_long, n_trans)``.
Elements are 27-node Lagrange hexahedra (Q2). The node grid has

* ``NC = 2 n_circ`` circumferential positions (periodic), index ``i``;
* ``2 n_long + 1`` longitudinal rows, index ``j``: row 0 is the base, row
  ``2 n_long`` is the apex, where every circumferential position collapses
  onto one node per transmural layer (degenerate elements at the apex);
* ``NT = 2 n_trans + 1`` transmural layers, index ``k``: 0 is the
  endocardium, ``NT - 1`` the epicardium.

Global node numbers: ``(j * NC + i) * NT + k`` for ``j < 2 n_long``, and
``2 n_long * NC * NT + k`` for the apex nodes.

Each node has parametric (material) coordinates ``(phi, s, t)``:
``phi = 2 pi i / NC`` (radians, counter-clockwise seen from the base, from the
+x axis), ``s = j / (2 n_long)`` (0 at the base, 1 at the apex) and
``t = k / (NT - 1)`` (0 endocardium, 1 epicardium).

A *graded* template (``level_elements``, e.g. ``(2, 1, 1, 2)``) places
``level_elements[l]`` equal elements in each of the four short-axis levels
instead of spacing all ``n_long`` element rows evenly in ``s``: element row
boundaries are :attr:`LVTemplate.s_breaks`, and ``s`` is linear in ``j``
within each element row. The topology (numbering, faces) is that of the
uniform template with the same counts; only the parametric coordinates and the
element regions change. Simulation meshes use grading to refine the
boundary layers at the clamped base and the apex (see
:mod:`lvcore.mechanics.mesh`); geometries stored on
:data:`DEFAULT_TEMPLATE` are uniform.

Local element node order: ``a + 3 b + 9 c`` with ``a`` the circumferential,
``b`` the transmural and ``c`` the longitudinal (towards the apex) local index,
each in {0, 1, 2}. With this order the isoparametric map has a positive
Jacobian for an LV with its apex on the negative z axis.

Region map (the 24 strain regions)
----------------------------------
Region ``r = 6 * level + sector`` with

* ``sector = floor(6 phi / 2 pi)``: six 60° sectors, counter-clockwise from
  +x (sector 0 spans phi in [0°, 60°));
* ``level = floor(4 s)``: four short-axis levels from base (0) to apex (3).

Regions are assigned from parametric coordinates, so they are defined for
any resolution (for element centroids or quadrature points alike).

Conventions: mm; the base plane is ``z = base_z`` in the reference
configuration and the apex lies below it on (or near) the z axis.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from lvcore.domain.outputs import N_LEVELS, N_REGIONS, N_SECTORS  # the region map's size is part of the outputs' definition


def checked_level_elements(level_elements, n_long: int) -> tuple[int, ...]:
    """``level_elements`` as a tuple of ints, checked: one count >= 1 per level, summing to ``n_long``.

    Raises
    ------
    ValueError
    """
    le = tuple(int(v) for v in level_elements)
    if len(le) != N_LEVELS or min(le) < 1 or sum(le) != n_long:
        raise ValueError(f"level_elements must be {N_LEVELS} counts >= 1 summing to n_long={n_long}; "
                         f"got {tuple(level_elements)!r}")
    return le


@dataclass(frozen=True)
class LVTemplate:
    """Fixed-topology structured Q2 hexahedral LV mesh topology.

    Parameters
    ----------
    n_circ, n_long, n_trans : int
        Number of quadratic elements circumferentially, base to apex and
        through the wall.
    """

    n_circ: int = 12
    n_long: int = 8
    n_trans: int = 2
    #: Elements per short-axis level, base to apex (graded template), or None (uniform).
    level_elements: tuple[int, ...] | None = None

    def __post_init__(self):
        if self.n_circ < 3 or self.n_long < 1 or self.n_trans < 1:
            raise ValueError(
                "LVTemplate needs n_circ >= 3, n_long >= 1 and n_trans >= 1; got "
                f"({self.n_circ}, {self.n_long}, {self.n_trans})"
            )
        if self.level_elements is not None:
            object.__setattr__(self, "level_elements", checked_level_elements(self.level_elements, self.n_long))

    @classmethod
    def graded(cls, n_circ: int, level_elements, n_trans: int) -> "LVTemplate":
        """A template with ``level_elements[l]`` element rows in short-axis level ``l``."""
        le = tuple(int(v) for v in level_elements)
        return cls(n_circ, sum(le), n_trans, le)

    @cached_property
    def s_breaks(self) -> np.ndarray:
        """(n_long + 1,) longitudinal coordinate s of the element-row boundaries (0 base, 1 apex)."""
        if self.level_elements is None:
            return np.linspace(0.0, 1.0, self.n_long + 1)
        parts = [np.zeros(1)] + [
            (lv + np.arange(1, n + 1) / n) / N_LEVELS for lv, n in enumerate(self.level_elements)
        ]
        return np.concatenate(parts)

    def _s_of_row(self, row) -> np.ndarray:
        """s at fractional element-row coordinates ``row`` in [0, n_long] (linear within a row)."""
        if self.level_elements is None:
            return np.asarray(row, dtype=float) / self.n_long
        return np.interp(row, np.arange(self.n_long + 1), self.s_breaks)

    def _row_of_s(self, s) -> np.ndarray:
        if self.level_elements is None:
            return np.asarray(s, dtype=float) * self.n_long
        return np.interp(s, self.s_breaks, np.arange(self.n_long + 1))

    # ----- sizes -----------------------------------------------------------
    @property
    def nc(self) -> int:
        """Circumferential node positions (periodic)."""
        return 2 * self.n_circ

    @property
    def nl(self) -> int:
        """Longitudinal node rows, base to apex inclusive."""
        return 2 * self.n_long + 1

    @property
    def nt(self) -> int:
        """Transmural node layers, endo to epi inclusive."""
        return 2 * self.n_trans + 1

    @property
    def n_nodes(self) -> int:
        """Number of distinct nodes (apex nodes counted once per layer)."""
        return (self.nl - 1) * self.nc * self.nt + self.nt

    @property
    def n_elements(self) -> int:
        return self.n_circ * self.n_long * self.n_trans

    # ----- numbering ---------------------------------------------------------
    def node_index(self, i, j, k):
        """Global node number of grid position (i, j, k); i is taken modulo NC."""
        i = np.asarray(i) % self.nc
        j = np.asarray(j)
        k = np.asarray(k)
        regular = (j * self.nc + i) * self.nt + k
        apex = (self.nl - 1) * self.nc * self.nt + k
        return np.where(j >= self.nl - 1, apex, regular)

    @cached_property
    def grid_ijk(self) -> np.ndarray:
        """(n_nodes, 3) int array of the grid position of every node (apex: i = 0)."""
        out = np.zeros((self.n_nodes, 3), dtype=int)
        j, i, k = np.meshgrid(
            np.arange(self.nl - 1), np.arange(self.nc), np.arange(self.nt), indexing="ij"
        )
        idx = self.node_index(i, j, k)
        out[idx.ravel()] = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
        kk = np.arange(self.nt)
        out[self.node_index(0, self.nl - 1, kk)] = np.stack(
            [np.zeros_like(kk), np.full_like(kk, self.nl - 1), kk], axis=1
        )
        return out

    @cached_property
    def parametric_coords(self) -> np.ndarray:
        """(n_nodes, 3) array of (phi [rad], s, t) for every node."""
        ijk = self.grid_ijk
        return np.stack(
            [
                2.0 * np.pi * ijk[:, 0] / self.nc,
                self._s_of_row(ijk[:, 1] / 2.0),
                ijk[:, 2] / (self.nt - 1),
            ],
            axis=1,
        )

    @cached_property
    def elements(self) -> np.ndarray:
        """(n_elements, 27) node numbers in the local order ``a + 3 b + 9 c``.

        Element number ``e = (el * n_circ + ec) * n_trans + et``.
        """
        ec, el, et = self.element_grid.T
        a, b, c = _local_abc()
        i = 2 * ec[:, None] + a[None, :]
        k = 2 * et[:, None] + b[None, :]
        j = 2 * el[:, None] + c[None, :]
        return self.node_index(i, j, k).astype(np.int64)

    @cached_property
    def element_grid(self) -> np.ndarray:
        """(n_elements, 3) int array of (ec, el, et) per element."""
        el, ec, et = np.meshgrid(
            np.arange(self.n_long), np.arange(self.n_circ), np.arange(self.n_trans), indexing="ij"
        )
        return np.stack([ec.ravel(), el.ravel(), et.ravel()], axis=1)

    # ----- surfaces ----------------------------------------------------------
    def _faces(self, fixed_axis: str, value: int) -> np.ndarray:
        q = np.arange(9)
        a, b = q % 3, q // 3  # local face order a + 3 b
        rows = []
        if fixed_axis == "k":  # endo (k=0) or epi (k=NT-1) facets: a circ, b long
            for el in range(self.n_long):
                for ec in range(self.n_circ):
                    rows.append(self.node_index(2 * ec + a, 2 * el + b, value))
        else:  # base facets (j = 0): a circ, b trans
            for et in range(self.n_trans):
                for ec in range(self.n_circ):
                    rows.append(self.node_index(2 * ec + a, 0, 2 * et + b))
        return np.asarray(rows, dtype=np.int64)

    @cached_property
    def endo_faces(self) -> np.ndarray:
        """(n_circ * n_long, 9) endocardial quadratic quads, local order a + 3 c.

        Facet number ``el * n_circ + ec``; the (a, c) orientation gives a
        normal that points into the cavity (out of the wall) for an LV with its
        apex on the negative z axis.
        """
        return self._faces("k", 0)

    @cached_property
    def epi_faces(self) -> np.ndarray:
        """(n_circ * n_long, 9) epicardial quadratic quads, local order a + 3 c."""
        return self._faces("k", self.nt - 1)

    @cached_property
    def base_faces(self) -> np.ndarray:
        """(n_circ * n_trans, 9) basal quadratic quads, local order a + 3 b."""
        return self._faces("j", 0)

    @cached_property
    def base_nodes(self) -> np.ndarray:
        """Node numbers on the base plane (row j = 0)."""
        return np.unique(self.base_faces)

    @cached_property
    def endo_nodes(self) -> np.ndarray:
        return np.unique(self.endo_faces)

    @cached_property
    def epi_nodes(self) -> np.ndarray:
        return np.unique(self.epi_faces)

    @property
    def apex_endo_node(self) -> int:
        return int(self.node_index(0, self.nl - 1, 0))

    @property
    def apex_epi_node(self) -> int:
        return int(self.node_index(0, self.nl - 1, self.nt - 1))

    # ----- geometry from a parametric map ------------------------------------
    def nodes_from_map(self, position) -> np.ndarray:
        """Sample a parametric map ``position(phi, s, t) -> (n, 3)`` at every node."""
        p = self.parametric_coords
        x = np.asarray(position(p[:, 0], p[:, 1], p[:, 2]), dtype=float)
        if x.shape != (self.n_nodes, 3):
            raise ValueError(f"position map returned shape {x.shape}, expected {(self.n_nodes, 3)}")
        return x

    def evaluate(self, nodes: np.ndarray, phi, s, t) -> np.ndarray:
        """Evaluate the isoparametric geometry of ``nodes`` at parametric points.

        Parameters
        ----------
        nodes : (n_nodes, 3) array
            Node positions on this template (mm).
        phi, s, t : array_like
            Parametric coordinates (rad, -, -), broadcast together.

        Returns
        -------
        (..., 3) array of positions (mm). This is how a geometry stored on the
        template is resampled onto a finer or coarser simulation mesh.
        """
        nodes = np.asarray(nodes, dtype=float)
        phi, s, t = np.broadcast_arrays(np.asarray(phi, float), np.asarray(s, float), np.asarray(t, float))
        shape = phi.shape
        phi, s, t = phi.ravel(), s.ravel(), t.ravel()
        u = np.mod(phi, 2 * np.pi) / (2 * np.pi) * self.n_circ
        v = self._row_of_s(np.clip(s, 0.0, 1.0))
        w = np.clip(t, 0.0, 1.0) * self.n_trans
        ec = np.minimum(np.floor(u).astype(int), self.n_circ - 1)
        el = np.minimum(np.floor(v).astype(int), self.n_long - 1)
        et = np.minimum(np.floor(w).astype(int), self.n_trans - 1)
        xi = np.stack([u - ec, w - et, v - el], axis=1) * 2.0 - 1.0  # (circ, trans, long)
        e = (el * self.n_circ + ec) * self.n_trans + et
        N = lagrange_q2_shape(xi)  # (n, 27)
        x = np.einsum("na,nad->nd", N, nodes[self.elements[e]])
        return x.reshape(shape + (3,))

    # ----- regions -----------------------------------------------------------
    @staticmethod
    def region_of(phi, s) -> np.ndarray:
        """Strain region ``6 * level + sector`` of parametric points (see module doc)."""
        sector = np.floor(np.mod(phi, 2 * np.pi) / (2 * np.pi) * N_SECTORS).astype(int)
        level = np.floor(np.clip(s, 0.0, 1.0 - 1e-12) * N_LEVELS).astype(int)
        return N_SECTORS * np.clip(level, 0, N_LEVELS - 1) + np.clip(sector, 0, N_SECTORS - 1)

    @cached_property
    def element_centroid_parametric(self) -> np.ndarray:
        """(n_elements, 3) parametric (phi, s, t) of each element centre."""
        ec, el, et = self.element_grid.T
        return np.stack(
            [
                2 * np.pi * (ec + 0.5) / self.n_circ,
                self._s_of_row(el + 0.5),
                (et + 0.5) / self.n_trans,
            ],
            axis=1,
        )

    @cached_property
    def element_regions(self) -> np.ndarray:
        """(n_elements,) strain region of each element, from its centroid."""
        p = self.element_centroid_parametric
        return self.region_of(p[:, 0], p[:, 1])


def _local_abc():
    idx = np.arange(27)
    return idx % 3, (idx // 3) % 3, idx // 9


def _lagrange_1d(x):
    """Quadratic Lagrange basis on nodes (-1, 0, 1) and its derivative; x shape (n,)."""
    N = np.stack([0.5 * x * (x - 1.0), 1.0 - x * x, 0.5 * x * (x + 1.0)], axis=-1)
    dN = np.stack([x - 0.5, -2.0 * x, x + 0.5], axis=-1)
    return N, dN


def lagrange_q2_shape(xi: np.ndarray, derivatives: bool = False):
    """27-node hexahedron shape functions at reference points ``xi`` (n, 3) in [-1, 1]³.

    Local node ``a + 3 b + 9 c`` sits at ``(a - 1, b - 1, c - 1)``.

    Returns
    -------
    N : (n, 27); and with ``derivatives=True`` also dN : (n, 27, 3).
    """
    xi = np.atleast_2d(np.asarray(xi, dtype=float))
    n1, d1 = _lagrange_1d(xi[:, 0])
    n2, d2 = _lagrange_1d(xi[:, 1])
    n3, d3 = _lagrange_1d(xi[:, 2])
    a, b, c = _local_abc()
    N = n1[:, a] * n2[:, b] * n3[:, c]
    if not derivatives:
        return N
    dN = np.stack(
        [d1[:, a] * n2[:, b] * n3[:, c], n1[:, a] * d2[:, b] * n3[:, c], n1[:, a] * n2[:, b] * d3[:, c]],
        axis=-1,
    )
    return N, dN


#: The template that geometries in lvcore are stored on (operators, PCA, cohort).
DEFAULT_TEMPLATE = LVTemplate(12, 8, 2)
