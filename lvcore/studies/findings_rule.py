"""The findings' verdict rule: the thresholds, the cited physiological dose ranges, a CI's call against a claim's
threshold, the symmetric verdict of a finding's calls, and the cluster bootstrap over independent units.

Part of :mod:`lvcore.studies.findings` (the study; its docstring states the rule in full).
"""
from __future__ import annotations

import numpy as np

from lvcore.domain.conditions import SIGMA_S

#: F1's threshold (the chapter's ≈ 2×, read as at least 1.5×), shared with :mod:`lvcore.studies.mismatch`.
F1_INFLATION = 1.5
#: F2: the discrepancy σ_S counts as "near the truth" inside this band (× 0.03).
F2_BAND = (0.5, 1.3)
#: F5: "at least as consistent as the new operators" read as no worse in at least half of the comparisons.
F5_SHARE = 0.5
#: The smallest strain RMS mismatch that can show F1: with none of it absorbed by θ the iid σ_S would be
#: √(0.03² + m²), which reaches 1.5 × 0.03 at m = 0.03 √(1.5² − 1) ≈ 0.034. Smaller doses cannot test F1–F3.
TESTABLE_RMS = SIGMA_S * float(np.sqrt(F1_INFLATION ** 2 - 1.0))
#: Fewest independent units for a deciding test: even unanimous units give a one-sided sign-test p < 0.05
#: only from 5 on (0.5⁵ = 0.031; with 3 units, 0.125).
N_MIN = 5
#: Largest share of data sets with split R-hat > 1.05 at a deciding dose.
RHAT_SHARE_MAX = 0.05
#: Fewest MCMC chains per fit at a deciding dose (one chain's split R-hat cannot see a second mode).
MIN_CHAINS = 2
#: Relative distance to an optimisation box's bound at which a parameter counts as on it (as operators.BOUND_TOL).
BOUND_TOL = 1e-3
#: The BO's box (bo-fibres and bo-mismatch): a, b, af, bf in [0.1, 10].
BO_THETA_BOX = (0.1, 10.0)
LEVEL = 0.9
N_BOOT = 2000

#: Physiological dose range per mismatch source, with its citation. ``max``: the largest dose inside the range
#: (None: no range is cited, every dose of the source is kept out of verdicts).
PHYSIOLOGICAL_RANGES = {
    "angles": {"max": 30.0, "range": "rotation |d| ≤ 30°",
               "cite": "Harrington et al. 2005, Am J Physiol Heart Circ Physiol 288:H1324 (10 ovine LVs): fibre "
                       "angle +42° (SD 16°) at the endocardium, −41° (SD 11°) at the epicardium; 30° ≈ 2 SD"},
    "base": {"max": 1.0, "range": "clamped base (one dose)",
             "cite": "a boundary condition in use: the base fixed in all directions in the Land et al. 2015 "
                     "benchmark (Proc R Soc A 471:20150641, problems 2-3), sliding in Dalton et al. 2022"},
    "sheet": {"max": None, "range": "none cited (a null control)", "cite": None},
    "dispersion": {"max": None, "range": "none cited", "cite": None},
    "heterogeneity": {"max": None, "range": "none cited: regional differences are reported (Novak et al. 1994, "
                                            "J Biomech 27:403, canine: inner and outer LV free wall stiffer than the "
                                            "mid-wall) but no spread that fixes a log-sd", "cite": None},
    "pericardium": {"max": None, "range": "none cited", "cite": None},
}

VERDICTS = ("reproduced", "not shown", "refuted")
#: F1's estimate as tables and the verdicts name it: the iid σ_S over the truth.
F1_COLUMN = f"iid σ_S / {SIGMA_S:g}"
#: The chapter's claim of each finding.
CLAIMS = {"F1": "iid inflates σ_S ≈ 2×", "F2": f"discrepancy σ_S near the truth (0.024; truth {SIGMA_S:g})",
          "F3": "output error: discrepancy ≈ volume < iid", "F5": "5/10 PCs no worse than a new operator (Fig 9.14)",
          "F6": "freeing the fibre angles cuts the LVV error (8/8, 18.9 → 5.9 mL)"}


# ----------------------------------------------------------------------------
# the rule
# ----------------------------------------------------------------------------
def call(ci, threshold: float, above: bool = True) -> str:
    """``"for"``, ``"against"`` or ``"open"``: where a CI lies against a claim's threshold.

    ``above``: the claim is "the statistic is at least ``threshold``" (else: below it).
    """
    lo, hi = ci
    if above:
        return "for" if lo >= threshold else "against" if hi < threshold else "open"
    return "for" if hi < threshold else "against" if lo >= threshold else "open"


