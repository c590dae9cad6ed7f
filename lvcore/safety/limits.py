"""Resource limits on everything lvcore reads, and the shared safe readers.

Every file lvcore reads from a user (case files, contour stacks, surfaces,
template meshes, measured CSVs, geometry scores, shape models, campaign
stores, designs) goes through :func:`read_regular_file` or
:func:`check_regular_file`, which refuse anything that is not a regular file
(a directory, ``/dev/zero``, a FIFO, a socket) and files larger than the
limit of their kind, *before* reading them. JSON goes through
:func:`loads_json`, which refuses duplicate keys, non-finite numbers
(``NaN``, ``Infinity``, ``1e400``), integers of more than
:data:`MAX_JSON_INT_DIGITS` digits and nesting deeper than
:data:`MAX_JSON_DEPTH`. Mesh sizes are checked by :func:`check_mesh_size`
from the element counts alone, before any array is allocated.

The limits are documented in ``docs/case_schema.md`` and
``docs/reliability.md``; they are generous for real use (see the comments)
and exist so that a hostile or mistaken input is refused in milliseconds
rather than exhausting memory or running for hours.
"""
from __future__ import annotations

import errno
import json
import os
import stat
from pathlib import Path
from typing import Any, Callable

from lvcore.exceptions import LimitError

MiB = 1024 * 1024

# ----------------------------------------------------------------------------- file sizes
#: Case JSON files (the examples are < 1 kB; 1,000 probes are about 40 kB).
MAX_CASE_BYTES = 1 * MiB
#: Contour-stack JSON files (the bundled example is 25 kB; a dense 30-slice stack < 2 MB).
MAX_CONTOUR_BYTES = 8 * MiB
#: Measured-data CSV files (25 numbers per subject: 1 MB is about 4,000 subjects).
MAX_MEASURED_BYTES = 4 * MiB
#: PC-score files (.json/.csv): a handful of numbers.
MAX_SCORES_BYTES = 1 * MiB
#: Template meshes (.vtu/.vtk/.xdmf/.npy/.npz); the bundled volunteers' VTU files are 50 kB.
MAX_MESH_BYTES = 32 * MiB
#: Surface meshes (STL/VTK/PLY/OBJ...): 64 MB is about 1.3 M binary-STL triangles.
MAX_SURFACE_BYTES = 64 * MiB
#: Shape-model files (.json metadata and .npz arrays; the bundled .npz is 1.4 MB).
MAX_SHAPE_MODEL_BYTES = 64 * MiB
#: Emulator files (``metadata.json``, ``network.npz``; the bundled network is 0.4 MB).
MAX_EMULATOR_BYTES = 64 * MiB
#: Study result JSON files (``lvcore study ... --out``, read by ``lvcore report --from``); the bundled ones are < 0.3 MB.
MAX_STUDY_RESULT_BYTES = 64 * MiB
#: Design CSV files (``lvcore design``): 100,000 points of 9 parameters are about 20 MB.
MAX_DESIGN_BYTES = 64 * MiB

# ----------------------------------------------------------------------------- JSON
#: Deepest JSON nesting accepted (a case is 3 levels deep).
MAX_JSON_DEPTH = 64
#: Most digits of a JSON integer (Python refuses > 4300; no field needs > 18).
MAX_JSON_INT_DIGITS = 32

# ----------------------------------------------------------------------------- meshes
#: Most elements of a simulation mesh (the "accurate" preset has 288; 24 x 16 x 4 has 1,536).
MAX_ELEMENTS = 20_000
#: Most degrees of freedom (3 per Q2 node) of a simulation mesh.
MAX_DOFS = 600_000
#: Most quadratic elements along one direction of a mesh.
MAX_ELEMENTS_PER_DIRECTION = 400
#: Estimated peak memory per element of a solve (bytes, 27 Gauss points): the
#: default LV at 12 x 8 x 2 (192 elements) peaked at 665 MB and at 24 x 8 x 2
#: (384) at 819 MB, 0.8 MB per extra element (benchmarks/limits_memory.py),
#: rounded up; used by :func:`estimate_memory_bytes`.
BYTES_PER_ELEMENT = 1.0 * MiB
#: Memory a solve may be estimated to need before it is refused (bytes); at
#: most half of the machine's physical memory.
MAX_SOLVE_MEMORY_BYTES = 16 * 1024 * MiB
#: Most probe points in a case.
MAX_PROBES = 1_000

