"""The shared LRU of compiled programs and prepared cases (lvcore.execution.bounded_cache)."""
import threading

import pytest

from lvcore.execution.bounded_cache import BoundedCache


def test_least_recently_used_entry_goes_first():
    cache = BoundedCache(2)
    cache.put("a", 1)
    cache.put("b", 2)
    assert cache.get("a") == 1  # "a" is now the most recent
    cache.put("c", 3)
    assert list(cache) == ["a", "c"]
    assert cache.get("b") is None
    assert len(cache) == 2 and "a" in cache and cache["c"] == 3


def test_get_or_create_makes_an_entry_once():
    cache = BoundedCache(3)
    made = []

    def factory():
        made.append(1)
        return object()

    first = cache.get_or_create("k", factory)
    assert cache.get_or_create("k", factory) is first
    assert len(made) == 1
    cache.clear()
    assert len(cache) == 0 and cache.get("k") is None


def test_concurrent_use_keeps_the_bound_and_the_right_values():
    cache = BoundedCache(4)
    made = {}
    lock = threading.Lock()

    def factory(k):
        with lock:
            made[k] = made.get(k, 0) + 1
        return k

    def work(offset):
        for i in range(400):
            k = (i + offset) % 3  # shared keys, evicted now and then by the churn below
            assert cache.get_or_create(k, lambda k=k: factory(k)) == k
            cache.put(("other", offset, i), i)  # churn beyond the bound
            assert len(cache) <= 4

    threads = [threading.Thread(target=work, args=(n,)) for n in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(cache) <= 4
    assert set(made) == {0, 1, 2}


@pytest.mark.parametrize("size", [0, -1])
def test_a_cache_must_keep_something(size):
    with pytest.raises(ValueError, match="at least 1"):
        BoundedCache(size)
