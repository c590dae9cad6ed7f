"""One calibration request: the whole set-up of a calibration, built once for every front end.

``lvcore calibrate`` (:mod:`lvcore.inference.cli`), the app's Calibration page and
its My subject flow (:mod:`lvcore.app.subject_flow`) gather their inputs in their
own terms (options, widgets, uploads) and hand them to :func:`build_request`,
which does everything that comes between the inputs and the sampler:

0. **the strain layer**: the data's wall layer (declared by the file or the front end) must be the emulator's
   (:func:`lvcore.inference.strain_layers.check_strain_layer`);
1. **conditions**: the EDP and fibre angles the emulator can honour
   (:func:`lvcore.inference.guards.check_conditions`), the subject's own EDP from
   the data (:func:`lvcore.inference.guards.subject_edp`), and for a subject with
   several loaded states or the Klotz prior an emulator that takes the EDP;
2. **geometry**: given PC scores and scale (a scores file, a template or volume
   mesh, the mean shape), the geometry bound into a subject-specific emulator, or
   ``"infer"`` (PC scores and scale sampled with θ from the geometric measures,
   :mod:`lvcore.inference.geometry_prior`);
3. **the box check**: the PC scores and conditions against the emulator's
   training box, an error naming what to fix unless extrapolation is allowed
   (then an ``EXTRAPOLATION:`` warning);
4. **the forward model**: the emulator with geometry and conditions bound in and
   the emulated LVV scaled by ``s³`` (:class:`lvcore.geometry.scaling.ScaledForward`);
5. **the representation floor**: the shape model's representation error added to
   the likelihood of a mesh or an inferred geometry
   (:mod:`lvcore.inference.representation_error`);
6. **the verdict's inputs**: the measured ``y``, the noise ``sigma_v`` (mL) and
   the reference strain noise ``sigma_ref`` of the fit check, and the prior
   bounds whose identifiability is checked (:mod:`lvcore.inference.verdict`).

A bad input raises one :class:`~lvcore.exceptions.LVCoreError` whose message
names what to fix; the same message in all three front ends (the CLI exits 2).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER
from lvcore.exceptions import DataError, EmulatorError
from lvcore.inference.plausibility import DEFAULT_SIGMA_REF

#: The ``geometry`` of :func:`build_request` that samples the PC scores and scale with θ (``--geometry infer``).
INFER = "infer"
#: Prefix of the box check's warnings (:func:`lvcore.inference.guards.check_inputs_in_box`).
EXTRAPOLATION = "EXTRAPOLATION: "


@dataclass(frozen=True)
class CalibrationRequest:
    """Everything a calibration of one subject needs before sampling (:func:`build_request`).

    Attributes
    ----------
    forward : Forward
        The emulator with the geometry and conditions bound in, emulated LVV × ``s³``, with the representation
        floor (:class:`lvcore.inference.representation_error.FlooredForward`) or an inferred geometry
        (:class:`lvcore.inference.geometry_prior.InferredGeometryForward`), and further loaded states or the Klotz
        prior (:class:`lvcore.inference.loaded_states.LoadedStatesForward`) when asked for.
    emulator_name : str
    conditions : dict
        ``edp_mmhg`` (mmHg), ``alpha_endo`` and ``alpha_epi`` (degrees) bound in, and ``fixed``: the names the
        emulator holds fixed.
    box : list of dict
        Each fixed input against the emulator's training range (``name``, ``value``, ``lower``, ``upper``,
        ``inside``).
    warnings : list of str
        The geometry's warnings, the no-measure warning of an inferred geometry, and the ``EXTRAPOLATION:``
        warnings of the box check.
    measures : dict or None
        The geometric measures of an inferred geometry (mL, mm); None for a given one.
    measure_sd_source : dict or None
        Where each measure's sd came from (only those given; the others are ``"default"``).
    representation_error : dict or None
        The representation floor's record of a given mesh (``mode`` "floor", ...); None without one (an
        inferred geometry's floor is in :attr:`geometry_record`).
    subject : str or None
        The subject's id; None when no measured row was given.
    y : ndarray, shape (25,), or None
        Measured ``[LVV (mL), 24 strains]`` of the primary loaded state.
    geometry : lvcore.inference.guards.GeometrySource or None
        The given (or bound-in) geometry; None when it is inferred.
    geometry_record : dict
        ``lvcore calibrate``'s ``geometry`` record (summary.json).
    edp_source : str
        Where the EDP came from (:func:`lvcore.inference.guards.edp_source`).
    infer_angles : bool
        The fibre angles are sampled with θ.
    allow_extrapolation : bool
        Inputs outside the training box are warnings, not errors.
    base : str
        The emulator's base condition (``clamped`` or ``sliding``).
    resolution : str
        The mesh resolution the emulator was trained on.
    strain_layer : str
        The wall layer of the strains, the emulator's and the data's (:mod:`lvcore.inference.strain_layers`).
    sigma_v : float
        LVV noise sd (mL) of the likelihood and the verdict.
    sigma_ref : float
        Reference strain noise sd of the verdict's fit check (default
        :data:`lvcore.inference.plausibility.DEFAULT_SIGMA_REF`).
    """

    forward: Any
    emulator_name: str
    conditions: dict
    box: list
    warnings: list = field(default_factory=list)
    measures: dict | None = None
    measure_sd_source: dict | None = None
    representation_error: dict | None = None
    subject: str | None = None
    y: np.ndarray | None = None
    geometry: Any = None
    geometry_record: dict = field(default_factory=dict)
    edp_source: str = "emulator default"
    infer_angles: bool = False
    allow_extrapolation: bool = False
    base: str = "clamped"
    resolution: str = "default"
    strain_layer: str = DEFAULT_STRAIN_LAYER
    sigma_v: float = SIGMA_V_ML
    sigma_ref: float = DEFAULT_SIGMA_REF

    @property
    def extrapolating(self) -> bool:
        """Some fixed input lies outside the emulator's training box."""
        return any(not row.get("inside", True) for row in self.box)

    @property
    def inferred(self) -> bool:
        """The geometry (PC scores and scale) is sampled with θ (``--geometry infer``)."""
        return self.measures is not None

    @property
    def extrapolation(self) -> list:
        """The box check's ``EXTRAPOLATION:`` warnings."""
        return [w for w in self.warnings if w.startswith(EXTRAPOLATION)]

    @property
    def bounds(self) -> dict:
        """Prior bounds whose identifiability the verdict checks (:func:`lvcore.inference.verdict.checked_bounds`)."""
        from lvcore.inference.verdict import checked_bounds

        return checked_bounds(self.forward, self.infer_angles)

    def consistency(self, y=None, seed: int = 0):
        """The verdict's fit check of the measured data (:func:`lvcore.inference.verdict.consistency_check`),
        one per subject whichever likelihood runs; ``y`` defaults to :attr:`y`."""
        from lvcore.inference.verdict import consistency_check

        data = self.y if y is None else y
        if data is None:
            raise DataError("no measurements: give the subject's LVV and 24 strains before the fit check")
        return consistency_check(np.asarray(data, float), self.forward, self.sigma_v, self.sigma_ref,
                                 infer_angles=self.infer_angles, seed=seed)

    def record(self) -> dict:
        """Plain data of everything but the forward model (compare two requests; log one)."""
        return {"subject": self.subject, "y": None if self.y is None else [float(v) for v in self.y],
                "emulator": self.emulator_name, "conditions": dict(self.conditions), "edp_source": self.edp_source,
                "box": [dict(b) for b in self.box], "warnings": list(self.warnings),
                "geometry": dict(self.geometry_record), "infer_angles": self.infer_angles,
                "allow_extrapolation": self.allow_extrapolation, "base": self.base, "resolution": self.resolution,
                "strain_layer": self.strain_layer,
                "sigma_v": float(self.sigma_v), "sigma_ref": float(self.sigma_ref),
                "forward": getattr(self.forward, "label", type(self.forward).__name__)}


