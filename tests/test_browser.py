"""The app in a real browser: Debian's Chromium via the playwright PyPI package (never `playwright install`).

Starts ``streamlit run app.py`` on 127.0.0.1, visits every page linked in the
sidebar, moves one slider on each (keyboard on the slider thumb), and checks
that no exception box appears; screenshots go to build/screenshots/ (CI
artifacts). On the Fibre angles page the live map must redraw after a slider move
within REDRAW_LIMIT_S (median of 5): a catch for a hang or a recompute of the
whole page per frame, not a speed target (the suite runs on two processes, so
the server shares the cores with another test file); the interactive target
(300 ms, under 1 s) is measured in BENCHMARKS.md by ``benchmarks/bench_app_browser.py``. Finally 5
browser sessions work the app at the same time for a bounded loop. Every visible plot, table and image of every
page is screenshotted alone at a 1400-px viewport (build/screenshots/figures/) and must have a non-zero box inside
the viewport's width.

In CI (env ``CI`` set) a missing Chromium or playwright is a failure, not a skip.
"""
from __future__ import annotations

import os
import re
import statistics
import time
from pathlib import Path

import pytest

from lvcore.testing import browser as drv

pytestmark = [pytest.mark.slow, pytest.mark.timeout(1200)]

ROOT = Path(__file__).resolve().parents[1]
SHOTS = ROOT / "build" / "screenshots"
#: Seconds: a broken live map never redraws, and one that recomputes the page per frame takes several seconds even
#: on a quiet machine; 3 s leaves room for a second test process on CI's other core.
REDRAW_LIMIT_S = 3.0
N_SESSIONS, N_ROUNDS = 5, 3


def _require_browser():
    problems = []
    if not Path(drv.CHROMIUM).is_file():
        problems.append(f"{drv.CHROMIUM} is missing (apt-get install chromium)")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        problems.append("the playwright package is missing (pip install -e '.[test]')")
    if problems:
        msg = "; ".join(problems)
        if os.environ.get("CI"):
            pytest.fail(f"browser test cannot run in CI: {msg}")
        pytest.skip(f"browser test skipped outside CI: {msg}")


#: Posterior draws of the EDPVR button in the module's server (``LVCORE_EDPVR_DRAWS``): the 100-draw default (a 90 %
#: band worth reading); the calibration is a bundled volunteer's, so the EDPVR emulator gives it (no FE solves).
EDPVR_TEST_DRAWS = "100"


@pytest.fixture(scope="module")
def app():
    _require_browser()
    from lvcore.app.physiology_panel import DRAWS_ENV

    before = os.environ.get(DRAWS_ENV)
    os.environ[DRAWS_ENV] = EDPVR_TEST_DRAWS   # the server inherits it
    try:
        with drv.StreamlitServer(app=ROOT / "app.py", log=ROOT / "build" / "streamlit_browser_test.log") as server:
            yield server
    finally:
        if before is None:
            os.environ.pop(DRAWS_ENV, None)
        else:
            os.environ[DRAWS_ENV] = before


@pytest.fixture(scope="module")
def chromium(app):
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = drv.launch(p)
        yield b
        b.close()


def _new_page(chromium, errors: list):
    ctx = chromium.new_context(viewport={"width": 1400, "height": 1000})
    page = ctx.new_page()
    page.set_default_timeout(180_000)
    page.on("pageerror", lambda e: errors.append(str(e)))
    return ctx, page


#: The elements screenshotted one by one: plots (Plotly, live charts), tables and dataframes, images.
FIGURE_SELECTORS = {"plot": '[data-testid="stPlotlyChart"], [data-testid="stCustomComponentV1"]',
                    "dataframe": '[data-testid="stDataFrame"]', "table": '[data-testid="stTable"]',
                    "image": '[data-testid="stImage"], [data-testid="stFullScreenFrame"] img'}
VIEWPORT_WIDTH = 1400


#: Selector of the tabs of the main area.
TAB = "[data-testid=stMain] [data-baseweb=tab], [data-testid=stMain] [role=tab]"


