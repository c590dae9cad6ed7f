"""Subject emulators with and without a prior mean, trained on the same FE runs (held-out accuracy, no timing).

Build a subject emulator once with the whole map (its FE runs are kept in ``training_data.npz``), then train both
ways on the first n of its training runs and compare on its held-out test runs::

    lvcore emulator build --geometry GEOMETRY --out DIR --n-train 800 --n-valid 100 --prior none
    python benchmarks/subject_prior_study.py DIR --n-train 800 512 400 300 [--n-valid 50]

The prior mean is chosen as ``lvcore emulator build --prior auto`` would (:func:`lvcore.emulator.subject.choose_prior`);
the training recipe is the subject default (:func:`lvcore.emulator.subject.default_training_config`). Prints one
table row per n and method: held-out LVV RMSE (mL), its p99 absolute error and the strain RMSE.
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None) -> int:
    from lvcore.emulator.io import load_emulator
    from lvcore.emulator.model import prior_outputs
    from lvcore.emulator.subject import choose_prior, default_training_config
    from lvcore.emulator.training import train_emulator

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("emulator", help="a subject emulator directory with training_data.npz")
    p.add_argument("--n-train", type=int, nargs="+", default=[800, 512, 400])
    p.add_argument("--n-valid", type=int, default=None, help="validation rows used (default all)")
    args = p.parse_args(argv)
    emu = load_emulator(args.emulator)
    prior, rec = choose_prior(emu.training_space, emu.subject_geometry, "auto")
    if prior is None:
        raise SystemExit(f"no prior mean matches this emulator's runs: {rec}")
    with np.load(f"{args.emulator}/training_data.npz") as z:
        sets = {k: (np.asarray(z[f"{k}_inputs"]), np.asarray(z[f"{k}_outputs"])) for k in ("train", "valid", "test")}
    (x, y), (xv, yv), (xt, yt) = sets["train"], sets["valid"], sets["test"]
    xv, yv = xv[:args.n_valid], yv[:args.n_valid]
    base = prior_outputs(prior, emu.input_names, xt)
    print(f"# {args.emulator}: prior '{rec['name']}' at scale {rec['scale']:.3f}, scores "
          f"{', '.join(f'{v:.2f}' for v in rec['inputs'].values())}; projection MSE {rec['projection_mse_cm2']:.3g} cm²")
    print(f"# prior alone on the {len(xt)} test runs: LVV RMSE {np.sqrt(np.mean((base[:, 0] - yt[:, 0]) ** 2)):.3f} mL, "
          f"strain RMSE {np.sqrt(np.mean((base[:, 1:] - yt[:, 1:]) ** 2)):.4f}; test LVV "
          f"{yt[:, 0].min():.0f}-{yt[:, 0].max():.0f} mL")
    print("| n_train | n_valid | method | LVV RMSE (mL) | LVV p99 abs (mL) | strain RMSE | training (s) |")
    print("|---|---|---|---|---|---|---|")
    for n in args.n_train:
        for label, pm in (("whole map", None), ("prior mean", prior)):
            t0 = time.perf_counter()
            e = train_emulator(x[:n], y[:n], xv, yv, input_names=emu.input_names, name="study", lower=emu.lower,
                               upper=emu.upper, config=default_training_config(0), x_test=xt, y_test=yt, prior=pm)
            m = e.metadata["test"]
            print(f"| {min(n, len(x))} | {len(xv)} | {label} | {m['lvv_rmse_ml']:.3f} | {m['lvv_p99_abs_ml']:.2f} | "
                  f"{m['strain_rmse']:.4f} | {time.perf_counter() - t0:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