def subject_geometry(emulator):
    """The geometry bound into a subject-specific emulator (``lvcore emulator build``): no PC scores, scale 1, the
    file it was built on, with the warnings of its fit."""
    from lvcore.inference.guards import GeometrySource

    sub = emulator.metadata["subject"]
    return GeometrySource(np.zeros(0), str(sub.get("geometry_source")), "subject-emulator",
                          fit_residual_mm=(sub.get("geometry_record") or {}).get("fit_residual_mm"),
                          warnings=tuple(sub.get("geometry_warnings") or ()))


@dataclass(frozen=True)
class _Setup:
    """The geometry-dependent part of a request: the forward model and box check at any EDP."""

    forward_at: Callable      # EDP (mmHg) -> (forward, representation record or None)
    box_at: Callable          # EDP (mmHg) -> (box report, extrapolation warnings)
    geometry: Any
    record: Callable          # forward, floor -> geometry record
    warnings: tuple = ()
    measures: dict | None = None
    measure_sd_source: dict | None = None


def build_request(emulator, emulator_name: str, geometry=None, *, row=None, edp_mmhg: float | None = None,
                  alpha_endo: float | None = None, alpha_epi: float | None = None, infer_angles: bool = False,
                  allow_extrapolation: bool = False, representation_error: str = "floor",
                  measures: Mapping[str, float] | None = None, measure_sd: Mapping[str, float] | None = None,
                  measure_sd_source: Mapping[str, str] | None = None, prior: str = "none",
                  geometry_label: str = "the geometry", no_measure_warning: str | None = None,
                  representation=None, sigma_v: float = SIGMA_V_ML,
                  sigma_ref: float | None = None, strain_layer: str | None = None) -> CalibrationRequest:
    """The calibration set-up of one subject (module docstring): conditions, geometry, box check, forward model,
    representation floor and the verdict's inputs.

    Parameters
    ----------
    emulator : lvcore.emulator.Emulator
        The loaded emulator.
    emulator_name : str
        Its name or folder, as the user chose it (messages and records).
    geometry : GeometrySource, "infer" or None
        The subject's geometry (:func:`lvcore.inference.guards.resolve_geometry`), :data:`INFER` to sample it
        with θ, or None with a subject-specific emulator (its geometry is bound in; a given one is not used).
    row : lvcore.inference.data.MeasuredData, optional
        The subject's measurements: its ``edp_mmhg`` column and loaded states are honoured.
    edp_mmhg, alpha_endo, alpha_epi : float, optional
        Conditions asked for (mmHg, degrees); None: the data's or the emulator's.
    infer_angles : bool
        Sample the fibre angles with θ (an emulator with angle inputs).
    allow_extrapolation : bool
        Inputs outside the training box become ``EXTRAPOLATION:`` warnings instead of an error.
    representation_error : {"floor", "off"}
        The shape model's representation error in the likelihood of a mesh or an inferred geometry.
    measures, measure_sd, measure_sd_source : mapping, optional
        An inferred geometry's measures (mL, mm), their sds and where each sd came from.
    prior : {"none", "klotz"}
        ``"klotz"``: the Klotz et al. (2006) EDPVR as a likelihood term.
    geometry_label : str
        How the user gave the geometry (the box check's error names it).
    no_measure_warning : str, optional
        The warning of an inferred geometry without measures, in the front end's words (default the CLI's).
    representation : RepresentationError, optional
        The floor to use (default the bundled one of the emulator's number of modes).
    sigma_v : float
        LVV noise sd (mL).
    sigma_ref : float, optional
        Reference strain noise sd of the verdict's fit check (default
        :data:`lvcore.inference.plausibility.DEFAULT_SIGMA_REF`).
    strain_layer : str, optional
        The wall layer of the measured strains (``--strain-layer``); default: the layer ``row`` declares, else the
        emulator's own (:func:`lvcore.inference.strain_layers.check_strain_layer`).

    Returns
    -------
    CalibrationRequest

    Raises
    ------
    lvcore.exceptions.DataError
        Conditions or data the emulator cannot take (an EDP outside 2-40 mmHg, loaded states without an EDP input,
        no geometry, strains of another wall layer than the emulator's), naming what to fix.
    lvcore.exceptions.EmulatorError
        Conditions the emulator was trained at fixed values of, or inputs outside its training box without
        ``allow_extrapolation``.

    Examples
    --------
    The bundled 'chapter' emulator at the mean shape (PC scores 0, scale 1): its own EDP and angles, no floor
    (a mesh would get one), and a refusal naming what to fix outside its box:

    >>> import numpy as np
    >>> from lvcore.emulator.io import load_emulator
    >>> from lvcore.inference.guards import GeometrySource
    >>> emulator = load_emulator("chapter")
    >>> request = build_request(emulator, "chapter", GeometrySource(np.zeros(5), "mean", "mean"))
    >>> request.conditions["edp_mmhg"], request.edp_source, request.representation_error
    (8.0, 'fixed by the emulator', None)
    >>> from lvcore.domain.conditions import THETA_TILDE
    >>> request.forward(THETA_TILDE).shape   # LVV (mL) and 24 strains at the chapter's θ̃
    (25,)
    >>> build_request(emulator, "chapter", GeometrySource(np.array([2.5, 0, 0, 0, 0]), "h.json", "scores"),
    ...               geometry_label="--geometry h.json")
    Traceback (most recent call last):
    ...
    lvcore.exceptions.EmulatorError: --geometry h.json: the PC scores (or conditions) outside ... h1 = 2.5 (trained on [-2, 2])...
    """
    from lvcore.inference import guards
    from lvcore.inference.strain_layers import check_strain_layer

    layer = check_strain_layer(emulator, emulator_name, getattr(row, "strain_layer", None), strain_layer,
                               where="the data" if row is None else f"subject {row.subject}")
    bound, inferred = _geometry_route(emulator, emulator_name, geometry, representation_error)
    cond = guards.check_conditions(emulator, edp_mmhg, alpha_endo, alpha_epi, infer_angles=infer_angles)
    _check_states(emulator, emulator_name, row, prior)
    if row is not None:
        cond = {**cond, "edp_mmhg": guards.subject_edp(row, cond, emulator, emulator_name, edp_mmhg)}
    args = dict(emulator=emulator, name=emulator_name, cond=cond, infer=infer_angles, allow=allow_extrapolation,
                representation_error=representation_error, representation=representation)
    if inferred:
        setup = _inferred_setup(**args, measures=measures, measure_sd=measure_sd, sources=measure_sd_source,
                                what="the conditions" if row is None else f"subject {row.subject}: the conditions",
                                no_measure_warning=no_measure_warning)
    else:
        setup = _given_setup(**args, geometry=subject_geometry(emulator) if bound else geometry,
                             what=f"{geometry_label}: the PC scores (or conditions)")
    box, extrapolation = setup.box_at(cond["edp_mmhg"])
    forward, floor = setup.forward_at(cond["edp_mmhg"])
    georec = setup.record(forward, floor)
    if row is not None and (row.states or prior == "klotz"):
        forward, more = _with_states(emulator, row, prior, setup, forward, cond["edp_mmhg"], inferred=inferred,
                                     bound=bound)
        extrapolation = extrapolation + [x for x in more if x not in extrapolation]
    return CalibrationRequest(
        forward, emulator_name, cond, list(box), list(setup.warnings) + list(extrapolation),
        measures=setup.measures, measure_sd_source=setup.measure_sd_source, representation_error=floor,
        subject=None if row is None else str(row.subject), y=None if row is None else np.asarray(row.y, float),
        geometry=setup.geometry, geometry_record=georec, edp_source=_edp_source(row, edp_mmhg, emulator),
        infer_angles=bool(infer_angles), allow_extrapolation=bool(allow_extrapolation),
        base=str(getattr(emulator, "base", "clamped")), resolution=str(getattr(emulator, "resolution", "default")),
        strain_layer=layer, sigma_v=float(sigma_v), sigma_ref=DEFAULT_SIGMA_REF if sigma_ref is None else float(sigma_ref))


