"""The runs of the simulation-based calibration study (:mod:`lvcore.studies.sbc`): SYNTHETIC subjects, the routes.

The design (the ``chapter`` emulator's training conditions), the SYNTHETIC
subjects (prior draws with their FE truth and noisy data), one subject's runs
through ``lvcore calibrate`` (``mesh`` and ``infer`` routes, in-process) with
the ranks of its truth, and the resumable work folder of JSON-lines records
(:class:`Store`, :func:`run_piece`). The module docstring of
:mod:`lvcore.studies.sbc` describes the study.
"""
from __future__ import annotations

import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP, SIGMA_S, SIGMA_V_ML
from lvcore.exceptions import LVCoreError
from lvcore.domain.outputs import EDP_NAME, THETA_NAMES
from lvcore.studies._common import clean, write_json_atomic
from lvcore.studies.sbc_stats import rank_of_truth

#: Version of the subject and route records; a work folder from another version is refused.
RECORD_VERSION = 1

ROUTES = ("mesh", "infer")
DERIVED_QUANTITIES = ("V0", "V20", "V30")
#: Every ranked quantity: θ, the derived FE volumes (mL) and the fibre Cauchy stress (kPa) at the fixed stretch.
QUANTITIES = tuple(THETA_NAMES) + DERIVED_QUANTITIES + ("fibre_stress",)
#: Quantities with the relative 90 % width.
WIDTH_QUANTITIES = ("V20", "V30")
#: Pressures (mmHg) of the derived volumes.
DERIVED_PRESSURES_MMHG = {"V0": 0.0, "V20": 20.0, "V30": 30.0}
#: ``--derived-pressures`` of the calibrations (V0 comes with every solve): only the pressures ranked here.
CLI_DERIVED_PRESSURES_MMHG = (20.0, 30.0)

# ---- the design (docs: the chapter emulator's training conditions)
DEFAULT_N_SUBJECTS = 200
DEFAULT_WARMUP = 500
DEFAULT_SAMPLES = 500
DEFAULT_CHAINS = 2
DEFAULT_DERIVED_DRAWS = 20
DEFAULT_THIN = 100
DEFAULT_WORKDIR = "build/sbc"
MODEL = "iid"
EMULATOR = "chapter"
N_PC = 5
#: Truncation of the PC scores (the ``chapter`` emulator's box).
H_TRUNCATION = 2.0
#: Range of the log-uniform reference cavity volume (mL).
V_REF_RANGE_ML = (40.0, 200.0)
EDP_MMHG = float(CHAPTER_EDP)
ANGLES = tuple(float(a) for a in CHAPTER_ANGLES)
BASE = "sliding"
RESOLUTION = "default"
#: Noise of the ``--reference-volume`` given to the infer route (mL; the command's default sd).
REFERENCE_VOLUME_SD_ML = 5.0
#: Fibre stretch of the stress quantity.
STRESS_STRETCH = 1.10
#: Prior redraws allowed per subject before the study stops (a failed FE solve is redrawn).
MAX_REDRAWS = 20
EDP_NOTE = ("EDP fixed at 8 mmHg: the default `chapter` emulator is trained at 8 mmHg only, so the EDP range "
            "4-20 mmHg of the design could not be drawn")


def flag_kind(flag: str) -> str:
    """The kind of a summary.json flag: its upper-case prefix (``CONSISTENCY``, ``MISFIT``, ``SAMPLER``,
    ``EXTRAPOLATION``, ...), ``IDENTIFIABILITY`` flags about a prior bound as ``BOUND``."""
    text = str(flag).strip()
    head = text.split(":", 1)[0].strip() if ":" in text else text.split(" ", 1)[0]
    kind = head if head.replace("_", "").replace("-", "").isalpha() and head.isupper() else "OTHER"
    if kind in ("IDENTIFIABILITY", "OTHER") and "bound" in text.lower():
        return "BOUND"
    return kind



