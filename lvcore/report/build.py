"""Build the report: every reproduced figure and table of the chapter, with its data, in one folder.

The report is a list of items over the studies: each :class:`Section` names a
study module of :mod:`lvcore.studies` and the figures it contributes (one per
study with a report section in the registry, :mod:`lvcore.studies.registry`). The
study draws them (``figures(result)``, ``tables(result)``: the same builders
as the app's Studies page); this module only gathers the results, and
:mod:`lvcore.report.export` writes the folder.

Layout of ``DIR`` (all paths in the manifest are relative to it)::

    index.html            one page with every figure (PNG linking to the interactive HTML)
    manifest.json         {"figures": [{"name", "title", "png", "svg", "html", "data", ...}, ...]}
    figures/<name>.png|svg|html   (the HTML files share figures/plotly.min.js)
    data/<name>.csv|json  what each figure was drawn from

Where the numbers come from: Fig 9.5 from the bundled ``angles`` emulator (or
the FE simulator, ``sweep="simulator"``); Table 9.4 and Fig 9.10 computed from
the bundled SYNTHETIC cohort; the calibration posterior from a short live NUTS
run on SYNTHETIC-HV3; Figs 9.6–9.9, Tables 9.2/9.3 and Figs 9.11–9.14 from
saved study results (``--from RESULTS`` first, then the bundled ones); the
mismatch dose–response and the findings table (F1, F2, F3, F5, F6 with
verdicts) from the shipped mismatch results (with the operator and fibre-angle
BO results); the simulation-based calibration of the pipeline (rank
histograms, coverage) from the shipped SBC results; all listed as missing with
the command that makes them when absent. Each study's result file is named by
its entry in :data:`lvcore.studies.registry.STUDIES`, the list the sections are
derived from.
"""
from __future__ import annotations

import importlib
import inspect
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from lvcore.report.export import (ReportError, ReportItem, StaticExportError, export_static, index_html,
                                  plotly_template, write_items)
from lvcore.studies.registry import STUDIES, Study


@dataclass(frozen=True)
class Section:
    """Items of the report drawn by one study module.

    ``saved``: the study's results are read from ``result_file`` (its module's ``load``);
    otherwise ``compute(options)`` makes them (seconds), None when impossible.
    """

    label: str
    study: str
    names: tuple[str, ...]
    saved: bool = False
    compute: Callable[[dict], object] | None = None
    result_file: str | None = None


def _live(study: str) -> Callable[[dict], object]:
    """``compute(**options)`` of a study module, given the report options its ``compute`` takes (e.g. ``sweep``)."""
    def compute(opts: dict):
        fn = importlib.import_module(f"lvcore.studies.{study}").compute
        return fn(**{k: v for k, v in opts.items() if k in inspect.signature(fn).parameters})
    return compute


def _section(study: Study) -> Section:
    saved = study.report_file is not None
    return Section(study.report, study.module, study.report_items, saved=saved,
                   compute=None if saved else _live(study.module), result_file=study.report_file)


#: The report's sections: one per study with a report section in the registry, in the registry's order.
SECTIONS = tuple(_section(s) for s in STUDIES.values() if s.report)
#: Every figure/table the report produces, in order (the manifest lists each, present or missing).
FIGURE_NAMES = tuple(n for s in SECTIONS for n in s.names)


def section_items(section: Section, results_dir=None, *, sweep: str = "emulator") -> list[ReportItem]:
    """The items of one section: drawn by its study, or missing with the reason and the command that makes them."""
    from lvcore.studies.results import bundled_studies_dir, find_result

    mod = importlib.import_module(f"lvcore.studies.{section.study}")
    titles = {n: mod.TITLES[n] for n in section.names}
    if section.saved:
        path = find_result(section.result_file, results_dir)
        rerun = f"run {mod.COMMAND}, then lvcore report --from RESULTS"
        if path is None:
            where = f"{results_dir} or {bundled_studies_dir()}" if results_dir else str(bundled_studies_dir())
            return [ReportItem(n, t, source=section.result_file,
                               missing=f"missing: {rerun} ({section.result_file} not found in {where})")
                    for n, t in titles.items()]
        try:
            result = mod.load(path.parent)
        except (KeyError, TypeError, ValueError, AttributeError, IndexError) as err:
            raise ReportError(f"study results '{path}' are not the output of {mod.COMMAND} "
                              f"({type(err).__name__}: {str(err)[:200]}); give the --out folder of that command") from None
    else:
        result = section.compute({"sweep": sweep})
        rerun = ""
    if result is None:
        return [ReportItem(n, t, missing=f"missing: {mod.MISSING[n]}") for n, t in titles.items()]
    figs, data = mod.figures(result), mod.tables(result)
    notes = mod.captions(result) if hasattr(mod, "captions") else {}
    source = mod.source_line(result)
    items = []
    for n, t in titles.items():
        if n in figs:
            items.append(ReportItem(n, t, figs[n], data.get(n), source, notes=notes.get(n, "")))
        else:
            why = getattr(mod, "MISSING", {}).get(n, "the results hold no data for it (older study output)")
            items.append(ReportItem(n, t, source=source, missing=f"missing: {why}" + (f"; {rerun}" if rerun else "")))
    return items


