"""lvcore.execution.jax_cache: the exported simulator kernels give bitwise the plain jit results, on the first process (made
and written) and on a later one (read back), and a missing, corrupt or stale file falls back with no error."""
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import jax
import jax.numpy as jnp

from lvcore.execution import jax_cache
from lvcore.execution.jax_cache import ExportedKernel, exported_kernel, read_exported, write_exported
from lvcore.mechanics import simulate as simulate_module
from lvcore.mechanics import system as system_module
from lvcore.mechanics.case import Case
from lvcore.mechanics.simulate import simulate

#: The simulator's kernels that are exported (every jitted kernel of a solve).
KERNELS = (system_module._residual, system_module._tangent, system_module._external_load,
           simulate_module._cavity_volume, simulate_module._outputs)


@pytest.fixture
def export_to(monkeypatch):
    """Point the exported kernels at a folder (or None: off) with every kernel's in-process programs forgotten,
    as in a new process."""
    def use(folder):
        monkeypatch.setattr(jax_cache, "export_dir", lambda: folder)
        monkeypatch.setattr(jax_cache, "_exports_off", lambda: folder is None)
        for k in KERNELS:
            k._programs.clear()
            k.files.clear()
        simulate_module._PREPARED.clear()  # the prepared case (its reference volume, load norm) made anew too
    yield use
    for k in KERNELS:
        k._programs.clear()


def _solve():
    # a stiffer material than the fixtures' so this solve is not shared with another test's cache
    r = simulate(Case.default_lv({"a": 0.9, "b": 1.7, "af": 1.4, "bf": 3.1}, resolution="fast"))
    assert r.converged
    return r


def _same(r1, r2):
    assert np.array_equal(r1.outputs(), r2.outputs())
    assert np.array_equal(np.asarray(r1.solver_state[0]), np.asarray(r2.solver_state[0]))


def test_exported_kernels_give_bitwise_the_jit_results_made_and_read_back(tmp_path, export_to):
    export_to(None)  # the plain jit path
    plain = _solve()
    export_to(tmp_path)  # first process: every kernel traced, exported and written
    made = _solve()
    files = {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("*.jaxexp")}
    assert {n.split("-")[0] for n in files} == {k.__name__ for k in KERNELS}
    export_to(tmp_path)  # a later process: every kernel read back, none made again
    loaded = _solve()
    assert {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("*.jaxexp")} == files
    assert all(callable(prog) for k in KERNELS for prog in k._programs.values())  # the exported path ran
    _same(plain, made)
    _same(plain, loaded)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "checksum-valid garbage", "stale", "forged"])