def combine(calls) -> str:
    """The symmetric verdict of a finding from its deciding tests' calls (see the module docstring)."""
    calls = [c for c in calls if c is not None]
    n_for, n_against = calls.count("for"), calls.count("against")
    if n_for and not n_against:
        return "reproduced"
    if n_against and not n_for:
        return "refuted"
    return "not shown"


def cluster_boot(units: dict, stat=np.median, n_boot: int = N_BOOT, seed: int = 0, level: float = LEVEL) -> dict:
    """Cluster bootstrap: resample the independent units, pool their values, take ``stat``.

    Parameters
    ----------
    units : dict
        unit name -> sequence of values (a unit's data sets; one value for a unit-level quantity).
    stat : callable
        Statistic of the pooled values (default the median).

    Returns
    -------
    dict
        ``value``, ``ci`` ([low, high], None with fewer than 2 units), ``n`` (units), ``unit_values``
        (each unit's own ``stat``).
    """
    from lvcore.studies._common import bootstrap_ci

    vals = {k: np.asarray([x for x in v if x is not None], dtype=float) for k, v in units.items()}
    vals = {k: v for k, v in vals.items() if v.size}
    unit_values = {k: float(stat(v)) for k, v in vals.items()}
    if stat in (np.median, np.mean) and vals:
        b = _pooled_boot(list(vals.values()), stat is np.median, n_boot, seed, level)
    else:
        b = bootstrap_ci(list(vals), lambda names: float(stat(np.concatenate([vals[n] for n in names]))),
                         n_boot=n_boot, seed=seed, level=level)
    return {"value": b["value"], "ci": b["ci"], "n": b["n_units"], "unit_values": unit_values}


def _pooled_boot(values: list, median: bool, n_boot: int, seed: int, level: float) -> dict:
    """:func:`lvcore.studies._common.bootstrap_ci` of the pooled median or mean of resampled units, vectorised:
    the same resamples (same seed, same draws), each one's statistic from its units' counts instead of a Python
    loop (the median is the count-weighted median of the sorted pooled values, exact)."""
    n_units = len(values)
    sizes = np.array([v.size for v in values])
    pooled = np.concatenate(values)
    value = float(np.median(pooled) if median else np.mean(pooled))
    ci = None
    if n_units >= 2:
        rng = np.random.default_rng(seed)
        draws = rng.integers(0, n_units, size=(int(n_boot), n_units))
        counts = np.stack([(draws == k).sum(axis=1) for k in range(n_units)], axis=1)  # (n_boot, n_units)
        if median:
            order = np.argsort(pooled, kind="stable")
            owner = np.repeat(np.arange(n_units), sizes)[order]
            cum = np.cumsum(counts[:, owner], axis=1)  # copies of the sorted values up to each one
            total = cum[:, -1]
            lo = np.argmax(cum > ((total - 1) // 2)[:, None], axis=1)
            hi = np.argmax(cum > (total // 2)[:, None], axis=1)
            s = pooled[order]
            boots = (s[lo] + s[hi]) / 2.0
        else:
            sums = np.array([v.sum() for v in values])
            boots = counts @ sums / (counts @ sizes)
        boots = boots[np.isfinite(boots)]
        if boots.size:
            ci = [float(v) for v in np.quantile(boots, [(1 - level) / 2, (1 + level) / 2])]
    return {"value": value, "ci": ci, "n_units": n_units}


def dose_range(source: str, dose: float) -> tuple[str, str]:
    """``(label, reason)``: ``realistic``, ``stress test`` (beyond the cited range) or ``uncited`` (no range)."""
    r = PHYSIOLOGICAL_RANGES.get(source)
    if not r or r["max"] is None:
        return "uncited", f"no cited physiological range for {source}"
    if abs(dose) <= r["max"] + 1e-12:
        return "realistic", f"{r['range']} ({r['cite']})"
    return "stress test", f"beyond {r['range']} ({r['cite']})"


def fmt_ci(b: dict | None, fmt: str = ".2f", unit: str = "") -> str:
    """An estimate as ``value [low, high]`` (``n/a`` when absent; the value alone without a CI)."""
    if not b:
        return "n/a"
    if not b.get("ci"):
        return f"{b['value']:{fmt}}{unit}"
    return f"{b['value']:{fmt}}{unit} [{b['ci'][0]:{fmt}}, {b['ci'][1]:{fmt}}]"


__all__ = ["F1_INFLATION", "F2_BAND", "F5_SHARE", "TESTABLE_RMS", "N_MIN", "RHAT_SHARE_MAX", "MIN_CHAINS",
           "BOUND_TOL", "BO_THETA_BOX", "LEVEL", "N_BOOT", "PHYSIOLOGICAL_RANGES", "VERDICTS", "CLAIMS", "call",
           "combine", "cluster_boot", "dose_range", "fmt_ci"]
