"""How the app shows a posterior summary table: column headers in words and a help text on every column.

The table is :func:`lvcore.inference.diagnostics.summary_table` (ArviZ's summary with the 90 % equal-tailed
interval, q05–q95, in place of ArviZ's HDI: the interval of the verdict and the derived quantities). Importing this
module does not import Streamlit.
"""
from __future__ import annotations

from lvcore.inference.diagnostics import INTERVAL_TEXT  # "90 % equal-tailed interval", one wording everywhere

#: Per column of the summary: (header, help). The ArviZ diagnostics are explained in plain words.
SUMMARY_COLUMNS = {
    "mean": ("mean", "Posterior mean."),
    "sd": ("sd", "Posterior standard deviation."),
    "median": ("median", "Posterior median (the 50 % quantile of the pooled draws of all chains)."),
    "q05": (f"q05 ({INTERVAL_TEXT})",
            f"5 % quantile of the pooled draws: the lower end of the {INTERVAL_TEXT} (5 % of the posterior below, "
            "5 % above q95); the same interval as the verdict and the derived quantities use."),
    "q95": (f"q95 ({INTERVAL_TEXT})",
            f"95 % quantile of the pooled draws: the upper end of the {INTERVAL_TEXT}."),
    "mcse_mean": ("mcse_mean", "Monte Carlo standard error of the mean: how much the reported mean would move if "
                               "the sampler were run again with another seed (small against sd is good)."),
    "mcse_sd": ("mcse_sd", "Monte Carlo standard error of the sd: the run-to-run uncertainty of the reported sd."),
    "ess_bulk": ("ess_bulk", "Bulk effective sample size: how many independent draws the correlated chains are "
                             "worth for the centre of the posterior (mean, median). At least 100 is required for "
                             "convergence, 400 or more for a green banner."),
    "ess_tail": ("ess_tail", "Tail effective sample size: the same for the tails (the 5 % and 95 % quantiles, so "
                             "for q05 and q95); low values make the interval's ends uncertain."),
    "r_hat": ("r_hat", "Rank-normalised split R-hat: compares the chains (and each chain's halves). About 1.00 when "
                       "they agree; above 1.05 the run has not converged. Needs at least two chains."),
}


def number_column(st, name: str):
    """The ``st.column_config.NumberColumn`` of summary column ``name`` (header in words, help, 4 significant
    digits)."""
    label, text = SUMMARY_COLUMNS[name]
    return st.column_config.NumberColumn(label, help=text, format="%.4g")


def summary_column_config(st, columns) -> dict:
    """``st.dataframe``'s ``column_config`` for the summary columns in ``columns``: a header in words and a help
    text each (other columns are left alone)."""
    return {col: number_column(st, col) for col in columns if col in SUMMARY_COLUMNS}


#: What a summary cell without a value says (R-hat compares chains: one chain has none).
MISSING_TEXT = {"r_hat": "n/a: needs ≥ 2 chains"}


def summary_view(st, table):
    """``(frame, column_config)`` to show a posterior summary with ``st.dataframe``: headers in words and a help text
    on every summary column; a column with missing values (R-hat of a single chain) is shown as text that says why
    ("n/a: needs ≥ 2 chains", else "–"), never as None or NaN."""
    import pandas as pd

    frame = table.copy()
    config = {}
    for col in frame.columns:
        if col not in SUMMARY_COLUMNS:
            continue
        if frame[col].isna().any():
            label, text = SUMMARY_COLUMNS[col]
            fill = MISSING_TEXT.get(col, "–")
            frame[col] = [fill if pd.isna(v) else f"{float(v):.4g}" for v in frame[col]]
            config[col] = st.column_config.TextColumn(label, help=text)
        else:
            config[col] = number_column(st, col)
    return frame, config


def no_missing(frame, fill: str = "–"):
    """A copy of ``frame`` for display whose missing cells read ``fill`` (a column with any is shown as text, its
    numbers with 4 significant digits), never None or NaN."""
    import pandas as pd

    out = frame.copy()
    for col in out.columns:
        if out[col].isna().any():
            out[col] = [fill if pd.isna(v) else (f"{v:.4g}" if isinstance(v, float) else str(v)) for v in out[col]]
    return out


__all__ = ["INTERVAL_TEXT", "SUMMARY_COLUMNS", "MISSING_TEXT", "number_column", "summary_column_config",
           "summary_view", "no_missing"]
