"""Process pools: where batches of forward evaluations run, a local process pool or a Dask cluster.

The one home of parallel execution, low in the layers so that every user
shares it: the simulator adapter (:class:`lvcore.mechanics.forward.SimulatorForward`),
campaigns (:mod:`lvcore.campaigns.runner`), emulator training and the studies.
Both executors expose the same small interface:

* ``submit(fn, *args) -> future``;
* ``as_completed(futures)`` yielding futures as they finish;
* ``workers`` (int) and ``describe()`` (str);
* ``close()`` (also a context manager).

:class:`LocalExecutor` (the default) is a
:class:`concurrent.futures.ProcessPoolExecutor` with one worker process per
core, started with ``spawn`` (forking a process that has imported JAX is
unsafe). Workers inherit one BLAS/OpenMP thread (:func:`pin_threads`) so that
numpy's BLAS does not fight XLA, and share JAX's persistent compilation cache
so only the first worker compiles.

:func:`pin_threads` is the one place that sets the thread variables: every
entry point (the app, the test suite, the benchmark and build scripts, the
servers and children they start) calls it. This module imports neither numpy
nor JAX, so a script can call it before its own ``import numpy``.

:class:`DaskExecutor` submits to a ``distributed`` scheduler given as
``tcp://HOST:PORT``, or to a :class:`distributed.LocalCluster` it starts
itself (used in the tests). Remote workers need ``lvcore`` installed.
"""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import os
import sys
import threading
import time
from collections.abc import MutableMapping

from lvcore.exceptions import CampaignError

#: The environment variables that set how many threads numpy's BLAS (OpenBLAS, MKL, BLIS, Accelerate), OpenMP and
#: numexpr start. Read once, when those libraries load: set them before ``import numpy`` (:func:`pin_threads`).
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def pin_threads(env: MutableMapping[str, str] | None = None, *, threads: int = 1,
                force: bool = False) -> MutableMapping[str, str]:
    """Pin BLAS/OpenMP to ``threads`` threads: numpy's BLAS must not fight XLA's threads on a small machine.

    Sets every :data:`THREAD_VARIABLES` entry in ``env``. The libraries read them when they load, so a script calls
    this before it imports numpy (this module imports neither numpy nor JAX). Where numpy is loaded already (a
    pytest plugin may import it before ``tests/conftest.py`` runs), the loaded BLAS and OpenMP libraries are set to
    the variables' values through threadpoolctl (:func:`limit_loaded_libraries`).

    Parameters
    ----------
    env : mutable mapping, optional
        The environment to set: ``os.environ`` (default), or a copy handed to a child process
        (``subprocess.run(..., env=pin_threads(dict(os.environ)))``).
    threads : int
        Threads per library (default 1).
    force : bool
        Overwrite values already set (default False: a value the user set, e.g. ``OMP_NUM_THREADS=4``, is kept).

    Returns
    -------
    mutable mapping
        ``env`` itself, for use in an expression.

    Examples
    --------
    >>> env = pin_threads({"OMP_NUM_THREADS": "4"})
    >>> env["OMP_NUM_THREADS"], env["OPENBLAS_NUM_THREADS"]
    ('4', '1')
    >>> pin_threads({"OMP_NUM_THREADS": "4"}, force=True)["OMP_NUM_THREADS"]
    '1'
    """
    if int(threads) < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    env = os.environ if env is None else env
    for var in THREAD_VARIABLES:
        if force or var not in env:
            env[var] = str(int(threads))
    if env is os.environ and "numpy" in sys.modules:
        limit_loaded_libraries()
    return env


#: threadpoolctl's name of a loaded library -> the variable that sets its threads.
LIBRARY_VARIABLES = {"openblas": "OPENBLAS_NUM_THREADS", "mkl": "MKL_NUM_THREADS", "blis": "BLIS_NUM_THREADS",
                     "openmp": "OMP_NUM_THREADS"}


def limit_loaded_libraries() -> dict[str, int]:
    """Set the threads of the BLAS and OpenMP libraries already loaded in this process to the values of their
    variables (:data:`LIBRARY_VARIABLES`) through threadpoolctl (a scikit-learn dependency); the limits last until
    the process ends. Returns the limits set (library -> threads; empty without threadpoolctl)."""
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - installed with scikit-learn
        return {}
    controller, limits = ThreadpoolController(), {}
    for library, var in LIBRARY_VARIABLES.items():
        try:
            limits[library] = int(os.environ.get(var, ""))
        except ValueError:  # unset or not a number: that library keeps its own setting
            continue
        controller.select(internal_api=library).limit(limits=limits[library])
    return limits


#: Environment set in worker processes (before they import numpy): one thread per library (:func:`pin_threads`)
#: and float64.
WORKER_ENV = {**dict.fromkeys(THREAD_VARIABLES, "1"), "JAX_ENABLE_X64": "1"}