# ============================================================================ subjects (SYNTHETIC)
def prior_draw(seed: int, index: int, attempt: int = 0) -> dict:
    """Subject ``index``'s prior draw number ``attempt``: θ (uniform on the prior box), PC scores (N(0, 1)
    truncated to ±2) and the target reference cavity volume (log-uniform in 40-200 mL). Depends only on
    ``(seed, index, attempt)``."""
    from lvcore.core.space import THETA_BOUNDS

    rng = np.random.default_rng([int(seed), int(index), int(attempt), 1])
    theta = {n: float(rng.uniform(*THETA_BOUNDS[n])) for n in THETA_NAMES}
    h = rng.standard_normal(N_PC)
    while np.any(np.abs(h) > H_TRUNCATION):   # rejection: the truncated normal, per score
        bad = np.abs(h) > H_TRUNCATION
        h[bad] = rng.standard_normal(int(bad.sum()))
    v_ref = float(np.exp(rng.uniform(*np.log(V_REF_RANGE_ML))))
    return {"theta": theta, "h": [float(v) for v in h], "v_ref_ml": v_ref}


def noise_draw(seed: int, index: int) -> dict:
    """Subject ``index``'s measurement noise: 25 outputs (σ_V, σ_S) and the reference-volume measurement."""
    rng = np.random.default_rng([int(seed), int(index), 2])
    return {"y": (np.r_[SIGMA_V_ML, np.full(24, SIGMA_S)] * rng.standard_normal(25)).tolist(),
            "reference_volume_ml": float(REFERENCE_VOLUME_SD_ML * rng.standard_normal())}


def calibration_seed(seed: int, index: int, route: str) -> int:
    """The sampler seed (``--seed``) of one subject and route."""
    return int(np.random.default_rng([int(seed), int(index), 3, ROUTES.index(route)]).integers(0, 2 ** 31 - 1))


def fibre_stress(theta: Mapping[str, object], stretch: float = STRESS_STRETCH) -> np.ndarray:
    """The HO fibre Cauchy stress σ_ff (kPa) at a fixed fibre stretch, for θ values or arrays of draws."""
    from lvcore.mechanics.stress import ho_fibre_stress

    ff, _ = ho_fibre_stress({n: np.asarray(theta[n], float) for n in THETA_NAMES}, stretch)
    return np.asarray(ff, float)


class TruthFailure(LVCoreError):
    """A prior draw whose FE truth could not be computed (it is redrawn)."""


def simulate_truth(draw: Mapping) -> dict:
    """FE truth of one prior draw: the scale, the 25 noise-free outputs, V0/V20/V30, the stress.

    Raises
    ------
    TruthFailure
        When a solve fails (the draw is redrawn).
    """
    from lvcore.mechanics.case_inputs import build_case
    from lvcore.inference.derived import fe_load_path
    from lvcore.mechanics.edpvr import pca_reference_volume_ml
    from lvcore.mechanics.simulate import simulate

    t0 = time.perf_counter()
    theta, h = dict(draw["theta"]), list(draw["h"])
    try:
        v_cav = pca_reference_volume_ml(h, RESOLUTION)
        scale = float(np.cbrt(draw["v_ref_ml"] / v_cav))
        case = build_case({**theta, **{f"h{k + 1}": v for k, v in enumerate(h)}, "alpha_endo": ANGLES[0],
                           "alpha_epi": ANGLES[1], EDP_NAME: EDP_MMHG}, resolution=RESOLUTION, base=BASE)
        res = simulate(case)
        if not res.converged:
            raise TruthFailure(f"the data solve did not converge: {res.message}")
        y = np.asarray(res.outputs(), float)
        y[0] *= scale ** 3      # strains are scale-free, volumes scale by s^3 (lvcore.geometry.scaling)
        path = fe_load_path([{**theta, "h": h, "scale": scale}], edp_mmhg=EDP_MMHG, angles=ANGLES, base=BASE,
                            resolution=RESOLUTION, pressures_mmhg=CLI_DERIVED_PRESSURES_MMHG)
    except TruthFailure:
        raise
    except LVCoreError as err:
        raise TruthFailure(f"{type(err).__name__}: {str(err)[:300]}") from None
    vols = np.asarray(path.volumes_ml, float)[0]
    if path.n_failed or not np.all(np.isfinite(vols)):
        raise TruthFailure(f"{path.n_failed} EDPVR solve(s) failed")
    p = [float(v) for v in path.pressures_mmhg]
    truth = {n: float(theta[n]) for n in THETA_NAMES}
    truth.update({q: float(vols[p.index(DERIVED_PRESSURES_MMHG[q])]) for q in DERIVED_QUANTITIES})
    truth["fibre_stress"] = float(fibre_stress(theta))
    return {"h": h, "scale": scale, "v_cav_ml": float(v_cav), "v_ref_ml": float(v_cav * scale ** 3),
            "y_clean": [float(v) for v in y], "edv_fe_ml": float(np.asarray(path.volume_at_edp_ml)[0]),
            "fibre_stretch_ed": float(np.asarray(path.fibre_stretch_at_edp)[0]), "truth": truth,
            "seconds": time.perf_counter() - t0}


