"""The mismatch study's data: each volunteer's simulator case with one mismatch source at a dose, the simulations
(resumable, on the campaign executors) and the measured size of each dose (strain RMS).

Part of :mod:`lvcore.studies.mismatch` (the study; its docstring describes the sources and doses).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP, HO_FIXED
from lvcore.mechanics.case_inputs import build_case
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, EDP_NAME, THETA_NAMES
from lvcore.studies._common import write_json_atomic

#: The calibration model's fixed conditions (the ``chapter`` emulator).
MODEL_ANGLES = CHAPTER_ANGLES
MODEL_BASE = "sliding"


def model_conditions_text() -> str:
    """The calibration model's fixed conditions in words, e.g. ``sliding base, inner half, angles (−60°, 60°),
    8 mmHg`` (from :data:`MODEL_BASE`, the default strain layer, :data:`MODEL_ANGLES` and the chapter's EDP)."""
    angles = ", ".join(f"{a:g}°".replace("-", "−") for a in MODEL_ANGLES)
    return (f"{MODEL_BASE} base, {DEFAULT_STRAIN_LAYER.replace('_', ' ')}, angles ({angles}), "
            f"{CHAPTER_EDP:g} mmHg")


#: Doses per source, chosen from a simulation-only pass (``--simulate-only``, HV1 and HV5, docs/studies.md) to
#: span a strain RMS mismatch of about 0.005-0.06 where the physics reaches it: the angle rotation peaks near
#: 0.017 (30°) and falls beyond; the sheet terms stay below 0.002 even at 32x (a null control, two doses);
#: heterogeneity 1.6 is refused by the case's multiplier bounds [0.01, 100] (1.2 gives 0.045); dispersion
#: reaches 0.03-0.11 at kappa = 1/3 depending on the volunteer; the pericardial spring saturates near 0.21.
DEFAULT_DOSES = {
    "angles": (5.0, 15.0, 30.0, 45.0),
    "base": (1.0,),
    "sheet": (4.0, 32.0),
    "dispersion": (0.025, 0.05, 0.1, 0.2, 0.333),
    "heterogeneity": (0.2, 0.4, 0.8, 1.2),
    "pericardium": (0.03, 0.1, 0.2, 0.3),
}
SOURCES = tuple(DEFAULT_DOSES)
#: Seed of the heterogeneity field (the same regional pattern at every dose and for every volunteer).
HETEROGENEITY_SEED = 26
#: Display names of the sources.
SOURCE_LABELS = {"angles": "fibre angles (°)", "base": "clamped base", "sheet": "sheet terms (× as, afs)",
                 "dispersion": "dispersion κ", "heterogeneity": "heterogeneity (log-sd)",
                 "pericardium": "pericardium k (kPa/mm)"}


def dose_label(source: str, dose: float) -> str:
    """A dose as a table or a list writes it: ``clamped base``, else ``<source> <dose>``."""
    return "clamped base" if source == "base" else f"{source} {dose:g}"


# ----------------------------------------------------------------------------
# the mismatched case (pure)
# ----------------------------------------------------------------------------
def mismatch_case(theta: dict, h: Sequence[float], source: str | None, dose: float, *,
                  resolution: str = "default", geometry: dict | None = None) -> dict:
    """The simulator case of a volunteer (θ, PC scores h) with one mismatch ``source`` at ``dose``.

    ``source=None`` (or dose 0) is the calibration model's own condition: angles
    :data:`MODEL_ANGLES`, base :data:`MODEL_BASE`, population sheet terms. ``geometry`` (a case geometry section,
    e.g. the real LV's template mesh ``{"kind": "mesh", "path": ...}``) replaces the PC scores ``h`` (give ``h=()``).
    Every source applies to a mesh too: the fibre angles, sheet terms and dispersion are material and fibre
    settings, the clamped base and the pericardial spring act on the mesh's base and epicardium, and the
    heterogeneity field on its 24 AHA regions; a source the simulator cannot apply is refused when the case is
    validated (:func:`lvcore.mechanics.case.Case.from_dict`), never skipped.
    """
    if geometry is not None and len(h):
        raise ValueError("give either PC scores h or a geometry section, not both")
    inputs = {**{n: float(theta[n]) for n in THETA_NAMES}, "alpha_endo": MODEL_ANGLES[0],
              "alpha_epi": MODEL_ANGLES[1], EDP_NAME: CHAPTER_EDP,
              **{f"h{i + 1}": float(v) for i, v in enumerate(h)}}
    base = MODEL_BASE
    if source == "angles":
        inputs["alpha_endo"] += dose
        inputs["alpha_epi"] += dose
    if source == "base" and dose:
        base = "clamped"
    case = build_case(inputs, resolution=resolution, base=base, geometry=geometry)
    mat, bnd = case["material"], case["boundary"]
    if source == "sheet":
        mat["as"], mat["afs"] = HO_FIXED["as"] * dose, HO_FIXED["afs"] * dose
    elif source == "dispersion":
        mat["kappa"] = float(dose)
    elif source == "heterogeneity" and dose:
        z = np.random.default_rng(HETEROGENEITY_SEED).standard_normal((2, 24))
        f = np.exp(float(dose) * z)
        mat["regional"] = {"a": f[0].tolist(), "af": f[1].tolist()}
    elif source == "pericardium" and dose:
        bnd["epicardial_spring"] = {"k": float(dose), "direction": "normal"}
    elif source not in (None, "angles", "base", "sheet", "dispersion", "heterogeneity", "pericardium"):
        raise ValueError(f"unknown mismatch source {source!r}; choose from {SOURCES}")
    return case


def _simulate_job(key: str, case: dict) -> dict:
    """Worker: simulate one case; failures are recorded, never raised."""
    from lvcore.core.forward import failure_reason
    from lvcore.mechanics.simulate import simulate

    t0 = time.perf_counter()
    try:
        r = simulate(case)
        if not r.converged:
            return {"key": key, "converged": False, "reason": r.message, "seconds": time.perf_counter() - t0}
        return {"key": key, "converged": True, "outputs": r.outputs().tolist(), "seconds": time.perf_counter() - t0}
    except Exception as err:  # noqa: BLE001 - a failed simulation is data
        return {"key": key, "converged": False, "reason": failure_reason(err), "seconds": time.perf_counter() - t0}


# ----------------------------------------------------------------------------
# volunteers
# ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Volunteer:
    """A volunteer of the study: name, PC scores h (the ``chapter`` emulator's geometry inputs) and hidden θ; or,
    for a mesh volunteer (the real LV), ``h=()`` and ``geometry`` (its case geometry section), calibrated through a
    subject emulator of that mesh."""

    name: str
    h: tuple[float, ...]
    theta: dict
    geometry: dict | None = None


#: The real LV's volunteer name (``volunteers=[..., REAL_LV]``, ``--volunteers ...,REAL-LV``).
REAL_LV = "REAL-LV"
#: The real LV's hidden θ (a, b, af, bf): the SYNTHETIC volunteers' (HV1-HV8) componentwise median θ, rounded to
#: 3 significant digits. A typical volunteer's material, inside the emulators' box and away from its edges (the
#: fibre-discrepancy study's first θ, a = 0.1, is near the lower edge), so that the real LV's mismatch sizes and
#: fits compare with the volunteers' at a material in their middle: the geometry is the one difference.
REAL_LV_THETA = {"a": 0.994, "b": 2.14, "af": 1.05, "bf": 3.90}


def real_lv_volunteer() -> Volunteer:
    """The real LV (the shipped patient-derived mesh, :func:`lvcore.resources.real_lv_files`) as a volunteer at
    :data:`REAL_LV_THETA`; its data are FE-simulated on its template mesh."""
    from lvcore.resources import real_lv_files

    return Volunteer(REAL_LV, (), dict(REAL_LV_THETA), {"kind": "mesh", "path": str(real_lv_files().template)})


def study_volunteers(names: Sequence[str] | None = None) -> list[Volunteer]:
    """The study's volunteers: the bundled SYNTHETIC ones named in ``names`` (all when None), then the real LV
    when ``names`` holds :data:`REAL_LV`."""
    bundled = None if names is None else [n for n in names if n != REAL_LV]
    out = bundled_volunteers(bundled) if bundled is None or bundled else []
    return out + ([real_lv_volunteer()] if names is not None and REAL_LV in names else [])


def bundled_volunteers(names: Sequence[str] | None = None) -> list[Volunteer]:
    """The bundled SYNTHETIC volunteers (all, or ``names`` such as ``HV1``) with their recorded h and θ."""
    from lvcore.resources import volunteer_truth, volunteers_dir

    meta = json.loads((volunteers_dir() / "SYNTHETIC_volunteers.json").read_text())
    out = []
    for v in meta["volunteers"]:
        short = v["subject"].split("-")[-1]
        if names and short not in names and v["subject"] not in names:
            continue
        truth = volunteer_truth(v["subject"])
        out.append(Volunteer(short, tuple(float(x) for x in v["pca_scores_h1_h5"]),
                             {n: truth[n] for n in THETA_NAMES}))
    if names and len(out) != len(set(names)):
        known = [v["subject"].split("-")[-1] for v in meta["volunteers"]]
        raise ValueError(f"unknown volunteer(s) in {list(names)}; bundled: {known}, and {REAL_LV} (the real LV)")
    return out


# ----------------------------------------------------------------------------
# steps: simulate, fit, summarise
# ----------------------------------------------------------------------------
def dose_key(vol: str, source: str | None, dose: float) -> str:
    """The key of one (volunteer, source, dose): its simulation's and its fits' file names."""
    return f"{vol}__{source or 'none'}__{dose:g}"


def simulate_all(volunteers, plan, out: Path, *, resolution="default", workers=1, scheduler=None,
                 progress: Callable | None = None, retry_failed: bool = False) -> dict:
    """Simulate every (volunteer, source, dose) of ``plan`` plus each volunteer's nominal case; resumable.

    Recorded results are reused; failed ones too, unless ``retry_failed``.
    Returns key -> record (``converged``, ``outputs`` or ``reason``).
    """
    sims = out / "sims"
    sims.mkdir(parents=True, exist_ok=True)
    jobs = {}
    for v in volunteers:
        for source, dose in [(None, 0.0)] + [(s, d) for s, ds in plan.items() for d in ds]:
            key = dose_key(v.name, source, dose)
            path = sims / f"{key}.json"
            if not path.is_file() or (retry_failed and not json.loads(path.read_text())["converged"]):
                jobs[key] = mismatch_case(v.theta, v.h, source, dose, resolution=resolution, geometry=v.geometry)
    if jobs:
        if workers == 1 and not scheduler:
            for i, (k, c) in enumerate(jobs.items()):
                write_json_atomic(sims / f"{k}.json", _simulate_job(k, c))
                if progress:
                    progress(f"simulated {k} ({i + 1}/{len(jobs)})")
        else:
            from lvcore.execution.parallel import make_executor

            with make_executor(workers=workers, scheduler=scheduler) as ex:
                futures = [ex.submit(_simulate_job, k, c) for k, c in jobs.items()]
                for i, fut in enumerate(ex.as_completed(futures)):
                    rec = fut.result()
                    write_json_atomic(sims / f"{rec['key']}.json", rec)
                    if progress:
                        progress(f"simulated {rec['key']} ({i + 1}/{len(jobs)})")
    return {p.stem: json.loads(p.read_text()) for p in sims.glob("*.json")}



def strain_rms(z, nominal) -> float:
    """The size of a dose: RMS over the 24 strains of the mismatched minus the nominal outputs."""
    return float(np.sqrt(np.mean((np.asarray(z)[1:] - np.asarray(nominal)[1:]) ** 2)))


def measured_doses(sims: dict, volunteers, plan: dict) -> dict:
    """``(source, dose) -> {"mean", "min", "max", "n", "failed", "by_volunteer"}`` of the strain RMS over the
    volunteers (``by_volunteer``: volunteer name -> its strain RMS)."""
    out = {}
    for source, ds in plan.items():
        for dose in ds:
            vals, names, failed = [], [], 0
            for v in volunteers:
                nom, rec = sims.get(dose_key(v.name, None, 0.0)), sims.get(dose_key(v.name, source, dose))
                if nom and rec and nom["converged"] and rec["converged"]:
                    vals.append(strain_rms(rec["outputs"], nom["outputs"]))
                    names.append(v.name)
                else:
                    failed += 1
            out[(source, dose)] = ({"mean": float(np.mean(vals)), "min": float(np.min(vals)),
                                    "max": float(np.max(vals)), "n": len(vals), "failed": failed,
                                    "by_volunteer": dict(zip(names, map(float, vals)))} if vals
                                   else {"mean": None, "min": None, "max": None, "n": 0, "failed": failed})
    return out



__all__ = ["MODEL_ANGLES", "MODEL_BASE", "DEFAULT_DOSES", "SOURCES", "HETEROGENEITY_SEED", "SOURCE_LABELS",
           "dose_key", "dose_label", "mismatch_case", "Volunteer", "bundled_volunteers", "REAL_LV", "REAL_LV_THETA",
           "real_lv_volunteer", "study_volunteers", "simulate_all", "strain_rms",
           "measured_doses"]
