"""Every malformed segmentation gets a clear GeometryError (or a warning) saying what to fix."""
import copy
import json

import numpy as np
import pytest

from lvcore.exceptions import GeometryError
from lvcore.geometry.analytic import DEFAULT_LV
from lvcore.geometry.contours import GeometryWarning, contours_from_dict, read_contours
from lvcore.geometry.fitting import fit_surfaces
from test_geometry_fitting import ellipsoid_stack_dict


@pytest.fixture(scope="module")
def good():
    return ellipsoid_stack_dict(DEFAULT_LV, long_axis=True)


def test_good_stack_reads_and_sorts_base_to_apex(good, tmp_path):
    d = copy.deepcopy(good)
    d["slices"] = d["slices"][::-1]  # any order is accepted
    p = tmp_path / "c.json"
    p.write_text(json.dumps(d))
    st = read_contours(p)
    z = [np.mean(np.asarray(s.epi)[:, 2]) for s in st.slices]
    assert z == sorted(z, reverse=True)
    assert st.label.startswith("SYNTHETIC")
    # save/read round trip
    st2 = read_contours(st.save(tmp_path / "c2.json"))
    assert np.allclose(st2.slices[0].epi, st.slices[0].epi, atol=1e-3)


def test_empty_and_invalid_files(tmp_path):
    p = tmp_path / "empty.json"
    p.write_text("  \n")
    with pytest.raises(GeometryError, match="empty"):
        read_contours(p)
    p.write_text("{not json")
    with pytest.raises(GeometryError, match="not valid JSON"):
        read_contours(p)
    with pytest.raises(GeometryError, match="does not exist"):
        read_contours(tmp_path / "missing.json")
    with pytest.raises(GeometryError, match="'slices'"):
        contours_from_dict({"units": "mm"})


def test_too_few_slices(good):
    d = copy.deepcopy(good)
    d["slices"] = d["slices"][:3]
    with pytest.raises(GeometryError, match="at least 4"):
        contours_from_dict(d)


def test_open_contour(good):
    d = copy.deepcopy(good)
    d["slices"][2]["endo"] = d["slices"][2]["endo"][:30]  # a 225-degree arc
    with pytest.raises(GeometryError, match="slice 2 endo contour is open"):
        contours_from_dict(d)


def test_self_intersecting_contour(good):
    d = copy.deepcopy(good)
    pts = d["slices"][1]["epi"]
    pts[5], pts[20] = pts[20], pts[5]  # a figure-of-eight
    with pytest.raises(GeometryError, match="crosses itself"):
        contours_from_dict(d)


def test_swapped_endo_epi(good):
    d = copy.deepcopy(good)
    for s in d["slices"]:
        if "endo" in s:
            s["endo"], s["epi"] = s["epi"], s["endo"]
    with pytest.raises(GeometryError, match="swapped"):
        contours_from_dict(d)


@pytest.mark.parametrize("factor,word", [(1e-3, "metres"), (0.1, "centimetres")])
def test_wrong_units_detected_by_size(good, factor, word):
    d = copy.deepcopy(good)
    for s in d["slices"]:
        for k in ("endo", "epi"):
            if k in s:
                s[k] = (np.asarray(s[k]) * factor).tolist()
    with pytest.raises(GeometryError, match=word):
        contours_from_dict(d)
    d["units"] = {1e-3: "m", 0.1: "cm"}[factor]
    d.pop("long_axis")
    d.pop("landmarks")
    st = contours_from_dict(d)  # declared units are converted to mm
    assert np.ptp(st.slices[0].epi[:, 0]) > 40


def test_too_few_points_and_non_numbers(good):
    d = copy.deepcopy(good)
    d["slices"][0]["epi"] = d["slices"][0]["epi"][::10]
    with pytest.raises(GeometryError, match="at least 8"):
        contours_from_dict(d)
    d = copy.deepcopy(good)
    d["slices"][0]["endo"] = [[1, 2], [3, 4]]
    with pytest.raises(GeometryError, match=r"\[x, y, z\]"):
        contours_from_dict(d)


def test_endo_outside_epi(good):
    d = copy.deepcopy(good)
    endo = np.asarray(d["slices"][1]["endo"])
    endo[:, 0] += 25.0
    d["slices"][1]["endo"] = endo.tolist()
    with pytest.raises(GeometryError, match="outside"):
        contours_from_dict(d)


def test_inconsistent_positions_warn(good):
    d = copy.deepcopy(good)
    for i, s in enumerate(d["slices"]):
        s["position"] = float(i)  # 1 mm apart, points are 8 mm apart
    with pytest.warns(GeometryWarning, match="position"):
        contours_from_dict(d)