def _shoot_visible(page, name: str, out: Path, shot: list, problems: list) -> None:
    """Screenshot every visible plot, table and image not yet taken on this page state (marked in the DOM), and
    check that each has a non-zero box inside the viewport's width."""
    for kind, selector in FIGURE_SELECTORS.items():
        items = page.locator(selector)
        for i in range(items.count()):
            item = items.nth(i)
            if not item.is_visible() or item.get_attribute("data-lv-shot"):  # in a tab not shown, or done
                continue
            item.scroll_into_view_if_needed()
            box = item.bounding_box()
            label = f"{name}_{kind}_{len(shot) + len(problems) + 1}"
            item.evaluate("e => e.setAttribute('data-lv-shot', '1')")
            if box is None or box["width"] <= 0 or box["height"] <= 0:
                problems.append(f"{label}: empty box {box}")
                continue
            if box["x"] < -0.5 or box["x"] + box["width"] > VIEWPORT_WIDTH + 0.5:
                problems.append(f"{label}: spans x = {box['x']:.0f}..{box['x'] + box['width']:.0f} px, beyond the "
                                f"{VIEWPORT_WIDTH}-px viewport")
            item.screenshot(path=str(out / f"{label}.png"))
            shot.append((label, round(box["width"]), round(box["height"])))


def _check_figures(page, name: str, out: Path, shot: list, problems: list) -> int:
    """:func:`_shoot_visible` on the page as shown, then on every visible tab, clicked one by one (a tab nested in
    a panel is clicked when its panel is the one shown); the number of tabs clicked."""
    _shoot_visible(page, name, out, shot, problems)
    clicked = 0
    tabs = page.locator(TAB)
    for t in range(tabs.count()):
        tab = tabs.nth(t)
        if not tab.is_visible():  # a nested tab in a panel not shown: reached when its parent tab is clicked
            continue
        tab.click()
        clicked += 1
        page.wait_for_timeout(400)  # a tab switch is drawn in the browser (no rerun); let Plotly resize
        _shoot_visible(page, f"{name}_tab{t + 1}", out, shot, problems)
    wide = page.evaluate("document.documentElement.scrollWidth")  # no sideways scrolling of the page
    if wide > VIEWPORT_WIDTH + 1:
        problems.append(f"page '{name}' is {wide} px wide at a {VIEWPORT_WIDTH}-px viewport")
    return clicked


def _run_small_calibration(page, chains: int = 1, warmup: int = 100, draws: int = 100) -> None:
    """Set the page's sampler to a small run, press "Run calibration" and wait for the results."""
    _number_input(page, "chains", chains)
    _number_input(page, "warm-up", warmup)
    _number_input(page, "draws kept", draws)
    page.get_by_role("button", name="Run calibration").click()
    drv.wait_rerun(page, timeout_s=600)


def _move_a_slider(page, label: str) -> tuple:
    """Move the page's first slider by keyboard (on its thumb): (slider, before, after); no exception after."""
    if not page.locator(drv.SLIDER).count():
        return "(no slider on this page)", "", ""
    name, before, after = drv.move_slider(page)
    assert after != before, f"page '{label}': slider '{name}' did not move ({before})"
    errs = drv.exceptions(page)
    assert not errs, f"page '{label}' shows an exception after moving '{name}' {before} -> {after}: {errs}"
    return name, before, after


def _url_path_checks(page, app, path: str, expected, where: str) -> None:
    """A page typed at its URL path: no "Page not found", no redirect, no exception or error box, the sidebar
    marks it (the hidden /simulator alias marks none), and it has a title."""
    body = page.locator("body").inner_text()
    assert "Page not found" not in body, f"{where}: {body[body.index('Page not found'):][:200]!r}"
    assert page.url.rstrip("/") == f"{app.url}/{path}".rstrip("/"), f"{where}: went to {page.url}"
    _no_error_box(page, where)
    current = page.locator("[data-testid=stSidebarNav] a[aria-current=page], [data-testid=stSidebarNavLink]"
                           "[aria-current=page]")
    if current.count():
        assert expected.title in current.first.inner_text(), f"{where}: sidebar shows {current.first.inner_text()}"
    assert page.locator("h1").count() >= 1, f"{where}: no title"


