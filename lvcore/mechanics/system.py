"""The discrete nonlinear system: energy, residual and tangent of a mechanics problem.

A :class:`DiscreteSystem` gathers the per-element reference data (shape
gradients, weights, fibre frames, projection matrices), the load surface and
the Dirichlet dofs, and evaluates with jitted kernels (compiled once per mesh
topology; parameters, pressure and geometry are traced arguments):

* :meth:`residual` -> mixed residuals (forces on free dofs, element
  pressure-constraint residuals), min J, strain energy;
* :meth:`tangent` -> condensed right-hand side and sparse tangent on free dofs
  (see :mod:`lvcore.mechanics.element`).

Optional, for model-data mismatch studies: per-element multipliers of the
law's parameters (a regional stiffness field; all ones is the homogeneous
law, bit-for-bit) and a linear Robin spring on a surface
(:mod:`lvcore.mechanics.robin`; none by default).

Units: mm, kPa; energies in kPa mm³ (µJ), forces in mN.
"""
from __future__ import annotations

import copy
from functools import lru_cache, partial

import jax
import jax.numpy as jnp
import numpy as np

from lvcore.execution.jax_cache import exported_kernel
from lvcore.mechanics import loads, robin
from lvcore.mechanics.assembly import SparsityPattern, block_dofs, build_pattern, upper_triangle
from lvcore.mechanics.element import element_residual, element_tangent
from lvcore.mechanics.materials import ConstitutiveModel
from lvcore.mechanics.mesh import FEMesh
from lvcore.mechanics.quadrature import p1_basis, reference_jacobians

#: Elements per batch in the element loops (lax.map) of meshes larger than
#: :data:`WHOLE_MESH_ELEMENTS`; bounds peak memory. Small batches keep the
#: per-element 81x81 tangents in cache: on the 2-core CPU machine 8 made the
#: tangent ~2x faster than 48 (and 12,8,2 ~1.4x than 64); at the ``accurate``
#: LV mesh (288 elements) all elements at once take 2x as long as batches of 8.
#: lax.map runs a remainder that does not fill a batch as one extra vectorised step.
ELEMENT_BATCH = 8

#: Meshes with at most this many elements go through the element kernels in one
#: vectorised step, without the loop: the ``fast`` and ``default`` LV meshes (24,
#: 36 elements), whose warm-chained solves took 0.95–0.97x the time so (paired
#: test, BENCHMARKS section 41). Land problem 2 (72 elements) and larger meshes
#: keep the batches.
WHOLE_MESH_ELEMENTS = 64


def _elem_args(data, x, p):
    return (x[data["elements"]], p, data["Jinv"], data["wdet"], data["frames"], data["Minv"], data["scale"])


def _map_elements(fn, data, x, p, model, **kw):
    P, dNdxi = data["P"], data["dNdxi"]

    def one(args):
        *a, s = args
        return fn(*a, P, dNdxi, model.scaled(s), **kw)

    args = _elem_args(data, x, p)
    if data["elements"].shape[0] <= WHOLE_MESH_ELEMENTS:
        return jax.vmap(one)(args)
    return jax.lax.map(one, args, batch_size=ELEMENT_BATCH)


def _external_forces(data, x, pressure, potential):
    """Nodal external forces (f, 9, 3) of the pressure on the load surface."""
    xf = x[data["faces"]]
    if potential:
        g = jax.vmap(jax.grad(loads.face_cavity_volume), in_axes=(0, None))(xf, data["base_z"])
        return pressure * g
    return jax.vmap(loads.follower_force, in_axes=(0, None))(xf, pressure)


def _external_stiffness(data, x, pressure, potential):
    """d(external forces)/dx per face, (f, 27, 27)."""
    xf = x[data["faces"]]
    if potential:
        H = jax.vmap(jax.hessian(loads.face_cavity_volume), in_axes=(0, None))(xf, data["base_z"])
        return (pressure * H).reshape(-1, 27, 27)
    return jax.vmap(jax.jacfwd(loads.follower_force), in_axes=(0, None))(xf, pressure).reshape(-1, 27, 27)


@exported_kernel(static_argnames=("potential", "energy"))
def _residual(u, p, pressure, model, data, potential, energy=True):
    x = data["X"] + u.reshape(-1, 3)
    r_u, r_p, mj, w = _map_elements(element_residual, data, x, p, model, energy=energy)
    R = jnp.zeros_like(x).at[data["elements"]].add(r_u)
    R = R.at[data["faces"]].add(-_external_forces(data, x, pressure, potential))
    R = R.at[data["spring_faces"]].add(_spring_forces(data, u))
    return R.ravel(), r_p, jnp.min(mj), jnp.sum(w)


