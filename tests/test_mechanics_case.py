"""Case schema: round trips and one clear CaseError per bad case."""
import copy
import json

import numpy as np
import pytest

from lvcore.domain import conditions
from lvcore.exceptions import CaseError
from lvcore.geometry.analytic import DEFAULT_LV, LAND_LV
from lvcore.geometry.template import DEFAULT_TEMPLATE
from lvcore.mechanics.case import Case, GeometrySpec, load_case
from lvcore.mechanics.resolution import RESOLUTION_PRESETS, LVResolution

LAND2 = {
    "geometry": {"kind": "ellipsoid", "endo": {"rs": 7, "rl": 17}, "epi": {"rs": 10, "rl": 20}, "base_z": 5,
                 "resolution": {"circumferential": 24, "longitudinal": 12, "transmural": 3}},
    "material": {"law": "guccione", "C": 10, "bf": 1, "bt": 1, "bfs": 1},
    "fibres": {"alpha_endo": -60, "alpha_epi": 90},
    "load": {"pressure": 10, "units": "kPa"},
    "boundary": {"base": "clamped"},
    "probes": [[0, 0, -17]],
}
BOX = {
    "geometry": {"kind": "box", "size": [10, 1, 1], "resolution": [10, 1, 1]},
    "material": {"law": "guccione", "C": 2, "bf": 8, "bt": 2, "bfs": 4},
    "fibres": {"direction": [1, 0, 0]},
    "load": {"pressure": 0.004, "units": "kPa", "surface": "z0"},
    "boundary": {"clamped": ["x0"]},
    "probes": [[10, 0.5, 1]],
}
HO = {
    "geometry": {"kind": "default", "resolution": "fast"},
    "material": {"law": "holzapfel-ogden", "a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6},
    "load": {"pressure": 8, "units": "mmHg"},
}
#: Every model-data mismatch field set away from its default.
HO_MISMATCH = {
    "geometry": {"kind": "default", "resolution": "fast"},
    "material": {"law": "holzapfel-ogden", "a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "as": 0.0, "bs": 3.0,
                 "afs": 1.2, "bfs": 5.0, "kappa": 0.1,
                 "regional": {"a": [1.0 + 0.05 * i for i in range(24)], "af": [2.0] * 24}},
    "load": {"pressure": 8, "units": "mmHg"},
    "boundary": {"base": "sliding", "epicardial_spring": {"k": 0.2, "direction": "full"}},
}


def test_land_problem2_fields():
    case = Case.from_dict(LAND2)
    g = case.geometry
    assert g.kind == "ellipsoid" and g.ellipsoid == LAND_LV
    assert g.resolution == LVResolution(24, 12, 3) and g.preset is None
    assert g.base_z() == 5.0
    np.testing.assert_allclose(g.position_map()(0.0, 1.0, 0.0), [0, 0, -17], atol=1e-12)
    np.testing.assert_allclose(g.position_map()(0.0, 1.0, 1.0), [0, 0, -20], atol=1e-12)
    assert case.material.params == {"C": 10.0, "bf": 1.0, "bt": 1.0, "bfs": 1.0}
    assert case.load.pressure_kpa == 10.0 and case.load.surface == "endocardium"
    assert case.boundary.base == "clamped" and case.probes == ((0.0, 0.0, -17.0),)
    assert case.outputs.strain_layer == "inner_half"  # the default layer (the old name "endocardial" is an alias)


@pytest.mark.parametrize("d", [LAND2, BOX, HO, HO_MISMATCH], ids=["land2", "box", "ho", "ho-mismatch"])
def test_round_trip(d):
    case = Case.from_dict(d)
    again = Case.from_dict(json.loads(json.dumps(case.to_dict())))
    assert again == case
    assert again.to_dict() == case.to_dict()


def test_defaults_and_units():
    case = Case.from_dict(HO)
    assert case.load.pressure_kpa == pytest.approx(8 * 0.1333223684)
    assert case.material.params["as"] == conditions.HO_FIXED["as"] and case.material.params["bfs"] == conditions.HO_FIXED["bfs"]
    assert case.fibres.alpha_endo_deg == -60 and case.fibres.alpha_epi_deg == 90 and case.fibres.direction is None
    assert case.geometry.ellipsoid is DEFAULT_LV and case.geometry.preset == "fast" and case.geometry.resolution is None
    assert case.boundary.base == "clamped"
    box = Case.from_dict(BOX)
    assert box.geometry.resolution.xyz == (10, 1, 1) and box.geometry.box_size == (10.0, 1.0, 1.0)
    assert box.geometry.position_map() is None and box.fibres.direction == (1.0, 0.0, 0.0)
    assert box.boundary.clamped_faces == ("x0",) and box.load.surface == "z0"
    for res in ("fast", None):
        d = copy.deepcopy(BOX)
        d["geometry"]["resolution"] = res
        if res is None:
            del d["geometry"]["resolution"]
        g = Case.from_dict(d).geometry
        assert g.resolution is None and g.preset == res
        assert Case.from_dict(Case.from_dict(d).to_dict()) == Case.from_dict(d)


def test_graded_resolution_parses_and_round_trips():
    d = copy.deepcopy(HO)
    d["geometry"]["resolution"] = {"circumferential": 6, "longitudinal": [2, 1, 1, 2], "transmural": 1,
                                   "transmural_gauss_points": 5}
    case = Case.from_dict(d)
    r = case.geometry.resolution
    assert (r.n_long, r.level_elements, r.transmural_gauss_points) == (6, (2, 1, 1, 2), 5)
    assert case.to_dict()["geometry"]["resolution"] == d["geometry"]["resolution"]
    assert Case.from_dict(case.to_dict()) == case
    assert r == RESOLUTION_PRESETS["default"]


def test_default_lv_constructor_matches_dict():
    assert Case.default_lv(resolution="fast") == Case.from_dict(HO)


def test_template_geometry_map_and_base(tmp_path, monkeypatch):
    nodes = DEFAULT_LV.nodes(DEFAULT_TEMPLATE)
    g = GeometrySpec("mesh", template_nodes=nodes, source="x")
    p = DEFAULT_TEMPLATE.parametric_coords[:50]
    np.testing.assert_allclose(g.position_map()(p[:, 0], p[:, 1], p[:, 2]), nodes[:50], atol=1e-9)
    assert g.base_z() == pytest.approx(DEFAULT_LV.base_z)


def test_load_case_file(tmp_path):
    path = tmp_path / "c.json"
    path.write_text(json.dumps(LAND2))
    assert load_case(path) == Case.from_dict(LAND2)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(CaseError, match="not valid JSON"):
        load_case(tmp_path / "bad.json")
    with pytest.raises(CaseError, match="does not exist"):
        load_case(tmp_path / "missing.json")


def _edit(base, path, value=None, delete=False):
    d = copy.deepcopy(base)
    *head, last = path
    node = d
    for k in head:
        node = node[k]
    if delete:
        del node[last]
    else:
        node[last] = value
    return d


BAD = [
    # (base, path, value, delete, field, message fragment)
    (LAND2, ("material", "bff"), 1, False, "material.bff", "did you mean 'bf'"),
    (LAND2, ("fibers",), {}, False, "fibers", "did you mean 'fibres'"),
    (LAND2, ("geometry", "endo", "rz"), 3, False, "geometry.endo.rz", "did you mean"),
    (LAND2, ("material",), None, True, "material", "missing"),
    (LAND2, ("load", "pressure"), None, True, "load.pressure", "missing"),
    (LAND2, ("geometry", "base_z"), None, True, "geometry.base_z", "missing"),
    (HO, ("material", "a"), None, True, "material.a", "missing"),
    (HO, ("material", "a"), -0.5, False, "material.a", "> 0"),
    (HO, ("material", "bf"), 0, False, "material.bf", "> 0"),
    (HO, ("material", "bs"), 0.0, False, "material.bs", "> 0"),
    (HO, ("material", "as"), -0.1, False, "material.as", ">= 0"),
    (HO, ("material", "bfs"), -2, False, "material.bfs", "> 0"),
    (HO, ("material", "kappa"), 0.34, False, "material.kappa", "[0, 0.333333]"),
    (HO, ("material", "kappa"), -0.01, False, "material.kappa", "[0, 0.333333]"),
    (LAND2, ("material", "kappa"), 0.1, False, "material.kappa", "unknown key"),
    (HO, ("material", "regional"), {"b": [1.0] * 24}, False, "material.regional.b", "unknown key"),
    (HO, ("material", "regional"), {"a": [1.0] * 16}, False, "material.regional.a", "24 multipliers"),
    (HO, ("material", "regional"), {"a": [1.0] * 23 + [0.0]}, False, "material.regional.a[23]", "[0.01, 100"),
    (HO, ("material", "regional"), {}, False, "material.regional", "at least one"),
    (BOX, ("material", "regional"), {"C": [1.0] * 24}, False, "material.regional", "LV geometry"),
    (HO, ("boundary",), {"epicardial_spring": {"k": -1}}, False, "boundary.epicardial_spring.k", "[0.0, 100"),
    (HO, ("boundary",), {"epicardial_spring": {"k": 1, "direction": "tangential"}}, False,
     "boundary.epicardial_spring.direction", "normal"),
    (HO, ("boundary",), {"epicardial_spring": {"direction": "normal"}}, False, "boundary.epicardial_spring.k",
     "missing"),
    (HO, ("boundary",), {"epicardial_spring": 0.5}, False, "boundary.epicardial_spring", "JSON object"),
    (BOX, ("boundary",), {"clamped": ["x0"], "epicardial_spring": {"k": 1}}, False, "boundary.epicardial_spring",
     "LV geometry"),
    (LAND2, ("material", "C"), -10, False, "material.C", "> 0"),
    (HO, ("material", "b"), "1.3", False, "material.b", "number"),
    (HO, ("material", "b"), True, False, "material.b", "number"),
    (HO, ("material", "af"), float("nan"), False, "material.af", "finite"),
    (HO, ("material", "af"), float("inf"), False, "material.af", "finite"),
    (HO, ("material", "law"), "holzapfel", False, "material.law", "holzapfel-ogden"),
    (HO, ("material", "C"), 1.0, False, "material.C", "unknown key"),
    (HO, ("load", "units"), "psi", False, "load.units", "kPa"),
    (HO, ("load", "units"), None, True, "load.units", "missing"),
    (HO, ("load", "pressure"), -1, False, "load.pressure", ">= 0"),
    (HO, ("load", "surface"), "epicardium", False, "load.surface", "endocardium"),
    (HO, ("fibres",), {"alpha_endo": -200}, False, "fibres.alpha_endo", "[-180"),
    (HO, ("fibres",), {"alpha_epi": 181}, False, "fibres.alpha_epi", "180"),
    (HO, ("fibres",), {"direction": [0, 0, 0]}, False, "fibres.direction", "non-zero"),
    (HO, ("fibres",), {"direction": [1, 0]}, False, "fibres.direction", "3 numbers"),
    (HO, ("geometry", "kind"), "sphere", False, "geometry.kind", "ellipsoid"),
    (HO, ("geometry", "resolution"), "medium", False, "geometry.resolution", "fast"),
    (HO, ("geometry", "resolution"), {"circumferential": 8, "longitudinal": 0, "transmural": 1}, False,
     "geometry.resolution.longitudinal", "positive integer"),
    (HO, ("geometry", "resolution"), {"circumferential": 8, "longitudinal": 4}, False,
     "geometry.resolution.transmural", "missing"),
    (HO, ("geometry", "resolution"), {"circumferential": 6, "longitudinal": [2, 1, 1], "transmural": 1}, False,
     "geometry.resolution.longitudinal", "four counts"),
    (HO, ("geometry", "resolution"), {"circumferential": 6, "longitudinal": [2, 0, 1, 2], "transmural": 1}, False,
     "geometry.resolution.longitudinal[1]", "positive integer"),
    (HO, ("geometry", "resolution"), {"circumferential": 6, "longitudinal": 4, "transmural": 1,
                                      "transmural_gauss_points": 12}, False,
     "geometry.resolution.transmural_gauss_points", "1..10"),
    (HO, ("geometry", "resolution"), {"circumferential": 2, "longitudinal": 4, "transmural": 1}, False,
     "geometry.resolution.circumferential", ">= 3"),
    (HO, ("geometry", "resolution"), {"circumferential": 6, "longitudinal": 4, "transmural": 1.5}, False,
     "geometry.resolution.transmural", "positive integer"),
    (HO, ("geometry", "size"), [1, 1, 1], False, "geometry.size", "not used"),
    (HO, ("boundary",), {"base": "free"}, False, "boundary.base", "clamped"),
    (HO, ("outputs",), {"strain_layer": "epi"}, False, "outputs.strain_layer", "endocardial"),
    (HO, ("probes",), [[0, 0]], False, "probes[0]", "3 numbers"),
    (HO, ("probes",), "apex", False, "probes", "list"),
    (LAND2, ("geometry", "epi", "rs"), 6, False, "geometry.epi.rs", "exceed"),
    (LAND2, ("geometry", "base_z"), 18, False, "geometry.base_z", "cut"),
    (LAND2, ("geometry", "endo", "rl"), -17, False, "geometry.endo.rl", "> 0"),
    (BOX, ("load", "surface"), "z2", False, "load.surface", "z0"),
    (BOX, ("load", "surface"), None, True, "load.surface", "missing"),
    (BOX, ("boundary",), {"clamped": ["x3"]}, False, "boundary.clamped[0]", "x0"),
    (BOX, ("boundary",), {"base": "clamped"}, False, "boundary.base", "unknown key"),
    (BOX, ("geometry", "size"), [10, 0, 1], False, "geometry.size[1]", "> 0"),
    (BOX, ("geometry", "resolution"), [10, 1], False, "geometry.resolution", "[nx, ny, nz]"),
    (BOX, ("geometry", "resolution"), "coarse", False, "geometry.resolution", "fast"),
    (BOX, ("geometry", "resolution"), [10, 0, 1], False, "geometry.resolution[1]", "positive integer"),
    (BOX, ("geometry", "resolution"), {"x": 1, "y": 1, "z": "2"}, False, "geometry.resolution.z", "positive integer"),
    (HO, ("geometry",), {"kind": "mesh", "path": "/nonexistent/lv.vtu"}, False, "geometry.path", "does not exist"),
    (HO, ("geometry",), {"kind": "pca", "scores": []}, False, "geometry.scores", "non-empty"),
    (HO, ("geometry",), {"kind": "pca", "scores": [1.0], "model": "/nonexistent/m.h5"}, False,
     "geometry.model", "does not exist"),
]


@pytest.mark.parametrize("base,path,value,delete,field,fragment", BAD, ids=[f"{b[4]}-{i}" for i, b in enumerate(BAD)])
def test_bad_case(base, path, value, delete, field, fragment):
    with pytest.raises(CaseError) as info:
        Case.from_dict(_edit(base, path, value, delete))
    assert info.value.field == field
    assert fragment in str(info.value)


def test_not_a_mapping():
    with pytest.raises(CaseError, match="JSON object"):
        Case.from_dict([1, 2])
    with pytest.raises(CaseError) as info:
        Case.from_dict(_edit(HO, ("material",), 3))
    assert info.value.field == "material"


def test_mesh_geometry_from_file(tmp_path):
    from lvcore.geometry import io as gio

    nodes = DEFAULT_LV.nodes(DEFAULT_TEMPLATE) * 1.1
    gio.write_template_mesh(tmp_path / "lv.vtu", nodes)
    d = copy.deepcopy(HO)
    d["geometry"] = {"kind": "mesh", "path": "lv.vtu", "resolution": "fast"}
    (tmp_path / "case.json").write_text(json.dumps(d))
    case = load_case(tmp_path / "case.json")  # relative path resolves against the case file's folder
    np.testing.assert_allclose(case.geometry.template_nodes, nodes)
    assert case.geometry.base_z() == pytest.approx(11.0)
    assert Case.from_dict(case.to_dict()) == case
    (tmp_path / "broken.vtu").write_text("<VTKFile>")
    d["geometry"]["path"] = str(tmp_path / "broken.vtu")
    with pytest.raises(CaseError) as info:
        Case.from_dict(d)
    assert info.value.field == "geometry.path" and "broken.vtu" in str(info.value)


def test_pca_geometry_from_bundled_model():
    from lvcore.geometry.shape_model import load_shape_model

    model = load_shape_model()  # bundled (scripts/build_cohort.py); missing data must fail, not skip
    d = copy.deepcopy(HO)
    d["geometry"] = {"kind": "pca", "scores": [1.0, -0.5]}
    case = Case.from_dict(d)
    np.testing.assert_allclose(case.geometry.template_nodes, model.reconstruct(np.array([1.0, -0.5])))
    assert "SYNTHETIC" in case.geometry.source
    d["geometry"]["scores"] = [0.0] * (model.n_modes + 1)
    with pytest.raises(CaseError) as info:
        Case.from_dict(d)
    assert info.value.field == "geometry.scores" and "modes" in str(info.value)


# ----------------------------------------------------------------------------- hostile input (issue 15)
@pytest.mark.parametrize("resolution", [
    {"circumferential": 100, "longitudinal": 100, "transmural": 10},
    {"circumferential": 6, "longitudinal": [250, 250, 250, 250], "transmural": 1},
    {"circumferential": 1000, "longitudinal": 1000, "transmural": 1000},
])
def test_huge_lv_resolutions_are_refused_before_allocation(resolution):
    import time

    t0 = time.perf_counter()
    with pytest.raises(CaseError, match="geometry.resolution.*limit"):
        Case.from_dict(_edit(HO, ("geometry", "resolution"), resolution))
    assert time.perf_counter() - t0 < 0.1


@pytest.mark.parametrize("resolution", [[100, 100, 10], [1000, 1000, 1000], {"x": 400, "y": 400, "z": 1}])
def test_huge_box_resolutions_are_refused(resolution):
    with pytest.raises(CaseError, match="geometry.resolution"):
        Case.from_dict(_edit(BOX, ("geometry", "resolution"), resolution))


def test_box_preset_on_a_needle_is_refused():
    d = _edit(BOX, ("geometry", "resolution"), "accurate")
    d["geometry"]["size"] = [1e6, 1, 1]
    with pytest.raises(CaseError, match="geometry.resolution"):
        Case.from_dict(d)


def test_too_many_probes():
    from lvcore.safety import limits

    Case.from_dict(_edit(LAND2, ("probes",), [[0, 0, -17]] * limits.MAX_PROBES))
    with pytest.raises(CaseError, match="probes.*MAX_PROBES"):
        Case.from_dict(_edit(LAND2, ("probes",), [[0, 0, -17]] * (limits.MAX_PROBES + 1)))


def test_duplicate_keys_in_a_case_file(tmp_path):
    p = tmp_path / "dup.json"
    p.write_text('{"geometry": {"kind": "default"}, "material": {"law": "neo-hookean", "mu": 1, "mu": 5},'
                 ' "load": {"pressure": 1, "units": "kPa"}}')
    with pytest.raises(CaseError, match="duplicate key 'mu'"):
        load_case(p)


def test_non_regular_case_files(tmp_path):
    with pytest.raises(CaseError, match="not a regular file"):
        load_case(tmp_path)
    with pytest.raises(CaseError, match="not a regular file"):
        load_case("/dev/zero")
    d = _edit(HO, ("geometry",), {"kind": "mesh", "path": "/dev/zero"})
    with pytest.raises(CaseError, match="geometry.path.*not a regular file"):
        Case.from_dict(d)


def test_long_values_are_cut_in_messages():
    with pytest.raises(CaseError) as info:
        Case.from_dict(_edit(HO, ("load", "units"), "x" * 100_000))
    assert len(str(info.value)) < 300


def test_mismatch_fields_parse_and_default_to_todays_model():
    plain = Case.from_dict(HO)
    assert plain.material.params["kappa"] == 0.0 and plain.regional is None
    assert plain.boundary.epicardial_spring == 0.0 and plain.boundary.spring_direction == "normal"
    assert "epicardial_spring" not in plain.to_dict()["boundary"] and "regional" not in plain.to_dict()["material"]
    c = Case.from_dict(HO_MISMATCH)
    assert c.material.params == {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "as": 0.0, "bs": 3.0, "afs": 1.2,
                                 "bfs": 5.0, "kappa": 0.1}
    m = c.regional.multipliers(c.material)
    assert m.shape == (24, 9) and m[5, 0] == 1.25 and np.all(m[:, 2] == 2.0) and np.all(m[:, [1, 3, 4, 8]] == 1)
    assert not c.regional.is_uniform()
    assert c.boundary.epicardial_spring == 0.2 and c.boundary.spring_direction == "full"
    # the Python constructor and explicit κ = 0 give the same case as leaving it out
    assert Case.from_dict(copy.deepcopy(HO) | {"material": {**HO["material"], "kappa": 0}}) == plain


def test_note_is_a_remark_for_the_reader_and_changes_nothing():
    """``note`` (a string, e.g. why the bundled default_lv.json has its θ) is accepted and ignored by the simulation."""
    with_note = Case.from_dict({**copy.deepcopy(HO), "note": "a typical healthy LV"})
    assert with_note == Case.from_dict(copy.deepcopy(HO)) and "note" not in with_note.to_dict()
    for bad in (3, ["x"], "x" * 4001):
        with pytest.raises(CaseError) as err:
            Case.from_dict({**copy.deepcopy(HO), "note": bad})
        assert err.value.field == "note"
