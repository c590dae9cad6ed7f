"""The runs of the information study (:mod:`lvcore.studies.information`): SYNTHETIC subjects, variants, summary.

Two parts, each a list of ``lvcore calibrate`` runs made in this process and
recorded one JSON line a run in a resumable work folder:

``states``
    ``n_subjects`` SYNTHETIC subjects on the simulator's default LV. θ is drawn
    from the SYNTHETIC population of :mod:`lvcore.inference.cohort` (log θ ~
    N(log θ̃, Σ), kept inside the state emulator's box), simulated by the FE
    simulator at 8, 14, 20 and 30 mmHg (sliding base, fibres −60/60°, inner-half
    strains); the data are the FE outputs at 8, 14 and 20 mmHg plus noise (σ_V
    5 mL, σ_S 0.03 at each state), the truth of V20 and V30 the FE volumes.
    Each subject is calibrated in :data:`STATE_VARIANTS`: one, two or three
    loaded states with and without ``--prior klotz`` through a subject emulator
    of that geometry with EDP as an input over 6–30 mmHg (built on first use by
    :data:`EMULATOR_BUILD_ARGS`), and with ``--geometry infer`` through the
    bundled ``angles`` emulator (its EDP box stops at 14 mmHg) and through the
    ``edpvr`` emulator composed with ``chapter`` (EDP 1–30 mmHg; 8 and 8 + 20).
``cohort``
    SYNTHETIC cohorts of :data:`COHORT_SIZES` subjects
    (:func:`lvcore.inference.cohort.synthetic_cohort`: data from the ``chapter``
    emulator at 8 mmHg), each calibrated subject by subject (``separate``) and in
    one joint posterior (``--hierarchical``). V20 and V30 come from the EDPVR
    emulator for both, with its own held-out error drawn in; their truth is the
    EDPVR emulator at the true θ.

:func:`lvcore.studies.information_summary.summarise` turns the records into the study's result file.
"""
from __future__ import annotations

import json
import shutil
import time
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore.domain.conditions import SIGMA_S, SIGMA_V_ML
from lvcore.domain.outputs import EDP_NAME, THETA_NAMES
from lvcore.exceptions import LVCoreError
from lvcore.studies._common import add_sampler_options, comma_list, write_json_atomic
from lvcore.studies.sbc_runner import Store, TruthFailure, calibrate_in_process, first_solvable_draw

#: Version of the run records; a work folder from another version is refused.
RECORD_VERSION = 1
PARTS = ("states", "cohort")
DEFAULT_WORKDIR = "build/information"
DEFAULT_N_SUBJECTS = 12
DEFAULT_COHORT_SIZES = (8, 24)
DEFAULT_CHAINS, DEFAULT_WARMUP, DEFAULT_SAMPLES = 2, 500, 500
#: Posterior draws of the derived V20 and V30.
DEFAULT_DERIVED_DRAWS = 100
MODEL = "iid"
ANGLES = (-60.0, 60.0)
BASE = "sliding"
#: Pressures (mmHg) the FE truth is solved at; the data use :data:`STATE_PRESSURES_MMHG`.
TRUTH_PRESSURES_MMHG = (8.0, 14.0, 20.0, 30.0)
STATE_PRESSURES_MMHG = (8.0, 14.0, 20.0)
#: Sd (mL) of the measured reference volume the infer route is given (``--reference-volume``).
REFERENCE_VOLUME_SD_ML = 5.0
#: The state emulator: a subject emulator of the default LV with EDP as an input (``lvcore emulator build``).
EMULATOR_BUILD_ARGS = ("--geometry", "default", "--inputs", "theta,edp", "--bound", "edp=6,30", "--bound", "b=0.5,30",
                       "--bound", "bf=0.5,30", "--prior", "none", "--n-train", "800", "--seed", "0")
