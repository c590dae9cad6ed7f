"""lvcore.core.space: the prior box, parameter spaces and the one case builder."""
import numpy as np
import pytest

from lvcore.conditions import CHAPTER_ANGLES, CHAPTER_EDP
from lvcore.core.space import ANGLE_BOUNDS, ANGLES_THETA_BOUNDS, THETA_BOUNDS, Parameter, ParameterSpace, build_case
from lvcore.exceptions import CampaignError, CaseError
from lvcore.mechanics.case import Case

THETA = {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}


def test_table_9_1_box_and_ranges():
    assert THETA_BOUNDS == {"a": (0.05, 10.0), "b": (0.1, 30.0), "af": (0.05, 10.0), "bf": (0.1, 30.0)}
    assert ANGLES_THETA_BOUNDS["b"] == ANGLES_THETA_BOUNDS["bf"] == (0.5, 30.0)
    assert ANGLES_THETA_BOUNDS["a"] == THETA_BOUNDS["a"]
    assert ANGLE_BOUNDS == {"alpha_endo": (-90.0, 0.0), "alpha_epi": (0.0, 90.0)}


def test_build_case_is_a_valid_case_with_every_input_in_place():
    case = build_case({**THETA, "alpha_endo": -45.0, "alpha_epi": 75.0, "edp": 10.0, "h1": 0.5, "h2": -1.0},
                      resolution="fast")
    parsed = Case.from_dict(case)  # the simulator's own validation accepts it
    assert parsed.geometry.kind == "pca" and parsed.geometry.preset == "fast"
    assert case["geometry"]["scores"] == [0.5, -1.0]
    assert {k: case["material"][k] for k in THETA} == THETA
    assert case["fibres"] == {"alpha_endo": -45.0, "alpha_epi": 75.0}
    assert case["load"] == {"pressure": 10.0, "units": "mmHg"}
    assert parsed.load.pressure_kpa == pytest.approx(10.0 * 0.1333224, rel=1e-6)


def test_build_case_defaults_and_explicit_geometry():
    case = build_case(THETA)
    assert case["geometry"] == {"kind": "default", "resolution": "default"}
    assert (case["fibres"]["alpha_endo"], case["fibres"]["alpha_epi"]) == CHAPTER_ANGLES
    assert case["load"]["pressure"] == CHAPTER_EDP and case["boundary"] == {"base": "clamped"}
    geom = {"kind": "ellipsoid", "endo": {"rs": 25, "rl": 60}, "epi": {"rs": 35, "rl": 70}, "base_z": 10}
    c2 = build_case(THETA, geometry=geom, resolution="fast", base="sliding")
    assert c2["geometry"]["kind"] == "ellipsoid" and c2["geometry"]["resolution"] == "fast"
    assert c2["boundary"] == {"base": "sliding"} and "resolution" not in geom  # the caller's dict is not changed


@pytest.mark.parametrize("inputs, match", [
    ({"a": 1.0, "b": 1.0, "af": 1.0}, "bf"),
    ({**THETA, "alpha": 10.0}, "unknown input"),
    ({**THETA, "h1": 0.0, "h3": 0.0}, "without gaps"),
])
def test_build_case_refuses_bad_inputs(inputs, match):
    with pytest.raises(CaseError, match=match):
        build_case(inputs)
    with pytest.raises(CaseError, match="not both"):
        build_case({**THETA, "h1": 0.2}, geometry={"kind": "default"})


def test_parameter_space_maps_the_unit_cube_and_builds_cases():
    space = ParameterSpace("t", (Parameter("a", 0.1, 10.0, "log"), Parameter("b", 1.0, 3.0),
                                 Parameter("af", 0.5, 2.0), Parameter("bf", 1.0, 2.0), Parameter("h1", -2.0, 2.0)),
                           (("alpha_endo", -50.0), ("edp", 9.0)))
    u = np.array([[0.5, 0.25, 0.0, 1.0, 0.75]])
    x = space.from_unit(u)
    np.testing.assert_allclose(x, [[1.0, 1.5, 0.5, 2.0, 1.0]])
    np.testing.assert_allclose(space.to_unit(x), u)
    case = space.case(x[0], resolution="fast")
    assert case == build_case({**dict(zip(space.names, x[0])), "alpha_endo": -50.0, "edp": 9.0}, resolution="fast")
    assert case["fibres"]["alpha_epi"] == CHAPTER_ANGLES[1] and case["geometry"]["scores"] == [x[0, 4]]
    assert ParameterSpace.from_json(space.to_json()) == space
    with pytest.raises(CampaignError, match="lower < upper"):
        Parameter("a", 1.0, 1.0)
    with pytest.raises(CampaignError, match="material parameter"):
        ParameterSpace("m", (Parameter("a", 0.1, 1.0),)).case([0.5])


def test_the_chapter_space_builds_sliding_cases_and_old_descriptions_read_as_clamped():
    from lvcore.campaigns.space import get_space
    from lvcore.core.space import ParameterSpace

    chapter = get_space("chapter")
    assert chapter.base == "sliding"
    assert chapter.case([1.0] * chapter.dim)["boundary"] == {"base": "sliding"}
    assert ParameterSpace.from_json(chapter.to_json()) == chapter
    old = chapter.to_dict()
    del old["base"]  # stores written before the field existed
    assert ParameterSpace.from_dict(old).base == "clamped"
    assert get_space("angles").case([1.0] * get_space("angles").dim)["boundary"] == {"base": "sliding"}
    assert get_space("material").case([1.0] * get_space("material").dim)["boundary"] == {"base": "clamped"}
    with pytest.raises(Exception, match="base must be one of"):
        ParameterSpace("x", chapter.parameters, (), base="pinned")
