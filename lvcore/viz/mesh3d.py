"""Off-screen 3-D pictures of LV meshes with PyVista (no display needed).

Meshes are 27-node (triquadratic) hexahedra in the template's local node
order ``a + 3 b + 9 c`` (see :mod:`lvcore.geometry.template`); they are
converted to ``VTK_TRIQUADRATIC_HEXAHEDRON`` cells with the permutation of
:mod:`lvcore.geometry.io`. Pictures are rendered with
``pv.Plotter(off_screen=True)`` and returned as PNG bytes, so the app, the CLI
and reports share them. ``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow`` is set
before PyVista is imported so that a head-less machine renders without an X
server.

Typical use::

    ref = lv_surface(nodes, elements)
    cur = lv_surface(nodes + u, elements, point_data={"|u| (mm)": np.linalg.norm(u, axis=1)})
    png = render_meshes([MeshLayer(ref, color="grey", style="wireframe", label="reference"),
                         MeshLayer(cur, scalars="|u| (mm)", label="end diastole")])
"""
from __future__ import annotations

import io
import os
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import numpy as np  # noqa: E402
import pyvista as pv  # noqa: E402

from lvcore.geometry.io import VTK_FROM_TEMPLATE, VTK_TRIQUADRATIC_HEXAHEDRON, as_q2_mesh  # noqa: E402

#: Named camera directions (from the focal point towards the camera) with +z up.
VIEWS = {
    "iso": (1.0, -1.6, 0.8),
    "side": (0.0, -1.0, 0.0),
    "front": (1.0, 0.0, 0.0),
    "base": (0.0, 0.0, 1.0),
    "apex": (0.0, 0.0, -1.0),
}


def lv_grid(nodes, elements, point_data: Mapping[str, Any] | None = None,
            cell_data: Mapping[str, Any] | None = None) -> pv.UnstructuredGrid:
    """A volume grid of 27-node hexahedra.

    Parameters
    ----------
    nodes : (n_nodes, 3) array
        Node positions (mm).
    elements : (n_elements, 27) int array
        Connectivity in the template's local order ``a + 3 b + 9 c``.
    point_data, cell_data : dict of name -> array, optional
        Fields attached to the grid (first dimension n_nodes / n_elements).

    Returns
    -------
    pyvista.UnstructuredGrid with ``VTK_TRIQUADRATIC_HEXAHEDRON`` cells.
    """
    nodes, elements = as_q2_mesh(nodes, elements)
    grid = pv.UnstructuredGrid({VTK_TRIQUADRATIC_HEXAHEDRON: elements[:, VTK_FROM_TEMPLATE]}, nodes)
    for name, val in (point_data or {}).items():
        grid.point_data[name] = np.asarray(val)
    for name, val in (cell_data or {}).items():
        grid.cell_data[name] = np.asarray(val)
    return grid


def lv_surface(nodes, elements, point_data: Mapping[str, Any] | None = None,
               cell_data: Mapping[str, Any] | None = None, subdivision: int = 2) -> pv.PolyData:
    """The boundary surface of a 27-node hexahedral mesh, as triangles for rendering.

    Parameters
    ----------
    nodes, elements, point_data, cell_data
        As for :func:`lv_grid`.
    subdivision : int
        Levels of nonlinear subdivision of the quadratic faces (0 = flat facets
        through the nodes; 2 follows the curved faces closely).

    Returns
    -------
    pyvista.PolyData carrying the interpolated point data.
    """
    grid = lv_grid(nodes, elements, point_data, cell_data)
    return grid.extract_surface(nonlinear_subdivision=int(subdivision), algorithm="dataset_surface")


def _local(a, b, c) -> int:
    return a + 3 * b + 9 * c


