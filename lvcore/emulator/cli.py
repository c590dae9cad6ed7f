"""``lvcore emulator train STORE ... --out DIR``, ``lvcore emulator build --geometry FILE --out DIR`` and
``lvcore emulator info NAME``."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from lvcore import cli_args
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, STRAIN_LAYERS
from lvcore.exceptions import EmulatorError


def register(subparsers) -> None:
    sub = cli_args.command_group(
        subparsers, "emulator", help="train or inspect neural-network emulators",
        description="Train a neural-network emulator on campaign stores, build one for a single subject's "
                    "geometry from FE runs, or show an emulator's inputs and accuracy.")

    t = cli_args.command(
        sub, "train", _train, help="train an emulator on campaign store(s)",
        description="Train an MLP emulator of the 25 outputs on the converged, consistent rows of campaign "
                    "store(s), choosing the architecture on validation data, and write network.npz and "
                    "metadata.json.")
    t.add_argument("stores", nargs="+", help="training campaign store(s) (HDF5, same space)")
    t.add_argument("--out", type=cli_args.output_dir, required=True,
                   help="output directory (network.npz + metadata.json), created if missing")
    t.add_argument("--inputs", nargs="+", default=None,
                   help="emulator inputs, e.g. a b af bf h1 h2 h3 h4 h5 (default: every varied input of the space)")
    t.add_argument("--valid", nargs="+", default=None, help="validation store(s); default: a random split of the training rows")
    t.add_argument("--valid-fraction", type=cli_args.float_in(0.0, 0.9, open_lo=True), default=0.1,
                   help="fraction held out for validation without --valid, in (0, 0.9] (default 0.1)")
    t.add_argument("--test", nargs="+", default=None,
                   help="held-out test store(s), never used for training or selection (default: none)")
    t.add_argument("--name", default=None, help="emulator name (default: the output directory's name)")
    add_training_arguments(t)
    t.add_argument("--seed", type=cli_args.seed, default=0,
                   help="seed of the split, initialisation and batches, 0 to 2^32 - 1 (default 0)")
    t.add_argument("--workers", type=cli_args.workers, default=1,
                   help="processes for the architecture search (one architecture each; same result as 1; default 1)")

    b = cli_args.command(
        sub, "build", _build,
        help="build a subject-specific emulator: FE runs on one exact geometry, trained and validated on held-out runs",
        description="Design over the prior box (scipy.stats.qmc Sobol), FE runs on the subject's geometry as it is "
                    "(no PCA projection), training, and validation on held-out FE runs the network never saw; the "
                    "held-out LVV and strain RMSE go into metadata.json. Use the result with `lvcore calibrate "
                    "--emulator DIR` (no --geometry: it is bound in).")
    b.add_argument("--geometry", required=True,
                   help="the subject's geometry: a template mesh (.vtu, e.g. from `lvcore geometry fit --out`), a "
                        "volumetric tet/hex mesh (.inp/.msh/.med/.vtu/.vtk/.xdmf, fitted), a contour stack or case "
                        "file (.json), PC scores (.json/.csv) or 'default'")
    b.add_argument("--out", type=cli_args.output_dir, required=True, help="output directory (geometry.vtu, network.npz, metadata.json, ...)")
    b.add_argument("--inputs", default="theta",
                   help="varied inputs: theta, plus optionally edp and angles, comma-separated (default theta)")
    b.add_argument("--units", choices=("mm", "cm", "m"), default="mm", help="units of a volumetric mesh")
    from lvcore.emulator.subject import SubjectDesign

    dd = SubjectDesign()  # one home of the default design (the app's build panel uses it too)
    b.add_argument("--n-train", type=int, default=dd.n_train,
                   help=f"training FE runs (default {dd.n_train}, sized for a build with a prior mean: on SYNTHETIC_HV3 "
                        "the default built in a median of 136 s on 2 cores with a held-out LVV RMSE of 0.30 mL, "
                        "BENCHMARKS.md row 44); without a prior mean use 800 or more")
    b.add_argument("--n-valid", type=int, default=dd.n_valid,
                   help=f"validation FE runs: early stopping (default {dd.n_valid})")
    b.add_argument("--n-test", type=int, default=dd.n_test,
                   help=f"held-out FE runs, never used in training; their RMSE is recorded (default {dd.n_test})")
    b.add_argument("--design", choices=("sobol", "lhs"), default=dd.method,
                   help=f"space-filling design (default {dd.method})")
    b.add_argument("--resolution", default="default", help="mesh preset of the FE runs (default 'default')")
    b.add_argument("--strain-layer", choices=tuple(STRAIN_LAYERS), default=DEFAULT_STRAIN_LAYER,
                   help=f"wall layer of the FE runs' strains, recorded in metadata.json (default {DEFAULT_STRAIN_LAYER}); "
                        "the outer layers want a mesh with two elements through the wall (docs/simulator.md)")
    b.add_argument("--base", choices=("sliding", "clamped"), default="sliding",
                   help="basal boundary condition (default sliding, as the 'chapter' emulator)")
    b.add_argument("--edp", type=float, default=None, help="EDP (mmHg) when not varied (default 8)")
    b.add_argument("--alpha-endo", type=float, default=None, help="alpha_endo (deg) when not varied (default -60)")
    b.add_argument("--alpha-epi", type=float, default=None, help="alpha_epi (deg) when not varied (default 60)")
    b.add_argument("--bound", action="append", default=[], metavar="NAME=LO,HI",
                   help="other bounds for a varied input, e.g. --bound a=0.3,3 (repeatable)")
    b.add_argument("--name", default=None, help="emulator name (default subject-<file stem>)")
    b.add_argument("--prior", default="auto",
                   help="the prior mean the network corrects: 'auto' (a bundled emulator over PC scores with the same "
                        "base and conditions, at the subject's size-normalised shape and size; none if none matches), "
                        "'none' (learn the whole map), or an emulator name or directory (default auto)")
    b.add_argument("--workers", type=int, default=2, help="FE worker processes, one continuation chain each")
    from lvcore.emulator.subject import DEFAULT_EDPVR
    from lvcore.emulator.subject_edpvr import EdpvrDesign

    ed = EdpvrDesign()
    b.add_argument("--edpvr", action=argparse.BooleanOptionalAction, default=None,
                   help="also build the subject's EDPVR emulator into OUT/edpvr: FE load paths of 0-30 mmHg on the "
                        f"same mesh ({ed.n_train} + {ed.n_valid} + {ed.n_test} paths), so the derived EDPVR of a "
                        "calibration through this emulator is evaluated directly (0.01 s) instead of by 700 FE "
                        "solves (2-3 min each calibration); it adds about 1.5 min on 2 cores with the default mesh "
                        "(82 s on SYNTHETIC_HV3, whose build took 39 s without it and 122 s with it; BENCHMARKS.md "
                        "row 51) "
                        f"(default {'on for a mesh geometry, off for default or PC scores' if DEFAULT_EDPVR else 'off'}"
                        "; --no-edpvr skips it)")
    b.add_argument("--seed", type=cli_args.seed, default=0, help="seed of the design and training, 0 to 2^32 - 1 (default 0)")
    from lvcore.emulator.subject import default_training_config

    add_training_arguments(b, default_training_config())

    i = cli_args.command(sub, "info", _info, help="show an emulator's inputs, box, architecture and accuracy",
                         description="Show a bundled or saved emulator's inputs, input box, architecture and "
                                     "validation and test accuracy.")
    i.add_argument("name", help="bundled name (e.g. chapter, angles) or directory")
    i.add_argument("--json", action="store_true", help="print the full metadata as JSON")


def add_training_arguments(parser, defaults=None) -> None:
    """The training options shared by ``lvcore emulator train`` and ``scripts/build_emulators.py``.

    ``defaults`` is a :class:`lvcore.emulator.training.TrainingConfig` (default: its own defaults).
    """
    from lvcore.emulator.training import ARCHITECTURES, TrainingConfig

    d = defaults or TrainingConfig()
    arch = "all" if tuple(d.architectures) == tuple(ARCHITECTURES) else \
        ",".join("x".join(str(w) for w in a) for a in d.architectures)
    parser.add_argument("--architectures", default=arch,
                        help="hidden widths to try: 'all' (the chapter's {50,100,120,200}^2) or e.g. '50x50,100x200' "
                             f"(default {arch})")
    parser.add_argument("--max-epochs", type=cli_args.int_in(1, 1_000_000), default=d.max_epochs,
                        help=f"most Adam epochs per architecture (default {d.max_epochs})")
    parser.add_argument("--patience", type=cli_args.int_in(1, 1_000_000), default=d.patience,
                        help=f"epochs without a better validation loss before stopping (default {d.patience})")
    parser.add_argument("--decay-epochs", type=cli_args.int_in(1, 1_000_000), default=d.decay_epochs,
                        help=f"the Adam learning rate (from 0.01) halves every this many epochs (default {d.decay_epochs})")
    parser.add_argument("--batch-size", type=cli_args.int_in(1, 1_000_000), default=d.batch_size,
                        help=f"minibatch size of Adam (default {d.batch_size})")
    parser.add_argument("--lbfgs-iterations", type=cli_args.int_in(0, 1_000_000), default=d.lbfgs_iterations,
                        help="full-batch L-BFGS refinement of the selected network (0: the chapter's Adam recipe "
                             f"alone; default {d.lbfgs_iterations})")
    parser.add_argument("--lvv-weight", type=float, default=d.lvv_weight,
                        help=f"loss weight of the LVV (each strain has 1; default {d.lvv_weight:g})")
    parser.add_argument("--lbfgs-lvv-weight", type=float, default=d.lbfgs_lvv_weight,
                        help="LVV loss weight of the L-BFGS stage (default: --lvv-weight)")


def training_config(args, seed: int):
    """A :class:`lvcore.emulator.training.TrainingConfig` from :func:`add_training_arguments` options."""
    from lvcore.emulator.training import TrainingConfig

    return TrainingConfig(architectures=parse_architectures(args.architectures), max_epochs=args.max_epochs,
                          patience=args.patience, decay_epochs=args.decay_epochs, batch_size=args.batch_size,
                          lbfgs_iterations=args.lbfgs_iterations, lvv_weight=args.lvv_weight,
                          lbfgs_lvv_weight=args.lbfgs_lvv_weight, seed=seed)


def parse_architectures(text: str) -> tuple[tuple[int, int], ...]:
    from lvcore.emulator.training import ARCHITECTURES

    if text == "all":
        return ARCHITECTURES
    try:
        archs = tuple(tuple(int(v) for v in item.lower().split("x")) for item in text.split(","))
    except ValueError as err:
        raise EmulatorError(f"--architectures must be 'all' or like '50x50,100x200', got {text!r}") from err
    if not archs or any(len(a) != 2 or min(a) < 1 for a in archs):
        raise EmulatorError(f"--architectures must list pairs of positive widths, got {text!r}")
    return archs


def _train(args) -> int:
    from lvcore.emulator.io import provenance_path, save_emulator
    from lvcore.emulator.training import load_store_data, train_emulator

    data = load_store_data(args.stores, args.inputs)
    x, y = data.inputs, data.outputs
    if args.valid:
        v = load_store_data(args.valid, data.input_names)
        xv, yv = v.inputs, v.outputs
    else:
        if not 0 < args.valid_fraction < 1:
            raise EmulatorError("--valid-fraction must be in (0, 1)")
        perm = np.random.default_rng(args.seed).permutation(x.shape[0])
        n_valid = max(1, int(round(args.valid_fraction * x.shape[0])))
        vi, ti = perm[:n_valid], perm[n_valid:]
        x, y, xv, yv = x[ti], y[ti], x[vi], y[vi]
    xt = yt = None
    if args.test:
        t = load_store_data(args.test, data.input_names)
        xt, yt = t.inputs, t.outputs
    for what, other in (("--valid", v if args.valid else data), ("--test", t if args.test else data)):
        if other.info["strain_layer"] != data.info["strain_layer"]:
            raise EmulatorError(f"{what} stores hold {other.info['strain_layer']} strains but the training stores "
                                f"{data.info['strain_layer']}; use stores of one wall layer")
    config = training_config(args, seed=args.seed)
    name = args.name or Path(args.out).name
    if data.n_inconsistent:
        print(f"WARNING: {data.n_inconsistent} inconsistent store row(s) excluded (lvcore campaign status --check):\n  "
              + "\n  ".join(data.problems), file=sys.stderr)
    print(f"training '{name}' on {x.shape[0]} rows ({data.n_failed} failed, {data.n_pending} pending and "
          f"{data.n_inconsistent} inconsistent rows excluded), validating on {xv.shape[0]}; inputs {list(data.input_names)}")
    emu = train_emulator(x, y, xv, yv, input_names=data.input_names, name=name, lower=data.lower, upper=data.upper,
                         fixed=data.fixed, config=config, x_test=xt, y_test=yt,
                         source={**data.info, "stores": [provenance_path(p, args.out) for p in data.info["stores"]],
                                 "paths_relative_to": "the emulator folder (--out); a store outside it by its file name",
                                 "n_failed_excluded": data.n_failed,
                                 "n_inconsistent_excluded": data.n_inconsistent}, log=print,
                         workers=args.workers)
    pred_x, pred_y = (xt, yt) if xt is not None else (xv, yv)
    save_emulator(emu, args.out, validation={"inputs": pred_x, "outputs": pred_y, "predictions": np.asarray(emu.apply(pred_x))})
    print(format_info(emu.metadata))
    return 0


def parse_bounds(items) -> dict:
    """``["a=0.3,3", ...]`` -> ``{"a": (0.3, 3.0)}`` (EmulatorError naming the option)."""
    out = {}
    for item in items or ():
        name, _, rng = str(item).partition("=")
        try:
            lo, hi = (float(v) for v in rng.split(","))
        except ValueError:
            raise EmulatorError(f"--bound {item}: write NAME=LO,HI, e.g. --bound a=0.3,3") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise EmulatorError(f"--bound {item}: need finite LO < HI")
        out[name.strip()] = (lo, hi)
    return out


def _build(args) -> int:
    from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP
    from lvcore.emulator.subject import SubjectDesign, build_subject_emulator
    from lvcore.mechanics.resolution import RESOLUTION_PRESET_NAMES

    if args.resolution not in RESOLUTION_PRESET_NAMES:
        raise EmulatorError(f"--resolution must be one of {', '.join(RESOLUTION_PRESET_NAMES)}, got {args.resolution!r}")
    if args.workers < 1:
        raise EmulatorError(f"--workers must be >= 1, got {args.workers}")
    for opt, value, lo, hi in (("--edp", args.edp, 2.0, 40.0), ("--alpha-endo", args.alpha_endo, -180.0, 180.0),
                               ("--alpha-epi", args.alpha_epi, -180.0, 180.0)):
        if value is not None and not (np.isfinite(value) and lo <= value <= hi):
            raise EmulatorError(f"{opt} must be in [{lo:g}, {hi:g}], got {value}")
    design = SubjectDesign(args.n_train, args.n_valid, args.n_test, args.design)
    emu = build_subject_emulator(
        args.geometry, args.out, inputs=args.inputs, design=design, resolution=args.resolution, base=args.base,
        edp_mmhg=CHAPTER_EDP if args.edp is None else args.edp,
        alpha_endo=CHAPTER_ANGLES[0] if args.alpha_endo is None else args.alpha_endo,
        alpha_epi=CHAPTER_ANGLES[1] if args.alpha_epi is None else args.alpha_epi,
        bounds=parse_bounds(args.bound), units=args.units, workers=args.workers, seed=args.seed,
        config=training_config(args, seed=args.seed), name=args.name, prior=args.prior, log=print,
        strain_layer=args.strain_layer, edpvr=args.edpvr)
    print(format_info(emu.metadata))
    return 0


def format_info(meta: dict) -> str:
    lines = [f"emulator '{meta.get('name')}'  (lvcore {meta.get('lvcore_version')}, {meta.get('created_at', '')})"]
    lo, hi = meta.get("bounds", {}).get("lower", []), meta.get("bounds", {}).get("upper", [])
    log = set(meta.get("log_inputs", []))
    lines.append("  inputs:")
    for n, a, b in zip(meta.get("input_names", []), lo, hi):
        lines.append(f"    {n:<11s} [{a:.4g}, {b:.4g}]{'  (log scale)' if n in log else ''}")
    if meta.get("fixed_inputs"):
        lines.append(f"  fixed in training: {meta['fixed_inputs']}")
    source = meta.get("source") or {}
    base = (source.get("space") or {}).get("base", "clamped")
    lines.append(f"  simulations: mesh {', '.join(map(str, source.get('resolution') or ['?']))}, base {base}, "
                 f"strains {meta.get('strain_layer', 'inner_half (not recorded: the default)')}, "
                 f"simulator {', '.join(map(str, source.get('simulator_versions') or ['?']))}")
    arch = meta.get("architecture", {})
    sub = meta.get("subject")
    if sub:
        runs, secs = sub.get("runs", {}), sub.get("seconds", {})
        lines.append(f"  SUBJECT-SPECIFIC: geometry fixed ({sub.get('geometry_kind')} from {sub.get('geometry_source')}); "
                     f"{runs.get('converged')} of {runs.get('total')} FE runs converged; wall {secs.get('total')} s "
                     f"(simulations {secs.get('simulations')} s, training {secs.get('training')} s)")
        from lvcore.emulator.subject import describe_prior

        lines.append(f"  {describe_prior(sub.get('prior'))}")
        e = sub.get("edpvr")
        lines.append("  EDPVR emulator: " + (f"'{e.get('name')}' in {e.get('folder')}/ (held-out log V/V0 RMSE up to "
                                             f"{e.get('log_volume_ratio_rmse_max', float('nan')):.4f}, "
                                             f"{e.get('n_test_paths')} paths; {e.get('seconds')} s)"
                                             if isinstance(e, dict) else "none (the derived EDPVR uses FE load paths; "
                                             "build with --edpvr)"))
    lines.append(f"  network: {meta.get('input_names') and len(meta['input_names'])} -> {arch.get('hidden')} (tanh) -> 25")
    tr = meta.get("training", {})
    if tr:
        lines.append(f"  trained on {tr.get('n_train')} rows, validated on {tr.get('n_valid')}; best epoch {tr.get('best_epoch')}; "
                     f"set hash {str(tr.get('set_hash'))[:12]}")
    for key in ("validation", "test"):
        m = meta.get(key)
        if m:
            lines.append(f"  {key} (n={m['n']}): LVV RMSE {m['lvv_rmse_ml']:.3f} mL (p99 |err| {m['lvv_p99_abs_ml']:.3f}), "
                         f"strain RMSE {m['strain_rmse']:.4f} (p99 |err| {m['strain_p99_abs']:.4f})")
    if meta.get("spec_note"):
        lines.append(f"  NOTE: {meta['spec_note']}")
    return "\n".join(lines)


def _info(args) -> int:
    from lvcore.emulator.io import load_emulator

    emu = load_emulator(args.name)
    print(json.dumps(emu.metadata, indent=2) if args.json else format_info(emu.metadata))
    return 0
