"""Round trip: contours and surfaces sliced from a known ellipsoid fit back closely."""
import numpy as np
import pytest

from lvcore.exceptions import GeometryError
from lvcore.geometry.analytic import DEFAULT_LV, EllipsoidSurface, TruncatedEllipsoidLV
from lvcore.geometry.contours import contours_from_dict
from lvcore.geometry.fitting import fit_contours, fit_surfaces
from lvcore.geometry.io import read_template_mesh, write_template_mesh
from lvcore.geometry.measures import cavity_volume
from lvcore.geometry.template import DEFAULT_TEMPLATE


def ring(surf, z, n=48):
    psi = np.arccos(-z / surf.rl)
    ph = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ry = surf.rs if surf.ry is None else surf.ry
    return np.stack([surf.rs * np.sin(psi) * np.cos(ph), ry * np.sin(psi) * np.sin(ph), np.full(n, z)], 1)


def meridian(surf, phi, zb, n=61):
    psib = np.arccos(-zb / surf.rl)
    ps = np.linspace(-psib, psib, n)
    ry = surf.rs if surf.ry is None else surf.ry
    return np.stack([surf.rs * np.sin(ps) * np.cos(phi), ry * np.sin(ps) * np.sin(phi), -surf.rl * np.cos(ps)], 1)


def ellipsoid_stack_dict(g, spacing=8.0, long_axis=True, rotation=None, shift=(0, 0, 0)):
    zs = np.arange(g.base_z, -g.epi.rl + 5, -spacing)
    R = np.eye(3) if rotation is None else rotation
    tf = lambda p: (p @ R.T + np.asarray(shift)).tolist()  # noqa: E731
    slices = []
    for z in zs:
        d = {"epi": tf(ring(g.epi, z))}
        if z > -g.endo.rl + 3:
            d["endo"] = tf(ring(g.endo, z))
        slices.append(d)
    d = {"schema": "lvcore.contours/1", "units": "mm", "patient": "ellipsoid", "operator": "exact",
         "synthetic": True, "slices": slices,
         "landmarks": {"septum": tf(np.array([g.epi.rs, 0.0, g.base_z - 20]))}}
    if long_axis:
        d["long_axis"] = [{"name": n, "endo": tf(meridian(g.endo, p, g.base_z)), "epi": tf(meridian(g.epi, p, g.base_z))}
                          for n, p in (("4CH", 0.0), ("2CH", np.pi / 2))]
    return d


def _rotation(seed=3):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


@pytest.mark.parametrize("long_axis", [True, False])
def test_ellipsoid_round_trip_contours(long_axis):
    g = DEFAULT_LV
    st = contours_from_dict(ellipsoid_stack_dict(g, long_axis=long_axis, rotation=_rotation(), shift=(40, -12, 100)))
    r = fit_contours(st)
    assert r.residual_mean_mm < 0.1
    assert r.residual_max_mm < 0.5
    v_true = g.cavity_volume_mm3() / 1000.0
    assert abs(r.cavity_volume_ml / v_true - 1) < 0.01
    assert abs(float(cavity_volume(r.nodes, DEFAULT_TEMPLATE)) / 1000.0 / v_true - 1) < 0.01
    # base plane exactly at z = 0, apex on -z, phi = 0 towards the septum landmark (+x here)
    assert np.allclose(r.nodes[DEFAULT_TEMPLATE.base_nodes, 2], 0.0)
    apex = r.nodes[DEFAULT_TEMPLATE.apex_epi_node]
    assert apex[2] < -70 and np.hypot(apex[0], apex[1]) < 1.0
    if long_axis:
        assert abs(r.length_mm - (g.epi.rl + g.base_z)) < 1.0
    # nodes agree with the analytic geometry at the same template rows (same phi, base and apex)
    x_epi_base = r.nodes[DEFAULT_TEMPLATE.node_index(0, 0, DEFAULT_TEMPLATE.nt - 1)]
    psi = g.epi.polar_angle_at(g.base_z)
    assert abs(x_epi_base[0] - g.epi.rs * np.sin(psi)) < 0.3


def ellipsoid_surface_mesh(surf, base_z, scale=1.0):
    """A triangulated truncated-ellipsoid surface, open at the base plane (PyVista PolyData)."""
    import pyvista as pv

    psib = surf.polar_angle_at(base_z)
    ph = np.linspace(0, 2 * np.pi, 73)[:-1]
    ps = np.linspace(0, psib, 40)[1:]
    P, S = np.meshgrid(ph, ps, indexing="ij")
    pts = np.vstack([[[0, 0, -surf.rl]], surf.point(P, S).reshape(-1, 3)]) * scale
    n_p, n_s = P.shape
    idx = 1 + np.arange(n_p * n_s).reshape(n_p, n_s)
    i1 = np.roll(idx, -1, 0)
    tris = np.vstack([np.stack([idx[:, :-1], idx[:, 1:], i1[:, 1:]], -1).reshape(-1, 3),
                      np.stack([idx[:, :-1], i1[:, 1:], i1[:, :-1]], -1).reshape(-1, 3),
                      np.stack([np.zeros(n_p, int), idx[:, 0], i1[:, 0]], -1)])
    return pv.PolyData(pts, np.hstack([np.full((len(tris), 1), 3), tris]).ravel())