STATE_EMULATOR_DIR = "state_emulator"
#: The states part's variants: key -> loaded states (mmHg), prior, route.
STATE_VARIANTS = {
    "states-8": {"states": (8.0,), "prior": "none", "route": "mesh"},
    "states-8-klotz": {"states": (8.0,), "prior": "klotz", "route": "mesh"},
    "states-8-20": {"states": (8.0, 20.0), "prior": "none", "route": "mesh"},
    "states-8-20-klotz": {"states": (8.0, 20.0), "prior": "klotz", "route": "mesh"},
    "states-8-14-20": {"states": (8.0, 14.0, 20.0), "prior": "none", "route": "mesh"},
    "states-8-14-20-klotz": {"states": (8.0, 14.0, 20.0), "prior": "klotz", "route": "mesh"},
    "infer-8": {"states": (8.0,), "prior": "none", "route": "infer"},
    "infer-8-14": {"states": (8.0, 14.0), "prior": "none", "route": "infer"},
    # the EDPVR emulator composed with ``chapter`` (lvcore.emulator.edpvr_states) takes an EDP of 1-30 mmHg
    "infer-edpvr-8": {"states": (8.0,), "prior": "none", "route": "infer", "emulator": "edpvr",
                      "reference": "infer-edpvr-8"},
    "infer-edpvr-8-20": {"states": (8.0, 20.0), "prior": "none", "route": "infer", "emulator": "edpvr",
                         "reference": "infer-edpvr-8"},
}
#: Reference of each variant's narrowing (the same route's one state without the prior), unless the variant names
#: its own (``reference``: the same emulator's one state).
REFERENCE = {"mesh": "states-8", "infer": "infer-8"}
#: The emulator of the infer route unless a variant names its own.
INFER_EMULATOR = "angles"


def variant_reference(variant: str) -> str:
    """The variant whose a-interval a variant's narrowing is measured against."""
    v = STATE_VARIANTS[variant]
    return v.get("reference", REFERENCE[v["route"]])
DERIVED = {"V20": 20.0, "V30": 30.0}
QUANTITIES = tuple(THETA_NAMES) + tuple(DERIVED)
MAX_REDRAWS = 20


# ============================================================================ the states part's subjects
def state_theta(seed: int, index: int, attempt: int = 0) -> dict:
    """Subject ``index``'s θ (draw ``attempt``): log θ ~ N(log θ̃, Σ) of the SYNTHETIC population, redrawn until
    inside the state emulator's box. Depends only on ``(seed, index, attempt)``."""
    from lvcore.inference.cohort import SYNTHETIC_MU, population_covariance

    lo = np.log([0.05, 0.5, 0.05, 0.5])
    hi = np.log([10.0, 30.0, 10.0, 30.0])
    rng = np.random.default_rng([int(seed), int(index), int(attempt), 11])
    chol = np.linalg.cholesky(population_covariance())
    m0 = np.log([float(SYNTHETIC_MU[k]) for k in THETA_NAMES])
    while True:
        x = m0 + chol @ rng.standard_normal(4)
        if np.all((x > lo) & (x < hi)):
            return {k: float(v) for k, v in zip(THETA_NAMES, np.exp(x))}


def simulate_states(theta: Mapping[str, float]) -> dict:
    """FE truth of one subject on the default LV: the 25 outputs at each of :data:`TRUTH_PRESSURES_MMHG` and V0.

    Raises
    ------
    TruthFailure
        When a solve fails (the draw is redrawn).
    """
    from lvcore.mechanics.case_inputs import build_case
    from lvcore.mechanics.simulate import simulate

    outputs, v0 = {}, None
    for p in TRUTH_PRESSURES_MMHG:
        case = build_case({**theta, EDP_NAME: p, "alpha_endo": ANGLES[0], "alpha_epi": ANGLES[1]},
                          geometry={"kind": "default", "resolution": "default"}, base=BASE)
        try:
            res = simulate(case)
        except LVCoreError as err:
            raise TruthFailure(f"{p:g} mmHg: {type(err).__name__}: {str(err)[:200]}") from None
        if not res.converged:
            raise TruthFailure(f"the {p:g} mmHg solve did not converge: {res.message}")
        outputs[f"{p:g}"] = [float(v) for v in res.outputs()]
        v0 = float(res.cavity_volume_mm3[0]) / 1000.0
    return {"outputs": outputs, "v0_ml": v0}


def make_state_subject(seed: int, index: int, truth_fn: Callable[[Mapping], dict] = simulate_states) -> dict:
    """Subject ``index`` of the states part: θ, its FE truth, the noisy data at each state and the noisy V0."""
    attempt, theta, fe, reasons = first_solvable_draw(lambda k: state_theta(seed, index, k), truth_fn, index,
                                                      max_redraws=MAX_REDRAWS)
    rng = np.random.default_rng([int(seed), int(index), 12])
    sd = np.r_[SIGMA_V_ML, np.full(24, SIGMA_S)]
    data = {f"{p:g}": (np.asarray(fe["outputs"][f"{p:g}"]) + sd * rng.standard_normal(25)).tolist()
            for p in STATE_PRESSURES_MMHG}
    truth = {**theta, **{q: float(fe["outputs"][f"{p:g}"][0]) for q, p in DERIVED.items()}}
    return {"subject": state_subject_name(index), "index": int(index), "truth": truth,
            "v0_ml": fe["v0_ml"], "data": data, "redraws": attempt, "redraw_reasons": reasons,
            "reference_volume_ml": float(fe["v0_ml"] + REFERENCE_VOLUME_SD_ML * rng.standard_normal())}


