"""Rank statistics of the simulation-based calibration study (:mod:`lvcore.studies.sbc`), pure functions.

The rank of the truth among L posterior draws, where it sits in the posterior
(``(rank + 0.5)/(L + 1)``), the coverage of the central intervals judged from
the ranks (the truth is inside the central ``level`` interval when
``(rank + 0.5)/(L + 1)`` lies in ``[(1 − level)/2, 1 − (1 − level)/2]``),
Wilson intervals of a share, the rank histogram with exact expected counts for
any L, its χ² test of uniformity and the binomial band of uniform ranks;
:func:`quantity_summary` puts them together for one quantity.
"""
from __future__ import annotations

import numpy as np

#: Central interval levels whose coverage is reported.
LEVELS = (0.5, 0.9)
#: Bins of the rank histogram.
N_BINS = 10
#: Smallest expected count per bin for which the χ² p-value is given (the approximation's usual rule).
MIN_EXPECTED_PER_BIN = 5.0
#: Confidence of the coverage CIs (Wilson) and of the uniform band of the histograms (binomial).
CI_LEVEL = 0.95
BAND_LEVEL = 0.99


def rank_of_truth(draws, truth: float, rng) -> tuple[int, int] | None:
    """Rank of ``truth`` among the finite ``draws``: the count of draws below it, ties broken at random.

    Returns
    -------
    (rank, L) with ``0 <= rank <= L`` (L the number of finite draws), or None without a finite draw or truth.
    """
    x = np.asarray(draws, float).reshape(-1)
    x = x[np.isfinite(x)]
    t = float(truth)
    if x.size == 0 or not np.isfinite(t):
        return None
    below = int(np.sum(x < t))
    ties = int(np.sum(x == t))
    extra = int(np.random.default_rng(rng).integers(0, ties + 1)) if ties else 0
    return below + extra, int(x.size)


def pit(ranks, Ls) -> np.ndarray:
    """``(rank + 0.5)/(L + 1)``: where the truth sits in the posterior, in (0, 1)."""
    return (np.asarray(ranks, float) + 0.5) / (np.asarray(Ls, float) + 1.0)


def inside_central(ranks, Ls, level: float) -> np.ndarray:
    """Whether the truth lies in the central ``level`` interval, judged from its rank (module docstring)."""
    u = pit(ranks, Ls)
    lo = (1.0 - level) / 2.0
    return (u >= lo - 1e-12) & (u <= 1.0 - lo + 1e-12)


def nominal_coverage(Ls, level: float) -> float:
    """Expected coverage of :func:`inside_central` when the ranks are uniform (a calibrated posterior), mean over
    subjects with L draws each: ``level`` up to the discreteness of L + 1 possible ranks."""
    Ls = np.atleast_1d(np.asarray(Ls, int))
    if Ls.size == 0:
        return float("nan")
    vals = {int(L): float(np.mean(inside_central(np.arange(L + 1), np.full(L + 1, L), level)))
            for L in set(Ls.tolist())}
    return float(np.mean([vals[int(L)] for L in Ls]))


def wilson_interval(k: int, n: int, level: float = CI_LEVEL) -> tuple[float, float] | None:
    """Wilson score interval of a binomial share ``k/n`` (None for n = 0)."""
    from scipy.stats import norm

    if n <= 0:
        return None
    z = float(norm.ppf(0.5 + level / 2.0))
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))


def _bin_of(u: np.ndarray, n_bins: int) -> np.ndarray:
    return np.minimum((np.asarray(u, float) * n_bins).astype(int), n_bins - 1)