# ----------------------------------------------------------------------------- geometry and results
#: Smallest reference cavity volume of an LV geometry (mL); Land et al. (2015)'s
#: small ellipsoid has 2.5 mL, an adult LV 50-200 mL. Below it the geometry is degenerate
#: (e.g. a base plane just above the apex) and is refused.
MIN_CAVITY_ML = 0.1
#: Smallest reference wall (myocardium) volume of an LV geometry (mL); Land's ellipsoid has 3.2 mL.
MIN_WALL_ML = 0.1
#: A loaded cavity more than this many times its reference volume is flagged in the
#: result's ``warnings`` (a physiological passive LV stays well below it).
PLAUSIBLE_MAX_STANDARDISED_LVV = 3.0
#: A loaded cavity more than this many times its reference volume is flagged at *any* pressure
#: (:data:`PLAUSIBLE_MAX_STANDARDISED_LVV` applies only at physiological pressures). Land et al.
#: (2015)'s problem 2, a benchmark at 10 kPa, reaches 4.3; a flattened ellipsoid inflated from
#: 2.6 to 187 mL (72 times) at 10 kPa is flagged.
PLAUSIBLE_MAX_STANDARDISED_LVV_ANY_PRESSURE = 5.0
#: A loaded cavity above this volume (mL) is flagged in the result's ``warnings``.
PLAUSIBLE_MAX_LVV_ML = 1000.0
#: A fitted (unloaded) LV cavity above this volume (mL) gets a warning naming ``--units``
#: (a dilated adult LV is below 400 mL; a mm mesh read with ``--units cm`` gives 1000x too much).
PLAUSIBLE_MAX_FITTED_CAVITY_ML = 500.0
#: A fitted base-apex length above this (mm) gets the same warning (adult LVs are 70-110 mm).
PLAUSIBLE_MAX_FITTED_LENGTH_MM = 160.0

# ----------------------------------------------------------------------------- contours
#: Most points in one contour (a 1-mm spaced 60-mm radius epicardium has about 380).
MAX_POINTS_PER_CONTOUR = 4_000
#: Most points in a whole contour stack (slices and long-axis views).
MAX_CONTOUR_POINTS = 100_000
#: Most short-axis slices plus long-axis views in a stack.
MAX_CONTOUR_SLICES = 500

# ----------------------------------------------------------------------------- declared sizes (file headers)
#: Most points (vertices, nodes) a mesh file may declare in its header (lvcore.safety.headers); a 64 MB binary
#: STL holds about 4 M vertex records, a real LV surface or volume mesh well under 1 M.
MAX_DECLARED_POINTS = 5_000_000
#: Most cells (faces, triangles, elements) a mesh file may declare.
MAX_DECLARED_CELLS = 5_000_000
#: Largest array (bytes) a ``.npy`` file or one ``.npz`` member may declare; the bundled
#: arrays are below 2 MB (shape model 1.4 MB, emulator network 0.4 MB).
MAX_ARRAY_BYTES = 256 * MiB
#: Most arrays in one ``.npz`` archive (the shape model has 4, an emulator network about 10).
MAX_NPZ_MEMBERS = 256
#: Most rows of a design and of a campaign store (``lvcore design --n``); 100,000 points of 9
#: parameters are about 20 MB, within :data:`MAX_DESIGN_BYTES`.
MAX_DESIGN_POINTS = 100_000
#: Most values (rows x parameters) of a design, so that every design ``lvcore design`` writes is
#: below :data:`MAX_DESIGN_BYTES` (about 25 bytes per value in the CSV).
MAX_DESIGN_VALUES = 2_000_000
#: Most columns (parameters) of a design or campaign store.
MAX_DESIGN_DIMENSIONS = 64
#: Extra address space (bytes) the child process that parses an untrusted mesh file with VTK or
#: meshio may allocate (lvcore.safety.isolation); a crafted file that asks for more fails there, not in the caller.
MAX_READER_MEMORY_BYTES = 3 * 1024 * MiB
#: Seconds the child process that parses a mesh file may run.
MAX_READER_SECONDS = 120.0

