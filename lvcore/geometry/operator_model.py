"""Realistic imitation operators: whole-slice choices, local trabecular inclusion, breath-hold misregistration.

Issue 26 item 4. The first operator study's imitation operators
(:data:`lvcore.geometry.cohort.OPERATORS`) differ mostly by smooth radial
offsets, which loss (9.11)'s relative-volume term largely cancels. Real
segmenters differ in other ways (inter-observer studies of cine short-axis
volumes name the basal slice first, then the trabeculae and the apex):

* **whole-slice choices** of the basal and the apical slice: whether the
  partial-volume slice at the base (or the apex) is counted as LV — a
  10 mm jump of the traced base, drawn per patient from each operator's
  habits (:class:`OperatorProfile` probabilities);
* **local trabecular inclusion**: on some slices the endocardial contour is
  pulled inwards over a local arc of the lateral wall (trabeculae and
  papillary muscles traced as myocardium;
  :attr:`~lvcore.geometry.cohort.OperatorStyle.trabecular_mm`);
* **per-slice in-plane misregistration**: every scan has its own breath-hold
  shifts per slice (shared by the operators who segment it,
  :func:`~lvcore.geometry.cohort.breath_hold_shifts`), and each operator
  realigns a fraction of them (``registration``).

On top of these each operator keeps the smooth per-contour noise and small
offsets of the first model. Everything here is SYNTHETIC: the patients are
draws of :func:`lvcore.geometry.cohort.sample_lv` from their own seed (they
are not in the shape model's training set), and each stack is fitted with
the same pipeline as a user's segmentation
(:func:`lvcore.geometry.fitting.fit_contours`).
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from lvcore.geometry.cohort import (
    OperatorGeometries,
    OperatorStyle,
    breath_hold_shifts,
    contour_stack,
    random_pose,
    sample_lv,
)

#: Seed of the realistic operator cohort.
DEFAULT_SEED = 26_04
#: Patients of the realistic operator study (issue 26: 20 or more).
DEFAULT_PATIENTS = 24
#: SD (mm, per in-plane axis) of a scan's per-slice breath-hold shifts.
BREATH_HOLD_MM = 1.5


@dataclass(frozen=True)
class OperatorProfile:
    """One realistic operator's habits: a segmentation style and how often each whole-slice choice is made.

    style : OperatorStyle
        Offsets, noise, trabecular inclusion and slice realignment (its
        ``basal_slices``/``apical_slices`` are drawn per patient).
    p_basal_add, p_basal_drop : float
        Probability, per patient, of counting one more slice above the base
        as LV, or of dropping the basal slice.
    p_apical_add, p_apical_drop : float
        The same for the apical (partial-volume) slice.
    """

    style: OperatorStyle
    p_basal_add: float = 0.0
    p_basal_drop: float = 0.0
    p_apical_add: float = 0.0
    p_apical_drop: float = 0.0

    @property
    def name(self) -> str:
        return self.style.name

    def __post_init__(self):
        for a, b in ((self.p_basal_add, self.p_basal_drop), (self.p_apical_add, self.p_apical_drop)):
            if min(a, b) < 0 or a + b > 1:
                raise ValueError(f"operator {self.name}: slice-choice probabilities must be >= 0 and sum to <= 1")


#: The three realistic imitation operators (see the module docstring and docs/studies.md).
REALISTIC_OPERATORS = (
    # careful: realigns most of the breath-hold shifts, seldom deviates on the base, little trabecular inclusion
    OperatorProfile(OperatorStyle("r1", noise_mm=0.35, shift_mm=0.25, trabecular_mm=1.0, trabecular_arc_deg=90.0,
                                  trabecular_share=0.3, registration=0.8),
                    p_basal_add=0.15, p_basal_drop=0.15, p_apical_add=0.2, p_apical_drop=0.1),
    # inclusive: counts the partial-volume base and apex as LV, traces trabeculae as myocardium, no realignment
    OperatorProfile(OperatorStyle("r2", epi_bias_mm=0.4, noise_mm=0.5, shift_mm=0.35, trabecular_mm=3.0,
                                  trabecular_arc_deg=100.0, trabecular_share=0.6, registration=0.0),
                    p_basal_add=0.35, p_basal_drop=0.05, p_apical_add=0.3, p_apical_drop=0.05),
    # conservative: drops doubtful basal and apical slices, moderate trabecular inclusion, partial realignment
    OperatorProfile(OperatorStyle("r3", endo_bias_mm=-0.2, epi_bias_mm=0.1, noise_mm=0.35, shift_mm=0.25,
                                  trabecular_mm=2.0, trabecular_arc_deg=80.0, trabecular_share=0.4,
                                  registration=0.5),
                    p_basal_add=0.05, p_basal_drop=0.35, p_apical_add=0.05, p_apical_drop=0.3),
)


def _choice(rng, p_add: float, p_drop: float) -> int:
    u = rng.random()
    return 1 if u < p_add else -1 if u < p_add + p_drop else 0


def draw_style(profile: OperatorProfile, rng) -> OperatorStyle:
    """The operator's style on one patient: its whole-slice choices of the base and the apex drawn."""
    rng = np.random.default_rng(rng)
    basal = _choice(rng, profile.p_basal_add, profile.p_basal_drop)
    apical = _choice(rng, profile.p_apical_add, profile.p_apical_drop)
    return replace(profile.style, basal_slices=basal, apical_slices=apical)