def make_subject(seed: int, index: int, *, truth_fn: Callable[[Mapping], dict] = simulate_truth,
                 max_redraws: int = MAX_REDRAWS) -> dict:
    """Subject ``index``: the first prior draw whose FE truth succeeds, with the noisy data.

    Returns
    -------
    dict
        ``index``, ``subject``, ``draw`` (the prior draw), the :func:`simulate_truth` fields, ``y`` (the noisy
        25 outputs), ``reference_volume_ml`` (V_ref + noise), ``redraws`` and ``redraw_reasons``.
    """
    attempt, draw, sim, reasons = first_solvable_draw(lambda k: prior_draw(seed, index, k), truth_fn, index,
                                                      max_redraws=max_redraws, what="prior draws")
    noise = noise_draw(seed, index)
    y = np.asarray(sim["y_clean"], float) + np.asarray(noise["y"], float)
    return {"index": int(index), "subject": subject_name(index), "draw": draw, **sim,
            "y": [float(v) for v in y],
            "reference_volume_ml": float(sim["v_ref_ml"] + noise["reference_volume_ml"]),
            "redraws": attempt, "redraw_reasons": reasons}


def first_solvable_draw(draw_fn: Callable[[int], object], truth_fn: Callable, index: int, *,
                        max_redraws: int = MAX_REDRAWS, what: str = "draws") -> tuple:
    """``(attempt, draw, truth, reasons)``: the first ``draw_fn(attempt)`` whose ``truth_fn`` succeeds; each
    :class:`TruthFailure` before it is kept (``reasons``, 200 characters each) and the next draw is tried.

    Raises
    ------
    LVCoreError
        When ``max_redraws + 1`` draws in a row fail (naming subject ``index`` and the last reason).
    """
    reasons = []
    for attempt in range(max_redraws + 1):
        draw = draw_fn(attempt)
        try:
            return attempt, draw, truth_fn(draw), reasons
        except TruthFailure as err:
            reasons.append(str(err)[:200])
    raise LVCoreError(f"subject {index}: {max_redraws + 1} {what} in a row failed in the FE simulator "
                      f"(last: {reasons[-1] if reasons else '?'})")


def subject_name(index: int) -> str:
    return f"SYNTHETIC-SBC-{int(index):05d}"


def write_subject_files(subject: Mapping, folder) -> dict:
    """The files a user would bring: ``data.csv`` (subject, lvv_ml, strain_01..24) and ``geometry.vtu`` (the
    template mesh of the shape at scale s)."""
    from lvcore.geometry.io import write_template_mesh
    from lvcore.geometry.scaling import scale_nodes
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.inference.data import MeasuredData, write_measured_csv

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    csv = write_measured_csv(folder / "data.csv", [MeasuredData(np.asarray(subject["y"], float), subject["subject"],
                                                                synthetic=True)])
    nodes = scale_nodes(load_shape_model().reconstruct(np.asarray(subject["h"], float)), subject["scale"])
    label = (f"SYNTHETIC {subject['subject']} (lvcore study sbc): PC scores "
             f"{[round(v, 4) for v in subject['h']]} at scale {subject['scale']:.4f}")
    vtu = write_template_mesh(folder / "geometry.vtu", nodes, metadata={"label": label})
    return {"data": str(csv), "mesh": str(vtu)}


