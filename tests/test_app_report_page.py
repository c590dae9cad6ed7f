"""The Report page runs lvcore.report.build_report into a temp dir and offers the result as a zip (AppTest)."""
import json
from pathlib import Path

from streamlit.testing.v1 import AppTest

from lvcore.app import PAGES_DIR, PAGES

PAGE = str(PAGES_DIR / "7_Report.py")


def test_report_page_is_in_the_navigation():
    assert "Report" in [p.title for p in PAGES]


def test_report_page_builds_a_zip(monkeypatch):
    from lvcore import report
    from lvcore.report import export

    monkeypatch.setattr(export, "static_export_problem", lambda: None)  # kaleido + Chromium found
    calls = []

    def fake_build(out, results_dir=None, *, calibration=True, formats=("png", "svg"), progress=None, **kw):
        calls.append({"calibration": calibration, "formats": formats})
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        progress and progress("Fig 9.5 angle sweep")
        manifest = {"figures": [{"name": "fig9_5_angle_sweep", "title": "Fig 9.5", "png": None}]}
        (out / "manifest.json").write_text(json.dumps(manifest))
        return manifest

    monkeypatch.setattr(report, "build_report", fake_build)
    at = AppTest.from_file(PAGE, default_timeout=60).run()
    assert not at.exception, at.exception
    at.checkbox[0].uncheck().run()
    next(b for b in at.button if b.label == "Build report").click().run()
    assert not at.exception, at.exception
    assert calls == [{"calibration": False, "formats": ("png", "svg")}]
    zipped = at.session_state["report"].result["zip"]
    assert zipped[:2] == b"PK"
    assert at.get("download_button")
    assert any(c.value == "Computed with: live calibration no; figures PNG, SVG and HTML" for c in at.caption)
    at.checkbox[1].uncheck().run()  # static export off: the shown report is stale
    assert any("Inputs changed, re-run" in w.value for w in at.warning)


def _page_text(at) -> str:
    return "\n".join(str(getattr(e, "value", "")) + " " + str(getattr(e, "help", "") or "") + " "
                     + str(getattr(e, "label", "") or "")
                     for kind in ("caption", "warning", "error", "markdown", "checkbox", "text", "exception")
                     for e in getattr(at, kind))


def test_without_kaleido_static_export_is_not_offered_and_the_html_report_is_built(monkeypatch, tmp_path):
    """Issue 49: with `pip install -e .` alone (no kaleido) the box was ticked, the page showed plotly's raw
    RuntimeError ("Image export requires the Kaleido package...") and "static PNG/SVG True"."""
    import io
    import zipfile

    import plotly.io as pio

    from lvcore.report import export

    problem = 'kaleido is not installed (pip install "lvcore[report]")'
    monkeypatch.setattr(export, "static_export_problem", lambda: problem)

    def plotly_without_kaleido(*a, **k):  # what plotly raises when it is asked anyway
        raise RuntimeError("\nImage export requires the Kaleido package, v1.0.0 or greater,\nwhich can be installed "
                           'using pip:\n\n    $ pip install --upgrade "kaleido>=1"\n')

    monkeypatch.setattr(pio, "write_images", plotly_without_kaleido)
    from lvcore.report import build as rb

    monkeypatch.setattr(rb, "SECTIONS", tuple(s for s in rb.SECTIONS if s.study == "findings"))  # seconds, not minutes
    at = AppTest.from_file(PAGE, default_timeout=300).run()
    assert not at.exception, at.exception
    static = at.checkbox[1]
    assert static.value is False and static.disabled
    assert 'pip install "lvcore[report]"' in static.help and "chromium" in static.help
    at.checkbox[0].uncheck().run()
    next(b for b in at.button if b.label == "Build report").click().run()
    assert not at.exception, at.exception
    assert not at.error, [e.value for e in at.error]
    zipped = zipfile.ZipFile(io.BytesIO(at.session_state["report"].result["zip"]))
    manifest = json.loads(zipped.read("lvcore-report/manifest.json"))
    assert manifest["formats"] == [] and manifest["skipped_formats"] == []
    drawn = [f for f in manifest["figures"] if f["status"] == "ok"]
    assert drawn and all(f["html"] and f["png"] is None for f in drawn)
    assert all(f"lvcore-report/{f['html']}" in zipped.namelist() for f in drawn)
    text = _page_text(at)
    for raw in ("RuntimeError", "Image export requires", ". It needs", "Traceback"):
        assert raw not in text, raw
    computed = next(c.value for c in at.caption if c.value.startswith("Computed with:"))
    assert computed == "Computed with: live calibration no; figures HTML only"
    assert not any(w in computed.split() for w in ("True", "False", "None"))


