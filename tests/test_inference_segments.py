"""Segment conventions: AHA 16 segments <-> lvcore's 6 sectors x 4 levels."""
import numpy as np
import pytest

from lvcore.exceptions import DataError
from lvcore.inference import segments as sg


@pytest.mark.parametrize("offset", [0.0, 20.0, 45.0, -75.0, 200.0, 359.0])
def test_aha_round_trip_is_the_identity_for_every_offset(offset):
    aha = np.linspace(-0.2, -0.05, 16)
    ours = sg.aha_to_lvcore(aha, offset)
    assert ours.shape == (24,)
    np.testing.assert_array_equal(sg.lvcore_to_aha(ours, offset), aha)
    # every AHA segment is used; basal and mid segments exactly once, apical once or twice
    counts = np.bincount(sg.aha_assignment(offset), minlength=16)
    assert np.all(counts[:6] == 1)   # basal: lvcore level 0
    assert np.all(counts[6:12] == 2)  # mid: lvcore levels 1 and 2
    assert np.all((counts[12:] >= 1) & (counts[12:] <= 2)) and counts[12:].sum() == 6


def test_lvcore_round_trip_is_a_projection():
    rng = np.random.default_rng(1)
    s = rng.normal(-0.15, 0.02, 24)
    p = sg.aha_to_lvcore(sg.lvcore_to_aha(s, 30.0), 30.0)
    np.testing.assert_allclose(sg.aha_to_lvcore(sg.lvcore_to_aha(p, 30.0), 30.0), p)


def test_zero_offset_layout_matches_the_documented_table():
    # lvcore sector k spans [60k, 60k+60) deg from the septal centre towards the anterior wall
    assert list(sg.aha_assignment(0.0)[:6] + 1) == [2, 1, 6, 5, 4, 3]       # basal
    assert list(sg.aha_assignment(0.0)[6:12] + 1) == [8, 7, 12, 11, 10, 9]  # level 1 -> mid
    assert list(sg.aha_assignment(0.0)[12:18] + 1) == [8, 7, 12, 11, 10, 9]  # level 2 -> mid
    assert list(sg.aha_assignment(0.0)[18:] + 1) == [14, 13, 16, 16, 15, 14]  # apical
    # an offset of one sector (60 deg) shifts the basal labels by one sector
    assert list(sg.aha_assignment(60.0)[:6] + 1) == [3, 2, 1, 6, 5, 4]


def test_rotated_lvcore_layout_and_errors():
    s = np.arange(24.0)
    np.testing.assert_array_equal(sg.rotate_lvcore(s, 0.0), s)
    r = sg.rotate_lvcore(s, 60.0)  # the data's sector 0 starts at our 60 deg: our sector 1 is their 0
    assert r[1] == 0.0 and r[0] == 5.0 and r[7] == 6.0
    np.testing.assert_array_equal(sg.rotate_lvcore(sg.rotate_lvcore(s, 60.0), -60.0), s)
    with pytest.raises(DataError, match="16 segments"):
        sg.aha_to_lvcore(np.zeros(12))
    with pytest.raises(DataError, match="not understood"):
        sg.to_lvcore(np.zeros(24), "bullseye")
    with pytest.raises(DataError, match="finite"):
        sg.aha_assignment(float("nan"))
    # the apical cap (17) is accepted and dropped
    assert sg.aha_to_lvcore(np.r_[np.full(16, -0.1), 0.0]).shape == (24,)
