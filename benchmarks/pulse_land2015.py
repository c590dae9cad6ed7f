"""Land et al. (2015) problem 2 in FEniCS pulse (legacy dolfin), for the side-by-side ratio in BENCHMARKS.md.

Not part of lvcore and not run by the tests: it runs under a Python that has
legacy FEniCS (dolfin 2019.2) and ``fenics-pulse``, which lvcore's environment
does not have. ``benchmarks/land2015.py --pulse-python PY`` writes the mesh and
calls this script with that interpreter, alternating with lvcore's solves.

Set-up on Debian 12 (bookworm), beside lvcore's own environment::

    apt-get install -y --no-install-recommends python3-dolfin python3-h5py-mpi python3-scipy python3-venv
    /usr/bin/python3 -m venv --system-site-packages /opt/pulse
    /opt/pulse/bin/pip install "fenics-pulse==2025.0.0"
    /opt/pulse/bin/pip uninstall -y numpy scipy h5py   # use Debian's builds, linked like dolfin

The problem is pulse's own problem 2 demo (``demo/benchmark/problem2``: Guccione
C = 10 kPa, b_f = b_t = b_fs = 1, base clamped, 10 kPa on the endocardium with
``pulse.iterate``, pulse's default solver: Taylor–Hood P2/P1, Newton with
MUMPS, relative and absolute tolerance 1e-5, quadrature degree 4) on a
tetrahedral mesh of the benchmark geometry made by lvcore
(:func:`lvcore.geometry.meshing.ellipsoid_tet_mesh`, gmsh, straight-sided
tetrahedra: legacy dolfin has no curved elements). pulse ships no benchmark
mesh in its wheel. The fibre frame is a constant one: with b_f = b_t = b_fs the
law is isotropic.

Usage::

    PY mesh.npz [repeats]    # mesh.npz: points (n, 3) mm, cells (m, 4)

prints one JSON line per solve: dofs, set-up and solve seconds, apex z (mm).
The first solve of a process includes FFC's form compilation (cached on disk
for later processes); the later ones are the warm time.
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np

#: Facet markers of the benchmark surfaces.
BASE, ENDO, EPI = 10, 30, 40


def build_geometry(npz_path):
    """A ``pulse.HeartGeometry`` from the points and tetrahedra in ``npz_path`` (base z = 5, apex on −z)."""
    import dolfin
    import pulse

    d = np.load(npz_path)
    pts, cells = np.asarray(d["points"], float), np.asarray(d["cells"], np.uintp)
    mesh = dolfin.Mesh()
    ed = dolfin.MeshEditor()
    ed.open(mesh, "tetrahedron", 3, 3)
    ed.init_vertices(len(pts))
    ed.init_cells(len(cells))
    for i, p in enumerate(pts):
        ed.add_vertex(i, p)
    for i, c in enumerate(cells):
        ed.add_cell(i, c)
    ed.close()
    mesh.order()
    ffun = dolfin.MeshFunction("size_t", mesh, 2, 0)
    mesh.init(2, 3)
    xyz = mesh.coordinates()
    for f in dolfin.facets(mesh):
        if not f.exterior():
            continue
        x = xyz[f.entities(0)]
        if np.all(np.abs(x[:, 2] - 5.0) < 1e-6):
            ffun[f] = BASE
        else:  # endocardium: (x² + y²) / 7² + z² / 17² = 1; the rest is the epicardium
            on_endo = np.abs((x[:, 0] ** 2 + x[:, 1] ** 2) / 49.0 + x[:, 2] ** 2 / 289.0 - 1.0) < 0.05
            ffun[f] = ENDO if np.all(on_endo) else EPI
    V = dolfin.VectorFunctionSpace(mesh, "DG", 0)
    frame = [dolfin.interpolate(dolfin.Constant(tuple(e)), V) for e in np.eye(3)]
    return pulse.HeartGeometry(mesh=mesh, markers={"BASE": (BASE, 2), "ENDO": (ENDO, 2), "EPI": (EPI, 2)},
                               marker_functions=pulse.MarkerFunctions(ffun=ffun),
                               microstructure=pulse.Microstructure(*frame))


def solve(geometry) -> dict:
    """One problem 2 solve: dofs, set-up and solve time (s), apex z (mm)."""
    import dolfin
    import pulse

    params = pulse.Guccione.default_parameters()
    params.update(C=10.0, bf=1.0, bfs=1.0, bt=1.0)  # pulse 2025 names: its old demo's "CC" and params= are ignored
    material = pulse.Guccione(parameters=params, f0=geometry.f0, s0=geometry.s0, n0=geometry.n0)
    if dict(material.parameters) != params or not material.is_isotropic():  # pulse ignores unknown keywords
        raise RuntimeError(f"pulse did not take the benchmark parameters: {dict(material.parameters)}")

    def clamped_base(W):
        V = W if W.sub(0).num_sub_spaces() == 0 else W.sub(0)
        return dolfin.DirichletBC(V, dolfin.Constant((0.0, 0.0, 0.0)), geometry.ffun, BASE)

    lvp = dolfin.Constant(0.0)
    bcs = pulse.BoundaryConditions(dirichlet=(clamped_base,), neumann=(pulse.NeumannBC(traction=lvp, marker=ENDO),))
    t0 = time.perf_counter()
    problem = pulse.MechanicsProblem(geometry, material, bcs)
    t1 = time.perf_counter()
    pulse.iterate.iterate(problem, lvp, 10.0)
    t2 = time.perf_counter()
    u, _ = problem.state.split(deepcopy=True)
    apex = {k: float(z + u(dolfin.Point(0.0, 0.0, z))[2]) for k, z in (("endo", -17.0), ("epi", -20.0))}
    return {"dofs": int(problem.state.function_space().dim()), "setup_s": t1 - t0, "solve_s": t2 - t1,
            "endo_apex_z": apex["endo"], "epi_apex_z": apex["epi"]}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    import dolfin

    dolfin.set_log_level(40)
    geometry = build_geometry(argv[0])
    for _ in range(int(argv[1]) if len(argv) > 1 else 2):
        print(json.dumps(solve(geometry)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
