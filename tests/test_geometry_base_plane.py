"""Surfaces as real pipelines write them: joined walls, oblique/uneven bases, outflow notches, scanner poses.

Every case is a SYNTHETIC truncated-ellipsoid pair (lvcore.geometry.synthetic_surfaces) in a random scanner
pose; a fit must give the closed-form cavity of the part kept below the reported cut (within 2 %), or be
refused with a message naming the real cause.
"""
import json

import numpy as np
import pytest

from lvcore.cli import main
from lvcore.exceptions import GeometryError
from lvcore.geometry.analytic import ellipsoid_volume_below_plane
from lvcore.geometry.base_plane import analyse_base, boundary_loops, closed_volume, volume_below_plane
from lvcore.geometry.fitting import fit_surfaces
from lvcore.geometry.surfaces import read_surface
from lvcore.geometry.synthetic_surfaces import (DEEP_NOTCH_DEPTH_MM, LIP_HEIGHT_MM, NOTCH_DEPTH_MM, OBLIQUE_DEG,
                                                UNEVEN_MM, synthetic_surface_pair)


def _surfaces(pair):
    return read_surface(pair.polydata("endo"), "endo"), read_surface(pair.polydata("epi"), "epi")


def _fit(case, seed=1, **kw):
    pair = synthetic_surface_pair(case, seed=seed)
    res = fit_surfaces(*_surfaces(pair), **kw)
    cut = res.base
    exact = pair.exact_cavity_below_ml(cut.cut_origin, cut.cut_normal)
    # the fit's template base plane is the reported cut
    assert np.allclose(res.frame.to_scanner([0.0, 0.0, res.frame.base_z]), cut.cut_origin)
    assert np.allclose(res.frame.rotation[2], cut.cut_normal)
    return pair, res, exact


def test_closed_form_below_a_plane():
    # horizontal plane: the truncated-ellipsoid formula; a plane through the centre: half the ellipsoid
    from lvcore.geometry.analytic import DEFAULT_LV

    e = DEFAULT_LV.endo
    assert ellipsoid_volume_below_plane(e.rs, e.ry, e.rl, [0, 0, DEFAULT_LV.base_z], [0, 0, 1]) == pytest.approx(
        DEFAULT_LV.cavity_volume_mm3(), rel=1e-12)
    n = np.array([0.3, -0.5, 0.8])
    half = 2 * np.pi / 3 * 10 * 20 * 30
    assert ellipsoid_volume_below_plane(10, 20, 30, [0, 0, 0], n) == pytest.approx(half, rel=1e-12)
    # Monte Carlo check of a tilted, offset plane
    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, (400_000, 3)) * [10, 20, 30]
    inside = ((x / [10, 20, 30]) ** 2).sum(1) <= 1
    p = np.array([2.0, 1.0, 5.0])
    mc = 8 * 10 * 20 * 30 * np.mean(inside & ((x - p) @ n <= 0))
    assert ellipsoid_volume_below_plane(10, 20, 30, p, n) == pytest.approx(mc, rel=0.01)


def test_loops_and_volumes_of_an_open_surface():
    pair = synthetic_surface_pair("flat", pose=False)
    loops = boundary_loops(pair.endo_triangles)
    assert len(loops) == 1 and len(loops[0]) == 96
    e = pair.lv.endo
    exact = ellipsoid_volume_below_plane(e.rs, e.ry, e.rl, [0, 0, 10.0], [0, 0, 1]) / 1000
    assert closed_volume(pair.endo_points, pair.endo_triangles) / 1000 == pytest.approx(exact, rel=0.005)
    below = volume_below_plane(pair.endo_points, pair.endo_triangles, [0, 0, -20.0], [0, 0, 1]) / 1000
    assert below == pytest.approx(ellipsoid_volume_below_plane(e.rs, e.ry, e.rl, [0, 0, -20.0], [0, 0, 1]) / 1000,
                                  rel=0.005)


def test_flat_base_is_not_cut():
    pair, res, exact = _fit("flat")
    b = res.base
    assert b.cut_depth_mm == 0.0 and b.rule == "flat base" and b.cavity_removed_ml == pytest.approx(0, abs=1e-6)
    assert not b.walls_meet and b.wall_at_ring_mm > 8 and b.unevenness_mm < 1e-6 and b.obliquity_deg < 0.5
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02
    assert res.warnings == ()
    assert res.length_mm == pytest.approx(90.0, abs=0.5)  # 10 mm base + 80 mm epicardial semi-axis


