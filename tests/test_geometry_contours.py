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
