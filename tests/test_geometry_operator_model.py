"""Realistic imitation operators: each realism feature changes the SYNTHETIC contours the intended way."""
from dataclasses import replace

import numpy as np
import pytest

from lvcore.geometry import operator_model as om
from lvcore.geometry.cohort import OperatorStyle, breath_hold_shifts, contour_stack, sample_lv, trabecular_profile

POSE = (np.eye(3), np.zeros(3))  # the LV frame itself, so contours can be compared with the shape
QUIET = OperatorStyle("q", noise_mm=0.0, shift_mm=0.0)  # no random error: only the feature under test differs


@pytest.fixture(scope="module")
def lv():
    return sample_lv(np.random.default_rng(11))


def stack(lv, style, **kw):
    return contour_stack(lv, style, np.random.default_rng(5), patient="T", pose=POSE, jitter=0.0, **kw)


def positions(s):
    return np.array([sl.position for sl in s.slices])


def test_basal_slice_choice_moves_the_top_slice_by_one_spacing(lv):
    ref = positions(stack(lv, QUIET))
    add = positions(stack(lv, replace(QUIET, basal_slices=1)))
    drop = positions(stack(lv, replace(QUIET, basal_slices=-1)))
    assert len(add) == len(ref) + 1 and len(drop) == len(ref) - 1
    assert add[0] == pytest.approx(ref[0] + 10.0) and drop[0] == pytest.approx(ref[1])
    np.testing.assert_allclose(add[1:], ref)
    np.testing.assert_allclose(drop, ref[1:])


def test_apical_slice_choice_adds_or_drops_the_last_slice():
    added = 0
    for seed in range(8):
        lv = sample_lv(np.random.default_rng(seed))
        ref = positions(stack(lv, QUIET))
        add = positions(stack(lv, replace(QUIET, apical_slices=1)))
        drop = positions(stack(lv, replace(QUIET, apical_slices=-1)))
        assert len(drop) == len(ref) - 1
        np.testing.assert_allclose(drop, ref[:-1])
        np.testing.assert_allclose(add[:len(ref)], ref)
        fits = ref[-1] - 10.0 > lv.apex_z("epi") + 0.5  # a further slice still cuts the myocardium
        assert len(add) == len(ref) + int(fits)
        if fits:
            assert add[-1] == pytest.approx(ref[-1] - 10.0)
            added += 1
    assert added >= 2


def _radii(ring, lv, z):
    return np.linalg.norm(ring[:, :2] - lv.centre_offset(z), axis=1)


def test_trabecular_inclusion_pulls_the_endocardium_inwards_over_a_local_lateral_arc(lv):
    ref = stack(lv, QUIET)
    trab = stack(lv, replace(QUIET, trabecular_mm=3.0, trabecular_arc_deg=90.0, trabecular_share=1.0))
    phi = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    n_pulled = 0
    for a, b in zip(ref.slices, trab.slices):
        np.testing.assert_allclose(a.epi, b.epi, atol=1e-12)  # the epicardium is untouched
        if a.endo is None:
            continue
        d = _radii(b.endo, lv, a.position) - _radii(a.endo, lv, a.position)
        assert np.all(d <= 1e-9)  # only inwards
        assert d.min() < -2.5  # by about the depth at the arc's centre (3 mm, sampled every 7.5 deg)
        pulled = phi[d < -1e-9]
        assert len(pulled) <= 90 / 7.5 + 1  # a local arc, not the whole contour
        assert np.all(np.cos(pulled) < np.cos(np.deg2rad(180 - 60 - 45)) + 1e-9)  # on the lateral side
        n_pulled += 1
    assert n_pulled >= 3


def test_trabecular_share_is_the_fraction_of_slices_affected(lv):
    ref = stack(lv, QUIET)
    some = stack(lv, replace(QUIET, trabecular_mm=3.0, trabecular_share=0.5))
    changed = [not np.allclose(a.endo, b.endo) for a, b in zip(ref.slices, some.slices) if a.endo is not None]
    assert 0 < sum(changed) < len(changed)