#: The 12 edges of a 27-node hexahedron as local node triples (end, middle, end).
_HEX_EDGES = np.array(
    [[_local(0, b, c), _local(1, b, c), _local(2, b, c)] for b in (0, 2) for c in (0, 2)]
    + [[_local(a, 0, c), _local(a, 1, c), _local(a, 2, c)] for a in (0, 2) for c in (0, 2)]
    + [[_local(a, b, 0), _local(a, b, 1), _local(a, b, 2)] for a in (0, 2) for b in (0, 2)]
)
#: The 6 faces of a 27-node hexahedron as local node lists (9 nodes each).
_HEX_FACES = [
    [_local(a, b, c) for b in range(3) for c in range(3) for a in (fa,)] for fa in (0, 2)
] + [
    [_local(a, b, c) for a in range(3) for c in range(3) for b in (fb,)] for fb in (0, 2)
] + [
    [_local(a, b, c) for a in range(3) for b in range(3) for c in (fc,)] for fc in (0, 2)
]


def element_edges(nodes, elements, *, boundary_only: bool = True, samples: int = 8) -> pv.PolyData:
    """Curved element edges of a 27-node hexahedral mesh, as polylines.

    Each edge is the quadratic curve through its three nodes, sampled at
    ``samples + 1`` points, so coarse meshes still look round.

    Parameters
    ----------
    nodes : (n_nodes, 3) array (mm)
    elements : (n_elements, 27) template-order connectivity
    boundary_only : bool
        Keep only edges lying on the boundary surface (all three nodes on
        faces that belong to a single element).
    samples : int
        Segments per edge.

    Returns
    -------
    pyvista.PolyData of lines.
    """
    nodes = np.asarray(nodes, dtype=float)
    elements = np.asarray(elements, dtype=np.int64)
    edges = elements[:, _HEX_EDGES].reshape(-1, 3)
    key = np.sort(edges[:, [0, 2]], axis=1)
    _, first = np.unique(np.column_stack([key, edges[:, 1]]), axis=0, return_index=True)
    edges = edges[np.sort(first)]
    edges = edges[~((edges[:, 0] == edges[:, 1]) & (edges[:, 1] == edges[:, 2]))]  # collapsed (apex)
    if boundary_only:
        faces = np.concatenate([elements[:, f] for f in _HEX_FACES], axis=0)
        _, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
        on_boundary = np.zeros(nodes.shape[0], dtype=bool)
        on_boundary[np.unique(faces[counts[inverse.ravel()] == 1])] = True
        edges = edges[on_boundary[edges].all(axis=1)]
    xi = np.linspace(-1.0, 1.0, samples + 1)
    shape = np.stack([0.5 * xi * (xi - 1.0), 1.0 - xi * xi, 0.5 * xi * (xi + 1.0)], axis=1)  # (m, 3)
    points = np.einsum("mk,ekd->emd", shape, nodes[edges]).reshape(-1, 3)
    m = samples + 1
    lines = np.hstack([np.full((edges.shape[0], 1), m), np.arange(edges.shape[0] * m).reshape(-1, m)]).ravel()
    return pv.PolyData(points, lines=lines)


@dataclass
class MeshLayer:
    """One mesh in a picture.

    Attributes
    ----------
    mesh : pyvista dataset (PolyData or UnstructuredGrid)
    color : str, optional
        A single colour (ignored when ``scalars`` is given).
    scalars : str or array, optional
        Name of a point/cell array of ``mesh``, or the values themselves,
        shown with ``cmap`` and a scalar bar titled ``label``.
    opacity : float
    label : str, optional
        Legend entry (single colour) or scalar-bar title (scalars).
    style : {"surface", "wireframe", "points"}
    cmap : str
    clim : (lo, hi), optional
    line_width : float
    show_edges : bool
    """

    mesh: Any
    color: str | None = None
    scalars: Any = None
    opacity: float = 1.0
    label: str | None = None
    style: str = "surface"
    cmap: str = "viridis"
    clim: tuple[float, float] | None = None
    line_width: float = 1.0
    show_edges: bool = False


def _as_layer(item) -> MeshLayer:
    if isinstance(item, MeshLayer):
        return item
    if isinstance(item, Mapping):
        return MeshLayer(**item)
    if isinstance(item, (tuple, list)):
        mesh, how, *rest = item
        opacity = rest[0] if len(rest) > 0 else 1.0
        label = rest[1] if len(rest) > 1 else None
        is_field = isinstance(how, str) and how in mesh.array_names
        is_values = how is not None and not isinstance(how, str) and np.size(how) in (mesh.n_points, mesh.n_cells)
        if is_field or is_values:
            return MeshLayer(mesh, scalars=how, opacity=opacity, label=label)
        return MeshLayer(mesh, color=how, opacity=opacity, label=label)
    return MeshLayer(item)


