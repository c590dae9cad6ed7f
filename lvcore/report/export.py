"""Writing the report folder: figure files, their data, the static export, index.html and manifest.json.

Nothing here knows a study: :mod:`lvcore.report.build` hands over a list of
:class:`ReportItem` and this module writes them.
"""
from __future__ import annotations

import contextlib
import html
import json
from dataclasses import dataclass, field
from pathlib import Path

from lvcore.exceptions import LVCoreError


class ReportError(LVCoreError):
    """The report could not be written (e.g. ``--from`` names no folder)."""


class StaticExportError(ReportError):
    """The static export (PNG/SVG) failed: no kaleido or no Chromium. The HTML report is still written."""


@dataclass(frozen=True)
class ReportItem:
    """One figure or table of the report.

    Attributes
    ----------
    name : str
        File stem (see :data:`lvcore.report.FIGURE_NAMES`).
    title : str
        Shown in index.html and the manifest (the figure carries its own title).
    fig : plotly Figure or None
        None when ``missing``.
    data : DataFrame, dict or list, or None
        What the figure was drawn from (CSV for a DataFrame, JSON otherwise).
    source : str
        Where the numbers come from (file, emulator, live run), readable text.
    missing : str or None
        Why the item is absent and the command that makes it.
    notes : str
        Free text shown under the figure in index.html (findings, caveats).
    """

    name: str
    title: str
    fig: object = field(default=None, repr=False)
    data: object = field(default=None, repr=False)
    source: str = ""
    missing: str | None = None
    notes: str = ""


@contextlib.contextmanager
def plotly_template(name: str = "plotly"):
    """Build figures with plotly's own template, whatever the process set as default.

    ``import streamlit`` makes its ``streamlit`` template the default; its colours
    are placeholders (``#000038``...) that only Streamlit's frontend replaces, so a
    report built inside the app would export tables as dark blocks.
    """
    import plotly.io as pio

    old = pio.templates.default
    pio.templates.default = name
    try:
        yield
    finally:
        pio.templates.default = old


