"""Sizes that files declare about themselves, checked before any reader allocates.

A 200-byte PLY file can declare 10⁹ vertices, a ``.npy`` header a 30 GB
array, a ``.msh`` file 10⁹ nodes: the readers (VTK, meshio, numpy) trust such
numbers and allocate them before they find that the data are not there. This
module reads only the headers (a few kB, never the whole file into arrays),
and refuses

* a count above the caps of :mod:`lvcore.safety.limits`
  (:data:`~lvcore.safety.limits.MAX_DECLARED_POINTS`,
  :data:`~lvcore.safety.limits.MAX_DECLARED_CELLS`,
  :data:`~lvcore.safety.limits.MAX_ARRAY_BYTES`), and
* a count whose data cannot fit in the file: each declared item needs at
  least a known number of bytes (2 per ASCII number, the type's size in a
  binary file), so ``count x bytes > file size`` means the header lies.

:func:`check_mesh_header` covers PLY, OBJ (face indices against the vertex
count), legacy and XML VTK, gmsh ``.msh`` (v2 and v4), binary STL and OFF;
other formats pass unchecked (their parsing still runs in a memory-limited
child process, :mod:`lvcore.safety.isolation`). :func:`load_npy` and
:func:`load_npz` check every array header and then load with
``allow_pickle=False``. Every refusal names the file and the declared count.
"""
from __future__ import annotations

import math
import re
import struct
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np

from lvcore.safety import limits
from lvcore.exceptions import LimitError, LVCoreError

#: Most bytes read to find a text header (PLY ``end_header``, the first lines of VTK/OFF/MSH).
HEADER_SCAN_BYTES = 64 * 1024

#: Bytes of one value of each binary type name used by PLY and legacy VTK.
_TYPE_BYTES = {
    "char": 1, "uchar": 1, "int8": 1, "uint8": 1, "bit": 1, "unsigned_char": 1,
    "short": 2, "ushort": 2, "int16": 2, "uint16": 2, "unsigned_short": 2,
    "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "unsigned_int": 4,
    "long": 8, "unsigned_long": 8, "double": 8, "float64": 8, "int64": 8, "uint64": 8,
    "vtktypeint64": 8, "vtktypeuint64": 8, "vtkidtype": 8,
}
#: Fewest bytes of one ASCII number ("0" and a separator).
_ASCII_BYTES = 2


def _fail(error, message):
    raise (error or LimitError)(message)


def _count(text: str, what: str, path, error) -> int:
    try:
        n = int(text)
    except (TypeError, ValueError):
        _fail(error, f"{what} '{path}': header count '{str(text)[:40]}' is not an integer")
    if n < 0:
        _fail(error, f"{what} '{path}': header declares a negative count ({n})")
    return n


def _check_cap(n: int, cap: int, noun: str, what: str, path, error, const: str) -> None:
    if n > cap:
        _fail(error, f"{what} '{path}' declares {n:,} {noun}, more than the limit of {cap:,} "
                     f"(lvcore.safety.limits.{const}); the file is damaged or not an LV mesh")


def _check_fits(need: int, have: int, detail: str, what: str, path, error) -> None:
    if need > have:
        _fail(error, f"{what} '{path}' declares {detail}, which needs at least {need:,} bytes, but the file "
                     f"has {have:,}; the header is wrong or the file is truncated")


def _head(path: Path, n: int = HEADER_SCAN_BYTES) -> bytes:
    with open(path, "rb") as f:
        return f.read(n)


# ----------------------------------------------------------------------------- meshes
def check_mesh_header(path, what: str = "mesh file", error: Callable[[str], Exception] | None = None) -> None:
    """Refuse a mesh file whose header declares more than the limits or than the file can hold.

    Parameters
    ----------
    path : str or Path
        A regular file (check it with :func:`lvcore.safety.limits.check_regular_file` first).
    what : str
        What the file is, for messages (e.g. ``"endo surface file"``).
    error : callable, optional
        ``error(message) -> exception`` (default :class:`~lvcore.exceptions.LimitError`).

    Raises
    ------
    LimitError (or ``error(message)``)
        Naming the file, the declared count and the limit.
    """
    path = Path(path)
    size = path.stat().st_size
    suffix = path.suffix.lower()
    head = _head(path)
    checker = {".ply": _ply, ".obj": _obj, ".vtk": _vtk_legacy, ".msh": _msh, ".stl": _stl, ".off": _off,
               ".vtu": _vtk_xml, ".vtp": _vtk_xml, ".vts": _vtk_xml, ".vtr": _vtk_xml, ".vti": _vtk_xml}.get(suffix)
    if checker is None:  # sniff: files are often misnamed
        if head.startswith(b"ply"):
            checker = _ply
        elif head.startswith(b"# vtk DataFile"):
            checker = _vtk_legacy
        elif head.startswith(b"$MeshFormat"):
            checker = _msh
        elif b"<VTKFile" in head[:1024]:
            checker = _vtk_xml
    if checker is not None:
        checker(path, head, size, what, error)


