"""The "My subject" flow: one's own geometry and measurements, from upload to a downloadable bundle.

The page ``pages/8_My_subject.py`` only gathers inputs and shows what this
module returns; every step here is Streamlit-free and does what ``lvcore
calibrate`` does for the same inputs (same geometry resolution, box check,
conditions, forward model and plausibility check), so the app and the CLI
give the same answer.

The steps:

1. :func:`read_geometry` — an uploaded geometry (a volume mesh, a template
   mesh, or PC scores) becomes a :class:`~lvcore.inference.guards.GeometrySource`
   (PC scores ``h`` and the uniform scale ``s``; the fit residual of a mesh).
   Without a mesh (``lvcore calibrate --geometry infer``), :func:`inferred_measures`
   takes the CMR measures (reference volume, wall volume, long axis) and
   :func:`prepare_inferred` samples ``h`` and ``s`` with θ
   (:mod:`lvcore.inference.geometry_prior`).
2. :func:`read_data` — uploaded measurements (24-region or AHA-16 CSV, JSON
   or ``.mat``) become :class:`~lvcore.inference.data.MeasuredData` rows.
3. :func:`prepare` — binds geometry and conditions (EDP) into the emulator,
   checks the PC scores against the emulator's training box and returns the
   forward model with what it used (:class:`Prepared`).
4. :func:`calibrate` — runs the chosen likelihoods and checks each result's
   plausibility (:class:`SubjectRun`).
5. :func:`bundle` — one zip: InferenceData (netCDF) per likelihood, the
   figures (HTML), ``settings.json``, ``summary.json`` and a one-page
   ``summary.html``.

Optionally, :class:`SubjectBuild` builds a subject-specific emulator on the
loaded geometry as it is (``lvcore emulator build --geometry FILE``,
:func:`lvcore.emulator.subject.build_subject_emulator`) in a background thread,
with progress and a stop request; :func:`prepare` then binds no PC scores
(the geometry is in the emulator), as ``lvcore calibrate --emulator DIR``.
"""
from __future__ import annotations

import hashlib
import html
import io
import json
import tempfile
import threading
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from lvcore.exceptions import DataError, LVCoreError

#: File types the geometry step takes (volume meshes are fitted, template meshes projected).
GEOMETRY_TYPES = ("vtu", "vtk", "msh", "inp", "npy", "npz", "json", "csv")
#: File types the data step takes.
DATA_TYPES = ("csv", "json", "mat", "txt")


#: The My-subject page's control for a volume mesh's length units, named by the wrong-units warning.
UNITS_CONTROL = "the 'Mesh length units' choice"


def read_geometry(session, name: str, data: bytes, *, n_pc: int = 5, units: str = "mm"):
    """The PC scores and scale of an uploaded geometry, as ``lvcore calibrate --geometry FILE`` reads it.

    Parameters
    ----------
    session : lvcore.uploads.UploadSession
        The browser session's upload folder.
    name : str
        The user's file name (its suffix picks the reader).
    data : bytes
        The file's contents.
    n_pc : int
        PC scores the emulator uses.
    units : {"mm", "cm", "m"}
        Length units of a volume mesh.

    Returns
    -------
    lvcore.inference.guards.GeometrySource

    Raises
    ------
    lvcore.uploads.UploadError
        With a message naming the user's file.
    """
    from lvcore.inference import guards

    return session.read(name, data, lambda path: guards.resolve_geometry(path, n_pc=n_pc, units=units,
                                                                          units_option=UNITS_CONTROL),
                        slot="geometry")


def geometry_nodes(geometry) -> np.ndarray:
    """Template nodes (mm) of the geometry the emulator sees: the shape model at ``h``, scaled by ``s``."""
    from lvcore.geometry.scaling import scale_nodes
    from lvcore.geometry.shape_model import load_shape_model

    model = load_shape_model()
    h = np.asarray(geometry.h, float)[:model.n_modes]
    return scale_nodes(model.reconstruct(h), float(geometry.scale))


#: Relative difference between the entered reference volume and the model geometry's cavity that is flagged.
REFERENCE_VOLUME_TOLERANCE = 0.10


def geometry_measures(geometry, reference_volume_ml: float | None = None) -> tuple[dict, list]:
    """Cavity and wall volume (mL) and length (mm) of the geometry the emulator sees, and warnings.

    When the user entered the subject's early-diastolic cavity volume (``reference_volume_ml``),
    a difference above :data:`REFERENCE_VOLUME_TOLERANCE` is a warning: the emulated volumes, and so the
    stiffness, would be biased by the geometry.
    """
    from lvcore.geometry.measures import geometry_info

    info = geometry_info(geometry_nodes(geometry))
    warnings = []
    if reference_volume_ml is not None and reference_volume_ml > 0:
        rel = info["cavity_volume_ml"] / float(reference_volume_ml) - 1.0
        info["reference_volume_ml"] = float(reference_volume_ml)
        info["reference_volume_difference"] = rel
        if abs(rel) > REFERENCE_VOLUME_TOLERANCE:
            warnings.append(f"the model geometry's cavity is {info['cavity_volume_ml']:.1f} mL, {100 * rel:+.0f} % "
                            f"from the {reference_volume_ml:.1f} mL you entered: check the mesh's units and that "
                            "it is the early-diastolic (reference) frame; the stiffness would be biased")
    return info, warnings


def read_data(session, name: str, data: bytes, segments: str | None = None) -> list:
    """Measured rows of an uploaded CSV/JSON/``.mat`` (24 lvcore regions or AHA-16), as ``lvcore calibrate --data``.

    Raises
    ------
    lvcore.uploads.UploadError
        With a message naming the user's file.
    """
    from lvcore.inference.data import read_measurements

    return session.read(name, data, lambda path: read_measurements(path, segments=segments), slot="measured")


