"""lvcore.app.live_chart: the component folder Streamlit serves (the page plus the installed plotly.js)."""
from __future__ import annotations

import threading
from pathlib import Path

import plotly

from lvcore.app import live_chart


def test_frontend_dir_holds_the_page_and_the_installed_plotly_js(tmp_path):
    d = live_chart.frontend_dir(tmp_path)
    page = (d / "index.html").read_text()
    assert '<script src="plotly.min.js">' in page and "Plotly.react" in page and "streamlit:componentReady" in page
    js = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"
    assert (d / "plotly.min.js").read_bytes() == js.read_bytes()
    assert live_chart.frontend_dir(tmp_path) == d  # made once, then reused
    assert [p.name for p in tmp_path.iterdir()] == [d.name]  # no staging folder left behind


def test_frontend_dir_is_safe_for_concurrent_servers(tmp_path):
    out, errors = [], []

    def make():
        try:
            out.append(live_chart.frontend_dir(tmp_path))
        except Exception as err:  # noqa: BLE001 - collected for the assertion
            errors.append(err)

    threads = [threading.Thread(target=make) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(set(out)) == 1
    assert sorted(p.name for p in out[0].iterdir()) == ["index.html", "plotly.min.js"]
    assert [p.name for p in tmp_path.iterdir()] == [out[0].name]
