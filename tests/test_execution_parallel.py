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
from lvcore.execution.parallel import LocalExecutor

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
    code = ("import os, time\nfrom lvcore.execution.parallel import watch_parent\n"
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
    from lvcore.execution.parallel import PIN_ENV, LocalExecutor, worker_cores

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


def test_pin_threads_fills_in_every_thread_variable_and_keeps_what_is_set():
    from lvcore.execution.parallel import THREAD_VARIABLES, WORKER_ENV, pin_threads

    env = {THREAD_VARIABLES[0]: "4", "OTHER": "x"}
    assert pin_threads(env) is env  # the mapping itself, for use in an expression
    assert env == {**dict.fromkeys(THREAD_VARIABLES, "1"), THREAD_VARIABLES[0]: "4", "OTHER": "x"}
    assert pin_threads(env, threads=2, force=True) == {**dict.fromkeys(THREAD_VARIABLES, "2"), "OTHER": "x"}
    assert {k: WORKER_ENV[k] for k in THREAD_VARIABLES} == dict.fromkeys(THREAD_VARIABLES, "1")
    with pytest.raises(ValueError, match="threads must be >= 1"):
        pin_threads({}, threads=0)


PIN_THEN_NUMPY = r"""
import sys
from lvcore.execution.parallel import pin_threads
assert "numpy" not in sys.modules and "jax" not in sys.modules, "lvcore.execution.parallel must not import numpy or JAX"
pin_threads()
import numpy, threadpoolctl
print(sorted({i["num_threads"] for i in threadpoolctl.threadpool_info()}))
"""
#: numpy imported first, as a pytest plugin does before tests/conftest.py: the loaded BLAS is limited instead.
NUMPY_THEN_PIN = r"""
import numpy, threadpoolctl
from lvcore.execution.parallel import pin_threads
pin_threads()
print(sorted({i["num_threads"] for i in threadpoolctl.threadpool_info()}))
"""


@pytest.mark.parametrize("code", [PIN_THEN_NUMPY, NUMPY_THEN_PIN], ids=["before-numpy", "after-numpy"])
def test_pin_threads_gives_numpy_one_blas_thread(code):
    """In a fresh process with no thread variables, pin_threads leaves numpy's BLAS one thread, called before or
    after numpy is imported (unpinned, OpenBLAS starts one per core: the check fails on a multi-core machine)."""
    pytest.importorskip("threadpoolctl")
    from lvcore.execution.parallel import THREAD_VARIABLES

    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-1] == "[1]"


def test_the_docstring_examples_run():
    import doctest

    import lvcore.execution.parallel

    result = doctest.testmod(lvcore.execution.parallel)
    assert result.attempted >= 3 and result.failed == 0


def test_this_test_process_blas_follows_the_variables():
    """tests/conftest.py pins the test processes too: their BLAS runs the threads the variables say (1 unless the
    user set them), whichever plugin imported numpy first. The BLAS only: an OpenMP runtime that a library loads
    later in the process is that library's to set (a full run once found libgomp at 3 threads after other files
    in the same worker; the BLAS was at 1)."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import numpy  # noqa: F401 - loads the BLAS

    from lvcore.execution.parallel import LIBRARY_VARIABLES

    for lib in threadpoolctl.threadpool_info():
        if lib["user_api"] != "blas":
            continue
        var = LIBRARY_VARIABLES.get(lib["internal_api"])
        if var and os.environ.get(var, "").isdigit():
            assert lib["num_threads"] == int(os.environ[var]), lib


def test_in_process_executor_runs_each_task_when_the_caller_takes_it():
    from lvcore.execution.parallel import InProcessExecutor

    ran = []

    def task(k):
        ran.append(k)
        return 2 ** k

    with InProcessExecutor(threads=1) as ex:
        assert ex.workers == 1 and ex.describe() == "this process (no worker processes)"
        futures = [ex.submit(task, k) for k in range(4)] + [ex.submit(int, "not a number")]
        assert ran == [] and not any(f.done() for f in futures)  # queued only
        for k, fut in enumerate(ex.as_completed(futures[:4])):  # one at a time: the caller records each first
            assert fut.done() and ran == list(range(k + 1)) and fut.result() == 2 ** k
        assert isinstance(futures[-1].exception(), ValueError)  # kept in the future, as a pool does
        assert ex.submit(task, 5).result() == 32  # result() runs a task not taken yet


def test_in_process_executor_on_two_threads_runs_two_tasks_at_once(monkeypatch):
    import threading

    from lvcore.execution import parallel
    from lvcore.execution.parallel import InProcessExecutor

    started, second_started = [], threading.Event()

    def first():  # ends only once the second task has started beside it (one thread: never, a 10 s time-out)
        started.append(0)
        return second_started.wait(10.0)

    def later(k):
        started.append(k)
        second_started.set()
        return 2 ** k

    with InProcessExecutor(threads=2) as ex:
        assert ex.workers == 1 and ex.describe().endswith("2 threads")
        futures = [ex.submit(first)] + [ex.submit(later, k) for k in range(1, 5)] + [ex.submit(int, "not a number")]
        assert started == []  # queued only
        done = list(ex.as_completed(futures))
    assert sorted(done, key=futures.index) == futures and all(f.done() for f in futures)
    assert [f.result() for f in futures[:5]] == [True, 2, 4, 8, 16] and started[0] == 0
    assert isinstance(futures[-1].exception(), ValueError)  # kept in the future, as a pool does
    monkeypatch.setenv(parallel.IN_PROCESS_THREADS_ENV, "1")
    assert InProcessExecutor().threads == 1
    monkeypatch.setenv(parallel.IN_PROCESS_THREADS_ENV, "many")
    with pytest.raises(ValueError, match="whole number"):
        parallel.in_process_threads()
    monkeypatch.delenv(parallel.IN_PROCESS_THREADS_ENV)
    assert parallel.in_process_threads() == min(2, parallel.default_workers())
