"""Declared sizes in file headers are refused before any reader allocates (issue 28, finding 1).

Every reproduction of a crash or a huge allocation runs in a child process
under ``ulimit -v`` (about 2 GB, :func:`hostile_files.run_limited`): before the
header checks these children died by SIGABRT/SIGSEGV or raised MemoryError;
now they print the lvcore error that names the file.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

import hostile_files as hf
from lvcore.safety import limits
from lvcore.exceptions import EmulatorError, GeometryError, LimitError
from lvcore.safety.headers import check_mesh_header, check_npy, check_npz, load_npy, load_npz


def _write(tmp_path, name, data: bytes):
    p = tmp_path / name
    p.write_bytes(data)
    return p


def _child_reads(tmp_path, name, data, call):
    """Write the file, run ``call`` on it in a memory-capped child; return (returncode, stdout+stderr)."""
    p = _write(tmp_path, name, data)
    code = ("import sys\nfrom lvcore.exceptions import LVCoreError\n"
            f"path = {str(p)!r}\n"
            "try:\n"
            f"    {call}\n"
            "    print('READ')\n"
            "except LVCoreError as err:\n"
            "    print('LVCOREERROR', type(err).__name__, err)\n")
    res = hf.run_limited(code)
    return res.returncode, res.stdout + res.stderr


# ----------------------------------------------------------------------------- meshes (through the real readers)
@pytest.mark.parametrize("name, data, noun", [
    ("endo.ply", hf.huge_ply(), "1,000,000,000 vertices"),
    ("endo.obj", hf.far_face_obj(), "vertex 1,000,000,000"),
    ("endo.vtk", hf.huge_vtk(), "1,000,000,000 points"),
])
def test_surface_files_declaring_huge_counts_are_refused_not_crashing(tmp_path, name, data, noun):
    """The 200-byte PLY (SIGABRT, exit 134) and 40-byte OBJ (SIGSEGV, exit 139) of the issue: now a GeometryError."""
    rc, out = _child_reads(tmp_path, name, data,
                           "from lvcore.geometry.surfaces import read_surface; read_surface(path, 'endo')")
    assert rc == 0, out[-2000:]
    assert "LVCOREERROR GeometryError" in out and name in out and noun in out


def test_msh_declaring_a_billion_nodes_is_refused(tmp_path):
    rc, out = _child_reads(tmp_path, "lv.msh", hf.huge_msh(),
                           "from lvcore.geometry.volume_mesh import read_volume_cells; read_volume_cells(path)")
    assert rc == 0, out[-2000:]
    assert "LVCOREERROR GeometryError" in out and "1,000,000,000 nodes" in out and "lv.msh" in out


def test_header_checks_in_process(tmp_path):
    for name, data in (("a.ply", hf.huge_ply()), ("a.obj", hf.far_face_obj()), ("a.vtk", hf.huge_vtk()),
                       ("a.msh", hf.huge_msh())):
        with pytest.raises(LimitError, match=name):
            check_mesh_header(_write(tmp_path, name, data))
    # a PLY declaring more than it holds (under the cap) is refused by its size
    ply = hf.huge_ply().replace(b"1000000000", b"4000000")
    with pytest.raises(LimitError, match="needs at least"):
        check_mesh_header(_write(tmp_path, "b.ply", ply))
    # a binary STL whose triangle count does not match its length
    stl = b"\x00" * 80 + (10 ** 6).to_bytes(4, "little") + b"\x00" * 50
    with pytest.raises(LimitError, match="STL"):
        check_mesh_header(_write(tmp_path, "c.stl", stl))
    # negative OBJ index beyond the vertices before it, and index 0
    with pytest.raises(LimitError, match="relative"):
        check_mesh_header(_write(tmp_path, "d.obj", b"v 0 0 0\nf -1 -2 -3\n"))
    with pytest.raises(LimitError, match="start at 1"):
        check_mesh_header(_write(tmp_path, "e.obj", b"v 0 0 0\nf 0 1 1\n"))


def test_valid_meshes_pass_the_header_checks(tmp_path):
    import meshio

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    mesh = meshio.Mesh(pts, [("triangle", np.array([[0, 1, 2], [0, 1, 3]]))])
    for suffix in (".ply", ".obj", ".vtk", ".stl", ".vtu", ".off"):
        p = tmp_path / f"ok{suffix}"
        meshio.write(p, mesh)
        check_mesh_header(p)
    tet = meshio.Mesh(pts, [("tetra", np.array([[0, 1, 2, 3]]))])
    for fmt in ("gmsh22", "gmsh"):
        p = tmp_path / f"ok_{fmt}.msh"
        meshio.write(p, tet, file_format=fmt, binary=False)
        check_mesh_header(p)


# ----------------------------------------------------------------------------- arrays
def test_npy_and_npz_headers_declaring_40_gb_are_refused(tmp_path):
    npy = _write(tmp_path, "nodes.npy", hf.npy_header(hf.HUGE_SHAPE))
    with pytest.raises(LimitError, match="MAX_ARRAY_BYTES"):
        check_npy(npy)
    npz = _write(tmp_path, "a.npz", hf.npz_of({"nodes": hf.npy_header(hf.HUGE_SHAPE)}))
    with pytest.raises(GeometryError, match="a.npz"):
        load_npz(npz, limits.MAX_MESH_BYTES, "geometry file", GeometryError)
    # under the cap, but more than the file holds
    small = _write(tmp_path, "b.npy", hf.npy_header((1000, 1000)))
    with pytest.raises(LimitError, match="needs at least 8,000,000 bytes"):
        load_npy(small, limits.MAX_MESH_BYTES, "geometry file")
    with pytest.raises(LimitError, match="needs at least"):
        check_npz(_write(tmp_path, "c.npz", hf.npz_of({"x": hf.npy_header((1000, 1000))})))
    # pickled object arrays are refused from the header
    with pytest.raises(LimitError, match="Python objects"):
        check_npy(_write(tmp_path, "o.npy", hf.npy_header((3,), dtype="|O")))
    # a valid archive loads
    ok = tmp_path / "ok.npz"
    np.savez_compressed(ok, a=np.arange(6.0).reshape(2, 3), b=np.zeros(3, dtype=np.int32))
    arrays = load_npz(ok, limits.MAX_MESH_BYTES, "x")
    assert arrays["a"].shape == (2, 3) and arrays["b"].dtype == np.int32
    with pytest.raises(LimitError, match=r"lacks the array\(s\) \['c'\]"):
        load_npz(ok, limits.MAX_MESH_BYTES, "x", keys=("a", "c"))


def test_geometry_npy_declaring_40_gb_is_a_geometry_error(tmp_path):
    """``read_pc_scores`` of a template-node .npy (was MemoryError of 37 GiB, exit 3)."""
    rc, out = _child_reads(tmp_path, "nodes.npy", hf.npy_header(hf.HUGE_SHAPE),
                           "from lvcore.inference.calibrate import read_pc_scores; read_pc_scores(path)")
    assert rc == 0, out[-2000:]
    assert "LVCOREERROR GeometryError" in out and "nodes.npy" in out


def test_shape_model_npz_declaring_40_gb_is_a_geometry_error(tmp_path):
    from lvcore.geometry.shape_model import BUNDLED_MODEL

    meta = json.loads(BUNDLED_MODEL.with_suffix(".json").read_text())
    (tmp_path / "m.json").write_text(json.dumps(meta))
    rc, out = _child_reads(tmp_path, "m.npz", hf.npz_of({"mean": hf.npy_header(hf.HUGE_SHAPE)}),
                           "from lvcore.geometry.shape_model import load_shape_model; load_shape_model(path)")
    assert rc == 0, out[-2000:]
    assert "LVCOREERROR GeometryError" in out and "m.npz" in out


def test_emulator_network_declaring_40_gb_is_an_emulator_error(tmp_path):
    from lvcore.emulator.io import resolve_emulator_dir

    src = resolve_emulator_dir("chapter")
    d = tmp_path / "emu"
    d.mkdir()
    (d / "metadata.json").write_text((src / "metadata.json").read_text())
    (d / "network.npz").write_bytes(hf.npz_of({"w0": hf.npy_header(hf.HUGE_SHAPE)}))
    rc, out = _child_reads(tmp_path, "unused", b"x",
                           f"from lvcore.emulator.io import load_emulator; load_emulator({str(d)!r})")
    assert rc == 0, out[-2000:]
    assert "LVCOREERROR EmulatorError" in out and "network.npz" in out
    assert EmulatorError  # the class the CLI maps to exit 2