def test_joined_walls_are_cut_where_the_wall_is_usable():
    pair, res, exact = _fit("joined")
    b = res.base
    assert b.walls_meet and b.wall_at_ring_mm < 0.1 and b.rule == "wall thickness"
    # the lip is 4 mm high: the cut lies at or below its foot, where the wall is ~9 mm
    assert LIP_HEIGHT_MM <= b.cut_depth_mm <= LIP_HEIGHT_MM + 3.0
    assert b.wall_at_cut_mm > 0.8 * b.wall_typical_mm
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02, (res.cavity_volume_ml, exact)
    assert b.cavity_removed_ml == pytest.approx(b.cavity_full_ml - b.cavity_kept_ml)
    assert b.cavity_removed_ml > 5.0
    assert any("meet at the base (wall thickness 0.0 mm at the ring)" in w for w in res.warnings)
    s = res.summary()["base"]
    assert s["cut"]["depth_mm"] > 0 and s["cavity_removed_ml"] > 5 and "normal" in s["base_plane"]


def test_joined_walls_cut_at_the_ring_are_refused_with_the_cause():
    pair = synthetic_surface_pair("joined", seed=1)
    with pytest.raises(GeometryError, match=r"the endocardium and epicardium meet at the base \(wall thickness 0.0 mm "
                                            r"at the ring\)") as err:
        fit_surfaces(*_surfaces(pair), base_cut_mm=0.0)
    assert "swapped" not in str(err.value) and "crossing" not in str(err.value)
    # a deeper explicit cut is honoured
    res = fit_surfaces(*_surfaces(pair), base_cut_mm=10.0)
    assert res.base.cut_depth_mm == 10.0 and res.base.rule == "base_cut_mm"
    exact = pair.exact_cavity_below_ml(res.base.cut_origin, res.base.cut_normal)
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02


def test_oblique_base_at_20_degrees():
    pair, res, exact = _fit("oblique")
    b = res.base
    assert b.obliquity_deg == pytest.approx(OBLIQUE_DEG, abs=1.5)
    ring = np.concatenate([r.points for r in b.rings])
    assert np.all((ring - b.cut_origin) @ b.cut_normal >= -1e-6)  # every ring point above the cut
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02, (res.cavity_volume_ml, exact)
    assert b.cavity_removed_ml > 10.0 and any("oblique" in w for w in res.warnings)


def test_uneven_base_plus_minus_3_mm():
    pair, res, exact = _fit("uneven")
    b = res.base
    assert 1.5 * UNEVEN_MM < b.unevenness_mm <= 2 * UNEVEN_MM + 0.1
    assert b.cut_depth_mm == pytest.approx(b.ring_depth_mm) and UNEVEN_MM - 1 < b.cut_depth_mm < UNEVEN_MM + 1
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02, (res.cavity_volume_ml, exact)
    assert any("uneven" in w for w in res.warnings)


def test_outflow_notch_is_closed_by_the_cut():
    pair, res, exact = _fit("notch")
    b = res.base
    assert b.cut_depth_mm > NOTCH_DEPTH_MM - 2.0
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02, (res.cavity_volume_ml, exact)


def test_deep_outflow_notch_is_refused_with_what_to_do():
    pair = synthetic_surface_pair("deep_notch", seed=1)
    with pytest.raises(GeometryError, match="outflow tract") as err:
        fit_surfaces(*_surfaces(pair))
    msg = str(err.value)
    assert "--base-cut" in msg and "Close the opening" in msg and "swapped" not in msg
    # the cut the message offers is accepted
    depth = float(msg.split("--base-cut ")[1].split()[0])
    assert depth > DEEP_NOTCH_DEPTH_MM - 6
    res = fit_surfaces(*_surfaces(pair), base_cut_mm=depth)
    exact = pair.exact_cavity_below_ml(res.base.cut_origin, res.base.cut_normal)
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02


def test_base_cut_above_part_of_the_ring_is_refused():
    pair = synthetic_surface_pair("uneven", seed=1)
    with pytest.raises(GeometryError, match="lies above part of the base"):
        fit_surfaces(*_surfaces(pair), base_cut_mm=0.0)


def test_scanner_pose_does_not_matter():
    """The same joined pair in two random scanner poses and in its own frame: the same cut (to the 0.5 mm step
    of the thickness scan), each within 2 % of the closed form below its cut."""
    depths = []
    for seed, pose in ((1, True), (7, True), (0, False)):
        pair = synthetic_surface_pair("joined", seed=seed, pose=pose)
        res = fit_surfaces(*_surfaces(pair))
        exact = pair.exact_cavity_below_ml(res.base.cut_origin, res.base.cut_normal)
        assert abs(res.cavity_volume_ml / exact - 1) < 0.02
        assert abs(res.base.cavity_kept_ml / exact - 1) < 0.01  # the input's own cavity below the cut
        depths.append(res.base.cut_depth_mm)
    assert np.ptp(depths) <= 0.5 + 1e-6


