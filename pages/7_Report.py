"""Report: every figure and table of the chapter that the project reproduces, as one zip download."""
from __future__ import annotations

import logging
import shutil
import tempfile
import time
from pathlib import Path

import pandas as pd
import streamlit as st

from lvcore.app import freshness
from lvcore.exceptions import LVCoreError
from lvcore.report import export as report_export
from lvcore.studies.volunteer_calibration import DEFAULT_SUBJECT, TYPICAL_SECONDS

st.set_page_config(page_title="Report", layout="wide")
st.title("Report")
st.caption(
    "Regenerates the chapter's figures and tables (Fig 9.5 angle sweeps, Figs 9.6–9.9 fibre discrepancy, "
    "Table 9.4 / Fig 9.10 operators and PCA, Figs 9.11–9.14 and Tables 9.2/9.3, the calibration posteriors) "
    "from the shipped study results, exactly as `lvcore report --out DIR` does, and offers them as a zip: "
    "PNG/SVG figures, the CSV/JSON each was drawn from, index.html and manifest.json. All data SYNTHETIC."
)
c1, c2 = st.columns(2)
calibration = c1.checkbox(f"Include the live calibration of {DEFAULT_SUBJECT} (adds about {TYPICAL_SECONDS[0]}–"
                          f"{TYPICAL_SECONDS[1]} s)", value=True,
                          help="iid model, `chapter` emulator, 4 chains × (500 + 500) NUTS draws; the time includes "
                               "JAX's compilation (docs/report.md, Timing)")
# offered only where it can run: kaleido importable and a Chromium found where kaleido looks for one
cannot_export = report_export.static_export_problem()
static = c2.checkbox("Static PNG + SVG figures (kaleido, needs Chromium)", value=cannot_export is None,
                     disabled=cannot_export is not None,
                     help="Off: interactive HTML figures only, faster and no Chromium needed." if cannot_export is None
                     else f"Not available here: {cannot_export}. For PNG/SVG install {report_export.STATIC_EXPORT_NEEDS}"
                          ", then restart the app. The HTML figures need neither.")
if cannot_export is not None:
    static = False
    c2.caption(f"PNG/SVG unavailable: {cannot_export}. The report is written with interactive HTML figures.")
inputs = {"live calibration": "yes" if calibration else "no",
          "figures": "PNG, SVG and HTML" if static else "HTML only"}

if st.button("Build report", type="primary"):
    from lvcore.report import build_report

    bar = st.progress(0.0, text="starting")
    messages: list[str] = []
    t0 = time.perf_counter()

    def progress(msg: str) -> None:
        messages.append(msg)
        bar.progress(min(0.95, len(messages) / 8), text=f"{msg} — {time.perf_counter() - t0:.0f} s elapsed")

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "lvcore-report"
        try:
            manifest = build_report(out, calibration=calibration, formats=("png", "svg") if static else (),
                                    progress=progress)
        except LVCoreError as err:
            bar.progress(1.0, text=f"failed after {time.perf_counter() - t0:.0f} s")
            st.error(f"Report failed: {err}")
        except Exception as err:  # noqa: BLE001 - a bug, not the user's input: say so in words, log the traceback
            logging.getLogger(__name__).exception("report build failed")
            bar.progress(1.0, text=f"failed after {time.perf_counter() - t0:.0f} s")
            st.error(f"Report failed: an unexpected error ({type(err).__name__}) stopped the build; the full "
                     "traceback is in the app's log. Please report it with that log.")
        else:
            archive = shutil.make_archive(str(Path(tmp) / "lvcore-report"), "zip", root_dir=out.parent,
                                          base_dir=out.name)
            freshness.remember("report", {"zip": Path(archive).read_bytes(), "manifest": manifest,
                                          "wall_s": time.perf_counter() - t0}, inputs)
            skipped = manifest.get("skipped_formats")
            bar.progress(1.0, text=f"done in {time.perf_counter() - t0:.0f} s"
                                   + (f", without {' and '.join(f.upper() for f in skipped)}" if skipped else ""))

stored = freshness.recall("report")
if stored is not None:
    with freshness.shown(stored, inputs, "report"):
        rep = stored.result
        figs = rep["manifest"].get("figures", [])
        st.download_button("Download the report (zip)", rep["zip"], file_name="lvcore-report.zip",
                           mime="application/zip", type="primary")
        st.write(f"{len(figs)} figures and tables in {rep['wall_s']:.0f} s.")
        if rep["manifest"].get("skipped_formats"):
            st.warning(f"No {' or '.join(f.upper() for f in rep['manifest']['skipped_formats'])} figures: "
                       f"{rep['manifest'].get('static_export_error') or 'the static export failed'}. The zip holds "
                       "the interactive HTML figures, their data, index.html and manifest.json.")
        st.dataframe(pd.DataFrame([{"name": f.get("name"), "title": f.get("title"),
                                    "status": f.get("status") or ("missing" if f.get("missing") else "ok"),
                                    "note": f.get("missing") or f.get("notes") or ""} for f in figs]),
                     hide_index=True, width="stretch")
