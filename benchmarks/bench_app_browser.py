"""Page timings of the Streamlit app as a user sees them in a real browser (Debian Chromium + playwright).

    python benchmarks/bench_app_browser.py                      # every page x 3 sessions, 7 redraws
    python benchmarks/bench_app_browser.py --repeats 5 --redraws 11
    python benchmarks/bench_app_browser.py --screenshots docs/screenshots   # also refresh the docs' small PNGs
    python benchmarks/bench_app_browser.py --calibration   # also time a calibration: click to results, to the
                                                           # verdict banners (R-hat, ESS), to every figure drawn
    python benchmarks/bench_app_browser.py --redraw-only --redraws 15   # only the Fibre-angles slider-to-redraw

Starts ``streamlit run app.py`` on 127.0.0.1 and, for every page linked in the
sidebar, opens it in a fresh browser session and measures the time from
navigation until the script has finished and every element is drawn (no
skeletons). The first visit after the server starts ("cold": imports, caches,
JIT compilation) is reported separately from the median of the later sessions
("warm"). On Fibre angles it shows the live (α_endo, α_epi) map and strain
chart and measures slider-to-redraw: from the key press on the sidebar's
first slider to the moment both live charts have new data (``--slider map``:
the map's grid slider, to the map's new data), alternating
ArrowRight/ArrowLeft. Prints a
Markdown table for BENCHMARKS.md (target: redraw median <= 300 ms).

Uses /usr/bin/chromium; never ``playwright install``.
"""
from __future__ import annotations

