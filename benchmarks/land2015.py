"""Land et al. (2015) benchmark problems 1 and 2: mesh-convergence tables.

Usage::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
        python benchmarks/land2015.py [--problem 1|2|both] [--p1 10,1,1 20,2,2] [--p2 6,8,2 12,8,2]

Prints markdown tables (dofs, results, Newton iterations, wall time) to be
pasted into docs/simulator.md. Reference values: problem 1 tip z in
[4.151, 4.185] mm (consensus ~4.17); problem 2 (Simula/FEniCS converged)
endocardial apex z = -26.612 mm, epicardial apex z = -28.279 mm, cavity
volume 10734 mm³.

Per-phase profile of problem 2::

    python benchmarks/land2015.py --profile 6,4+2+2+4,1,5 6,4+2+2+4,1,3 [--repeats 5] [--solvers cholmod superlu]

For each resolution and sparse solver: apex errors against the reference, and
the median over ``--repeats`` warm solves of the wall time split into case
preparation (mesh, fibres, reference gradients; cached per process, so the
cold value is given apart), tangent assembly, numeric factorisation, back
substitutions, residual evaluations (line search), outputs and the rest, with
the counts of Newton iterations, tangents (= factorisations), residuals and
load steps; then the symbolic analysis of CHOLMOD (done once per sparsity
pattern and reused by every factorisation) against a numeric factorisation.
With ``--pulse-python PY`` (a Python with legacy dolfin and fenics-pulse: see
``benchmarks/pulse_land2015.py`` for the set-up) FEniCS pulse solves problem 2
here too, on lvcore's gmsh tetrahedral mesh of the benchmark geometry
(``--pulse-mesh-mm``, 1.25 mm: 49k P2/P1 dofs, apex errors within 0.02–0.03 mm, the
matched accuracy recorded in BENCHMARKS.md), between two rounds of lvcore's
solves, and the ratio is measured in one window. Without it the pulse column
is the time recorded in BENCHMARKS.md (pulse 2025.0.0 at ~30k dofs, 36 s, measured
in one window beside lvcore with SuperLU) and the table says so.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

from lvcore.mechanics.verification import P1_TIP_POINT, P1_TIP_Z_RANGE_MM, P2_REF, problem1_case, problem2_case  # noqa: E402


def _timed(case):
    from lvcore.mechanics.simulate import simulate

    t0 = time.perf_counter()
    r = simulate(case)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = simulate(case)
    return r, first, time.perf_counter() - t0


#: FEniCS pulse 2025.0.0 on Land problem 2 at matched accuracy (~30k dofs), from issue 25 (measured side by side).
PULSE_RECORDED_S = 36.0
PULSE_RECORDED_NOTE = "pulse 2025.0.0, ~30k dofs, 36 s (recorded in BENCHMARKS.md; pulse is not installed here)"


def _pulse_note() -> str:
    try:
        import pulse  # noqa: F401
    except ImportError:
        return PULSE_RECORDED_NOTE
    return "pulse is importable here, but --pulse-python was not given: " + PULSE_RECORDED_NOTE


def _lvcore_runs(case, repeats: int):
    """``repeats`` warm solves of ``case``: the last result and each solve's phase times (s)."""
    from lvcore.mechanics import simulate as sim

    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = sim.simulate(case)
        total = time.perf_counter() - t0
        tm = r.timings
        newton_s = tm["seconds"]
        runs.append({"total": total, "tangent": tm["t_tangent"], "factor": tm["t_factor"],
                     "solve": tm["t_solve"], "residuals": tm["t_line"],
                     "newton_other": newton_s - tm["t_tangent"] - tm["t_factor"] - tm["t_solve"] - tm["t_line"],
                     "outside": total - newton_s})
    return r, runs


#: gmsh element size (mm) of pulse's tetrahedral mesh: 1.25 mm gives 49,029 P2/P1 dofs and apex errors of
#: +0.018 / +0.025 mm (endo / epi), issue 25's matched accuracy (0.02–0.03 mm); 1.5 mm (33,893 dofs, the
#: issue's "~30k") gives +0.054 / +0.046 mm, 2 mm (14,535) +0.040 / +0.195 mm (straight-sided tetrahedra).
PULSE_MESH_MM = 1.25


