"""What the simulator reports: cavity volume, regional strains, point positions.

Volume and strains are jax functions of the displacement so that the adjoint
(:mod:`lvcore.mechanics.sensitivities`) can differentiate them.
"""
from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, STRAIN_LAYERS, strain_layer
from lvcore.geometry.template import N_REGIONS, lagrange_q2_shape
from lvcore.mechanics.fibres import lv_wall_frame
from lvcore.mechanics.kinematics import circumferential_green_strain
from lvcore.mechanics.mesh import FEMesh
from lvcore.mechanics.quadrature import gauss_hex, reference_gradients


@dataclass(frozen=True, eq=False)
class StrainOperator:
    """Averaging of circumferential Green strain over the 24 regions.

    Attributes
    ----------
    elements : (m,) elements that contribute; connectivity : (m, 27) their nodes.
    dNdX : (m, q, 27, 3) shape gradients at the strain sampling points.
    e_c : (m, q, 3) reference circumferential unit vectors there.
    weights : (24, m * q) volume weights, each row summing to 1.
    volumes : (24,) reference volume of each region's part of the layer (mm³); None where not kept.
    """

    elements: np.ndarray
    connectivity: np.ndarray
    dNdX: np.ndarray
    e_c: np.ndarray
    weights: np.ndarray
    volumes: np.ndarray | None = None


#: Transmural coordinate at which every band is cut: each half-wall piece is integrated with its own mapped Gauss
#: rule, so the whole wall is exactly the volume-weighted mean of the inner and the outer half.
SPLIT_T = 0.5


def layer_pieces(layer: str, nt: int) -> list[tuple[int, float, float]]:
    """The parts of the transmural element layers inside a strain layer's band, each integrated on its own.

    Parameters
    ----------
    layer : a name of :data:`lvcore.domain.outputs.STRAIN_LAYERS` (or a deprecated alias)
    nt : transmural elements of the mesh

    Returns
    -------
    list of (element layer, t_lo, t_hi)
        The band ``[lo, hi]`` intersected with each element layer ``[et / nt, (et + 1) / nt]`` and cut at
        :data:`SPLIT_T`; empty pieces dropped.
    """
    lo, hi = STRAIN_LAYERS[strain_layer(layer)]
    out = []
    for et in range(nt):
        a, b = max(et / nt, lo), min((et + 1) / nt, hi)
        cuts = [a] + [c for c in (SPLIT_T,) if a + 1e-12 < c < b - 1e-12] + [b]
        out += [(et, p, q) for p, q in zip(cuts[:-1], cuts[1:]) if q > p + 1e-12]
    return out


