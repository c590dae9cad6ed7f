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
import dataclasses
from dataclasses import dataclass
from pathlib import Path

import arviz as az
import jax
import numpy as np

from lvcore import cli_args
from lvcore.core.forward import Forward
from lvcore.emulator.forward import load_emulator_forward
from lvcore.mechanics.forward import SimulatorForward
from lvcore._exports import moved_names
from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP, FIBRE_DISCREPANCY_ANGLE_PAIRS, SIGMA_S, SIGMA_V_ML
from lvcore.inference import coverage, diagnostics, samplers
from lvcore.studies import registry
from lvcore.domain.outputs import ANGLE_NAMES, DEFAULT_STRAIN_LAYER, EDP_NAME, THETA_NAMES, pc_names

THETA_SETS = ((0.1, 5.0, 1.0, 6.0), (0.5, 8.0, 1.5, 6.0), (1.0, 1.0, 1.0, 1.0), (1.0, 5.0, 1.0, 5.0))
#: The synthetic geometry: a point in the shape model's standardised 5-PC space.
DEFAULT_H = (0.5, -0.4, 0.3, -0.2, 0.1)
MODELS = ("volume", "iid", "discrepancy")
#: ``--geometry`` value naming the shipped real LV (patient-derived, not synthetic; :mod:`lvcore.resources`).
REAL_LV = "real-lv"
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


def data_simulator(h=DEFAULT_H, resolution: str = "default", base: str = "clamped",
                   geometry: dict | None = None, strain_layer: str = DEFAULT_STRAIN_LAYER) -> SimulatorForward:
    """The FE simulator that makes the test data: inputs theta and the fibre angles, at 8 mmHg.

    The geometry is the PCA geometry ``h``, or ``geometry`` (a case geometry section, e.g. a subject's template
    mesh ``{"kind": "mesh", "path": ...}``) when given. ``base`` is the basal boundary condition and
    ``strain_layer`` the wall layer of the strains; the study passes the emulator's own, so that the fibre angles
    are the only discrepancy between data and model.
    """
    if geometry is not None:
        return SimulatorForward(input_names=THETA_NAMES + ANGLE_NAMES, conditions={EDP_NAME: CHAPTER_EDP},
                                geometry=dict(geometry), resolution=resolution, base=base, strain_layer=strain_layer,
                                label="FE simulator (fibre-discrepancy test data, subject mesh)")
    return SimulatorForward(input_names=THETA_NAMES + ANGLE_NAMES,
                            conditions={**dict(zip(pc_names(len(h)), map(float, h))), EDP_NAME: CHAPTER_EDP},
                            resolution=resolution, base=base, strain_layer=strain_layer,
                            label="FE simulator (fibre-discrepancy test data)")


def emulator_layer(forward) -> str:
    """The wall layer of ``forward``'s strains: its emulator's (:attr:`lvcore.emulator.model.Emulator.strain_layer`),
    else the default (the inner half)."""
    return getattr(getattr(forward, "emulator", None), "strain_layer", DEFAULT_STRAIN_LAYER)


def geometry_section(geometry) -> dict:
    """The case geometry section of ``--geometry``: ``real-lv`` (the shipped real LV,
    :func:`lvcore.resources.real_lv_files`) or a template mesh (.vtu, e.g. from ``lvcore geometry fit --out``)."""
    from lvcore.resources import real_lv_files

    path = real_lv_files().template if str(geometry) == REAL_LV else Path(geometry)
    return {"kind": "mesh", "path": str(path)}