def _pulse_runs(python: str, size_mm: float, repeats: int) -> list[dict]:
    """``repeats`` warm pulse solves of problem 2 (``benchmarks/pulse_land2015.py`` under ``python``).

    The mesh is lvcore's gmsh mesh of the benchmark geometry at ``size_mm``; one
    process solves ``repeats + 1`` times and the first solve (FFC form
    compilation) is dropped.
    """
    import json
    import subprocess
    import tempfile
    from pathlib import Path

    import numpy as np

    from lvcore.geometry.analytic import LAND_LV
    from lvcore.geometry.meshing import ellipsoid_tet_mesh

    with tempfile.TemporaryDirectory() as tmp:
        mesh = ellipsoid_tet_mesh(LAND_LV, size_mm)
        path = Path(tmp) / "land_problem2.npz"
        np.savez(path, points=mesh.points, cells=mesh.cells[0].data)
        script = Path(__file__).with_name("pulse_land2015.py")
        out = subprocess.run([python, str(script), str(path), str(repeats + 1)], capture_output=True, text=True,
                             env=pin_threads(dict(os.environ), force=True))
    runs = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    if out.returncode != 0 or len(runs) != repeats + 1:
        raise RuntimeError(f"pulse run failed (exit {out.returncode}): {out.stderr[-2000:]}")
    for r in runs:
        r["size_mm"] = size_mm
    print(f"  pulse: {[round(r['solve_s'], 2) for r in runs]} s (first includes compilation)", file=sys.stderr,
          flush=True)
    return runs[1:]