def _ply(path, head, size, what, error):
    if not head.startswith(b"ply"):
        return  # not PLY: the reader reports it
    end = head.find(b"end_header")
    if end < 0:
        _fail(error, f"{what} '{path}': PLY header has no 'end_header' in its first {HEADER_SCAN_BYTES // 1024} kB")
    lines = head[:end].decode("latin-1").splitlines()
    data_start = head.find(b"\n", end)
    data_bytes = size - (data_start + 1 if data_start >= 0 else size)
    ascii_fmt = True
    elements: list[list] = []  # [name, count, min_bytes_per_item]
    for line in lines:
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "format" and len(tok) > 1:
            ascii_fmt = tok[1] == "ascii"
        elif tok[0] == "element" and len(tok) >= 3:
            elements.append([tok[1], _count(tok[2], what, path, error), 0])
        elif tok[0] == "property" and elements and len(tok) >= 3:
            if tok[1] == "list" and len(tok) >= 5:
                nbytes = _ASCII_BYTES if ascii_fmt else _TYPE_BYTES.get(tok[2], 1)
            else:
                nbytes = _ASCII_BYTES if ascii_fmt else _TYPE_BYTES.get(tok[1], 1)
            elements[-1][2] += nbytes
    need = 0
    for name, n, per in elements:
        if name == "vertex":
            _check_cap(n, limits.MAX_DECLARED_POINTS, "vertices", what, path, error, "MAX_DECLARED_POINTS")
        else:
            _check_cap(n, limits.MAX_DECLARED_CELLS, f"'{name[:40]}' elements", what, path, error,
                       "MAX_DECLARED_CELLS")
        need += n * max(per, 1)
    if elements:
        detail = ", ".join(f"{n:,} {name[:40]}" for name, n, _ in elements)
        _check_fits(need - (1 if ascii_fmt else 0), max(data_bytes, 0), detail, what, path, error)


_OBJ_FACE = re.compile(rb"^[ \t]*([fpl])[ \t]+([^\r\n#]*)", re.M)


def _obj(path, head, size, what, error):
    data = path.read_bytes()  # within MAX_SURFACE_BYTES (checked before)
    n_v = len(re.findall(rb"(?m)^[ \t]*v[ \t]", data))
    _check_cap(n_v, limits.MAX_DECLARED_POINTS, "vertices", what, path, error, "MAX_DECLARED_POINTS")
    n_f = 0
    # vertices defined so far, for negative (relative) indices
    v_pos = [m.start() for m in re.finditer(rb"(?m)^[ \t]*v[ \t]", data)]
    for m in _OBJ_FACE.finditer(data):
        n_f += 1
        before = None
        for tok in m.group(2).split():
            first = tok.split(b"/", 1)[0]
            try:
                idx = int(first)
            except ValueError:
                _fail(error, f"{what} '{path}': face entry '{tok[:40].decode('latin-1')}' is not a vertex index")
            if idx == 0:
                _fail(error, f"{what} '{path}': face index 0 (OBJ indices start at 1)")
            if idx > 0 and idx > n_v:
                _fail(error, f"{what} '{path}': a face refers to vertex {idx:,} but the file has {n_v:,} vertices; the file is damaged: export the surface again")
            if idx < 0:
                if before is None:
                    before = int(np.searchsorted(v_pos, m.start()))
                if -idx > before:
                    _fail(error, f"{what} '{path}': a face refers to vertex {idx:,} (relative) but only {before:,} "
                                 "vertices precede it")
    _check_cap(n_f, limits.MAX_DECLARED_CELLS, "faces", what, path, error, "MAX_DECLARED_CELLS")


