"""Model–data mismatch as a dose–response (issue 26, item 2): ``lvcore study mismatch``.

The chapter's findings on the likelihoods (F1: iid inflates σ_S about 2×;
F2: the discrepancy model's σ_S near the truth; F3: discrepancy ≈ volume <
iid in output error) depend on how far the data are from the model. Here the
SYNTHETIC data come from the FE simulator with one **mismatch source** at a
**dose** that the calibration model (the ``chapter`` emulator: HO law with
the population sheet terms, no dispersion, homogeneous, no pericardium,
angles (−60°, 60°), sliding base) does not have:

=================  ==========================================================  =====================
source             what the data-generating simulator changes                  dose
=================  ==========================================================  =====================
``angles``         both helix angles rotated: (−60 + d, 60 + d)                d in degrees
``base``           clamped instead of sliding base                             1 (one dose)
``sheet``          sheet and fibre-sheet stiffnesses ``as``, ``afs`` × d       multiplier d
``dispersion``     GOH fibre dispersion ``kappa`` = d                          κ in [0, 1/3]
``heterogeneity``  per-region multipliers exp(d·z) of a and af, z ~ N(0, 1)    log-sd d
                   with a fixed seed (the same field for every volunteer)
``pericardium``    epicardial Robin spring, normal direction, k = d            kPa/mm
=================  ==========================================================  =====================

For each volunteer (the bundled SYNTHETIC HV1–HV8, on the PCA geometry of
their recorded scores h, at their hidden θ) the simulator runs once without
mismatch (the *nominal* outputs) and once per (source, dose). The dose's
size is measured as the RMS over the 24 strains of (mismatched − nominal).
Each mismatched output gets ``seeds`` noise draws (σ_V = 5 mL, σ_S = 0.03)
and every data set is calibrated with the volume, iid and discrepancy
likelihoods on the emulator at the volunteer's h. Reported per (source,
dose), each with a percentile bootstrap CI over the data sets:

* the iid σ_S inflation (median posterior σ_S / 0.03, median over data sets);
* the discrepancy model's σ_S;
* the output error per likelihood: |η(θ_post, h) − η(θ_true, h)| over the
  24 strains, median over draws, median over data sets;
* the θ coverage per likelihood: the fraction of the 4 central 90 %
  intervals that cover the true θ;

and per source the smallest dose at which F1 (iid inflation ≥ 1.5 with the
CI above 1.2) and the F3 ordering (discrepancy and volume errors below iid's)
appear, or "does not appear up to RMS x".

**The real LV.** ``volunteers=[..., "REAL-LV"]`` (``--volunteers ...,REAL-LV``) adds the shipped REAL,
patient-derived LV (:func:`lvcore.resources.real_lv_files`) as a volunteer at a fixed hidden θ
(:data:`REAL_LV_THETA`, the SYNTHETIC volunteers' median): its nominal and mismatched data are FE-simulated on its
template mesh with the same sources (each applies to a mesh), and its fits go through a subject emulator of that
mesh at the model's conditions (``subject_emulators={"REAL-LV": DIR}``, ``--subject-emulator REAL-LV=DIR``;
:func:`subject_forward` refuses another geometry, base, strain layer or fixed angles and EDP, and says how to build
the right one). Its fit files have the volunteers' format and name tag, so that one work folder holds both and a
``recorded_only`` run summarises them together (``per_volunteer`` names ``REAL-LV``).

**Resumable.** Each simulation result is written atomically to
``OUT/sims/<volunteer>__<source>__<dose>.json`` and each fit to
``OUT/fits/...json`` as soon as it finishes; a rerun with the same ``OUT``
skips what is there. Simulations run on the campaign executors (a local
process pool, or a Dask scheduler with ``--scheduler``), as campaigns do.
The full chapter-size run (6 sources × 4–5 doses × 8 volunteers × ≥ 20
seeds) is not done by default; see docs/studies.md for its cost.

**Discrepancy kernel.** The discrepancy likelihood uses the chapter's additive
polar kernel unless ``--discrepancy-kernel product`` (``SamplerConfig``'s
``discrepancy_kernel``) asks for the product (sector × level) one. The result
records it (``discrepancy_kernel``; the source line, the figures and the docs
text name a product-kernel run as such), and a product-kernel run's fit files
carry ``_kproduct`` in their name and the kernel in their record: a work folder
keeps the two kernels' fits apart, and a fit file of the other kernel is refused.
"""
from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from lvcore.domain.conditions import CHAPTER_EDP, SIGMA_S, SIGMA_V_ML
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, THETA_NAMES
from lvcore.studies._common import clean, write_json_atomic
from lvcore.studies.mismatch_docs import DOCS_BEGIN, DOCS_END, docs_markdown, mesh_note, volunteers_text
from lvcore.studies.mismatch_fit import (BATCH, F1_CI_FLOOR, F1_INFLATION, MODELS, PER_VOLUNTEER_DIGITS,  # noqa: F401
                                         appearance, budget_text, fit_cost, fit_datasets, noisy_copies,
                                         per_volunteer_values, promote_check, sampler_text, summarise, unit_seed,
                                         verdict_rows, verdict_rows_by_dose)