# ============================================================================ one route through `lvcore calibrate`
def calibrate_argv(route: str, files: Mapping, subject: Mapping, settings: Mapping, out) -> list[str]:
    """The ``lvcore calibrate`` command line of one subject and route."""
    argv = ["calibrate", "--data", str(files["data"]), "--model", MODEL, "--chains", str(settings["chains"]),
            "--warmup", str(settings["warmup"]), "--samples", str(settings["samples"]),
            "--seed", str(calibration_seed(settings["seed"], subject["index"], route)),
            "--derived-draws", str(settings["derived_draws"]),
            "--derived-pressures", ",".join(f"{p:g}" for p in settings["derived_pressures"]),
            "--out", str(out), "--json"]
    if route == "mesh":
        argv[3:3] = ["--geometry", str(files["mesh"])]
    elif route == "infer":
        argv[3:3] = ["--geometry", "infer", "--reference-volume", f"{subject['reference_volume_ml']:.6f}"]
    else:
        raise LVCoreError(f"unknown route '{route}'; choose from {', '.join(ROUTES)}")
    if settings.get("allow_extrapolation"):
        argv.append("--allow-extrapolation")
    return argv


def calibrate_in_process(argv: Sequence[str], log_path=None) -> tuple[int, str]:
    """Run ``lvcore calibrate ...`` (``argv`` starts with ``calibrate``) in this process.

    The sub-command's own parser and handler (:mod:`lvcore.inference.cli`), with the exit codes of
    ``lvcore.cli.main``: 0 fine, 1 did not converge, 2 bad input, 3 internal error, 4 ran but flagged.
    Its printed output goes to ``log_path``.

    Returns
    -------
    (exit code, the last error line printed, or "")
    """
    import argparse
    import contextlib
    import io

    from lvcore.exceptions import SolverError
    from lvcore.inference import cli as calibrate_cli

    buf = io.StringIO()
    code = 0
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        try:
            parser = argparse.ArgumentParser(prog="lvcore")
            calibrate_cli.register(parser.add_subparsers(dest="command", required=True))
            args = parser.parse_args(list(argv))
            args.extra = []
            code = int(args.func(args) or 0)
        except SystemExit as err:          # argparse: exit 2 with its message
            code = int(err.code) if isinstance(err.code, int) else 2
        except SolverError as err:
            print(f"lvcore: did not converge: {err}", file=sys.stderr)
            code = 1
        except LVCoreError as err:
            print(f"lvcore: error: {str(err)[:4000]}", file=sys.stderr)
            code = 2
        except OSError as err:
            print(f"lvcore: error: {type(err).__name__}: {err}", file=sys.stderr)
            code = 2 if err.filename is not None else 3
        except KeyboardInterrupt:
            raise
        except Exception as err:  # noqa: BLE001 - as lvcore.cli.main: one line, exit 3
            print(f"lvcore: internal error: {type(err).__name__}: {' '.join(str(err).split())[:2000]}",
                  file=sys.stderr)
            code = 3
    text = buf.getvalue()
    if log_path is not None:
        Path(log_path).write_text(text)
    errors = [ln for ln in text.splitlines()
              if ln.startswith(("lvcore: error", "lvcore: internal error", "lvcore: did not converge"))
              or ": error: " in ln]   # argparse: "lvcore calibrate: error: ..."
    return code, (errors[-1][:400] if errors and code not in (0, 4) else "")


def _thin(n_total: int, n: int) -> np.ndarray:
    return np.unique(np.linspace(0, n_total - 1, min(int(n), int(n_total))).round().astype(int))


