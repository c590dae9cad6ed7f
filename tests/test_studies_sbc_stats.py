"""The rank statistics of the simulation-based calibration study (lvcore.studies.sbc_stats): ranks, coverage from
ranks, the rank histogram and its chi-square test, Wilson intervals; statistics that can fail."""
from __future__ import annotations

import numpy as np
import pytest

from lvcore.studies import sbc_stats as stats


# --------------------------------------------------------------------------- ranks, coverage, chi-square
def _ranks(truth_sd: float, draw_sd: float = 1.0, shift: float = 0.0, n: int = 400, L: int = 100, seed: int = 0):
    """n SYNTHETIC subjects: each posterior is L draws of N(mu + shift, draw_sd²), the truth one draw of
    N(mu, truth_sd²). With truth_sd == draw_sd and no shift the truth comes from the posterior itself."""
    rng = np.random.default_rng(seed)
    ranks, Ls = [], []
    for _ in range(n):
        mu = rng.normal(0, 5)
        r = stats.rank_of_truth(rng.normal(mu + shift, draw_sd, L), rng.normal(mu, truth_sd), rng)
        ranks.append(r[0])
        Ls.append(r[1])
    return np.array(ranks), np.array(Ls)


def test_calibrated_posteriors_get_nominal_coverage_and_uniform_ranks():
    ranks, Ls = _ranks(truth_sd=1.0)
    s = stats.quantity_summary(ranks, Ls)
    assert s["n"] == 400 and sum(s["rank_histogram"]) == 400
    for level in ("90", "50"):
        lo, hi = s[f"coverage_{level}_ci"]
        assert lo <= s[f"nominal_{level}_at_L"] <= hi, (level, s[f"coverage_{level}"])
    assert abs(s["coverage_90"] - 0.9) < 0.05 and abs(s["coverage_50"] - 0.5) < 0.08
    assert s["rank_chi2_p"] > 0.01


def test_overconfident_biased_and_underconfident_posteriors_are_caught():
    over = stats.quantity_summary(*_ranks(truth_sd=3.0))           # posterior 3x too narrow
    assert over["coverage_90"] < 0.6 and over["coverage_90_ci"][1] < 0.9
    assert over["rank_chi2_p"] < 1e-6
    assert over["rank_histogram"][0] + over["rank_histogram"][-1] > 0.4 * over["n"]   # U shape
    biased = stats.quantity_summary(*_ranks(truth_sd=1.0, shift=1.5))
    assert biased["rank_chi2_p"] < 1e-6 and biased["coverage_90"] < 0.8
    assert biased["rank_histogram"][0] > biased["rank_histogram"][-1]   # the truth sits low in the posterior
    under = stats.quantity_summary(*_ranks(truth_sd=0.3))          # posterior 3x too wide
    assert under["coverage_50"] > 0.85 and under["coverage_50_ci"][0] > 0.5
    assert under["rank_chi2_p"] < 1e-6


def test_rank_counts_draws_below_breaks_ties_at_random_and_drops_nan():
    assert stats.rank_of_truth([1.0, 2.0, 3.0, np.nan], 2.5, 0) == (2, 3)
    assert stats.rank_of_truth([np.nan], 1.0, 0) is None and stats.rank_of_truth([1.0], np.nan, 0) is None
    rng = np.random.default_rng(1)
    ties = [stats.rank_of_truth(np.full(4, 7.0), 7.0, rng)[0] for _ in range(2000)]
    assert set(ties) == {0, 1, 2, 3, 4}
    assert np.allclose(np.bincount(ties) / 2000, 0.2, atol=0.04)


def test_coverage_from_ranks_is_exact_for_any_number_of_draws():
    # with L + 1 = 100 ranks the central intervals hold exactly 90 and 50 of them
    assert stats.nominal_coverage([99], 0.9) == pytest.approx(0.9)
    assert stats.nominal_coverage([99], 0.5) == pytest.approx(0.5)
    # with 20 derived draws: 19 and 11 of the 21 possible ranks
    assert stats.nominal_coverage([20], 0.9) == pytest.approx(19 / 21)
    assert stats.nominal_coverage([20], 0.5) == pytest.approx(11 / 21)
    assert stats.nominal_coverage([20, 99], 0.9) == pytest.approx((19 / 21 + 0.9) / 2)
    assert list(stats.inside_central([0, 1, 19, 20], [20] * 4, 0.9)) == [False, True, True, False]


def test_rank_histogram_expects_the_exact_counts_of_uneven_bins():
    obs, exp = stats.rank_histogram([0, 100, 50, 3], [100, 100, 100, 3])
    assert obs.sum() == 4 and exp.sum() == pytest.approx(4)
    # 101 ranks in 10 bins: one bin holds 11 of them, the others 10
    _, e = stats.rank_histogram(np.arange(101), np.full(101, 100))
    assert sorted(e.round(6)) == [10] * 9 + [11]
    # exactly uniform ranks -> chi2 p = 1
    assert stats.rank_chi2(np.arange(101), np.full(101, 100))[1] == pytest.approx(1.0)
    lo, hi = stats.uniform_band(e, 101)
    assert np.all(lo <= e) and np.all(e <= hi)
    # too few subjects for the chi-square approximation: no p-value, and it says why
    few = stats.quantity_summary([3, 50, 90], [100] * 3)   # 3.5/101 lies outside the central 90 %
    assert few["rank_chi2_p"] is None and "χ²" in few["rank_chi2_note"] and few["coverage_90"] == pytest.approx(2 / 3)


def test_wilson_interval():
    lo, hi = stats.wilson_interval(50, 100)
    assert (lo, hi) == pytest.approx((0.4038, 0.5962), abs=1e-4)
    lo, hi = stats.wilson_interval(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-4)
    assert stats.wilson_interval(0, 0) is None