@dataclass(frozen=True)
class Prepared:
    """The forward model for one subject and what went into it.

    Attributes
    ----------
    forward : Forward
        Emulator with the geometry and conditions bound in, LVV scaled by ``s^3``.
    emulator_name : str
    conditions : dict
        ``edp_mmhg``, ``alpha_endo``, ``alpha_epi`` used (mmHg, degrees) and ``fixed`` (those the
        emulator fixes).
    box : list of dict
        Each fixed input against the emulator's training range (``name``, ``value``, ``low``, ``high``, ``inside``).
    warnings : list of str
        Geometry warnings and extrapolation warnings (scores outside the box).
    measures : dict or None
        See :attr:`inferred`.
    """

    forward: Any
    emulator_name: str
    conditions: dict
    box: list
    warnings: list = field(default_factory=list)
    #: The measured geometric measures of an inferred geometry (the no-mesh route), None for a given geometry.
    measures: dict | None = None
    #: Where each measure sd given to an inferred geometry came from (:func:`inferred_measure_sds`).
    measure_sd_source: dict | None = None
    #: The representation-error floor's record of a given mesh (``lvcore calibrate``'s
    #: ``geometry.representation_error``), None without one (:func:`prepare`).
    representation_error: dict | None = None

    @property
    def extrapolating(self) -> bool:
        return any(not row.get("inside", True) for row in self.box)

    @property
    def inferred(self) -> bool:
        """The geometry (PC scores and scale) is sampled with θ (``--geometry infer``)."""
        return self.measures is not None


def _conditions(emulator, edp_mmhg):
    """The CLI's conditions check; the EDP a fixed-EDP emulator was trained at counts as not given."""
    from lvcore.inference import guards
    from lvcore.outputs import EDP_NAME

    fixed_edp = dict(getattr(emulator, "fixed", None) or {}).get(EDP_NAME)
    if edp_mmhg is not None and fixed_edp is not None and abs(float(edp_mmhg) - float(fixed_edp)) <= 1e-6:
        edp_mmhg = None  # the EDP the emulator was trained at: nothing to honour (another EDP is refused)
    return guards.check_conditions(emulator, edp_mmhg, None, None, infer_angles=False)


def prepare(emulator, emulator_name: str, geometry, *, edp_mmhg: float | None = None,
            representation_error: str = "floor") -> Prepared:
    """Bind ``geometry`` and the EDP into ``emulator``, with the CLI's condition and box checks.

    A mesh (a template or volume mesh) is seen through its 5-mode projection and gets the shape model's
    representation-error floor, as ``lvcore calibrate --geometry MESH`` (``representation_error`` "floor",
    the default, or "off"; :func:`lvcore.inference.representation_error.given_geometry_floor`).

    Scores outside the training box do not stop the flow (the CLI refuses them without
    ``--allow-extrapolation``); they come back as warnings and :attr:`Prepared.extrapolating`.
    A subject-specific emulator (``emulator.is_subject``) has its geometry bound in: no PC scores, scale 1,
    as ``lvcore calibrate --emulator DIR``; ``geometry`` may then be None.

    Raises
    ------
    lvcore.exceptions.EmulatorError
        If the emulator cannot take the EDP asked for (a fixed-EDP emulator and another EDP).
    """
    from lvcore.emulator.forward import emulator_forward
    from lvcore.geometry.scaling import ScaledForward
    from lvcore.inference import guards

    cond = _conditions(emulator, edp_mmhg)
    bound = bool(getattr(emulator, "is_subject", False))
    h, scale = (np.zeros(0), 1.0) if bound else (geometry.h, geometry.scale)
    box, extrapolation = guards.check_inputs_in_box(guards.fixed_inputs(h, cond, emulator, False), emulator,
                                                    allow_extrapolation=True, what="the subject's PC scores")
    forward = ScaledForward(emulator_forward(emulator, h, name=emulator_name,
                                             alpha_endo=cond["alpha_endo"], alpha_epi=cond["alpha_epi"],
                                             edp_mmhg=cond["edp_mmhg"]), scale)
    floor = None
    if not bound:   # a mesh is seen through its projection: the CLI's representation-error floor
        from lvcore.inference.representation_error import given_geometry_floor

        forward, floor = given_geometry_floor(forward, geometry.kind, representation_error, len(h),
                                              projection_mse_cm2=getattr(geometry, "projection_mse_cm2", None))
    geometry_warnings = list(subject_emulator_geometry(emulator).warnings) if bound else list(geometry.warnings)
    return Prepared(forward, emulator_name, cond, list(box), geometry_warnings + list(extrapolation),
                    representation_error=floor)


def floor_caption(record: Mapping | None) -> str:
    """One line on the representation-error floor a run used (its record, :func:`prepare` /
    ``geometry.representation_error``): off, or its cases, strain sd and, for a mesh, its own factor."""
    if not record:
        return "Representation-error floor: off"
    text = (f"Representation-error floor: on ({record.get('n_cases', '?')} SYNTHETIC cohort cases; strain sd RMS "
            f"{record.get('strain_sd_rms', float('nan')):.4f}")
    if record.get("projection_mse_cm2") is not None:
        text += (f"; ×{record.get('strain_scale', 1.0):.2f} of the cohort's mean strain covariance for this mesh's "
                 f"projection error {record['projection_mse_cm2']:.4f} cm² at the mean size")
        if record.get("beyond_cohort"):
            text += ", beyond every cohort case: the scaling is extrapolated"
    return text + ")"