def test_trabecular_profile_is_a_raised_cosine_bump():
    phi = np.deg2rad([180.0, 180 + 22.5, 180 + 45.0, 90.0, -180.0])
    np.testing.assert_allclose(trabecular_profile(phi, np.pi, np.pi / 2), [1.0, 0.5, 0.0, 0.0, 1.0], atol=1e-12)


@pytest.mark.parametrize("registration", [0.0, 0.5, 1.0])
def test_breath_hold_shifts_move_each_slice_by_the_unrealigned_part(lv, registration):
    bh = breath_hold_shifts(3, 2.0)
    ref = stack(lv, QUIET)
    moved = stack(lv, replace(QUIET, registration=registration), breath_hold=bh)
    for k, (a, b) in enumerate(zip(ref.slices, moved.slices)):
        shift = (b.epi - a.epi)[:, :2]
        np.testing.assert_allclose(shift, np.broadcast_to((1 - registration) * bh[k + 1], shift.shape), atol=1e-12)
        assert np.all(b.epi[:, 2] == a.epi[:, 2])  # in plane only
    if registration < 1:  # per slice: the shifts differ between slices (not one rigid move)
        d = np.array([(b.epi - a.epi)[0, :2] for a, b in zip(ref.slices, moved.slices)])
        assert np.std(d[:, 0]) > 0.1


def test_features_off_draw_nothing_extra(lv):
    """Defaults of the new fields keep the first model's random stream: its shipped stacks stay reproducible."""
    base = OperatorStyle("op", endo_bias_mm=0.5, noise_mm=0.4, shift_mm=0.3)
    a = stack(lv, base)
    b = stack(lv, replace(base, trabecular_mm=2.0, trabecular_share=0.0))
    c = stack(lv, replace(base, trabecular_mm=0.0, trabecular_share=0.7))
    for s in (b, c):
        for x, y in zip(a.slices, s.slices):
            np.testing.assert_array_equal(x.epi, y.epi)
            np.testing.assert_array_equal(x.endo, y.endo)


def test_slice_choices_are_drawn_with_the_operators_probabilities():
    prof = om.OperatorProfile(OperatorStyle("p"), p_basal_add=0.3, p_basal_drop=0.2, p_apical_add=0.1,
                              p_apical_drop=0.4)
    rng = np.random.default_rng(0)
    draws = [om.draw_style(prof, rng) for _ in range(4000)]
    basal = np.array([d.basal_slices for d in draws])
    apical = np.array([d.apical_slices for d in draws])
    for got, p in (((basal == 1).mean(), 0.3), ((basal == -1).mean(), 0.2), ((apical == 1).mean(), 0.1),
                   ((apical == -1).mean(), 0.4)):
        assert abs(got - p) < 4 * np.sqrt(p * (1 - p) / 4000)
    with pytest.raises(ValueError, match="probabilities"):
        om.OperatorProfile(OperatorStyle("x"), p_basal_add=0.7, p_basal_drop=0.5)


def test_realistic_stacks_are_seeded_per_patient():
    a = om.realistic_stacks(2, seed=7)
    b = om.realistic_stacks(3, seed=7)
    assert [p for p, _, _ in a] == ["SYNTHETIC-R01", "SYNTHETIC-R02"]
    for (pa, _, sa), (pb, _, sb) in zip(a, b):
        assert pa == pb
        for name in sa:
            assert sa[name][0] == sb[name][0]
            np.testing.assert_array_equal(sa[name][1].slices[0].epi, sb[name][1].slices[0].epi)
    assert all(st.synthetic and "SYNTHETIC" in st.patient for _, _, ops in a for _, st in ops.values())


def test_dropping_the_basal_slice_shrinks_the_fitted_cavity(lv):
    from lvcore.geometry.fitting import fit_contours

    op = OperatorStyle("f", noise_mm=0.2, shift_mm=0.1)
    full = fit_contours(contour_stack(lv, op, np.random.default_rng(2), patient="T"))
    dropped = fit_contours(contour_stack(lv, replace(op, basal_slices=-1), np.random.default_rng(2), patient="T"))
    assert dropped.cavity_volume_ml < full.cavity_volume_ml - 5.0  # a 10 mm slab of cavity, minus the taper