def _geometry_route(emulator, name: str, geometry, representation_error: str) -> tuple[bool, bool]:
    """``(bound, inferred)``: the geometry is bound into a subject-specific emulator, or sampled with θ; a route
    the emulator cannot take, no geometry at all, or an unknown floor mode is refused."""
    if representation_error not in ("floor", "off"):
        raise ValueError(f"representation_error must be 'floor' or 'off', got {representation_error!r}")
    bound = bool(getattr(emulator, "is_subject", False))
    inferred = isinstance(geometry, str) and geometry.strip().lower() == INFER
    if bound and inferred:
        raise EmulatorError(f"the '{name}' emulator is subject-specific: its geometry is bound in, so there is none "
                            "to infer; choose a shape-model emulator (e.g. 'chapter') for the no-mesh route")
    if not (bound or inferred) and geometry is None:
        raise DataError("no geometry: give the subject's mesh or PC scores ('mean' for the mean shape, knowingly), "
                        "or infer it from the geometric measures")
    return bound, inferred


def _edp_source(row, edp_mmhg, emulator) -> str:
    """Where the EDP came from (:func:`lvcore.inference.guards.edp_source`; without data: no ``edp_mmhg`` column)."""
    from types import SimpleNamespace

    from lvcore.inference.guards import edp_source

    return edp_source(SimpleNamespace(edp_mmhg=None) if row is None else row, edp_mmhg, emulator)


