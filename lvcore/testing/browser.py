"""Drive the Streamlit app in a real Chromium: start the server, visit pages, move sliders, time redraws.

Shared by ``tests/test_browser.py`` (CI) and ``benchmarks/bench_app_browser.py``
(BENCHMARKS.md timings). It uses the ``playwright`` PyPI package with Debian's
Chromium (``/usr/bin/chromium``, ``apt-get install chromium``); it never
downloads a browser (no ``playwright install``).

Streamlit content arrives over a websocket after the page loads, so "rendered"
means: the app reports its script as not running (``data-test-script-state``
on the ``stApp`` element) and no skeleton placeholders are left.
"""
from __future__ import annotations

import contextlib
import os
import re
import socket
import subprocess
import sys
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from lvcore.execution.parallel import pin_threads

#: Debian's Chromium (the only browser used; never ``playwright install``).
CHROMIUM = "/usr/bin/chromium"
#: Flags for a headless Chromium in a container without a GPU or network.
LAUNCH_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
               "--disable-component-update", "--disable-sync"]
#: A slider's focusable thumb (Streamlit >= 1.50 renders an <input type=range> inside ``stSlider``).
SLIDER = "[data-testid=stSlider] input[type=range], [role=slider]"
#: Elements Streamlit shows for an uncaught exception in a page.
EXCEPTION = "[data-testid=stException], .stException"
_IDLE_JS = ("() => { const a = document.querySelector('[data-testid=stApp]');"
            " return !!a && a.getAttribute('data-test-script-state') === 'notRunning'"
            " && !document.querySelector('[data-testid=stSkeleton]'); }")
_RUNNING_JS = ("() => { const a = document.querySelector('[data-testid=stApp]');"
               " return !!a && a.getAttribute('data-test-script-state') !== 'notRunning'; }")
#: The data of every plotly chart in the main area (and in its live-chart iframes), as one string (changes when a figure is redrawn with new data).
_EACH_PLOT_JS = ("() => Array.from(document.querySelectorAll('[data-testid=stMain] .js-plotly-plot')).concat("
                 " ...Array.from(document.querySelectorAll('[data-testid=stMain] iframe')).map(f => {"
                 "   try { return Array.from(f.contentDocument.querySelectorAll('.js-plotly-plot')); }"
                 "   catch (e) { return []; } }))"  # live charts (lvcore.app.live_chart) draw in a same-origin iframe
                 ".map(g => JSON.stringify((g.data || []).map(d => [d.x, d.y, d.z])))")
_PLOTS_JS = f"() => ({_EACH_PLOT_JS})().join('|')"


def repo_root() -> Path:
    """The repository root (where ``app.py`` is)."""
    return Path(__file__).resolve().parents[2]


def free_port() -> int:
    with contextlib.closing(socket.socket(socket.AF_INET, socket.SOCK_STREAM)) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class StreamlitServer:
    """``streamlit run app.py`` on 127.0.0.1 in a subprocess (a context manager).

    Attributes
    ----------
    app : path of the entry script (default ``<repo>/app.py``)
    port : int (default: a free port)
    log : path of the server's combined stdout/stderr
    """

    app: Path | None = None
    port: int | None = None
    log: Path | None = None
    startup_timeout_s: float = 180.0

    def __post_init__(self):
        self.app = Path(self.app) if self.app else repo_root() / "app.py"
        self.port = self.port or free_port()
        self.log = Path(self.log) if self.log else repo_root() / "build" / f"streamlit_{self.port}.log"
        self._proc = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def __enter__(self) -> "StreamlitServer":
        self.log.parent.mkdir(parents=True, exist_ok=True)
        env = pin_threads(dict(os.environ))
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(repo_root()), env.get("PYTHONPATH", "")]))
        cmd = [sys.executable, "-m", "streamlit", "run", str(self.app), "--server.headless", "true",
               "--server.address", "127.0.0.1", "--server.port", str(self.port),
               "--browser.gatherUsageStats", "false", "--server.fileWatcherType", "none"]
        self._logf = open(self.log, "w")
        self._proc = subprocess.Popen(cmd, cwd=str(self.app.parent), env=env, stdout=self._logf,
                                      stderr=subprocess.STDOUT)
        deadline = time.monotonic() + self.startup_timeout_s
        while time.monotonic() < deadline:
            if self._proc.poll() is not None:
                self.__exit__(None, None, None)
                raise RuntimeError(f"streamlit exited with {self._proc.returncode}; see {self.log}:\n"
                                   + self.log.read_text()[-2000:])
            try:
                with urllib.request.urlopen(f"{self.url}/_stcore/health", timeout=2) as r:
                    if r.status == 200:
                        return self
            except OSError:
                time.sleep(0.5)
        self.__exit__(None, None, None)
        raise TimeoutError(f"streamlit did not answer on {self.url} within {self.startup_timeout_s:.0f} s; see {self.log}")

    def __exit__(self, *exc) -> None:
        if self._proc is not None and self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait(timeout=5)
        if getattr(self, "_logf", None):
            self._logf.close()

    def log_text(self) -> str:
        return self.log.read_text() if self.log.is_file() else ""


def launch(playwright):
    """Debian's Chromium through playwright (headless)."""
    return playwright.chromium.launch(executable_path=CHROMIUM, args=LAUNCH_ARGS, headless=True)