from lvcore.studies.mismatch_sim import (DEFAULT_DOSES, HETEROGENEITY_SEED, MODEL_ANGLES, MODEL_BASE,  # noqa: F401
                                         REAL_LV, REAL_LV_THETA, SOURCE_LABELS, SOURCES, Volunteer, bundled_volunteers,
                                         dose_key, dose_label, measured_doses, mismatch_case, model_conditions_text,
                                         real_lv_volunteer,
                                         simulate_all, strain_rms, study_volunteers)
from lvcore.studies import registry

#: Result file of :func:`run_study` (the shipped one is under ``assets/studies/``), read by :func:`load`.
RESULT_FILE = registry.result_file("mismatch")


def run_study(*, sources: Sequence[str] = SOURCES, doses: dict | None = None, volunteers: Sequence[str] | None = None,
              seeds: int = 20, config=None, seed: int = 0, resolution: str = "default", emulator: str = "chapter",
              workers: int = 1, scheduler: str | None = None, out: str | Path = "study_mismatch",
              progress: Callable | None = None, retry_failed: bool = False, simulate_only: bool = False,
              batch: int = BATCH, recorded_only: bool = False, result_file: str = RESULT_FILE,
              subject_emulators: dict | None = None) -> dict:
    """Run (or resume) the study under ``out``; returns the result (also written to ``out/<result_file>``).

    Every data set of every volunteer and dose goes through one compiled
    sampler per likelihood, in batches of ``batch`` data sets (the
    volunteers' PC scores are run-time arguments); each (volunteer, source,
    dose)'s fits are written as soon as its batch finishes. With
    ``simulate_only`` only the simulations run and the measured strain RMS
    of each dose is returned (``doses_measured``) and written to ``out/doses.json``.
    With ``recorded_only`` no new fits start: the result summarises the doses
    whose fits are recorded and lists the others under ``not_fitted``.
    ``fit_cost`` sums the CPU seconds of the MCMC batches behind the fits
    (each fit file records its batch's cost; a padded batch counts in full).
    ``config.discrepancy_kernel``: the discrepancy likelihood's GP kernel (module docstring).
    ``volunteers`` may hold :data:`REAL_LV` (the real LV's mesh, at :data:`REAL_LV_THETA`); its fits go through
    the subject emulator ``subject_emulators[REAL_LV]`` (a name or directory, checked by :func:`subject_forward`),
    in batches of their own, and are written in the same fit-file format as the volunteers'.
    """
    from lvcore.inference import samplers

    t0 = time.perf_counter()
    out = Path(out)
    # Algorithm 4 as the chapter writes it, whatever the caller's config: the shipped results were made with it,
    # and a resumed study must not mix samplers (its recorded fits are keyed by budget, not by sampler)
    config = dataclasses.replace(config or samplers.SamplerConfig(), discrepancy_block="chapter")
    kernel, tag = _fit_tag(seeds, config)
    plan = {s: tuple(float(d) for d in (doses or {}).get(s, DEFAULT_DOSES[s])) for s in sources}
    bad = sorted(set(plan) - set(SOURCES))
    if bad:
        raise ValueError(f"unknown mismatch source(s) {bad}; choose from {SOURCES}")
    vols = study_volunteers(volunteers)
    subject_emulators = dict(subject_emulators or {})
    stray = sorted(set(subject_emulators) - {v.name for v in vols if v.geometry is not None})
    if stray:
        raise ValueError(f"subject emulator(s) given for {stray}, which are not mesh volunteers of this run")
    subjects = {} if simulate_only else {  # a recorded-only run checks (and names) only the emulators it is given
        v.name: subject_forward(_needs_subject(v, subject_emulators), v) for v in vols
        if v.geometry is not None and (v.name in subject_emulators or not recorded_only)}
    sims = simulate_all(vols, plan, out, resolution=resolution, workers=workers, scheduler=scheduler,
                        progress=progress, retry_failed=retry_failed)
    t_sim = time.perf_counter() - t0
    rms = measured_doses(sims, vols, plan)
    measured = [{"source": s, "dose": d, "strain_rms_mismatch": r} for (s, d), r in rms.items()]
    if simulate_only:
        res = {"study": "mismatch", "synthetic": True, "volunteers": [v.name for v in vols], "resolution": resolution,
               "doses_measured": measured, "timings_s": {"simulate": t_sim}}
        write_json_atomic(out / "doses.json", clean(res))
        return res
    fits, failed, todo = {}, [], []
    for v in vols:
        nominal = sims[dose_key(v.name, None, 0.0)]
        if not nominal["converged"]:
            failed.append({"key": dose_key(v.name, None, 0.0), "reason": nominal["reason"]})
            continue
        for source, ds in plan.items():
            for dose in ds:
                key = dose_key(v.name, source, dose)
                rec = sims[key]
                if not rec["converged"]:
                    failed.append({"key": key, "reason": rec["reason"]})
                    continue
                path = out / "fits" / f"{key}__{tag}.json"
                if path.is_file():
                    fits.setdefault((source, dose), {})[v.name] = _recorded_fit(path, kernel)
                else:
                    todo.append((v, source, dose, key, np.asarray(rec["outputs"], dtype=float)))
    not_fitted = [{"volunteer": u[0].name, "source": u[1], "dose": u[2]} for u in todo] if recorded_only else []
    if todo and not recorded_only:
        _fit_all(todo, vols, emulator, subjects, fits, out=out, tag=tag, kernel=kernel, seeds=seeds, seed=seed,
                 batch=batch, config=config, progress=progress)
    t_fit = time.perf_counter() - t0 - t_sim
    rows = summarise({k: fits[k] for k in rms if k in fits}, rms)
    costs = [f["batch_cost"] for per in fits.values() for f in per.values() if "batch_cost" in f]
    result = {
        "study": "mismatch", "synthetic": True,
        "emulator": emulator, "resolution": resolution,
        "model_conditions": {"angles": list(MODEL_ANGLES), "base": MODEL_BASE},
        "volunteers": [v.name for v in vols], "seeds_per_dose": seeds,
        **({"subject_emulators": {n: f.label for n, f in subjects.items()},
            "mesh_volunteers": {v.name: {"theta": v.theta, "geometry": _geometry_label(v)}
                                for v in vols if v.geometry is not None}} if any(v.geometry for v in vols) else {}),
        "doses": {s: list(d) for s, d in plan.items()},
        "doses_measured": measured,
        "sampler": {"num_warmup": config.num_warmup, "num_samples": config.num_samples,
                    "num_chains": config.num_chains, "batch": batch},
        "noise": {"sigma_v_ml": SIGMA_V_ML, "sigma_s": SIGMA_S},
        "discrepancy_kernel": kernel,
        "rows": rows, "appearance": appearance(rows), "failed": failed, "not_fitted": not_fitted,
        "complete": not not_fitted and not failed,
        "timings_s": {"simulate": t_sim, "calibrate": t_fit, "total": time.perf_counter() - t0},
        "fit_cost": fit_cost(costs),
    }
    write_json_atomic(out / result_file, clean(result))
    return result