_VTK_KEY = re.compile(rb"(?m)^[ \t]*(POINTS|CELLS|POLYGONS|VERTICES|LINES|TRIANGLE_STRIPS|CELL_TYPES|POINT_DATA|"
                      rb"CELL_DATA|DIMENSIONS)[ \t]+([^\r\n]{0,200})")


def _vtk_legacy(path, head, size, what, error):
    if not head.startswith(b"# vtk DataFile"):
        return
    lines = head.split(b"\n", 3)
    binary = len(lines) > 2 and lines[2].strip().upper().startswith(b"BINARY")
    data = path.read_bytes()  # within the size limit of its kind (checked before)
    for m in _VTK_KEY.finditer(data):
        key = m.group(1).decode()
        tok = m.group(2).decode("latin-1").split()
        if not tok:
            continue
        if key == "DIMENSIONS":
            dims = [_count(t, what, path, error) for t in tok[:3]]
            n = math.prod(dims)
            _check_cap(n, limits.MAX_DECLARED_POINTS, "grid points (DIMENSIONS)", what, path, error,
                       "MAX_DECLARED_POINTS")
            continue
        n = _count(tok[0], what, path, error)
        if key in ("POINTS", "POINT_DATA"):
            _check_cap(n, limits.MAX_DECLARED_POINTS, f"points ({key})", what, path, error, "MAX_DECLARED_POINTS")
        else:
            _check_cap(n, limits.MAX_DECLARED_CELLS, f"cells ({key})", what, path, error, "MAX_DECLARED_CELLS")
        per = _TYPE_BYTES.get(tok[1].lower(), 1) if binary and len(tok) > 1 else (1 if binary else _ASCII_BYTES)
        if key == "POINTS":
            _check_fits(3 * n * per - 1, size, f"{n:,} points", what, path, error)
        elif key in ("CELLS", "POLYGONS", "VERTICES", "LINES", "TRIANGLE_STRIPS") and len(tok) > 1:
            total = _count(tok[1], what, path, error)
            _check_cap(total, 16 * limits.MAX_DECLARED_CELLS, f"connectivity entries ({key})", what, path, error,
                       "MAX_DECLARED_CELLS")
            _check_fits(total * (4 if binary else _ASCII_BYTES) - 1, size, f"{total:,} {key} entries",
                        what, path, error)
        elif key == "CELL_TYPES":
            _check_fits(n * (4 if binary else _ASCII_BYTES) - 1, size, f"{n:,} cell types", what, path, error)


_XML_COUNT = re.compile(rb'NumberOf(Points|Cells|Polys|Verts|Lines|Strips)\s*=\s*"\s*(-?\d{1,40})\s*"')


def _vtk_xml(path, head, size, what, error):
    data = path.read_bytes()
    for m in _XML_COUNT.finditer(data):
        key, n = m.group(1).decode(), _count(m.group(2).decode(), what, path, error)
        if key == "Points":
            _check_cap(n, limits.MAX_DECLARED_POINTS, "points (NumberOfPoints)", what, path, error,
                       "MAX_DECLARED_POINTS")
        else:
            _check_cap(n, limits.MAX_DECLARED_CELLS, f"cells (NumberOf{key})", what, path, error, "MAX_DECLARED_CELLS")


def _msh(path, head, size, what, error):
    if not head.lstrip().startswith(b"$MeshFormat"):
        return
    data = path.read_bytes()
    for section, cap, const, noun, per in (("Nodes", limits.MAX_DECLARED_POINTS, "MAX_DECLARED_POINTS", "nodes", 6),
                                           ("Elements", limits.MAX_DECLARED_CELLS, "MAX_DECLARED_CELLS", "elements", 4)):
        for m in re.finditer(rb"(?m)^\$" + section.encode() + rb"[ \t]*\r?\n([^\r\n]{0,200})", data):
            tok = m.group(1).decode("latin-1").split()
            if not tok:
                continue
            nums = [_count(t, what, path, error) for t in tok[:4]]
            if len(nums) >= 2:  # v4: numEntityBlocks numItems minTag maxTag
                _check_cap(nums[0], cap, f"{noun[:-1]} blocks", what, path, error, const)
                total = nums[1]
                if len(nums) >= 4:
                    _check_cap(nums[3], cap, f"as the largest {noun[:-1]} tag", what, path, error, const)
            else:  # v2: numItems
                total = nums[0]
            _check_cap(total, cap, noun, what, path, error, const)
            _check_fits(total * per, size, f"{total:,} {noun}", what, path, error)