def subject_forward(emulator, section: dict):
    """The subject emulator ``emulator`` (name or directory) as the study's forward model of theta.

    Raises
    ------
    EmulatorError
        If it is not a subject emulator, was trained on another geometry than ``section`` (template nodes more
        than 1e-6 mm apart) or at other fixed conditions than the study's (angles (-60°, 60°), 8 mmHg).
    """
    from lvcore.emulator.io import load_emulator
    from lvcore.emulator.forward import emulator_forward
    from lvcore.emulator.subject import subject_template_nodes
    from lvcore.exceptions import EmulatorError

    emu = load_emulator(emulator)
    how = (f"build it with lvcore emulator build --geometry {section.get('path')} --out DIR "
           "(theta inputs, angles (-60, 60), 8 mmHg)")
    if not emu.is_subject:
        raise EmulatorError(f"emulator '{emulator}' takes PC scores; a subject mesh needs a subject emulator: {how}")
    gap = np.abs(subject_template_nodes(emu.subject_geometry) - subject_template_nodes(section)).max()
    if not gap <= 1e-6:
        raise EmulatorError(f"emulator '{emulator}' was trained on another geometry (nodes up to {gap:.3g} mm "
                            f"apart): {how}")
    fixed = dict(emu.fixed)
    want = {ANGLE_NAMES[0]: CHAPTER_ANGLES[0], ANGLE_NAMES[1]: CHAPTER_ANGLES[1], EDP_NAME: CHAPTER_EDP}
    bad = {k: fixed.get(k) for k, v in want.items() if fixed.get(k) is None or abs(float(fixed[k]) - v) > 1e-9}
    if bad or tuple(emu.input_names) != THETA_NAMES:
        raise EmulatorError(f"emulator '{emulator}' has inputs {list(emu.input_names)} and fixed {bad}; the study "
                            f"needs theta inputs at {want}: {how}")
    return emulator_forward(emu, (), alpha_endo=CHAPTER_ANGLES[0], alpha_epi=CHAPTER_ANGLES[1],
                            edp_mmhg=CHAPTER_EDP, name=emu.name)


def make_test_sets(forward, h=DEFAULT_H, *, seed: int = 0, simulator: Forward | None = None,
                   resolution: str = "default", progress=None, set_indices=None,
                   geometry: dict | None = None) -> list[TestSet]:
    """The 12 SYNTHETIC test sets (or those in ``set_indices``).

    ``simulator`` reads ``a, b, af, bf, alpha_endo, alpha_epi`` and makes the
    noise-free data (default :func:`data_simulator`); ``forward`` (theta only)
    gives the benchmark; ``geometry`` (a case geometry section) replaces ``h`` in the default simulator.
    Set ``i`` has angles ``FIBRE_DISCREPANCY_ANGLE_PAIRS[i // 4]`` (:mod:`lvcore.domain.conditions`) and theta
    ``THETA_SETS[i % 4]``.
    """
    simulator = simulator or data_simulator(h, resolution, getattr(forward, "base", "clamped"), geometry,
                                            strain_layer=emulator_layer(forward))
    rng = np.random.default_rng(seed)
    out = []
    for i, ((ae, ap), th) in enumerate((a, t) for a in FIBRE_DISCREPANCY_ANGLE_PAIRS for t in THETA_SETS):
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


def _geometry_record(geometry) -> dict:
    """What the test data were simulated on (JSON-ready; a file's name only, no build-machine path)."""
    if geometry is None:
        return {"kind": "pca", "label": "SYNTHETIC PCA geometry h", "synthetic": True}
    if str(geometry) == REAL_LV:
        from lvcore.resources import REAL_LV_LABEL

        return {"kind": "mesh", "source": REAL_LV, "label": REAL_LV_LABEL, "synthetic": False}
    return {"kind": "mesh", "source": Path(geometry).name, "label": f"subject mesh {Path(geometry).name}",
            "synthetic": None}


def _build_record(forward) -> dict:
    """Which emulator build (creation time, mesh, base condition) the study calibrated with."""
    emu = getattr(forward, "emulator", None)
    if emu is None:
        return {"base": getattr(forward, "base", None), "strain_layer": DEFAULT_STRAIN_LAYER}
    return {"name": emu.name, "created_at": emu.metadata.get("created_at"), "resolution": emu.resolution,
            "base": emu.base, "strain_layer": emu.strain_layer, "lvcore_version": emu.metadata.get("lvcore_version")}


