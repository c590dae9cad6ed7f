"""The chapter's findings F1, F2, F3, F5 and F6 with one symmetric verdict rule, from the shipped study results.

Every number comes from saved results read through their study modules
(:func:`lvcore.studies.results.find_result` then the module's ``load``):
F1–F3 from the mismatch dose–response (:mod:`lvcore.studies.mismatch`) and,
as rows of their own, from the direct replication of the chapter's design
(:mod:`lvcore.studies.fibre_discrepancy`: its 12 angle × θ test sets); F5
from the realistic-operator study (:mod:`lvcore.studies.operators_realistic`)
with the first operator study (:mod:`lvcore.studies.operators`) beside it;
F6 from the known-mismatch BO (:mod:`lvcore.studies.bo_mismatch`) with the
first fibre-angle BO (:mod:`lvcore.studies.bo_fibres`) beside it.

The verdict rule (the same for every finding)
---------------------------------------------
Each finding is tested at one or more *tests* (a dose of a mismatch source,
a PC count, a study). A test is **deciding** when all of these hold:

* its dose lies inside a cited physiological range (:data:`PHYSIOLOGICAL_RANGES`;
  a dose beyond it is a *stress test*, a source without a cited range is
  *uncited*; both are reported and kept out of verdicts);
* the dose is large enough to show the claim at all (F1–F3: a strain RMS
  mismatch of at least :data:`TESTABLE_RMS`, the smallest mismatch that
  could inflate the iid σ_S to 1.5× even if θ absorbed none of it);
* its CI resamples the independent unit (volunteers, patients, test sets)
  with a percentile bootstrap, over at least :data:`N_MIN` units;
* its fits are trustworthy: MCMC with ≥ 2 chains and at most
  :data:`RHAT_SHARE_MAX` of the data sets with split R-hat > 1.05;
  optimisation fits with no parameter on a bound of their box (those are
  left out; a test left with too few units is not deciding).

A deciding test calls **for** the claim when its 90 % CI lies on the claim's
side of the threshold, **against** when it lies on the other side, and
*open* when it straddles. A finding is **reproduced** when at least one
deciding test is for and none against, **refuted** when at least one is
against and none for, and **not shown** otherwise (no deciding test, all
open, or for and against at different tests). Swapping for and against
swaps reproduced and refuted: the rule is symmetric.

=====  ===================================  ===============================================================
F1     iid inflates σ_S ≈ 2×                 iid σ_S / 0.03: for when the CI's lower end ≥ 1.5, against when
                                            its upper end < 1.5
F2     the discrepancy σ_S stays near the    discrepancy σ_S, only where F1 is for: for when the CI lies in
       truth (0.024; truth 0.03)            [0.5, 1.3] × 0.03, against when it lies outside that band
F3     output error discrepancy ≈ volume     paired iid − discrepancy and iid − volume output errors: for when
       < iid                                both CIs lie above 0, against when either lies below 0
F5     5/10 PCs no worse than a new          share of comparisons (PC refit vs another operator's) no worse in
       operator in output space             output space: for when the CI's lower end ≥ 0.5, against when its
                                            upper end < 0.5; per PC count
F6     freeing the angles cuts the LVV       LVV error fixed − free per volunteer (mean): for when the CI lies
       error                                above 0, against when below 0
=====  ===================================  ===============================================================
"""
from __future__ import annotations

from lvcore.studies import registry
from lvcore.studies.findings_docs import (DOCS_BEGIN, DOCS_END, PROSE_BEGIN, PROSE_END, docs_markdown,  # noqa: F401
                                          prose_markdown, ranges_markdown, rewrite_docs)
from lvcore.studies.findings_rule import (BO_THETA_BOX, BOUND_TOL, CLAIMS, F1_COLUMN, F1_INFLATION,  # noqa: F401
                                          F2_BAND, F5_SHARE, LEVEL, MIN_CHAINS, N_BOOT, N_MIN, PHYSIOLOGICAL_RANGES,
                                          RHAT_SHARE_MAX, TESTABLE_RMS, VERDICTS, call, cluster_boot, combine,
                                          dose_range, fmt_ci)
from lvcore.studies.findings_tests import (COLUMNS, SOURCES, _f5_row, _f6_rows, _mismatch_row,  # noqa: F401
                                           _replication_rows, bo_on_bound, dose_rows, f5_tests, f6_tests,
                                           mismatch_dose_tests, replication_tests, verdicts)

#: The result file the report looks for: the mismatch study's (the first of the inputs), from the registry.
RESULT_FILE = registry.STUDIES["findings"].report_file
#: The command that makes it.
COMMAND = "python scripts/ship_mismatch.py"
TITLES = {"table_findings": "The chapter's findings: verdicts with 90 % CIs over the independent unit",
          "table_findings_doses": "Findings F1–F3 per mismatch dose: range, convergence, resampled unit, calls"}
MISSING = {"table_findings": "the shipped mismatch results (python scripts/ship_mismatch.py)",
           "table_findings_doses": "the shipped mismatch results (python scripts/ship_mismatch.py)"}