def state_subject_name(index: int) -> str:
    return f"SYNTHETIC-INF-{int(index):03d}"


def write_state_data(subject: Mapping, states: Sequence[float], path, *, reference_volume: bool) -> Path:
    """The subject's data CSV with one row per loaded state (``states``, mmHg)."""
    from lvcore.inference.data import LoadedState, MeasuredData, write_measured_csv

    ys = [np.asarray(subject["data"][f"{p:g}"], float) for p in states]
    extras = {"edp_mmhg": float(states[0])}
    rows = [MeasuredData(ys[0], subject["subject"], synthetic=True, extras=extras,
                         states=tuple(LoadedState(float(p), y) for p, y in zip(states[1:], ys[1:])))]
    path = write_measured_csv(path, rows)
    if reference_volume:   # one value per subject, on every row of it
        import pandas as pd

        df = pd.read_csv(path)
        df["reference_volume_ml"] = round(float(subject["reference_volume_ml"]), 3)
        df.to_csv(path, index=False, float_format="%.8g")
    return Path(path)


def state_argv(variant: str, data, subject: Mapping, settings: Mapping, out, emulator: str) -> list[str]:
    """``lvcore calibrate`` of one subject in one states-part variant."""
    v = STATE_VARIANTS[variant]
    argv = ["calibrate", "--data", str(data), "--model", MODEL, "--chains", str(settings["chains"]),
            "--warmup", str(settings["warmup"]), "--samples", str(settings["samples"]),
            "--seed", str(settings["seed"] + 1000 * int(subject["index"]) + list(STATE_VARIANTS).index(variant)),
            "--derived-draws", str(settings["derived_draws"]),
            "--derived-pressures", ",".join(f"{p:g}" for p in DERIVED.values()), "--out", str(out), "--json"]
    if v["route"] == "mesh":
        argv += ["--emulator", emulator]
    else:
        name = v.get("emulator", INFER_EMULATOR)
        argv += ["--emulator", name, "--geometry", "infer"]
        if name == INFER_EMULATOR:   # angles are inputs of the angles emulator: pin them; edpvr has them fixed
            argv += ["--alpha-endo", f"{ANGLES[0]:g}", "--alpha-epi", f"{ANGLES[1]:g}"]
    if v["prior"] == "klotz":
        argv += ["--prior", "klotz"]
    return argv


# ============================================================================ records of one calibration
def record_from_summary(rec: Mapping) -> dict:
    """q05/median/q95 of θ and of V20/V30 (the derived EDPVR) from one summary.json record."""
    out = {c: {} for c in ("q05", "median", "q95")}
    for n in THETA_NAMES:
        for c in out:
            out[c][n] = float(rec[n][c])
    for row in ((rec.get("derived") or {}).get("edpvr") or []):
        for q, p in DERIVED.items():
            if abs(float(row["pressure_mmhg"]) - p) < 1e-9 and row.get("median") is not None:
                for c in out:
                    out[c][q] = float(row[c])
    return {**out, "converged": bool(rec.get("converged")), "flags": list(rec.get("flags") or [])}


def read_calibration(out, code: int) -> dict:
    """:func:`record_from_summary` of the iid record in ``out/summary.json`` after a run that wrote one (exit 0,
    1 or 4); ``{}`` otherwise."""
    summary = Path(out) / "summary.json"
    if code not in (0, 1, 4) or not summary.is_file():
        return {}
    return record_from_summary(next(r for r in json.loads(summary.read_text()) if r.get("model") == MODEL))