def test_unreadable_and_bad_surfaces(tmp_path):
    bad = tmp_path / "bad.stl"
    bad.write_bytes(b"\x00\x01garbage")
    good = tmp_path / "x.vtk"
    with pytest.raises(GeometryError, match="(cannot read|no surface)"):
        fit_surfaces(bad, bad)
    empty = tmp_path / "empty.ply"
    empty.write_text("")
    with pytest.raises(GeometryError, match="empty"):
        fit_surfaces(empty, empty)
    with pytest.raises(GeometryError, match="does not exist"):
        fit_surfaces(good, good)
    import pyvista as pv

    small = pv.Sphere(radius=0.02).clip("z", value=0.01, invert=True)
    big = pv.Sphere(radius=0.03).clip("z", value=0.01, invert=True)
    small.save(tmp_path / "s.vtp")
    big.save(tmp_path / "b.vtp")
    with pytest.raises(GeometryError, match="metres"):
        fit_surfaces(tmp_path / "s.vtp", tmp_path / "b.vtp")
    pv.Sphere(radius=30).save(tmp_path / "closed.vtp")
    pv.Sphere(radius=40).save(tmp_path / "closed2.vtp")
    with pytest.raises(GeometryError, match="closed"):
        fit_surfaces(tmp_path / "closed.vtp", tmp_path / "closed2.vtp")
    (pv.Sphere(radius=40, theta_resolution=40, phi_resolution=40).clip("z", value=10, invert=True)
     .save(tmp_path / "e.vtp"))
    (pv.Sphere(radius=25, theta_resolution=40, phi_resolution=40).clip("z", value=10, invert=True)
     .save(tmp_path / "p.vtp"))
    with pytest.raises(GeometryError, match="swapped"):
        fit_surfaces(tmp_path / "e.vtp", tmp_path / "p.vtp")


# ----------------------------------------------------------------------------- hostile input (issue 15)
def test_huge_contour_is_refused_fast(good, tmp_path):
    """A 15,000-point contour used to build n x n arrays (6 GB); it is now refused by the point limit."""
    import time

    d = copy.deepcopy(good)
    th = np.linspace(0, 2 * np.pi, 15_000, endpoint=False)
    z = float(np.mean(np.asarray(d["slices"][0]["epi"])[:, 2]))
    d["slices"][0]["epi"] = np.c_[40 * np.cos(th), 40 * np.sin(th), np.full_like(th, z)].round(3).tolist()
    p = tmp_path / "huge.json"
    p.write_text(json.dumps(d))
    t0 = time.perf_counter()
    with pytest.raises(GeometryError, match="MAX_POINTS_PER_CONTOUR"):
        read_contours(p)
    assert time.perf_counter() - t0 < 2.0


def test_too_many_points_in_all_are_refused(good, monkeypatch):
    from lvcore.safety import limits

    monkeypatch.setattr(limits, "MAX_CONTOUR_POINTS", 100)
    with pytest.raises(GeometryError, match="MAX_CONTOUR_POINTS"):
        contours_from_dict(copy.deepcopy(good))


def test_self_intersections_uses_bounded_memory():
    """4,000 points (the per-contour limit): the old n x n version peaked at > 1 GB."""
    import tracemalloc

    from lvcore.geometry.contours import self_intersections

    th = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
    circle = np.c_[30 * np.cos(th), 30 * np.sin(th)]
    tracemalloc.start()
    try:
        assert self_intersections(circle) == 0
        eight = np.c_[30 * np.sin(th), 15 * np.sin(2 * th)]  # a figure of eight crosses itself once
        assert self_intersections(eight) == 1
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 200e6, peak


def test_self_intersections_matches_brute_force():
    from lvcore.geometry.contours import self_intersections

    def brute(xy):
        n = len(xy)
        q = np.roll(xy, -1, axis=0)
        count = 0
        for i in range(n):
            for j in range(i + 2, n):
                if i == 0 and j == n - 1:
                    continue
                a, b, c, e = xy[i], q[i], xy[j], q[j]

                def cr(u, v):
                    return u[0] * v[1] - u[1] * v[0]

                if cr(b - a, c - a) * cr(b - a, e - a) < 0 and cr(e - c, a - c) * cr(e - c, b - c) < 0:
                    count += 1
        return count

    rng = np.random.default_rng(3)
    for k in range(60):
        xy = rng.normal(size=(int(rng.integers(3, 40)), 2))
        if k % 4 == 0:
            xy = np.round(xy)  # collinear and repeated points
        assert self_intersections(xy) == brute(xy)


