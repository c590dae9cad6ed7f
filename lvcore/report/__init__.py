"""``lvcore report``: regenerate the chapter's figures and tables in one folder.

:func:`build_report` writes PNG + SVG (plotly static export via kaleido and a
Chromium), interactive HTML, the data behind every figure, ``index.html`` and
``manifest.json``. The figures are drawn by the study modules
(:mod:`lvcore.studies`); figures whose study results are absent are listed in
the manifest as missing with the command that makes them; nothing is faked.
Without kaleido or Chromium the HTML report is written and the skipped static
formats are named.
"""
from lvcore.report.build import FIGURE_NAMES, SECTIONS, build_report
from lvcore.report.export import ReportError, ReportItem

__all__ = ["FIGURE_NAMES", "SECTIONS", "ReportError", "ReportItem", "build_report"]