def test_a_corrupt_or_stale_file_falls_back_with_no_error(tmp_path, export_to, damage):
    export_to(None)
    plain = _solve()
    export_to(tmp_path)
    _solve()
    known = {path: identity for k in KERNELS for path, identity in k.files.items()}
    files = sorted(known)
    assert files == sorted(tmp_path.glob("*.jaxexp"))
    blobs = {f: f.read_bytes() for f in files}
    for i, f in enumerate(files):
        other = files[(i + 1) % len(files)]  # another kernel's valid file
        if damage == "garbage":
            f.write_bytes(b"\x00\xff" * 100)
        elif damage == "truncated":
            f.write_bytes(blobs[f][: len(blobs[f]) // 2])
        elif damage == "checksum-valid garbage":
            write_exported(f, b"not a serialized program" * 10, known[f])
        elif damage == "stale":  # a file written for another program (another kernel, signature or code version)
            f.write_bytes(blobs[other])
        else:  # another kernel's program framed as this one's (_residual and _tangent take the same inputs)
            write_exported(f, read_exported_bytes(blobs[other]), known[f])
    export_to(tmp_path)
    again = _solve()  # no error
    _same(plain, again)
    for f in files:  # made again: valid files, which a later process reads
        assert read_exported(f, known[f]) is not None
    export_to(tmp_path)
    _same(plain, _solve())


def read_exported_bytes(blob: bytes) -> bytes:
    """The payload of a framed file's bytes (magic line, checksum line, payload)."""
    return blob.split(b"\n", 2)[2]


def test_traced_arguments_and_the_off_switch_take_the_jit_path(tmp_path, monkeypatch):
    kernel = ExportedKernel(lambda x, y, scale=1.0: scale * jnp.sum(jnp.sin(x) * y), static_argnames=("scale",))
    monkeypatch.setattr(jax_cache, "export_dir", lambda: tmp_path)
    monkeypatch.setattr(jax_cache, "_exports_off", lambda: False)
    x, y = np.linspace(0, 1, 5), np.arange(5.0)
    assert float(kernel(x, y, scale=2.0)) == float(kernel.jitted(x, y, scale=2.0))
    assert len(list(tmp_path.glob("*.jaxexp"))) == 1
    # inside a transformation the arguments are tracers: the jit path (an exported program has no derivative)
    np.testing.assert_allclose(jax.grad(kernel)(x, y), np.cos(x) * y, rtol=1e-14)
    np.testing.assert_allclose(jax.vmap(kernel, in_axes=(0, None))(np.stack([x, 2 * x]), y),
                               [kernel.jitted(x, y), kernel.jitted(2 * x, y)], rtol=1e-14)
    # another shape is another program; another static value too
    kernel(np.ones(3), np.ones(3))
    kernel(x, y, scale=3.0)
    assert len(list(tmp_path.glob("*.jaxexp"))) == 3
    monkeypatch.undo()
    monkeypatch.setenv(jax_cache.EXPORT_ENV, "0")
    assert jax_cache.export_dir() is None and jax_cache._exports_off()


def test_the_file_name_follows_the_code_version(tmp_path, monkeypatch):
    @exported_kernel
    def kernel(x):
        return x * 2

    key = ("tree", (), (((3,), "float64", False),))
    name = kernel.file_for(tmp_path, key)
    monkeypatch.setattr(jax_cache, "_CODE_VERSION", ["lvcore 0.0.0+src.other"])
    assert kernel.file_for(tmp_path, key) != name
    assert jax_cache.code_version() == "lvcore 0.0.0+src.other"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(blob=st.binary(max_size=400), framed=st.booleans())
def test_fuzz_any_file_content_is_read_or_refused_and_the_kernel_still_runs(tmp_path, monkeypatch, blob, framed):
    kernel = ExportedKernel(lambda x: jnp.cumsum(x) * 3.0)
    monkeypatch.setattr(jax_cache, "export_dir", lambda: tmp_path)
    monkeypatch.setattr(jax_cache, "_exports_off", lambda: False)
    x = np.arange(4.0)
    key = kernel.signature((x,), {})
    path, identity = kernel.file_for(tmp_path, key), kernel.identity(key)
    if framed:
        write_exported(path, blob, identity)
        assert read_exported(path, identity) == blob
        assert read_exported(path, identity + " of another program") is None
    else:
        path.write_bytes(blob)
        assert read_exported(path, identity) is None  # random bytes never pass the checksum
    np.testing.assert_array_equal(kernel(x), np.cumsum(x) * 3.0)
    assert read_exported(path, identity) is not None  # made again where it could not be used


def test_the_folder_keeps_the_most_recent_programs(tmp_path):
    for k in range(7):
        f = tmp_path / f"k{k}.jaxexp"
        write_exported(f, b"x" * k, f"identity {k}")
        os.utime(f, ns=(k * 10**9, k * 10**9))  # written in this order
    assert jax_cache.prune_exported(tmp_path, keep=3) == 4
    assert sorted(p.name for p in tmp_path.glob("*.jaxexp")) == ["k4.jaxexp", "k5.jaxexp", "k6.jaxexp"]
    assert jax_cache.prune_exported(tmp_path, keep=3) == 0