def _check_states(emulator, name: str, row, prior: str) -> None:
    """Loaded states and the Klotz prior need an emulator that takes the EDP (and covers the prior's pressures)."""
    from lvcore.inference import loaded_states as ls

    if prior not in ls.PRIOR_NAMES:
        raise DataError(f"prior {prior!r}: choose from {', '.join(ls.PRIOR_NAMES)}")
    if row is not None and row.states:
        where = row.source and Path(row.source).name or "the data"
        ls.check_edp_input(emulator, name, f"{where}: subject '{row.subject}' has {row.n_states} loaded states, which")
    if prior == "klotz":
        ls.check_klotz_pressures(emulator, name)


def _given_setup(*, emulator, name, cond, infer, allow, representation_error, representation, geometry,
                 what) -> _Setup:
    """A given geometry (scores, a mesh, the mean shape, or a subject emulator's own): the emulator at its PC
    scores and scale; a mesh, seen through its projection, gets the representation floor scaled to its own
    projection error (:func:`lvcore.inference.representation_error.given_geometry_floor`)."""
    from lvcore.emulator.forward import emulator_forward
    from lvcore.geometry.scaling import ScaledForward
    from lvcore.inference import guards
    from lvcore.inference.representation_error import given_geometry_floor
    from lvcore.domain.outputs import is_pc_name

    n_pc = sum(1 for n in emulator.input_names if is_pc_name(n))
    h, scale = np.asarray(geometry.h, float), float(geometry.scale)

    def box_at(p):
        return guards.check_inputs_in_box(guards.fixed_inputs(h, {**cond, "edp_mmhg": p}, emulator, infer),
                                          emulator, allow, what=what)

    def forward_at(p):
        fw = ScaledForward(emulator_forward(emulator, h, name=name, infer_angles=infer, alpha_endo=cond["alpha_endo"],
                                            alpha_epi=cond["alpha_epi"], edp_mmhg=p), scale)
        return given_geometry_floor(fw, geometry.kind, representation_error, n_pc, representation=representation,
                                    projection_mse_cm2=getattr(geometry, "projection_mse_cm2", None))

    return _Setup(forward_at, box_at, geometry, lambda fw, floor: {**geometry.record(), "representation_error": floor},
                  warnings=tuple(geometry.warnings))


