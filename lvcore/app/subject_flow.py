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
"""
from __future__ import annotations

import html
import io
import json
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from lvcore.exceptions import DataError

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
    """

    forward: Any
    emulator_name: str
    conditions: dict
    box: list
    warnings: list = field(default_factory=list)

    @property
    def extrapolating(self) -> bool:
        return any(not row.get("inside", True) for row in self.box)


def prepare(emulator, emulator_name: str, geometry, *, edp_mmhg: float | None = None) -> Prepared:
    """Bind ``geometry`` and the EDP into ``emulator``, with the CLI's condition and box checks.

    Scores outside the training box do not stop the flow (the CLI refuses them without
    ``--allow-extrapolation``); they come back as warnings and :attr:`Prepared.extrapolating`.

    Raises
    ------
    lvcore.exceptions.EmulatorError
        If the emulator cannot take the EDP asked for (a fixed-EDP emulator and another EDP).
    """
    from lvcore.emulator.forward import emulator_forward
    from lvcore.geometry.scaling import ScaledForward
    from lvcore.inference import guards

    from lvcore.outputs import EDP_NAME

    fixed_edp = dict(getattr(emulator, "fixed", None) or {}).get(EDP_NAME)
    if edp_mmhg is not None and fixed_edp is not None and abs(float(edp_mmhg) - float(fixed_edp)) <= 1e-6:
        edp_mmhg = None  # the EDP the emulator was trained at: nothing to honour (another EDP is refused)
    cond = guards.check_conditions(emulator, edp_mmhg, None, None, infer_angles=False)
    box, extrapolation = guards.check_inputs_in_box(guards.fixed_inputs(geometry.h, cond, emulator, False), emulator,
                                                    allow_extrapolation=True, what="the subject's PC scores")
    forward = ScaledForward(emulator_forward(emulator, geometry.h, name=emulator_name,
                                             alpha_endo=cond["alpha_endo"], alpha_epi=cond["alpha_epi"],
                                             edp_mmhg=cond["edp_mmhg"]), geometry.scale)
    return Prepared(forward, emulator_name, cond, list(box), list(geometry.warnings) + list(extrapolation))


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
        run = ModelRun(item.model, item.result, verdict.run_verdict(item.result, consistency, bounds))
        runs.append(run)
        if on_result is not None:
            on_result(run)

    cal.calibrate_subjects([(subject, y, prepared.forward)], list(models), config=config or SamplerConfig(),
                           sigma_v=sigma_v, progress=progress, on_result=finish,
                           attrs={"emulator": prepared.emulator_name, "edp_mmhg": prepared.conditions["edp_mmhg"]})
    return runs


def figures(runs: Sequence[ModelRun], y, truth: Mapping | None = None) -> dict:
    """The run's figures by file stem: the posterior predictive of every likelihood and, per likelihood, the
    θ pair plot (the a–b trade-off), with the hidden truth of a SYNTHETIC subject when given."""
    from lvcore.inference.models import MODEL_LABELS
    from lvcore.viz import inference_figures as figs

    out = {"posterior_predictive": figs.predictive_density_figure(
        {MODEL_LABELS[r.model]: r.result.idata for r in runs}, np.asarray(y, float))}
    for r in runs:
        out[f"{r.model}_pair"] = figs.pair_figure(r.result.idata, truth=truth)
    return out


def bound_flags(run: ModelRun, prepared: Prepared) -> list:
    """The verdict's identifiability flags of one run (posterior piled on a prior bound, intervals as wide as the
    prior; :func:`lvcore.inference.verdict.identifiability_flags`), as ``lvcore calibrate`` reports them."""
    from lvcore.inference import verdict

    post = run.result.idata.posterior
    bounds = verdict.checked_bounds(prepared.forward)
    return list(verdict.identifiability_flags({n: np.asarray(post[n]) for n in bounds if n in post}, bounds)[0])


def summary_record(subject: str, y, geometry, prepared: Prepared, runs: Sequence[ModelRun],
                   settings: Mapping) -> dict:
    """Plain-data summary of a subject's run: inputs used, geometry, conditions, per-likelihood results and flags."""
    from lvcore.inference.diagnostics import banner_status

    models = {}
    for run in runs:
        level, text = banner_status(run.result.convergence, flags=bound_flags(run, prepared))
        table = run.result.summary
        models[run.model] = {
            "convergence": text, "converged_cleanly": level == "success",
            "plausible": bool(run.check.plausible), "flags": list(run.check.flags),
            "verdict": run.check.record(),
            "wall_s": float(run.result.wall_s),
            "posterior": {str(k): {c: float(table.loc[k, c]) for c in table.columns
                                   if np.issubdtype(type(table.loc[k, c]), np.number)} for k in table.index},
        }
    flagged = [m for m, r in models.items() if r["flags"] or not r["converged_cleanly"]]
    return {
        "subject": subject, "synthetic": str(subject).upper().startswith("SYNTHETIC"),
        "measured": {"lvv_ml": float(y[0]), "strains": [float(v) for v in np.asarray(y)[1:]]},
        "geometry": geometry.record(), "emulator": prepared.emulator_name,
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
    head = "".join(f"<th>{esc(c)}</th>" for c in columns)
    flags = [f"<li><b>{esc(m)}</b>: {esc(f)}</li>" for m, r in summary["models"].items() for f in r["flags"]]
    flags += [f"<li>{esc(w)}</li>" for w in summary["warnings"]]
    conv = "".join(f"<li><b>{esc(m)}</b>: {esc(r['convergence'])}</li>" for m, r in summary["models"].items())
    geo = summary["geometry"]
    cond = summary["conditions"]
    label = " (SYNTHETIC data: generated, not a real subject)" if summary["synthetic"] else ""
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>{esc(summary['subject'])}: calibration</title>
<style>body{{font-family:sans-serif;max-width:60em;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #bbb;padding:2px 6px;text-align:right}}td:first-child,td:nth-child(2){{text-align:left}}</style>
</head><body><h1>Calibration of {esc(summary['subject'])}{esc(label)}</h1>
<p>Measured LVV {summary['measured']['lvv_ml']:.1f} mL; strains {min(summary['measured']['strains']):.3f} to
{max(summary['measured']['strains']):.3f}.</p>
<p>Geometry: {esc(geo['kind'])} from {esc(Path(str(geo['source'])).name)}; PC scores
{esc(', '.join(f'{v:.2f}' for v in geo['scores']))}; scale s = {geo['scale']:.3f}
(emulated LVV &times; s&sup3;).</p>
<p>Emulator {esc(summary['emulator'])}; EDP {cond['edp_mmhg']:.2f} mmHg; fibre angles
{cond['alpha_endo']:.0f}&deg; / {cond['alpha_epi']:.0f}&deg;.</p>
<h2>Verdict</h2><p>{'Flagged: ' + esc(', '.join(summary['flagged_models'])) if summary['flagged_models']
                      else 'No flags: every likelihood converged and the data look plausible for it.'}</p>
<ul>{''.join(flags) or '<li>no warnings</li>'}</ul>
<h2>Convergence</h2><ul>{conv}</ul>
<h2>Posterior</h2><table><tr><th>likelihood</th><th>parameter</th>{head}</tr>{''.join(rows)}</table>
<h2>Settings</h2><pre>{esc(json.dumps(summary['settings'], indent=1))}</pre>
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