def profile(specs, repeats: int, solvers, pulse: str | None = None, pulse_mesh_mm: float = PULSE_MESH_MM,
            pulse_repeats: int = 2) -> None:
    """The per-phase profile table of problem 2 (see the module docstring).

    With ``pulse`` (a Python interpreter with legacy dolfin and fenics-pulse),
    pulse solves problem 2 between two rounds of lvcore's solves of every row, and
    the ratio is the median of those pulse solves over lvcore's median.
    """
    pulse_runs: list[dict] = []
    import datetime as dt
    import statistics

    import numpy as np

    from lvcore.mechanics import linear, simulate as sim
    from lvcore.mechanics.case import Case
    from lvcore.mechanics.resolution import resolution_label
    from lvcore.mechanics.verification import P2_REF

    when = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    load0 = "/".join(f"{v:.1f}" for v in os.getloadavg())
    rows, sym = [], []
    for spec in specs:
        case = Case.from_dict(problem2_case(spec))
        for solver in solvers:
            if solver not in linear.available_backends():
                print(f"  {solver} not available here, skipped", file=sys.stderr)
                continue
            os.environ[linear.BACKEND_ENV] = solver
            sim._PREPARED.clear()
            t0 = time.perf_counter()
            sim.prepare_case(case)
            prep_cold = time.perf_counter() - t0
            sim.simulate(case)  # compile
            r, runs = _lvcore_runs(case, repeats)
            if pulse is not None:  # pulse between two rounds of lvcore solves: one window for both
                pulse_runs.extend(_pulse_runs(pulse, pulse_mesh_mm, pulse_repeats))
                runs += _lvcore_runs(case, repeats)[1]
            med = {k: statistics.median(x[k] for x in runs) for k in runs[0]}
            rows.append((resolution_label(spec), r.dofs, solver, r, prep_cold, med))
            print(f"  done {spec} {solver}: {med['total']:.3f} s", file=sys.stderr, flush=True)
            if solver == "cholmod":
                from sksparse.cholmod import analyze

                prep = sim.prepare_case(case)
                p = prep.system.with_model(sim.constitutive_model(case, prep.mesh))
                _, K, _, _ = p.tangent(*r.solver_state, 1.0)
                A = linear._as_csc(K, True)
                ta, tf = [], []
                mode = linear.cholmod_mode()  # the mode and ordering the solves used
                ordering = linear.supernodal_ordering(A) if mode == "supernodal" else "default"
                for _ in range(max(3, repeats)):
                    t0 = time.perf_counter()
                    f = analyze(A, mode=mode, ordering_method=ordering)
                    ta.append(time.perf_counter() - t0)
                    t0 = time.perf_counter()
                    f.cholesky(A)
                    tf.append(time.perf_counter() - t0)
                sym.append((resolution_label(spec), r.dofs, statistics.median(ta), statistics.median(tf),
                            r.timings["tangents"], ordering))
    os.environ.pop(linear.BACKEND_ENV, None)
    load1 = "/".join(f"{v:.1f}" for v in os.getloadavg())
    pulse_s = statistics.median(r["solve_s"] for r in pulse_runs) if pulse_runs else PULSE_RECORDED_S
    print(f"Land 2015 problem 2 per-phase profile, {when}; load average (1/5/15 min) {load0} -> {load1}; "
          f"median of {2 * repeats if pulse_runs else repeats} warm solves (lvcore); 2-core machine shared with other "
          "jobs: compare within the table.")
    print(f"Reference apex z: endo {P2_REF['endo']}, epi {P2_REF['epi']} mm.\n")
    print("| resolution | dofs | solver | endo err (mm) | epi err (mm) | total (s) | tangent assembly | numeric "
          "factorisation | back-subst. | residuals (line search) | Newton other | outside Newton (outputs, set-up) "
          "| its / tangents / residuals / load steps | prepare, first time (s) | vs pulse |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for label, dofs, solver, r, prep_cold, m in rows:
        e = r.apex_endocardium[2] - P2_REF["endo"] if r.converged else float("nan")
        p = r.apex_epicardium[2] - P2_REF["epi"] if r.converged else float("nan")
        tm = r.timings

        def pct(k):
            return f"{m[k]:.3f} s ({m[k] / m['total']:.0%})"

        print(f"| {label} | {dofs} | {solver} | {e:+.3f} | {p:+.3f} | {m['total']:.3f} | {pct('tangent')} | "
              f"{pct('factor')} | {pct('solve')} | {pct('residuals')} | {pct('newton_other')} | {pct('outside')} | "
              f"{r.newton_iterations} / {tm['tangents']} / {tm['residuals']} / {r.load_steps} | {prep_cold:.3f} | "
              f"{pulse_s / m['total']:.0f}x |")
    if pulse_runs:
        print(f"\nvs pulse: measured here, alternating with lvcore (pulse between two rounds of {repeats} lvcore "
              f"solves per row): the ratio is pulse's median warm solve over lvcore's median total.\n")
        print("| pulse solve | mesh (mm) | dofs | endo err (mm) | epi err (mm) | set-up (s) | solve (s) |")
        print("|---|---|---|---|---|---|---|")
        for i, pr in enumerate(pulse_runs):
            print(f"| {i + 1} | {pr['size_mm']} | {pr['dofs']} | {pr['endo_apex_z'] - P2_REF['endo']:+.3f} | "
                  f"{pr['epi_apex_z'] - P2_REF['epi']:+.3f} | {pr['setup_s']:.2f} | {pr['solve_s']:.2f} |")
        print("\npulse 2025.0.0 (legacy dolfin 2019.2), its defaults (Taylor-Hood P2/P1, MUMPS, Newton tolerances "
              "1e-5, quadrature degree 4) on straight-sided tetrahedra; its apex error on that mesh is in the table.")
    else:
        print(f"\nvs pulse: {_pulse_note()}; the ratio is that time over lvcore's median total.")
    if sym:
        print(f"\nCHOLMOD ({linear.cholmod_mode()}) symbolic analysis (once per sparsity pattern, reused) vs numeric "
              "factorisation (each tangent):\n")
        print("| resolution | dofs | ordering | analyse (ms) | factorise (ms) | tangents per solve | saved per solve (ms) |")
        print("|---|---|---|---|---|---|---|")
        for label, dofs, ta, tf, nt, ordering in sym:
            print(f"| {label} | {dofs} | {ordering} | {1e3 * ta:.1f} | {1e3 * tf:.1f} | {nt} | "
                  f"{1e3 * ta * (nt - 1):.0f} |")
        print("\nSuperLU (SciPy) has no separate symbolic phase: every factorisation repeats the ordering and analysis.")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problem", default="both", choices=["1", "2", "both"])
    ap.add_argument("--p1", nargs="*", default=["10,1,1", "20,2,2", "30,3,3"])
    ap.add_argument("--p2", nargs="*", default=["6,8,2", "6,12,2", "6,16,3", "12,8,2"])
    ap.add_argument("--profile", nargs="*", default=None, metavar="RES",
                    help="per-phase profile of problem 2 at these resolutions (NC,NL,NT[,GP]); no other table")
    ap.add_argument("--repeats", type=int, default=5, help="--profile: warm solves per configuration")
    ap.add_argument("--solvers", nargs="*", default=["cholmod", "superlu"], help="--profile: sparse solvers")
    ap.add_argument("--pulse-python", default=None, metavar="PY",
                    help="--profile: a Python with legacy dolfin and fenics-pulse; pulse then solves problem 2 here, "
                         "alternating with lvcore (benchmarks/pulse_land2015.py says how to install it)")
    ap.add_argument("--pulse-mesh-mm", type=float, default=PULSE_MESH_MM, help="--pulse-python: tetrahedron size (mm)")
    ap.add_argument("--pulse-repeats", type=int, default=2, help="--pulse-python: warm pulse solves per row")
    a = ap.parse_args(argv)
    if a.profile is not None:
        profile(a.profile or ["6,4+2+2+4,1,5", "6,4+2+2+4,1,3"], a.repeats, a.solvers, a.pulse_python,
                a.pulse_mesh_mm, a.pulse_repeats)
        return 0
    from lvcore.mechanics.linear import available_backends

    print(f"linear solver: {available_backends()[0]}; CPU shared with other jobs (times are indicative)\n")
    if a.problem in ("1", "both"):
        lo, hi = P1_TIP_Z_RANGE_MM
        print(f"Problem 1 (beam), tip {P1_TIP_POINT}: reference z in [{lo}, {hi}] mm\n")
        print("| elements (x,y,z) | dofs | tip x | tip y | tip z | Newton its | 1st run incl. compile (s) | warm (s) |")
        print("|---|---|---|---|---|---|---|---|")
        for s in a.p1:
            res = tuple(int(v) for v in s.split(","))
            r, first, warm = _timed(problem1_case(res))
            tip = r.probes[0] if r.converged else [float("nan")] * 3
            print(f"| {res} | {r.dofs} | {tip[0]:.4f} | {tip[1]:.4f} | {tip[2]:.4f} | {r.newton_iterations} "
                  f"| {first:.1f} | {warm:.1f} |", flush=True)
        print()
    if a.problem in ("2", "both"):
        print(f"Problem 2 (LV inflation): reference endo apex z {P2_REF['endo']}, epi apex z {P2_REF['epi']} mm, "
              f"volume {P2_REF['volume']:.0f} mm³\n")
        print("| elements (circ x long x trans, Gauss points through the wall) | dofs | endo apex z | epi apex z | volume (mm³) | vol. error "
              "| Newton its | steps | 1st run incl. compile (s) | warm (s) |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        from lvcore.mechanics.resolution import resolution_label

        for s in a.p2:
            r, first, warm = _timed(problem2_case(s))
            res = resolution_label(s)
            if r.converged:
                v = r.cavity_volume_mm3[1]
                print(f"| {res} | {r.dofs} | {r.apex_endocardium[2]:.3f} | {r.apex_epicardium[2]:.3f} | {v:.0f} "
                      f"| {(v - P2_REF['volume']) / P2_REF['volume']:+.2%} | {r.newton_iterations} | {r.load_steps} "
                      f"| {first:.1f} | {warm:.1f} |", flush=True)
            else:
                print(f"| {res} | {r.dofs} | failed: {r.message} |", flush=True)


if __name__ == "__main__":
    sys.exit(main())