def run_state_variant(variant: str, subject: Mapping, settings: Mapping, folder, emulator: str,
                      calibrate=calibrate_in_process) -> dict:
    """One subject in one states-part variant: write its data, calibrate, read the summary; the record."""
    v = STATE_VARIANTS[variant]
    folder = Path(folder) / subject["subject"] / variant
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    data = write_state_data(subject, v["states"], folder / "data.csv", reference_volume=v["route"] == "infer")
    t0, c0 = time.perf_counter(), time.process_time()
    code, error = calibrate(state_argv(variant, data, subject, settings, folder / "out", emulator),
                            folder / "calibrate.log")
    rec = {"part": "states", "variant": variant, "subject": subject["subject"], "index": subject["index"],
           "exit": int(code), "error": error, "wall_s": time.perf_counter() - t0,
           "cpu_s": time.process_time() - c0, "truth": dict(subject["truth"]), "version": RECORD_VERSION}
    return {**rec, **read_calibration(folder / "out", code)}


# ============================================================================ the work folder
def read_records(workdir) -> list[dict]:
    """Every complete run record of the folder (a line cut off by a kill is skipped)."""
    out = []
    for f in sorted(Path(workdir).glob("runs_*.jsonl")):
        for line in f.read_text(errors="replace").splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(rec, dict) and rec.get("version") == RECORD_VERSION and "variant" in rec:
                out.append(rec)
    return out


def check_settings(workdir, settings: Mapping) -> None:
    """Write ``settings.json`` on the first run; refuse a folder made with other sampler settings or seed."""
    path = Path(workdir) / "settings.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    key = {k: settings[k] for k in ("seed", "chains", "warmup", "samples", "derived_draws")}
    old = json.loads(path.read_text()) if path.is_file() else None
    if old is not None and {k: old.get(k) for k in key} != key:
        raise LVCoreError(f"work folder {workdir} holds an information study with other settings "
                          f"({ {k: old.get(k) for k in key} }); these are {key}: give another --workdir")
    write_json_atomic(path, {**(old or {}), **settings, "version": RECORD_VERSION})


def ensure_state_emulator(workdir, emulator: str | None = None, workers: int = 2) -> str:
    """The state emulator's folder: ``emulator`` when given, else ``<workdir>/state_emulator`` (built there
    with :data:`EMULATOR_BUILD_ARGS` when missing: 950 FE runs and a training, minutes on 2 cores)."""
    if emulator:
        return str(emulator)
    path = Path(workdir) / STATE_EMULATOR_DIR
    if not (path / "metadata.json").is_file():
        import subprocess
        import sys

        cmd = [sys.executable, "-m", "lvcore.cli", "emulator", "build", *EMULATOR_BUILD_ARGS,
               "--workers", str(workers), "--out", str(path)]
        print("building the state emulator: lvcore " + " ".join(cmd[3:]), flush=True)
        subprocess.run(cmd, check=True)
    return str(path)


def record_state_emulator(workdir, emulator: str) -> dict:
    """The state emulator's name, EDP box and held-out error, added to the folder's ``settings.json``."""
    meta = json.loads((Path(emulator) / "metadata.json").read_text())
    names = list(meta.get("input_names", []))
    bounds = meta.get("bounds") or {}
    box = ([float(bounds["lower"][names.index(EDP_NAME)]), float(bounds["upper"][names.index(EDP_NAME)])]
           if EDP_NAME in names and "lower" in bounds else None)
    test = meta.get("test") or {}
    rec = {"name": meta.get("name", Path(emulator).name), "edp_box_mmhg": box,
           "heldout_lvv_rmse_ml": test.get("lvv_rmse_ml"), "heldout_strain_rmse": test.get("strain_rmse"),
           "build": "lvcore emulator build " + " ".join(EMULATOR_BUILD_ARGS)}
    path = Path(workdir) / "settings.json"
    write_json_atomic(path, {**json.loads(path.read_text()), "state_emulator": rec})
    return rec


def run_states(settings: Mapping, workdir, *, emulator: str | None = None, variants: Sequence[str] | None = None,
               say=print, calibrate=calibrate_in_process, truth_fn=simulate_states, between=None) -> int:
    """Run the states part's missing (subject, variant) pairs; returns how many ran. ``between()`` is called
    after each subject (the command line's restart before the memory-mapping limit)."""
    from lvcore.inference.calibrate import release_compiled_programs

    workdir = Path(workdir)
    check_settings(workdir, settings)
    done = {(r["variant"], r["subject"]) for r in read_records(workdir) if r["part"] == "states"}
    todo = [v for v in (variants or STATE_VARIANTS)
            if any((v, state_subject_name(i)) not in done for i in range(int(settings["n_subjects"])))]
    emu = None
    if any(STATE_VARIANTS[v]["route"] == "mesh" for v in todo):   # only the mesh route needs the state emulator
        emu = ensure_state_emulator(workdir, emulator)
        record_state_emulator(workdir, emu)
    store, n = Store(workdir), 0
    for index in range(int(settings["n_subjects"])):
        subject = None
        name = state_subject_name(index)
        for variant in variants or STATE_VARIANTS:
            if (variant, name) in done:
                continue
            subject = subject or make_state_subject(settings["seed"], index, truth_fn)
            rec = run_state_variant(variant, subject, settings, workdir / "states", emu, calibrate)
            store.append(workdir / "runs_states.jsonl", rec)
            n += 1
            say(f"{name} {variant}: exit {rec['exit']}, a {_interval(rec, 'a')}, {rec['wall_s']:.0f} s")
        if subject is not None:
            release_compiled_programs()
            if between is not None:
                between()
    return n