def subject_emulator_geometry(emulator):
    """The geometry record of a subject-specific emulator (bound in), as ``lvcore calibrate --emulator DIR``
    records it: no PC scores, scale 1, the file it was built on."""
    from lvcore.inference import guards

    sub = emulator.metadata["subject"]
    return guards.GeometrySource(np.zeros(0), str(sub.get("geometry_source")), "subject-emulator",
                                 fit_residual_mm=(sub.get("geometry_record") or {}).get("fit_residual_mm"),
                                 warnings=tuple(sub.get("geometry_warnings") or ()))


# ----------------------------------------------------------------------------- no mesh: geometry inferred
#: The no-mesh route's geometric measures, as the page labels them (units in the name).
MEASURE_LABELS = {"reference_volume_ml": "Reference (early-diastolic) cavity volume, mL",
                  "wall_volume_ml": "Wall (myocardial) volume, mL (LV mass in g / 1.05)",
                  "long_axis_mm": "Long axis, base plane to epicardial apex, mm"}
#: The warning of a no-mesh run without any geometric measure (the CLI's, in the page's terms).
NO_MEASURE_WARNING = ("no geometric measure given: the subject's size is inferred from the LVV and strains alone, and "
                      "size and stiffness trade off (a larger reference cavity inflated less fits the same LVV as a "
                      "smaller one inflated more); measure the early-diastolic cavity volume and enter it as the "
                      "reference volume")


@dataclass(frozen=True)
class InferredGeometry:
    """The no-mesh route's geometry: PC scores and scale sampled with θ, informed by ``measures``.

    Attributes
    ----------
    measures : dict
        Measured ``reference_volume_ml``, ``wall_volume_ml`` (mL) and ``long_axis_mm`` (mm); any subset.
    measure_sd : dict
        Each measure's standard deviation (mL, mm; default
        :data:`lvcore.inference.geometry_prior.MEASURE_SD`).
    measure_sd_source : dict
        Where each sd came from: ``"default"``, ``"entered"`` (the page's field) or ``"data column <name>_sd"``.
    likelihood_sd : dict
        The sd the likelihood used: ``measure_sd`` widened by the shape model's representation error.
    representation_error : dict or None
        The representation-error floor's record (``mode`` "floor" and
        :meth:`lvcore.inference.representation_error.RepresentationError.record`), None without a floor.

    :meth:`of` builds it from :func:`prepare_inferred`'s result; :meth:`record`
    is ``lvcore calibrate --geometry infer``'s geometry record.
    """

    measures: dict
    kind: str = "inferred"
    source: str = "infer"
    measure_sd: dict | None = None
    measure_sd_source: dict | None = None
    likelihood_sd: dict | None = None
    representation_error: dict | None = None

    @classmethod
    def of(cls, prepared: "Prepared") -> "InferredGeometry":
        """The geometry record of an inferred :class:`Prepared` (its forward model's sds and floor)."""
        if not prepared.inferred:
            raise ValueError("not an inferred geometry: prepare it with prepare_inferred")
        fw = prepared.forward
        rep = getattr(fw, "representation", None)
        return cls(dict(prepared.measures), measure_sd=dict(fw.measure_sds),
                   measure_sd_source=dict(prepared.measure_sd_source or {}),
                   likelihood_sd=dict(fw.likelihood_sds),
                   representation_error=None if rep is None else {"mode": "floor", **rep.record()})

    def record(self) -> dict:
        """The CLI's geometry record of ``--geometry infer``."""
        from lvcore.inference.geometry_prior import MEASURE_SD

        sd = self.measure_sd if self.measure_sd is not None else {k: MEASURE_SD[k] for k in self.measures}
        return {"kind": self.kind, "source": self.source, "measures": dict(self.measures),
                "measure_sd": dict(sd),
                "measure_sd_source": {k: (self.measure_sd_source or {}).get(k, "default") for k in self.measures},
                "likelihood_sd": dict(self.likelihood_sd if self.likelihood_sd is not None else sd),
                "representation_error": self.representation_error}


def _entered_fields(entered: Mapping[str, float | None], ranges: Mapping[str, tuple], *, unknown, outside) -> dict:
    """Fields the user entered (0 or None: not given), each checked against its ``(lo, hi)`` range.

    ``unknown(name)`` and ``outside(name, value, lo, hi, unit)`` make the :class:`DataError` messages; the unit (mL
    or mm) is read from the field name's suffix.
    """
    import math

    given = {k: (None if v is None or float(v) == 0.0 else float(v)) for k, v in dict(entered).items()}
    for name, value in given.items():
        if name not in ranges:
            raise DataError(unknown(name))
        lo, hi = ranges[name]
        unit = {"ml": "mL", "mm": "mm"}[name.rsplit("_", 1)[-1]]
        if value is not None and not (math.isfinite(value) and lo <= value <= hi):
            raise DataError(outside(name, value, lo, hi, unit))
    return given


def inferred_measures(entered: Mapping[str, float | None], data_measures: Mapping[str, float] | None = None) -> dict:
    """The geometric measures of the no-mesh route: those entered (0 or None: not measured) and the data's columns.

    Validated as ``lvcore calibrate --reference-volume/--wall-volume/--long-axis``
    (:func:`lvcore.inference.geometry_prior.check_measures`).

    Raises
    ------
    lvcore.exceptions.DataError
        A measure outside its plausible range, or an entered measure that disagrees with the data's column,
        naming the field.
    """
    from lvcore.inference.geometry_prior import MEASURE_NAMES, MEASURE_RANGES, check_measures

    given = _entered_fields(
        entered, MEASURE_RANGES,
        unknown=lambda name: f"unknown geometric measure '{name}'; use {', '.join(MEASURE_NAMES)}",
        outside=lambda name, value, lo, hi, unit: (f"'{MEASURE_LABELS[name]}' = {value:g} is outside the plausible "
                                                   f"range {lo:g}-{hi:g} {unit}; enter it in {unit}, or 0 if not "
                                                   "measured"))
    out = check_measures(data_measures or {}, "the measurements file's geometric columns")
    for name, value in given.items():
        if value is None:
            continue
        if name in out and abs(out[name] - value) > 1e-9:
            raise DataError(f"'{MEASURE_LABELS.get(name, name)}' {value:g} and the measurements file's {name} "
                            f"{out[name]:g} disagree; enter 0 to use the file's value, or correct one of them")
        out[name] = value
    return out


