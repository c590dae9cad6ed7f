"""The My subject flow's set-up: the user's geometry, measurements and EDP made into one
:class:`~lvcore.inference.request.CalibrationRequest` by :func:`lvcore.inference.request.build_request`, the
builder ``lvcore calibrate`` and the Calibration page call (:mod:`lvcore.app.subject_flow`).

Two things differ from the CLI, both decided here: inputs outside the emulator's training box do not stop the
flow (the CLI refuses them without ``--allow-extrapolation``), they come back as ``EXTRAPOLATION:`` warnings and
:attr:`~lvcore.inference.request.CalibrationRequest.extrapolating`; and the page's EDP field always holds a value,
so the EDP a fixed-EDP emulator was trained at counts as not given.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

from lvcore.app.subject_inputs import NO_MEASURE_WARNING
from lvcore.inference.request import CalibrationRequest, subject_geometry

#: What :func:`prepare` returns (the request of :mod:`lvcore.inference.request`; the name the pages know).
Prepared = CalibrationRequest
#: How the box check's error names the geometry of this flow.
GEOMETRY_LABEL = "the subject's geometry"


def _edp(emulator, edp_mmhg):
    """The page's EDP; the EDP a fixed-EDP emulator was trained at counts as not given (another is refused)."""
    from lvcore.domain.outputs import EDP_NAME

    fixed_edp = dict(getattr(emulator, "fixed", None) or {}).get(EDP_NAME)
    if edp_mmhg is not None and fixed_edp is not None and abs(float(edp_mmhg) - float(fixed_edp)) <= 1e-6:
        return None
    return edp_mmhg


def prepare(emulator, emulator_name: str, geometry, *, edp_mmhg: float | None = None,
            representation_error: str = "floor", row=None) -> CalibrationRequest:
    """The request of a given geometry: ``lvcore calibrate --geometry FILE`` for one subject.

    A mesh (a template or volume mesh) is seen through its 5-mode projection and gets the shape model's
    representation-error floor (``representation_error`` "floor", the default, or "off"). A subject-specific
    emulator (``emulator.is_subject``) has its geometry bound in: no PC scores, scale 1, as ``lvcore calibrate
    --emulator DIR``; ``geometry`` may then be None.

    Parameters
    ----------
    emulator, emulator_name
        The loaded emulator and its name as chosen.
    geometry : lvcore.inference.guards.GeometrySource or None
        From :func:`lvcore.app.subject_inputs.read_geometry`.
    edp_mmhg : float, optional
        The page's EDP (mmHg).
    representation_error : {"floor", "off"}
    row : lvcore.inference.data.MeasuredData, optional
        The subject's measurements (their ``edp_mmhg`` and loaded states are honoured, as by the CLI).

    Raises
    ------
    lvcore.exceptions.LVCoreError
        What :func:`lvcore.inference.request.build_request` refuses (an EDP the emulator cannot take, ...).
    """
    from lvcore.inference.request import build_request

    return build_request(emulator, emulator_name, geometry, row=row, edp_mmhg=_edp(emulator, edp_mmhg),
                         allow_extrapolation=True, representation_error=representation_error,
                         geometry_label=GEOMETRY_LABEL)


def prepare_inferred(emulator, emulator_name: str, measures: Mapping[str, float], *,
                     edp_mmhg: float | None = None, measure_sd: Mapping[str, float] | None = None,
                     measure_sd_source: Mapping[str, str] | None = None,
                     representation_error: str = "floor", row=None) -> CalibrationRequest:
    """The request of the no-mesh route: ``lvcore calibrate --geometry infer`` for one subject.

    The PC scores and a scale are sampled with θ (:func:`lvcore.inference.geometry_prior.inferred_geometry_forward`),
    the measures observed with ``measure_sd`` (default :data:`lvcore.inference.geometry_prior.MEASURE_SD`;
    ``measure_sd_source`` says where each came from, :func:`lvcore.app.subject_inputs.inferred_measure_sds`;
    "entered" when not said); ``representation_error`` "floor" (the CLI's default) adds the shape model's
    representation error to the likelihood, "off" leaves it out; :data:`NO_MEASURE_WARNING` when no measure is
    given.

    Raises
    ------
    lvcore.exceptions.EmulatorError
        The emulator is subject-specific (no geometry to infer), or cannot take the EDP asked for.
    """
    from lvcore.inference.request import INFER, build_request

    sources = {k: (measure_sd_source or {}).get(k, "entered") for k in (measure_sd or {})}
    return build_request(emulator, emulator_name, INFER, row=row, edp_mmhg=_edp(emulator, edp_mmhg),
                         allow_extrapolation=True, representation_error=representation_error, measures=measures,
                         measure_sd=measure_sd, measure_sd_source=sources, no_measure_warning=NO_MEASURE_WARNING)


def subject_emulator_geometry(emulator):
    """The geometry record of a subject-specific emulator (bound in), as ``lvcore calibrate --emulator DIR``
    records it: no PC scores, scale 1, the file it was built on."""
    return subject_geometry(emulator)


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
        rec = prepared.geometry_record
        return cls(dict(prepared.measures), measure_sd=dict(rec["measure_sd"]),
                   measure_sd_source=dict(prepared.measure_sd_source or {}),
                   likelihood_sd=dict(rec["likelihood_sd"]), representation_error=rec["representation_error"])

    def record(self) -> dict:
        """The CLI's geometry record of ``--geometry infer``."""
        from lvcore.inference.geometry_prior import MEASURE_SD

        sd = self.measure_sd if self.measure_sd is not None else {k: MEASURE_SD[k] for k in self.measures}
        return {"kind": self.kind, "source": self.source, "measures": dict(self.measures),
                "measure_sd": dict(sd),
                "measure_sd_source": {k: (self.measure_sd_source or {}).get(k, "default") for k in self.measures},
                "likelihood_sd": dict(self.likelihood_sd if self.likelihood_sd is not None else sd),
                "representation_error": self.representation_error}