def run_study(forward=None, *, h=DEFAULT_H, config: samplers.SamplerConfig | None = None, seed: int = 0,
              simulator: Forward | None = None, resolution: str = "default", out: str | Path | None = None,
              progress=None, set_indices=None, emulator: str = "chapter", geometry=None) -> dict:
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
    geometry : str or Path, optional
        A subject mesh instead of ``h``: ``real-lv`` (:data:`REAL_LV`, the shipped real LV) or a template mesh.
        The test data are FE-simulated on it and the default forward is the subject emulator ``emulator``
        trained on it (:func:`subject_forward`; a directory from ``lvcore emulator build --geometry MESH``).
    """
    t_start = time.perf_counter()
    # Algorithm 4 as the chapter writes it, whatever the caller's config, as in the shipped results
    config = dataclasses.replace(config or samplers.SamplerConfig(), discrepancy_block="chapter")
    section = None if geometry is None else geometry_section(geometry)
    if forward is None:
        forward = load_emulator_forward(emulator, h) if section is None else subject_forward(emulator, section)
    sets = make_test_sets(forward, h, seed=seed, simulator=simulator, resolution=resolution, progress=progress,
                          set_indices=set_indices, geometry=section)
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
        "h": None if section else [float(v) for v in h],
        "geometry": _geometry_record(geometry),
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


# ----------------------------------------------------------------------------- saved results: load, tables, figures
#: Result file of :func:`write_study`, read by :func:`load`.
RESULT_FILE = registry.result_file("fibre-discrepancy")
#: The command that makes the results (15-30 min of MCMC; the package ships one run).
COMMAND = "lvcore study fibre-discrepancy --out RESULTS"
#: Figures and tables :func:`figures` draws, with their titles.
TITLES = {
    "fig9_6_strain_predictive": "Fig 9.6: posterior predictive of the strains, iid vs discrepancy model",
    "fig9_7_sigma_s": f"Fig 9.7: posterior of the strain noise sd σ_S vs the truth {SIGMA_S:g}",
    "fig9_7_sigma_s_all_sets": "Fig 9.7 (all sets): σ_S median and 90 % interval per test set",
    "fig9_8_eta_vs_benchmark": "Fig 9.8: posterior of η(θ, h) vs the benchmark η(θ̃, h), three test sets",
    "fig9_9_error_violins": "Fig 9.9: |η(θ_post, h) − η(θ̃, h)| over the 12 test sets, per likelihood",
    "table_fibre_discrepancy_findings": "Fibre-discrepancy findings against the chapter",
}
#: Why a figure is absent from older results.
MISSING = {"fig9_7_sigma_s": "the results hold no σ_S draws (older study output)",
           "fig9_8_eta_vs_benchmark": "the results hold no η quantiles (older study output)"}


def load(folder) -> dict:
    """The result file (:data:`RESULT_FILE`) of a result folder (or the bundled one), with ``folder``.

    Examples
    --------
    The bundled (SYNTHETIC) result:

    >>> from lvcore.studies import fibre_discrepancy
    >>> from lvcore.studies.results import bundled_studies_dir
    >>> result = fibre_discrepancy.load(bundled_studies_dir())
    >>> len(result["sets"])                      # the chapter's 12 fibre-angle sets
    12
    """
    from lvcore.studies.results import read_result

    return read_result(folder, RESULT_FILE)


def _build_text(build) -> str:
    if not build:
        return "build not recorded"
    parts = [f"built {build['created_at'][:10]}" if build.get("created_at") else None,
             f"{build['resolution']} mesh" if build.get("resolution") else None,
             f"{build['base']} base" if build.get("base") else None]
    return ", ".join(p for p in parts if p)


def _sampler_text(sampler) -> str:
    if not isinstance(sampler, dict) or not sampler:
        return "sampler not recorded"
    runs = ""
    if {"num_chains", "num_warmup", "num_samples"} <= set(sampler):
        runs = f"{sampler['num_chains']} chains × ({sampler['num_warmup']} warm-up + {sampler['num_samples']} draws)"
    kinds = "; ".join(f"{v} for {k.replace('_', ' and ')}" for k, v in sampler.items()
                      if k not in ("num_chains", "num_warmup", "num_samples"))
    return ", ".join(p for p in (runs, kinds) if p)


def source_line(result: dict) -> str:
    """Where the numbers come from, as one readable line (no Python reprs)."""
    from lvcore.studies.results import source_label

    return (f"{RESULT_FILE} ({source_label(result['folder'])}); forward model {result.get('forward_model', '?')} "
            f"emulator ({_build_text(result.get('forward_build'))}); sampler: {_sampler_text(result.get('sampler'))}")


def example_set(result: dict) -> dict:
    """The set shown in Figs 9.6/9.7: angles (0°, 90°) like the chapter, else the last one."""
    sets = result["sets"]
    return next((s for s in sets if (s["alpha_endo"], s["alpha_epi"]) == (0.0, 90.0)), sets[-1])


def _set_label(s: dict) -> str:
    return f"set {s['set']} ({s['alpha_endo']:g}°, {s['alpha_epi']:g}°)"


def eta_cases(result: dict) -> list[dict]:
    """Fig 9.8's three sets: the example first, then the same θ at the other angle pairs."""
    sets, ex = result["sets"], example_set(result)
    same_theta = [s for s in sets if s["theta"] == ex["theta"] and s is not ex]
    return [ex] + (same_theta or [s for s in sets if s is not ex])[:2]