def inferred_measure_sds(entered: Mapping[str, float | None], data_sds: Mapping[str, float] | None = None,
                         measures: Mapping[str, float] | None = None) -> tuple[dict, dict]:
    """The measures' standard deviations of the no-mesh route, as ``--reference-volume-sd`` etc. and the data's
    ``*_sd`` columns: those entered (0 or None: the default) and the data's, which must agree.

    Returns
    -------
    sds : dict
        Measure name -> sd (mL, mm), only those given (the rest take
        :data:`lvcore.inference.geometry_prior.MEASURE_SD`).
    sources : dict
        Measure name -> ``"entered"`` or ``"data column <name>_sd"``.

    Raises
    ------
    lvcore.exceptions.DataError
        An sd outside its range (naming the field and the range), an entered sd that disagrees with the data's
        column, or an sd for a measure that is not given.
    """
    from lvcore.inference.geometry_prior import MEASURE_SD_COLUMNS, MEASURE_SD_RANGES, check_measure_sds

    given = _entered_fields(
        entered, MEASURE_SD_RANGES, unknown=lambda name: f"unknown geometric measure '{name}'",
        outside=lambda name, value, lo, hi, unit: (f"SD of '{MEASURE_LABELS[name]}' = {value:g} is outside "
                                                   f"{lo:g}-{hi:g} {unit}; enter the measurement's standard "
                                                   f"deviation in {unit}, or 0 for the default"))
    out = check_measure_sds(data_sds or {}, "the measurements file's geometric columns", by="column")
    sources = {k: f"data column {MEASURE_SD_COLUMNS[k]}" for k in out}
    for name, value in given.items():
        if value is None:
            continue
        if name in out and abs(out[name] - value) > 1e-9:
            raise DataError(f"SD of '{MEASURE_LABELS[name]}' {value:g} and the measurements file's "
                            f"{MEASURE_SD_COLUMNS[name]} {out[name]:g} disagree; enter 0 to use the file's value")
        out[name], sources[name] = value, "entered"
    have = set(measures or {})
    for name in out:
        if name not in have:
            raise DataError(f"an SD is given for '{MEASURE_LABELS[name]}' ({sources[name]}) but not the measure "
                            "itself; enter the measure too, or drop the SD")
    return out, sources


def prepare_inferred(emulator, emulator_name: str, measures: Mapping[str, float], *,
                     edp_mmhg: float | None = None, measure_sd: Mapping[str, float] | None = None,
                     measure_sd_source: Mapping[str, str] | None = None,
                     representation_error: str = "floor") -> Prepared:
    """The forward model of the no-mesh route: ``lvcore calibrate --geometry infer`` for one subject.

    The emulator with the conditions bound in and its PC scores and a scale sampled with θ
    (:func:`lvcore.inference.geometry_prior.inferred_geometry_forward`), the measures observed with
    ``measure_sd`` (default :data:`lvcore.inference.geometry_prior.MEASURE_SD`; ``measure_sd_source`` says
    where each came from, :func:`inferred_measure_sds`); ``representation_error`` "floor" (the CLI's default)
    adds the shape model's representation error to the likelihood, "off" leaves it out; the conditions
    checked against the emulator's box; :data:`NO_MEASURE_WARNING` when no measure is given.

    Raises
    ------
    lvcore.exceptions.EmulatorError
        The emulator has no PC-score inputs (e.g. a subject-specific one), or cannot take the EDP asked for.
    """
    from lvcore.inference import geometry_prior, guards
    from lvcore.outputs import is_pc_name

    if getattr(emulator, "is_subject", False):
        from lvcore.exceptions import EmulatorError

        raise EmulatorError(f"the '{emulator_name}' emulator is subject-specific: its geometry is bound in, so there "
                            "is none to infer; choose a shape-model emulator (e.g. 'chapter') for the no-mesh route")
    if representation_error not in ("floor", "off"):
        raise ValueError(f"representation_error must be 'floor' or 'off', got {representation_error!r}")
    cond = _conditions(emulator, edp_mmhg)
    measures = geometry_prior.check_measures(measures)
    sds = geometry_prior.check_measure_sds(measure_sd or {})
    forward = geometry_prior.inferred_geometry_forward(emulator, name=emulator_name, measures=measures,
                                                       alpha_endo=cond["alpha_endo"], alpha_epi=cond["alpha_epi"],
                                                       edp_mmhg=cond["edp_mmhg"], measure_sd=sds,
                                                       representation="bundled" if representation_error == "floor"
                                                       else None)
    n_pc = len(forward.pc_names)
    fixed = {k: v for k, v in guards.fixed_inputs(np.zeros(n_pc), cond, emulator, False).items() if not is_pc_name(k)}
    box, extrapolation = guards.check_inputs_in_box(fixed, emulator, allow_extrapolation=True,
                                                    what="the conditions")
    warnings = list(extrapolation) + ([] if measures else [NO_MEASURE_WARNING])
    return Prepared(forward, emulator_name, cond, list(box), warnings, measures=dict(measures),
                    measure_sd_source={k: (measure_sd_source or {}).get(k, "entered") for k in sds})