# ----------------------------------------------------------------------------- measured data
#: Most rows (subjects) in a measured-data CSV.
MAX_MEASURED_ROWS = 10_000


#: Most characters of a user's value (a key, a path, an option) repeated in a message.
MAX_ECHO_CHARS = 200


def echo(value, limit: int = MAX_ECHO_CHARS) -> str:
    """``str(value)`` cut to ``limit`` characters (noting the full length), for messages that repeat user input."""
    text = str(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text):,} characters)"


def _human(n: float) -> str:
    if n >= MiB:
        return f"{n / MiB:.1f} MB"
    if n >= 1024:
        return f"{n / 1024:.1f} kB"
    return f"{int(n)} bytes"


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _raise(error: Callable[[str], Exception] | None, message: str):
    raise (error or LimitError)(message)


def check_regular_file(path, max_bytes: int, what: str, error: Callable[[str], Exception] | None = None) -> Path:
    """Check that ``path`` is an existing regular file of at most ``max_bytes`` bytes.

    For readers that hand the path on to a library (meshio, PyVista, h5py,
    pandas). Symbolic links are followed.

    Parameters
    ----------
    path : str or Path
    max_bytes : int
        Largest size accepted (bytes).
    what : str
        What the file is, for the message (e.g. ``"case file"``).
    error : callable, optional
        ``error(message) -> exception`` raised on failure (default :class:`LimitError`).

    Returns
    -------
    Path
    """
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        _raise(error, f"{what} '{echo(path)}' does not exist")
    except NotADirectoryError:
        _raise(error, f"{what} '{echo(path)}' does not exist (a parent is not a directory)")
    except PermissionError:
        _raise(error, f"{what} '{echo(path)}' cannot be read (permission denied)")
    except (OSError, ValueError) as err:
        _raise(error, f"{what} '{echo(path)}' cannot be opened ({getattr(err, 'strerror', None) or err})")
    _check_stat(st, path, max_bytes, what, error)
    return path


def _check_stat(st, path, max_bytes, what, error) -> None:
    if not stat.S_ISREG(st.st_mode):
        _raise(error, f"{what} '{echo(path)}' is not a regular file ({_kind(st.st_mode)}); give a file")
    if st.st_size > max_bytes:
        _raise(error, f"{what} '{echo(path)}' is {_human(st.st_size)}, larger than the limit of {_human(max_bytes)} "
                      "(lvcore.safety.limits); check that it is the right file")
    if st.st_size == 0:
        _raise(error, f"{what} '{echo(path)}' is an empty file")


