"""HOSTILE TEST FILES (issue 28): small files whose headers declare huge sizes.

Each function returns the bytes of a file of a few hundred bytes at most that
made a reader allocate gigabytes (or crash) before lvcore checked headers.
:func:`run_limited` runs Python code in a child with its address space
capped (``ulimit -v``), so a test that reproduces a crash can never take the
shared machine's memory, whatever the code under test does.
"""
from __future__ import annotations

import io
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np

from lvcore.execution.parallel import pin_threads

ROOT = Path(__file__).resolve().parents[1]
#: Address-space cap of :func:`run_limited` (KiB for ``ulimit -v``): about 2 GB.
LIMIT_KB = 2_000_000


def huge_ply() -> bytes:
    """A PLY (169 bytes) declaring 10⁹ vertices: VTK aborted with std::bad_alloc (SIGABRT)."""
    return (b"ply\nformat ascii 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\n"
            b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n")


def far_face_obj() -> bytes:
    """An OBJ (33 bytes) whose face refers to vertex 10⁹: VTK read out of bounds (SIGSEGV)."""
    return b"v 0 0 0\nv 1 0 0\nf 1 2 1000000000\n"


def huge_vtk() -> bytes:
    """A legacy VTK declaring 10⁹ points."""
    return b"# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 1000000000 float\n0 0 0\n"


def huge_msh() -> bytes:
    """A gmsh 2.2 file declaring 10⁹ nodes."""
    return (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1000000000\n1 0 0 0\n$EndNodes\n"
            b"$Elements\n1\n1 4 2 0 1 1 1 1 1\n$EndElements\n")


def npy_header(shape, dtype="<f8") -> bytes:
    """A .npy file that is only a header declaring ``shape`` (no data)."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": dtype, "fortran_order": False, "shape": tuple(shape)})
    return buf.getvalue() + b"\x00" * 16


def npz_of(members: dict) -> bytes:
    """A .npz archive of raw .npy member bytes ``{name: bytes}``."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, data in members.items():
            zf.writestr(name + ".npy", data)
    return buf.getvalue()


#: Shape of a 40 GB float64 array.
HUGE_SHAPE = (100_000, 50_000)


def run_limited(code: str, limit_kb: int = LIMIT_KB, timeout: float = 240.0) -> subprocess.CompletedProcess:
    """Run ``python -c code`` under ``ulimit -v limit_kb`` with this checkout first on the path."""
    env = pin_threads(dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
                           JAX_PLATFORMS="cpu"), force=True)
    script = f"ulimit -v {int(limit_kb)}; exec \"$0\" -c \"$1\""
    return subprocess.run(["bash", "-c", script, sys.executable, code], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=str(ROOT))
