"""A plotly chart that updates in place: the live views' figure element.

``st.plotly_chart`` gives a figure a new identity whenever its data change,
so the browser unmounts the chart and draws it anew (``Plotly.newPlot``) on
every rerun. For a view that follows a slider that is most of the redraw
time. :func:`live_plotly_chart` instead renders the figure in a Streamlit
custom component with a fixed key: it stays mounted, and each rerun only
sends the new figure, which the browser applies with ``Plotly.react``.

The component's page (``live_chart_frontend/index.html``) loads plotly.js
from the installed ``plotly`` Python package: both are copied into a cache
folder on first use (no network, no bundled copy of plotly.js in lvcore).
"""
from __future__ import annotations

import functools
import hashlib
import os
import re
import shutil
import tempfile
from pathlib import Path

#: The component's page, shipped with the package.
FRONTEND_DIR = Path(__file__).resolve().parent / "live_chart_frontend"
#: Component name (Streamlit serves its files under /component/<name>/).
COMPONENT_NAME = "lvcore_live_plotly_chart"
#: The app's font, set on the live figures (the Streamlit theme does not reach into the component's frame).
FONT_FAMILY = "Source Sans Pro, Source Sans 3, sans-serif"

_component = None


def _plotly_js() -> Path:
    import plotly

    path = Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"
    if not path.is_file():
        raise FileNotFoundError(f"plotly.js not found at {path}: reinstall the 'plotly' package")
    return path


@functools.lru_cache(maxsize=None)
def _folder_name() -> str:
    """``lvcore-live-chart-<digest>`` of this (page, plotly.js) pair: computed once per process."""
    index = (FRONTEND_DIR / "index.html").read_bytes()
    js = _plotly_js().stat()
    return f"lvcore-live-chart-{hashlib.sha256(index + str(js.st_size).encode() + str(js.st_mtime_ns).encode()).hexdigest()[:16]}"


def frontend_dir(cache_root: Path | None = None) -> Path:
    """The folder Streamlit serves the component from: ``index.html`` and ``plotly.min.js``.

    Made once per (lvcore page, plotly.js) pair under ``cache_root`` (default
    the system's temporary folder), written atomically so concurrent servers
    never see a half-copied file.
    """
    target = Path(cache_root or tempfile.gettempdir()) / _folder_name()
    if (target / "index.html").is_file() and (target / "plotly.min.js").is_file():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=target.name + ".", dir=target.parent))
    try:
        (staging / "index.html").write_bytes((FRONTEND_DIR / "index.html").read_bytes())
        shutil.copyfile(_plotly_js(), staging / "plotly.min.js")
        try:
            os.replace(staging, target)
        except OSError:  # another process made it first
            if not (target / "plotly.min.js").is_file():
                raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


@functools.lru_cache(maxsize=None)
def _plain_template() -> dict:
    import plotly.io as pio

    return pio.templates["plotly_white"].to_plotly_json()


def _restyled(spec: dict) -> dict:
    """A figure's JSON for the component's frame, which has no Streamlit theme: the plain ``plotly_white``
    template, the app's font, and axes whose tick labels make room for themselves (``automargin``).

    Works on the JSON rather than on a copy of the figure: a second validated figure cost ~20 ms per chart
    on every rerun.
    """
    layout = spec.setdefault("layout", {})
    layout["template"] = _plain_template()
    layout["font"] = {**layout.get("font", {}), "family": FONT_FAMILY}
    axes = {k for k in layout if re.fullmatch(r"[xy]axis\d*", k)} | {"xaxis", "yaxis"}
    for k in axes:
        layout[k] = {**layout.get(k, {}), "automargin": True}
    return spec


def live_plotly_chart(fig, *, key: str, config: dict | None = None) -> None:
    """Draw ``fig`` (a plotly figure) so that later reruns update it in place.

    Parameters
    ----------
    fig : plotly.graph_objects.Figure
        The figure; its ``layout.height`` (px, default 420) sets the frame height.
    key : str
        Fixed Streamlit key: the identity that keeps the chart mounted across reruns.
    config : dict, optional
        plotly.js config (``displayModeBar``, ...).
    """
    import json

    import streamlit.components.v1 as components

    global _component
    served = frontend_dir()  # cheap when it exists; remade if a temp-folder cleaner removed it
    if _component is None:
        _component = components.declare_component(COMPONENT_NAME, path=str(served))
    spec = _restyled(json.loads(fig.to_json()))  # plotly's encoder: numpy arrays and NaN made JSON-safe
    _component(figure=spec, config=config or {}, key=key, default=None)