def render_meshes(layers: Sequence, *, window_size: tuple[int, int] = (800, 600), view: str | Sequence[float] = "iso",
                  background: str = "white", title: str | None = None, legend: bool = True,
                  zoom: float = 1.0, parallel_projection: bool = False) -> bytes:
    """Render meshes off-screen and return a PNG image.

    Parameters
    ----------
    layers : sequence
        Each a :class:`MeshLayer`, a dict of its fields, or a tuple
        ``(mesh, color_or_scalars, opacity, label)`` (trailing items optional;
        the second item is taken as scalars when it names an array of the mesh
        or is an array).
    window_size : (width, height) in pixels.
    view : str or (x, y, z)
        One of :data:`VIEWS` or a direction from the scene centre towards the camera.
    background : str
    title : str, optional
        Text in the upper left corner.
    legend : bool
        Show a legend of the labelled single-colour layers.
    zoom : float
        Camera zoom factor after fitting the scene.
    parallel_projection : bool

    Returns
    -------
    bytes of a PNG image of ``window_size``.
    """
    layers = [_as_layer(item) for item in layers]
    if isinstance(view, str) and view not in VIEWS:
        raise ValueError(f"view must be one of {sorted(VIEWS)} or a non-zero 3-vector, got {view!r}")
    if not layers:
        raise ValueError("render_meshes needs at least one mesh")
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    try:
        plotter.set_background(background)
        legend_entries = []
        for n, layer in enumerate(layers):
            kwargs: dict[str, Any] = dict(opacity=layer.opacity, style=layer.style, line_width=layer.line_width,
                                          show_edges=layer.show_edges, smooth_shading=layer.style == "surface")
            if layer.scalars is not None:
                kwargs.update(scalars=layer.scalars, cmap=layer.cmap, clim=layer.clim,
                              scalar_bar_args={"title": layer.label or (layer.scalars if isinstance(layer.scalars, str)
                                                                        else f"layer {n}"),
                                               "color": "black", "vertical": True, "position_x": 0.8,
                                               "title_font_size": 16, "label_font_size": 14,
                                               "position_y": 0.1, "height": 0.7, "width": 0.06})
            else:
                kwargs.update(color=layer.color or "lightgrey")
                if layer.label:
                    legend_entries.append((layer.label, layer.color or "lightgrey"))
            plotter.add_mesh(layer.mesh, **kwargs)
        if legend and legend_entries:
            plotter.add_legend(legend_entries, bcolor="white", face="rectangle", size=(0.28, 0.06 * len(legend_entries)),
                               loc="lower left")
        if title:
            plotter.add_text(title, position="upper_left", font_size=11, color="black")
        direction = np.asarray(VIEWS[view] if isinstance(view, str) else view, dtype=float)
        if direction.shape != (3,) or not np.any(direction):
            raise ValueError(f"view must be one of {sorted(VIEWS)} or a non-zero 3-vector, got {view!r}")
        bounds = np.array(plotter.bounds).reshape(3, 2)
        centre = bounds.mean(axis=1)
        up = (0.0, 1.0, 0.0) if abs(direction[2]) > 0.99 * np.linalg.norm(direction) else (0.0, 0.0, 1.0)
        plotter.camera_position = [tuple(centre + direction), tuple(centre), up]
        plotter.reset_camera()
        if parallel_projection:
            plotter.enable_parallel_projection()
        if zoom != 1.0:
            plotter.camera.zoom(zoom)
        image = plotter.screenshot(return_img=True)
    finally:
        plotter.close()
    return png_bytes(image)


