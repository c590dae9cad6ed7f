"""Mesh resolutions: each bound checked once (in the resolution classes), presets in one place."""
from __future__ import annotations

import pytest

from lvcore.exceptions import CaseError
from lvcore.mechanics.case import Case
from lvcore.mechanics.resolution import (
    BOX_RESOLUTION_PRESET_NAMES,
    BOX_RESOLUTION_PRESETS,
    RESOLUTION_PRESET_NAMES,
    RESOLUTION_PRESETS,
    BoxResolution,
    LVResolution,
    ResolutionError,
    resolution_label,
)


@pytest.mark.parametrize("args, field", [
    ((2, 4, 1), "circumferential"),
    ((6, 0, 1), "longitudinal"),
    ((6, 4, 0), "transmural"),
    ((6, 4, 1, None, 11), "transmural_gauss_points"),
    ((6, 4, 1, None, 0), "transmural_gauss_points"),
    ((6, 4, 1, (1, 1, 1)), "longitudinal"),
    ((6, 4, 1, (1, 1, 1, 2)), "longitudinal"),
    ((6, 4, 1, (2, 0, 1, 1)), "longitudinal[1]"),
    ((6.5, 4, 1), "circumferential"),
])
def test_lv_resolution_bounds_name_the_field(args, field):
    with pytest.raises(ResolutionError) as err:
        LVResolution(*args)
    assert err.value.field == field


def test_lv_resolution_accepts_the_bounds_and_normalises():
    r = LVResolution(3.0, 4, 1, [1, 1, 1, 1], 10)
    assert (r.n_circ, r.level_elements, r.transmural_gauss_points) == (3, (1, 1, 1, 1), 10)
    assert LVResolution.graded(6, [2, 1, 1, 2], 1, 5) == RESOLUTION_PRESETS["default"]
    assert LVResolution.from_spec("6,2+1+1+2,1,5") == RESOLUTION_PRESETS["default"]
    assert resolution_label("default") == "default: 6x(2,1,1,2)x1, 5 GP"
    for name, res in RESOLUTION_PRESETS.items():
        assert LVResolution.from_spec(name) is res
        assert LVResolution(**{k: getattr(res, k) for k in ("n_circ", "n_long", "n_trans", "level_elements",
                                                             "transmural_gauss_points")}) == res


def test_case_errors_come_from_the_resolution_classes():
    """The case parser reports the resolution classes' bound with the field path."""
    d = {"geometry": {"kind": "default", "resolution": {"circumferential": 6, "longitudinal": 4, "transmural": 1,
                                                        "transmural_gauss_points": 11}},
         "material": {"law": "neo-hookean", "mu": 1.0}, "load": {"pressure": 1, "units": "kPa"}}
    with pytest.raises(CaseError) as err:
        Case.from_dict(d)
    assert err.value.field == "geometry.resolution.transmural_gauss_points"


def test_box_resolution_presets():
    assert BoxResolution.from_preset((10.0, 1.0, 1.0), "fast").xyz == (10, 1, 1)
    assert BoxResolution.from_preset((10.0, 1.0, 2.0), "default").xyz == (20, 2, 4)
    with pytest.raises(ResolutionError):
        BoxResolution(1, 0, 1)


def test_preset_names_are_the_preset_keys():
    assert RESOLUTION_PRESET_NAMES == tuple(RESOLUTION_PRESETS) == ("fast", "coarse", "default", "accurate")
    assert BOX_RESOLUTION_PRESET_NAMES == tuple(BOX_RESOLUTION_PRESETS)
    from lvcore.campaigns.runner import RESOLUTIONS

    assert RESOLUTIONS == RESOLUTION_PRESET_NAMES