def test_every_page_its_figures_a_slider_a_calibration_and_its_edpvr(app, chromium):
    """Every page typed at its URL path (the home page at /simulator and at /), each in a fresh browser context
    (a new session), at a 1400-px-wide viewport. The first visit of all goes to the fresh server at /simulator:
    Streamlit used to run that first session inside the page list of the ``pages/`` folder beside app.py, which
    knew none of the app's URL paths. On each page (:func:`_url_path_checks` on all, the rest from / on):
    - its own title, no "Page not found", no redirect, no exception and no error box, the sidebar marks it;
    - every plot, table and image, on every tab, screenshotted alone (build/screenshots/figures/): each has a
      non-zero box and ends inside the viewport's width;
    - one slider moved by keyboard: the value changes and no exception follows (a full-page screenshot after);
    - no request of any page leaves localhost; the sidebar links only to these URL paths;
    then a small calibration on the Calibration page: its result figures (one tab per likelihood) fit too, and the
    EDPVR button (:data:`EDPVR_TEST_DRAWS` posterior draws) draws the derived EDPVR with the measured point inside
    its band, V₀ and Klotz's curve, the identified combination, and no error or exception box.
    (One walk: it used to be two, one typing each URL path and one following the sidebar, each loading every page.)"""
    import shutil
    from urllib.parse import urlparse

    from lvcore.app import PAGES

    out = SHOTS / "figures"
    shutil.rmtree(out, ignore_errors=True)  # only this run's pictures
    out.mkdir(parents=True, exist_ok=True)
    js_errors: list = []
    hosts: set = set()
    shot, problems, tabs, moved, links = [], [], 0, [], None
    home, *others = PAGES
    visits = [(home.url_path, home), ("", home)] + [(p.url_path, p) for p in others]
    for path, expected in visits:
        ctx, page = _new_page(chromium, js_errors)
        ctx.on("request", lambda req: hosts.add(urlparse(req.url).hostname or urlparse(req.url).scheme))
        assert page.viewport_size["width"] == VIEWPORT_WIDTH
        page.goto(f"{app.url}/{path}")
        drv.wait_idle(page, timeout_s=600)  # a first visit compiles the page's imports (minutes on a loaded machine)
        label = expected.title
        _url_path_checks(page, app, path, expected, f"/{path} ({label})")
        if path == home.url_path:  # the alias, the fresh server's first visit: the rest is done at /
            ctx.close()
            continue
        if links is None:
            links = drv.page_links(page)
            assert len(links) >= 5, f"expected the app's pages in the sidebar, found {links}"
            paths = {p for p, _ in visits}
            assert all(urlparse(h).path.strip("/") in paths for _, h in links), (links, sorted(paths))
        tabs += _check_figures(page, drv.slug(label), out, shot, problems)
        moved.append((label, *_move_a_slider(page, label)))
        page.screenshot(path=str(SHOTS / f"{drv.slug(label)}.png"), full_page=True)
        ctx.close()
    print("\n".join(f"{lab}: moved '{n}' {b} -> {a}" for lab, n, b, a in moved))
    assert any(b for _, _, b, _ in moved), f"no page had a slider to move: {moved}"
    ctx, page = _new_page(chromium, js_errors)
    ctx.on("request", lambda req: hosts.add(urlparse(req.url).hostname or urlparse(req.url).scheme))
    # figures that appear only after a calibration: the Calibration page's results, one tab per likelihood
    page.goto(dict(links)["Calibration"])
    drv.wait_idle(page)
    # the page's smallest run (1 chain: no R-hat here), as the My subject test's: the same sampler settings
    for label, value in (("chains", 1), ("warm-up", 50), ("draws kept", 50)):
        _number_input(page, label, value)
        assert page.get_by_label(label, exact=True).input_value() == str(value), label
    page.get_by_role("button", name="Run calibration").click()  # runs in the background; a 1 s timer polls it
    try:
        page.get_by_text(re.compile("^Results for")).first.wait_for(timeout=900_000)
        drv.wait_idle(page)
    finally:
        page.screenshot(path=str(SHOTS / "calibration_results.png"), full_page=True)
    assert not drv.exceptions(page), drv.exceptions(page)
    before = len(shot)
    result_tabs = _check_figures(page, "calibration_results", out, shot, problems)
    print("\n".join(f"{n}: {w} x {h} px" for n, w, h in shot))
    assert result_tabs >= 2, "the calibration results show no per-likelihood tabs"
    assert len(shot) - before >= 6, f"too few result figures: {shot[before:]}"  # predictive, per tab: table, 4 plots
    assert tabs >= 5, f"only {tabs} tabs clicked on the pages"
    assert len(shot) >= 10, f"too few figures and tables found: {shot}"
    assert {n.split("_")[-2] for n, _, _ in shot} >= {"plot", "dataframe", "image"}, shot
    assert not problems, problems
    # the derived EDPVR of that calibration
    button = page.get_by_role("button", name=re.compile("Compute the EDPVR"))
    button.wait_for(timeout=300_000)
    assert f"EDPVR emulator, {EDPVR_TEST_DRAWS} posterior draws" in button.inner_text()
    t_edpvr = time.perf_counter()
    button.click()
    page.get_by_text("The measured point lies inside the band", exact=False).wait_for(timeout=300_000)
    print(f"EDPVR, {EDPVR_TEST_DRAWS} draws: click to the band {time.perf_counter() - t_edpvr:.1f} s")
    drv.wait_idle(page)
    page.get_by_text("Physiology: EDV/V₀", exact=False).scroll_into_view_if_needed()
    page.screenshot(path=str(SHOTS / "calibration_edpvr_top.png"))
    page.get_by_text("Contraction", exact=False).first.scroll_into_view_if_needed()
    page.screenshot(path=str(SHOTS / "calibration_edpvr_bottom.png"))
    figure = page.locator("[data-testid=stPlotlyChart]").last
    figure.scroll_into_view_if_needed()
    figure.screenshot(path=str(SHOTS / "calibration_edpvr_figure.png"))
    assert "V₀ =" in figure.inner_text() and "Klotz" in figure.inner_text()
    _no_error_box(page, "Calibration: EDPVR")
    assert page.get_by_text("Identified combination", exact=False).count() >= 1
    assert not js_errors, f"JavaScript errors in the page: {js_errors[:3]}"
    assert "Traceback" not in app.log_text(), app.log_text()[-3000:]
    outside = {h for h in hosts if h not in LOCAL_HOSTS}
    assert not outside, f"requests left localhost: {sorted(outside)}"
    ctx.close()