def png_bytes(image: np.ndarray) -> bytes:
    """Encode an (h, w, 3 or 4) uint8 image as PNG."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.asarray(image, dtype=np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def render_reference_and_deformed(reference_nodes, deformed_nodes, elements, *, scalars=None,
                                  scalars_label: str = "displacement (mm)", window_size=(800, 600), view="iso",
                                  title: str | None = None, cmap: str = "viridis",
                                  reference_label: str = "reference") -> bytes:
    """Reference mesh as a grey wireframe and the deformed mesh as a coloured surface.

    Parameters
    ----------
    reference_nodes, deformed_nodes : (n_nodes, 3) arrays (mm)
    elements : (n_elements, 27) template-order connectivity
    scalars : (n_nodes,) array, optional
        Values on the deformed surface; default the displacement magnitude (mm).
        The reference is drawn as the curved element edges of its boundary.
    scalars_label : str
        Scalar bar title.
    reference_label : str
        Legend entry of the reference wireframe.

    Returns
    -------
    PNG bytes.
    """
    ref = np.asarray(reference_nodes, dtype=float)
    cur = np.asarray(deformed_nodes, dtype=float)
    values = np.linalg.norm(cur - ref, axis=1) if scalars is None else np.asarray(scalars, dtype=float)
    ref_edges = element_edges(ref, elements)
    cur_surface = lv_surface(cur, elements, point_data={scalars_label: values})
    return render_meshes(
        [
            MeshLayer(ref_edges, color="black", style="wireframe", opacity=0.8, line_width=1.5, label=reference_label),
            MeshLayer(cur_surface, scalars=scalars_label, opacity=0.7, label=scalars_label, cmap=cmap),
        ],
        window_size=window_size, view=view, title=title,
    )


#: Distinct colours for overlays of several geometries.
OVERLAY_COLOURS = ("tomato", "royalblue", "seagreen", "darkorange", "mediumpurple", "goldenrod", "teal", "hotpink")


def render_overlay(geometries: Mapping[str, Any], elements, *, opacity: float = 0.35, edges: bool = True,
                   window_size=(800, 600), view="iso", title: str | None = None) -> bytes:
    """Several geometries on one mesh topology, overlaid in distinct colours (e.g. three operators, a PCA
    reconstruction and its original).

    Parameters
    ----------
    geometries : dict label -> (n_nodes, 3) node array (mm)
        All on the same topology ``elements``.
    elements : (n_elements, 27) template-order connectivity
    opacity : float
        Surface opacity of each geometry.
    edges : bool
        Also draw each geometry's curved boundary element edges in its colour.

    Returns
    -------
    PNG bytes.
    """
    layers = []
    for n, (label, nodes) in enumerate(geometries.items()):
        colour = OVERLAY_COLOURS[n % len(OVERLAY_COLOURS)]
        layers.append(MeshLayer(lv_surface(nodes, elements), color=colour, opacity=opacity, label=str(label)))
        if edges:
            layers.append(MeshLayer(element_edges(nodes, elements), color=colour, style="wireframe", line_width=1.5))
    return render_meshes(layers, window_size=window_size, view=view, title=title)


def render_scalar_map(nodes, elements, values, *, label: str = "value", cmap: str = "viridis",
                      clim: tuple[float, float] | None = None, window_size=(800, 600), view="iso",
                      title: str | None = None) -> bytes:
    """One geometry coloured by a nodal or element field (e.g. node distance to another geometry, region ids).

    Parameters
    ----------
    nodes : (n_nodes, 3) array (mm)
    elements : (n_elements, 27) template-order connectivity
    values : (n_nodes,) or (n_elements,) array
        Point values (interpolated over the curved faces) or cell values.
    label : str
        Scalar bar title (with units).

    Returns
    -------
    PNG bytes.
    """
    values = np.asarray(values, dtype=float)
    nodes = np.asarray(nodes, dtype=float)
    if values.shape[0] == nodes.shape[0]:
        surface = lv_surface(nodes, elements, point_data={label: values})
    elif values.shape[0] == np.shape(elements)[0]:
        surface = lv_surface(nodes, elements, cell_data={label: values})
    else:
        raise ValueError(f"values must have one entry per node ({nodes.shape[0]}) or per element "
                         f"({np.shape(elements)[0]}), got {values.shape[0]}")
    return render_meshes([MeshLayer(surface, scalars=label, label=label, cmap=cmap, clim=clim),
                          MeshLayer(element_edges(nodes, elements), color="black", style="wireframe", opacity=0.5)],
                         window_size=window_size, view=view, title=title)