def read_route_outputs(out, subject_name_: str) -> dict:
    """What one ``lvcore calibrate`` run left in ``out``: its summary record, the flattened posterior θ draws
    (``<stem>_iid.nc``) and the derived draws (``<stem>_iid_derived.npz``), each None when missing."""
    from lvcore.inference.calibrate import file_stem

    out = Path(out)
    stem = file_stem(subject_name_)
    rec = None
    if (out / "summary.json").is_file():
        records = json.loads((out / "summary.json").read_text())
        rec = next((r for r in records if r.get("model") == MODEL), None)
    theta = None
    nc = out / f"{stem}_{MODEL}.nc"
    if nc.is_file():
        import arviz as az

        idata = az.from_netcdf(str(nc))
        try:
            theta = {n: np.asarray(idata.posterior[n].values, float).reshape(-1) for n in THETA_NAMES}
        finally:
            close = getattr(idata, "close", None)
            if close is not None:
                close()
    derived = None
    npz = out / f"{stem}_{MODEL}_derived.npz"
    if npz.is_file():
        with np.load(npz) as z:
            derived = {k: np.asarray(z[k]) for k in z.files}
    return {"record": rec, "theta": theta, "derived": derived}


def route_ranks(truth: Mapping[str, float], theta_draws: Mapping | None, derived: Mapping | None, *, thin: int,
                rng) -> tuple[dict, dict, int, dict]:
    """Ranks ``{quantity: [rank, L]}``, relative 90 % widths ``{V20, V30}``, the derived draws with a failed
    solve and the relative error of the posterior median ``{V0, V20, V30}`` (``(median − truth)/truth``), from
    one run's posterior (:func:`read_route_outputs`)."""
    rng = np.random.default_rng(rng)
    ranks, widths, n_failed, rel_error = {}, {}, 0, {}
    if theta_draws is not None:
        n_total = len(theta_draws[THETA_NAMES[0]])
        idx = _thin(n_total, thin)
        thinned = {n: np.asarray(theta_draws[n], float)[idx] for n in THETA_NAMES}
        for n in THETA_NAMES:
            r = rank_of_truth(thinned[n], truth[n], rng)
            ranks[n] = None if r is None else list(r)
        r = rank_of_truth(fibre_stress(thinned), truth["fibre_stress"], rng)
        ranks["fibre_stress"] = None if r is None else list(r)
    if derived is not None and "edpvr_ml" in derived:
        p = [float(v) for v in np.asarray(derived["edpvr_pressures_mmhg"], float)]
        vols = np.asarray(derived["edpvr_ml"], float).reshape(-1, len(p))
        n_failed = int(np.sum(~np.all(np.isfinite(vols), axis=1)))
        for q in DERIVED_QUANTITIES:
            pq = DERIVED_PRESSURES_MMHG[q]
            if pq not in p:
                ranks[q] = None
                continue
            col = vols[:, p.index(pq)]
            r = rank_of_truth(col, truth[q], rng)
            ranks[q] = None if r is None else list(r)
            ok = col[np.isfinite(col)]
            rel_error[q] = float((np.median(ok) - truth[q]) / truth[q]) if ok.size else None
            if q in WIDTH_QUANTITIES:
                widths[q] = (float((np.quantile(ok, 0.95) - np.quantile(ok, 0.05)) / truth[q])
                             if ok.size >= 2 else None)
    return ranks, widths, n_failed, rel_error


def run_route(route: str, subject: Mapping, files: Mapping, settings: Mapping, folder, *,
              calibrate: Callable[[Sequence[str], object], tuple[int, str]] = calibrate_in_process) -> dict:
    """Calibrate one subject by one route and rank its truth; the route's record."""
    folder = Path(folder)
    out = folder / route
    t0, c0 = time.perf_counter(), time.process_time()
    argv = calibrate_argv(route, files, subject, settings, out)
    code, error = calibrate(argv, folder / f"{route}.log")
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    found = read_route_outputs(out, subject["subject"])
    rec = found["record"] or {}
    flags = [str(f) for f in rec.get("flags") or []]
    ranks, widths, n_failed, rel_error = route_ranks(subject["truth"], found["theta"], found["derived"],
                                                     thin=settings["thin"],
                                                     rng=[int(settings["seed"]), int(subject["index"]), 4,
                                                          ROUTES.index(route)])
    geometry = rec.get("geometry") or {}
    # the record names the subject's folder as WORKDIR/runs/<index>, never the machine's path (records are shipped)
    for path in {str(folder.resolve()), str(folder)}:
        error = (error or "").replace(path, f"WORKDIR/runs/{folder.name}")
    return {"exit_code": int(code), "error": error or None, "converged": rec.get("converged"),
            "flag_kinds": sorted({flag_kind(f) for f in flags}), "flags": [f[:240] for f in flags],
            "ranks": ranks, "width_rel": widths, "median_rel_error": rel_error, "derived_failed": n_failed,
            "geometry_scale": geometry.get("scale"),
            "seed": calibration_seed(settings["seed"], subject["index"], route),
            "seconds": wall, "cpu_seconds": cpu}