def _interval(rec: Mapping, q: str) -> str:
    if q not in rec.get("q05", {}):
        return "–"
    return f"[{rec['q05'][q]:.3g}, {rec['q95'][q]:.3g}]"


# ============================================================================ the cohort part
def cohort_key(n: int, method: str) -> str:
    return f"cohort{int(n)}-{method}"


def edpvr_volumes(theta: np.ndarray, h: Sequence[float], scale: float, *, error: bool) -> np.ndarray:
    """V20 and V30 (mL, columns) of θ rows (a, b, af, bf) on one geometry (PC scores, scale) by the EDPVR
    emulator, with its held-out error drawn in when ``error`` (the truth is its mean)."""
    from lvcore.emulator import edpvr

    emu = edpvr.load_edpvr_emulator()
    draws = [{**dict(zip(THETA_NAMES, map(float, row))), "h": list(h), "scale": float(scale)}
             for row in np.atleast_2d(theta)]
    path = edpvr.emulated_load_path(emu, draws, edp_mmhg=8.0, pressures_mmhg=list(DERIVED.values()))
    vols = edpvr.emulator_error_draws(emu, path, 8.0)[0] if error else np.asarray(path.volumes_ml, float)
    return np.asarray(vols, float)[:, 1:]


def _quantile_record(draws: Mapping[str, np.ndarray]) -> dict:
    """q05, median and q95 of each quantity's draws."""
    return {c: {q: float(np.quantile(v, lvl)) for q, v in draws.items()}
            for c, lvl in (("q05", 0.05), ("median", 0.5), ("q95", 0.95))}


def write_cohort_files(n: int, seed: int, folder) -> tuple[Path, dict]:
    """A SYNTHETIC cohort of ``n`` subjects in ``folder`` (CSV, geometry files, truth with V20/V30)."""
    from lvcore.emulator.io import load_emulator
    from lvcore.inference import cohort as co

    c = co.synthetic_cohort(int(n), load_emulator("chapter"), seed=int(seed))
    csv = co.write_cohort(c, folder)
    truth = {}
    for i, s in enumerate(c.subjects):
        v = edpvr_volumes(c.theta[i][None, :], c.h[i], c.scale[i], error=False)[0]
        truth[s] = {**dict(zip(THETA_NAMES, map(float, c.theta[i]))), "V20": float(v[0]), "V30": float(v[1]),
                    "h": [float(x) for x in c.h[i]], "scale": float(c.scale[i])}
    write_json_atomic(Path(folder) / "truth_derived.json", truth)
    return csv, truth


