"""Which form should a subject EDPVR emulator learn? Held-out error of a few representations on the same load paths.

    lvcore emulator build --geometry assets/volunteers/SYNTHETIC_HV3_geometry.vtu --out EMU --edpvr
    python benchmarks/subject_edpvr_forms.py EMU

Reads the FE load paths a ``--edpvr`` build keeps (``EMU/edpvr/load_paths_{train,valid,test}.npz``,
lvcore.emulator.subject_edpvr) and trains, with the shipped schedule (``default_edpvr_config``), one network per
form; prints the held-out RMSE of ``log V/V₀`` per test pressure over all test paths and over those with
EDV/V₀ <= 2.5 at 8 mmHg:

* ``direct log(1+p)``: (log θ, log(1 + p)) -> log V/V₀, log λ_f (the shipped form);
* ``direct p``: the same with p as the pressure input;
* ``anchored, FE V8``: both outputs divided by L₈ = log V₈/V₀, as the bundled ``edpvr`` emulator does, with each
  path's own FE V₈ (interpolated in p) as the anchor: an optimistic bound, since in use the anchor is an emulator;
* ``direct log(1+p), half the paths``: the shipped form on the first half of the training paths.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from lvcore.execution.parallel import pin_threads  # noqa: E402 - imports neither numpy nor JAX

pin_threads()


def log_v8(data):
    """Each path's FE log V₈/V₀ (interpolated in p; 0 at p = 0)."""
    import numpy as np

    out = []
    for i in range(data.inputs.shape[0]):
        lv = np.log(data.lvv_ml[i] / data.v0_ml[i])
        ok = np.isfinite(lv)
        out.append(np.interp(8.0, np.r_[0.0, data.pressures_mmhg[ok]], np.r_[0.0, lv[ok]]))
    return np.array(out)


def rows(data, anchored: bool):
    """Training rows (inputs θ, p; outputs log V/V₀, log λ_f, divided by L₈ when ``anchored``)."""
    import numpy as np

    from lvcore.emulator.subject_edpvr import training_rows

    x, y = training_rows(data)
    if anchored:
        L = dict(zip(map(tuple, data.inputs), log_v8(data)))
        y = y / np.array([L[tuple(r[:4])] for r in x])[:, None]
    return x, y


def fit_and_test(train, valid, test, *, log1p: bool, anchored: bool) -> tuple:
    """Held-out RMSE of log V/V₀ per test pressure (all paths, physiological paths) and the training seconds."""
    import numpy as np

    from lvcore.emulator.edpvr import STRETCH_WEIGHT
    from lvcore.emulator.network import to_arrays
    from lvcore.emulator.subject_edpvr import default_edpvr_config
    from lvcore.emulator.training import refine_lbfgs, search_architectures

    def tf(x):
        z = np.array(x, float)
        z[..., :4] = np.log(z[..., :4])
        if log1p:
            z[..., 4] = np.log1p(z[..., 4])
        return z

    t0 = time.perf_counter()
    (x, y), (xv, yv) = rows(train, anchored), rows(valid, anchored)
    tx, txv = tf(x), tf(xv)
    xm, xs, ym, ys = tx.mean(0), tx.std(0), y.mean(0), y.std(0)
    ys[1] /= np.sqrt(STRETCH_WEIGHT)
    cfg = default_edpvr_config()
    zx, zxv, zy, zyv = (tx - xm) / xs, (txv - xm) / xs, (y - ym) / ys, (yv - ym) / ys
    net, _ = refine_lbfgs(search_architectures(zx, zy, zxv, zyv, cfg)[0].network, zx, zy, zxv, zyv, cfg)
    a = to_arrays(net)
    n = len(a) // 2
    P, N = test.pressures_mmhg, test.inputs.shape[0]
    h = (tf(np.concatenate([np.repeat(test.inputs[:, None], P.size, 1),
                            np.broadcast_to(P[None, :, None], (N, P.size, 1))], 2)) - xm) / xs
    for i in range(n - 1):
        h = np.tanh(h @ np.asarray(a[f"layer{i}_weight"]).T + np.asarray(a[f"layer{i}_bias"]))
    pred = (h @ np.asarray(a[f"layer{n - 1}_weight"]).T + np.asarray(a[f"layer{n - 1}_bias"])) * ys + ym
    L8 = log_v8(test)
    err = pred[..., 0] * (L8[:, None] if anchored else 1.0) - np.log(test.lvv_ml / test.v0_ml[:, None])
    phys = np.exp(L8) <= 2.5
    return (np.sqrt(np.nanmean(err ** 2, 0)), np.sqrt(np.nanmean(err[phys] ** 2, 0)), int(phys.sum()),
            time.perf_counter() - t0)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("emulator", help="a subject emulator folder built with --edpvr")
    args = p.parse_args(argv)

    import dataclasses

    from lvcore.campaigns.load_paths import LoadPathData

    folder = Path(args.emulator) / "edpvr"
    data = {k: LoadPathData.load(folder / f"load_paths_{k}.npz") for k in ("train", "valid", "test")}
    tr = data["train"]
    half = dataclasses.replace(tr, **{k: getattr(tr, k)[: tr.inputs.shape[0] // 2] for k in
                                      ("inputs", "v0_ml", "lvv_ml", "strains", "fibre_stretch", "seconds")})
    print(f"# {folder}: {tr.inputs.shape[0]} training paths at {tr.pressures_mmhg.tolist()} mmHg, "
          f"{data['test'].inputs.shape[0]} test paths at {data['test'].pressures_mmhg.tolist()} mmHg")
    print("| form | training paths | train (s) | log V/V0 RMSE, all test paths (%) | EDV/V0 <= 2.5 at 8 mmHg (%) |")
    print("|---|---|---|---|---|")
    for label, train, log1p, anchored in (("direct log(1+p)", tr, True, False), ("direct p", tr, False, False),
                                          ("anchored, FE V8", tr, True, True),
                                          ("direct log(1+p), half the paths", half, True, False)):
        all_, phys, n_phys, secs = fit_and_test(train, data["valid"], data["test"], log1p=log1p, anchored=anchored)
        print(f"| {label} | {train.inputs.shape[0]} | {secs:.0f} | {100 * all_.min():.2f}-{100 * all_.max():.2f} "
              f"(5-30 mmHg: {100 * all_[data['test'].pressures_mmhg >= 5].max():.2f}) | "
              f"{100 * phys.min():.2f}-{100 * phys.max():.2f} ({n_phys} paths) |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
