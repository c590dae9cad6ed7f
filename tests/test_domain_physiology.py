"""lvcore.domain.physiology: the Klotz et al. (2006) EDPVR and typical EDV/V0, against their formulas."""
import numpy as np
import pytest

from lvcore.domain import physiology as ph


def test_klotz_curve_matches_the_formula():
    # EDP = An * EDVn**Bn with An = 27.78 mmHg, Bn = 2.76; EDVn = (V - V0)/(V30 - V0)
    v0, v30 = 60.0, 180.0
    p = np.array([0.0, 2.0, 8.0, 15.0, 27.78, 30.0])
    v = ph.klotz_volume(p, v0, v30)
    edvn = (v - v0) / (v30 - v0)
    np.testing.assert_allclose(27.78 * edvn ** 2.76, p, rtol=1e-12, atol=1e-12)
    assert v[0] == v0 and v[4] == pytest.approx(v30 - (v30 - v0) * (1 - 1.0))  # EDVn = 1 at An
    assert ph.klotz_volume(30.0, v0, v30) == pytest.approx(v0 + (v30 - v0) * (30 / 27.78) ** (1 / 2.76))
    np.testing.assert_allclose(ph.klotz_edp(ph.klotz_edvn(p)), p, atol=1e-12)
    assert np.all(np.diff(v) > 0)
    # the curve through one point passes through it
    v30_fit = ph.klotz_v30(150.0, 8.0, 80.0)
    assert ph.klotz_volume(8.0, 80.0, v30_fit) == pytest.approx(150.0)
    with pytest.raises(ValueError):
        ph.klotz_edvn(-1.0)


def test_typical_edv_ratio_from_klotz_v0_estimate():
    r = ph.typical_edv_ratio(8.0)
    assert r.central == pytest.approx(1 / (0.6 - 0.006 * 8))  # 1.81
    assert r.low == pytest.approx(1 / (0.552 + 0.05)) and r.high == pytest.approx(1 / (0.552 - 0.05))
    assert r.low < r.central < r.high and "Klotz" in r.source
    assert ph.typical_edv_ratio(20.0).central > r.central  # more pressure, more filling
    with pytest.raises(ValueError, match="no typical"):
        ph.typical_edv_ratio(75.0)


def test_edv_ratio_note_speaks_only_where_unusual_and_physiological():
    assert ph.edv_ratio_note(1.8, 8.0) is None
    assert "above" in ph.edv_ratio_note(2.14, 8.0)
    assert "below" in ph.edv_ratio_note(1.2, 8.0)
    assert ph.edv_ratio_note(4.31, 75.0) is None  # Land et al. 2015 problem 2: 10 kPa
    assert ph.edv_ratio_note(4.31, None) is None


def test_edv_ratio_note_has_a_tolerance_and_says_why_in_both_directions():
    """A ratio just outside the band (1.65 against 1.66-1.99 at 8 mmHg) is within the ratio's own 2 % uncertainty:
    no note; beyond it the note says which way the model errs: above, soft/thin inflates more; below, stiff inflates
    less."""
    r = ph.typical_edv_ratio(8.0)
    tol = ph.EDV_RATIO_NOTE_TOLERANCE
    assert tol == 0.02
    assert round(r.low, 2) == 1.66 and round(r.high, 2) == 1.99
    assert ph.edv_ratio_note(1.65, 8.0) is None and ph.edv_ratio_note(2.0, 8.0) is None
    assert ph.edv_ratio_note(r.low / (1 + tol) * 1.0001, 8.0) is None
    assert ph.edv_ratio_note(r.high * (1 + tol) * 0.9999, 8.0) is None
    above = ph.edv_ratio_note(r.high * (1 + tol) * 1.001, 8.0)
    below = ph.edv_ratio_note(r.low / (1 + tol) * 0.999, 8.0)
    assert above and below
    assert "is above the typical" in above and "soft or thin-walled model inflates more than a normal LV" in above
    assert "stiff" not in above and "inflates less" not in above
    assert "is below the typical" in below and "stiff or thick-walled model inflates less than a normal LV" in below
    assert "soft" not in below and "inflates more" not in below
    for note in (above, below):
        assert note.startswith("unusual result: EDV/V₀ = ") and "2 % uncertainty" in note


def test_posterior_edv_ratio():
    draws = np.random.default_rng(0).normal(150.0, 5.0, size=(4, 500))
    post = ph.posterior_edv_ratio(draws, 80.0, 8.0, measured_lvv_ml=152.0)
    assert post.q05 < post.median < post.q95
    assert post.median == pytest.approx(150 / 80, rel=0.01)
    assert post.measured == pytest.approx(152 / 80)
    with pytest.raises(ValueError):
        ph.edv_ratio(100.0, 0.0)


