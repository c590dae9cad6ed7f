"""Local executor: pool workers die with their driver (even when it is killed with SIGKILL) and are pinned one per core."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

DRIVER = r"""
import os, sys, time
from lvcore.parallel import LocalExecutor

def work(i):
    time.sleep(600)
    return os.getpid()

if __name__ == "__main__":
    ex = LocalExecutor(2)
    futures = [ex.submit(os.getpid) for _ in range(2)] + [ex.submit(work, i) for i in range(4)]
    print("pids", *sorted({f.result() for f in futures[:2]} | {p.pid for p in ex._pool._processes.values()}),
          flush=True)
    time.sleep(600)
"""


def _children(pid: int) -> set[int]:
    """Pids of the direct children of ``pid`` (from /proc)."""
    out = set()
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.add(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc (Linux)")
def test_workers_and_resource_tracker_die_with_a_sigkilled_driver(tmp_path):
    script = tmp_path / "driver.py"
    script.write_text(DRIVER)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                                         os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env,
                            start_new_session=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("pids"), line
        workers = {int(p) for p in line.split()[1:]}
        children = _children(proc.pid)  # the workers and multiprocessing's resource tracker
        assert len(workers) == 2 and workers <= children
        assert len(children) >= 3  # and multiprocessing's resource tracker
        assert all(_alive(p) for p in children)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        deadline = time.time() + 5.0
        while time.time() < deadline and any(_alive(p) for p in children):
            time.sleep(0.1)
        left = [p for p in children if _alive(p)]
        assert not left, f"orphaned processes after SIGKILL of the driver: {left}"
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # clean up on failure (the session of this test only)
        except ProcessLookupError:
            pass


def test_watch_parent_exits_when_the_parent_changes():
    code = ("import os, time\nfrom lvcore.parallel import watch_parent\n"
            "watch_parent(os.getppid() + 999999, poll_s=0.05)\ntime.sleep(30)\n")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    t0 = time.time()
    r = subprocess.run([sys.executable, "-c", code], env=env, timeout=60)
    assert r.returncode == 1 and time.time() - t0 < 25


def _affinity_after(seconds):
    time.sleep(seconds)
    return sorted(os.sched_getaffinity(0))


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs Linux and two cores")
def test_local_workers_are_pinned_one_per_core_unless_switched_off(monkeypatch):
    from lvcore.parallel import PIN_ENV, LocalExecutor, worker_cores

    cores = sorted(os.sched_getaffinity(0))
    assert worker_cores(2) == cores[:2]
    assert worker_cores(1) == [] and worker_cores(len(cores) + 1) == []  # one worker, or more than cores: free
    with LocalExecutor(2) as ex:
        # hold both workers busy at once so that each answers for itself
        futs = [ex.submit(_affinity_after, 1.0) for _ in range(2)]
        got = sorted(tuple(f.result()) for f in futs)
    assert got == [(cores[0],), (cores[1],)]
    assert "pinned" in ex.describe()
    monkeypatch.setenv(PIN_ENV, "0")
    assert worker_cores(2) == []
