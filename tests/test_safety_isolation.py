"""Parsers run in a memory-limited child: crashes, memory and time become errors naming the file (issue 28)."""
from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

import hostile_files as hf
from lvcore.exceptions import CaseError, GeometryError
from lvcore.safety.isolation import run_isolated


def _returns(x):
    return {"x": np.arange(x, dtype=float)}


def _segfault():
    os.kill(os.getpid(), signal.SIGSEGV)


def _allocate(n_bytes):
    return np.ones(n_bytes // 8).sum()


def _raises_geometry_error():
    raise GeometryError("endo surface 'x.ply' has no cells")


def _raises_case_error():
    raise CaseError("material.a", "must be positive")


def _sleeps():
    time.sleep(60)


def test_result_comes_back():
    out = run_isolated(_returns, 5, what="test file", path="x")
    np.testing.assert_array_equal(out["x"], np.arange(5.0))


def test_a_crash_becomes_an_error_naming_the_file_and_the_caller_lives():
    with pytest.raises(GeometryError, match=r"endo surface file 'x\.obj' crashed the mesh reader \(SIGSEGV"):
        run_isolated(_segfault, what="endo surface file", path="x.obj", error=GeometryError)
    assert run_isolated(_returns, 2, what="t", path="y")["x"].size == 2


def test_memory_is_capped_in_the_child():
    """4 GB asked in a child allowed 256 MB: an error, and this process never allocates it."""
    with pytest.raises(GeometryError, match="memory"):
        run_isolated(_allocate, 4 * 1024 ** 3, what="mesh", path="m.vtk", error=GeometryError,
                     memory_bytes=256 * 1024 ** 2)


def test_lvcore_errors_are_raised_again_with_their_class():
    with pytest.raises(GeometryError, match="has no cells"):
        run_isolated(_raises_geometry_error, what="t", path="x")
    with pytest.raises(GeometryError, match="must be positive"):  # CaseError cannot be rebuilt from one message
        run_isolated(_raises_case_error, what="t", path="x", error=GeometryError)


def test_timeout_kills_the_child():
    t0 = time.monotonic()
    with pytest.raises(GeometryError, match="took longer than 1 s"):
        run_isolated(_sleeps, what="mesh", path="slow.msh", error=GeometryError, timeout_s=1.0)
    assert time.monotonic() - t0 < 30


def test_vtk_crashes_of_the_issue_are_contained(tmp_path):
    """The two files that killed the process (VTK's SIGABRT and SIGSEGV), parsed without the header check."""
    from lvcore.geometry.surfaces import _read_surface

    for name, data, sig in (("endo.ply", hf.huge_ply(), "SIGABRT"), ("endo.obj", hf.far_face_obj(), "SIGSEGV")):
        p = tmp_path / name
        p.write_bytes(data)
        with pytest.raises(GeometryError, match=name) as info:
            run_isolated(_read_surface, p, "endo", "mm", what="endo surface file", path=p, error=GeometryError,
                         memory_bytes=1024 ** 3)
        assert sig in str(info.value) or "memory" in str(info.value)
