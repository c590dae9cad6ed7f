#!/usr/bin/env python
"""Build the SYNTHETIC cohort, the operator-study segmentations and the PCA shape model.

One command, seeded and reproducible (from the repository root)::

    OMP_NUM_THREADS=1 .venv/bin/python scripts/build_cohort.py            # about 1-2 min on 2 cores

It writes (all labelled SYNTHETIC; nothing here is patient data):

* ``assets/cohort/SYNTHETIC_cohort.{npz,json}`` — every synthetic LV fitted from
  a careful reference segmentation: training shapes, the 6 operator-study
  patients (P01..P06) and the 8 volunteers (HV1..HV8), with shape parameters,
  true and fitted cavity volumes and fit residuals;
* ``assets/cohort/contours/SYNTHETIC_Pxx_opN.json`` — the 6 × 3 imitation
  operators' contour stacks (op1 has a motion-correction error on P01, as the
  chapter's operator 1 did on its first patient);
* ``assets/cohort/SYNTHETIC_operators.{npz,json}`` — those stacks fitted with
  the same pipeline as a user's segmentation (:func:`lvcore.geometry.fitting.fit_contours`);
* ``assets/shape_model/SYNTHETIC_shape_model.{npz,json}`` — PCA of the training
  shapes only (operator-study patients and volunteers held out).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402

import lvcore  # noqa: E402,F401
from lvcore.geometry.cohort import (  # noqa: E402
    OPERATORS,
    REFERENCE_OPERATOR,
    ROLE_OPERATOR,
    ROLE_TRAIN,
    ROLE_VOLUNTEER,
    contour_stack,
    random_pose,
    sample_lv,
    with_motion_error,
)
from lvcore.geometry.fitting import fit_contours  # noqa: E402
from lvcore.geometry.shape_model import fit_shape_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
N_OPERATOR_PATIENTS = 6
N_VOLUNTEERS = 8


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=20240601, help="master seed (default 20240601)")
    ap.add_argument("--n-train", type=int, default=66, help="training shapes for the PCA (default 66)")
    ap.add_argument("--out", type=Path, default=ROOT / "assets", help="assets directory (default the checkout's assets/, shipped as package data)")
    ap.add_argument("--motion-error-mm", type=float, default=3.5,
                    help="in-plane shift of op1's apical slices on P01 (default 3.5 mm)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    root = np.random.default_rng(args.seed)
    seeds = root.spawn(3)
    shape_rng, stack_rng, op_rng = (np.random.default_rng(s) for s in seeds)

    ids = [f"SYNTHETIC-P{i + 1:02d}" for i in range(N_OPERATOR_PATIENTS)]
    ids += [f"SYNTHETIC-HV{i + 1}" for i in range(N_VOLUNTEERS)]
    ids += [f"SYNTHETIC-C{i + 1:03d}" for i in range(args.n_train)]
    roles = [ROLE_OPERATOR] * N_OPERATOR_PATIENTS + [ROLE_VOLUNTEER] * N_VOLUNTEERS + [ROLE_TRAIN] * args.n_train

    cohort_dir = args.out / "cohort"
    (cohort_dir / "contours").mkdir(parents=True, exist_ok=True)
    nodes, records, poses = [], [], {}
    fit_times = []
    for pid, role in zip(ids, roles):
        lv = sample_lv(shape_rng)
        pose = random_pose(stack_rng)
        poses[pid] = pose
        stack = contour_stack(lv, REFERENCE_OPERATOR, stack_rng, patient=pid, pose=pose)
        t = time.perf_counter()
        fit = fit_contours(stack)
        fit_times.append(time.perf_counter() - t)
        nodes.append(fit.nodes)
        params = {k: (v.tolist() if isinstance(v, np.ndarray) else float(v)) for k, v in asdict(lv).items()}
        records.append({"id": pid, "role": role, "shape": params, "true_cavity_volume_ml": lv.cavity_volume_ml(),
                        "n_slices": len(stack.slices), "fit": fit.summary(), "_lv": lv})
        print(f"{pid:18s} {role:15s} V_true={records[-1]['true_cavity_volume_ml']:6.1f} mL "
              f"V_fit={fit.cavity_volume_ml:6.1f} mL residual {fit.residual_mean_mm:.3f}/{fit.residual_max_mm:.3f} mm",
              flush=True)
    nodes = np.asarray(nodes)

    # operator study: 6 patients x 3 imitation operators, fitted like a user's segmentation
    op_names = tuple(o.name for o in OPERATORS)
    op_nodes = np.zeros((N_OPERATOR_PATIENTS, len(OPERATORS)) + nodes.shape[1:])
    fits = {}
    for p in range(N_OPERATOR_PATIENTS):
        pid = ids[p]
        for o, op in enumerate(OPERATORS):
            style = with_motion_error(op, args.motion_error_mm) if (p == 0 and op.name == "op1") else op
            stack = contour_stack(records[p]["_lv"], style, op_rng, patient=pid, pose=poses[pid])
            short = pid.replace("SYNTHETIC-", "")
            stack.save(cohort_dir / "contours" / f"SYNTHETIC_{short}_{op.name}.json")
            t = time.perf_counter()
            fit = fit_contours(stack)
            fit_times.append(time.perf_counter() - t)
            op_nodes[p, o] = fit.nodes
            fits[f"{pid}/{op.name}"] = {**fit.summary(), "motion_error_mm": style.motion_error_mm,
                                        "contours": f"contours/SYNTHETIC_{short}_{op.name}.json"}
            print(f"{pid} {op.name}: residual {fit.residual_mean_mm:.3f} mm, V={fit.cavity_volume_ml:.1f} mL", flush=True)

    label = f"SYNTHETIC cohort (scripts/build_cohort.py, seed {args.seed})"
    for r in records:
        r.pop("_lv")
    np.savez_compressed(cohort_dir / "SYNTHETIC_cohort.npz", nodes=nodes.astype(np.float32))
    meta = {
        "label": label,
        "synthetic": True,
        "seed": args.seed,
        "command": "python scripts/build_cohort.py" + (f" --seed {args.seed}" if args.seed != 20240601 else ""),
        "units": "mm",
        "template": [12, 8, 2],
        "ids": ids,
        "roles": roles,
        "reference_operator": asdict(REFERENCE_OPERATOR),
        "records": records,
    }
    (cohort_dir / "SYNTHETIC_cohort.json").write_text(json.dumps(meta, indent=1))
    np.savez_compressed(cohort_dir / "SYNTHETIC_operators.npz", nodes=op_nodes.astype(np.float32))
    (cohort_dir / "SYNTHETIC_operators.json").write_text(json.dumps({
        "label": "SYNTHETIC operator study: 6 synthetic patients x 3 imitation operators",
        "synthetic": True,
        "seed": args.seed,
        "patients": ids[:N_OPERATOR_PATIENTS],
        "operators": list(op_names),
        "operator_styles": [asdict(o) for o in OPERATORS],
        "motion_error": {"patient": ids[0], "operator": "op1", "shift_mm": args.motion_error_mm},
        "fits": fits,
    }, indent=1))

    train = nodes[[i for i, r in enumerate(roles) if r == ROLE_TRAIN]]
    train_ids = [i for i, r in zip(ids, roles) if r == ROLE_TRAIN]
    model = fit_shape_model(train, ids=train_ids, label=f"{label}: {len(train_ids)} training shapes")
    path = model.save(args.out / "shape_model" / "SYNTHETIC_shape_model.json")
    evr = np.cumsum(model.explained_variance_ratio)
    elapsed = time.perf_counter() - t0
    print(f"shape model: {model.n_modes} modes, cumulative explained variance 5/10 modes = {evr[4]:.3f}/{evr[9]:.3f}")
    print(f"fits: mean {np.mean(fit_times):.2f} s, max {np.max(fit_times):.2f} s per contour stack; "
          f"total build {elapsed:.0f} s; wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
