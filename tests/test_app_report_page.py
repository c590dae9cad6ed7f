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
    at.checkbox[1].uncheck().run()  # static export off: the shown report is stale
    assert any("Inputs changed, re-run" in w.value for w in at.warning)


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