def default_workers() -> int:
    """One worker per core available to this process."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


#: How often a worker checks that its driver is alive (s).
PARENT_POLL_S = 0.5


def watch_parent(parent_pid: int, poll_s: float = PARENT_POLL_S) -> threading.Thread:
    """Exit this process (``os._exit``) as soon as ``parent_pid`` is no longer its parent.

    A daemon thread polls :func:`os.getppid`: when the driver dies, even by
    SIGKILL, the worker is re-parented (to init or a subreaper) and exits
    within ``poll_s`` seconds, so no orphaned workers (and, once they are
    gone, no orphaned multiprocessing resource tracker) stay behind. A thread
    is used rather than ``prctl(PR_SET_PDEATHSIG)`` because the latter fires
    when the *thread* that started the worker exits, which a pool may do
    while the driver lives on.
    """
    def run():
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)
            time.sleep(poll_s)

    t = threading.Thread(target=run, name="lvcore-parent-watch", daemon=True)
    t.start()
    return t


#: Environment variable: ``0`` leaves local workers free to run on any core (default: pinned, see
#: :class:`LocalExecutor`).
PIN_ENV = "LVCORE_PIN_WORKERS"


def worker_cores(workers: int) -> list[int]:
    """The core each of ``workers`` local workers is pinned to, or ``[]`` for no pinning.

    One core per worker when there are no more workers than cores available to this process
    (and ``$LVCORE_PIN_WORKERS`` is not ``0``); otherwise none.
    """
    if os.environ.get(PIN_ENV, "1").strip() == "0" or not hasattr(os, "sched_getaffinity"):
        return []
    cores = sorted(os.sched_getaffinity(0))
    return cores[:workers] if 1 < workers <= len(cores) else []


def _worker_init(parent_pid: int | None = None, slots=None, cores: tuple[int, ...] = ()) -> None:
    """Runs once in every local worker process: environment, core, JAX set-up, and death with the driver."""
    if parent_pid is not None:
        watch_parent(parent_pid)
    if slots is not None and cores:
        with slots.get_lock():  # the n-th worker to start takes the n-th core
            slot = slots.value
            slots.value += 1
        try:
            os.sched_setaffinity(0, {cores[slot % len(cores)]})
        except OSError:  # a core taken away meanwhile: run anywhere
            pass
    for k, v in WORKER_ENV.items():
        os.environ.setdefault(k, v)
    import lvcore.execution.jax_cache  # noqa: F401 - imports lvcore: float64 and the persistent compilation cache


class LocalExecutor:
    """A process pool on this machine.

    Parameters
    ----------
    workers : int, optional
        Number of worker processes (default: one per core).

    With no more workers than cores, each worker is pinned to a core of its own
    (:func:`worker_cores`): XLA's CPU runtime otherwise spreads a worker's kernels
    over the other cores too, where they compete with the other workers
    (`default` mesh, warm-chained solves: ≈ 50 ms of CPU per solve pinned against
    ≈ 68 ms unpinned; ``benchmarks/bench_campaign.py``). ``LVCORE_PIN_WORKERS=0``
    turns this off.
    """

    def __init__(self, workers: int | None = None):
        self.workers = int(workers or default_workers())
        if self.workers < 1:
            raise CampaignError(f"--workers must be >= 1, got {workers}")
        for k, v in WORKER_ENV.items():  # inherited by the spawned children
            os.environ.setdefault(k, v)
        ctx = mp.get_context("spawn")
        self.cores = worker_cores(self.workers)
        self._pool = cf.ProcessPoolExecutor(
            max_workers=self.workers, mp_context=ctx, initializer=_worker_init,
            initargs=(os.getpid(), ctx.Value("i", 0) if self.cores else None, tuple(self.cores)),
        )

    def describe(self) -> str:
        pinned = f", pinned to cores {self.cores}" if self.cores else ""
        return f"local process pool, {self.workers} worker(s){pinned}"

    def submit(self, fn, *args):
        return self._pool.submit(fn, *args)

    def as_completed(self, futures):
        return cf.as_completed(futures)

    def close(self, cancel: bool = False) -> None:
        self._pool.shutdown(wait=True, cancel_futures=cancel)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(cancel=exc_type is not None)


class DaskExecutor:
    """Rows run on a Dask ``distributed`` cluster.

    Parameters
    ----------
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a running scheduler. If omitted, a
        :class:`distributed.LocalCluster` is started with ``workers`` workers.
    workers : int, optional
        Workers of the local cluster (ignored with ``scheduler``).
    processes : bool
        Local cluster only: worker processes (True) or threads in this
        process (False, cheapest for tests).
    """

    def __init__(self, scheduler: str | None = None, workers: int | None = None, processes: bool = True):
        try:
            from distributed import Client, LocalCluster
        except ImportError as err:  # pragma: no cover - dask is a dependency
            raise CampaignError("the Dask executor needs `distributed` (pip install 'dask[distributed]')") from err
        self._cluster = None
        if scheduler:
            if not str(scheduler).startswith(("tcp://", "tls://", "inproc://", "ucx://")):
                raise CampaignError(f"--scheduler must look like tcp://HOST:PORT, got {scheduler!r}")
            try:
                self._client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError) as err:
                raise CampaignError(f"cannot reach the Dask scheduler at {scheduler}: {err}") from err
        else:
            n = int(workers or default_workers())
            self._cluster = LocalCluster(
                n_workers=n, threads_per_worker=1, processes=processes, dashboard_address=None, silence_logs=40
            )
            self._client = Client(self._cluster)
        info = self._client.scheduler_info()
        self.workers = max(1, sum(w.get("nthreads", 1) for w in info.get("workers", {}).values()))
        self.scheduler = scheduler or self._cluster.scheduler_address

    def describe(self) -> str:
        return f"Dask cluster at {self.scheduler}, {self.workers} thread(s)"

    def submit(self, fn, *args):
        return self._client.submit(fn, *args, pure=False)

    def as_completed(self, futures):
        from distributed import as_completed

        return as_completed(futures)

    def close(self, cancel: bool = False) -> None:
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(cancel=exc_type is not None)


class _Deferred(cf.Future):
    """A future of :class:`InProcessExecutor`: its task runs when the caller first needs it (``result``,
    ``exception`` or the executor's ``as_completed``), in the caller's thread or one of the executor's."""

    _take = threading.Lock()  # one task, one run: the caller and a thread of the executor may both ask

    def __init__(self, fn, args):
        super().__init__()
        self._task = (fn, args)

    def run(self) -> "_Deferred":
        with self._take:
            task, self._task = self._task, None
        if task is not None:
            fn, args = task
            try:
                self.set_result(fn(*args))
            except Exception as err:  # noqa: BLE001 - handed to the caller through the future, as a pool does
                self.set_exception(err)
        return self

    def result(self, timeout=None):
        return self.run() and super().result(timeout)

    def exception(self, timeout=None):
        return self.run() and super().exception(timeout)


#: Environment variable: how many threads :class:`InProcessExecutor` runs tasks on (default
#: :func:`in_process_threads`), e.g. ``1`` to compare.
IN_PROCESS_THREADS_ENV = "LVCORE_IN_PROCESS_THREADS"
#: Most threads of :class:`InProcessExecutor` by default (at most one per core).
IN_PROCESS_MAX_THREADS = 2


def in_process_threads() -> int:
    """Threads of an :class:`InProcessExecutor` by default: ``$LVCORE_IN_PROCESS_THREADS``, else one per core up to
    :data:`IN_PROCESS_MAX_THREADS`."""
    want = os.environ.get(IN_PROCESS_THREADS_ENV, "").strip()
    if want:
        if not want.isdigit() or int(want) < 1:
            raise ValueError(f"{IN_PROCESS_THREADS_ENV}={want!r}: use a whole number of threads, 1 or more")
        return int(want)
    return min(IN_PROCESS_MAX_THREADS, default_workers())


class InProcessExecutor:
    """Tasks run in this process, on ``threads`` threads, when the caller takes them: no worker start-up.

    For work too small to repay starting worker processes (each spawned worker imports the simulator and loads
    its compiled kernels, about 2 CPU-s, before its first task): a small campaign
    (:data:`lvcore.campaigns.runner.IN_PROCESS_MAX_ROWS`). ``submit`` only queues the task; ``as_completed``
    runs the tasks in submission order, at most ``threads`` at a time, handing each future over as soon as its
    task ended, so a campaign records every row as it ends (a killed run loses only the rows being solved).
    The simulator's heavy calls (XLA's kernels, PARDISO) release the GIL, so two threads of one process solve
    two rows at once without a second import of the simulator. A task's exception is kept in its future, as a
    pool's.

    Parameters
    ----------
    threads : int, optional
        Tasks run at once (default :func:`in_process_threads`: one per core, at most 2); 1: one at a time, in
        the caller's thread.
    """

    workers = 1  # one process: the chains of a chained campaign are planned for one worker

    def __init__(self, threads: int | None = None):
        self.threads = in_process_threads() if threads is None else max(1, int(threads))

    def describe(self) -> str:
        return "this process (no worker processes)" + (f", {self.threads} threads" if self.threads > 1 else "")

    def submit(self, fn, *args):
        return _Deferred(fn, args)

    def as_completed(self, futures):
        futures = list(futures)
        if self.threads == 1:
            for fut in futures:
                yield fut.run() if isinstance(fut, _Deferred) else fut
            return
        with cf.ThreadPoolExecutor(self.threads, thread_name_prefix="lvcore-in-process") as pool:
            queued, running = iter(futures), {}
            for fut in queued:  # the first ``threads`` tasks
                running[pool.submit(fut.run) if isinstance(fut, _Deferred) else fut] = fut
                if len(running) == self.threads:
                    break
            while running:
                done, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
                for d in [f for f in running if f in done]:  # in submission order among those done
                    yield running.pop(d)
                    nxt = next(queued, None)
                    if nxt is not None:
                        running[pool.submit(nxt.run) if isinstance(nxt, _Deferred) else nxt] = nxt

    def close(self, cancel: bool = False) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def make_executor(workers: int | None = None, scheduler: str | None = None):
    """The executor the CLI asks for: Dask if ``scheduler`` is given, else local processes."""
    if scheduler:
        return DaskExecutor(scheduler=scheduler)
    return LocalExecutor(workers)