def _fibre_angles_url(page, app) -> str:
    page.goto(app.url)
    drv.wait_idle(page)
    hrefs = [h for lab, h in drv.page_links(page) if re.search(r"fibre\s*angles", lab, re.I)]
    assert hrefs, "no 'Fibre angles' page in the sidebar"
    return hrefs[0]


def test_fibre_angle_map_redraws_after_a_slider_move(app, chromium):
    js_errors: list = []
    ctx, page = _new_page(chromium, js_errors)
    page.goto(_fibre_angles_url(page, app))
    drv.wait_idle(page)
    drv.open_live_map(page)
    assert drv.plot_count(page) >= 2, "the live fibre-angle map and strain chart are not shown"
    slider = page.locator(f"[data-testid=stSidebar] :is({drv.SLIDER})").first
    times = drv.redraw_times(page, slider, n=5, every_plot=True)  # θ moves both live charts
    page.screenshot(path=str(SHOTS / "fibre_angles_live_map.png"), full_page=True)
    assert not drv.exceptions(page)
    med = statistics.median(times)
    print(f"slider-to-redraw on Fibre angles: median {med:.3f} s, all {[round(t, 3) for t in times]}")
    assert med <= REDRAW_LIMIT_S, f"live map redraw took {med:.2f} s (median of {times}); limit {REDRAW_LIMIT_S} s"
    ctx.close()


def test_five_concurrent_sessions(app, chromium):
    js_errors: list = []
    sessions = [_new_page(chromium, js_errors) for _ in range(N_SESSIONS)]
    url = _fibre_angles_url(sessions[0][1], app)
    for _, page in sessions:
        page.goto(url)
    for _, page in sessions:
        drv.wait_idle(page)
    for r in range(N_ROUNDS):
        for _, page in sessions:  # every session's rerun starts before any is awaited
            page.locator(drv.SLIDER).first.focus()
            page.keyboard.press("ArrowRight" if r % 2 == 0 else "ArrowLeft")
        for k, (_, page) in enumerate(sessions):
            drv.wait_rerun(page)
            errs = drv.exceptions(page)
            assert not errs, f"session {k}, round {r}: {errs}"
    assert not js_errors, f"JavaScript errors: {js_errors[:3]}"
    sessions[-1][1].screenshot(path=str(SHOTS / "concurrent_session.png"))
    for ctx, _ in sessions:
        ctx.close()