def _stl(path, head, size, what, error):
    if len(head) < 84 or (head[:5].lower() == b"solid" and b"\x00" not in head[:512]):
        return  # ASCII STL: no declared count
    (n,) = struct.unpack("<I", head[80:84])
    if n > limits.MAX_DECLARED_CELLS or 84 + 50 * n > size:
        _fail(error, f"{what} '{path}' is not a valid STL file: an ASCII STL starts with 'solid', and read as a binary "
                     f"STL it declares {n:,} triangles ({84 + 50 * n:,} bytes) in {size:,} bytes (limit "
                     f"{limits.MAX_DECLARED_CELLS:,} triangles, lvcore.safety.limits.MAX_DECLARED_CELLS); export the "
                     "surface again as STL, VTK, PLY or OBJ")


def _off(path, head, size, what, error):
    lines = [ln.split(b"#", 1)[0].strip() for ln in head.split(b"\n")[:50]]
    lines = [ln for ln in lines if ln]
    if not lines or not lines[0].upper().endswith(b"OFF"):
        return
    tok = (lines[0][lines[0].upper().rfind(b"OFF") + 3:].split() or (lines[1].split() if len(lines) > 1 else []))
    if len(tok) < 2:
        return
    nv, nf = _count(tok[0].decode("latin-1"), what, path, error), _count(tok[1].decode("latin-1"), what, path, error)
    _check_cap(nv, limits.MAX_DECLARED_POINTS, "vertices", what, path, error, "MAX_DECLARED_POINTS")
    _check_cap(nf, limits.MAX_DECLARED_CELLS, "faces", what, path, error, "MAX_DECLARED_CELLS")
    _check_fits((3 * nv + 4 * nf) * _ASCII_BYTES - 1, size, f"{nv:,} vertices and {nf:,} faces", what, path, error)


# ----------------------------------------------------------------------------- arrays
def _npy_header(fp, what: str, where: str, error) -> tuple[tuple[int, ...], np.dtype, int]:
    """(shape, dtype, nbytes) from the header of a .npy stream (the stream is left after the header)."""
    from numpy.lib import format as npformat

    try:
        version = npformat.read_magic(fp)
        if version == (1, 0):
            shape, _fortran, dtype = npformat.read_array_header_1_0(fp)
        elif version == (2, 0):
            shape, _fortran, dtype = npformat.read_array_header_2_0(fp)
        else:
            shape, _fortran, dtype = npformat._read_array_header(fp, version)  # noqa: SLF001 - v3.0 has no public reader
    except (ValueError, SyntaxError, TypeError, EOFError, OSError, struct.error) as err:
        _fail(error, f"{what} '{where}' does not have a valid .npy header ({type(err).__name__}: {str(err)[:200]})")
    if dtype.hasobject:
        _fail(error, f"{what} '{where}' holds Python objects (pickled data), which lvcore never loads; "
                     "save numeric arrays")
    if any(int(s) < 0 for s in shape):
        _fail(error, f"{what} '{where}': negative dimension in shape {shape}")
    nbytes = math.prod(int(s) for s in shape) * int(dtype.itemsize)
    if nbytes > limits.MAX_ARRAY_BYTES:
        _fail(error, f"{what} '{where}' declares an array of shape {tuple(shape)[:8]} ({dtype}), "
                     f"{nbytes / 1024 ** 3:.1f} GB, more than the limit of {limits.MAX_ARRAY_BYTES // limits.MiB} MB "
                     "(lvcore.safety.limits.MAX_ARRAY_BYTES); the file is damaged or not an lvcore array")
    return tuple(int(s) for s in shape), dtype, nbytes


def check_npy(path, what: str = "array file", error: Callable[[str], Exception] | None = None) -> None:
    """Refuse a ``.npy`` file whose header declares an over-limit array or more data than the file holds."""
    path = Path(path)
    size = path.stat().st_size
    with open(path, "rb") as fp:
        shape, dtype, nbytes = _npy_header(fp, what, str(path), error)
        offset = fp.tell()
    _check_fits(nbytes, size - offset, f"an array of shape {shape[:8]} ({dtype})", what, path, error)


