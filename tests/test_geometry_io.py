import numpy as np
import pytest

from lvcore.exceptions import GeometryError
from lvcore.geometry.analytic import DEFAULT_LV
from lvcore.geometry.io import (
    TEMPLATE_FROM_VTK,
    VTK_FROM_TEMPLATE,
    VTK_TRIQUADRATIC_HEX_PCOORDS,
    read_template_mesh,
    write_template_mesh,
)
from lvcore.geometry.template import DEFAULT_TEMPLATE, LVTemplate


def test_permutation_matches_vtk_parametric_coords():
    import vtk

    cell = vtk.vtkTriQuadraticHexahedron()
    p = cell.GetParametricCoords()
    pc = np.array([p[i] for i in range(81)]).reshape(27, 3)
    assert np.allclose(pc, VTK_TRIQUADRATIC_HEX_PCOORDS)
    assert sorted(VTK_FROM_TEMPLATE) == list(range(27))
    assert np.array_equal(VTK_FROM_TEMPLATE[TEMPLATE_FROM_VTK], np.arange(27))


def test_round_trip_and_vtk_interpolation_agrees_with_template(tmp_path):
    import pyvista as pv

    X = DEFAULT_LV.nodes(DEFAULT_TEMPLATE)
    path = write_template_mesh(tmp_path / "lv.vtu", X, metadata={"label": "SYNTHETIC"})
    Y = read_template_mesh(path)
    assert np.allclose(X, Y)
    grid = pv.read(path)
    assert set(np.unique(grid.celltypes)) == {29}
    # VTK's own isoparametric map of a cell must equal the template's map
    rng = np.random.default_rng(1)
    for e in [0, 37, 100, DEFAULT_TEMPLATE.n_elements - 1]:
        cell = grid.GetCell(e)
        for _ in range(3):
            rst = rng.uniform(0.1, 0.9, 3)
            import vtk

            x = [0.0, 0.0, 0.0]
            w = [0.0] * 27
            cell.EvaluateLocation(vtk.reference(0), list(rst), x, w)  # subId, pcoords, x, weights
            ec, el, et = DEFAULT_TEMPLATE.element_grid[e]
            t = DEFAULT_TEMPLATE
            phi = 2 * np.pi * (ec + rst[0]) / t.n_circ
            tt = (et + rst[1]) / t.n_trans
            s = (el + rst[2]) / t.n_long
            assert np.allclose(x, t.evaluate(X, phi, s, tt), atol=1e-8)
    sizes = grid.compute_cell_sizes(length=False, area=False)["Volume"]
    assert (sizes > 0).all()


def test_rejects_wrong_topology_units_and_garbage(tmp_path):
    X = DEFAULT_LV.nodes(DEFAULT_TEMPLATE)
    small = LVTemplate(6, 4, 1)
    p = write_template_mesh(tmp_path / "small.vtu", DEFAULT_LV.nodes(small), template=small)
    with pytest.raises(GeometryError, match="template"):
        read_template_mesh(p)
    p = tmp_path / "empty.vtu"
    p.write_text("")
    with pytest.raises(GeometryError, match="empty"):
        read_template_mesh(p)
    p = tmp_path / "junk.vtu"
    p.write_text("not a mesh")
    with pytest.raises(GeometryError, match="cannot read"):
        read_template_mesh(p)
    with pytest.raises(GeometryError, match="metres"):
        write_template_mesh(tmp_path / "m.vtu", X / 1000.0)
    with pytest.raises(GeometryError, match="centimetres"):
        write_template_mesh(tmp_path / "cm.vtu", X / 10.0)
    flipped = X * np.array([1.0, 1.0, -1.0])
    with pytest.raises(GeometryError, match="inverted"):
        write_template_mesh(tmp_path / "f.vtu", flipped)
    with pytest.raises(GeometryError, match="does not exist"):
        read_template_mesh(tmp_path / "nope.vtu")


def test_a_template_mesh_is_read_once_until_the_file_changes(tmp_path, monkeypatch):
    """The in-process cache: a second read of the same unchanged file parses nothing and returns a copy the
    caller may change; a rewritten file (new size or time) is parsed and checked again."""
    import os

    from lvcore.geometry import io as gio

    path = tmp_path / "m.vtu"
    nodes = DEFAULT_LV.nodes(DEFAULT_TEMPLATE)
    gio.write_template_mesh(path, nodes)
    calls = []
    real = gio._read_template_mesh
    monkeypatch.setattr(gio, "_read_template_mesh", lambda p, t: calls.append(p) or real(p, t))
    first = gio.read_template_mesh(path)
    first[0] += 1000.0                                   # the caller's copy: the cache is not changed
    second = gio.read_template_mesh(path)
    assert len(calls) == 1 and np.array_equal(second, nodes) and not np.shares_memory(first, second)
    gio.write_template_mesh(path, nodes * 1.01)
    os.utime(path, ns=(1, 1))                            # a different time even on a coarse-clock file system
    np.testing.assert_allclose(gio.read_template_mesh(path), nodes * 1.01)
    assert len(calls) == 2
    with pytest.raises(gio.GeometryError):               # another template: read and checked again, refused
        gio.read_template_mesh(path, LVTemplate(n_circ=6, n_long=4, n_trans=1))
    assert len(calls) == 3