def _number_input(page, label: str, value: int) -> None:
    box = page.get_by_label(label, exact=True)
    box.fill(str(value))
    box.press("Enter")
    drv.wait_rerun(page)


#: Hosts (and URL schemes) a page of the app may request: nothing leaves the machine.
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1", "data", "blob", "about")


def _no_error_box(page, where: str) -> None:
    """Neither an exception nor an error box (st.error) on the page."""
    assert not drv.exceptions(page), f"{where}: {drv.exceptions(page)}"
    errors = page.locator("[data-testid=stAlertContentError]").all_inner_texts()
    assert not errors, f"{where}: error box {errors}"


def test_my_subject_both_routes_end_to_end_without_an_error_box(chromium, tmp_path, monkeypatch):
    """The My subject flow in a real browser, as short as the page allows (1 chain, 50 + 50 draws), on the packaged
    entry (``lvcore app``): typed at its own URL (/my-subject), no shared inputs in its sidebar, the greyed-out
    "Run calibration" says why; the mesh route (upload a bundled SYNTHETIC volume mesh and its measurements: the
    fitted geometry's volumes shown; calibrate, the EDPVR and derived quantities, download the zip: settings,
    summary, the posterior (.nc) and figures) and the "No mesh: infer" route (``lvcore calibrate --geometry
    infer``: measurements, the warning while no measure is given, then the reference volume; the posterior of the PC
    scores, the scale and the implied reference cavity on the page and in the zip). Every result figure and table
    fits at 1400 px; no request leaves localhost; it fails on any exception at every step and on any error box but
    the EDPVR's own CONSISTENCY verdict."""
    import json
    import zipfile
    from urllib.parse import urlparse

    from lvcore.app import ENTRY
    from lvcore.app import subject_flow as flow
    from lvcore.inference import guards
    from lvcore.resources import volunteer_files

    _require_browser()
    monkeypatch.setenv("LVCORE_EDPVR_DRAWS", "4")   # the server inherits it: 4 FE draws keep the EDPVR step short
    SHOTS.mkdir(parents=True, exist_ok=True)
    files = volunteer_files("SYNTHETIC_HV3")
    ref = round(flow.geometry_measures(guards.resolve_geometry(files.geometry, n_pc=5))[0]["cavity_volume_ml"])
    with drv.StreamlitServer(app=ENTRY, log=ROOT / "build" / "streamlit_browser_my_subject.log") as server:
        # the module's browser: a second sync_playwright() in this thread while the chromium fixture's is running
        # fails ("Sync API inside the asyncio loop")
        browser = chromium
        js_errors: list = []
        hosts: set = set()
        (SHOTS / "figures").mkdir(parents=True, exist_ok=True)
        for route in ("mesh", "infer"):
            ctx, page = _new_page(browser, js_errors)   # a fresh context per route: the first one is closed below
            ctx.on("request", lambda req: hosts.add(urlparse(req.url).hostname or urlparse(req.url).scheme))
            page.goto(f"{server.url}/my-subject")  # its own URL path (a new session each time)
            drv.wait_idle(page)
            assert page.get_by_text("Page not found").count() == 0
            assert page.locator("h1").first.inner_text() == "My subject"
            assert page.locator("[data-testid=stSidebar]").get_by_text("Shared inputs").count() == 0
            button = page.get_by_role("button", name="Run calibration")
            assert button.is_disabled() and page.get_by_text("Disabled: no measurements yet").count() == 1
            if route == "infer":
                page.get_by_text("No mesh: infer it from CMR measures", exact=True).click()
                drv.wait_rerun(page)
            uploads = page.locator("[data-testid=stFileUploader] input[type=file]")
            if route == "mesh":
                uploads.nth(0).set_input_files(str(files.geometry))
                drv.wait_rerun(page)
                _no_error_box(page, "mesh uploaded")
                assert page.get_by_text("cavity", exact=False).count() >= 1, "the fitted geometry's volumes not shown"
                uploads.nth(1).set_input_files(str(files.measured))
            else:
                assert uploads.count() == 1, "the no-mesh route still asks for a geometry file"
                uploads.nth(0).set_input_files(str(files.measured))
                drv.wait_rerun(page)
                assert page.get_by_text("no geometric measure given", exact=False).count() >= 1, "no warning"
                _number_input(page, "Reference (early-diastolic) cavity volume, mL (optional, 0 = not measured)",
                              ref)
                assert page.get_by_text("no geometric measure given", exact=False).count() == 0
            drv.wait_rerun(page)
            _no_error_box(page, f"{route}: inputs given")
            assert page.get_by_text("Conditions used:", exact=False).count() == 1
            for label, value in (("chains", 1), ("warm-up", 50), ("draws kept", 50)):
                _number_input(page, label, value)
            assert button.is_enabled() and page.get_by_text("Disabled:", exact=False).count() == 0
            button.click()
            download = page.get_by_role("button", name=re.compile("Download everything"))
            download.wait_for(timeout=600_000)
            drv.wait_idle(page)
            page.set_viewport_size({"width": 1400, "height": 4200})  # the main area scrolls inside: a tall window
            page.wait_for_timeout(800)
            page.screenshot(path=str(SHOTS / f"my_subject_{route}_done.png"))
            page.set_viewport_size({"width": 1400, "height": 1000})
            _no_error_box(page, f"{route}: results")
            text = page.locator("[data-testid=stMain]").inner_text()
            assert "None" not in text and "exit code" not in text, route
            assert page.get_by_text("90 % equal-tailed interval", exact=False).count() >= 1 or route == "mesh"
            assert route == "mesh" or page.get_by_text("Inferred geometry", exact=False).count() >= 1
            shot, problems = [], []   # the results' figures and tables at 1400 px, as every page's
            _check_figures(page, f"my_subject_{route}_results", SHOTS / "figures", shot, problems)
            assert len(shot) >= 4 and not problems, (route, shot, problems)
            edpvr = page.get_by_role("button", name=re.compile("Compute the EDPVR"))
            edpvr.wait_for(timeout=60_000)
            assert "4 posterior draws" in edpvr.inner_text()
            edpvr.click()
            done = page.get_by_text(re.compile("The measured point lies inside the band|CONSISTENCY: the EDPVR"))
            done.first.wait_for(timeout=600_000)
            drv.wait_idle(page)
            assert not drv.exceptions(page), f"{route}: EDPVR: {drv.exceptions(page)}"
            errors = [e for e in page.locator("[data-testid=stAlertContentError]").all_inner_texts()
                      if not e.startswith("CONSISTENCY: the EDPVR")]
            assert not errors, f"{route}: EDPVR: error box {errors}"
            assert page.get_by_text("Identified combination", exact=False).count() >= 1, route
            with page.expect_download() as info:
                download.click()
            target = tmp_path / f"{route}.zip"
            info.value.save_as(target)
            with zipfile.ZipFile(target) as z:
                names = set(z.namelist())
                assert {"settings.json", "summary.json", "summary.html"} <= names, names
                html = z.read("summary.html").decode()
                assert "90 % equal-tailed interval" in html and ">None<" not in html and "null" not in html
                summary = json.loads(z.read("summary.json"))
                assert summary["subject"] == "SYNTHETIC-HV3" and summary["synthetic"], route
                assert summary["conditions"]["edp_mmhg"] > 0
                assert any(n.startswith("figures/") for n in names), names
                if route == "mesh":
                    assert any(n.endswith(".nc") for n in names), names
                else:
                    assert "figures/iid_geometry.html" in names, names
                    assert summary["geometry"]["kind"] == "inferred"
                    assert summary["geometry"]["measures"] == {"reference_volume_ml": ref}
                    post = summary["models"]["iid"]["geometry_posterior"]
                    assert {"h1", "h5", "scale", "implied_reference_volume_ml"} <= set(post)
                    assert "inferred (no mesh)" in html
            _no_error_box(page, f"{route}: downloaded")
            ctx.close()
        assert not js_errors, js_errors[:3]
        outside = {h for h in hosts if h not in LOCAL_HOSTS}
        assert not outside, f"requests left localhost: {sorted(outside)}"