def _needs_subject(volunteer, subject_emulators: dict):
    """The subject emulator given for a mesh volunteer, or a ValueError saying how to give and build one."""
    if volunteer.name not in subject_emulators:
        raise ValueError(f"volunteer {volunteer.name} is a mesh (not PC scores): its fits need a subject emulator of "
                         f"that mesh, given as subject_emulators={{'{volunteer.name}': DIR}} (CLI --subject-emulator "
                         f"{volunteer.name}=DIR); {_build_hint(volunteer)}")
    return subject_emulators[volunteer.name]


def _build_hint(volunteer) -> str:
    return (f"build one with lvcore emulator build --geometry {volunteer.geometry.get('path')} --base {MODEL_BASE} "
            f"--strain-layer {DEFAULT_STRAIN_LAYER} --alpha-endo {MODEL_ANGLES[0]:g} --alpha-epi {MODEL_ANGLES[1]:g} "
            f"--edp {CHAPTER_EDP:g} --out DIR")


def _geometry_label(volunteer) -> str:
    """A mesh volunteer's geometry without a machine path: the real LV's label, else the mesh file's name."""
    from lvcore.resources import REAL_LV_LABEL

    return REAL_LV_LABEL if volunteer.name == REAL_LV else Path(str(volunteer.geometry.get("path"))).name