def run_subject(index: int, settings: Mapping, workdir, *, calibrate=calibrate_in_process,
                truth_fn: Callable[[Mapping], dict] = simulate_truth, keep_runs: bool = False) -> dict:
    """Everything of one subject: the truth, its files, both routes; the JSON-lines record."""
    t0, c0 = time.perf_counter(), time.process_time()
    folder = Path(workdir) / "runs" / f"{int(index):05d}"
    if folder.exists():
        shutil.rmtree(folder)          # a run killed in flight: start the subject again
    subject = make_subject(settings["seed"], index, truth_fn=truth_fn)
    files = write_subject_files(subject, folder)
    routes = {r: run_route(r, subject, files, settings, folder, calibrate=calibrate) for r in settings["routes"]}
    if not keep_runs:
        shutil.rmtree(folder, ignore_errors=True)
    from lvcore.inference.calibrate import release_compiled_programs

    release_compiled_programs()
    return {"version": RECORD_VERSION, "index": int(index), "subject": subject["subject"],
            "settings_key": settings_key(settings), "h": subject["h"], "scale": subject["scale"],
            "v_ref_ml": subject["v_ref_ml"], "reference_volume_ml": subject["reference_volume_ml"],
            "truth": subject["truth"], "y": subject["y"], "y_clean": subject["y_clean"],
            "redraws": subject["redraws"], "redraw_reasons": subject["redraw_reasons"],
            "truth_seconds": subject["seconds"], "routes": routes, "seconds": time.perf_counter() - t0,
            "cpu_seconds": time.process_time() - c0, "load_average": _load_average(),
            "finished": time.strftime("%Y-%m-%dT%H:%M:%S")}