import argparse
import os
import re
import statistics
import sys
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=3, help="fresh sessions per page (the first one is cold)")
    p.add_argument("--redraws", type=int, default=7, help="slider presses timed on Fibre angles")
    p.add_argument("--screenshots", type=Path, default=None, help="write small PNGs of every page here")
    p.add_argument("--calibration", action="store_true",
                   help="also time 'Run calibration' on the Calibration page with its defaults, click to results")
    p.add_argument("--redraw-only", action="store_true", help="skip the page timings; only slider-to-redraw")
    p.add_argument("--slider", choices=("sidebar", "map"), default="sidebar",
                   help="slider timed on Fibre angles: the shared sidebar's first θ slider (the whole page reruns) "
                        "or the map's first slider (only the map's fragment reruns)")
    p.add_argument("--app-script", type=Path, default=REPO / "app.py",
                   help="entry script to serve (e.g. another checkout's app.py, with PYTHONPATH set to that checkout, "
                        "for an A/B in one run)")
    args = p.parse_args(argv)

    from playwright.sync_api import sync_playwright

    from lvcore.testing import browser as drv

    shots = REPO / "build" / "screenshots"
    shots.mkdir(parents=True, exist_ok=True)
    rows = []
    t_start = time.perf_counter()
    with drv.StreamlitServer(app=args.app_script, log=REPO / "build" / "streamlit_bench.log") as server, \
            sync_playwright() as pw:
        t_server = time.perf_counter() - t_start
        b = drv.launch(pw)

        def session():
            ctx = b.new_context(viewport={"width": 1400, "height": 1000})
            page = ctx.new_page()
            page.set_default_timeout(300_000)
            return ctx, page

        ctx, page = session()
        page.goto(server.url)
        drv.wait_idle(page)
        links = drv.page_links(page)
        ctx.close()
        for label, href in ([] if args.redraw_only else links):
            times = []
            for r in range(args.repeats):
                ctx, page = session()
                t0 = time.perf_counter()
                page.goto(href)
                drv.wait_idle(page)
                times.append(time.perf_counter() - t0)
                if r == 0:
                    page.screenshot(path=str(shots / f"{drv.slug(label)}.png"), full_page=True)
                    if args.screenshots:
                        drv.shrink_png(shots / f"{drv.slug(label)}.png", args.screenshots / f"{drv.slug(label)}.png")
                errs = drv.exceptions(page)
                ctx.close()
                if errs:
                    print(f"{label}: exception on the page: {errs}", file=sys.stderr)
            warm = times[1:] or times
            rows.append((label, times[0], statistics.median(warm), len(warm)))
            print(f"{label}: first render {times[0]:.2f} s, warm {['%.2f' % t for t in warm]}", flush=True)

        redraw = None
        fa = [h for lab, h in links if re.search(r"fibre\s*angles", lab, re.I)]
        if fa:
            ctx, page = session()
            page.goto(fa[0])
            drv.wait_idle(page)
            drv.open_live_map(page)
            where = "[data-testid=stSidebar]" if args.slider == "sidebar" else "[data-testid=stMain]"
            slider = page.locator(f"{where} :is({drv.SLIDER})").first
            slider_label = slider.get_attribute("aria-label")
            # the sidebar θ slider moves every live chart: the clock stops when all of them are redrawn
            redraw = drv.redraw_times(page, slider, n=args.redraws, every_plot=args.slider == "sidebar")
            page.screenshot(path=str(shots / "fibre_angles_live_map.png"), full_page=True)
            if args.screenshots:
                drv.shrink_png(shots / "fibre_angles_live_map.png", args.screenshots / "fibre_angles_live_map.png")
            ctx.close()
        calib = None
        cp = [h for lab, h in links if re.search(r"calibration", lab, re.I)]
        if args.calibration and cp:
            ctx, page = session()
            page.goto(cp[0])
            drv.wait_idle(page)
            button = page.get_by_role("button", name=re.compile("run calibration", re.I))
            t0 = time.perf_counter()
            button.click()
            page.get_by_text(re.compile("^Results for")).first.wait_for(timeout=1_800_000)
            calib = {"results": time.perf_counter() - t0}
            # the verdict's banners (one per likelihood, green or amber, with divergences, R-hat and ESS)
            banners = page.get_by_text(re.compile(r"(Converged: divergences|Treat with care: )"))
            models = page.locator("[data-testid=stMain] [data-testid=stMultiSelect] [data-baseweb=tag]").count() or 1
            deadline = time.perf_counter() + 600
            while banners.count() < models and time.perf_counter() < deadline:
                time.sleep(0.02)
            calib["verdict"] = time.perf_counter() - t0
            drv.wait_idle(page)
            calib["idle"] = time.perf_counter() - t0
            calib["banners"] = [banners.nth(i).inner_text() for i in range(banners.count())]
            page.screenshot(path=str(shots / "calibration_results.png"), full_page=True)
            if args.screenshots:
                drv.shrink_png(shots / "calibration_results.png", args.screenshots / "calibration_results.png")
            errs = drv.exceptions(page)
            ctx.close()
            print(f"calibration: click to results {calib['results']:.1f} s, to the verdict banners "
                  f"{calib['verdict']:.1f} s, to every figure drawn {calib['idle']:.1f} s"
                  + (f"; exceptions {errs}" if errs else ""), flush=True)
            for text in calib["banners"]:
                print(f"  banner: {text}", flush=True)
        b.close()

    print(f"\nserver start {t_server:.1f} s; {args.repeats} fresh sessions per page; cpus {os.cpu_count()}, "
          f"load average {os.getloadavg()[0]:.1f}")
    print("| page | first render, cold server (s) | first render, new session, median (s) |")
    print("|---|---|---|")
    for label, cold, warm, n in rows:
        print(f"| {label} | {cold:.2f} | {warm:.2f} (n={n}) |")
    if redraw:
        print(f"\nFibre angles live map, slider '{slider_label}' -> redraw: median {statistics.median(redraw) * 1000:.0f} ms, "
              f"min {min(redraw) * 1000:.0f}, max {max(redraw) * 1000:.0f} (n={len(redraw)}; target <= 300 ms)")
    if calib is not None:
        print(f"Calibration page, 'Run calibration' with the page's defaults -> results shown: {calib['results']:.1f} s; "
              f"verdict banners: {calib['verdict']:.1f} s; every figure drawn: {calib['idle']:.1f} s")
    print(f"time {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}; server log {REPO / 'build' / 'streamlit_bench.log'} "
          "(the app's warm-up reports there)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
