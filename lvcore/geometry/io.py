"""Template meshes on disk: VTU files of 27-node hexahedra.

A geometry in lvcore is the node array of :data:`DEFAULT_TEMPLATE` (mm). It is
written as an unstructured-grid VTU file whose cells are
``VTK_TRIQUADRATIC_HEXAHEDRON`` (VTK cell type 29, meshio ``hexahedron27``),
so ParaView and PyVista show it directly.

Node order
----------
The template's local element order is ``a + 3 b + 9 c`` (circumferential,
transmural, longitudinal index, each 0..2; see :mod:`lvcore.geometry.template`).
VTK orders the 27 nodes of a triquadratic hexahedron as 8 corners, 12 edge
mid-points, 6 face centres and the centre. With VTK's parametric axes
``(r, s, t)`` identified with ``(a, b, c) / 2`` (the same handedness, so the
Jacobian keeps its sign) the VTK node ``m`` is the template's local node
``VTK_FROM_TEMPLATE[m]``::

    vtk_cells = template.elements[:, VTK_FROM_TEMPLATE]
    template_elements = vtk_cells[:, TEMPLATE_FROM_VTK]

The point array of the file is the template's global node array itself
(``points[n]`` is node ``n``); :func:`read_template_mesh` checks that the
connectivity is exactly the template's, so files from other tools that
renumber points are rejected with a clear message rather than misread.
"""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from lvcore.exceptions import GeometryError
from lvcore.geometry.template import DEFAULT_TEMPLATE, LVTemplate, lagrange_q2_shape