def patient_ids(n_patients: int) -> list[str]:
    """``SYNTHETIC-R01`` ... (R: the realistic-operator study)."""
    return [f"SYNTHETIC-R{i + 1:02d}" for i in range(int(n_patients))]


def realistic_stacks(n_patients: int = DEFAULT_PATIENTS, seed: int = DEFAULT_SEED,
                     operators=REALISTIC_OPERATORS, breath_hold_mm: float = BREATH_HOLD_MM):
    """Per SYNTHETIC patient: its LV and each operator's style and contour stack (one scan, shared shifts).

    Returns a list of ``(patient id, SyntheticLV, {operator: (OperatorStyle, ContourStack)})``;
    patient ``i`` depends only on ``(seed, i)``.
    """
    out = []
    for pid, ss in zip(patient_ids(n_patients), np.random.SeedSequence(seed).spawn(int(n_patients))):
        shape_rng, pose_rng, bh_rng, *op_rngs = (np.random.default_rng(s) for s in ss.spawn(3 + len(operators)))
        lv = sample_lv(shape_rng)
        pose = random_pose(pose_rng)
        bh = breath_hold_shifts(bh_rng, breath_hold_mm)
        per_op = {}
        for prof, r in zip(operators, op_rngs):
            style = draw_style(prof, r)
            per_op[prof.name] = (style, contour_stack(lv, style, r, patient=pid, pose=pose, breath_hold=bh))
        out.append((pid, lv, per_op))
    return out


def build_operator_geometries(n_patients: int = DEFAULT_PATIENTS, seed: int = DEFAULT_SEED, cache_dir=None,
                              operators=REALISTIC_OPERATORS, breath_hold_mm: float = BREATH_HOLD_MM,
                              log=None) -> OperatorGeometries:
    """Fit every operator's stack of every patient (:func:`~lvcore.geometry.fitting.fit_contours`).

    A patient any of whose stacks cannot be fitted is left out (listed in
    ``meta["left_out"]`` with the reason). With ``cache_dir`` the result is
    kept there as ``SYNTHETIC_operators.{npz,json}`` and reused when the
    settings match (a rerun does not refit).
    """
    from lvcore.exceptions import LVCoreError
    from lvcore.geometry.cohort import load_operator_geometries
    from lvcore.geometry.fitting import fit_contours

    settings = {"n_patients": int(n_patients), "seed": int(seed), "breath_hold_mm": float(breath_hold_mm),
                "operators": [{**asdict(p.style), **{k: getattr(p, k) for k in
                                                     ("p_basal_add", "p_basal_drop", "p_apical_add", "p_apical_drop")}}
                              for p in operators]}
    if cache_dir is not None and (Path(cache_dir) / "SYNTHETIC_operators.json").is_file():
        og = load_operator_geometries(cache_dir)
        if og.meta.get("settings") == json.loads(json.dumps(settings)):
            return og
    t0 = time.perf_counter()
    names = [p.name for p in operators]
    patients, nodes, fits, left_out = [], [], {}, {}
    for pid, lv, per_op in realistic_stacks(n_patients, seed, operators, breath_hold_mm):
        row, recs = [], {}
        try:
            for name in names:
                style, stack = per_op[name]
                fit = fit_contours(stack)
                row.append(fit.nodes)
                recs[f"{pid}/{name}"] = {**fit.summary(), "basal_slices": style.basal_slices,
                                         "apical_slices": style.apical_slices, "n_slices": len(stack.slices)}
        except (LVCoreError, ValueError, np.linalg.LinAlgError) as err:
            left_out[pid] = f"{name}: {err}"
            continue
        patients.append(pid)
        nodes.append(row)
        fits.update(recs)
        if log is not None:
            log(f"{pid}: " + ", ".join(f"{n} V={recs[f'{pid}/{n}']['cavity_volume_ml']:.1f} mL "
                                      f"(base {recs[f'{pid}/{n}']['basal_slices']:+d}, apex "
                                      f"{recs[f'{pid}/{n}']['apical_slices']:+d})" for n in names))
    meta = {"label": f"SYNTHETIC realistic-operator study: {len(patients)} synthetic patients x {len(names)} "
                     "realistic imitation operators (lvcore.geometry.operator_model)",
            "synthetic": True, "seed": int(seed), "patients": patients, "operators": names, "fits": fits,
            "left_out": left_out, "settings": settings, "seconds": round(time.perf_counter() - t0, 1)}
    og = OperatorGeometries(patients=tuple(patients), operators=tuple(names), nodes=np.asarray(nodes, float),
                            fits=fits, meta=meta)
    if cache_dir is not None:
        d = Path(cache_dir)
        d.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(d / "SYNTHETIC_operators.npz", nodes=og.nodes)
        (d / "SYNTHETIC_operators.json").write_text(json.dumps(meta, indent=1))
    return og


__all__ = ["OperatorProfile", "REALISTIC_OPERATORS", "draw_style", "realistic_stacks", "build_operator_geometries",
           "patient_ids", "DEFAULT_SEED", "DEFAULT_PATIENTS", "BREATH_HOLD_MM"]