def rank_histogram(ranks, Ls, n_bins: int = N_BINS) -> tuple[np.ndarray, np.ndarray]:
    """Observed and expected counts of the ranks in ``n_bins`` equal bins of ``(rank + 0.5)/(L + 1)``.

    The expected count of a bin is the sum over subjects of the share of the L + 1 equally likely ranks that fall
    in it, so the test is exact for any L (L + 1 need not be a multiple of ``n_bins``) and for L varying between
    subjects.
    """
    ranks, Ls = np.asarray(ranks, int), np.asarray(Ls, int)
    observed = np.bincount(_bin_of(pit(ranks, Ls), n_bins), minlength=n_bins).astype(float)
    expected = np.zeros(n_bins)
    for L, count in zip(*np.unique(Ls, return_counts=True)):
        share = np.bincount(_bin_of(pit(np.arange(L + 1), np.full(L + 1, L)), n_bins), minlength=n_bins) / (L + 1)
        expected += count * share
    return observed, expected


def rank_chi2(ranks, Ls, n_bins: int = N_BINS) -> tuple[float, float]:
    """χ² statistic and p-value of the rank histogram against uniform ranks (:func:`scipy.stats.chisquare`)."""
    from scipy.stats import chisquare

    obs, exp = rank_histogram(ranks, Ls, n_bins)
    keep = exp > 0
    if obs.sum() == 0 or keep.sum() < 2:
        return float("nan"), float("nan")
    res = chisquare(obs[keep], exp[keep])
    return float(res.statistic), float(res.pvalue)


def uniform_band(expected, n: int, level: float = BAND_LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Per bin, the central ``level`` binomial range of the count under uniform ranks (the histogram's band)."""
    from scipy.stats import binom

    exp = np.asarray(expected, float)
    if n <= 0:
        return np.zeros_like(exp), np.zeros_like(exp)
    p = exp / n
    a = (1.0 - level) / 2.0
    return binom.ppf(a, n, p), binom.ppf(1.0 - a, n, p)


def quantity_summary(ranks, Ls, widths=None, n_bins: int = N_BINS) -> dict:
    """Coverage (50 %, 90 %) with Wilson CIs, the rank histogram with its χ² p-value, ``n``; and the median
    relative width when ``widths`` are given."""
    ranks, Ls = np.asarray(ranks, int).reshape(-1), np.asarray(Ls, int).reshape(-1)
    n = int(ranks.size)
    out: dict = {"n": n}
    for level in LEVELS:
        tag = f"{round(level * 100):d}"
        k = int(np.sum(inside_central(ranks, Ls, level))) if n else 0
        out[f"coverage_{tag}"] = k / n if n else None
        out[f"coverage_{tag}_ci"] = list(wilson_interval(k, n)) if n else None
        out[f"nominal_{tag}_at_L"] = nominal_coverage(Ls, level) if n else None
    obs, exp = rank_histogram(ranks, Ls, n_bins) if n else (np.zeros(n_bins), np.zeros(n_bins))
    lo, hi = uniform_band(exp, n)
    out["rank_histogram"] = [int(v) for v in obs]
    out["rank_histogram_expected"] = [float(v) for v in exp]
    out["rank_band"] = {"level": BAND_LEVEL, "lo": [float(v) for v in lo], "hi": [float(v) for v in hi]}
    out["rank_chi2"], out["rank_chi2_p"] = rank_chi2(ranks, Ls, n_bins) if n else (None, None)
    if n and float(np.min(exp)) < MIN_EXPECTED_PER_BIN:
        out["rank_chi2"] = out["rank_chi2_p"] = None
        out["rank_chi2_note"] = (f"not computed: {n} subject(s), fewer than {MIN_EXPECTED_PER_BIN:g} expected per bin "
                                 "(the χ² approximation does not hold)")
    out["L"] = {"min": int(Ls.min()), "max": int(Ls.max())} if n else None
    if widths is not None:
        w = np.asarray([v for v in widths if v is not None and np.isfinite(v)], float)
        out["median_width_rel"] = float(np.median(w)) if w.size else None
    return out



__all__ = ["LEVELS", "N_BINS", "MIN_EXPECTED_PER_BIN", "CI_LEVEL", "BAND_LEVEL", "rank_of_truth", "pit",
           "inside_central", "nominal_coverage", "wilson_interval", "rank_histogram", "rank_chi2", "uniform_band",
           "quantity_summary"]
