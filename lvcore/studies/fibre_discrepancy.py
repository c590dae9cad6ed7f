"""The chapter's fibre-discrepancy study (Sections 9.3.2 and 9.4.3).

The ``chapter`` emulator is trained at fixed fibre angles (-60°, 60°). Test
data come from the FE simulator at angles (-60, 90), (-30, 60), (0, 90)
crossed with four theta, on one geometry from a point ``h`` in 5-PC space,
with noise sigma_V = 5 mL and sigma_S = 0.03 (12 SYNTHETIC test sets). Each
set is fitted with (i) volume only, (ii) iid strains and (iii) the polar-GP
discrepancy model, and the posterior of eta(theta, h) is compared with the
benchmark eta(theta_true, h).

Reported (plain data, JSON + CSV, and the figures' HTML):

* posterior predictive of the 24 strains vs data for (ii) and (iii) (Fig. 9.6);
* posterior of sigma_S vs the true 0.03 (Fig. 9.7);
* per model, the distribution over the 12 sets of |eta(theta_post, h) - eta(theta_true, h)|
  over the 24 strains (Fig. 9.9, violins);
* whether the chapter's findings are reproduced: iid inflates sigma_S by about 2x,
  (iii) gets sigma_S near the truth (0.024 in the chapter), and (iii) and
  volume-only beat iid.

The real simulator and the real ``chapter`` emulator are used; if the
emulator is missing the study stops with an error saying how to build it.
Other forward models/simulators can be passed explicitly (tests do this).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import arviz as az
import jax
import numpy as np

from lvcore.core.forward import Forward
from lvcore.emulator.forward import load_emulator_forward
from lvcore.mechanics.forward import SimulatorForward
from lvcore.core.space import CHAPTER_EDP, SIGMA_V_ML
from lvcore.inference import coverage, diagnostics, samplers
from lvcore.outputs import ANGLE_NAMES, THETA_NAMES, pc_names

ANGLE_SETS = ((-60.0, 90.0), (-30.0, 60.0), (0.0, 90.0))
THETA_SETS = ((0.1, 5.0, 1.0, 6.0), (0.5, 8.0, 1.5, 6.0), (1.0, 1.0, 1.0, 1.0), (1.0, 5.0, 1.0, 5.0))
#: The synthetic geometry: a point in the shape model's standardised 5-PC space.
DEFAULT_H = (0.5, -0.4, 0.3, -0.2, 0.1)
SIGMA_S = 0.03
MODELS = ("volume", "iid", "discrepancy")
CHAPTER_SIGMA_S_DISCREPANCY = 0.024


@dataclass(frozen=True)
class TestSet:
    """One SYNTHETIC test set: simulator outputs at (theta, angles) plus noise."""

    index: int
    alpha_endo: float
    alpha_epi: float
    theta: dict
    z: np.ndarray          # noise-free simulator outputs (25)
    y: np.ndarray          # z + noise (25)
    benchmark: np.ndarray  # eta(theta, h): the emulator at the truth (25)


def data_simulator(h=DEFAULT_H, resolution: str = "default", base: str = "clamped") -> SimulatorForward:
    """The FE simulator that makes the test data: inputs theta and the fibre angles, on the PCA geometry ``h`` at 8 mmHg.

    ``base`` is the basal boundary condition; the study passes the emulator's
    own, so that the fibre angles are the only discrepancy between data and model.
    """
    return SimulatorForward(input_names=THETA_NAMES + ANGLE_NAMES,
                            conditions={**dict(zip(pc_names(len(h)), map(float, h))), "edp": CHAPTER_EDP},
                            resolution=resolution, base=base, label="FE simulator (fibre-discrepancy test data)")


def make_test_sets(forward, h=DEFAULT_H, *, seed: int = 0, simulator: Forward | None = None,
                   resolution: str = "default", progress=None, set_indices=None) -> list[TestSet]:
    """The 12 SYNTHETIC test sets (or those in ``set_indices``).

    ``simulator`` reads ``a, b, af, bf, alpha_endo, alpha_epi`` and makes the
    noise-free data (default :func:`data_simulator`); ``forward`` (theta only)
    gives the benchmark. Set ``i`` has angles ``ANGLE_SETS[i // 4]`` and theta ``THETA_SETS[i % 4]``.
    """
    simulator = simulator or data_simulator(h, resolution, getattr(forward, "base", "clamped"))
    rng = np.random.default_rng(seed)
    out = []
    for i, ((ae, ap), th) in enumerate((a, t) for a in ANGLE_SETS for t in THETA_SETS):
        theta = dict(zip(THETA_NAMES, th))
        z_noise = rng.standard_normal(25)  # drawn for every set so a subset sees the same noise
        if set_indices is not None and i not in set_indices:
            continue
        if progress:
            progress(f"simulating test set {i + 1}/12: angles ({ae:g}, {ap:g}), theta {th}", i / 12)
        point = {**theta, ANGLE_NAMES[0]: ae, ANGLE_NAMES[1]: ap}
        z = simulator.evaluate({n: [point[n]] for n in simulator.input_names}).raise_on_failure().outputs[0]
        y = z + np.r_[SIGMA_V_ML, np.full(24, SIGMA_S)] * z_noise
        out.append(TestSet(i, ae, ap, theta, z, y, np.asarray(forward(theta), dtype=float)))
    return out


def _fit_all(forward, sets, model: str, config: samplers.SamplerConfig, seed: int) -> dict:
    """All 12 sets for one model in one compiled, vmapped run; draws grouped (set, chain, draw, ...)."""
    sites = list(THETA_NAMES) + {"volume": [], "iid": ["sigma_s2"],
                                 "discrepancy": ["sigma_s2", "disc", "v"]}[model]
    ys = np.stack([s.y for s in sets])
    keys = jax.random.split(jax.random.PRNGKey(seed), len(sets))
    draws = coverage.batched_posteriors(forward, model, ys, keys, config, SIGMA_V_ML, sites=sites, group_by_chain=True)
    flat = {n: draws[n].reshape((len(sets), -1)) for n in THETA_NAMES}
    eta = jax.jit(jax.vmap(jax.vmap(forward)))(flat)
    draws["eta"] = np.asarray(eta).reshape(draws[THETA_NAMES[0]].shape + (25,))
    return draws


def _rhat(draws: dict, i: int, names) -> float:
    post = {n: draws[n][i] for n in names if n in draws}
    r = az.rhat(az.from_dict(posterior=post))
    return float(max(float(r[n]) for n in r.data_vars))


def _build_record(forward) -> dict:
    """Which emulator build (creation time, mesh, base condition) the study calibrated with."""
    emu = getattr(forward, "emulator", None)
    if emu is None:
        return {"base": getattr(forward, "base", None)}
    return {"name": emu.name, "created_at": emu.metadata.get("created_at"), "resolution": emu.resolution,
            "base": emu.base, "lvcore_version": emu.metadata.get("lvcore_version")}


def run_study(forward=None, *, h=DEFAULT_H, config: samplers.SamplerConfig | None = None, seed: int = 0,
              simulator: Forward | None = None, resolution: str = "default", out: str | Path | None = None,
              progress=None, set_indices=None, emulator: str = "chapter") -> dict:
    """Run the study; returns plain data (and writes it under ``out`` if given).

    Parameters
    ----------
    forward : Forward, optional
        JAX-traceable, reads theta. Default: emulator ``emulator`` (name or
        directory; ``chapter``) with ``h`` bound in
        (:func:`lvcore.emulator.load_emulator_forward`); raises EmulatorError if absent.
    simulator : Forward, optional
        Reads theta and the fibre angles and makes the test data; default
        the FE simulator (:func:`data_simulator`).
    """
    t_start = time.perf_counter()
    config = config or samplers.SamplerConfig()
    if forward is None:
        forward = load_emulator_forward(emulator, h)
    sets = make_test_sets(forward, h, seed=seed, simulator=simulator, resolution=resolution, progress=progress,
                          set_indices=set_indices)
    t_sim = time.perf_counter() - t_start
    fits, timings = {}, {}
    for k, m in enumerate(MODELS):
        if progress:
            progress(f"fitting model {m} to the 12 sets", k / 3)
        t0 = time.perf_counter()
        fits[m] = _fit_all(forward, sets, m, config, seed + k + 1)
        timings[m] = time.perf_counter() - t0
    per_set = []
    errors = {m: [] for m in MODELS}
    for pos, s in enumerate(sets):
        rec = {"set": s.index, "alpha_endo": s.alpha_endo, "alpha_epi": s.alpha_epi, "theta": s.theta,
               "y": s.y.tolist(), "z": s.z.tolist(), "benchmark": s.benchmark.tolist(), "models": {}}
        for m in MODELS:
            d = fits[m]
            eta = d["eta"][pos].reshape(-1, 25)
            err = np.abs(eta[:, 1:] - s.benchmark[1:])       # (draws, 24)
            errors[m].append(err.mean(axis=1))
            mr = {"rhat_max": _rhat(d, pos, list(THETA_NAMES) + ["sigma_s2", "v"]),
                  "abs_error_median": float(np.median(err)), "abs_error_mean": float(err.mean()),
                  "theta_median": {n: float(np.median(d[n][pos])) for n in THETA_NAMES}}
            qe = np.quantile(eta, [0.05, 0.5, 0.95], axis=0)  # eta(theta_post, h), 25 outputs (Fig 9.8)
            mr["eta_quantiles"] = {"q05": qe[0].tolist(), "q50": qe[1].tolist(), "q95": qe[2].tolist()}
            if "sigma_s2" in d:
                sig = np.sqrt(d["sigma_s2"][pos].reshape(-1))
                mr["sigma_s"] = {"median": float(np.median(sig)), "q05": float(np.quantile(sig, 0.05)),
                                 "q95": float(np.quantile(sig, 0.95)),
                                 # 200 evenly thinned draws for the density of Fig 9.7
                                 "draws": sig[np.linspace(0, sig.size - 1, min(sig.size, 200)).astype(int)].tolist()}
                draws = {"eta": eta, "sigma_s2": sig**2}
                if "disc" in d:
                    draws.update(disc=d["disc"][pos].reshape(-1, 24), v=d["v"][pos].reshape(-1))
                rep = diagnostics.posterior_predictive(draws, SIGMA_V_ML, np.random.default_rng(s.index))[:, 1:]
                q = np.quantile(rep, [0.05, 0.5, 0.95], axis=0)
                mr["strain_predictive"] = {"q05": q[0].tolist(), "q50": q[1].tolist(), "q95": q[2].tolist()}
            rec["models"][m] = mr
        per_set.append(rec)
    med_sigma = {m: float(np.median([r["models"][m]["sigma_s"]["median"] for r in per_set]))
                 for m in ("iid", "discrepancy")}
    med_err = {m: float(np.median(np.concatenate(errors[m]))) for m in MODELS}
    findings = {
        "iid_sigma_s_inflation": med_sigma["iid"] / SIGMA_S,
        "iid_inflates_sigma_s_about_2x": bool(med_sigma["iid"] / SIGMA_S >= 1.5),
        "discrepancy_sigma_s_median": med_sigma["discrepancy"],
        "discrepancy_sigma_s_near_truth": bool(abs(med_sigma["discrepancy"] - SIGMA_S) <= 0.01),
        "median_abs_error": med_err,
        "discrepancy_beats_iid": bool(med_err["discrepancy"] < med_err["iid"]),
        "volume_beats_iid": bool(med_err["volume"] < med_err["iid"]),
        "chapter": {"iid_sigma_s_inflation": 2.0, "discrepancy_sigma_s_median": CHAPTER_SIGMA_S_DISCREPANCY},
    }
    result = {
        "study": "fibre-discrepancy",
        "synthetic": True,
        "forward_model": getattr(forward, "label", type(forward).__name__),
        "forward_build": _build_record(forward),
        "h": [float(v) for v in h],
        "noise": {"sigma_v_ml": SIGMA_V_ML, "sigma_s": SIGMA_S},
        "sampler": {"num_warmup": config.num_warmup, "num_samples": config.num_samples,
                    "num_chains": config.num_chains, "discrepancy": "HMC-within-Gibbs (Algorithm 4)",
                    "volume_iid": "NUTS"},
        "timings_s": {"simulate": t_sim, **{f"fit_{m}": v for m, v in timings.items()},
                      "total": time.perf_counter() - t_start},
        "findings": findings,
        "sets": per_set,
        "error_draws": {m: np.concatenate(errors[m]).tolist() for m in MODELS},
    }
    if out is not None:
        write_study(result, out)
    return result


def write_study(result: dict, out) -> dict:
    """Write JSON, CSVs behind every figure, and the figures as HTML under ``out``."""
    import pandas as pd

    from lvcore.viz import inference_figures as figs

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "fibre_discrepancy.json"}
    paths["json"].write_text(json.dumps(result, indent=1))
    rows = []
    for s in result["sets"]:
        for m in ("iid", "discrepancy"):
            sp = s["models"][m]["strain_predictive"]
            for r in range(24):
                rows.append({"set": s["set"], "model": m, "region": r, "data": s["y"][1 + r],
                             "q05": sp["q05"][r], "q50": sp["q50"][r], "q95": sp["q95"][r]})
    paths["strain_predictive_csv"] = out / "strain_predictive.csv"
    pd.DataFrame(rows).to_csv(paths["strain_predictive_csv"], index=False)
    paths["sigma_s_csv"] = out / "sigma_s.csv"
    pd.DataFrame([{"set": s["set"], "model": m, **{k: v for k, v in s["models"][m]["sigma_s"].items() if k != "draws"},
                   "truth": SIGMA_S}
                  for s in result["sets"] for m in ("iid", "discrepancy")]).to_csv(paths["sigma_s_csv"], index=False)
    paths["errors_csv"] = out / "errors.csv"
    pd.DataFrame([{"model": m, "mean_abs_strain_error": e} for m, es in result["error_draws"].items()
                  for e in es]).to_csv(paths["errors_csv"], index=False)
    # figures: example set (0, 90) like the chapter, the sigma_S summary and the violins
    ex = next((s for s in result["sets"] if (s["alpha_endo"], s["alpha_epi"]) == (0.0, 90.0)), result["sets"][-1])
    fig = figs.strain_predictive_figure({m: {k: np.asarray(v) for k, v in ex["models"][m]["strain_predictive"].items()}
                                        for m in ("iid", "discrepancy")}, ex["y"])
    fig.update_layout(title=f"SYNTHETIC set {ex['set']} (angles {ex['alpha_endo']:g}, {ex['alpha_epi']:g}): "
                            "posterior predictive of the strains vs data")
    paths["fig_strain_predictive"] = figs.write_html(fig, out / "fig_strain_predictive.html")
    paths["fig_errors"] = figs.write_html(figs.error_violin_figure(
        {m: np.asarray(v) for m, v in result["error_draws"].items()}), out / "fig_errors_violin.html")
    return {k: str(v) for k, v in paths.items()}


def add_study_parser(study_subparsers) -> None:
    """``lvcore study fibre-discrepancy [--json] [--out DIR]``."""
    p = study_subparsers.add_parser("fibre-discrepancy",
                                    help="chapter 9.3.2: iid vs polar-GP discrepancy vs volume-only under wrong fibre angles")
    p.add_argument("--out", default="study_fibre_discrepancy", help="output folder")
    p.add_argument("--json", action="store_true", help="print the findings as JSON")
    p.add_argument("--warmup", type=int, default=1000)
    p.add_argument("--samples", type=int, default=1000)
    p.add_argument("--chains", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--resolution", default="default", help="simulator mesh preset for the test data")
    p.add_argument("--emulator", default="chapter",
                   help="emulator name or directory trained at angles (-60, 60) (default: chapter)")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    samplers.use_host_devices(args.chains)
    cfg = samplers.SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains,
                                 seed=args.seed)
    res = run_study(config=cfg, seed=args.seed, resolution=args.resolution, out=args.out, emulator=args.emulator,
                    progress=None if args.json else (lambda msg, frac: print(msg, flush=True)))
    if args.json:
        print(json.dumps({k: res[k] for k in ("findings", "timings_s", "forward_model")}, indent=2))
    else:
        print(json.dumps(res["findings"], indent=2))
        print(f"wrote {args.out}/fibre_discrepancy.json, CSVs and figures")
    return 0