def test_ellipsoid_round_trip_surfaces(tmp_path):
    g = TruncatedEllipsoidLV(EllipsoidSurface(22.0, 60.0), EllipsoidSurface(31.0, 70.0), 8.0)
    paths = []
    for name, surf, fmt in (("endo", g.endo, "stl"), ("epi", g.epi, "ply")):
        p = tmp_path / f"{name}.{fmt}"
        ellipsoid_surface_mesh(surf, g.base_z).save(p)
        paths.append(p)
    r = fit_surfaces(*paths)
    assert r.residual_mean_mm < 0.15
    assert abs(r.cavity_volume_ml / (g.cavity_volume_mm3() / 1000.0) - 1) < 0.01
    out = write_template_mesh(tmp_path / "fit.vtu", r.nodes)
    assert np.allclose(read_template_mesh(out), r.nodes)


def test_spherical_harmonics_match_scipy():
    from scipy.special import sph_harm_y

    from lvcore.geometry.fitting import _sh_basis

    rng = np.random.default_rng(0)
    th, ph = rng.uniform(0, np.pi, 50), rng.uniform(-np.pi, np.pi, 50)
    B, ls = _sh_basis(th, ph, 6)
    col = 0
    for l in range(7):
        for m in range(l + 1):
            y = sph_harm_y(l, m, th, ph)
            refs = [y.real] if m == 0 else [np.sqrt(2) * y.real, np.sqrt(2) * y.imag]
            for ref in refs:
                assert np.allclose(np.abs(B[:, col]), np.abs(ref), atol=1e-12) and ls[col] == l
                col += 1


def test_inverted_elements_are_the_last_guard_and_name_where():
    """An endocardium bulging through the epicardium: refused by the inverted-element guard, which says where
    and what, without blaming swapped or crossing contours."""
    import pyvista as pv

    from lvcore.exceptions import GeometryError
    from lvcore.geometry.surfaces import read_surface
    from lvcore.geometry.synthetic_surfaces import synthetic_surface_pair

    p = synthetic_surface_pair("flat", pose=False)
    pts = p.endo_points.copy()
    ph, z = np.arctan2(pts[:, 1], pts[:, 0]), pts[:, 2]
    w = np.exp(-((z + 20) / 8) ** 2) * np.exp(-(np.angle(np.exp(1j * ph)) / 0.4) ** 2)
    pts[:, :2] *= (1 + 0.6 * w)[:, None]
    endo = pv.PolyData(pts, np.hstack([np.full((len(p.endo_triangles), 1), 3), p.endo_triangles]).ravel())
    with pytest.raises(GeometryError, match="inverted elements") as err:
        fit_surfaces(read_surface(endo, "endo"), read_surface(p.polydata("epi"), "epi"))
    msg = str(err.value)
    assert "outside the epicardium" in msg and "swapped" not in msg and "crossing" not in msg


def test_a_septum_on_the_long_axis_is_refused_naming_the_file(tmp_path, capsys):
    """SYNTHETIC: the bundled example contours with the septum landmark on the long axis (the basal centroid)."""
    import json
    from pathlib import Path

    from lvcore.cli import main
    from lvcore.geometry.contours import read_contours

    example = Path(__file__).resolve().parents[1] / "examples" / "contours" / "SYNTHETIC_example_contours.json"
    data = json.loads(example.read_text())
    data["landmarks"]["septum"] = [float(v) for v in read_contours(example).slices[0].endo.mean(axis=0)]
    path = tmp_path / "septum_on_axis.json"
    path.write_text(json.dumps(data))
    assert main(["geometry", "fit", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"contour file '{path}'" in err and "landmarks.septum" in err and "long axis" in err
    # surfaces: the message names both files
    g = TruncatedEllipsoidLV(EllipsoidSurface(22.0, 60.0), EllipsoidSurface(31.0, 70.0), 8.0)
    paths = []
    for name, surf in (("endo", g.endo), ("epi", g.epi)):
        p = tmp_path / f"{name}.stl"
        ellipsoid_surface_mesh(surf, g.base_z).save(p)
        paths.append(p)
    with pytest.raises(GeometryError, match=rf"'{paths[0]}' \+ '{paths[1]}': the septum point .* long axis"):
        fit_surfaces(*paths, septum=[0.0, 0.0, -20.0])
