#!/usr/bin/env python3
"""Wheel smoke test: the package as a user gets it from ``pip install``, not from the checkout.

1. builds the wheel with ``python -m pip wheel . --no-deps -w dist/`` in a clean
   copy of the source tree (no ``build/`` left-overs of the checkout can leak in);
2. installs it into a FRESH virtual environment (dependencies from PyPI or the
   pip cache);
3. from a folder outside the checkout, with ``PYTHONPATH`` unset:

   * checks that ``lvcore`` is imported from that environment;
   * runs the simulator on a ``pca`` geometry of the bundled shape model;
   * loads both bundled emulators (``chapter``, ``angles``) and evaluates them;
   * finds the live chart's page (``lvcore.app.live_chart``) and plotly.js;
   * finds the bundled data and every page script inside the installed package
     (the repository's top-level ``assets/`` and ``pages/``, mapped by pyproject);
   * reads the shipped REAL patient-derived LV (``assets/real_lv/``) and its upstream licence from the package;
   * calibrates on a bundled SYNTHETIC volunteer with a tiny chain
     (``lvcore calibrate --volunteer``);
   * starts the app (``lvcore app``, headless on 127.0.0.1, a free port), waits
     for ``/_stcore/health`` to answer ``ok``, and stops it.

Uses the standard library only, so any Python >= 3.11 can run it::

    python3 scripts/wheel_smoke.py            # prints the time of every step

Exit status 0 when every step passed. JAX compiles into a fresh cache folder
(cold, as on a new machine) unless ``--warm-jax-cache`` is given.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Not part of a source tree: never copied into the clean build copy.
IGNORE = shutil.ignore_patterns(".git", ".venv", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache",
                                ".jax_cache", "out", "tmp")

SIMULATE_AND_EMULATE = r"""
import json, sys
from pathlib import Path
import numpy as np
import lvcore
from lvcore.emulator.io import load_emulator