def _inferred_setup(*, emulator, name, cond, infer, allow, representation_error, representation, measures,
                    measure_sd, sources, what, no_measure_warning) -> _Setup:
    """An inferred geometry: PC scores and scale sampled with θ, observed through the measures
    (:func:`lvcore.inference.geometry_prior.inferred_geometry_forward`); the conditions box-checked."""
    from lvcore.inference import geometry_prior, guards
    from lvcore.domain.outputs import is_pc_name

    n_pc = sum(1 for n in emulator.input_names if is_pc_name(n))
    measures = geometry_prior.check_measures(measures or {})
    sds = geometry_prior.check_measure_sds(measure_sd or {})
    rep = None
    if representation_error == "floor":
        from lvcore.inference.representation_error import load_representation_error

        rep = representation if representation is not None else load_representation_error(n_pc)

    def box_at(p):
        fixed = {k: v for k, v in guards.fixed_inputs(np.zeros(n_pc), {**cond, "edp_mmhg": p}, emulator,
                                                       infer).items() if not is_pc_name(k)}
        return guards.check_inputs_in_box(fixed, emulator, allow, what=what)

    def forward_at(p):
        return geometry_prior.inferred_geometry_forward(
            emulator, name=name, measures=measures, infer_angles=infer, alpha_endo=cond["alpha_endo"],
            alpha_epi=cond["alpha_epi"], edp_mmhg=p, measure_sd=sds, representation=rep), None

    given = {k: str(v) for k, v in (sources or {}).items() if k in sds}

    def record(fw, _floor):
        return {"kind": "inferred", "source": INFER, "measures": dict(measures), "measure_sd": dict(fw.measure_sds),
                "measure_sd_source": {k: given.get(k, "default") for k in measures},
                "likelihood_sd": dict(fw.likelihood_sds),
                "representation_error": None if rep is None else {"mode": "floor", **rep.record()}}

    warnings = () if measures else (no_measure_warning or geometry_prior.NO_MEASURE_WARNING,)
    return _Setup(forward_at, box_at, None, record, warnings=warnings, measures=dict(measures),
                  measure_sd_source=given)