def subject_forward(emulator, volunteer):
    """The subject emulator ``emulator`` (name or directory) as the forward model of a mesh ``volunteer``'s fits.

    Raises
    ------
    EmulatorError
        If it is not a subject emulator, was trained on another geometry than the volunteer's mesh (template nodes
        more than 1e-6 mm apart), or at other conditions than the calibration model's: θ inputs, angles
        :data:`MODEL_ANGLES`, 8 mmHg, base :data:`MODEL_BASE`, strains of the inner half (the ``chapter``
        emulator's). The message says how to build the right one.
    """
    from lvcore.domain.outputs import ANGLE_NAMES, EDP_NAME
    from lvcore.emulator.forward import emulator_forward
    from lvcore.emulator.io import load_emulator
    from lvcore.emulator.subject import subject_template_nodes
    from lvcore.exceptions import EmulatorError

    emu = load_emulator(emulator)
    how = _build_hint(volunteer)
    if not emu.is_subject:
        raise EmulatorError(f"emulator '{emulator}' takes PC scores; volunteer {volunteer.name} (a mesh) needs a "
                            f"subject emulator: {how}")
    gap = np.abs(subject_template_nodes(emu.subject_geometry) - subject_template_nodes(volunteer.geometry)).max()
    if not gap <= 1e-6:
        raise EmulatorError(f"emulator '{emulator}' was trained on another geometry than volunteer {volunteer.name}'s "
                            f"mesh (nodes up to {gap:.3g} mm apart): {how}")
    fixed, want = dict(emu.fixed), {ANGLE_NAMES[0]: MODEL_ANGLES[0], ANGLE_NAMES[1]: MODEL_ANGLES[1],
                                    EDP_NAME: CHAPTER_EDP}
    bad = {k: fixed.get(k) for k, v in want.items() if fixed.get(k) is None or abs(float(fixed[k]) - v) > 1e-9}
    if emu.base != MODEL_BASE:
        bad["base"] = emu.base
    if emu.strain_layer != DEFAULT_STRAIN_LAYER:
        bad["strain_layer"] = emu.strain_layer
    if bad or tuple(emu.input_names) != THETA_NAMES:
        raise EmulatorError(f"emulator '{emulator}' has inputs {list(emu.input_names)} and {bad}; the mismatch "
                            f"study's model needs θ inputs at {want}, base {MODEL_BASE}, strain layer "
                            f"{DEFAULT_STRAIN_LAYER}: {how}")
    return emulator_forward(emu, (), alpha_endo=MODEL_ANGLES[0], alpha_epi=MODEL_ANGLES[1], edp_mmhg=CHAPTER_EDP,
                            name=emu.name)