def run_hierarchical(n: int, csv, truth: Mapping, settings: Mapping, folder,
                     calibrate=calibrate_in_process) -> dict:
    """The cohort's joint posterior (``lvcore calibrate --hierarchical``): one record with every subject's
    intervals (θ from the joint posterior, V20/V30 from its draws by the EDPVR emulator), μ against the truth
    and the diagnostics per level."""
    out = Path(folder) / "hierarchical"
    t0, c0 = time.perf_counter(), time.process_time()
    code, error = calibrate(["calibrate", "--data", str(csv), "--hierarchical", "--model", MODEL,
                             "--chains", str(settings["chains"]), "--warmup", str(settings["warmup"]),
                             "--samples", str(settings["samples"]), "--seed", str(settings["seed"] + int(n)),
                             "--out", str(out), "--json"], Path(folder) / "hierarchical.log")
    rec = {"part": "cohort", "variant": cohort_key(n, "hierarchical"), "subject": f"cohort of {n}",
           "cohort_size": int(n), "exit": int(code), "error": error, "wall_s": time.perf_counter() - t0,
           "cpu_s": time.process_time() - c0, "version": RECORD_VERSION}
    if code not in (0, 1, 4) or not (out / "hierarchical.nc").is_file():
        return rec
    import arviz as az

    from lvcore.inference.derived import thinned_indices

    summary = json.loads((out / "summary.json").read_text())["hierarchical"]
    idata = az.from_netcdf(str(out / "hierarchical.nc"))
    log_theta = np.asarray(idata.posterior["log_theta"].values, float)
    subjects = [str(s) for s in idata.posterior["subject"].values]
    log_theta = log_theta.reshape(-1, len(subjects), len(THETA_NAMES))
    keep = thinned_indices(log_theta.shape[0], settings["derived_draws"])
    truth_all = json.loads((Path(csv).parent / "truth.json").read_text())
    mu = summary["population"]["groups"]["all"]["mu_log"]
    rec["mu_covered"] = {k: bool(mu[k]["q05"] <= truth_all["mu_log"]["A"][j] <= mu[k]["q95"])
                         for j, k in enumerate(THETA_NAMES)}
    rec["diagnostics"] = {lv: {k: d.get(k) for k in ("max_rhat", "min_ess_bulk", "n_divergent", "converged")}
                          for lv, d in summary["diagnostics"].items()}
    rec["subjects"] = {}
    for j, s in enumerate(subjects):
        theta = np.exp(log_theta[:, j, :])
        v = edpvr_volumes(theta[keep], truth[s]["h"], truth[s]["scale"], error=True)
        q = _quantile_record({**{k: theta[:, i] for i, k in enumerate(THETA_NAMES)},
                              **{k: v[:, i] for i, k in enumerate(DERIVED)}})
        rec["subjects"][s] = {**q, "truth": {k: truth[s][k] for k in QUANTITIES}}
    rec["converged"] = bool(summary.get("converged"))
    return rec


def run_separate(n: int, subject: str, truth: Mapping, settings: Mapping, folder,
                 calibrate=calibrate_in_process) -> dict:
    """One cohort subject calibrated alone (its data row, its PC-scores geometry; the ``chapter`` emulator)."""
    import pandas as pd

    folder = Path(folder)
    df = pd.read_csv(folder / "cohort.csv")
    row = df[df["subject"] == subject].drop(columns=["geometry"] + [c for c in ("group",) if c in df])
    work = folder / "separate" / subject
    work.mkdir(parents=True, exist_ok=True)
    row.to_csv(work / "data.csv", index=False, float_format="%.8g")
    t0, c0 = time.perf_counter(), time.process_time()
    code, error = calibrate(["calibrate", "--data", str(work / "data.csv"), "--geometry",
                             str(folder / "geometry" / f"{subject}.json"), "--model", MODEL,
                             "--chains", str(settings["chains"]), "--warmup", str(settings["warmup"]),
                             "--samples", str(settings["samples"]),
                             "--seed", str(settings["seed"] + 1000 * int(n) + int(subject.rsplit("C", 1)[-1])),
                             "--derived-draws", str(settings["derived_draws"]),
                             "--derived-pressures", ",".join(f"{p:g}" for p in DERIVED.values()),
                             "--out", str(work / "out"), "--json"], work / "calibrate.log")
    rec = {"part": "cohort", "variant": cohort_key(n, "separate"), "subject": subject, "cohort_size": int(n),
           "exit": int(code), "error": error, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
           "truth": {k: truth[subject][k] for k in QUANTITIES}, "version": RECORD_VERSION}
    return {**rec, **read_calibration(work / "out", code)}


