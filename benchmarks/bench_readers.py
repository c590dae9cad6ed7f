"""Cost of the hostile-file defences: header checks and the forked, memory-capped reader.

For an open SYNTHETIC ellipsoidal surface (STL, about 12,000 triangles, written here) and the same
shape as a volumetric tet mesh (VTU), times

* ``in-process``: the reader as before those defences (``lvcore.geometry.surfaces._read_surface`` /
  ``meshio.read``) in this process;
* ``header check``: :func:`lvcore.safety.headers.check_mesh_header` alone;
* ``checked + child``: the public reader (``read_surface`` / ``read_meshio_file``): size and header
  checks, then the parse in a forked child with ``RLIMIT_AS`` (:mod:`lvcore.safety.isolation`);
* and the time from upload to error for the two files that crashed VTK (169-byte PLY, 33-byte OBJ).

Prints a table of medians over ``--repeat`` runs (default 7)::

    python benchmarks/bench_readers.py [--repeat 7]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported


def _median_ms(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        try:
            fn()
        except Exception:  # noqa: BLE001 - the hostile files raise on purpose
            pass
        times.append(time.perf_counter() - t)
    return 1000.0 * statistics.median(times)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="runs per row (default 7)")
    args = ap.parse_args(argv)

    import meshio
    import pyvista as pv

    from lvcore.safety import limits
    from lvcore.exceptions import GeometryError
    from lvcore.geometry.io import read_meshio_file
    from lvcore.geometry.surfaces import _read_surface, read_surface
    from lvcore.safety.headers import check_mesh_header

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import hostile_files as hf

    with tempfile.TemporaryDirectory() as d, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = Path(d)
        surf = pv.ParametricEllipsoid(30, 30, 60).clip("z", value=20).extract_surface(
            algorithm="dataset_surface").triangulate()
        stl = d / "endo.stl"
        surf.save(stl)
        vol = pv.ParametricEllipsoid(30, 30, 60).delaunay_3d()
        vtu = d / "lv.vtu"
        meshio.write(vtu, pv.to_meshio(vol) if hasattr(pv, "to_meshio") else meshio.Mesh(
            vol.points, [("tetra", vol.cells_dict[10])]))
        ply, obj = d / "crash.ply", d / "crash.obj"
        ply.write_bytes(hf.huge_ply())
        obj.write_bytes(hf.far_face_obj())
        rows = [
            (f"surface STL ({surf.n_cells:,} triangles)", "in-process", lambda: _read_surface(stl, "endo", "mm")),
            ("", "header check", lambda: check_mesh_header(stl)),
            ("", "checked + child", lambda: read_surface(stl, "endo")),
            (f"volume VTU ({vol.n_cells:,} tets)", "in-process (meshio.read)", lambda: meshio.read(vtu)),
            ("", "header check", lambda: check_mesh_header(vtu)),
            ("", "checked + child", lambda: read_meshio_file(vtu, "volume mesh", limits.MAX_SURFACE_BYTES, "")),
            ("PLY declaring 10^9 vertices", "checked (refused)", lambda: read_surface(ply, "endo")),
            ("OBJ with face index 10^9", "checked (refused)", lambda: read_surface(obj, "endo")),
        ]
        print(f"load average {os.getloadavg()[0]:.1f}; median of {args.repeat} runs")
        print(f"| {'file':34s} | {'reader':26s} | ms |")
        print(f"|{'-' * 36}|{'-' * 28}|----|")
        for what, how, fn in rows:
            print(f"| {what:34s} | {how:26s} | {_median_ms(fn, args.repeat):.1f} |")
        try:
            read_surface(ply, "endo")
        except GeometryError as err:
            print(f"PLY message: {err}")


if __name__ == "__main__":
    main()