def _with_states(emulator, row, prior: str, setup: _Setup, forward, edp_mmhg: float, *, inferred: bool,
                 bound: bool):
    """The primary state's forward model with the further loaded states and the Klotz prior as likelihood terms
    (:class:`lvcore.inference.loaded_states.LoadedStatesForward`), and the states' extrapolation warnings."""
    from lvcore.inference import loaded_states as ls

    terms, extrapolation = [], []
    for st in row.states:
        extrapolation += [x for x in setup.box_at(st.edp_mmhg)[1] if x not in extrapolation]
        terms.append(ls.StateTerm(setup.forward_at(st.edp_mmhg)[0], np.asarray(st.y, float), float(st.edp_mmhg)))
    klotz = None
    if prior == "klotz":
        klotz = _klotz_prior(ls, forward, setup, edp_mmhg, inferred=inferred, bound=bound, emulator=emulator)
    return ls.LoadedStatesForward(forward, tuple(terms), klotz), extrapolation


def _klotz_prior(ls, forward, setup: _Setup, edp_mmhg: float, *, inferred: bool, bound: bool, emulator):
    """The Klotz prior of one subject (:class:`lvcore.inference.loaded_states.KlotzPrior`): the forward model at
    20 and 30 mmHg and V0, the geometry's reference cavity (inferred: from the sampled scores and scale)."""
    import jax.numpy as jnp

    from lvcore.inference.geometry_prior import SCALE_NAME

    fws = tuple(setup.forward_at(p)[0] for p in ls.KLOTZ_PRESSURES_MMHG)
    if inferred:
        def v0_fn(params, fw=forward):
            return fw.shape(jnp.stack([params[n] for n in fw.pc_names]), params[SCALE_NAME])["reference_volume_ml"]

        return ls.KlotzPrior(fws, edp_mmhg, v0_fn=v0_fn)
    if bound:
        v0 = ls.reference_volume_ml(dict(emulator.subject_geometry))
    else:
        geo = setup.geometry
        v0 = ls.reference_volume_ml({"kind": "pca", "scores": [float(h) for h in geo.h],
                                     "resolution": str(emulator.resolution)}) * float(geo.scale) ** 3
    return ls.KlotzPrior(fws, edp_mmhg, v0_ml=v0)


__all__ = ["INFER", "EXTRAPOLATION", "CalibrationRequest", "build_request", "subject_geometry"]