def import_summary(result: Mapping, settings: Mapping, workdir, source: str) -> int:
    """Take over the runs of an earlier result file made with the same settings (e.g. the shipped one), so that a
    lost work folder resumes where that result stopped; returns how many records were written.

    A result keeps each run's intervals, truth, exit code and wall time but not its CPU time: the imported runs'
    CPU time is kept as one total (``settings.json``'s ``imported``) and added to the cost by the summary. A joint
    (hierarchical) posterior, shipped as one run per subject, becomes one record again with its population checks.
    """
    workdir = Path(workdir)
    key = ("seed", "chains", "warmup", "samples", "derived_draws")
    old = result.get("settings") or {}
    if {k: old.get(k) for k in key} != {k: settings[k] for k in key}:
        raise LVCoreError(f"{source} was made with other settings ({ {k: old.get(k) for k in key} }); these are "
                          f"{ {k: settings[k] for k in key} }")
    check_settings(workdir, settings)
    if read_records(workdir):
        return 0
    path = workdir / "settings.json"
    extra = {k: old[k] for k in ("state_emulator",) if k in old}
    write_json_atomic(path, {**json.loads(path.read_text()), **extra, "imported": {
        "from": str(source), "cpu_s_total": float((result.get("cost") or {}).get("cpu_s_total") or 0.0)}})
    variants = {v["key"]: v for v in result.get("variants") or []}
    wall = (result.get("cost") or {}).get("wall_s_median_by_variant") or {}
    recs, joints = [], {}
    for r in result.get("runs") or []:
        v = variants.get(r["variant"], {})
        base = {**r, "version": RECORD_VERSION, "cpu_s": None, "imported": True}
        if v.get("method") == "hierarchical":
            j = joints.setdefault(r["variant"], {
                "part": "cohort", "variant": r["variant"], "subject": f"cohort of {v['cohort_size']}",
                "cohort_size": int(v["cohort_size"]), "exit": r["exit"], "converged": r.get("converged"),
                "wall_s": wall.get(r["variant"]), "cpu_s": None, "version": RECORD_VERSION, "imported": True,
                "mu_covered": v.get("mu_covered"), "diagnostics": v.get("diagnostics"), "subjects": {}})
            j["subjects"][r["subject"]] = {c: r[c] for c in ("truth", "q05", "median", "q95")}
        else:
            recs.append({**base, **({"cohort_size": int(v["cohort_size"])} if v.get("part") == "cohort" else {})})
    store = Store(workdir)
    for rec in recs + list(joints.values()):
        store.append(workdir / f"runs_{rec['part']}_imported.jsonl", rec)
    return len(recs) + len(joints)


def run_cohorts(settings: Mapping, workdir, *, say=print, calibrate=calibrate_in_process, between=None) -> int:
    """Run the cohort part's missing runs (each cohort: its subjects alone, then the joint posterior);
    ``between()`` is called after each step, as in :func:`run_states`."""
    from lvcore.inference.calibrate import release_compiled_programs

    workdir = Path(workdir)
    check_settings(workdir, settings)
    done = {(r["variant"], r["subject"]) for r in read_records(workdir) if r["part"] == "cohort"}
    store, count = Store(workdir), 0
    for n in settings["cohort_sizes"]:
        folder = workdir / f"cohort{n}"
        csv, truth = write_cohort_files(n, settings["seed"] + 100 + int(n), folder)
        for s in truth:
            if (cohort_key(n, "separate"), s) not in done:
                rec = run_separate(n, s, truth, settings, folder, calibrate)
                store.append(workdir / "runs_cohort.jsonl", rec)
                count += 1
                say(f"cohort of {n}, {s} alone: exit {rec['exit']}, a {_interval(rec, 'a')}, {rec['wall_s']:.0f} s")
                if between is not None:
                    between()
        release_compiled_programs()
        if (cohort_key(n, "hierarchical"), f"cohort of {n}") not in done:
            rec = run_hierarchical(n, csv, truth, settings, folder, calibrate)
            store.append(workdir / "runs_cohort.jsonl", rec)
            count += 1
            say(f"cohort of {n}, joint posterior: exit {rec['exit']}, {rec['wall_s']:.0f} s")
            release_compiled_programs()
            if between is not None:
                between()
    return count