def geometry_posterior(run: "ModelRun", prepared: Prepared) -> dict:
    """Posterior (median, 5 % and 95 % quantiles) of the PC scores, the scale and the implied measures of an
    inferred geometry, as ``lvcore calibrate --geometry infer`` writes it (summary.json's ``geometry.posterior``)."""
    from lvcore.inference.geometry_prior import geometry_posterior as posterior

    forward = prepared.forward
    return posterior({n: np.asarray(run.result.idata.posterior[n]) for n in forward.latent_names}, forward)


def geometry_posterior_rows(posterior: Mapping) -> list[dict]:
    """Table rows of :func:`geometry_posterior`: one per PC score, the scale and each implied measure."""
    units = {"scale": "–", "implied_reference_volume_ml": "mL", "implied_wall_volume_ml": "mL",
             "implied_long_axis_mm": "mm"}
    rows = []
    for name, q in posterior.items():
        if not isinstance(q, Mapping) or "median" not in q:
            continue
        measured = posterior.get("measured", {}).get(name.replace("implied_", ""))
        rows.append({"quantity": name.replace("implied_", "implied "), "unit": units.get(name, "SD"),
                     "median": q["median"], "5 %": q["q05"], "95 %": q["q95"],
                     "measured": measured})
    return rows


@dataclass(frozen=True)
class ModelRun:
    """One likelihood's calibration result and its verdict (:class:`lvcore.inference.verdict.Verdict`: the
    subject's consistency with the best-fitting model, shared by every likelihood, plus this run's
    identifiability and sampler flags), as ``lvcore calibrate`` reports them."""

    model: str
    result: Any
    check: Any


def calibrate(subject: str, y, prepared: Prepared, models: Sequence[str], *, config=None,
              sigma_v: float | None = None, progress: Callable[[str, float], None] | None = None,
              on_result: Callable[[ModelRun], None] | None = None) -> list[ModelRun]:
    """Calibrate each likelihood in ``models`` for one subject and give each result the CLI's verdict."""
    from lvcore.conditions import SIGMA_V_ML
    from lvcore.inference import calibrate as cal
    from lvcore.inference import verdict
    from lvcore.inference.samplers import SamplerConfig

    sigma_v = SIGMA_V_ML if sigma_v is None else float(sigma_v)
    y = np.asarray(y, float)
    consistency = verdict.consistency_check(y, prepared.forward, sigma_v)  # one per subject, whichever model runs
    bounds = verdict.checked_bounds(prepared.forward)
    runs: list[ModelRun] = []

    def finish(item):
        run = ModelRun(item.model, item.result, verdict.run_verdict(item.result, consistency, bounds, prepared.forward))
        runs.append(run)
        if on_result is not None:
            on_result(run)

    cal.calibrate_subjects([(subject, y, prepared.forward)], list(models), config=config or SamplerConfig(),
                           sigma_v=sigma_v, progress=progress, on_result=finish,
                           attrs={"emulator": prepared.emulator_name, "edp_mmhg": prepared.conditions["edp_mmhg"],
                                  "geometry": "infer" if prepared.inferred else "given"})
    return runs


def figures(runs: Sequence[ModelRun], y, truth: Mapping | None = None, prepared: Prepared | None = None) -> dict:
    """The run's figures by file stem: the posterior predictive of every likelihood and, per likelihood, the
    θ pair plot (the a–b trade-off), with the hidden truth of a SYNTHETIC subject when given; for an inferred
    geometry (``prepared.inferred``), per likelihood the posterior of the PC scores, the scale and the implied
    reference cavity against the measured one."""
    from lvcore.inference.models import MODEL_LABELS
    from lvcore.viz import inference_figures as figs

    out = {"posterior_predictive": figs.predictive_density_figure(
        {MODEL_LABELS[r.model]: r.result.idata for r in runs}, np.asarray(y, float))}
    for r in runs:
        out[f"{r.model}_pair"] = figs.pair_figure(r.result.idata, truth=truth)
        if prepared is not None and prepared.inferred:
            out[f"{r.model}_geometry"] = geometry_figure(r, prepared)
    return out


def implied_cavity_draws(run: ModelRun, prepared: Prepared, max_draws: int = 1000) -> np.ndarray:
    """Posterior draws (thinned to ``max_draws``) of the implied reference cavity ``s^3 V_cav(h)`` (mL) of an
    inferred geometry (:class:`lvcore.inference.geometry_prior.ShapeMeasures`, as the sampler's likelihood)."""
    import jax
    import jax.numpy as jnp

    forward = prepared.forward
    post = run.result.idata.posterior
    h = np.stack([np.asarray(post[n], float).reshape(-1) for n in forward.pc_names], axis=-1)
    s = np.asarray(post["scale"], float).reshape(-1)
    idx = np.linspace(0, h.shape[0] - 1, min(h.shape[0], max_draws)).astype(int)
    meas = jax.vmap(lambda hh, ss: forward.shape(hh, ss)["reference_volume_ml"])(jnp.asarray(h[idx]),
                                                                               jnp.asarray(s[idx]))
    return np.asarray(meas, float)


def geometry_figure(run: ModelRun, prepared: Prepared):
    """The posterior of an inferred geometry: PC scores within the emulator's box, the scale, and the implied
    reference cavity against the measured one (± its SD)."""
    from lvcore.inference.geometry_prior import MEASURE_SD, SCALE_NAME
    from lvcore.inference.models import MODEL_LABELS
    from lvcore.viz.inference_figures import geometry_posterior_figure

    forward = prepared.forward
    post = run.result.idata.posterior
    bounds = forward.latent_bounds
    box = bounds[forward.pc_names[0]] if forward.pc_names else None
    measured = prepared.measures.get("reference_volume_ml")
    return geometry_posterior_figure({n: np.asarray(post[n]) for n in forward.pc_names},
                                     np.asarray(post[SCALE_NAME]), implied_cavity_draws(run, prepared), box=box,
                                     measured_ml=measured,
                                     measured_sd_ml=MEASURE_SD["reference_volume_ml"] if measured else None,
                                     title=f"Inferred geometry (no mesh), {MODEL_LABELS[run.model]}")


