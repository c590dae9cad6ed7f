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
