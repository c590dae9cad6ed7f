"""The My subject flow's calibration and results: each likelihood with the CLI's verdict, the figures, and the
posterior of an inferred geometry (:mod:`lvcore.app.subject_flow`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from lvcore.inference.request import CalibrationRequest as Prepared


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
    from lvcore.domain.conditions import SIGMA_V_ML
    from lvcore.inference import calibrate as cal
    from lvcore.inference import verdict
    from lvcore.inference.samplers import SamplerConfig

    sigma_v = SIGMA_V_ML if sigma_v is None else float(sigma_v)
    y = np.asarray(y, float)
    # the verdict's inputs are the request's (one fit check per subject, whichever model runs)
    consistency = verdict.consistency_check(y, prepared.forward, sigma_v, prepared.sigma_ref,
                                            infer_angles=prepared.infer_angles)
    bounds = prepared.bounds
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
    bounds = prepared.bounds
    return list(verdict.identifiability_flags({n: np.asarray(post[n]) for n in bounds if n in post}, bounds)[0])

