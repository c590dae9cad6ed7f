"""lvcore.core.space: the prior box and parameter spaces (their cases: tests/test_mechanics_case_inputs.py)."""
import numpy as np
import pytest

from lvcore.core.space import ANGLE_BOUNDS, ANGLES_THETA_BOUNDS, THETA_BOUNDS, Parameter, ParameterSpace
from lvcore.exceptions import CampaignError


def test_table_9_1_box_and_ranges():
    assert THETA_BOUNDS == {"a": (0.05, 10.0), "b": (0.1, 30.0), "af": (0.05, 10.0), "bf": (0.1, 30.0)}
    assert ANGLES_THETA_BOUNDS["b"] == ANGLES_THETA_BOUNDS["bf"] == (0.5, 30.0)
    assert ANGLES_THETA_BOUNDS["a"] == THETA_BOUNDS["a"]
    assert ANGLE_BOUNDS == {"alpha_endo": (-90.0, 0.0), "alpha_epi": (0.0, 90.0)}


def test_parameter_space_maps_the_unit_cube():
    space = ParameterSpace("t", (Parameter("a", 0.1, 10.0, "log"), Parameter("b", 1.0, 3.0),
                                 Parameter("af", 0.5, 2.0), Parameter("bf", 1.0, 2.0), Parameter("h1", -2.0, 2.0)),
                           (("alpha_endo", -50.0), ("edp", 9.0)))
    u = np.array([[0.5, 0.25, 0.0, 1.0, 0.75]])
    x = space.from_unit(u)
    np.testing.assert_allclose(x, [[1.0, 1.5, 0.5, 2.0, 1.0]])
    np.testing.assert_allclose(space.to_unit(x), u)
    assert space.full_inputs(x[0]) == {**dict(zip(space.names, x[0])), "alpha_endo": -50.0, "edp": 9.0}
    assert ParameterSpace.from_json(space.to_json()) == space
    with pytest.raises(CampaignError, match="lower < upper"):
        Parameter("a", 1.0, 1.0)


def test_the_chapter_space_is_sliding_and_old_descriptions_read_as_clamped():
    from lvcore.campaigns.space import get_space

    chapter = get_space("chapter")
    assert chapter.base == "sliding"
    assert ParameterSpace.from_json(chapter.to_json()) == chapter
    old = chapter.to_dict()
    del old["base"]  # stores written before the field existed
    assert ParameterSpace.from_dict(old).base == "clamped"
    with pytest.raises(Exception, match="base must be one of"):
        ParameterSpace("x", chapter.parameters, (), base="pinned")