def test_a_failed_static_export_is_said_in_words(monkeypatch):
    """kaleido found but the export fails anyway: the page names what is missing, never the raw exception."""
    from lvcore import report
    from lvcore.report import export

    monkeypatch.setattr(export, "static_export_problem", lambda: None)

    def fake_build(out, results_dir=None, *, formats=("png", "svg"), **kw):
        import plotly.graph_objects as go

        Path(out).mkdir(parents=True, exist_ok=True)
        monkeypatch.setattr(export, "static_export_problem",
                            lambda: "no Chromium found (install Debian's chromium: apt-get install chromium)")
        try:
            export.export_static([go.Figure()], [Path(out) / "x.png"])
        except export.StaticExportError as err:
            manifest = {"figures": [], "formats": list(formats), "skipped_formats": list(formats),
                        "static_export_error": str(err)}
        (Path(out) / "manifest.json").write_text(json.dumps(manifest))
        return manifest

    monkeypatch.setattr(report, "build_report", fake_build)
    at = AppTest.from_file(PAGE, default_timeout=60).run()
    at.checkbox[0].uncheck().run()
    next(b for b in at.button if b.label == "Build report").click().run()
    assert not at.exception, at.exception
    warning = next(w.value for w in at.warning if "figures" in w.value)
    assert warning.startswith("No PNG or SVG figures: static export (PNG/SVG) not possible: no Chromium found")
    assert "apt-get install chromium" in warning and ". ." not in warning and "Error" not in warning


def test_an_unexpected_error_is_said_in_the_apps_words(monkeypatch):
    from lvcore import report
    from lvcore.report import export

    monkeypatch.setattr(export, "static_export_problem", lambda: None)

    def broken_build(*a, **k):
        raise KeyError("internal detail")

    monkeypatch.setattr(report, "build_report", broken_build)
    at = AppTest.from_file(PAGE, default_timeout=60).run()
    at.checkbox[0].uncheck().run()
    next(b for b in at.button if b.label == "Build report").click().run()
    assert not at.exception, at.exception
    assert [e.value for e in at.error][0].startswith("Report failed: an unexpected error (KeyError)")
    assert "internal detail" not in _page_text(at)


def _figure_spec(html: str) -> dict:
    """The data and layout a plotly HTML file draws (the arguments of its Plotly.newPlot call)."""
    import re

    start = html.index("Plotly.newPlot(")
    m = re.compile(r'\s*"[^"]*",\s*').match(html, start + len("Plotly.newPlot("))
    dec = json.JSONDecoder()
    data, end = dec.raw_decode(html, m.end())
    end = re.compile(r"\s*,\s*").match(html, end).end()
    layout, _ = dec.raw_decode(html, end)
    return {"data": data, "layout": layout}


def test_the_apps_report_tables_are_the_clis(tmp_path):
    """Built in the app (Streamlit's plotly theme is the process default there) and by `lvcore report`: the same
    table figures, with plotly's own colours, not Streamlit's placeholder colours (#000038 ...)."""
    import io
    import os
    import subprocess
    import sys
    import zipfile

    cli_out = tmp_path / "cli"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    subprocess.run([sys.executable, "-m", "lvcore.cli", "report", "--out", str(cli_out), "--no-calibration",
                    "--formats", ""], check=True, env=env, capture_output=True, timeout=600)
    at = AppTest.from_file(PAGE, default_timeout=600).run()
    at.checkbox[0].uncheck().run()  # no live calibration
    at.checkbox[1].uncheck().run()  # HTML only: the table specs are compared, not PNG pixels
    next(b for b in at.button if b.label == "Build report").click().run()
    assert not at.exception, at.exception
    zipped = zipfile.ZipFile(io.BytesIO(at.session_state["report"].result["zip"]))
    app_manifest = json.loads(zipped.read("lvcore-report/manifest.json"))
    cli_manifest = json.loads((cli_out / "manifest.json").read_text())
    assert [f["name"] for f in app_manifest["figures"]] == [f["name"] for f in cli_manifest["figures"]]
    tables = [f for f in cli_manifest["figures"] if f["name"].startswith("table") and f["status"] == "ok"]
    assert len(tables) >= 4
    for f in tables:
        app = _figure_spec(zipped.read(f"lvcore-report/{f['html']}").decode())
        cli = _figure_spec((cli_out / f["html"]).read_text())
        assert "#000038" not in json.dumps(app) and "#000037" not in json.dumps(app), f["name"]
        assert app == cli, f["name"]


def test_the_calibration_checkbox_names_the_subject_and_time_the_report_runs():
    """It said HV1 and ~10-40 s while the report calibrated HV3; both now come from the study module."""
    import inspect

    from lvcore.studies import volunteer_calibration as vc

    at = AppTest.from_file(PAGE, default_timeout=60).run()
    label = at.checkbox[0].label
    assert vc.DEFAULT_SUBJECT in label and f"{vc.TYPICAL_SECONDS[0]}–{vc.TYPICAL_SECONDS[1]} s" in label
    assert inspect.signature(vc.compute).parameters["subject"].default == vc.DEFAULT_SUBJECT