# ============================================================================ the command line
def add_parser(study_subparsers) -> None:
    """``lvcore study information`` (:func:`lvcore.studies.information.add_study_parser`)."""
    from lvcore import cli_args
    from lvcore.studies.registry import result_file

    p = study_subparsers.add_parser(
        "information", help="what several loaded states, --prior klotz and a hierarchical cohort add to a's "
                            "interval (SYNTHETIC subjects)",
        description="How much extra information pins the stiffness: SYNTHETIC subjects calibrated with one, two "
                    "and three loaded states, with and without --prior klotz (FE truth on the default LV), and "
                    "SYNTHETIC cohorts calibrated separately and in one hierarchical model. Resumable; "
                    "--summarise builds the result file from what is finished.")
    p.add_argument("--part", choices=(*PARTS, "all"), default="all", help="which part to run (default all)")
    p.add_argument("--workdir", type=cli_args.output_dir, default=DEFAULT_WORKDIR,
                   help=f"work folder with the run records (default {DEFAULT_WORKDIR}); a rerun resumes")
    p.add_argument("--n-subjects", type=cli_args.int_in(1, 1000), default=DEFAULT_N_SUBJECTS,
                   help=f"SYNTHETIC subjects of the states part (default {DEFAULT_N_SUBJECTS})")
    p.add_argument("--cohort-sizes", default=",".join(map(str, DEFAULT_COHORT_SIZES)),
                   help="comma-separated cohort sizes of the cohort part (default "
                        f"{','.join(map(str, DEFAULT_COHORT_SIZES))})")
    p.add_argument("--variants", default=",".join(STATE_VARIANTS),
                   help=f"states-part variants to run (default all: {','.join(STATE_VARIANTS)})")
    p.add_argument("--emulator", default=None,
                   help="the state emulator's folder (default: WORKDIR/state_emulator, built there when missing "
                        "by `lvcore emulator build " + " ".join(EMULATOR_BUILD_ARGS) + "`)")
    p.add_argument("--seed", type=cli_args.seed, default=0, help="seed of the subjects, noise and samplers (default 0)")
    add_sampler_options(p, chains=DEFAULT_CHAINS, warmup=DEFAULT_WARMUP, samples=DEFAULT_SAMPLES)
    p.add_argument("--derived-draws", type=cli_args.int_in(2, 2000), default=DEFAULT_DERIVED_DRAWS,
                   help=f"posterior draws behind V20 and V30 (default {DEFAULT_DERIVED_DRAWS})")
    p.add_argument("--import-summary", type=Path, default=None, metavar="INFORMATION_JSON",
                   help="before running, take over the runs of an earlier result made with the same settings (e.g. "
                        f"the shipped {result_file('information')}), into an empty --workdir (default: none)")
    p.add_argument("--summarise", action="store_true",
                   help="build the result from the finished runs in --workdir instead of running any")
    p.add_argument("--out", type=cli_args.output_file, default=None,
                   help=f"with --summarise: the result file (default WORKDIR/{result_file('information')})")
    p.add_argument("--json", action="store_true", help="with --summarise: print the result as JSON")
    p.set_defaults(func=_cli)


def _cli(args) -> int:
    from lvcore.studies.registry import result_file

    if args.summarise:
        from lvcore.studies.information_summary import summarise

        out = args.out or Path(args.workdir) / result_file("information")
        res = summarise(args.workdir, out)
        if args.json:
            print(json.dumps({k: v for k, v in res.items() if k != "runs"}, indent=1))
        else:
            for v in res["variants"]:
                print(f"{v['label']}: a q95/q05 median {(v['a_ratio'] or {}).get('median', float('nan')):.1f}, "
                      f"narrowing {(v['narrowing'] or {}).get('median', float('nan')):.2f}, "
                      f"coverage all four {v['coverage_90']['all4']}")
            for d in res["verdicts"]:
                print(f"{'met' if d['met'] else 'NOT met'}: {d['claim']}: {d['value']}")
            print(f"wrote {out}")
        return 0
    sizes = [int(x) for x in comma_list(args.cohort_sizes)]
    variants = comma_list(args.variants)
    bad = [v for v in variants if v not in STATE_VARIANTS] + [str(n) for n in sizes if n < 2]
    if bad or not variants:
        raise LVCoreError(f"unknown variant or cohort size {', '.join(bad) or '(none)'}: variants are "
                          f"{', '.join(STATE_VARIANTS)}; a cohort has at least 2 subjects")
    from lvcore.inference import samplers

    samplers.use_host_devices(args.chains)
    settings = {"seed": args.seed, "chains": args.chains, "warmup": args.warmup, "samples": args.samples,
                "derived_draws": args.derived_draws, "n_subjects": args.n_subjects, "cohort_sizes": sizes,
                "state_pressures_mmhg": list(STATE_PRESSURES_MMHG), "sigma_v_ml": SIGMA_V_ML, "sigma_s": SIGMA_S}
    from lvcore.execution.restart import restart_when_mappings_high

    say = (lambda m: print(m, flush=True))
    between = (lambda: restart_when_mappings_high(say))
    if args.import_summary is not None:
        from lvcore.studies.results import read_json

        n = import_summary(read_json(args.import_summary), settings, args.workdir, str(args.import_summary))
        say(f"imported {n} runs from {args.import_summary}")
    if args.part in ("states", "all"):
        run_states(settings, args.workdir, emulator=args.emulator, variants=variants, say=say, between=between)
    if args.part in ("cohort", "all"):
        run_cohorts(settings, args.workdir, say=say, between=between)
    print(f"done; summarise with `lvcore study information --summarise --workdir {args.workdir}`")
    return 0
