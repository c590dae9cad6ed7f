"""``lvcore report``: regenerate the chapter's figures and tables in one folder.

:func:`build_report` writes PNG + SVG (plotly static export via kaleido and a
Chromium), interactive HTML, the data behind every figure, ``index.html`` and
``manifest.json``. Figures whose study results are absent are listed in the
manifest as missing with the command that makes them; nothing is faked.
"""
from lvcore.report.build import FIGURE_NAMES, ReportItem, build_report, studies_dir

__all__ = ["FIGURE_NAMES", "ReportItem", "build_report", "studies_dir"]