def bound_flags(run: ModelRun, prepared: Prepared) -> list:
    """The verdict's identifiability flags of one run (posterior piled on a prior bound, intervals as wide as the
    prior; :func:`lvcore.inference.verdict.identifiability_flags`), as ``lvcore calibrate`` reports them."""
    from lvcore.inference import verdict

    post = run.result.idata.posterior
    bounds = verdict.checked_bounds(prepared.forward)
    return list(verdict.identifiability_flags({n: np.asarray(post[n]) for n in bounds if n in post}, bounds)[0])


def _geometry_record(geometry, prepared: Prepared) -> dict:
    """``lvcore calibrate``'s geometry record: a given geometry's (with its representation-error floor, or None)
    or an inferred one's (:meth:`InferredGeometry.record`)."""
    rec = geometry.record()
    if not prepared.inferred:
        rec["representation_error"] = prepared.representation_error
    return rec


def summary_record(subject: str, y, geometry, prepared: Prepared, runs: Sequence[ModelRun],
                   settings: Mapping) -> dict:
    """Plain-data summary of a subject's run: inputs used, geometry, conditions, per-likelihood results and flags."""
    from lvcore.inference.diagnostics import banner_status

    models = {}
    for run in runs:
        # the convergence alone (the flags are listed once, under "flags"); the app's banner adds them (banner_status)
        level, text = banner_status(run.result.convergence)
        table = run.result.summary
        models[run.model] = {
            "convergence": text, "converged_cleanly": level == "success",
            "plausible": bool(run.check.plausible), "flags": list(run.check.flags),
            "verdict": run.check.record(),
            "wall_s": float(run.result.wall_s),
            "posterior": {str(k): {c: float(table.loc[k, c]) for c in table.columns
                                   if np.issubdtype(type(table.loc[k, c]), np.number)} for k in table.index},
        }
        if prepared.inferred:
            models[run.model]["geometry_posterior"] = geometry_posterior(run, prepared)
    flagged = [m for m, r in models.items() if r["flags"] or not r["converged_cleanly"]]
    return {
        "subject": subject, "synthetic": str(subject).upper().startswith("SYNTHETIC"),
        "measured": {"lvv_ml": float(y[0]), "strains": [float(v) for v in np.asarray(y)[1:]]},
        "geometry": _geometry_record(geometry, prepared), "emulator": prepared.emulator_name,
        "conditions": {k: v for k, v in prepared.conditions.items() if k != "fixed"},
        "box": prepared.box, "warnings": list(prepared.warnings), "settings": dict(settings),
        "models": models, "flagged_models": flagged,
    }


