"""Peak memory of the Streamlit app server through a realistic browser session, optionally under ``ulimit -v``.

    python benchmarks/bench_app_memory.py                       # 4 GB cap (ulimit -v 4000000), warm-up on, 3 runs
    python benchmarks/bench_app_memory.py --cap-kib 0           # no cap
    python benchmarks/bench_app_memory.py --repeats 5 --no-calibration

Each run starts a fresh ``streamlit run app.py`` (its address space capped with ``ulimit -v`` in the shell that
starts it, the browser is not capped; the background warm-up on, as a user's server has it) and drives one
Chromium session (Debian's ``/usr/bin/chromium`` through playwright; never ``playwright install``): the Simulator
page (its default solve, then Simulate with a stiffer ``a``), every other page of the sidebar, the Fibre angles
sweep, and on the Calibration page a small calibration (1 chain, 100 + 100 draws). It then waits for the warm-up
to finish. After each step it reads the server's ``/proc/<pid>/status``: ``VmHWM`` (peak resident memory) and
``VmPeak`` (peak address space, what ``ulimit -v`` limits), both kept by the kernel. A run fails if the server
dies or a page shows an exception. Prints a Markdown table: per step, the median over the runs.
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import statistics
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from lvcore.execution.parallel import pin_threads  # noqa: E402


def _status(pid: int) -> dict:
    out = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key, _, rest = line.partition(":")
            if key in ("VmHWM", "VmPeak", "VmRSS", "VmSize"):
                out[key] = int(rest.split()[0]) * 1024
    return out


def _server(port: int, cap_kib: int, log: Path):
    env = pin_threads({**os.environ, "LVCORE_APP_WARMUP": "1"})
    cmd = " ".join(shlex.quote(c) for c in [sys.executable, "-m", "streamlit", "run", str(REPO / "app.py"),
                                             "--server.headless", "true", "--server.address", "127.0.0.1",
                                             "--server.port", str(port), "--browser.gatherUsageStats", "false",
                                             "--server.fileWatcherType", "none"])
    shell = (f"ulimit -v {cap_kib}; " if cap_kib else "") + "exec " + cmd
    proc = subprocess.Popen(["bash", "-c", shell], cwd=REPO, env=env, stdout=open(log, "w"), stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"server exited {proc.returncode}: {log.read_text()[-2000:]}")
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/_stcore/health", timeout=2):
                return proc
        except OSError:
            time.sleep(0.5)
    proc.kill()
    raise TimeoutError("server did not start")


def one_run(port: int, cap_kib: int, calibration: bool, log: Path) -> list[tuple[str, dict, float]]:
    """One server, one browser session; [(step, /proc status, seconds)]."""
    from playwright.sync_api import sync_playwright

    from lvcore.testing import browser as drv

    proc = _server(port, cap_kib, log)
    url = f"http://127.0.0.1:{port}"
    steps = []
    t0 = time.perf_counter()

    def record(step, page=None):
        if proc.poll() is not None:
            raise RuntimeError(f"the server died at '{step}' (exit {proc.returncode}): {log.read_text()[-1500:]}")
        if page is not None and drv.exceptions(page):
            raise RuntimeError(f"exception on '{step}': {drv.exceptions(page)[:1]}")
        steps.append((step, _status(proc.pid), time.perf_counter() - t0))
        print(f"  {step:<34} peak RSS {steps[-1][1]['VmHWM'] / 2**30:5.2f} GB, peak address space "
              f"{steps[-1][1]['VmPeak'] / 2**30:5.2f} GB ({steps[-1][2]:.0f} s)", flush=True)

    try:
        record("server started")
        with sync_playwright() as p:
            b = drv.launch(p)
            page = b.new_context(viewport={"width": 1400, "height": 1000}).new_page()
            page.set_default_timeout(600_000)
            page.goto(url)
            drv.wait_idle(page, 600)
            record("Simulator (default solve)", page)
            slider = page.locator(drv.SLIDER).first
            slider.focus()
            for _ in range(8):
                page.keyboard.press("ArrowRight")
            page.get_by_role("button", name="Simulate").click()
            drv.wait_rerun(page, 600)
            record("Simulator (stiffer a)", page)
            for label, href in drv.page_links(page):
                if href.rstrip("/") == url:
                    continue
                page.goto(href)
                drv.wait_idle(page, 600)
                if re.search("fibre", label, re.I):
                    page.get_by_role("button", name="Run sweep").click()
                    drv.wait_rerun(page, 600)
                    label += " (sweep)"
                if calibration and re.search("^calibration", label, re.I):
                    for name, value in (("chains", 1), ("warm-up", 100), ("draws kept", 100)):
                        box = page.get_by_label(name, exact=True)
                        box.fill(str(value))
                        box.press("Enter")
                        drv.wait_rerun(page)
                    page.get_by_role("button", name="Run calibration").click()
                    page.get_by_text(re.compile("^Results for")).first.wait_for(timeout=1_200_000)
                    drv.wait_idle(page, 600)
                    label += " (1 chain, 100+100)"
                record(label, page)
            b.close()
        deadline = time.monotonic() + 600
        while "warm-up" not in log.read_text() and time.monotonic() < deadline:
            time.sleep(1)
        warm = [ln for ln in log.read_text().splitlines() if "warm-up" in ln]
        record("warm-up finished: " + (warm[-1].split(" in ")[0].replace("lvcore app warm-up ", "") if warm else "?"))
        print("  " + (warm[-1] if warm else "no warm-up line in the log"), flush=True)
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
    return steps


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cap-kib", type=int, default=4_000_000,
                   help="ulimit -v of the server in KiB, 0 for none (default 4000000, about 4 GB)")
    p.add_argument("--repeats", type=int, default=3, help="fresh servers and sessions (default 3)")
    p.add_argument("--no-calibration", action="store_true", help="skip the small calibration (default: run it)")
    p.add_argument("--port", type=int, default=8593, help="server port (default 8593)")
    args = p.parse_args(argv)
    log = REPO / "build" / "bench_app_memory_server.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    runs = []
    for r in range(args.repeats):
        print(f"run {r + 1}/{args.repeats}", flush=True)
        runs.append(one_run(args.port, args.cap_kib, not args.no_calibration, log))
    cap = f"ulimit -v {args.cap_kib} ({args.cap_kib * 1024 / 2**30:.2f} GiB)" if args.cap_kib else "no cap"
    print(f"\n{cap}; warm-up on; {args.repeats} runs; cpus {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}\n")
    print("| step | peak RSS (VmHWM), GB, median | peak address space (VmPeak), GB, median | s after start |")
    print("|---|---|---|---|")
    for i, (step, _, _) in enumerate(runs[0]):
        vals = [run[i] for run in runs if len(run) > i]
        hwm = statistics.median(v[1]["VmHWM"] for v in vals) / 2**30
        peak = statistics.median(v[1]["VmPeak"] for v in vals) / 2**30
        print(f"| {step} | {hwm:.2f} | {peak:.2f} | {statistics.median(v[2] for v in vals):.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
