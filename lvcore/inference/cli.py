"""``lvcore calibrate``: Bayesian calibration of theta from a measured-data CSV and a geometry."""
from __future__ import annotations

import json
from pathlib import Path

from lvcore.core.space import SIGMA_V_ML


def register(subparsers) -> None:
    """Add the ``calibrate`` sub-command."""
    p = subparsers.add_parser(
        "calibrate",
        help="infer theta = (a, b, af, bf) from measured LVV + 24 strains",
        description="Bayesian calibration with an emulator: volume-only, iid or polar-GP discrepancy likelihood. "
                    "Writes ArviZ InferenceData (netCDF) and summary tables.",
    )
    p.add_argument("--data", help="measured CSV: lvv_ml, strain_01..strain_24 (optional subject column)")
    p.add_argument("--geometry",
                   help="PC scores (.json/.csv) or a template mesh (.vtu/.vtk/.xdmf/.npy/.npz) to project")
    p.add_argument("--volunteer", default=None, metavar="NAME",
                   help="a bundled SYNTHETIC volunteer (e.g. SYNTHETIC_HV1) instead of --data and --geometry")
    p.add_argument("--model", default="iid",
                   help="volume | iid | discrepancy, or a comma-separated list (default iid)")
    p.add_argument("--angles", choices=("fixed", "infer"), default="fixed",
                   help="fibre angles fixed at the emulator's values, or inferred (needs the 'angles' emulator)")
    p.add_argument("--emulator", default=None, help="emulator name (default: chapter, or angles with --angles infer)")
    p.add_argument("--alpha-endo", type=float, default=-60.0,
                   help="fixed alpha_endo (deg), used only by emulators that take angles (default -60)")
    p.add_argument("--alpha-epi", type=float, default=90.0,
                   help="fixed alpha_epi (deg), used only by emulators that take angles (default 90); "
                        "the 'chapter' emulator is trained at (-60, 60) and ignores both")
    p.add_argument("--edp", type=float, default=8.0, help="end-diastolic pressure (mmHg) for emulators that take it")
    p.add_argument("--sigma-v", type=float, default=SIGMA_V_ML, help=f"LVV noise sd (mL), fixed (default {SIGMA_V_ML:g})")
    p.add_argument("--sampler", choices=("auto", "nuts", "hmc_gibbs"), default="auto",
                   help="auto: NUTS for volume/iid, HMC-within-Gibbs for discrepancy")
    p.add_argument("--chains", type=int, default=4)
    p.add_argument("--warmup", type=int, default=1000)
    p.add_argument("--samples", type=int, default=1000, help="draws kept per chain after convergence")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--subject", default=None, help="row to use (subject id); default: every row")
    p.add_argument("--out", default="calibration_out", help="output folder")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run_calibrate)


def check_options(args) -> None:
    """Refuse nonsensical sampler options before anything runs (DataError naming the option)."""
    import math

    from lvcore.exceptions import DataError

    for name, value, lo in (("--chains", args.chains, 1), ("--warmup", args.warmup, 1), ("--samples", args.samples, 1)):
        if value < lo:
            raise DataError(f"{name} must be >= {lo}, got {value}")
    if args.chains > 64:
        raise DataError(f"--chains must be <= 64, got {args.chains}")
    if args.warmup > 1_000_000 or args.samples > 1_000_000:
        raise DataError("--warmup and --samples must be <= 1,000,000")
    if not (math.isfinite(args.sigma_v) and args.sigma_v > 0):
        raise DataError(f"--sigma-v must be a positive number of mL, got {args.sigma_v}")
    if not (math.isfinite(args.edp) and args.edp >= 0):
        raise DataError(f"--edp must be a finite pressure >= 0 (mmHg), got {args.edp}")
    for name, value in (("--alpha-endo", args.alpha_endo), ("--alpha-epi", args.alpha_epi)):
        if not (math.isfinite(value) and -180 <= value <= 180):
            raise DataError(f"{name} must be an angle in [-180, 180] degrees, got {value}")


def run_calibrate(args) -> int:
    from lvcore.inference.samplers import use_host_devices

    check_options(args)
    use_host_devices(args.chains)

    from lvcore.core.forward import load_emulator_forward
    from lvcore.exceptions import DataError
    from lvcore.inference import calibrate as cal
    from lvcore.inference.data import read_measured_csv
    from lvcore.inference.models import MODEL_NAMES
    from lvcore.inference.samplers import SamplerConfig

    if args.volunteer is not None:
        from lvcore.resources import volunteer_files

        if args.data is not None or args.geometry is not None:
            raise DataError("--volunteer replaces --data and --geometry: give one or the other")
        vol = volunteer_files(args.volunteer)
        args.data, args.geometry = str(vol.measured), str(vol.geometry)
    elif args.data is None or args.geometry is None:
        raise DataError("give --data and --geometry (your measurements), or --volunteer NAME (a bundled one)")
    model_names = [m.strip() for m in args.model.split(",") if m.strip()]
    bad = [m for m in model_names if m not in MODEL_NAMES]
    if bad or not model_names:
        raise DataError(f"--model {','.join(bad)}: choose from {', '.join(MODEL_NAMES)}")
    rows = read_measured_csv(args.data)
    if args.subject is not None:
        rows = [r for r in rows if r.subject == args.subject]
        if not rows:
            raise DataError(f"--subject {args.subject}: no such subject in {args.data}")
    cal.output_stems([r.subject for r in rows], source=str(args.data))  # unique file names, before any work
    h = cal.read_pc_scores(args.geometry)
    infer = args.angles == "infer"
    name = args.emulator or ("angles" if infer else "chapter")
    forward = load_emulator_forward(name, h, infer_angles=infer, alpha_endo=args.alpha_endo,
                                    alpha_epi=args.alpha_epi, edp_mmhg=args.edp)
    config = SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains, seed=args.seed)

    def show(item):
        res = item.result
        print(f"\n== {item.subject} / {item.model} ({res.sampler}, {res.wall_s:.1f} s) ==")
        print(res.summary.to_string())
        print(res.convergence.message())

    results = cal.calibrate_subjects(
        [(r.subject, r.y, forward) for r in rows], model_names, config=config, sampler=args.sampler,
        sigma_v=args.sigma_v, infer_angles=infer, out_dir=args.out,
        attrs={"data_file": str(args.data), "emulator": name, "angles": args.angles},
        progress=None if args.json else (lambda msg, frac: print(msg)), on_result=None if args.json else show)
    records = [item.record() for item in results]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(records, indent=2))
    if args.json:
        print(json.dumps(records, indent=2))
    else:
        print(f"\nwrote {out}/summary.json and per-model .nc / _summary.csv")
    return 0 if all(r["converged"] for r in records) else 1