# ----------------------------------------------------------------------------
# loading
# ----------------------------------------------------------------------------
def load(folder=None) -> dict:
    """The input studies' results: ``folder``'s result files first, then the bundled ones.

    Parameters
    ----------
    folder : path, optional
        A folder with result files of the input studies (:data:`SOURCES`; e.g. a mismatch ``--out`` folder);
        each file it lacks is taken from the bundled results.

    Returns
    -------
    dict
        Study module -> its result as its own ``load`` reads it (None when no result file is found), and
        ``folder``.

    Raises
    ------
    FileNotFoundError
        No mismatch result in ``folder`` nor bundled (F1–F3 rest on it).

    Examples
    --------
    The bundled (SYNTHETIC) results and the verdict of each finding:

    >>> from lvcore.studies import findings
    >>> result = findings.load()
    >>> sorted(k for k in result if k != "folder") == sorted(findings.SOURCES)
    True
    >>> rows = findings.verdicts(result)
    >>> [r["finding"] for r in rows][:3]
    ['F1', 'F2', 'F3']
    >>> all(r["verdict"] in findings.VERDICTS for r in rows)
    True
    """
    from lvcore.studies.results import find_result

    out = {"folder": str(folder) if folder else None}
    for name in registry.STUDIES["findings"].inputs:
        study = registry.STUDIES[name]
        path = find_result(study.result_file, folder)
        out[study.module] = study.load(path.parent) if path else None
    if out["mismatch"] is None:
        raise FileNotFoundError(f"no {SOURCES['mismatch']} (run python scripts/ship_mismatch.py)")
    return out


def source_line(result: dict) -> str:
    """Where the numbers come from."""
    from lvcore.studies.results import source_label

    parts = [f"{SOURCES[k]} ({source_label(result[k].get('folder'))})" for k in SOURCES
             if isinstance(result.get(k), dict)]
    from lvcore.studies.mismatch import kernel_note

    return ("findings from " + ", ".join(parts) + "; SYNTHETIC data; 90 % percentile bootstrap CIs over the "
            "independent unit; one symmetric verdict rule over cited physiological doses (lvcore.studies.findings)"
            + kernel_note(result.get("mismatch") or {}))


def tables(result: dict) -> dict:
    import pandas as pd

    return {"table_findings": pd.DataFrame(verdicts(result), columns=list(COLUMNS)),
            "table_findings_doses": pd.DataFrame(dose_rows(result))}


def _slim_doses(d):
    """The per-dose table in six columns (the report's width)."""
    import pandas as pd

    if d.empty:
        return d
    return pd.DataFrame({
        "dose (strain RMS; range)": d["source"] + " " + d["dose"].map("{:g}".format) + " ("
        + d["strain RMS"].map("{:.4f}".format) + "; " + d["range"] + ")",
        "sampler; R-hat > 1.05 volume / iid / discrepancy": d["sampler"] + "; "
        + d["R-hat > 1.05 (volume / iid / discrepancy)"],
        "CI over": d["CI over"], F1_COLUMN: d[F1_COLUMN], "calls F1 / F2 / F3": d["calls F1 / F2 / F3"],
        "deciding": d["deciding"]})


def figures(result: dict) -> dict:
    """The findings table (five columns, so that it wraps to the report's width) and the per-dose table."""
    import pandas as pd

    from lvcore.viz.report_figures import table_figure

    tabs = tables(result)
    t = tabs["table_findings"]
    slim = pd.DataFrame({"finding: the chapter's claim": t["finding"] + ": " + t["claim"], "verdict": t["verdict"],
                         "estimate [90 % CI]: call (CI over)": t["ci"] + " (" + t["unit"] + ")",
                         "doses, range; source": t["doses"] + "; " + t["source"], "what decides": t["why"]})
    return {"table_findings": table_figure(slim,
                                           title="SYNTHETIC studies: the chapter's findings, verdicts with 90 % "
                                                 "CIs over the independent unit"),
            "table_findings_doses": table_figure(_slim_doses(tabs["table_findings_doses"]),
                                                 title="SYNTHETIC mismatch doses: range, convergence, calls")}


__all__ = ["load", "verdicts", "dose_rows", "mismatch_dose_tests", "replication_tests", "f5_tests", "f6_tests",
           "bo_on_bound", "call", "combine", "cluster_boot", "dose_range", "fmt_ci", "tables", "figures",
           "source_line", "docs_markdown", "prose_markdown", "ranges_markdown", "rewrite_docs", "PROSE_BEGIN",
           "PROSE_END", "PHYSIOLOGICAL_RANGES", "TESTABLE_RMS", "N_MIN", "RHAT_SHARE_MAX", "MIN_CHAINS", "VERDICTS",
           "CLAIMS", "DOCS_BEGIN", "DOCS_END", "SOURCES", "COLUMNS", "RESULT_FILE", "COMMAND", "TITLES", "MISSING",
           "F1_INFLATION", "F2_BAND", "F5_SHARE", "BOUND_TOL", "BO_THETA_BOX", "LEVEL", "N_BOOT"]
