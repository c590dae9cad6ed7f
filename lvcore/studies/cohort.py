"""The hierarchical calibration of a SYNTHETIC cohort (``lvcore calibrate --hierarchical``), as the report shows it.

The result file is written by ``benchmarks/bench_hierarchical.py --ship FOLDER``: summary.json's
``hierarchical`` section of its one-group cohort (24 SYNTHETIC subjects drawn from a known population,
:func:`lvcore.inference.cohort.synthetic_cohort`) with the truth, and the two-group run's difference in mu_a.
The report draws each subject's a in the joint posterior against its separate fit, with the population and the
truth (:func:`lvcore.viz.inference_figures.cohort_figure`), and a table of the population against the truth.
"""
from __future__ import annotations

from lvcore.studies.registry import result_file

RESULT_FILE = result_file("cohort")
COMMAND = "nice python benchmarks/bench_hierarchical.py --ship RESULTS"
TITLES = {"fig_cohort_a": "Hierarchical calibration of a SYNTHETIC cohort: a per subject, joint posterior vs "
                          "separate fits, with the population median exp(mu_a) and the truth",
          "table_cohort_population": "Hierarchical calibration of a SYNTHETIC cohort: population mean and sd of "
                                     "log theta against the truth, median narrowing against separate fits"}


def load(folder) -> dict:
    """The result (:data:`RESULT_FILE`) in ``folder``: ``hierarchical`` (summary.json's section), ``truth``
    (``truth.json`` of the SYNTHETIC cohort), ``two_groups`` (the difference in mu_a of a two-group cohort) and
    ``meta``, with ``folder`` added.

    Raises
    ------
    LVCoreError
        The file is missing, too large or not JSON (naming it).
    """
    from lvcore.studies.results import read_result

    return read_result(folder, RESULT_FILE)


def source_line(result: dict) -> str:
    from lvcore.studies.results import source_label

    m = result.get("meta", {})
    return (f"{RESULT_FILE} ({source_label(result['folder'])}); SYNTHETIC cohort of {m.get('n', '?')} subjects, "
            f"{m.get('chains', '?')} chains x ({m.get('warmup', '?')} + {m.get('samples', '?')}), "
            f"{m.get('command', COMMAND)}")


def population_rows(result: dict) -> list[dict]:
    """One row per parameter: mu and the sd of log theta (median and 90 % interval) against the truth, and the
    median narrowing of the subjects' intervals against separate fits."""
    import math

    rec, truth = result["hierarchical"], result["truth"]
    names = truth["theta_names"]
    mu = rec["population"]["groups"]["all"]["mu_log"]
    sd = rec["population"]["sd"]
    rows = []
    for j, k in enumerate(names):
        rows.append({"parameter": k, "mu true": truth["mu_log"]["A"][j], "mu median": mu[k]["median"],
                     "mu q05": mu[k]["q05"], "mu q95": mu[k]["q95"],
                     "covered": mu[k]["q05"] <= truth["mu_log"]["A"][j] <= mu[k]["q95"],
                     "sd true": math.sqrt(truth["cov_log"][j][j]), "sd median": sd[k]["median"],
                     "sd q05": sd[k]["q05"], "sd q95": sd[k]["q95"],
                     "median narrowing": rec["shrinkage"]["median_narrowing"][k]})
    return rows


def tables(result: dict) -> dict:
    import pandas as pd

    return {"table_cohort_population": pd.DataFrame(population_rows(result)),
            "fig_cohort_a": pd.DataFrame([{"subject": s, **{f"joint {c}": q["a"][c] for c in ("q05", "median", "q95")},
                                           **{f"separate {c}": result["hierarchical"]["separate"][s]["a"][c]
                                              for c in ("q05", "median", "q95")},
                                           "truth": result["truth"]["theta"][s][0]}
                                          for s, q in result["hierarchical"]["subjects"].items()])}


def figures(result: dict) -> dict:
    from lvcore.viz.inference_figures import cohort_figure
    from lvcore.viz.report_figures import table_figure

    truth = {s: th[0] for s, th in result["truth"]["theta"].items()}
    return {"fig_cohort_a": cohort_figure(result["hierarchical"], "a", truth=truth),
            "table_cohort_population": table_figure(tables(result)["table_cohort_population"],
                                                    title=TITLES["table_cohort_population"])}


__all__ = ["RESULT_FILE", "COMMAND", "TITLES", "load", "source_line", "tables", "figures", "population_rows"]