def test_cli_reports_plane_cut_and_removed_volume(tmp_path, capsys):
    pair = synthetic_surface_pair("joined", seed=2)
    endo, epi = pair.save(tmp_path, "stl")
    out = tmp_path / "fit.vtu"
    assert main(["geometry", "fit", "--endo", str(endo), "--epi", str(epi), "--out", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    b = s["base"]
    assert b["walls_meet"] and b["cut"]["rule"] == "wall thickness" and b["cavity_removed_ml"] > 5
    assert len(b["base_plane"]["normal"]) == 3 and len(b["cut"]["origin"]) == 3
    exact = pair.exact_cavity_below_ml(b["cut"]["origin"], b["cut"]["normal"])
    assert abs(s["cavity_volume_ml"] / exact - 1) < 0.02
    assert main(["geometry", "fit", "--endo", str(endo), "--epi", str(epi)]) == 0
    text = capsys.readouterr().out
    assert "base plane through" in text and "cavity removed" in text and "meet at the base" in text
    assert main(["geometry", "fit", "--endo", str(endo), "--epi", str(epi), "--base-cut", "0"]) == 2
    err = capsys.readouterr().err
    assert "meet at the base (wall thickness 0.0 mm at the ring)" in err and "swapped" not in err
    assert main(["geometry", "fit", "--endo", str(endo), "--epi", str(epi), "--base-cut", "-3"]) == 2
    assert "--base-cut" in capsys.readouterr().err


def test_analyse_base_reports_rings_and_axis():
    pair = synthetic_surface_pair("notch", seed=3)
    b = analyse_base(*_surfaces(pair))
    assert [r.surface for r in b.rings] == ["endo", "epi"] and all(r.is_base for r in b.rings)
    axis = pair.rotation @ np.array([0.0, 0.0, 1.0])
    assert b.axis @ axis > np.cos(np.radians(3.0))
    apex = pair.rotation @ np.array([0.0, 0.0, -pair.lv.epi.rl]) + pair.shift
    assert np.linalg.norm(b.apex - apex) < 2.0


def test_separate_outflow_opening_is_closed_by_the_cut():
    """A second boundary loop (an outflow opening through both walls just below a flat base): the cut goes below
    it, the opening is reported, and the cavity is the closed form below the cut."""
    from lvcore.geometry.synthetic_surfaces import HOLE_DEPTH_MM

    pair, res, exact = _fit("outflow_hole", seed=3)
    b = res.base
    extra = [r for r in b.rings if not r.is_base]
    assert {r.surface for r in extra} == {"endo", "epi"}
    assert b.cut_depth_mm >= max(r.depth_mm for r in extra) >= HOLE_DEPTH_MM - 1.0
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02, (res.cavity_volume_ml, exact)
    assert any("extra opening" in w for w in res.warnings)


def test_small_holes_are_bridged_not_cut_below():
    """A mesh defect (two missing triangles half-way down the endocardium) neither moves the cut nor the volume."""
    import pyvista as pv

    pair = synthetic_surface_pair("flat", seed=5)
    tri = pair.endo_triangles
    z = pair.to_local(pair.endo_points[tri].mean(axis=1))[:, 2]
    drop = np.argsort(np.abs(z + 30.0))[:2]
    keep = np.setdiff1d(np.arange(len(tri)), drop)
    endo = pv.PolyData(pair.endo_points, np.hstack([np.full((len(keep), 1), 3), tri[keep]]).ravel())
    res = fit_surfaces(read_surface(endo, "endo"), read_surface(pair.polydata("epi"), "epi"))
    b = res.base
    assert b.cut_depth_mm == 0.0 and any("small hole" in w for w in res.warnings)
    assert any(not r.is_base for r in b.rings)
    exact = pair.exact_cavity_below_ml(b.cut_origin, b.cut_normal)
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02


def test_walls_that_meet_over_part_of_the_ring():
    """The wall vanishes over a quarter of the ring only (next to an outflow tract): still found (10th percentile
    of the ring's wall), cut where the wall is usable, closed form below the cut."""
    pair, res, exact = _fit("partial_join", seed=3)
    b = res.base
    assert b.walls_meet and b.rule == "wall thickness" and b.cut_depth_mm > 2.0
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02, (res.cavity_volume_ml, exact)


def test_an_endocardium_without_volume_is_refused_naming_it():
    """SYNTHETIC: the endocardium flattened onto its base plane encloses 0 mL; it was a division by zero."""
    import dataclasses

    endo, epi = _surfaces(synthetic_surface_pair("flat", pose=False))
    pts = endo.points.copy()
    pts[:, 2] = pts[:, 2].max()
    flat = dataclasses.replace(endo, points=pts, source="flat_endo.vtk")
    with pytest.raises(GeometryError, match=r"'flat_endo.vtk' encloses no volume"):
        analyse_base(flat, epi)
