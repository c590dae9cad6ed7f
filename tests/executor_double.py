"""The one executor test double: runs every submitted task at once in this process.

It has the interface of :mod:`lvcore.execution.parallel`'s executors (``workers``,
``describe``, ``submit``, ``as_completed``), so campaigns and studies run
through their real code paths while monkeypatches stay visible and no
worker process is started.
"""
from __future__ import annotations

from concurrent.futures import Future


class InlineExecutor:
    """Runs submitted tasks immediately in this process (keeps monkeypatches visible)."""

    workers = 1

    def describe(self) -> str:
        return "inline"

    def submit(self, fn, *args) -> Future:
        fut = Future()
        fut.set_result(fn(*args))
        return fut

    def as_completed(self, futures):
        return iter(futures)