def summary_html(summary: Mapping) -> str:
    """A one-page HTML summary of :func:`summary_record` (inputs, conditions, posterior table, flags)."""
    esc = html.escape
    rows = []
    for model, rec in summary["models"].items():
        for name, stats in rec["posterior"].items():
            cells = "".join(f"<td>{v:.4g}</td>" for v in stats.values())
            rows.append(f"<tr><td>{esc(model)}</td><td>{esc(name)}</td>{cells}</tr>")
    first = next(iter(summary["models"].values()), {"posterior": {}})
    columns = next(iter(first["posterior"].values()), {})
    from lvcore.app.tables import SUMMARY_COLUMNS  # q05/q95: "q05 (90 % equal-tailed interval)", as in the app

    head = "".join(f"<th>{esc(SUMMARY_COLUMNS.get(c, (c,))[0])}</th>" for c in columns)
    flags = [f"<li><b>{esc(m)}</b>: {esc(f)}</li>" for m, r in summary["models"].items() for f in r["flags"]]
    flags += [f"<li>{esc(w)}</li>" for w in summary["warnings"]]
    conv = "".join(f"<li><b>{esc(m)}</b>: {esc(r['convergence'])}</li>" for m, r in summary["models"].items())
    geo = summary["geometry"]
    cond = summary["conditions"]
    if geo["kind"] == "inferred":
        given = ", ".join(f"{k} {v:g}" for k, v in geo["measures"].items()) or "none (size and stiffness trade off)"
        geo_rows = []
        for model, rec in summary["models"].items():
            for row in geometry_posterior_rows(rec.get("geometry_posterior", {})):
                geo_rows.append(f"<tr><td>{esc(model)}</td><td>{esc(row['quantity'])} ({esc(row['unit'])})</td>"
                                f"<td>{row['median']:.4g}</td><td>{row['5 %']:.4g}</td><td>{row['95 %']:.4g}</td>"
                                f"<td>{'' if row['measured'] is None else format(row['measured'], '.4g')}</td></tr>")
        geometry_text = (f"<p>Geometry: inferred (no mesh): PC scores h and scale s sampled with &theta; "
                         f"(lvcore calibrate --geometry infer); geometric measures given: {esc(given)}.</p>"
                         "<table><tr><th>likelihood</th><th>quantity</th><th>median</th><th>q05 (90 % equal-tailed "
                         "interval)</th><th>q95 (90 % equal-tailed interval)</th>"
                         f"<th>measured</th></tr>{''.join(geo_rows)}</table>")
    elif geo["kind"] == "subject-emulator":
        geometry_text = (f"<p>Geometry: bound into the subject-specific emulator, built on "
                         f"{esc(Path(str(geo['source'])).name)} as it is (no PC projection).</p>")
    else:
        geometry_text = (f"<p>Geometry: {esc(geo['kind'])} from {esc(Path(str(geo['source'])).name)}; PC scores "
                         f"{esc(', '.join(f'{v:.2f}' for v in geo['scores']))}; scale s = {geo['scale']:.3f} "
                         "(emulated LVV &times; s&sup3;).</p>")
    label = " (SYNTHETIC data: generated, not a real subject)" if summary["synthetic"] else ""
    from lvcore.app.freshness import readable  # yes/no, – and none: never null/None/{} (settings.json keeps JSON)

    settings_rows = "".join(f"<tr><td>{esc(str(k))}</td><td>{esc(readable(v))}</td></tr>"
                            for k, v in summary["settings"].items())
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>{esc(summary['subject'])}: calibration</title>
<style>body{{font-family:sans-serif;max-width:60em;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #bbb;padding:2px 6px;text-align:right}}td:first-child,td:nth-child(2){{text-align:left}}</style>
</head><body><h1>Calibration of {esc(summary['subject'])}{esc(label)}</h1>
<p>Measured LVV {summary['measured']['lvv_ml']:.1f} mL; strains {min(summary['measured']['strains']):.3f} to
{max(summary['measured']['strains']):.3f}.</p>
{geometry_text}
<p>Emulator {esc(summary['emulator'])}; EDP {cond['edp_mmhg']:.2f} mmHg; fibre angles
{cond['alpha_endo']:.0f}&deg; / {cond['alpha_epi']:.0f}&deg;.</p>
<h2>Verdict</h2><p>{'Flagged: ' + esc(', '.join(summary['flagged_models'])) if summary['flagged_models']
                      else 'No flags: every likelihood converged and the data look plausible for it.'}</p>
<ul>{''.join(flags) or '<li>no warnings</li>'}</ul>
<h2>Convergence</h2><ul>{conv}</ul>
<h2>Posterior</h2><table><tr><th>likelihood</th><th>parameter</th>{head}</tr>{''.join(rows)}</table>
<h2>Settings</h2><table>{settings_rows}</table>
</body></html>"""


def bundle(summary: Mapping, runs: Sequence[ModelRun], figures: Mapping[str, Any]) -> bytes:
    """The subject's download: a zip with ``<stem>_<model>.nc``, ``figures/<name>.html``,
    ``settings.json``, ``summary.json`` and ``summary.html``."""
    from lvcore.inference.calibrate import file_stem

    stem = file_stem(str(summary["subject"]))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z, tempfile.TemporaryDirectory() as tmp:
        for run in runs:
            nc = Path(tmp) / f"{stem}_{run.model}.nc"
            run.result.idata.to_netcdf(str(nc))
            z.write(nc, nc.name)
        for name, fig in figures.items():
            z.writestr(f"figures/{name}.html", fig.to_html(include_plotlyjs=True, full_html=True))
        z.writestr("settings.json", json.dumps(summary["settings"], indent=1))
        z.writestr("summary.json", json.dumps(summary, indent=1, default=_plain))
        z.writestr("summary.html", summary_html(summary))
    return buf.getvalue()


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise DataError(f"cannot write {type(value).__name__} to summary.json")


# ----------------------------------------------------------------------------- a subject-specific emulator
#: Where the app keeps the subject emulators it builds (one folder per geometry, design and seed; a rebuild of
#: the same is found there, and a stopped or failed build resumes from the FE runs it kept).
BUILD_CACHE = Path(tempfile.gettempdir()) / "lvcore_subject_emulators"
#: Held-out accuracy targets of a subject emulator (issue 25): LVV RMSE (mL) and strain RMSE.
HELD_OUT_TARGETS = {"lvv_rmse_ml": 1.0, "strain_rmse": 0.003}


def build_dir(geometry_bytes: bytes, stem: str, *, units: str = "mm", design=None, seed: int = 0,
              resolution: str = "default", root: Path | None = None) -> Path:
    """The cache folder of a subject emulator: named by the geometry file's stem and a digest of its contents,
    units, design, seed and mesh, so the same request finds the same folder."""
    from lvcore.emulator.subject import SubjectDesign
    from lvcore.uploads import safe_name

    design = design or SubjectDesign()
    key = json.dumps({"units": units, "design": [design.n_train, design.n_valid, design.n_test, design.method],
                      "seed": int(seed), "resolution": resolution}, sort_keys=True).encode()
    digest = hashlib.sha256(bytes(geometry_bytes) + b"\0" + key).hexdigest()[:16]
    return Path(root or BUILD_CACHE) / f"{safe_name(Path(stem).stem, 'geometry')}-{digest}"


def held_out_summary(metadata: Mapping) -> dict:
    """The held-out test accuracy of a subject emulator (``metadata["test"]``: FE runs the training never saw),
    the run counts and wall time, and whether the accuracy meets :data:`HELD_OUT_TARGETS`."""
    from lvcore.emulator.subject import describe_prior

    test = dict(metadata.get("test") or {})
    sub = dict(metadata.get("subject") or {})
    runs, secs = dict(sub.get("runs") or {}), dict(sub.get("seconds") or {})
    return {"n_test": test.get("n"), "lvv_rmse_ml": test.get("lvv_rmse_ml"), "strain_rmse": test.get("strain_rmse"),
            "runs_converged": runs.get("converged"), "runs_total": runs.get("total"), "wall_s": secs.get("total"),
            "geometry_source": sub.get("geometry_source"), "prior": describe_prior(sub.get("prior")),
            "within_targets": bool(test) and all(float(test[k]) <= v for k, v in HELD_OUT_TARGETS.items())}


class SubjectBuild:
    """One subject-emulator build, ``lvcore emulator build --geometry FILE --out DIR``, for the app.

    :meth:`start` runs :func:`lvcore.emulator.subject.build_subject_emulator` in a background thread (or finds a
    finished build in ``out``); the page polls :attr:`fraction`, :attr:`lines` and :attr:`finished`. A failed or
    stopped build sets :attr:`error`, a message saying what to do; the FE runs done are kept in ``out`` and the
    next build of the same design resumes from them.

    Parameters
    ----------
    geometry_file : path
        The geometry as the CLI's ``--geometry`` takes it (a volume or template mesh, contours, PC scores).
    out : path
        The emulator folder (:func:`build_dir`).
    design : lvcore.emulator.subject.SubjectDesign, optional
        Run counts; default the CLI's (``SubjectDesign()``: 512 + 50 + 100).
    units : str
        Units of a volume mesh.
    workers, seed, resolution
        As the CLI's ``--workers`` (2), ``--seed`` (0) and ``--resolution`` (``default``).
    label : str, optional
        The user's name of the geometry (messages).
    """

    def __init__(self, geometry_file, out, *, design=None, units: str = "mm", workers: int = 2, seed: int = 0,
                 resolution: str = "default", label: str | None = None):
        from lvcore.emulator.subject import SubjectDesign

        self.geometry_file = Path(geometry_file)
        self.out = Path(out)
        self.design = design or SubjectDesign()
        self.units, self.workers, self.seed, self.resolution = units, int(workers), int(seed), resolution
        self.label = label or self.geometry_file.name
        self.lines: list[str] = []
        self.done_runs = 0
        self.error: str | None = None
        self.metadata: dict | None = None
        self.finished = False
        self.cached = False
        self.t0 = time.perf_counter()
        self.elapsed: float | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # --- state the page reads ------------------------------------------------
    @property
    def total_runs(self) -> int:
        return int(self.design.total)

    @property
    def running(self) -> bool:
        return not self.finished

    @property
    def ok(self) -> bool:
        return self.finished and self.error is None and self.metadata is not None

    @property
    def fraction(self) -> float:
        """Progress in [0, 1]: the FE runs are 90 %, the training the rest."""
        if self.finished:
            return 1.0
        return 0.9 * min(1.0, self.done_runs / max(1, self.total_runs))

    def status(self) -> str:
        """One line: what the build is doing now."""
        t = (self.elapsed if self.elapsed is not None else time.perf_counter() - self.t0)
        if self.finished:
            return f"{'found in the cache' if self.cached else 'built'} in {t:.0f} s" if self.ok else "failed"
        if self.done_runs < self.total_runs:
            return f"FE runs {self.done_runs} of {self.total_runs} ({t:.0f} s)"
        return f"training the network on the converged runs ({t:.0f} s)"

    # --- running -------------------------------------------------------------
    def start(self, background: bool = True) -> "SubjectBuild":
        """Start the build (in a daemon thread unless ``background`` is False); a finished build in ``out`` is
        loaded instead."""
        if (self.out / "metadata.json").is_file() and (self.out / "network.npz").is_file():
            try:
                from lvcore.emulator.io import load_emulator

                self.metadata = dict(load_emulator(self.out).metadata)
                self.cached = True
                self._finish()
                return self
            except LVCoreError:
                pass  # damaged: build again
        if background:
            self._thread = threading.Thread(target=self.run, name=f"subject-emulator {self.label}", daemon=True)
            self._thread.start()
        else:
            self.run()
        return self

    def stop(self) -> None:
        """Ask the build to stop before its next batch of FE runs (the runs done are kept)."""
        self._stop.set()

    def join(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def run(self) -> None:
        """The build itself (what the thread runs)."""
        from lvcore.emulator.subject import build_subject_emulator

        try:
            emu = build_subject_emulator(self.geometry_file, self.out, design=self.design, units=self.units,
                                         workers=self.workers, seed=self.seed, resolution=self.resolution,
                                         log=self.lines.append, progress=self._progress, stop=self._stop.is_set)
            self.metadata = dict(emu.metadata)
        except (LVCoreError, ValueError) as err:
            self.error = self._failure(str(err))
        except Exception as err:  # noqa: BLE001 - a dead worker or the like: shown to the user, never a traceback
            self.error = self._failure(f"{type(err).__name__}: {err}")
        finally:
            self._finish()

    def _progress(self, done: int, total: int) -> None:
        self.done_runs = int(done)

    def _finish(self) -> None:
        self.elapsed = time.perf_counter() - self.t0
        self.finished = True

    def _failure(self, reason: str) -> str:
        from lvcore.emulator.subject import RUNS_FILE

        kept = (f"The {self.done_runs} FE runs done are kept ({self.out / RUNS_FILE}); build again with the same "
                "geometry, design size and seed to resume from them") if self.done_runs else "No FE run was finished"
        d = self.design
        return (f"The subject emulator for {self.label} was not built: {reason}. {kept}. If it fails again, run it "
                f"in a terminal, where it reports every stage: lvcore emulator build --geometry {self.label} "
                f"--units {self.units} --n-train {d.n_train} --n-valid {d.n_valid} --n-test {d.n_test} "
                f"--out {self.out}")


def template_mesh_file(session, nodes, label: str) -> Path:
    """Write fitted template nodes (mm) as a template mesh in the session's upload folder, the file
    ``lvcore emulator build --geometry`` takes (the Geometry page's fitted segmentations)."""
    from lvcore.geometry.io import write_template_mesh
    from lvcore.uploads import safe_name

    path = Path(session.path) / f"fitted_{safe_name(label, 'geometry')}.vtu"
    write_template_mesh(path, np.asarray(nodes, float), metadata={"label": f"fitted geometry {label}"})
    return path
