"""VTU export of 27-node meshes: read back with meshio and VTK."""
import numpy as np
import pytest

from lvcore.geometry import io
from lvcore.geometry.analytic import LAND_LV, TruncatedEllipsoidLV
from lvcore.geometry.template import LVTemplate, lagrange_q2_shape
from lvcore.geometry.io import write_vtu


def _gauss_volume(nodes, elements):
    g, w = np.polynomial.legendre.leggauss(4)
    xi = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    wq = np.einsum("i,j,k->ijk", w, w, w).ravel()
    _, dN = lagrange_q2_shape(xi, derivatives=True)
    jac = np.einsum("qak,eai->eqik", dN, nodes[elements])
    return np.linalg.det(jac) @ wq


def test_write_vtu_round_trip(tmp_path):
    import meshio
    import pyvista as pv

    tmpl = LVTemplate(8, 4, 2)
    nodes = LAND_LV.nodes(tmpl)
    u = np.zeros_like(nodes)
    u[:, 2] = -0.1 * (5.0 - nodes[:, 2])  # some displacement
    regions = tmpl.element_regions
    fibres = np.tile([1.0, 0.0, 0.0], (tmpl.n_elements, 1))
    path = write_vtu(tmp_path / "out.vtu", nodes, tmpl.elements, displacement=u, cell_data={"region": regions,
                     "fibre": fibres}, field_data={"pressure_kpa": 10.0})
    mesh = meshio.read(path)
    np.testing.assert_allclose(mesh.points, nodes)
    np.testing.assert_allclose(mesh.point_data["displacement"], u)
    cells = mesh.cells_dict["hexahedron27"]
    np.testing.assert_array_equal(cells[:, io.TEMPLATE_FROM_VTK], tmpl.elements)
    np.testing.assert_array_equal(mesh.cell_data["region"][0], regions)
    # exact wall volume of the truncated ellipsoid from the elements read back
    outer = TruncatedEllipsoidLV(LAND_LV.epi, LAND_LV.epi, LAND_LV.base_z).cavity_volume_mm3()
    wall = outer - LAND_LV.cavity_volume_mm3()
    vol = _gauss_volume(mesh.points, cells[:, io.TEMPLATE_FROM_VTK])
    assert np.all(vol > 0) and vol.sum() == pytest.approx(wall, rel=2e-3)
    # VTK reads the same cells: positive sizes, interpolation equals the template map at a cell point
    grid = pv.read(path)
    assert set(np.unique(grid.celltypes)) == {29}
    sizes = grid.compute_cell_sizes(length=False, area=False).cell_data["Volume"]
    assert np.all(sizes > 0) and sizes.sum() == pytest.approx(wall, rel=0.1)  # VTK linearises
    from vtkmodules.vtkCommonCore import reference

    e = 13
    x, w = [0.0] * 3, [0.0] * 27
    grid.GetCell(e).EvaluateLocation(reference(0), [0.3, 0.7, 0.4], x, w)
    ec, el, et = tmpl.element_grid[e]
    expected = tmpl.evaluate(nodes, 2 * np.pi * (ec + 0.3) / tmpl.n_circ, (el + 0.4) / tmpl.n_long,
                             (et + 0.7) / tmpl.n_trans)
    np.testing.assert_allclose(x, expected, atol=1e-9)


def test_write_vtu_rejects_bad_input(tmp_path):
    tmpl = LVTemplate(4, 2, 1)
    nodes = LAND_LV.nodes(tmpl)
    with pytest.raises(ValueError, match="displacement"):
        write_vtu(tmp_path / "a.vtu", nodes, tmpl.elements, displacement=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="elements"):
        write_vtu(tmp_path / "a.vtu", nodes, tmpl.elements[:, :8])
    with pytest.raises(Exception, match=".vtu"):
        write_vtu(tmp_path / "a.vtk", nodes, tmpl.elements)