def write_data(data, base: Path) -> Path | None:
    """``data`` as ``base.csv`` (a DataFrame) or ``base.json`` (anything else); None for no data."""
    import pandas as pd

    if data is None:
        return None
    if isinstance(data, pd.DataFrame):
        path = base.with_suffix(".csv")
        data.to_csv(path, index=False)
    else:
        path = base.with_suffix(".json")
        path.write_text(json.dumps(data, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
    return path


#: What the static export (PNG/SVG) needs, as the app and the CLI tell the user.
STATIC_EXPORT_NEEDS = ('kaleido (pip install "lvcore[report]") and a Chromium (Debian\'s chromium: '
                       'apt-get install chromium)')


def _kaleido_problem() -> str | None:
    """Why kaleido cannot export here (plotly needs kaleido >= 1), in words; None when it can."""
    import importlib
    import importlib.metadata

    try:
        major = int(importlib.metadata.version("kaleido").split(".")[0])
        importlib.import_module("kaleido")
    except Exception:  # noqa: BLE001 - not installed or broken: either way there is no exporter
        return 'kaleido is not installed (pip install "lvcore[report]")'
    if major < 1:
        return f'kaleido {importlib.metadata.version("kaleido")} is too old, plotly needs 1 or later ' \
               '(pip install "lvcore[report]")'
    return None


def find_chromium() -> str | None:
    """The Chromium kaleido would start: its own search (BROWSER_PATH, PATH, typical paths, a kaleido download)."""
    import os
    import shutil

    try:
        from choreographer.browsers.chromium import Chromium  # kaleido's browser driver

        path = Chromium.find_browser(skip_local=False)
    except Exception:  # noqa: BLE001 - choreographer moved its API: look where it looks (BROWSER_PATH, then PATH)
        path = os.environ.get("BROWSER_PATH") or next(
            (p for n in ("chromium", "chromium-browser", "google-chrome", "chrome") if (p := shutil.which(n))), None)
    return str(path) if path and Path(path).is_file() else None


def static_export_problem() -> str | None:
    """Why the static export (PNG/SVG) cannot run here, in words; None when kaleido and a Chromium are found.

    The Report page asks this before it offers static figures, and :func:`export_static`
    before it starts Chromium, so a missing exporter is said plainly, never as kaleido's
    or plotly's own exception.
    """
    problem = _kaleido_problem()
    if problem is None and find_chromium() is None:
        problem = ("no Chromium found, which kaleido needs to draw PNG/SVG "
                   "(install Debian's chromium: apt-get install chromium)")
    return problem


def _one_line(err: BaseException, limit: int = 200) -> str:
    text = " ".join(str(err).split()).rstrip(". ")
    return f"{type(err).__name__}: {text[:limit] + ('…' if len(text) > limit else '')}"


def export_static(figs: list, paths: list[Path]) -> None:
    """PNG/SVG of every figure in one Chromium session (kaleido); :class:`StaticExportError` when that fails.

    The error's message is a sentence for the user: what is missing and how to install it
    (:func:`static_export_problem`), or that kaleido failed with a one-line reason.
    """
    if not figs:
        return
    problem = static_export_problem()
    if problem is not None:
        raise StaticExportError(f"static export (PNG/SVG) not possible: {problem}")
    import plotly.io as pio

    from lvcore.viz.report_figures import EXPORT_WIDTH_PX

    widths = [int(f.layout.width or EXPORT_WIDTH_PX) for f in figs]
    heights = [int(f.layout.height or 500) for f in figs]  # kaleido would use 500 px whatever the layout says
    try:
        pio.write_images(figs, [str(p) for p in paths], width=widths, height=heights)
    except Exception as err:  # kaleido raises its own types (ChromeNotFoundError, ...)
        raise StaticExportError(
            f"static export (PNG/SVG) failed in kaleido/Chromium ({_one_line(err)}); it needs "
            f"{STATIC_EXPORT_NEEDS}") from err


def index_html(manifest: dict) -> str:
    """The report's one page: every figure (PNG linking to its HTML), source and notes; missing ones say why."""
    esc = html.escape
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>LV Calibration Lab report</title>",
             "<style>body{font-family:sans-serif;max-width:1150px;margin:auto;padding:1em}"
             "figure{margin:1.5em 0;border-bottom:1px solid #ddd;padding-bottom:1em}"
             ".fig{overflow-x:auto}img{max-width:none}"
             ".missing{background:#fff3f0;border:1px solid #f0b0a0;padding:.6em}.note{color:#555}</style>"
             "</head><body>",
             "<h1>LV Calibration Lab: the chapter's figures and tables</h1>",
             f"<p>Generated {esc(manifest['generated'])} by <code>lvcore report</code> (lvcore {esc(manifest['lvcore'])}) "
             f"in {manifest['wall_s']:.0f} s. All data are SYNTHETIC. Study results from: "
             f"{esc(', '.join(manifest['results_dirs']))}.</p>"]
    if manifest.get("skipped_formats"):
        parts.append(f"<p class='missing'>Static formats skipped ({esc(', '.join(manifest['skipped_formats']))}): "
                     f"{esc(manifest.get('static_export_error') or '')}. The interactive HTML figures are complete."
                     "</p>")
    parts.append("<ul>")
    for f in manifest["figures"]:
        mark = "" if f["status"] == "ok" else " (missing)"
        parts.append(f"<li><a href='#{esc(f['name'])}'>{esc(f['title'])}</a>{mark}</li>")
    parts.append("</ul>")
    for f in manifest["figures"]:
        parts.append(f"<figure id='{esc(f['name'])}'><h3>{esc(f['title'])}</h3>")
        if f["status"] != "ok":
            parts.append(f"<p class='missing'>{esc(f['missing'])}</p></figure>")
            continue
        img = f["png"] or f["svg"]
        if img:  # wide tables scroll sideways instead of being shrunk or clipped
            parts.append(f"<div class='fig'><a href='{esc(f['html'])}'><img src='{esc(img)}' "
                         f"alt='{esc(f['title'])}' style='max-width:100%'></a></div>")
        else:
            parts.append(f"<p><a href='{esc(f['html'])}'>interactive figure (HTML)</a></p>")
        links = [f"<a href='{esc(f[k])}'>{k.upper()}</a>" for k in ("html", "png", "svg", "data") if f.get(k)]
        parts.append(f"<figcaption>{' · '.join(links)}<br><span class='note'>source: {esc(f['source'])}"
                     + (f"<br>{esc(f['notes'])}" if f.get("notes") else "") + "</span></figcaption></figure>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_items(items: list[ReportItem], out: Path, formats: tuple[str, ...]) -> tuple[list[dict], list, list[Path]]:
    """Write each drawn item's HTML and data; return the manifest entries and the figures/paths to export."""
    from lvcore.viz.report_figures import wrap_title

    entries, figs, static_paths = [], [], []
    for it in items:
        entry = {"name": it.name, "title": it.title, "png": None, "svg": None, "html": None, "data": None,
                 "status": "missing" if it.fig is None else "ok", "missing": it.missing, "source": it.source,
                 "notes": it.notes}
        if it.fig is not None:
            wrap_title(it.fig)
            base = out / "figures" / it.name
            it.fig.write_html(str(base.with_suffix(".html")), include_plotlyjs="directory")
            entry["html"] = f"figures/{it.name}.html"
            for fmt in formats:
                figs.append(it.fig)
                static_paths.append(base.with_suffix(f".{fmt}"))
                entry[fmt] = f"figures/{it.name}.{fmt}"
            data_path = write_data(it.data, out / "data" / it.name)
            entry["data"] = None if data_path is None else str(data_path.relative_to(out))
        entries.append(entry)
    return entries, figs, static_paths


__all__ = ["ReportError", "StaticExportError", "ReportItem", "STATIC_EXPORT_NEEDS", "plotly_template", "write_data",
           "find_chromium", "static_export_problem", "export_static", "index_html", "write_items"]