def tables(result: dict) -> dict:
    """The data behind each figure (by figure name), and the findings table."""
    import pandas as pd

    from lvcore.inference.models import MODEL_LABELS

    sets, ex = result["sets"], example_set(result)
    pair = ("iid", "discrepancy")
    out = {"fig9_6_strain_predictive": pd.DataFrame(
        [{"set": ex["set"], "model": m, "region": r + 1, "data": ex["y"][1 + r],
          **{q: ex["models"][m]["strain_predictive"][q][r] for q in ("q05", "q50", "q95")}}
         for m in pair for r in range(24)])}
    if all("draws" in ex["models"][m]["sigma_s"] for m in pair):
        out["fig9_7_sigma_s"] = {"set": ex["set"], "truth": SIGMA_S,
                                 "draws": {MODEL_LABELS[m]: list(ex["models"][m]["sigma_s"]["draws"]) for m in pair}}
    out["fig9_7_sigma_s_all_sets"] = pd.DataFrame(
        [{"label": _set_label(s), "series": MODEL_LABELS[m], **{k: s["models"][m]["sigma_s"][k]
                                                                for k in ("median", "q05", "q95")}}
         for s in sets for m in pair])
    cases = eta_cases(result)
    if all("eta_quantiles" in c["models"][m] for c in cases for m in MODELS):
        out["fig9_8_eta_vs_benchmark"] = pd.DataFrame(
            [{"set": c["set"], "model": m, "region": r + 1, "benchmark": c["benchmark"][1 + r],
              **{q: c["models"][m]["eta_quantiles"][q][1 + r] for q in ("q05", "q50", "q95")}}
             for c in cases for m in MODELS for r in range(24)])
    out["fig9_9_error_violins"] = pd.DataFrame([{"model": m, "mean_abs_strain_error": e}
                                                for m, es in result["error_draws"].items() for e in es])
    f = result["findings"]
    med = f["median_abs_error"]
    out["table_fibre_discrepancy_findings"] = pd.DataFrame([
        {"finding": f"iid inflates σ_S (median / {SIGMA_S:g})", "ours": f["iid_sigma_s_inflation"],
         "chapter": f["chapter"]["iid_sigma_s_inflation"], "holds": f["iid_inflates_sigma_s_about_2x"]},
        {"finding": "discrepancy model σ_S median", "ours": f["discrepancy_sigma_s_median"],
         "chapter": f["chapter"]["discrepancy_sigma_s_median"], "holds": f["discrepancy_sigma_s_near_truth"]},
        {"finding": "discrepancy beats iid (median |error|)", "ours": f"{med['discrepancy']:.4f} vs {med['iid']:.4f}",
         "chapter": "yes", "holds": f["discrepancy_beats_iid"]},
        {"finding": "volume-only beats iid (median |error|)", "ours": f"{med['volume']:.4f} vs {med['iid']:.4f}",
         "chapter": "yes", "holds": f["volume_beats_iid"]},
    ])
    out["sets"] = pd.DataFrame([{"set": s["set"], "alpha_endo": s["alpha_endo"], "alpha_epi": s["alpha_epi"],
                                 "model": MODEL_LABELS[m], "median |error|": r["abs_error_median"],
                                 "σ_S median": r.get("sigma_s", {}).get("median")}
                                for s in sets for m, r in s["models"].items()])
    return out