def strain_operator(mesh: FEMesh, layer: str = DEFAULT_STRAIN_LAYER) -> StrainOperator:
    """Build the regional strain average for an LV mesh.

    The strains are averaged over the layer's transmural band ``[lo, hi]``
    (:data:`lvcore.domain.outputs.STRAIN_LAYERS`, fractions of the wall from
    the endocardium): ``inner_half`` [0, 1/2] (the default), ``mid_wall``
    [1/4, 3/4], ``whole_wall`` [0, 1], ``outer_half`` [1/2, 1]. Each part of
    an element inside the band (:func:`layer_pieces`) is integrated with
    3x3x3 Gauss points mapped into it, so the definition does not depend on
    the resolution. The deprecated names ``endocardial`` and ``wall`` are the
    inner half and the whole wall.

    Raises
    ------
    ValueError
        An unknown layer, or a resolution that leaves a region empty.
    """
    try:
        layer = strain_layer(layer)
    except ValueError as err:
        raise ValueError(str(err)) from None
    tpl = mesh.template
    nt = mesh.resolution[2]
    xi0, w0 = gauss_hex(3)
    parts = []
    for et, lo, hi in layer_pieces(layer, nt):
        b_lo, b_hi = 2 * (lo * nt - et) - 1, 2 * (hi * nt - et) - 1
        xi = xi0.copy()
        xi[:, 1] = b_lo + (xi0[:, 1] + 1) * 0.5 * (b_hi - b_lo)
        w = w0 * 0.5 * (b_hi - b_lo)
        sel = np.flatnonzero(tpl.element_grid[:, 2] == et)
        dNdX, wdet, _ = reference_gradients(mesh.nodes, mesh.elements[sel], points=(xi, w))
        e_c, _, _ = lv_wall_frame(mesh.nodes, mesh.elements[sel], xi)
        parts.append((sel, dNdX, wdet, e_c))
    sel = np.concatenate([p[0] for p in parts])
    dNdX = np.concatenate([p[1] for p in parts])
    wdet = np.concatenate([p[2] for p in parts])
    e_c = np.concatenate([p[3] for p in parts])
    regions = tpl.element_regions[sel]
    W = np.zeros((N_REGIONS,) + wdet.shape)
    for r in range(N_REGIONS):
        W[r, regions == r] = wdet[regions == r]
    tot = W.reshape(N_REGIONS, -1).sum(axis=1)
    if np.any(tot <= 0):
        raise ValueError(
            f"resolution {mesh.resolution} leaves strain regions {np.flatnonzero(tot <= 0).tolist()} empty; "
            "use at least 6 elements around and 4 base to apex"
        )
    return StrainOperator(elements=sel, connectivity=mesh.elements[sel], dNdX=dNdX, e_c=e_c,
                          weights=W.reshape(N_REGIONS, -1) / tot[:, None], volumes=tot)


def regional_strains(x, op: StrainOperator):
    """(24,) circumferential Green strains (end diastole as reference) for current nodes x (n, 3)."""
    xe = x[jnp.asarray(op.connectivity)]
    F = jnp.einsum("eai,eqaJ->eqiJ", xe, jnp.asarray(op.dNdX))
    e = circumferential_green_strain(F, jnp.asarray(op.e_c))
    return jnp.asarray(op.weights) @ e.reshape(-1)


def locate_points(mesh: FEMesh, points, tol: float = 1e-6, n_candidates: int = 12):
    """Find the element and reference coordinates of material points.

    Parameters
    ----------
    points : (n, 3) positions in the reference configuration (mm).

    Returns
    -------
    elem : (n,) element numbers; xi : (n, 3) reference coordinates.

    Raises
    ------
    ValueError naming the first point outside the mesh.
    """
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    X = mesh.nodes[mesh.elements]  # (e, 27, 3)
    centres = X.mean(axis=1)
    elem = np.zeros(len(pts), int)
    xis = np.zeros((len(pts), 3))
    for n, x in enumerate(pts):
        order = np.argsort(np.linalg.norm(centres - x, axis=1))[:n_candidates]
        best = None
        for e in order:
            xi = np.zeros(3)
            for _ in range(30):
                N, dN = lagrange_q2_shape(xi[None], derivatives=True)
                r = N[0] @ X[e] - x
                Jm = X[e].T @ dN[0]
                try:
                    step = np.linalg.solve(Jm, r)
                except np.linalg.LinAlgError:
                    break
                xi = np.clip(xi - step, -1.5, 1.5)
                if np.linalg.norm(step) < 1e-12:
                    break
            err = np.linalg.norm(lagrange_q2_shape(xi[None])[0] @ X[e] - x)
            out = np.max(np.abs(xi)) - 1.0
            if err < 1e-6 * (1 + np.linalg.norm(x)) and out <= tol:
                best = (e, np.clip(xi, -1, 1))
                break
        if best is None:
            raise ValueError(f"probe point {n} at {x.tolist()} mm is not inside the reference mesh")
        elem[n], xis[n] = best
    return elem, xis


def point_positions(x: np.ndarray, mesh: FEMesh, elem: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """Current positions (n, 3) of located material points for current nodes ``x``."""
    if len(elem) == 0:
        return np.zeros((0, 3))
    N = lagrange_q2_shape(xi)
    return np.einsum("na,nad->nd", N, x[mesh.elements[elem]])