@pytest.mark.parametrize("field, value, fragment", [
    ("units", ["mm"], "units"),
    ("landmarks", ["septum", [1, 2, 3]], "landmarks"),
    ("landmarks", {"septum": "anterior"}, "septum"),
    ("landmarks", {"septum": [1, 2]}, "septum"),
    ("long_axis", 7, "long_axis"),
    ("long_axis", [{"name": {"x": 1}, "endo": None, "epi": None}], "long_axis"),
    ("synthetic", {"yes": 1}, "synthetic"),
    ("extra", [1, 2], "extra"),
])
def test_fields_of_the_wrong_type(good, field, value, fragment):
    d = copy.deepcopy(good)
    d[field] = value
    with pytest.raises(GeometryError, match=fragment):
        contours_from_dict(d)


def test_points_of_the_wrong_type(good):
    for bad in ("abc", [[1, 2, "3"]] * 10, [[True, 2, 3]] * 10, [[1, 2, None]] * 10, 5):
        d = copy.deepcopy(good)
        d["slices"][0]["epi"] = bad
        with pytest.raises(GeometryError, match="slice 0 epi"):
            contours_from_dict(d)


def test_duplicate_keys_are_refused(good, tmp_path):
    text = json.dumps(good)
    p = tmp_path / "dup.json"
    p.write_text(text[:-1] + ', "units": "cm"}')
    with pytest.raises(GeometryError, match="duplicate key 'units'"):
        read_contours(p)


def _outflow_stack(good, arc_deg=60.0, inset=1.0):
    """The basal slice cut through the outflow tract: over ``arc_deg`` the epicardial contour runs along the
    endocardial one (``inset`` < 1 puts it just inside, so the endocardium pokes out)."""
    d = copy.deepcopy(good)
    s0 = d["slices"][0]
    endo, epi = np.asarray(s0["endo"]), np.asarray(s0["epi"])
    ph = 2 * np.pi * np.arange(len(epi)) / len(epi)
    sel = np.abs(np.angle(np.exp(1j * (ph - 1.0)))) < np.radians(arc_deg) / 2
    epi[sel] = endo[sel] * [inset, inset, 1.0]
    s0["epi"] = epi.tolist()
    return d


@pytest.mark.parametrize("inset", [1.0, 0.97])
def test_basal_slice_through_the_outflow_tract_is_dropped(good, inset):
    from lvcore.geometry.analytic import ellipsoid_volume_below_plane
    from lvcore.geometry.fitting import fit_contours

    st = contours_from_dict(_outflow_stack(good, inset=inset))
    with pytest.warns(GeometryWarning, match="includes the outflow tract"):
        res = fit_contours(st)
    b = res.base
    assert len(b.dropped) == 1 and b.walls_meet and b.rule == "outflow tract" and b.wall_at_ring_mm < 0.5
    assert b.cut_depth_mm == pytest.approx(8.0, abs=1e-6)  # the next slice, 8 mm down
    e, zb = DEFAULT_LV.endo, DEFAULT_LV.base_z - 8.0
    exact = ellipsoid_volume_below_plane(e.rs, e.ry, e.rl, [0, 0, zb], [0, 0, 1]) / 1000
    assert abs(res.cavity_volume_ml / exact - 1) < 0.02, (res.cavity_volume_ml, exact)
    removed = DEFAULT_LV.cavity_volume_mm3() / 1000 - exact
    assert b.cavity_removed_ml == pytest.approx(removed, rel=0.05)
    s = res.summary()["base"]
    assert s["cut"]["dropped_slices"] and s["cavity_removed_ml"] > 10
    # keeping that slice as the base is refused with the cause
    with pytest.raises(GeometryError, match="includes the outflow tract"):
        fit_contours(st, base_cut_mm=0.0)


def test_complete_basal_slice_is_kept(good):
    from lvcore.geometry.fitting import fit_contours

    res = fit_contours(contours_from_dict(good))
    assert res.base.dropped == () and res.base.cut_depth_mm == 0.0 and not res.base.walls_meet
    assert res.base.cavity_removed_ml == 0.0
    res2 = fit_contours(contours_from_dict(good), base_cut_mm=5.0)  # drops the basal slice (8 mm spacing)
    assert len(res2.base.dropped) == 1 and res2.base.rule == "base_cut_mm"


def test_basal_slice_where_the_walls_meet_all_round_is_dropped_with_that_cause(good):
    from lvcore.geometry.fitting import fit_contours

    d = copy.deepcopy(good)
    d["slices"][0]["epi"] = (np.asarray(d["slices"][0]["endo"]) * [1.02, 1.02, 1.0]).tolist()
    with pytest.warns(GeometryWarning, match="the endocardium and epicardium meet there"):
        res = fit_contours(contours_from_dict(d))
    assert len(res.base.dropped) == 1 and res.base.cut_depth_mm == pytest.approx(8.0, abs=1e-6)
