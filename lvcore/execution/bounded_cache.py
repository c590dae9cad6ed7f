"""A thread-safe, size-bounded least-recently-used cache of per-process work.

Compiled samplers, compiled best-fit programs and prepared simulation cases are
expensive to build and cheap to keep, but each compiled XLA program holds
executable memory mappings (the kernel allows 65,530 per process), and a
long-running app server meets many emulators and meshes. One of these caches
per kind of work keeps the most recently used ``maxsize`` entries; the app's
sessions run in threads, so every operation holds a lock.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from typing import Generic, TypeVar

V = TypeVar("V")


class BoundedCache(Generic[V]):
    """Least recently used entries dropped first once more than ``maxsize`` are kept.

    Parameters
    ----------
    maxsize : int
        The number of entries kept (≥ 1).

    Examples
    --------
    >>> cache = BoundedCache(2)
    >>> cache.get_or_create("a", lambda: 1)
    1
    >>> cache.put("b", 2); cache.put("c", 3)
    >>> sorted(cache)
    ['b', 'c']
    """

    def __init__(self, maxsize: int):
        if int(maxsize) < 1:
            raise ValueError(f"maxsize must be at least 1, got {maxsize}")
        self.maxsize = int(maxsize)
        self._entries: OrderedDict[Hashable, V] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: Hashable) -> V | None:
        """The entry for ``key`` (now the most recently used), or None."""
        with self._lock:
            value = self._entries.get(key)
            if value is not None:
                self._entries.move_to_end(key)
            return value

    def put(self, key: Hashable, value: V) -> None:
        """Keep ``value`` for ``key`` as the most recently used entry; drop the oldest beyond ``maxsize``."""
        with self._lock:
            self._store(key, value)

    def get_or_create(self, key: Hashable, factory: Callable[[], V]) -> V:
        """The entry for ``key``, made by ``factory()`` (under the lock: made once) when there is none."""
        with self._lock:
            value = self._entries.get(key)
            if value is None:
                value = factory()
            self._store(key, value)
            return value

    def _store(self, key, value) -> None:
        self._entries[key] = value
        self._entries.move_to_end(key)
        while len(self._entries) > self.maxsize:
            self._entries.popitem(last=False)

    def clear(self) -> None:
        """Forget every entry."""
        with self._lock:
            self._entries.clear()

    def __len__(self) -> int:
        return len(self._entries)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._entries

    def __getitem__(self, key: Hashable) -> V:
        """The entry for ``key`` without marking it used (KeyError when absent)."""
        return self._entries[key]

    def __iter__(self) -> Iterator[Hashable]:
        """The keys, least recently used first (a snapshot)."""
        with self._lock:
            return iter(list(self._entries))
