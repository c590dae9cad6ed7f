"""Geometry from a volumetric mesh: Land et al. (2015) problem 2 meshed with gmsh tetrahedra -> fit."""
import json

import numpy as np
import pytest

import gmsh  # noqa: F401,E402 - a test dependency; a missing one fails, never skips
import meshio  # noqa: E402

from lvcore.cli import main  # noqa: E402
from lvcore.exceptions import GeometryError  # noqa: E402
from lvcore.geometry.analytic import DEFAULT_LV, LAND_LV  # noqa: E402
from lvcore.geometry.meshing import ellipsoid_tet_mesh  # noqa: E402
from lvcore.geometry.template import DEFAULT_TEMPLATE  # noqa: E402
from lvcore.geometry.volume_mesh import extract_lv_boundary, fit_volume_mesh  # noqa: E402

LAND_CAVITY_ML = LAND_LV.cavity_volume_mm3() / 1000.0  # closed form, 2.492 mL


def _rotation(deg_x=25.0, deg_z=40.0):
    ax, az = np.radians(deg_x), np.radians(deg_z)
    rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    rz = np.array([[np.cos(az), -np.sin(az), 0], [np.sin(az), np.cos(az), 0], [0, 0, 1]])
    return rz @ rx


@pytest.fixture(scope="module")
def land_tets():
    """Land problem 2 wall, linear tetrahedra of about 1.5 mm (about 6,000 elements)."""
    return ellipsoid_tet_mesh(LAND_LV, 1.5)


def test_land_problem2_tet_mesh_fits_the_closed_form_cavity_volume(land_tets):
    res = fit_volume_mesh(land_tets)
    b = res.boundary
    assert b.n_tets == len(land_tets.cells[0].data) > 1000
    # the base is the z = 5 mm plane, its outward normal +z
    assert b.base_normal @ np.array([0.0, 0.0, 1.0]) > 0.999
    assert abs(b.base_origin[2] - LAND_LV.base_z) < 1e-6
    # the endocardium is the smaller piece: its points lie on the inner ellipsoid
    e = b.endo.points
    r_in = (e[:, 0] ** 2 + e[:, 1] ** 2) / 7.0 ** 2 + e[:, 2] ** 2 / 17.0 ** 2
    assert np.allclose(r_in, 1.0, atol=1e-3)
    # fitted reference cavity volume within 2 % of the closed form (measured: -0.9 % at 1.5 mm)
    err = (res.fit.cavity_volume_ml - LAND_CAVITY_ML) / LAND_CAVITY_ML
    assert abs(err) < 0.02, err
    assert abs(b.cavity_volume_ml - LAND_CAVITY_ML) / LAND_CAVITY_ML < 0.02
    assert res.fit.residual_mean_mm < 0.1
    # base-to-epicardial-apex length 25 mm
    assert res.fit.length_mm == pytest.approx(25.0, abs=0.3)


def test_abaqus_inp_in_cm_rotated_and_shifted(land_tets, tmp_path):
    """An .inp written by meshio, in cm, with the long axis tilted: same volume, same length."""
    pts = (land_tets.points @ _rotation().T + np.array([30.0, -12.0, 70.0])) / 10.0
    path = tmp_path / "lv.inp"
    meshio.write(path, meshio.Mesh(pts, [("tetra", land_tets.cells[0].data)]), file_format="abaqus")
    res = fit_volume_mesh(path, units="cm")
    assert abs(res.fit.cavity_volume_ml - LAND_CAVITY_ML) / LAND_CAVITY_ML < 0.02
    assert res.fit.length_mm == pytest.approx(25.0, abs=0.3)
    axis = _rotation() @ np.array([0.0, 0.0, 1.0])
    assert res.boundary.base_normal @ axis > 0.999
    # the CLI takes the same file; mm units are refused with a units hint
    out = tmp_path / "fitted.vtu"
    assert main(["geometry", "fit", "--mesh", str(path), "--units", "cm", "--out", str(out), "--json"]) == 0
    assert out.is_file()
    assert main(["geometry", "fit", "--mesh", str(path)]) == 2


