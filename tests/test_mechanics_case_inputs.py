"""lvcore.mechanics.case_inputs: the one writer of simulator cases from named inputs, and the shims of its old home."""
import doctest

import numpy as np
import pytest

from lvcore.campaigns.space import get_space
from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP, THETA_TILDE
from lvcore.core.space import Parameter, ParameterSpace
from lvcore.exceptions import CampaignError, CaseError
from lvcore.mechanics import case_inputs
from lvcore.mechanics.case import Case
from lvcore.mechanics.case_inputs import build_case, space_case

THETA = dict(THETA_TILDE)


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


def test_space_case_is_build_case_of_the_full_row_with_the_space_base():
    space = ParameterSpace("t", (Parameter("a", 0.1, 10.0, "log"), Parameter("b", 1.0, 3.0),
                                 Parameter("af", 0.5, 2.0), Parameter("bf", 1.0, 2.0), Parameter("h1", -2.0, 2.0)),
                           (("alpha_endo", -50.0), ("edp", 9.0)))
    x = space.from_unit(np.array([[0.5, 0.25, 0.0, 1.0, 0.75]]))
    case = space_case(space, x[0], resolution="fast")
    assert case == build_case({**dict(zip(space.names, x[0])), "alpha_endo": -50.0, "edp": 9.0}, resolution="fast")
    assert case["fibres"]["alpha_epi"] == CHAPTER_ANGLES[1] and case["geometry"]["scores"] == [x[0, 4]]
    with pytest.raises(CampaignError, match="material parameter"):
        space_case(ParameterSpace("m", (Parameter("a", 0.1, 1.0),)), [0.5])
    for name, base in (("chapter", "sliding"), ("angles", "sliding"), ("material", "clamped")):
        named = get_space(name)
        assert space_case(named, [1.0] * named.dim)["boundary"] == {"base": base}


def test_the_docstring_examples_run():
    result = doctest.testmod(case_inputs)
    assert result.attempted >= 2 and result.failed == 0


def test_the_old_home_forwards_with_a_deprecation_warning():
    import lvcore.core
    import lvcore.core.space

    with pytest.warns(DeprecationWarning, match=r"lvcore\.core\.space\.build_case is deprecated; use "
                                                r"lvcore\.mechanics\.case_inputs\.build_case"):
        from lvcore.core.space import build_case as old
    assert old is build_case
    with pytest.warns(DeprecationWarning, match=r"lvcore\.core\.build_case is deprecated"):
        assert lvcore.core.build_case is build_case
    with pytest.warns(DeprecationWarning, match="CASE_LAW"):
        assert lvcore.core.space.CASE_LAW == case_inputs.CASE_LAW == "holzapfel-ogden"
    space = get_space("material")
    with pytest.warns(DeprecationWarning, match=r"ParameterSpace\.case is deprecated; use .*space_case"):
        assert space.case([1.0] * space.dim, "fast") == space_case(space, [1.0] * space.dim, "fast")
    assert "build_case" not in lvcore.core.__all__
