"""A/B of the template-mesh cache (:func:`lvcore.geometry.io.read_template_mesh`) on a subject emulator's build.

Builds the CI-sized subject emulator of ``tests/test_emulator_subject_edpvr.py`` (SYNTHETIC_HV3's mesh, ``fast``
mesh, 8 + 3 + 3 subject runs and 12 + 4 + 6 EDPVR load paths) with the cache off (every case parses the mesh in
an isolated child process, as before the cache) and on, alternating, and prints wall and CPU seconds per build
(CPU: this process only; the isolated readers are children). Run from the repository root::

    OMP_NUM_THREADS=1 python benchmarks/bench_mesh_cache.py --repeats 2
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def build_once(cache: bool) -> tuple[float, float]:
    """One build, cache on or off: (wall s, CPU s of this process)."""
    sys.path.insert(0, str(ROOT / "tests"))
    import test_emulator_subject_edpvr as t

    from lvcore.emulator import subject_edpvr
    from lvcore.emulator.subject import SubjectDesign, build_subject_emulator
    from lvcore.geometry import io as gio
    from lvcore.resources import volunteer_files

    identity = gio._mesh_identity
    gio._MESH_CACHE.clear()
    if not cache:
        gio._mesh_identity = lambda path, template: None
    try:
        out = Path(tempfile.mkdtemp()) / "emu"
        t0, c0 = time.perf_counter(), time.process_time()
        build_subject_emulator(volunteer_files("SYNTHETIC_HV3").geometry, out, design=SubjectDesign(8, 3, 3),
                               resolution="fast", bounds=t.BOUNDS, workers=1, seed=3, config=t.CONFIG, edpvr=True,
                               edpvr_design=subject_edpvr.EdpvrDesign(12, 4, 6))
        return time.perf_counter() - t0, time.process_time() - c0
    finally:
        gio._mesh_identity = identity


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=2, help="builds per setting, alternating (default 2)")
    args = p.parse_args(argv)
    build_once(True)  # warm-up: imports and compiled programs, not timed
    rows = {"off": [], "on": []}
    for _ in range(args.repeats):
        for name in ("off", "on"):
            rows[name].append(build_once(name == "on"))
    print("| mesh cache | builds | wall s, median | CPU s, median |\n| --- | ---: | ---: | ---: |")
    for name, r in rows.items():
        print(f"| {name} | {len(r)} | {statistics.median(w for w, _ in r):.1f} | "
              f"{statistics.median(c for _, c in r):.1f} |")
    off, on = (statistics.median(w for w, _ in rows[n]) for n in ("off", "on"))
    print(f"\nwall off / on: {off / on:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