def check_npz(path, what: str = "array archive", error: Callable[[str], Exception] | None = None) -> None:
    """Refuse a ``.npz`` archive with too many members or a member whose header declares too much.

    Each member's declared array must fit in the member's uncompressed size
    (recorded in the zip directory, which :mod:`zipfile` enforces on reading)
    and below :data:`~lvcore.safety.limits.MAX_ARRAY_BYTES`; their sum too.
    """
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            if len(infos) > limits.MAX_NPZ_MEMBERS:
                _fail(error, f"{what} '{path}' holds {len(infos):,} members, more than the limit of "
                             f"{limits.MAX_NPZ_MEMBERS} (lvcore.safety.limits.MAX_NPZ_MEMBERS)")
            total = 0
            for info in infos:
                where = f"{path}' member '{info.filename[:80]}"
                if info.file_size > limits.MAX_ARRAY_BYTES:
                    _fail(error, f"{what} '{where}' is {info.file_size / 1024 ** 3:.1f} GB uncompressed, more than "
                                 f"the limit of {limits.MAX_ARRAY_BYTES // limits.MiB} MB (lvcore.safety.limits.MAX_ARRAY_BYTES)")
                if not info.filename.endswith(".npy"):
                    continue
                with zf.open(info) as fp:
                    shape, dtype, nbytes = _npy_header(fp, what, where, error)
                    offset = fp.tell()
                _check_fits(nbytes, info.file_size - offset, f"an array of shape {shape[:8]} ({dtype})", what,
                            where, error)
                total += nbytes
            if total > limits.MAX_ARRAY_BYTES:
                _fail(error, f"{what} '{path}' declares {total / 1024 ** 2:.0f} MB of arrays in all, more than the "
                             f"limit of {limits.MAX_ARRAY_BYTES // limits.MiB} MB (lvcore.safety.limits.MAX_ARRAY_BYTES)")
    except LVCoreError:
        raise
    except zipfile.BadZipFile as err:
        _fail(error, f"{what} '{path}' is not a valid .npz (zip) archive ({str(err)[:200]})")
    except (OSError, EOFError, ValueError, NotImplementedError, RuntimeError) as err:
        _fail(error, f"{what} '{path}' cannot be read as an .npz archive ({type(err).__name__}: {str(err)[:200]})")


def load_npy(path, max_bytes: int, what: str, error: Callable[[str], Exception] | None = None) -> np.ndarray:
    """Load a ``.npy`` file after :func:`lvcore.safety.limits.check_regular_file` and :func:`check_npy`.

    Raises ``error`` (default :class:`LimitError`) for every problem, naming the file.
    """
    path = limits.check_regular_file(path, max_bytes, what, error)
    check_npy(path, what, error)
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, TypeError) as err:
        _fail(error, f"{what} '{path}' cannot be read ({type(err).__name__}: {str(err)[:200]})")


def load_npz(path, max_bytes: int, what: str, error: Callable[[str], Exception] | None = None,
             keys=None) -> dict[str, np.ndarray]:
    """Load the arrays of a ``.npz`` archive (all, or ``keys``) after checking every header.

    Raises ``error`` (default :class:`LimitError`) for every problem, naming the
    file; a missing key names the keys present.
    """
    path = limits.check_regular_file(path, max_bytes, what, error)
    check_npz(path, what, error)
    try:
        with np.load(path, allow_pickle=False) as z:
            names = list(z.files)
            if keys is not None:
                missing = [k for k in keys if k not in names]
                if missing:
                    _fail(error, f"{what} '{path}' lacks the array(s) {missing} (it holds {names[:20]})")
                names = list(keys)
            return {k: z[k] for k in names}
    except LVCoreError:
        raise
    except (ValueError, OSError, EOFError, TypeError, KeyError, zipfile.BadZipFile, NotImplementedError) as err:
        _fail(error, f"{what} '{path}' cannot be read ({type(err).__name__}: {str(err)[:200]})")


__all__ = ["check_mesh_header", "check_npy", "check_npz", "load_npy", "load_npz"]