def _fit_all(todo, vols, emulator, subjects, fits, *, out, tag, kernel, seeds, seed, batch, config, progress):
    """Fit the ``todo`` units ((volunteer, source, dose, key, outputs)) in batches and write each one's fit file.

    The volunteers over PC scores share one compiled sampler on ``emulator`` (their scores are run-time
    conditions); each mesh volunteer is fitted on its subject forward model (``subjects``) in batches of its own.
    """
    import jax

    from lvcore.emulator.forward import emulator_forward
    from lvcore.emulator.io import load_emulator
    from lvcore.inference import samplers

    pca = [v for v in vols if v.geometry is None and any(u[0].name == v.name for u in todo)]
    fwd, cond = dict(subjects), {}
    if pca:
        emu = load_emulator(emulator)
        fwd.update({v.name: emulator_forward(emu, v.h, name=emulator) for v in pca})
        cond = {v.name: np.asarray(samplers.runtime_conditions(fwd[v.name])[1]["conditions"]) for v in pca}
    groups: dict = {}
    for u in todo:  # one compiled sampler per group: the PCA volunteers together, each mesh volunteer alone
        groups.setdefault(None if u[0].geometry is None else u[0].name, []).append(u)
    per = max(1, batch // seeds)  # (volunteer, source, dose) units per batch
    done = 0
    for group, items in groups.items():
        for b in range(0, len(items), per):
            units = items[b:b + per]
            padded = units + [units[0]] * (per - len(units))  # same shape every batch: no recompilation
            ys, cs, th, et, ks = [], [], [], [], []
            for v, source, dose, key, z in padded:
                us = unit_seed(key, seed)
                ys.append(noisy_copies(z, seeds, us))
                if group is None:
                    cs.append(np.repeat(cond[v.name][None, :], seeds, axis=0))
                th.append(np.repeat(np.array([[v.theta[n] for n in THETA_NAMES]]), seeds, axis=0))
                et.append(np.repeat(np.asarray(fwd[v.name](v.theta), dtype=float)[None, :], seeds, axis=0))
                ks.append(jax.random.split(jax.random.PRNGKey(us), seeds))
            done += len(units)
            if progress:
                progress(f"calibrating {', '.join(u[3] for u in units)}: {len(units) * seeds} data sets x "
                         f"{len(MODELS)} likelihoods ({done}/{len(todo)})")
            cpu0, wall0 = time.process_time(), time.perf_counter()
            res = fit_datasets(fwd[units[0][0].name], np.concatenate(ys), np.concatenate(cs) if cs else None,
                               np.concatenate(th), np.concatenate(et), config=config, keys=np.concatenate(ks))
            cost = {"cpu_s": time.process_time() - cpu0, "wall_s": time.perf_counter() - wall0,
                    "datasets": len(padded) * seeds, "units": len(units)}
            if progress:
                progress(f"  batch done: {cost['cpu_s']:.0f} CPU-s, {cost['wall_s']:.0f} s wall for "
                         f"{cost['datasets']} data sets x {len(MODELS)} likelihoods")
            for i, (v, source, dose, key, _) in enumerate(units):
                sl = slice(i * seeds, (i + 1) * seeds)
                fit = clean({**{m: {k: np.asarray(a)[sl] for k, a in r.items()} for m, r in res.items()},
                             "batch_cost": cost, **({} if kernel == "additive" else {"discrepancy_kernel": kernel})})
                write_json_atomic(out / "fits" / f"{key}__{tag}.json", fit)
                fits.setdefault((source, dose), {})[v.name] = fit


def _fit_tag(seeds: int, config) -> tuple[str, str]:
    """``(kernel, tag)``: the discrepancy kernel of ``config`` (checked) and the fit files' name tag (seeds and
    sampler budget), with ``_k<kernel>`` for a kernel other than the chapter's (whose file names stay as they
    were), so that one work folder keeps the two kernels' fits apart."""
    from lvcore.inference.models import check_kernel

    kernel = check_kernel(config.discrepancy_kernel)
    tag = f"s{seeds}_w{config.num_warmup}_n{config.num_samples}_c{config.num_chains}"
    return kernel, tag + ("" if kernel == "additive" else f"_k{kernel}")


def _recorded_fit(path: Path, kernel: str) -> dict:
    """A recorded fit file, refused (ValueError) when it was fitted with another discrepancy kernel."""
    fit = json.loads(path.read_text())
    if fit.get("discrepancy_kernel", "additive") != kernel:
        raise ValueError(f"{path}: fitted with the {fit.get('discrepancy_kernel')} discrepancy kernel, this run "
                         f"uses the {kernel} one; use another --out folder")
    return fit


# ----------------------------------------------------------------------------
# results: load, tables, figures (the Studies page, lvcore report and the docs read these)
# ----------------------------------------------------------------------------
#: The command that makes the results.
COMMAND = "python scripts/ship_mismatch.py (or lvcore study mismatch --out RESULTS)"
#: Figures and tables :func:`figures` draws, with their titles.
TITLES = {"fig_mismatch_sigma_s_inflation": "Mismatch dose–response: iid σ_S inflation vs strain RMS mismatch",
          "fig_mismatch_discrepancy_sigma_s": "Mismatch dose–response: the discrepancy model's σ_S vs mismatch",
          "fig_mismatch_output_error": "Mismatch dose–response: output error per likelihood vs dose",
          "table_mismatch_doses": "Mismatch dose–response: per source and dose, with 90 % bootstrap CIs",
          "table_mismatch_real_lv": "The real LV beside the volunteers: per source and dose"}
#: Why a figure can be missing.
MISSING = {n: "the results hold no fitted doses (a --simulate-only run)" for n in TITLES}
MISSING["table_mismatch_real_lv"] = "the results hold no real-LV rows (scripts/ship_mismatch.py --real-lv-doses)"


def load(folder) -> dict:
    """The results of a mismatch ``--out`` folder (or the bundled one).

    Parameters
    ----------
    folder : path
        A folder holding the study's result file (:data:`RESULT_FILE`).

    Returns
    -------
    dict
        The result file's record (``rows``: one per source and dose, with bootstrap CIs; ``volunteers``,
        ``seeds_per_dose``, ``sampler``, ``appearance``, ...) plus ``folder``.

    Raises
    ------
    LVCoreError
        The file is missing, too large or not JSON (naming it).
    ValueError
        It is JSON but not this study's output.

    Examples
    --------
    The bundled (SYNTHETIC) result: the iid likelihood's σ_S inflation (posterior σ_S / 0.03) at each dose of the
    clamped base, with its 90 % bootstrap CI:

    >>> from lvcore.studies import mismatch
    >>> from lvcore.studies.results import bundled_studies_dir
    >>> result = mismatch.load(bundled_studies_dir())
    >>> result["study"], set(mismatch.MODELS) <= set(result["rows"][0]["output_error"])
    ('mismatch', True)
    >>> base = [r for r in result["rows"] if r["source"] == "base"]
    >>> [sorted(r["iid_sigma_s_inflation"]) for r in base][:1]
    [['ci', 'n', 'value']]
    """
    from lvcore.studies.results import read_json

    data = read_json(Path(folder) / RESULT_FILE)
    if not isinstance(data, dict) or data.get("study") != "mismatch" or "rows" not in data:
        raise ValueError(f"{Path(folder) / RESULT_FILE} is not the output of lvcore study mismatch")
    data["folder"] = str(folder)
    return data


def source_line(result: dict) -> str:
    """Where the numbers come from, as one readable line."""
    from lvcore.studies.results import source_label

    return (f"{RESULT_FILE} ({source_label(result['folder'])}); SYNTHETIC data from the FE simulator "
            f"({result.get('resolution', '?')} mesh), {volunteers_text(result)} × "
            f"{result.get('seeds_per_dose', '?')} noise seeds per dose; calibrated on the "
            f"{result.get('emulator', '?')} emulator{mesh_note(result)}; sampler {sampler_text(result)}"
            + kernel_note(result))


def kernel_note(result: dict) -> str:
    """``""`` for the chapter's additive discrepancy kernel (a result that does not record one is the chapter's);
    for another, a clause naming it, so that its numbers are never read as the chapter's."""
    kind = result.get("discrepancy_kernel", "additive")
    return "" if kind == "additive" else (f"; discrepancy likelihood with the {kind} (sector × level) GP kernel, "
                                          "not the chapter's additive one")


def tables(result: dict) -> dict:
    """The data behind each figure (by figure name): one row per (source, dose[, likelihood])."""
    import pandas as pd

    rows = result.get("rows", [])
    if not rows:
        return {}
    infl, disc, err, flat = [], [], [], []
    for r in rows:
        x = r["strain_rms_mismatch"]["mean"]
        base = {"panel": SOURCE_LABELS.get(r["source"], r["source"]), "source": r["source"], "dose": r["dose"],
                "x": x, "label": dose_label(r["source"], r["dose"])}
        i, d = r["iid_sigma_s_inflation"], r["discrepancy_sigma_s"]
        infl.append({**base, "series": SOURCE_LABELS.get(r["source"], r["source"]), "value": i["value"],
                     "lo": i["ci"][0], "hi": i["ci"][1]})
        disc.append({**base, "series": SOURCE_LABELS.get(r["source"], r["source"]), "value": d["value"],
                     "lo": d["ci"][0], "hi": d["ci"][1]})
        for m in MODELS:
            e = r["output_error"][m]
            err.append({**base, "series": m, "value": e["value"], "lo": e["ci"][0], "hi": e["ci"][1]})
        c = r["theta_coverage"]
        flat.append({"source": r["source"], "dose": r["dose"], "strain RMS": x,
                     "data sets": r.get("n_datasets", i["n"]),
                     f"iid σ_S/{SIGMA_S:g}": i["value"], "iid CI": f"[{i['ci'][0]:.2f}, {i['ci'][1]:.2f}]",
                     "discrepancy σ_S": d["value"], "disc. CI": f"[{d['ci'][0]:.3f}, {d['ci'][1]:.3f}]",
                     **{f"error {m}": r["output_error"][m]["value"] for m in MODELS},
                     **{f"coverage {m}": c[m]["value"] for m in MODELS},
                     "F1": r["f1"], "F3": r["f3"]})
    out = {"fig_mismatch_sigma_s_inflation": pd.DataFrame(infl),
           "fig_mismatch_discrepancy_sigma_s": pd.DataFrame(disc),
           "fig_mismatch_output_error": pd.DataFrame(err),
           "table_mismatch_doses": pd.DataFrame(flat)}
    real = (result.get("real_lv") or {}).get("rows") or []
    if real:
        vol = verdict_rows_by_dose(result)
        def volunteers(r, key):
            return ((vol.get((r["source"], r["dose"])) or {}).get(key) or {}).get(
                "mean" if key == "strain_rms_mismatch" else "value")

        out["table_mismatch_real_lv"] = pd.DataFrame([
            {"source": r["source"], "dose": r["dose"], "strain RMS real LV": r["strain_rms_mismatch"]["mean"],
             "strain RMS volunteers": volunteers(r, "strain_rms_mismatch"),
             f"iid σ_S/{SIGMA_S:g} real LV": r["iid_sigma_s_inflation"]["value"],
             "real LV CI (its data sets)": f"[{r['iid_sigma_s_inflation']['ci'][0]:.2f}, "
                                           f"{r['iid_sigma_s_inflation']['ci'][1]:.2f}]",
             f"iid σ_S/{SIGMA_S:g} volunteers": volunteers(r, "iid_sigma_s_inflation"),
             "discrepancy σ_S real LV": r["discrepancy_sigma_s"]["value"],
             "discrepancy σ_S volunteers": volunteers(r, "discrepancy_sigma_s"),
             **{f"error {m} real LV": r["output_error"][m]["value"] for m in MODELS}} for r in real])
    return out


def figures(result: dict) -> dict:
    """The study's figures by name (see :data:`TITLES`); none when the results hold no fitted doses."""
    from lvcore.viz.report_figures import table_figure
    from lvcore.viz.study_figures import dose_response_figure

    tabs = tables(result)
    if not tabs:
        return {}
    n = f"{len(result.get('volunteers', []))} volunteer(s) × {result.get('seeds_per_dose')} seeds per dose"
    xt = "strain RMS mismatch of the dose (mismatched − nominal simulator outputs, 24 strains)"
    out = {"fig_mismatch_sigma_s_inflation": dose_response_figure(
        tabs["fig_mismatch_sigma_s_inflation"].to_dict("records"),
        title=f"SYNTHETIC mismatch dose–response ({n}): iid posterior median σ_S / {SIGMA_S:g}, median over data "
              "sets, 90 % bootstrap CI band; F1 (chapter) ≈ 2×",
        xaxis_title=xt, yaxis_title=f"iid σ_S inflation (σ_S / {SIGMA_S:g})", refs=((1.0, "no inflation"),
                                                                            (2.0, "chapter ≈ 2×")))}
    out["fig_mismatch_discrepancy_sigma_s"] = dose_response_figure(
        tabs["fig_mismatch_discrepancy_sigma_s"].to_dict("records"),
        title=f"SYNTHETIC mismatch dose–response ({n}): discrepancy model's posterior median σ_S, 90 % bootstrap "
              f"CI band; truth {SIGMA_S:g}, chapter 0.024 (F2){kernel_note(result)}",
        xaxis_title=xt, yaxis_title="discrepancy σ_S (strain)", refs=((SIGMA_S, f"truth {SIGMA_S:g}"),))
    panels = list(dict.fromkeys(tabs["fig_mismatch_output_error"]["panel"]))
    out["fig_mismatch_output_error"] = dose_response_figure(
        tabs["fig_mismatch_output_error"].to_dict("records"), panels=panels,
        title=f"SYNTHETIC mismatch dose–response ({n}): output error |η(θ_post, h) − η(θ̃, h)| per likelihood, "
              "median over data sets, 90 % bootstrap CI band (F3: discrepancy ≈ volume < iid)",
        xaxis_title="strain RMS mismatch", yaxis_title="output error (strain)")
    out["table_mismatch_doses"] = table_figure(tabs["table_mismatch_doses"],
                                               title=f"SYNTHETIC mismatch study ({n}): per source and dose")
    if "table_mismatch_real_lv" in tabs:
        out["table_mismatch_real_lv"] = table_figure(
            tabs["table_mismatch_real_lv"], title="The REAL LV's mesh (data FE-simulated on it) beside the SYNTHETIC "
                                                  "volunteers: per source and dose (one geometry: no verdict)")
    return out

# ----------------------------------------------------------------------------
# CLI
# ----------------------------------------------------------------------------
def add_study_parser(study_subparsers) -> None:
    """``lvcore study mismatch``."""
    p = study_subparsers.add_parser("mismatch", help="model-data mismatch as a dose-response: sigma_S "
                                                     "inflation, output error and theta coverage per likelihood")
    p.add_argument("--out", default="study_mismatch", help="output (and resume) folder")
    p.add_argument("--sources", default=",".join(SOURCES), help=f"comma-separated, from {','.join(SOURCES)}")
    p.add_argument("--doses", action="append", default=[], metavar="SOURCE=D1,D2",
                   help="doses of one source (repeatable); default DEFAULT_DOSES")
    p.add_argument("--volunteers", default=None,
                   help=f"e.g. HV1,HV2 (default all bundled); {REAL_LV} adds the real LV (its shipped mesh, data "
                        f"FE-simulated on it; needs --subject-emulator {REAL_LV}=DIR)")
    p.add_argument("--subject-emulator", action="append", default=[], metavar="VOLUNTEER=DIR",
                   help=f"the subject emulator of a mesh volunteer's fits (repeatable), e.g. {REAL_LV}=DIR: one "
                        "built on its mesh at the model's conditions (lvcore emulator build --geometry MESH --base "
                        "sliding --strain-layer inner_half --alpha-endo -60 --alpha-epi 60 --edp 8 --out DIR)")
    p.add_argument("--seeds", type=int, default=20, help="noise seeds per dose and volunteer")
    p.add_argument("--warmup", type=int, default=500, help="warm-up iterations per chain (default 500)")
    p.add_argument("--samples", type=int, default=500, help="draws kept per chain (default 500)")
    p.add_argument("--chains", type=int, default=2, help="MCMC chains (default 2)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--resolution", default="default", help="simulator mesh preset (default 'default')")
    p.add_argument("--emulator", default="chapter", help="emulator of the calibrations (default chapter)")
    p.add_argument("--workers", type=int, default=1, help="local simulation workers")
    p.add_argument("--scheduler", default=None,
                   help="tcp://HOST:PORT of a Dask scheduler for the simulations (default: none, local workers)")
    p.add_argument("--retry-failed", action="store_true", help="run recorded failed simulations again")
    p.add_argument("--simulate-only", action="store_true",
                   help="only simulate and print the measured strain RMS of each dose (OUT/doses.json); no fits")
    p.add_argument("--recorded-only", action="store_true",
                   help="start no new fits: summarise the recorded ones and list the rest as not fitted")
    p.add_argument("--discrepancy-kernel", choices=("additive", "product"), default="additive",
                   help="GP kernel of the discrepancy likelihood: additive (default, the chapter's) or product "
                        "(sector x level); a product run's fits are kept apart in --out and its result says so")
    p.add_argument("--batch", type=int, default=BATCH,
                   help=f"data sets per compiled MCMC batch (default {BATCH}; the last batch is padded)")
    p.add_argument("--json", action="store_true", help="print the findings as JSON")
    p.set_defaults(func=_cli)


def _parse_doses(items, sources) -> dict:
    """``["dispersion=0.1,0.2", ...]`` -> ``{"dispersion": (0.1, 0.2)}`` (ValueError naming the bad item)."""
    doses = {}
    for item in items:
        name, _, vals = item.partition("=")
        if name not in sources or not vals:
            raise ValueError(f"--doses {item!r}: expected SOURCE=D1,D2 with SOURCE one of {','.join(sources)}")
        try:
            doses[name] = tuple(float(x) for x in vals.split(","))
        except ValueError:
            raise ValueError(f"--doses {item!r}: doses must be numbers") from None
    return doses


def _parse_subject_emulators(items) -> dict:
    """``["REAL-LV=DIR", ...]`` -> ``{"REAL-LV": "DIR"}`` (ValueError naming the bad item)."""
    out = {}
    for item in items:
        name, _, path = item.partition("=")
        if not name or not path:
            raise ValueError(f"--subject-emulator {item!r}: expected VOLUNTEER=DIR, e.g. {REAL_LV}=DIR")
        out[name] = path
    return out


def _cli(args) -> int:
    import sys

    from lvcore.inference import samplers

    sources = tuple(s for s in args.sources.split(",") if s)
    unknown = sorted(set(sources) - set(SOURCES))
    if unknown:
        print(f"lvcore study mismatch: --sources: unknown {unknown}; choose from {','.join(SOURCES)}", file=sys.stderr)
        return 2
    for opt, val in (("--seeds", args.seeds), ("--warmup", args.warmup), ("--samples", args.samples),
                     ("--chains", args.chains), ("--batch", args.batch), ("--workers", args.workers)):
        if val < 1:
            print(f"lvcore study mismatch: {opt} {val}: give a positive integer", file=sys.stderr)
            return 2
    try:
        doses = _parse_doses(args.doses, sources)
        vols = args.volunteers.split(",") if args.volunteers else None
        subject_emulators = _parse_subject_emulators(args.subject_emulator)
        for v in study_volunteers(vols) if vols else []:
            if v.geometry is not None and not (args.simulate_only or args.recorded_only):
                _needs_subject(v, subject_emulators)
    except ValueError as err:  # bad options: a clear message, exit 2
        print(f"lvcore study mismatch: {err}", file=sys.stderr)
        return 2
    samplers.use_host_devices(args.chains)
    cfg = samplers.SamplerConfig(num_warmup=args.warmup, num_samples=args.samples, num_chains=args.chains,
                                 seed=args.seed, discrepancy_kernel=args.discrepancy_kernel)
    res = run_study(sources=sources, doses=doses, volunteers=vols, seeds=args.seeds, config=cfg, seed=args.seed,
                    resolution=args.resolution, emulator=args.emulator, workers=args.workers,
                    scheduler=args.scheduler, out=args.out, retry_failed=args.retry_failed,
                    simulate_only=args.simulate_only, batch=args.batch, recorded_only=args.recorded_only,
                    subject_emulators=subject_emulators,
                    progress=None if args.json else (lambda msg: print(msg, flush=True)))
    if args.simulate_only:
        for r in res["doses_measured"]:
            m = r["strain_rms_mismatch"]
            size = "all failed" if m["mean"] is None else f"{m['mean']:.4f} [{m['min']:.4f}, {m['max']:.4f}]"
            print(f"{r['source']:>14} {r['dose']:>8g}  strain RMS {size}  ({m['n']} ok, {m['failed']} failed)")
        print(f"wrote {args.out}/doses.json")
        return 0
    brief = {"appearance": res["appearance"], "failed": res["failed"], "timings_s": res["timings_s"]}
    print(json.dumps(brief, indent=2))
    if not args.json:
        print(f"wrote {args.out}/{RESULT_FILE}")
    return 0


__all__ = ["SOURCES", "DEFAULT_DOSES", "MODEL_ANGLES", "MODEL_BASE", "REAL_LV", "REAL_LV_THETA", "real_lv_volunteer",
           "study_volunteers", "subject_forward", "HETEROGENEITY_SEED", "SOURCE_LABELS", "MODELS",
           "F1_INFLATION", "F1_CI_FLOOR", "BATCH", "PER_VOLUNTEER_DIGITS", "Volunteer", "mismatch_case",
           "bundled_volunteers", "dose_key", "dose_label", "simulate_all", "unit_seed", "noisy_copies",
           "fit_datasets", "run_study", "summarise", "per_volunteer_values", "appearance", "measured_doses",
           "strain_rms", "fit_cost", "budget_text", "sampler_text", "verdict_rows", "verdict_rows_by_dose",
           "promote_check", "model_conditions_text", "RESULT_FILE", "COMMAND",
           "TITLES", "MISSING", "load", "source_line", "tables", "figures", "docs_markdown", "DOCS_BEGIN",
           "DOCS_END", "add_study_parser", "kernel_note"]