def build_report(out, results_dir=None, *, sweep: str = "emulator", calibration: bool = True,
                 formats: tuple[str, ...] = ("png", "svg"), progress: Callable[[str], None] | None = None) -> dict:
    """Write the report under ``out`` and return the manifest (also written as ``out/manifest.json``).

    Parameters
    ----------
    out : path
        Output folder (created).
    results_dir : path, optional
        Folder with saved study results (the ``--out`` folder of ``lvcore study ...``); each study's result
        file falls back to the bundled one.
    sweep : {"emulator", "simulator"}
        Fig 9.5 by the bundled ``angles`` emulator or by the FE simulator (fast mesh).
    calibration : bool
        Run the short live calibration of SYNTHETIC-HV3 (``timings_s["calibration posterior"]``).
    formats : tuple of str
        Static formats (``png``, ``svg``); empty for HTML only. When the static export
        fails (no kaleido, no Chromium) the HTML report is still written and the
        manifest's ``skipped_formats`` and ``static_export_error`` say so.

    Returns
    -------
    dict
        ``{"figures": [{"name", "title", "png", "svg", "html", "data", "status", "missing",
        "source", "notes"}, ...], "timings_s", "wall_s", "skipped_formats", ...}`` with paths relative to ``out``.
    """
    import lvcore
    from lvcore.studies.results import bundled_studies_dir

    t0 = time.perf_counter()
    say = progress or (lambda m: None)
    out = Path(out)
    if results_dir is not None and not Path(results_dir).is_dir():
        raise ReportError(f"--from {results_dir}: no such folder; give the --out folder of `lvcore study ...`")
    (out / "figures").mkdir(parents=True, exist_ok=True)
    (out / "data").mkdir(parents=True, exist_ok=True)
    items, timings = [], {}
    with plotly_template("plotly"):
        for section in SECTIONS:
            if section.study == "volunteer_calibration" and not calibration:
                items += [ReportItem(n, n.replace("_", " "), missing="skipped: lvcore report --no-calibration")
                          for n in section.names]
                continue
            t = time.perf_counter()
            say(f"{section.label}...")
            items += section_items(section, results_dir, sweep=sweep)
            timings[section.label] = round(time.perf_counter() - t, 2)
        entries, figs, static_paths = write_items(items, out, tuple(formats))
        t = time.perf_counter()
        skipped, error = [], None
        if figs:
            say(f"static export of {len(figs)} images...")
            try:
                export_static(figs, static_paths)
            except StaticExportError as err:
                skipped, error = list(formats), str(err)
                for e in entries:
                    for fmt in formats:
                        e[fmt] = None
                say(f"static formats skipped ({', '.join(skipped)}): {error}")
        timings["static export"] = round(time.perf_counter() - t, 2)
    manifest = {
        "figures": entries,
        "generated": time.strftime("%Y-%m-%d %H:%M:%S"),
        "lvcore": getattr(lvcore, "__version__", "?"),
        "results_dirs": ([str(results_dir)] if results_dir else []) + [str(bundled_studies_dir())],
        "formats": list(formats), "skipped_formats": skipped, "static_export_error": error,
        "timings_s": timings,
        "wall_s": round(time.perf_counter() - t0, 2),
    }
    (out / "index.html").write_text(index_html(manifest))
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1))
    say(f"done in {manifest['wall_s']:.0f} s")
    return manifest


__all__ = ["FIGURE_NAMES", "SECTIONS", "Section", "ReportItem", "ReportError", "section_items", "build_report"]
