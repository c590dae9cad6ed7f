"""Designs over named parameter spaces: shapes, bounds, seeding, balance, CSV."""
import numpy as np
import pytest

from lvcore.campaigns.designs import Design, load_design, make_design, save_design, unit_design
from lvcore.campaigns.space import get_space
from lvcore.core.space import Parameter, ParameterSpace
from lvcore.exceptions import CampaignError
from lvcore.mechanics.case_inputs import space_case

SD = [10.0, 8.0, 6.0, 4.0, 2.0]  # PC score sds for spaces with PCs (no shape model needed)


@pytest.mark.parametrize("method", ["sobol", "lhs", "random", "exp"])
@pytest.mark.parametrize("name", ["material", "chapter", "angles", "bo6"])
def test_shapes_bounds_and_seeding(method, name):
    space = get_space(name, score_sd=SD)
    d = make_design(space, method, 64, seed=3)
    assert d.points.shape == (64, space.dim)
    assert np.all(d.points >= space.lower) and np.all(d.points <= space.upper)
    again = make_design(space, method, 64, seed=3)
    np.testing.assert_array_equal(d.points, again.points)
    other = make_design(space, method, 64, seed=4)
    assert not np.allclose(d.points, other.points)


def test_space_dimensions_and_cases():
    chapter = get_space("chapter", score_sd=SD)
    assert chapter.names == ("a", "b", "af", "bf", "h1", "h2", "h3", "h4", "h5")
    angles = get_space("angles", score_sd=SD)
    assert angles.names[:7] == ("a", "b", "af", "bf", "alpha_endo", "alpha_epi", "edp") and angles.dim == 12
    np.testing.assert_allclose(chapter.upper[4:], 2 * np.array(SD))
    row = [0.6, 1.3, 1.0, 3.6, 1, 2, 3, 4, 5]
    case = space_case(chapter, row, "fast")
    assert case["geometry"] == {"kind": "pca", "scores": [1.0, 2.0, 3.0, 4.0, 5.0], "resolution": "fast"}
    assert case["fibres"] == {"alpha_endo": -60.0, "alpha_epi": 60.0}
    assert case["load"] == {"pressure": 8.0, "units": "mmHg"}
    assert space_case(get_space("material"), [0.6, 1.3, 1.0, 3.6])["geometry"]["kind"] == "default"
    with pytest.raises(CampaignError, match="unknown parameter space"):
        get_space("nope")


def test_log_uniform_mapping_is_uniform_in_log():
    p = Parameter("a", 0.01, 100.0, "log")
    np.testing.assert_allclose(p.from_unit(np.array([0.0, 0.5, 1.0])), [0.01, 1.0, 100.0])
    np.testing.assert_allclose(p.to_unit(p.from_unit(np.linspace(0, 1, 7))), np.linspace(0, 1, 7))


def test_sobol_balance():
    # A scrambled Sobol set of 2^m points puts exactly 2^(m-1) points in each half
    # of every coordinate and 2^(m-2) in each quarter (it is a (t, m, s)-net).
    u = unit_design("sobol", 256, 4, seed=11)
    for j in range(4):
        assert np.sum(u[:, j] < 0.5) == 128
        counts = np.histogram(u[:, j], bins=4, range=(0, 1))[0]
        np.testing.assert_array_equal(counts, 64)
    # much more uniform than random sampling: low discrepancy
    from scipy.stats import qmc
    assert qmc.discrepancy(u) < 0.2 * qmc.discrepancy(unit_design("random", 256, 4, seed=11))


def test_lhs_one_point_per_stratum():
    u = unit_design("lhs", 50, 3, seed=2)
    for j in range(3):
        np.testing.assert_array_equal(np.sort(np.floor(u[:, j] * 50)), np.arange(50))


def test_exp_design_range_and_warp():
    space = get_space("bo6")
    d = make_design(space, "exp", 300, seed=0)
    theta = d.points[:, :4]
    assert theta.min() >= 0.1 and theta.max() <= 10.0
    assert theta.min() < 0.2 and theta.max() > 9.8  # spans the range
    # exp warp: x = 0.1 + 9.9 (e^u - 1)/(e - 1) with u from an LHS -> known median
    expected_median = 0.1 + 9.9 * np.expm1(0.5) / np.expm1(1.0)
    assert abs(np.median(theta) - expected_median) < 0.3
    # compromise between uniform (median 5.05) and log-uniform (median 1.0)
    assert 1.0 < np.median(theta) < 5.05
    # the angle columns stay uniform within their bounds
    assert d.points[:, 4].min() >= -90 and d.points[:, 4].max() <= 0
    assert d.points[:, 5].min() >= 0 and d.points[:, 5].max() <= 90


def test_csv_round_trip(tmp_path):
    space = get_space("angles", score_sd=SD)
    d = make_design(space, "sobol", 32, seed=5)
    path = save_design(d, tmp_path / "d.csv")
    back = load_design(path)
    np.testing.assert_array_equal(back.points, d.points)
    assert back.space == space and back.method == "sobol" and back.seed == 5
    assert path.read_text().splitlines()[1] == "row," + ",".join(space.names)


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda lines: lines[1:], "first line"),
        (lambda lines: [lines[0], "row,a,b,af,bX"] + lines[2:], "columns"),
        (lambda lines: lines[:2] + ["0,0.5,1.0,oops,2.0"] + lines[3:], "not a number"),
        (lambda lines: lines[:2] + ["0,0.5,1.0"] + lines[3:], "expected 5 values"),
        (lambda lines: lines[:2] + ["0,500,1.0,1.0,2.0"] + lines[3:], "outside the bounds"),
        (lambda lines: lines[:2] + [lines[3], lines[2]] + lines[4:], "row number"),
        (lambda lines: lines[:-1], "truncated"),
        (lambda lines: ["# lvcore-design {not json"] + lines[1:], "not valid JSON"),
    ],
)
def test_malformed_design_gets_clear_error(tmp_path, edit, match):
    path = save_design(make_design(get_space("material"), "lhs", 8, seed=1), tmp_path / "d.csv")
    lines = path.read_text().splitlines()
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(edit(lines)) + "\n")
    with pytest.raises(CampaignError, match=match):
        load_design(bad)
    with pytest.raises(CampaignError, match="does not exist"):
        load_design(tmp_path / "missing.csv")


def test_design_validates_shape():
    space = ParameterSpace("s", (Parameter("a", 0.1, 1.0),))
    with pytest.raises(CampaignError):
        Design(space, np.zeros((3, 2)))
    with pytest.raises(CampaignError, match="lower < upper"):
        Parameter("a", 1.0, 0.5)


def test_design_cli(tmp_path):
    from lvcore.cli import main

    out = tmp_path / "d.csv"
    assert main(["design", "lhs", "--space", "bo4", "--n", "10", "--seed", "7", "--out", str(out)]) == 0
    d = load_design(out)
    assert d.n == 10 and d.space.name == "bo4"