def read_regular_file(path, max_bytes: int, what: str, error: Callable[[str], Exception] | None = None) -> bytes:
    """Read a whole regular file of at most ``max_bytes`` bytes.

    The file is opened without blocking (a FIFO swapped in after the check
    cannot hang the reader), checked with ``fstat`` on the open descriptor,
    and never read past ``max_bytes``.

    Raises
    ------
    LimitError (or ``error(message)``)
        Missing, not a regular file (directory, device, FIFO, socket), empty,
        larger than ``max_bytes``, or unreadable.
    """
    path = Path(path)
    check_regular_file(path, max_bytes, what, error)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as err:
        if err.errno == errno.ENOENT:
            _raise(error, f"{what} '{echo(path)}' does not exist")
        _raise(error, f"{what} '{echo(path)}' cannot be opened ({err.strerror})")
    try:
        _check_stat(os.fstat(fd), path, max_bytes, what, error)
        chunks, total = [], 0
        while True:
            chunk = os.read(fd, min(1 * MiB, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > max_bytes:
                _raise(error, f"{what} '{echo(path)}' grew past the limit of {_human(max_bytes)} while being read")
    except OSError as err:
        _raise(error, f"{what} '{echo(path)}' cannot be read ({err.strerror})")
    finally:
        os.close(fd)
    return b"".join(chunks)


def read_text_file(path, max_bytes: int, what: str, error: Callable[[str], Exception] | None = None) -> str:
    """:func:`read_regular_file` decoded as UTF-8 (a byte-order mark is dropped); binary files are refused."""
    data = read_regular_file(path, max_bytes, what, error)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        _raise(error, f"{what} '{echo(path)}' is not UTF-8 text (byte {err.start} is 0x{data[err.start]:02x}); "
                      "is it a binary file?")
    if "\x00" in text:
        _raise(error, f"{what} '{echo(path)}' contains NUL bytes; is it a binary file?")
    return text


class _JSONProblem(Exception):
    pass


def _pairs(pairs):
    out = {}
    for key, value in pairs:
        if key in out:
            raise _JSONProblem(f"duplicate key '{key}' (every key may appear once per object)")
        out[key] = value
    return out


def _parse_float(s: str) -> float:
    x = float(s)
    if x in (float("inf"), float("-inf")):
        raise _JSONProblem(f"number {s[:20]}{'...' if len(s) > 20 else ''} is too large for a float")
    return x


def _parse_int(s: str) -> int:
    if len(s.lstrip("-")) > MAX_JSON_INT_DIGITS:
        raise _JSONProblem(f"integer of {len(s.lstrip('-'))} digits (at most {MAX_JSON_INT_DIGITS})")
    return int(s)


def _parse_constant(s: str):
    raise _JSONProblem(f"'{s}' is not a number JSON allows; give a finite number")


def _depth(obj) -> int:
    """Nesting depth of parsed JSON (iterative: no recursion)."""
    deepest, stack = 0, [(obj, 1)]
    while stack:
        node, d = stack.pop()
        if isinstance(node, (dict, list)):
            deepest = max(deepest, d)
            stack.extend((v, d + 1) for v in (node.values() if isinstance(node, dict) else node))
    return deepest


def loads_json(text: str, what: str, error: Callable[[str], Exception] | None = None) -> Any:
    """Parse JSON strictly.

    Refuses duplicate keys, ``NaN``/``Infinity``, numbers that overflow a
    float (``1e400``), integers of more than :data:`MAX_JSON_INT_DIGITS`
    digits and nesting deeper than :data:`MAX_JSON_DEPTH`, with a message
    starting with ``what`` (e.g. ``"case file 'x.json'"``).
    """
    try:
        obj = json.loads(text, object_pairs_hook=_pairs, parse_float=_parse_float, parse_int=_parse_int,
                          parse_constant=_parse_constant)
    except _JSONProblem as err:
        _raise(error, f"{what} is not valid for lvcore: {err}")
    except json.JSONDecodeError as err:
        _raise(error, f"{what} is not valid JSON ({err})")
    except RecursionError:
        _raise(error, f"{what} is nested too deeply to be an lvcore file (at most {MAX_JSON_DEPTH} levels)")
    except (ValueError, TypeError) as err:
        _raise(error, f"{what} cannot be parsed as JSON ({type(err).__name__}: {err})")
    if _depth(obj) > MAX_JSON_DEPTH:
        _raise(error, f"{what} is nested more than {MAX_JSON_DEPTH} levels deep; it is not an lvcore file")
    return obj


def read_json_file(path, max_bytes: int, what: str, error: Callable[[str], Exception] | None = None) -> Any:
    """Read a regular file of at most ``max_bytes`` and parse it with :func:`loads_json`."""
    text = read_text_file(path, max_bytes, what, error)
    return loads_json(text, f"{what} '{echo(path)}'", error)


# ----------------------------------------------------------------------------- mesh sizes
def lv_mesh_size(n_circ: int, n_long: int, n_trans: int) -> tuple[int, int]:
    """(elements, dofs) of an LV mesh of quadratic hexahedra (periodic around, apex collapsed)."""
    n_el = n_circ * n_long * n_trans
    nodes = (2 * n_circ) * (2 * n_long + 1) * (2 * n_trans + 1)
    return n_el, 3 * nodes


def box_mesh_size(nx: int, ny: int, nz: int) -> tuple[int, int]:
    """(elements, dofs) of a box mesh of quadratic hexahedra."""
    return nx * ny * nz, 3 * (2 * nx + 1) * (2 * ny + 1) * (2 * nz + 1)


def estimate_memory_bytes(n_elements: int, gauss_points_per_element: int = 27) -> float:
    """Rough peak memory of one solve (bytes), from :data:`BYTES_PER_ELEMENT` (27 Gauss points)."""
    return float(n_elements) * BYTES_PER_ELEMENT * max(1.0, gauss_points_per_element / 27.0)


def mem_available_bytes() -> float:
    """The kernel's ``MemAvailable`` (bytes): memory it can give without swapping; ``inf`` where unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):  # pragma: no cover - non-Linux
        pass
    return float("inf")


def available_memory_bytes() -> float:
    """Memory this process can still get (bytes): the kernel's ``MemAvailable``, and the room left under
    an address-space limit (``ulimit -v``, ``RLIMIT_AS``) if one is set; ``inf`` where neither is known."""
    room = mem_available_bytes()
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            with open("/proc/self/statm") as f:
                used = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
            room = min(room, float(max(soft - used, 0)))
    except (ImportError, OSError, ValueError, IndexError):  # pragma: no cover - non-POSIX
        pass
    return room


def memory_budget_bytes() -> float:
    """Memory a solve may use: the least of :data:`MAX_SOLVE_MEMORY_BYTES`, half the physical memory and
    the memory available now (:func:`available_memory_bytes`: free memory, and an address-space limit)."""
    try:
        phys = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        phys = 2 * MAX_SOLVE_MEMORY_BYTES
    return float(min(MAX_SOLVE_MEMORY_BYTES, 0.5 * phys, available_memory_bytes()))


def check_mesh_size(counts, kind: str = "lv", gauss_points_per_element: int = 27,
                    error: Callable[[str], Exception] | None = None, where: str = "resolution") -> None:
    """Refuse a mesh whose element counts exceed the limits, before anything is allocated.

    Parameters
    ----------
    counts : (n1, n2, n3)
        LV: (circumferential, longitudinal, transmural); box: (nx, ny, nz).
    kind : {"lv", "box"}
    gauss_points_per_element : int
        Quadrature points per element (memory scales with them).
    error : callable, optional
        ``error(message) -> exception``.
    where : str
        Name of the setting, for the message.
    """
    counts = tuple(int(c) for c in counts)
    big = [c for c in counts if c > MAX_ELEMENTS_PER_DIRECTION]
    if big:
        _raise(error, f"{where}: {big[0]} elements along one direction is more than the limit of "
                      f"{MAX_ELEMENTS_PER_DIRECTION} (lvcore.safety.limits.MAX_ELEMENTS_PER_DIRECTION)")
    n_el, dofs = (box_mesh_size if kind == "box" else lv_mesh_size)(*counts)
    shape = " x ".join(str(c) for c in counts)
    if n_el > MAX_ELEMENTS:
        _raise(error, f"{where}: {shape} = {n_el:,} elements is more than the limit of {MAX_ELEMENTS:,} "
                      "(lvcore.safety.limits.MAX_ELEMENTS); use a coarser resolution (the 'accurate' preset has 288)")
    if dofs > MAX_DOFS:
        _raise(error, f"{where}: {shape} has {dofs:,} degrees of freedom, more than the limit of {MAX_DOFS:,} "
                      "(lvcore.safety.limits.MAX_DOFS); use a coarser resolution")
    need, budget = estimate_memory_bytes(n_el, gauss_points_per_element), memory_budget_bytes()
    if need > budget:
        _raise(error, f"{where}: {shape} = {n_el:,} elements would need about {need / 1024 ** 3:.1f} GB of memory, "
                      f"more than the {budget / 1024 ** 3:.1f} GB available (the least of lvcore.safety.limits."
                      "MAX_SOLVE_MEMORY_BYTES, half the machine's memory, its free memory and any ulimit -v); "
                      "use a coarser resolution")


__all__ = [name for name in dir() if name.isupper()] + [
    "LimitError", "check_regular_file", "read_regular_file", "read_text_file", "loads_json", "read_json_file",
    "lv_mesh_size", "box_mesh_size", "estimate_memory_bytes", "memory_budget_bytes", "check_mesh_size",
    "mem_available_bytes", "available_memory_bytes",
]