def _spring_forces(data, u):
    """Nodal forces (m, 9, 3) of the Robin spring faces: ``K_f u_f``."""
    uf = u.reshape(-1, 3)[data["spring_faces"]].reshape(-1, 27)
    return jnp.einsum("mij,mj->mi", data["spring_K"], uf).reshape(-1, 9, 3)


@exported_kernel(static_argnames=("potential",))
def _external_load(pressure, data, potential):
    """The external nodal forces (mN) in the reference configuration, (n_nodes, 3)."""
    x = data["X"]
    return jnp.zeros_like(x).at[data["faces"]].add(_external_forces(data, x, pressure, potential))


@exported_kernel(static_argnames=("potential", "triangle"))
def _tangent(u, p, pressure, model, data, potential, triangle=False):
    """Condensed residual, element tangents (n_el, 6, 27, 27), load-face stiffnesses (f, 27, 27), D, r_p.

    The element tangents come as their six node blocks (layout ``"node_blocks"`` of
    :mod:`lvcore.mechanics.assembly`) either way; ``triangle``: the face matrices as their raveled
    upper triangles (f, 378) (a symmetric tangent). The sum into the sparse pattern, where the
    scatter map picks the upper triangle or mirrors the blocks, is done outside
    (:meth:`DiscreteSystem.tangent`: a SciPy sparse product, ~4x faster on the CPU than XLA's ``segment_sum``).
    """
    x = data["X"] + u.reshape(-1, 3)
    rhs, K, D, r_p = _map_elements(element_tangent, data, x, p, model)
    R = jnp.zeros_like(x).at[data["elements"]].add(rhs.reshape(-1, 27, 3))
    R = R.at[data["faces"]].add(-_external_forces(data, x, pressure, potential))
    R = R.at[data["spring_faces"]].add(_spring_forces(data, u))
    Ks = -_external_stiffness(data, x, pressure, potential)
    return R.ravel(), K, upper_triangle(Ks) if triangle else Ks, D, r_p


@lru_cache(maxsize=32)
def _pattern_cached(key, n_dofs, fixed_bytes, el_bytes, el_shape, f_bytes, f_shape, s_bytes=b"", s_shape=(0, 9),
                    triangle=False):
    fixed = np.frombuffer(fixed_bytes, dtype=np.int64)
    el = np.frombuffer(el_bytes, dtype=np.int64).reshape(el_shape)
    fa = np.frombuffer(f_bytes, dtype=np.int64).reshape(f_shape)
    blocks = [(block_dofs(el), "node_blocks"), block_dofs(fa)]
    if s_shape[0]:
        blocks.append(block_dofs(np.frombuffer(s_bytes, dtype=np.int64).reshape(s_shape)))
    return build_pattern(n_dofs, fixed, blocks, triangle)