venv = Path(sys.prefix).resolve()
where = Path(lvcore.__file__).resolve()
assert venv in where.parents, f"lvcore imported from {where}, not from the fresh environment {venv}"
res = lvcore.simulate({"geometry": {"kind": "pca", "scores": [0.5], "resolution": "fast"},
                       "material": {"law": "holzapfel-ogden", "a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6},
                       "load": {"pressure": 8, "units": "mmHg"}})
assert res.converged, res.message
s = res.to_dict()
lvv = s["cavity_volume_ml"]["loaded"]
assert 60 < lvv < 300 and len(s["strains"]) == 24, s
out = {"lvcore": str(where.parent), "pca_lvv_ml": round(lvv, 2)}
for name in ("chapter", "angles"):
    emu = load_emulator(name)
    x = {n: 0.5 * (lo + hi) for n, lo, hi in zip(emu.input_names, emu.lower, emu.upper)}
    y = np.asarray(emu.predict(x, strict=True))
    assert y.shape == (25,) and np.isfinite(y).all() and 20 < y[0] < 400, (name, y)
    out[f"{name}_inputs"] = len(emu.input_names)
from lvcore.app.live_chart import frontend_dir  # the live charts' page ships in the wheel; plotly.js from plotly
live = frontend_dir()
assert (live / "index.html").is_file() and (live / "plotly.min.js").stat().st_size > 1_000_000, live
from lvcore.app import PAGES  # assets/ and pages/ are mapped into the wheel (pyproject package-dir)
from lvcore.resources import assets_dir
assert venv in assets_dir().resolve().parents and assets_dir().parts[-2:] == ("lvcore", "assets"), assets_dir()
assert all(p.path.is_file() and venv in p.path.resolve().parents for p in PAGES), [str(p.path) for p in PAGES]
out["pages"] = len(PAGES)
from lvcore.geometry.io import read_template_mesh  # the REAL patient-derived LV ships with its upstream licence
from lvcore.resources import real_lv_files
real = real_lv_files()
assert venv in real.template.resolve().parents and "MIT License" in real.licence.read_text(), real
out["real_lv_nodes"] = int(read_template_mesh(real.template).shape[0])
print(json.dumps(out))
"""

#: The thread variables as the installed package sets them (lvcore.execution.parallel.pin_threads), printed as JSON.
PIN_THREADS = "import json; from lvcore.execution.parallel import pin_threads; print(json.dumps(dict(pin_threads({}, force=True))))"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Smoke:
    def __init__(self, work: Path, env: dict):
        self.work, self.env, self.times = work, env, {}

    def step(self, name: str, cmd: list[str], *, cwd: Path | None = None, ok=(0,), timeout: float = 600) -> str:
        print(f"--- {name}: {' '.join(map(str, cmd))}", flush=True)
        t0 = time.perf_counter()
        proc = subprocess.run([str(c) for c in cmd], cwd=cwd or self.work / "run", env=self.env, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout)
        self.times[name] = time.perf_counter() - t0
        if proc.returncode not in ok:
            print(proc.stdout[-6000:])
            raise SystemExit(f"wheel smoke: step '{name}' failed with exit status {proc.returncode}")
        print(f"    ok in {self.times[name]:.1f} s", flush=True)
        return proc.stdout

    def app(self, lvcore_exe: Path, timeout: float = 180) -> None:
        port = free_port()
        cmd = [str(lvcore_exe), "app", "--port", str(port), "--server.headless", "true",
               "--server.address", "127.0.0.1", "--browser.gatherUsageStats", "false"]
        print(f"--- app: {' '.join(cmd)}", flush=True)
        log = open(self.work / "app.log", "w+")
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=self.work / "run", env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
        url = f"http://127.0.0.1:{port}/_stcore/health"
        body = ""
        try:
            while time.perf_counter() - t0 < timeout and proc.poll() is None:
                try:
                    with urllib.request.urlopen(url, timeout=2) as r:
                        body = r.read().decode().strip()
                    if body == "ok":
                        break
                except OSError:
                    pass
                time.sleep(0.5)
            self.times["app"] = time.perf_counter() - t0
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
                try:
                    proc.wait(15)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
        if body != "ok":
            log.seek(0)
            print(log.read()[-6000:])
            raise SystemExit(f"wheel smoke: the app did not answer 'ok' on {url} (got {body!r})")
        print(f"    ok in {self.times['app']:.1f} s (health 'ok')", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--python", default=sys.executable, help="interpreter for the fresh environment")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder (printed)")
    ap.add_argument("--warm-jax-cache", action="store_true", help="use the user's JAX compilation cache")
    args = ap.parse_args(argv)

    t_start = time.perf_counter()
    work = Path(tempfile.mkdtemp(prefix="lvcore-wheel-smoke-"))
    try:
        (work / "run").mkdir()
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV",
                                                                 "LVCORE_EMULATORS")}
        env.update(MPLBACKEND="Agg", VTK_DEFAULT_OPENGL_WINDOW="vtkEGLRenderWindow", PIP_DISABLE_PIP_VERSION_CHECK="1")
        if not args.warm_jax_cache:
            env["LVCORE_JAX_CACHE"] = str(work / "jax-cache")
        smoke = Smoke(work, env)
        src = work / "src"
        shutil.copytree(ROOT, src, ignore=IGNORE)
        venv = work / "venv"
        smoke.step("venv", [args.python, "-m", "venv", venv], cwd=work)
        py, bin_ = venv / "bin" / "python", venv / "bin"
        smoke.step("build wheel", [py, "-m", "pip", "wheel", ".", "--no-deps", "-w", "dist/", "-q"], cwd=src)
        (wheel,) = (src / "dist").glob("lvcore-*.whl")
        smoke.times["wheel MB"] = wheel.stat().st_size / 1e6
        smoke.step("install wheel", [py, "-m", "pip", "install", "-q", "--no-compile", wheel])  # no .pyc: faster
        # the installed package's own thread pinning (one BLAS/OpenMP thread) for every later step
        out = smoke.step("pin threads", [py, "-c", PIN_THREADS])
        env.update(json.loads(out.strip().splitlines()[-1]))
        out = smoke.step("simulate pca + emulators", [py, "-c", SIMULATE_AND_EMULATE])
        print("    " + out.strip().splitlines()[-1])
        smoke.step("calibrate", [bin_ / "lvcore", "calibrate", "--volunteer", "SYNTHETIC_HV3", "--model", "iid",
                                 "--chains", "1", "--warmup", "50", "--samples", "50", "--out", "cal", "--json"],
                   ok=(0, 1))  # 1 = ran, but a chain this short is not declared converged
        summary = json.loads((work / "run" / "cal" / "summary.json").read_text())
        assert summary and summary[0]["subject"] == "SYNTHETIC-HV3", summary
        smoke.app(bin_ / "lvcore")
    finally:
        if args.keep:
            print(f"kept {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)
    total = time.perf_counter() - t_start
    use = resource.getrusage(resource.RUSAGE_CHILDREN)  # CPU of every finished step: the wall time on a busy machine
    cpu = use.ru_utime + use.ru_stime                   # overstates the work, this does not
    print("wheel smoke passed: " + ", ".join(f"{k} {v:.1f}" + ("" if k.endswith("MB") else " s")
                                             for k, v in smoke.times.items())
          + f"; total {total:.0f} s wall, {cpu:.0f} s CPU in the steps")
    return 0


if __name__ == "__main__":
    sys.exit(main())
