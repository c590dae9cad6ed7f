#!/usr/bin/env python
"""Build the shape model's representation error (a model discrepancy of ``--geometry infer``).

One command, seeded and reproducible (from the repository root)::

    OMP_NUM_THREADS=1 nice .venv/bin/python scripts/build_representation_error.py     # 80 FE pairs, ~1 h on 2 cores

It writes ``assets/shape_model/SYNTHETIC_representation_error_5pc.json``
(SYNTHETIC: from the SYNTHETIC cohort and shape model; about 60 kB), read
by :func:`lvcore.inference.representation_error.load_representation_error`.

For every cohort shape the shape model did not see (the 8 volunteers and 6
operator-study patients, held out of the PCA by ``scripts/build_cohort.py``)
and every training shape under a leave-one-out refit of the PCA, the shape
``x`` is split into a scale ``s`` and ``k``-mode scores ``h``
(:func:`lvcore.geometry.scaling.size_normalised_scores`, the split the CLI
makes of a mesh), and both ``x`` and ``s * reconstruct(h)`` are simulated
by the FE simulator with the ``chapter`` emulator's conditions (sliding
base, fibres -60/60 deg, 8 mmHg, default resolution) at one theta each from
a scrambled Sobol design over the emulator's box (log scale), kept where the
emulator says the mean shape fills like a heart (EDV/V0 1.2-2.8,
:data:`EDV_RATIO_RANGE`); a theta whose solve still fails or is flagged
implausible is replaced by the next design point. The strain
differences, the inflation ratio error and the geometric-measure errors go
through :func:`lvcore.inference.representation_error.representation_error_stats`.
The per-case numbers are stored too, so the statistics can be recomputed.
Resumable: finished cases are kept in ``--workdir``.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: Conditions of the ``chapter`` emulator (its metadata: sliding base, -60/60 deg, 8 mmHg).
CONDITIONS = {"fibres": {"alpha_endo": -60.0, "alpha_epi": 60.0}, "load": {"pressure": 8.0, "units": "mmHg"},
              "boundary": {"base": "sliding"}}


def split_cases(n_pc: int, n_train: int | None = None):
    """``(id, role, x, shape model without x)`` for the held-out shapes and the leave-one-out training shapes."""
    from lvcore.geometry.cohort import ROLE_TRAIN, load_cohort
    from lvcore.geometry.shape_model import fit_shape_model, load_shape_model

    cohort = load_cohort()
    full = load_shape_model()
    train_ids, train_x = cohort.select(ROLE_TRAIN)
    for pid, role, x in zip(cohort.ids, cohort.roles, cohort.nodes):
        if role != ROLE_TRAIN:
            yield pid, role, x, full
    for i, (pid, x) in enumerate(zip(train_ids, train_x)):
        if n_train is not None and i >= n_train:
            break
        keep = [j for j in range(len(train_ids)) if j != i]
        yield pid, ROLE_TRAIN + " (leave-one-out)", x, fit_shape_model(train_x[keep], n_modes=n_pc)


#: Range of EDV/V0 (at 8 mmHg, the ``chapter`` emulator at the mean shape) of the theta kept: LVs that fill like
#: hearts. Most of the prior box inflates far more (the simulator flags a cavity above 3 times its reference as
#: implausible, and soft corners often fail to converge); those solves would be wasted or would not describe a heart.
EDV_RATIO_RANGE = (1.2, 2.8)


def theta_design(n: int, seed: int) -> list[dict]:
    """``n`` points of a scrambled Sobol design over the chapter emulator's theta box (log scale), keeping
    those whose emulated EDV/V0 at the mean shape lies in :data:`EDV_RATIO_RANGE`."""
    from scipy.stats import qmc

    from lvcore.core.space import THETA_BOUNDS
    from lvcore.emulator import load_emulator
    from lvcore.emulator.forward import emulator_forward
    from lvcore.inference.geometry_prior import shape_measures

    names = ("a", "b", "af", "bf")
    lo = np.log([THETA_BOUNDS[k][0] for k in names])
    hi = np.log([THETA_BOUNDS[k][1] for k in names])
    u = qmc.Sobol(d=4, scramble=True, seed=seed).random_base2(14)
    thetas = np.exp(lo + (hi - lo) * u)
    fw = emulator_forward(load_emulator("chapter"), np.zeros(5), name="chapter")
    v0 = float(shape_measures(5).unit(np.zeros(5))["reference_volume_ml"])
    lvv = np.asarray(fw.evaluate(dict(zip(names, thetas.T))).outputs)[:, 0]
    keep = thetas[(lvv / v0 >= EDV_RATIO_RANGE[0]) & (lvv / v0 <= EDV_RATIO_RANGE[1])]
    return [dict(zip(names, row.tolist())) for row in keep[:n]]


def simulate_nodes(nodes, theta: dict, tmp: Path, initial=None):
    """FE solve of template ``nodes`` (mm) at ``theta`` with :data:`CONDITIONS`."""
    from lvcore.geometry.io import write_template_mesh
    from lvcore.mechanics.simulate import simulate

    path = tmp / "geometry.vtu"
    write_template_mesh(path, np.asarray(nodes, float))
    case = {"geometry": {"kind": "mesh", "path": str(path)},
            "material": {"law": "holzapfel-ogden", **theta}, **CONDITIONS}
    return simulate(case, initial=initial)


def one_case(x, model, n_pc: int, theta: dict, tmp: Path) -> dict | None:
    """The representation error of shape ``x`` at ``theta``; None when either solve fails or is implausible."""
    from lvcore.geometry.measures import geometry_info
    from lvcore.geometry.scaling import size_normalised_scores

    sc = size_normalised_scores(x, n_pc, model)
    recon = sc.scale * model.reconstruct(sc.h)     # base plane at the model's, z = 0: scaling about it
    rx = simulate_nodes(x, theta, tmp)
    if not rx.converged or rx.warnings:
        return None
    rr = simulate_nodes(recon, theta, tmp, initial=rx.solver_state)
    if not rr.converged or rr.warnings:
        return None
    yx, yr = np.asarray(rx.outputs(), float), np.asarray(rr.outputs(), float)
    v0x, v0r = rx.cavity_volume_mm3[0] / 1000.0, rr.cavity_volume_mm3[0] / 1000.0
    gx, gr = geometry_info(np.asarray(x, float)), geometry_info(recon)
    return {"theta": theta, "h": sc.h.tolist(), "scale": sc.scale, "projection_mse_cm2": sc.projection_mse_cm2,
            "v0_ml": v0x, "v0_recon_ml": v0r, "edv_ml": float(yx[0]), "edv_recon_ml": float(yr[0]),
            "strain_delta": (yx[1:] - yr[1:]).tolist(),
            "lvv_rel_delta": float((yx[0] / v0x) / (yr[0] / v0r) - 1.0),
            "measure_rel_delta": {"reference_volume_ml": gr["cavity_volume_ml"] / gx["cavity_volume_ml"] - 1.0,
                                  "wall_volume_ml": gr["wall_volume_ml"] / gx["wall_volume_ml"] - 1.0,
                                  "long_axis_mm": gr["length_mm"] / gx["length_mm"] - 1.0},
            "seconds": rx.seconds + rr.seconds}


def main(argv=None) -> int:
    from lvcore.inference.representation_error import FORMAT, asset_file, representation_error_stats

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n-pc", type=int, default=5, help="shape modes of the emulator (default 5, the shipped ones)")
    ap.add_argument("--n-train", type=int, default=None,
                    help="leave-one-out training shapes to use (default all 66)")
    ap.add_argument("--seed", type=int, default=20261125, help="seed of the Sobol theta design (default 20261125)")
    ap.add_argument("--workdir", type=Path, default=ROOT / "build" / "representation_error",
                    help="resumable per-case results (default build/representation_error)")
    ap.add_argument("--out", type=Path, default=None, help="output file (default the bundled asset)")
    args = ap.parse_args(argv)
    out = args.out or asset_file(args.n_pc)
    args.workdir.mkdir(parents=True, exist_ok=True)
    done_path = args.workdir / f"cases_{args.n_pc}pc_seed{args.seed}.json"
    done = json.loads(done_path.read_text()) if done_path.is_file() else {}
    cases = list(split_cases(args.n_pc, args.n_train))
    # a theta whose solve fails or is implausible is replaced by the next point: about 4-5 tries per accepted
    # case were needed, so the design has 10 points per case (a prefix of one filtered Sobol sequence: a
    # longer design keeps every earlier case's theta)
    design = theta_design(10 * len(cases), args.seed)
    k = 0
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmpdir:
        for pid, role, x, model in cases:
            if pid in done:
                k = max(k, done[pid]["design_index"] + 1)
                continue
            rec = None
            while rec is None and k < len(design):
                rec = one_case(x, model, args.n_pc, design[k], Path(tmpdir))
                k += 1
            if rec is None:
                print(f"{pid}: no design point gave two plausible solves", file=sys.stderr)
                continue
            done[pid] = {"id": pid, "role": role, "design_index": k - 1, **rec}
            done_path.write_text(json.dumps(done))
            print(f"{pid:16s} {role:24s} s {rec['scale']:.3f} strain RMS err {np.sqrt(np.mean(np.square(rec['strain_delta']))):.4f} "
                  f"EDV/V0 err {100 * rec['lvv_rel_delta']:+.2f} % ({rec['seconds']:.1f} s)", flush=True)
    recs = [done[pid] for pid, *_ in cases if pid in done]
    stats = representation_error_stats([r["strain_delta"] for r in recs], [r["lvv_rel_delta"] for r in recs],
                                       {m: [r["measure_rel_delta"][m] for r in recs]
                                        for m in ("reference_volume_ml", "wall_volume_ml", "long_axis_mm")})
    cmd = "python scripts/build_representation_error.py" + (f" --n-pc {args.n_pc}" if args.n_pc != 5 else "") \
        + (f" --n-train {args.n_train}" if args.n_train is not None else "") \
        + (f" --seed {args.seed}" if args.seed != 20261125 else "")
    meta = {"format": FORMAT, "synthetic": True, "n_pc": args.n_pc, "seed": args.seed, "command": cmd,
            "label": f"SYNTHETIC: {len(recs)} SYNTHETIC cohort shapes (held out or leave-one-out) against their "
                     f"{args.n_pc}-mode reconstructions, FE simulator, sliding base, -60/60 deg, 8 mmHg",
            "conditions": CONDITIONS, "resolution": "default", "stats": stats,
            "cases": [{k2: (round(v, 7) if isinstance(v, float) else v) for k2, v in r.items()
                       if k2 not in ("strain_delta",)} | {"strain_delta": [round(v, 7) for v in r["strain_delta"]]}
                      for r in recs]}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(meta, indent=0))
    sd = np.sqrt(np.diag(np.asarray(stats["strain_cov"])))
    print(f"wrote {out}: {len(recs)} cases; strain error sd RMS {np.sqrt(np.mean(sd ** 2)):.4f} "
          f"(min {sd.min():.4f}, max {sd.max():.4f}); EDV/V0 {100 * stats['lvv_rel_sd']:.2f} %; measures "
          + ", ".join(f"{k2} {100 * v:.2f} %" for k2, v in stats["measure_rel_sd"].items())
          + f"; shrinkage {stats['shrinkage']:.3f}; {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
