#!/usr/bin/env python
"""Build the 8 SYNTHETIC "volunteers" HV1..HV8: geometry, measured data, and (separately) the truth.

Run after ``scripts/build_cohort.py`` (from the repository root)::

    OMP_NUM_THREADS=1 .venv/bin/python scripts/build_volunteers.py            # 8 simulations

For each volunteer geometry of the SYNTHETIC cohort (held out of the shape
model) it draws hidden HO parameters θ = (a, b, a_f, b_f) and fibre angles,
runs the simulator (``lvcore.simulate``) at EDP = 8 mmHg, and adds noise
σ_V = 5 mL to the LVV and σ_S = 0.03 to each of the 24 strains (the chapter's
values). It writes, all labelled SYNTHETIC:

* ``assets/volunteers/SYNTHETIC_HV<i>_geometry.vtu`` — the early-diastolic geometry;
* ``assets/volunteers/SYNTHETIC_HV<i>_measured.csv`` — one row ``subject, lvv_ml,
  strain_01..strain_24`` (the :mod:`lvcore.inference.data` layout);
* ``assets/volunteers/SYNTHETIC_volunteers.json`` — what a user may know: the
  files, EDP, early-diastolic cavity volume, noise levels, PCA scores h1..h5;
* ``assets/volunteers/truth/SYNTHETIC_volunteers_truth.json`` — the hidden
  generating θ, fibre angles, noise-free outputs and the noise drawn. Keep it
  out of any calibration input; it exists to score calibrations.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()  # before numpy is imported

import numpy as np  # noqa: E402

import lvcore  # noqa: E402
from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.mechanics.case_inputs import build_case  # noqa: E402
from lvcore.exceptions import SolverError  # noqa: E402
from lvcore.geometry.cohort import ROLE_VOLUNTEER, load_cohort  # noqa: E402
from lvcore.geometry.io import write_template_mesh  # noqa: E402
from lvcore.geometry.measures import cavity_volume  # noqa: E402
from lvcore.geometry.shape_model import load_shape_model  # noqa: E402
from lvcore.geometry.template import DEFAULT_TEMPLATE  # noqa: E402
from lvcore.domain.outputs import OUTPUT_COLUMNS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SIGMA_S = 0.03
EDP_MMHG = 8.0
#: Ranges of the hidden truth: log-uniform θ around the population values, uniform angles (deg).
THETA_RANGES = {"a": (0.3, 1.5), "b": (1.0, 6.0), "af": (0.5, 3.0), "bf": (1.5, 8.0)}
ANGLE_RANGES = {"alpha_endo": (-75.0, -45.0), "alpha_epi": (45.0, 90.0)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=20240602)
    ap.add_argument("--resolution", default="default", help="simulator resolution preset (default 'default')")
    ap.add_argument("--out", type=Path, default=ROOT / "assets" / "volunteers")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    ids, nodes = load_cohort().select(ROLE_VOLUNTEER)
    sm = load_shape_model()
    (args.out / "truth").mkdir(parents=True, exist_ok=True)
    public, truth = [], []
    t0 = time.perf_counter()
    for pid, g in zip(ids, nodes):
        short = pid.replace("SYNTHETIC-", "")
        geo = write_template_mesh(args.out / f"SYNTHETIC_{short}_geometry.vtu", g,
                                  metadata={"label": f"SYNTHETIC volunteer {short}"})
        failed = []
        for attempt in range(5):  # a draw the solver cannot load is redrawn (and recorded in the truth file)
            theta = {k: float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) for k, (lo, hi) in THETA_RANGES.items()}
            angles = {k: float(rng.uniform(lo, hi)) for k, (lo, hi) in ANGLE_RANGES.items()}
            case = build_case({**theta, **angles, "edp": EDP_MMHG}, geometry={"kind": "mesh", "path": str(geo)},
                              resolution=args.resolution)
            t = time.perf_counter()
            try:
                y_true = np.asarray(lvcore.simulate(case).outputs(), float)
                break
            except SolverError as err:
                failed.append({"theta": theta, "fibres_deg": angles, "error": str(err)})
                print(f"{pid}: solver failed ({err}); redrawing", flush=True)
        else:
            raise SolverError(f"{pid}: 5 draws failed to solve; see the messages above")
        dt = time.perf_counter() - t
        noise = np.r_[rng.normal(0.0, SIGMA_V_ML), rng.normal(0.0, SIGMA_S, 24)]
        y = y_true + noise
        meas = args.out / f"SYNTHETIC_{short}_measured.csv"
        with meas.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["subject", *OUTPUT_COLUMNS])
            w.writerow([f"SYNTHETIC-{short}", *[f"{v:.6f}" for v in y]])
        v_early = float(cavity_volume(g, DEFAULT_TEMPLATE)) / 1000.0
        public.append({"subject": f"SYNTHETIC-{short}", "geometry": geo.name, "measured": meas.name,
                       "edp_mmhg": EDP_MMHG, "early_diastolic_volume_ml": v_early,
                       "pca_scores_h1_h5": [float(v) for v in sm.project(g, 5)]})
        truth.append({"subject": f"SYNTHETIC-{short}", "theta": theta, "fibres_deg": angles,
                      "outputs_noise_free": y_true.tolist(), "noise": noise.tolist(), "resolution": args.resolution,
                      "simulation_seconds": dt, "failed_draws": failed})
        print(f"{pid}: LVV {y_true[0]:.1f} mL (early {v_early:.1f}), mean strain {y_true[1:].mean():.3f}, "
              f"{dt:.0f} s", flush=True)
    meta = {"label": "SYNTHETIC volunteers HV1-HV8 (generated by scripts/build_volunteers.py; not patient data)",
            "synthetic": True, "seed": args.seed, "noise": {"sigma_v_ml": SIGMA_V_ML, "sigma_s": SIGMA_S},
            "columns": list(OUTPUT_COLUMNS), "volunteers": public,
            "truth_file": "truth/SYNTHETIC_volunteers_truth.json (hidden generating values; do not calibrate on it)"}
    (args.out / "SYNTHETIC_volunteers.json").write_text(json.dumps(meta, indent=1))
    (args.out / "truth" / "SYNTHETIC_volunteers_truth.json").write_text(json.dumps(
        {"label": "SYNTHETIC volunteers: hidden generating truth", "synthetic": True, "seed": args.seed,
         "theta_ranges": THETA_RANGES, "angle_ranges_deg": ANGLE_RANGES, "edp_mmhg": EDP_MMHG,
         "volunteers": truth}, indent=1))
    print(f"wrote {len(public)} volunteers to {args.out} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