def _load_average() -> float | None:
    """The machine's 1-minute load average when the subject finished (None where unknown)."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None


# ============================================================================ the resumable store
def default_settings(**kw) -> dict:
    s = {"seed": 0, "warmup": DEFAULT_WARMUP, "samples": DEFAULT_SAMPLES, "chains": DEFAULT_CHAINS,
         "derived_draws": DEFAULT_DERIVED_DRAWS, "derived_pressures": list(CLI_DERIVED_PRESSURES_MMHG),
         "thin": DEFAULT_THIN, "routes": list(ROUTES), "allow_extrapolation": False}
    s.update(kw)
    s["routes"] = list(s["routes"])
    s["derived_pressures"] = [float(p) for p in s["derived_pressures"]]
    return s


def settings_key(settings: Mapping) -> dict:
    """The settings that must agree between the records of one work folder (the number of subjects may grow)."""
    keys = ("seed", "warmup", "samples", "chains", "derived_draws", "derived_pressures", "thin", "routes",
            "allow_extrapolation")
    return {"version": RECORD_VERSION, **{k: settings[k] for k in keys}}


class Store:
    """One work folder: ``settings.json`` and one JSON-lines file per piece (subject index range).

    A record is one line, appended and flushed when its subject is done; a
    half-written last line (a kill mid-write) is ignored when reading and cut
    off before the next append. Subjects recorded in any piece file count as done.
    """

    def __init__(self, workdir):
        self.root = Path(workdir)

    def piece_path(self, start: int, stop: int) -> Path:
        return self.root / f"subjects_{int(start):05d}-{int(stop):05d}.jsonl"

    def check_settings(self, settings: Mapping, n_subjects: int | None = None) -> dict:
        """Write ``settings.json`` on the first run; refuse a folder made with other settings."""
        self.root.mkdir(parents=True, exist_ok=True)
        path = self.root / "settings.json"
        key = settings_key(settings)
        old = json.loads(path.read_text()) if path.is_file() else None
        if old is not None and old.get("key") != key:
            raise LVCoreError(f"work folder {self.root} holds an SBC run with other settings ({old.get('key')}); "
                              f"these are {key}: give another --workdir, or the same settings")
        n = max(int(n_subjects or 0), int((old or {}).get("n_subjects") or 0))
        data = {"key": key, "n_subjects": n}
        if data != old:
            write_json_atomic(path, data)
        return data

    def settings(self) -> dict | None:
        path = self.root / "settings.json"
        return json.loads(path.read_text()) if path.is_file() else None

    def records(self) -> list[dict]:
        """Every complete record, one per subject index (the first one found), sorted by index."""
        out: dict[int, dict] = {}
        for f in sorted(self.root.glob("subjects_*.jsonl")):
            for line in f.read_text(errors="replace").splitlines():
                line = line.strip()
                if not line:
                    continue
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:
                    continue              # a line cut off by a kill
                if isinstance(rec, dict) and "index" in rec and "routes" in rec:
                    out.setdefault(int(rec["index"]), rec)
        return [out[k] for k in sorted(out)]

    def done(self) -> set[int]:
        return {int(r["index"]) for r in self.records()}

    #: File of the records taken over from an earlier summary (:meth:`import_summary`).
    IMPORTED_FILE = "subjects_imported.jsonl"

    def import_summary(self, result: Mapping, settings: Mapping, source: str) -> int:
        """Take over the subjects of an earlier summary (the study's result file) whose work folder is gone.

        The summary's subjects keep every field the statistics read (truths,
        ranks, widths, exit codes, flag kinds, seconds); each imported record
        says where it came from (``imported_from``). The summary must have been
        made with the same settings. Subjects already in the folder are kept
        as they are. Returns the number of subjects imported.
        """
        theirs = dict(result.get("settings") or {})
        key = settings_key(settings)
        mismatch = {k: (theirs.get(k), v) for k, v in key.items() if k != "version" and theirs.get(k) != v}
        if mismatch:
            raise LVCoreError(f"--import-summary {source}: made with other settings "
                              f"({', '.join(f'{k} {a!r} there, {b!r} here' for k, (a, b) in mismatch.items())}); "
                              "run with the same settings or without --import-summary")
        subjects = result.get("subjects")
        if not isinstance(subjects, list) or not subjects:
            raise LVCoreError(f"--import-summary {source}: no per-subject records in it (a summary written by "
                              "`lvcore study sbc --summarise` has them under 'subjects')")
        self.check_settings(settings, result.get("n_subjects_planned"))
        done, n = self.done(), 0
        for sub in subjects:
            if int(sub["index"]) in done:
                continue
            rec = {**sub, "version": RECORD_VERSION, "subject": subject_name(int(sub["index"])),
                   "settings_key": key, "imported_from": str(source)}
            rec["routes"] = {r: {"derived_failed": 0, "error": None, **v} for r, v in sub["routes"].items()}
            self.append(self.root / self.IMPORTED_FILE, rec)
            n += 1
        return n

    def append(self, path, record: Mapping) -> None:
        """Append one record as a line (a partial last line left by a kill is cut off first)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.is_file() and path.stat().st_size:
            with open(path, "rb+") as f:
                data = f.read()
                if not data.endswith(b"\n"):
                    f.truncate(data.rfind(b"\n") + 1)
        with open(path, "a", encoding="utf-8") as f:
            f.write(json.dumps(clean(record), allow_nan=False) + "\n")
            f.flush()
            os.fsync(f.fileno())