class DiscreteSystem:
    """One mechanics problem on one mesh, ready for Newton.

    Parameters
    ----------
    mesh : FEMesh
    model : ConstitutiveModel
        The material law and the compressibility term (bulk penalty κ, kPa).
    frames : (n_el, n_q, 3, 3) fibre frames at the mesh's Gauss points (``mesh.quadrature``).
    load_surface : "endocardium" (pressure potential with the base plane) or a box face.
    pressure : full load (kPa).
    fixed_dofs : global dof numbers held at zero displacement.
    element_scale : (n_el, n_params) array, optional
        Multipliers of the law's parameters (``keys`` order) per element, e.g.
        a regional stiffness field; default all ones (the homogeneous law).
    spring : (surface, k, direction), optional
        A linear Robin spring of stiffness k (kPa/mm) on the named mesh
        surface (:mod:`lvcore.mechanics.robin`); ``None`` or k = 0: none.
    """

    def __init__(self, mesh: FEMesh, model: ConstitutiveModel, frames, load_surface, pressure, fixed_dofs,
                 element_scale=None, spring=None):
        self.mesh = mesh
        self.model = model.as_arrays()
        self.kappa = self.model.kappa
        self.pressure = float(pressure)
        self.potential = load_surface == "endocardium"
        if load_surface not in mesh.surfaces:
            raise ValueError(f"load surface {load_surface!r} not in mesh surfaces {sorted(mesh.surfaces)}")
        faces = np.ascontiguousarray(mesh.surfaces[load_surface], dtype=np.int64)
        xi, w = mesh.quadrature
        dNdxi, Jinv, wdet = reference_jacobians(mesh.nodes, mesh.elements, points=(xi, w))
        P = p1_basis(xi)
        M = np.einsum("eq,qm,qn->emn", wdet, P, P)
        elements = np.ascontiguousarray(mesh.elements, dtype=np.int64)
        fixed = np.unique(np.asarray(fixed_dofs, dtype=np.int64))
        n_par = len(model.material.keys)
        scale = np.ones((mesh.n_elements, n_par)) if element_scale is None else np.asarray(element_scale, float)
        if scale.shape != (mesh.n_elements, n_par):
            raise ValueError(f"element_scale must have shape {(mesh.n_elements, n_par)}, got {scale.shape}")
        spring_faces, spring_K = np.zeros((0, 9), np.int64), np.zeros((0, 27, 27))
        self.spring = None
        if spring is not None and float(spring[1]) > 0:
            surf, k, direction = spring[0], float(spring[1]), spring[2]
            if surf not in mesh.surfaces:
                raise ValueError(f"spring surface {surf!r} not in mesh surfaces {sorted(mesh.surfaces)}")
            spring_faces = np.ascontiguousarray(mesh.surfaces[surf], dtype=np.int64)
            spring_K = robin.face_stiffness(mesh.nodes[spring_faces], k, direction)
            self.spring = (surf, k, direction)
        pattern_args = ((mesh.topology_key(), load_surface, None if self.spring is None else self.spring[0]),
                        mesh.n_dofs, fixed.tobytes(), elements.tobytes(), elements.shape, faces.tobytes(), faces.shape,
                        spring_faces.tobytes(), spring_faces.shape)
        self.pattern: SparsityPattern = _pattern_cached(*pattern_args)
        #: The upper-triangle pattern of a symmetric tangent (pressure potential), built on first use.
        self._triangle_pattern = partial(_pattern_cached, *pattern_args, triangle=True) if self.potential else None
        self.spring_faces, self.spring_K = spring_faces, spring_K
        self.wdet = wdet
        # jax.device_put, not jnp.asarray: the latter compiles a small program per shape (~20 ms each a process)
        self.data = {
            "X": jax.device_put(mesh.nodes),
            "elements": jax.device_put(elements),
            "Jinv": jax.device_put(Jinv),
            "dNdxi": jax.device_put(dNdxi),
            "wdet": jax.device_put(wdet),
            "frames": jax.device_put(frames),
            "Minv": jax.device_put(np.linalg.inv(M)),
            "P": jax.device_put(P),
            "faces": jax.device_put(faces),
            "base_z": jax.device_put(float(mesh.base_z) if mesh.base_z is not None else 0.0),
            "scale": jax.device_put(scale),
            "spring_faces": jax.device_put(spring_faces),
            "spring_K": jax.device_put(spring_K),
        }
        self.free = self.pattern.free
        self._shared = {}  # values computed once per system, shared by its with_model copies
        self.Minv = np.linalg.inv(M)
        self.edofs = block_dofs(elements)

    def with_model(self, model: ConstitutiveModel) -> "DiscreteSystem":
        """The same mesh, frames, load and boundary conditions with another constitutive model.

        Shares every array (and the sparsity pattern with its cached symbolic
        factorisation) with ``self``; only the law's parameters and the bulk
        penalty change, so a batch of solves on one geometry builds its system once.
        """
        out = copy.copy(self)
        out.model = model.as_arrays()
        out.kappa = out.model.kappa
        return out

    # ----- vectors ----------------------------------------------------------
    @property
    def n_free(self) -> int:
        return self.pattern.n_free

    def full(self, u_free: np.ndarray) -> np.ndarray:
        """Free-dof vector -> full dof vector (fixed dofs zero)."""
        u = np.zeros(self.mesh.n_dofs)
        u[self.free] = u_free
        return u

    # ----- evaluations --------------------------------------------------------
    def spring_energy(self, u_free) -> float:
        """Energy stored in the Robin spring (kPa mm³; 0 without one)."""
        if self.spring is None:
            return 0.0
        u = self.full(u_free).reshape(-1, 3)
        return robin.spring_energy(u[self.spring_faces], self.spring_K)

    def load_norm(self) -> float:
        """‖f_ext‖ (mN): the norm of the full external load on the free dofs, in the reference configuration.

        Independent of the material, so computed once per system (and shared by
        :meth:`with_model` copies); Newton's force tolerances are relative to it.
        """
        v = self._shared.get("load_norm")
        if v is None:
            f = np.asarray(_external_load(float(self.pressure), self.data, potential=self.potential)).ravel()
            v = self._shared["load_norm"] = float(np.linalg.norm(f[self.free]))
        return v

    def zero_pressure(self) -> np.ndarray:
        return np.zeros((self.mesh.n_elements, 4))

    def residual(self, u_free, p, load_factor: float, energy: bool = True):
        """Mixed residuals at (u, p): (r_u on free dofs, r_p (n_el, 4), min J, strain energy).

        ``energy=False`` skips the strain energy (returned as None): Newton's calls, which do not use it.
        """
        # NumPy arrays and a Python float go to the jitted kernel as they are (its C++ dispatch
        # transfers them; a jnp.asarray per argument costs more than a small residual)
        R, r_p, mj, w = _residual(self.full(u_free), np.asarray(p, dtype=float), float(load_factor * self.pressure),
                                  self.model, self.data, potential=self.potential, energy=energy)
        return np.asarray(R)[self.free], np.asarray(r_p), float(mj), float(w) if energy else None

    def tangent_pattern(self, triangle: bool = False) -> SparsityPattern:
        """The sparsity pattern of :meth:`tangent` (``triangle``: of its upper triangle; symmetric tangents only).

        Its ``cache`` holds the solvers' symbolic analysis of matrices of that pattern.
        """
        if not triangle:
            return self.pattern
        if self._triangle_pattern is None:
            raise ValueError("only a symmetric tangent (pressure potential) can be assembled as its upper triangle")
        return self._triangle_pattern()

    def tangent(self, u_free, p, load_factor: float, triangle: bool = False):
        """Condensed system: (rhs on free dofs, CSR tangent, D (n_el, 4, 81), r_p (n_el, 4)).

        ``triangle``: the CSR matrix holds the upper triangle of the (symmetric) tangent only, what
        CHOLMOD reads (:func:`lvcore.mechanics.linear.factorize` with ``triangle=True``); half the
        entries to sum. Symmetric tangents (pressure potential) only.
        """
        pattern = self.tangent_pattern(triangle)
        R, K, Ks, D, r_p = _tangent(self.full(u_free), np.asarray(p, dtype=float),
                                    float(load_factor * self.pressure), self.model, self.data,
                                    potential=self.potential, triangle=triangle)
        K, Ks = np.asarray(K).ravel(), np.asarray(Ks).ravel()
        n_el, n_loaded = K.size, K.size + Ks.size
        kd = pattern.scatter(0, n_el) @ K + pattern.scatter(n_el, n_loaded) @ Ks
        if self.spring_K.size:  # the Robin spring's stiffness is constant: summed once per system
            key = ("spring_slots", triangle)
            spring = self._shared.get(key)
            if spring is None:
                values = (upper_triangle(self.spring_K) if triangle else self.spring_K).ravel()
                spring = self._shared[key] = pattern.scatter(n_loaded, n_loaded + values.size) @ values
            kd += spring
        return np.asarray(R)[self.free], pattern.matrix(kd), np.asarray(D), np.asarray(r_p)

    def pressure_increment(self, du_free, D, r_p) -> np.ndarray:
        """Condensed pressure update ``κ M⁻¹ (r_p + D du_e)`` per element, (n_el, 4)."""
        du = self.full(du_free)[self.edofs]
        return float(self.kappa) * np.einsum("emn,en->em", self.Minv, r_p + np.einsum("emk,ek->em", D, du))

    def condensed(self, r_u, r_p, D) -> np.ndarray:
        """Condensed residual ``r_u + κ Dᵀ M⁻¹ r_p`` on the free dofs (D from a tangent call)."""
        q = float(self.kappa) * np.einsum("emn,en->em", self.Minv, r_p)
        # bincount sums repeated dofs like np.add.at, ~10x faster (called once or twice per Newton iteration)
        g = np.bincount(self.edofs.ravel(), weights=np.einsum("emk,em->ek", D, q).ravel(), minlength=self.mesh.n_dofs)
        return r_u + g[self.free]

    def residual_param_jacobian(self, u_free, p, load_factor: float = 1.0) -> np.ndarray:
        """d r_u / d (law parameters) on the free dofs at fixed (u, p), (n_free, n_params).

        Columns in the order of the law's ``keys``.
        """
        u = jnp.asarray(self.full(u_free))
        pr = jnp.asarray(load_factor * self.pressure)
        pj = jnp.asarray(p)

        def r(v):
            return _residual(u, pj, pr, self.model.with_parameters(v), self.data, potential=self.potential)[0]

        return np.asarray(jax.jacfwd(r)(jnp.asarray(self.model.material.vector())))[self.free]