def wait_idle(page, timeout_s: float = 180.0, settle_s: float = 0.25) -> None:
    """Wait until the script has finished and every element is drawn (still idle ``settle_s`` later)."""
    deadline = time.monotonic() + timeout_s
    while True:
        page.wait_for_function(_IDLE_JS, timeout=max(1.0, deadline - time.monotonic()) * 1000, polling=50)
        time.sleep(settle_s)
        if page.evaluate(_IDLE_JS) or time.monotonic() > deadline:
            return


def wait_rerun(page, timeout_s: float = 180.0) -> None:
    """After an input: wait for the rerun it triggers to start (if it is not already over) and to finish."""
    with contextlib.suppress(Exception):
        page.wait_for_function(_RUNNING_JS, timeout=1500, polling=20)
    wait_idle(page, timeout_s)


def page_links(page) -> list[tuple[str, str]]:
    """(label, absolute URL) of every page link in the sidebar navigation (``pages/`` or ``st.navigation``)."""
    links = page.locator("[data-testid=stSidebarNav] a, [data-testid=stSidebarNavLink]")
    out = []
    for i in range(links.count()):
        a = links.nth(i)
        href = a.get_attribute("href")
        label = a.evaluate("e => { const c = e.cloneNode(true);"  # without the icon's ligature text
                           " c.querySelectorAll('[data-testid=stIconMaterial]').forEach(x => x.remove());"
                           " return c.innerText.trim(); }")
        if href and (label, href) not in out:
            out.append((label, href))
    return out


def slug(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", label).strip("_").lower() or "home"


def exceptions(page) -> list[str]:
    """Texts of the exception boxes on the page."""
    return [t.strip()[:500] for t in page.locator(EXCEPTION).all_inner_texts()]


def slider_value(slider) -> str:
    return slider.get_attribute("aria-valuetext") or slider.input_value()


def move_slider(page, slider=None, key: str = "ArrowRight") -> tuple[str, str, str]:
    """Focus a slider thumb (default: the first one) and press ``key``; returns (label, before, after)."""
    slider = slider if slider is not None else page.locator(SLIDER).first
    slider.focus()
    before = slider_value(slider)
    page.keyboard.press(key)
    wait_rerun(page)
    return slider.get_attribute("aria-label") or "", before, slider_value(slider)


def plots_signature(page) -> str:
    return page.evaluate(_PLOTS_JS)


def plot_count(page) -> int:
    """Plotly charts drawn in the main area, live charts in their frames included."""
    return len(page.evaluate(_EACH_PLOT_JS))


def open_live_map(page) -> None:
    """On the Fibre angles page: show the (α_endo, α_epi) map computed by the emulator, where the page has them."""
    tab = page.get_by_role("tab", name=re.compile("map", re.I))
    if tab.count():
        tab.first.click()
        wait_rerun(page)
    # the engine radio in the main area (the shared sidebar also has an "Emulator" selectbox label)
    live = page.locator("[data-testid=stMain] [data-testid=stRadio] label").filter(has_text=re.compile("emulator", re.I))
    if live.count():
        live.first.click()
        wait_rerun(page)


def redraw_times(page, slider, n: int = 5, timeout_s: float = 30.0, every_plot: bool = False) -> list[float]:
    """Seconds from a slider key press to the change of the main area's plot data, ``n`` times.

    By default the clock stops at the first plot whose data change; with
    ``every_plot`` only when every plot shown has new data (for a slider that
    all of them follow). Alternates ArrowRight and ArrowLeft so the value
    stays near its default; waits for the page to be idle between presses.
    """
    times = []
    for k in range(n):
        wait_idle(page)
        before = page.evaluate(_EACH_PLOT_JS)
        slider.focus()
        t0 = time.perf_counter()
        page.keyboard.press("ArrowRight" if k % 2 == 0 else "ArrowLeft")
        page.wait_for_function(f"([b, every]) => {{ const now = ({_EACH_PLOT_JS})();"
                               " if (now.length !== b.length) return now.length > 0;"
                               " const changed = now.map((s, i) => s !== b[i]);"
                               " return every ? changed.every(Boolean) : changed.some(Boolean); }",
                               arg=[before, every_plot], timeout=timeout_s * 1000, polling=10)
        times.append(time.perf_counter() - t0)
    wait_idle(page)
    return times


def shrink_png(src, dst, width: int = 900, max_bytes: int = 200_000) -> Path:
    """A small copy of a screenshot for docs/: top part (at most 1.4 × width tall), resized, palette PNG."""
    from PIL import Image

    dst = Path(dst)
    dst.parent.mkdir(parents=True, exist_ok=True)
    with Image.open(src) as im:
        im = im.convert("RGB")
        scale = width / im.width
        im = im.resize((width, int(im.height * scale)), Image.LANCZOS)
        im = im.crop((0, 0, width, min(im.height, int(1.4 * width))))
        colours = 256
        while True:
            im.quantize(colours).save(dst, optimize=True)
            if dst.stat().st_size <= max_bytes or colours <= 16:
                break
            colours //= 2
    return dst


__all__ = ["CHROMIUM", "LAUNCH_ARGS", "SLIDER", "EXCEPTION", "StreamlitServer", "launch", "wait_idle", "wait_rerun",
           "page_links", "slug", "exceptions", "move_slider", "slider_value", "plots_signature", "plot_count", "open_live_map",
           "redraw_times", "shrink_png", "free_port", "repo_root"]