#: VTK parametric coordinates (r, s, t) of the 27 nodes of VTK_TRIQUADRATIC_HEXAHEDRON,
#: as returned by ``vtkTriQuadraticHexahedron().GetParametricCoords()``.
VTK_TRIQUADRATIC_HEX_PCOORDS = np.array(
    [
        [0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
        [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
        [0.5, 0, 0], [1, 0.5, 0], [0.5, 1, 0], [0, 0.5, 0],
        [0.5, 0, 1], [1, 0.5, 1], [0.5, 1, 1], [0, 0.5, 1],
        [0, 0, 0.5], [1, 0, 0.5], [1, 1, 0.5], [0, 1, 0.5],
        [0, 0.5, 0.5], [1, 0.5, 0.5], [0.5, 0, 0.5], [0.5, 1, 0.5],
        [0.5, 0.5, 0], [0.5, 0.5, 1], [0.5, 0.5, 0.5],
    ]
)
#: VTK cell type number of the triquadratic hexahedron.
VTK_TRIQUADRATIC_HEXAHEDRON = 29
#: ``VTK_FROM_TEMPLATE[m]`` = template local node (a + 3 b + 9 c) of VTK node m.
VTK_FROM_TEMPLATE = np.array(
    [int(round(2 * r)) + 3 * int(round(2 * s)) + 9 * int(round(2 * t)) for r, s, t in VTK_TRIQUADRATIC_HEX_PCOORDS],
    dtype=np.int64,
)
#: Inverse permutation: ``TEMPLATE_FROM_VTK[q]`` = VTK node of template local node q.
TEMPLATE_FROM_VTK = np.argsort(VTK_FROM_TEMPLATE)

_MESHIO_TYPE = "hexahedron27"
_FIELD_TEMPLATE = "lvcore_template"


def template_to_vtk_cells(template: LVTemplate = DEFAULT_TEMPLATE) -> np.ndarray:
    """(n_elements, 27) connectivity of ``template`` in VTK node order."""
    return template.elements[:, VTK_FROM_TEMPLATE]


def write_template_mesh(path, nodes, template: LVTemplate = DEFAULT_TEMPLATE, point_data=None,
                        metadata: dict | None = None) -> Path:
    """Write node positions on ``template`` as a VTU of triquadratic hexahedra.

    Parameters
    ----------
    path : str or Path
        Output file; must end in ``.vtu``.
    nodes : (n_nodes, 3) array
        Node positions (mm).
    template : LVTemplate
        Topology of ``nodes`` (default :data:`DEFAULT_TEMPLATE`).
    point_data : dict of name -> (n_nodes, ...) arrays, optional
        Extra per-node fields (e.g. a distance map, mm).
    metadata : dict of str -> str, optional
        Stored as string field data ``lvcore_<key>`` (e.g. ``{"label": "SYNTHETIC"}``).

    Returns
    -------
    Path of the written file.
    """
    nodes = _check_nodes(nodes, template, "nodes")
    pdata = {"parametric_coords": template.parametric_coords.astype(float)}
    for key, val in (point_data or {}).items():
        val = np.asarray(val)
        if val.shape[0] != template.n_nodes:
            raise GeometryError(f"point_data '{key}' has {val.shape[0]} rows, expected {template.n_nodes}")
        pdata[key] = val
    field = {_FIELD_TEMPLATE: np.array([template.n_circ, template.n_long, template.n_trans], dtype=np.int64)}
    path = write_vtu(path, nodes, template.elements, point_data=pdata, field_data=field)
    if metadata:
        _append_metadata(path, metadata)
    return path


def write_vtu(path, nodes, elements, *, displacement=None, point_data: Mapping[str, Any] | None = None,
              cell_data: Mapping[str, Any] | None = None, field_data: Mapping[str, Any] | None = None) -> Path:
    """Write a 27-node hexahedral mesh with fields as a VTU file (the one VTU writer of lvcore).

    Parameters
    ----------
    path : str or Path
        Output file (``.vtu``).
    nodes : (n_nodes, 3) array
        Node positions (mm).
    elements : (n_elements, 27) int array
        Connectivity in the template's local order ``a + 3 b + 9 c``
        (written in VTK order with :data:`VTK_FROM_TEMPLATE`).
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

    Raises
    ------
    GeometryError
        If ``path`` does not end in ``.vtu``.
    ValueError
        If an array does not match the mesh.
    """
    import meshio

    path = Path(path)
    if path.suffix.lower() != ".vtu":
        raise GeometryError(f"meshes are written as VTU; give a path ending in .vtu, got '{path}'")
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
    mesh = meshio.Mesh(points=nodes, cells=[(_MESHIO_TYPE, elements[:, VTK_FROM_TEMPLATE])],
                       point_data=pdata, cell_data=cdata, field_data=fdata)
    path.parent.mkdir(parents=True, exist_ok=True)
    meshio.write(path, mesh, file_format="vtu")
    return path


def _append_metadata(path: Path, metadata: dict) -> None:
    """Record string metadata as an XML comment after the VTU header (readers ignore it)."""
    import json

    text = path.read_text()
    comment = "<!-- lvcore metadata: " + json.dumps({str(k): str(v) for k, v in metadata.items()}).replace("--", "- -") + " -->\n"
    head, sep, rest = text.partition("?>\n")
    if sep:
        path.write_text(head + sep + comment + rest)
    else:
        path.write_text(comment + text)


def read_meshio_file(path, what: str, max_bytes: int, hint: str):
    """Read a mesh file with meshio, every failure a :class:`GeometryError`.

    Parameters
    ----------
    path : str or Path
        A regular file of at most ``max_bytes`` bytes.
    what : str
        What the file is, for messages (e.g. ``"template mesh"``).
    max_bytes : int
        Size limit (:mod:`lvcore.safety.limits`).
    hint : str
        What to do instead, appended to the message when meshio cannot read it.

    Returns
    -------
    meshio.Mesh
    """
    from lvcore.safety import limits
    from lvcore.safety.headers import check_mesh_header
    from lvcore.safety.isolation import run_isolated

    path = limits.check_regular_file(path, max_bytes, what, GeometryError)
    check_mesh_header(path, what, GeometryError)
    # parsed in a memory-limited child: a crafted file cannot crash or exhaust the caller (lvcore.safety.isolation)
    return run_isolated(_meshio_read, path, what, hint, what=what, path=path, error=GeometryError)


def _meshio_read(path: Path, what: str, hint: str):
    """``meshio.read`` with every failure a :class:`GeometryError` that says what the file should be."""
    import meshio

    fmt = path.suffix.lower().lstrip(".") or "mesh"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return meshio.read(path)
    except SystemExit:  # meshio sys.exit()s on some files without a message
        raise GeometryError(f"cannot read {what} '{path}': it is not a valid .{fmt} file "
                            f"(the mesh reader gave up on its contents); {hint}") from None
    except Exception as err:  # noqa: BLE001 - meshio raises many types
        detail = " ".join(str(err).split())[:200] or "no detail"
        if isinstance(err, UnicodeDecodeError):
            detail = f"byte {err.start} is not text; is it a binary file saved with the wrong extension?"
        raise GeometryError(f"cannot read {what} '{path}': it is not a valid .{fmt} file ({detail}); {hint}") from None


#: Template meshes already read and checked, by file identity (path, inode, size, modification time) and template:
#: a campaign or a BO parses the same mesh for every case (440 times for one subject EDPVR emulator, each in an
#: isolated child process: 40 % of its build). A changed file has another identity and is read again.
_MESH_CACHE: dict = {}
_MESH_CACHE_SIZE = 16


def _mesh_identity(path, template: LVTemplate):
    try:
        p = Path(path).resolve()
        st = p.stat()
        return (str(p), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, template)
    except (OSError, TypeError, ValueError):
        return None  # the reader below reports what is wrong


def read_template_mesh(path, template: LVTemplate = DEFAULT_TEMPLATE) -> np.ndarray:
    """Read a template mesh written by :func:`write_template_mesh` (or an equivalent VTU).

    A mesh read before (same file, unchanged, same template) is returned from a small in-process cache, as a
    fresh copy; every check below ran when it was first read.

    Parameters
    ----------
    path : str or Path
        A ``.vtu`` file with one block of 27-node hexahedra.
    template : LVTemplate
        Expected topology (default :data:`DEFAULT_TEMPLATE`).

    Returns
    -------
    nodes : (n_nodes, 3) float array (mm).

    Raises
    ------
    GeometryError
        If the file is missing, empty or unreadable, holds other cell types or a
        different number of nodes or elements, numbers nodes differently from
        the template, has non-finite coordinates, looks like it is in metres or
        centimetres, or has inverted elements.
    """
    key = _mesh_identity(path, template)
    if key is not None and key in _MESH_CACHE:
        _MESH_CACHE[key] = _MESH_CACHE.pop(key)  # most recently used last
        return _MESH_CACHE[key].copy()
    nodes = _read_template_mesh(path, template)
    if key is not None:
        _MESH_CACHE[key] = nodes.copy()
        while len(_MESH_CACHE) > _MESH_CACHE_SIZE:
            _MESH_CACHE.pop(next(iter(_MESH_CACHE)))
    return nodes


def _read_template_mesh(path, template: LVTemplate) -> np.ndarray:
    """:func:`read_template_mesh` without the cache."""
    from lvcore.safety import limits

    mesh = read_meshio_file(path, "template mesh", limits.MAX_MESH_BYTES,
                            "write it with `lvcore geometry fit ... --out MESH.vtu` or write_template_mesh()")
    if _FIELD_TEMPLATE in mesh.field_data:
        dims = tuple(int(v) for v in np.ravel(mesh.field_data[_FIELD_TEMPLATE])[:3])
        if dims != (template.n_circ, template.n_long, template.n_trans):
            raise GeometryError(f"'{path}' was written on template {dims}, expected "
                                f"({template.n_circ}, {template.n_long}, {template.n_trans})")
    blocks = [c for c in mesh.cells if c.type == _MESHIO_TYPE]
    other = sorted({c.type for c in mesh.cells if c.type != _MESHIO_TYPE})
    if not blocks:
        raise GeometryError(f"'{path}' has no 27-node hexahedra (found cell types {other or 'none'}); "
                            "a template mesh holds VTK_TRIQUADRATIC_HEXAHEDRON cells only")
    if other:
        raise GeometryError(f"'{path}' mixes other cell types {other} with the 27-node hexahedra")
    cells = np.concatenate([b.data for b in blocks], axis=0)
    if mesh.points.shape[0] != template.n_nodes:
        raise GeometryError(f"'{path}' has {mesh.points.shape[0]} points, the template has {template.n_nodes}; "
                            "it was not written on this template")
    if cells.shape[0] != template.n_elements:
        raise GeometryError(f"'{path}' has {cells.shape[0]} hexahedra, the template has {template.n_elements}")
    if not np.array_equal(cells[:, TEMPLATE_FROM_VTK], template.elements):
        raise GeometryError(f"'{path}' numbers its nodes differently from the template "
                            "(connectivity mismatch); renumbered meshes cannot be compared node by node")
    nodes = _check_nodes(mesh.points[:, :3], template, f"'{path}'")
    return nodes


def check_extent_is_mm(extent: float, what: str, fix_metres: str, fix_centimetres: str, max_mm: float) -> None:
    """Raise GeometryError when an LV's size betrays metres, centimetres or nonsense.

    Parameters
    ----------
    extent : float
        Largest bounding-box side of the geometry, in the file's units.
    what : str
        What is measured, starting the message (e.g. "endo surface 'x.stl'").
    fix_metres, fix_centimetres : str
        What the user should do when the units look like m or cm.
    max_mm : float
        Largest plausible size (mm).
    """
    if extent < 1.0:
        raise GeometryError(f"{what} is {extent:.3g} units across: the coordinates look like metres; {fix_metres}")
    if extent < 20.0:
        raise GeometryError(f"{what} is {extent:.3g} units across: the coordinates look like centimetres; "
                            f"{fix_centimetres}")
    if extent > max_mm:
        raise GeometryError(f"{what} is {extent:.0f} mm across, far larger than an LV; check the units (mm expected)")


def as_q2_mesh(nodes, elements) -> tuple[np.ndarray, np.ndarray]:
    """Validate and convert a 27-node hexahedral mesh: (n, 3) float nodes, (n_el, 27) int elements."""
    nodes = np.asarray(nodes, dtype=float)
    elements = np.asarray(elements, dtype=np.int64)
    if nodes.ndim != 2 or nodes.shape[1] != 3:
        raise ValueError(f"nodes must have shape (n, 3), got {nodes.shape}")
    if elements.ndim != 2 or elements.shape[1] != 27:
        raise ValueError(f"elements must have shape (n_elements, 27), got {elements.shape}")
    return nodes, elements


def _check_nodes(nodes, template: LVTemplate, where: str) -> np.ndarray:
    nodes = np.asarray(nodes, dtype=float)
    if nodes.shape != (template.n_nodes, 3):
        raise GeometryError(f"{where}: node array has shape {nodes.shape}, expected {(template.n_nodes, 3)}")
    if not np.all(np.isfinite(nodes)):
        raise GeometryError(f"{where}: node coordinates contain NaN or inf")
    check_extent_is_mm(float(np.ptp(nodes, axis=0).max()), f"{where}: the LV", "multiply by 1000",
                       "multiply by 10", max_mm=1000.0)
    detj = element_jacobian_determinants(nodes, template)
    if np.any(detj <= 0):
        bad = np.unique(np.nonzero(detj <= 0)[0])
        raise GeometryError(f"{where}: {bad.size} elements are inverted or collapsed (non-positive Jacobian), "
                            f"e.g. element {int(bad[0])}; check the endo/epi order and the apex direction (-z)")
    return nodes


def element_jacobian_determinants(nodes, template: LVTemplate = DEFAULT_TEMPLATE) -> np.ndarray:
    """Jacobian determinants (mm³ per unit reference volume) at 2×2×2 interior points of every element.

    Points at ±0.5 avoid the collapsed apex edge where the determinant vanishes.
    Returns an array of shape (n_elements, 8).
    """
    g = np.array([-0.5, 0.5])
    xi = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    _, dN = lagrange_q2_shape(xi, derivatives=True)
    jac = np.einsum("qak,eai->eqik", dN, np.asarray(nodes)[template.elements])
    return np.linalg.det(jac)