def piece_range(n_subjects: int, piece: str | None = None, start: int | None = None,
                stop: int | None = None) -> tuple[int, int]:
    """Subject indices ``[start, stop)`` of ``--piece K/N`` (K-th of N near-equal parts, 1-based) or of
    ``--start``/``--stop`` (default the whole range)."""
    n = int(n_subjects)
    if piece is not None:
        if start is not None or stop is not None:
            raise LVCoreError("give --piece K/N or --start/--stop, not both")
        try:
            k, m = (int(v) for v in str(piece).split("/"))
        except ValueError:
            raise LVCoreError(f"--piece {piece!r}: write K/N, e.g. 1/2") from None
        if not (1 <= k <= m):
            raise LVCoreError(f"--piece {piece}: need 1 <= K <= N")
        return (k - 1) * n // m, k * n // m
    a = 0 if start is None else int(start)
    b = n if stop is None else int(stop)
    if not 0 <= a <= b:
        raise LVCoreError(f"--start {a} --stop {b}: need 0 <= start <= stop")
    return a, b


def run_piece(start: int, stop: int, settings: Mapping, workdir, *, n_subjects: int | None = None,
              subject_fn: Callable[[int], dict] | None = None, log: Callable[[str], None] | None = None,
              keep_runs: bool = False, between: Callable[[], None] | None = None) -> dict:
    """Run subjects ``start..stop-1`` not yet recorded in ``workdir``; each finished one is appended at once.

    ``subject_fn(index) -> record`` replaces :func:`run_subject` (tests). ``between()`` is called after each
    recorded subject (the command line's restart before the memory-mapping limit,
    :func:`lvcore.execution.restart.restart_when_mappings_high`).
    """
    store = Store(workdir)
    store.check_settings(settings, n_subjects if n_subjects is not None else stop)
    done = store.done()
    todo = [i for i in range(start, stop) if i not in done]
    path = store.piece_path(start, stop)
    say = log or (lambda m: None)
    say(f"SBC piece [{start}, {stop}): {len(todo)} to run, {stop - start - len(todo)} already done; "
        f"records -> {path}")
    t0 = time.perf_counter()
    for k, i in enumerate(todo):
        rec = subject_fn(i) if subject_fn is not None else run_subject(i, settings, workdir, keep_runs=keep_runs)
        store.append(path, rec)
        codes = ", ".join(f"{r} exit {v['exit_code']} ({v['seconds']:.0f} s)" for r, v in rec["routes"].items())
        say(f"[{k + 1}/{len(todo)}] {rec['subject']}: {codes}; {rec['seconds']:.0f} s wall, "
            f"{rec.get('cpu_seconds', float('nan')):.0f} CPU-s")
        if between is not None:
            between()
    return {"piece": [start, stop], "ran": len(todo), "seconds": time.perf_counter() - t0, "file": str(path)}


def check_emulator_conditions(name: str = EMULATOR) -> dict:
    """The ``chapter`` emulator's training conditions must be the study's (EDP, angles, base, mesh)."""
    from lvcore.emulator import load_emulator

    emu = load_emulator(name)
    fixed = emu.metadata.get("fixed_inputs", {})
    found = {EDP_NAME: fixed.get(EDP_NAME), "alpha_endo": fixed.get("alpha_endo"), "alpha_epi": fixed.get("alpha_epi"),
             "base": emu.base, "resolution": emu.resolution}
    want = {EDP_NAME: EDP_MMHG, "alpha_endo": ANGLES[0], "alpha_epi": ANGLES[1], "base": BASE, "resolution": RESOLUTION}
    if found != want:
        raise LVCoreError(f"the '{name}' emulator's conditions {found} are not the SBC study's {want}")
    return found



__all__ = ["RECORD_VERSION", "ROUTES", "DERIVED_QUANTITIES", "QUANTITIES", "WIDTH_QUANTITIES", "flag_kind",
           "prior_draw", "noise_draw", "calibration_seed", "fibre_stress", "TruthFailure", "simulate_truth",
           "make_subject", "first_solvable_draw", "subject_name", "write_subject_files", "calibrate_argv",
           "calibrate_in_process",
           "read_route_outputs", "route_ranks", "run_route", "run_subject", "default_settings", "settings_key",
           "Store", "piece_range", "run_piece", "check_emulator_conditions"]