def captions(result: dict) -> dict:
    """Notes shown under figures (the thinning of the shipped draws)."""
    thinned = result.get("error_draws_thinned_to_per_set")
    return {"fig9_9_error_violins": f"posterior draws thinned to {thinned} per set"} if thinned else {}


def figures(result: dict) -> dict:
    """The study's figures by name (see :data:`TITLES`); those the results lack (:data:`MISSING`) are left out."""
    from lvcore.inference.models import MODEL_LABELS
    from lvcore.viz import inference_figures as ifig
    from lvcore.viz.report_figures import eta_band_grid, interval_figure, table_figure

    tabs = tables(result)
    ex, tag, n_sets = example_set(result), "SYNTHETIC", len(result["sets"])
    ex_label = f"set {ex['set']}, angles ({ex['alpha_endo']:g}°, {ex['alpha_epi']:g}°)"
    out = {}
    fig = ifig.strain_predictive_figure(
        {MODEL_LABELS[m]: {k: np.asarray(v) for k, v in ex["models"][m]["strain_predictive"].items()}
         for m in ("iid", "discrepancy")}, ex["y"])
    fig.update_layout(title=f"Fig 9.6 — {tag} {ex_label}: posterior predictive of the 24 strains (median, 5–95 %) "
                            "vs data")
    out["fig9_6_strain_predictive"] = fig
    if "fig9_7_sigma_s" in tabs:
        fig = ifig.sigma_s_figure({k: np.asarray(v) for k, v in tabs["fig9_7_sigma_s"]["draws"].items()},
                                  truth=SIGMA_S)
        fig.update_layout(title=f"Fig 9.7 — {tag} {ex_label}: posterior of σ_S; dashed: truth {SIGMA_S}")
        out["fig9_7_sigma_s"] = fig
    out["fig9_7_sigma_s_all_sets"] = interval_figure(
        tabs["fig9_7_sigma_s_all_sets"].to_dict("records"), truth=SIGMA_S, xaxis_title="σ_S (strain)",
        title=f"Fig 9.7 (all sets) — {tag}: posterior median and 5–95 % of σ_S per test set; dashed: truth {SIGMA_S}")
    if "fig9_8_eta_vs_benchmark" in tabs:
        spec = [{"title": _set_label(c), "benchmark": c["benchmark"],
                 "bands": {MODEL_LABELS[m]: c["models"][m]["eta_quantiles"] for m in MODELS}}
                for c in eta_cases(result)]
        out["fig9_8_eta_vs_benchmark"] = eta_band_grid(
            spec, [MODEL_LABELS[m] for m in MODELS],
            title=f"Fig 9.8 — {tag}: posterior of η(θ, h) (5–95 %, median) vs the benchmark η(θ̃, h) (dashed)")
    fig = ifig.error_violin_figure({MODEL_LABELS[m]: np.asarray(v) for m, v in result["error_draws"].items()})
    fig.update_layout(title=f"Fig 9.9 — {tag}: mean |η(θ_post, h) − η(θ̃, h)| over the 24 strains, all "
                            f"{n_sets} test sets, per likelihood")
    out["fig9_9_error_violins"] = fig
    out["table_fibre_discrepancy_findings"] = table_figure(
        tabs["table_fibre_discrepancy_findings"], title=f"Fibre-discrepancy study ({tag}): findings vs the chapter")
    return out