def test_cli_json_reports_residuals_and_mesh_volume(land_tets, tmp_path, capsys):
    path = tmp_path / "lv.msh"
    meshio.write(path, land_tets, file_format="gmsh", binary=False)
    assert main(["geometry", "fit", "--mesh", str(path), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["residual_mean_mm"] < 0.1
    assert s["mesh"]["n_tets"] == len(land_tets.cells[0].data)
    assert abs(s["cavity_volume_ml"] - LAND_CAVITY_ML) / LAND_CAVITY_ML < 0.02
    assert abs(s["cavity_volume_change_pct"]) < 1.0


def _linear_hexes(template):
    """Each 27-node template element split into 8 linear hexahedra (VTK corner order)."""
    corners = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    subs = []
    for i in (0, 1):
        for j in (0, 1):
            for k in (0, 1):
                local = [(i + a) + 3 * (j + b) + 9 * (k + c) for a, b, c in corners]
                subs.append(template.elements[:, local])
    return np.concatenate(subs)


def test_hexahedral_mesh_of_the_default_lv(tmp_path):
    """Linear hexahedra (the default template's elements split 2 x 2 x 2) of the default LV."""
    nodes = DEFAULT_LV.nodes(DEFAULT_TEMPLATE)
    path = tmp_path / "lv_hex.vtu"
    meshio.write(path, meshio.Mesh(nodes, [("hexahedron", _linear_hexes(DEFAULT_TEMPLATE))]))
    res = fit_volume_mesh(path)
    assert res.boundary.n_hexes == 8 * DEFAULT_TEMPLATE.n_elements
    exact = DEFAULT_LV.cavity_volume_mm3() / 1000.0
    assert abs(res.boundary.cavity_volume_ml - exact) / exact < 0.03  # faceted by the coarse hexahedra
    assert abs(res.fit.cavity_volume_ml - exact) / exact < 0.03
    assert res.fit.length_mm == pytest.approx(DEFAULT_LV.base_z + DEFAULT_LV.epi.rl, abs=1.0)


def test_surface_only_file_is_refused_with_a_hint(land_tets, tmp_path):
    b = extract_lv_boundary(land_tets)
    path = tmp_path / "endo.vtu"
    meshio.write(path, meshio.Mesh(b.endo.points, [("triangle", b.endo.triangles)]))
    with pytest.raises(GeometryError, match="--endo/--epi"):
        fit_volume_mesh(path)


def test_untruncated_shell_is_refused(tmp_path):
    """A closed ellipsoidal shell has no flat base."""
    from lvcore.geometry.analytic import EllipsoidSurface, TruncatedEllipsoidLV

    closed = TruncatedEllipsoidLV(EllipsoidSurface(7.0, 17.0), EllipsoidSurface(10.0, 20.0), 25.0)
    mesh = ellipsoid_tet_mesh(closed, 2.5)
    with pytest.raises(GeometryError, match="flat base"):
        fit_volume_mesh(mesh)


def test_missing_and_empty_files(tmp_path):
    with pytest.raises(GeometryError, match="does not exist"):
        fit_volume_mesh(tmp_path / "nope.inp")
    (tmp_path / "empty.inp").write_text("")
    with pytest.raises(GeometryError, match="empty"):
        fit_volume_mesh(tmp_path / "empty.inp")


@pytest.mark.parametrize("case", ["joined", "oblique", "uneven", "notch"])
def test_volume_mesh_whose_base_is_not_one_flat_patch(case, tmp_path):
    """SYNTHETIC tetrahedral walls (scanner pose) whose base is a shared ring, an oblique, uneven or notched cap:
    split at sharp edges, cut below the base, cavity within 2 % of the closed form below the cut."""
    from lvcore.geometry.synthetic_surfaces import synthetic_surface_pair

    pair = synthetic_surface_pair(case, seed=4, n_phi=48, n_psi=24)
    path = tmp_path / f"{case}.inp"
    meshio.write(path, pair.tet_mesh(4.0), file_format="abaqus")
    res = fit_volume_mesh(path)
    b = res.fit.base
    exact = pair.exact_cavity_below_ml(b.cut_origin, b.cut_normal)
    assert abs(res.fit.cavity_volume_ml / exact - 1) < 0.02, (res.fit.cavity_volume_ml, exact)
    assert b.cut_depth_mm > 1.0 and b.cavity_removed_ml > 2.0
    assert abs(res.summary()["cavity_volume_change_pct"]) < 2.0  # against the mesh's own cavity below the cut
    if case == "joined":
        assert b.walls_meet and res.boundary.n_faces["base"] == 0


def test_volume_mesh_with_a_deep_outflow_opening_is_refused():
    from lvcore.geometry.synthetic_surfaces import synthetic_surface_pair

    pair = synthetic_surface_pair("deep_notch", seed=4, n_phi=48, n_psi=24)
    with pytest.raises(GeometryError, match="outflow tract") as err:
        fit_volume_mesh(pair.tet_mesh(4.0))
    assert "--base-cut" in str(err.value) and "swapped" not in str(err.value)