#: Markers of the block of docs/calibration.md written by :func:`docs_markdown` (a test compares the two).
DOCS_BEGIN = "<!-- fibre-discrepancy shipped numbers: begin (generated by lvcore.studies.fibre_discrepancy.docs_markdown) -->"
DOCS_END = "<!-- fibre-discrepancy shipped numbers: end -->"


def docs_markdown(result: dict) -> str:
    """The docs' tables of a study result: findings against the chapter, and one row per test set.

    docs/calibration.md quotes the shipped run through this text only, between
    :data:`DOCS_BEGIN` and :data:`DOCS_END`; ``tests/test_studies_fibre_discrepancy.py``
    checks that the block equals this function's output for the shipped JSON.
    The strain mismatch of a set is the RMS over the 24 strains of the
    noise-free simulator data minus the emulator at the true θ (the model
    the fits assume).
    """
    f, med = result["findings"], result["findings"]["median_abs_error"]
    b, smp, t = result.get("forward_build") or {}, result.get("sampler") or {}, result.get("timings_s") or {}
    yes = {True: "yes", False: "no"}
    lines = [
        f"Emulator: `{b.get('name', '?')}` ({_build_text(b)}). Sampler: {_sampler_text(smp)}. "
        f"Run time {t.get('total', float('nan')):.0f} s (simulations {t.get('simulate', float('nan')):.0f} s, "
        f"volume {t.get('fit_volume', float('nan')):.0f} s, iid {t.get('fit_iid', float('nan')):.0f} s, "
        f"discrepancy {t.get('fit_discrepancy', float('nan')):.0f} s).",
        "",
        "| quantity | shipped run | chapter |",
        "|---|---|---|",
        f"| iid σ_S, median over sets / {SIGMA_S:g} | **{f['iid_sigma_s_inflation']:.2f}×** | "
        f"≈ {f['chapter']['iid_sigma_s_inflation']:g}× |",
        f"| discrepancy σ_S, median over sets | **{f['discrepancy_sigma_s_median']:.4f}** | "
        f"{f['chapter']['discrepancy_sigma_s_median']:g} |",
        f"| median \\|η(θ_post) − η(θ̃)\\| over strains, draws and sets: volume / iid / discrepancy | "
        f"**{med['volume']:.4f} / {med['iid']:.4f} / {med['discrepancy']:.4f}** | volume ≈ discrepancy < iid |",
        f"| discrepancy beats iid; volume beats iid | {yes[f['discrepancy_beats_iid']]}; "
        f"{yes[f['volume_beats_iid']]} | yes; yes |",
        "",
        "| set | angles (°) | θ = (a, b, af, bf) | strain mismatch RMS | median \\|error\\| volume / iid / discrepancy "
        "| σ_S iid / discrepancy |",
        "|---|---|---|---|---|---|",
    ]
    for st in result["sets"]:
        z, bench = np.asarray(st["z"]), np.asarray(st["benchmark"])
        rms = float(np.sqrt(np.mean((z[1:] - bench[1:]) ** 2)))
        m = st["models"]
        th = ", ".join(f"{st['theta'][n]:g}" for n in THETA_NAMES)
        lines.append(f"| {st['set']} | ({st['alpha_endo']:g}, {st['alpha_epi']:g}) | ({th}) | {rms:.4f} | "
                     + " / ".join(f"{m[k]['abs_error_median']:.4f}" for k in MODELS)
                     + f" | {m['iid']['sigma_s']['median']:.4f} / {m['discrepancy']['sigma_s']['median']:.4f} |")
    return "\n".join(lines)


def write_study(result: dict, out) -> dict:
    """Write the JSON, the CSVs behind the figures and the figures as HTML under ``out`` (through :func:`tables`
    and :func:`figures`, the same as the Studies page and ``lvcore report``)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / RESULT_FILE}
    paths["json"].write_text(json.dumps(result, indent=1))
    tabs = tables(result)
    # sigma_s.csv: every set's sigma_S summary (Fig 9.7), errors.csv: the draws of the Fig 9.9 violins
    for key, name in (("fig9_6_strain_predictive", "strain_predictive"), ("fig9_7_sigma_s_all_sets", "sigma_s"),
                      ("fig9_9_error_violins", "errors")):
        paths[f"{name}_csv"] = out / f"{name}.csv"
        tabs[key].to_csv(paths[f"{name}_csv"], index=False)
    figs = figures(result)
    for key, name in (("fig9_6_strain_predictive", "fig_strain_predictive"), ("fig9_9_error_violins", "fig_errors_violin")):
        paths[name] = out / f"{name}.html"
        figs[key].write_html(str(paths[name]), include_plotlyjs=True)
    return {k: str(v) for k, v in paths.items()}


def add_study_parser(study_subparsers) -> None:
    """``lvcore study fibre-discrepancy [--json] [--out DIR]``."""
    p = study_subparsers.add_parser("fibre-discrepancy",
                                    help="chapter 9.3.2: iid vs polar-GP discrepancy vs volume-only under wrong fibre angles")
    p.add_argument("--out", type=cli_args.output_dir, default="study_fibre_discrepancy",
                   help="output folder, created if missing (default study_fibre_discrepancy)")
    p.add_argument("--json", action="store_true", help="print the findings as JSON")
    p.add_argument("--warmup", type=cli_args.int_in(1, 1_000_000), default=1000,
                   help="warm-up iterations per chain (default 1000)")
    p.add_argument("--samples", type=cli_args.int_in(1, 1_000_000), default=1000,
                   help="draws kept per chain (default 1000)")
    p.add_argument("--chains", type=cli_args.int_in(1, 64), default=4, help="MCMC chains, 1 to 64 (default 4)")
    p.add_argument("--seed", type=cli_args.seed, default=0, help="random seed, 0 to 2^32 - 1 (default 0)")
    p.add_argument("--resolution", default="default",
                   help="simulator mesh preset for the test data (default 'default')")
    p.add_argument("--emulator", default="chapter",
                   help=f"emulator name or directory trained at angles ({CHAPTER_ANGLES[0]:g}, {CHAPTER_ANGLES[1]:g}) "
                        "(default: chapter)")
    p.add_argument("--geometry", default=None,
                   help=f"a subject mesh instead of the PCA geometry h: '{REAL_LV}' (the shipped real, patient-derived "
                        "LV) or a template mesh (.vtu); the data are FE-simulated on it and --emulator must be a "
                        "subject emulator of it (lvcore emulator build --geometry MESH --out DIR) "
                        "(default: the SYNTHETIC PCA geometry h)")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    samplers.use_host_devices(args.chains)
    cfg = samplers.SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains,
                                 seed=args.seed)
    res = run_study(config=cfg, seed=args.seed, resolution=args.resolution, out=args.out, emulator=args.emulator,
                    geometry=args.geometry, progress=None if args.json else (lambda msg, frac: print(msg, flush=True)))
    if args.json:
        print(json.dumps({k: res[k] for k in ("findings", "timings_s", "forward_model")}, indent=2))
    else:
        print(json.dumps(res["findings"], indent=2))
        print(f"wrote {args.out}/{RESULT_FILE}, CSVs and figures")
    return 0


#: Moved: the study's angle pairs live with the other conditions.
__getattr__ = moved_names(__name__, {"ANGLE_SETS": "lvcore.domain.conditions:FIBRE_DISCREPANCY_ANGLE_PAIRS"})
