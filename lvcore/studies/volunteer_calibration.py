"""A short live calibration of one bundled SYNTHETIC volunteer (the report's calibration posterior).

The iid likelihood and the ``chapter`` emulator, on the volunteer's measured
CSV with its geometry size-normalised as ``lvcore calibrate --volunteer`` does
(:func:`lvcore.inference.guards.resolve_geometry`): ``h`` the 5-PC projection
of the geometry at the shape model's mean size and ``s`` its scale, the
emulated LVV times ``s^3`` (:mod:`lvcore.geometry.scaling`); the uniform prior and the
volunteer's hidden truth are kept beside the posterior so that the figure can
show both (the truth scores the fit, it never enters it). The default subject
is SYNTHETIC-HV3, whose PC scores lie inside the emulator box (HV5's do not, even size-normalised).
"""
from __future__ import annotations

import numpy as np

from lvcore.domain.outputs import THETA_NAMES

#: The subject of the report's calibration.
DEFAULT_SUBJECT = "SYNTHETIC-HV3"
#: Seconds the calibration adds to ``lvcore report`` (JAX compilation included): the range measured on the
#: 2-core development machine, ``timings_s["calibration posterior"]`` of the manifest (docs/report.md, Appendix: measured runs).
TYPICAL_SECONDS = (20, 45)
#: Figures and tables :func:`figures` draws (for the default subject), with their titles.
TITLES = {"fig_calibration_posterior": f"Calibration posterior of θ, {DEFAULT_SUBJECT} (prior and truth shown)",
          "table_calibration_summary": f"Calibration summary, {DEFAULT_SUBJECT}",
          "fig_calibration_edpvr": f"EDPVR of the posterior, {DEFAULT_SUBJECT} (FE simulator, measured point, Klotz curve)",
          "table_calibration_derived": f"What the data identify, {DEFAULT_SUBJECT}: EDPVR, stress, combinations"}
#: Why the figures can be absent.
MISSING = dict.fromkeys(TITLES, "the `chapter` emulator is not installed; build it with python "
                                "scripts/build_emulators.py --emulators chapter")


def compute(subject: str = DEFAULT_SUBJECT, *, num_warmup: int = 500, num_samples: int = 500,
            num_chains: int = 4, seed: int = 0, derived_draws: int | None = None) -> dict | None:
    """Run the calibration; None when the ``chapter`` emulator is not installed.

    Returns
    -------
    dict
        ``subject``, ``draws`` {θ name: (n,) array}, ``bounds`` {name: (lo, hi)} of the
        uniform prior, ``truth`` {name: value} or None, ``summary`` (DataFrame with
        ``parameter`` and ``truth``), ``status`` (convergence text), ``wall_s``, ``config`` and ``derived``
        (:func:`lvcore.inference.derived.derive`'s record with ``derived_draws`` posterior draws, default
        :func:`lvcore.inference.derived.default_draws`: 100, or the environment's ``LVCORE_DERIVED_DRAWS``; None
        with 0).
    """
    from lvcore.emulator.io import available_emulators

    if "chapter" not in available_emulators():
        return None
    from lvcore.emulator.forward import load_emulator_forward
    from lvcore.geometry.scaling import ScaledForward
    from lvcore.inference import models
    from lvcore.inference.calibrate import calibrate
    from lvcore.inference.guards import resolve_geometry
    from lvcore.inference.data import read_measured_csv
    from lvcore.inference.samplers import SamplerConfig
    from lvcore.resources import volunteer_files, volunteer_truth

    files = volunteer_files(subject.replace("-", "_"))
    row = read_measured_csv(files.measured)[0]
    geo = resolve_geometry(str(files.geometry))   # size-normalised: scores h and scale s, as the CLI
    forward = ScaledForward(load_emulator_forward("chapter", geo.h), geo.scale)
    config = SamplerConfig(num_warmup=num_warmup, num_samples=num_samples, num_chains=num_chains, seed=seed)
    res = calibrate(row.y, forward, "iid", config=config, max_rounds=1)
    from lvcore.inference import derived

    n_derived = derived.default_draws() if derived_draws is None else int(derived_draws)
    derived_rec = None
    if n_derived:
        from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP, SIGMA_V_ML

        emu = forward.forward.emulator if hasattr(forward.forward, "emulator") else None
        derived_rec, _ = derived.derive(
            res.idata, bounds={n: b for n, b in models.prior_bounds(forward=forward).items() if n in THETA_NAMES},
            edp_mmhg=CHAPTER_EDP, angles=CHAPTER_ANGLES, base=str(getattr(emu, "base", "sliding")),
            resolution=str(getattr(emu, "resolution", "default")), measured_edv_ml=float(row.y[0]),
            lvv_sd_ml=SIGMA_V_ML, h=geo.h, scale=geo.scale, n_draws=n_derived)
    truth = volunteer_truth(row.subject)  # the hidden truth scores the fit; it never enters it
    truth = {n: truth[n] for n in THETA_NAMES if n in truth} if truth else None
    stats = res.idata.sample_stats
    n_div = int(np.asarray(stats["diverging"]).sum()) if "diverging" in stats else 0
    summary = res.summary.reset_index().rename(columns={"index": "parameter"})
    if truth:
        summary["truth"] = summary["parameter"].map(truth)
    return {"subject": row.subject, "draws": {n: np.asarray(res.idata.posterior[n]).reshape(-1) for n in THETA_NAMES},
            "bounds": models.prior_bounds(forward=forward), "truth": truth, "summary": summary,
            "status": f"{res.convergence.message()}; {n_div} divergent transitions", "wall_s": res.wall_s,
            "config": {"num_warmup": num_warmup, "num_samples": num_samples, "num_chains": num_chains},
            "derived": derived_rec}


def source_line(result: dict) -> str:
    return (f"live NUTS run ({result['wall_s']:.1f} s) on {result['subject']}'s measured CSV, its geometry "
            "size-normalised: h = 5-PC projection at the mean size, emulated LVV x s^3")


def tables(result: dict) -> dict:
    """The posterior draws (thinned to about 1000) behind the figure, and the summary table."""
    import pandas as pd

    draws = result["draws"]
    out = {"fig_calibration_posterior": pd.DataFrame({n: d[:: max(1, d.size // 1000)] for n, d in draws.items()}),
           "table_calibration_summary": result["summary"]}
    if result.get("derived"):
        from lvcore.inference.derived import summary_rows

        out["fig_calibration_edpvr"] = pd.DataFrame(result["derived"]["edpvr"])
        out["table_calibration_derived"] = pd.DataFrame(summary_rows(result["derived"]))
    return out


def captions(result: dict) -> dict:
    return {k: result["status"] for k in TITLES}


def figures(result: dict) -> dict:
    """The posterior of θ with the uniform prior and the hidden truth, and the summary as a table."""
    from lvcore.viz.inference_figures import UNITS
    from lvcore.viz.report_figures import posterior_prior_figure, table_figure

    c = result["config"]
    subject = result["subject"]
    out = {
        "fig_calibration_posterior": posterior_prior_figure(
            result["draws"], result["bounds"], truth=result["truth"], units=UNITS,
            title=f"Calibration — {subject} (SYNTHETIC volunteer), iid model, chapter emulator, "
                  f"{c['num_chains']}×({c['num_warmup']}+{c['num_samples']}) NUTS: posterior, uniform prior "
                  "(dotted), hidden truth (red)"),
        "table_calibration_summary": table_figure(
            result["summary"], title=f"Calibration summary — {subject} (SYNTHETIC), iid model: {result['status']}"),
    }
    d = result.get("derived")
    if d:
        from lvcore.viz.figures import derived_edpvr_figure

        data = tables(result)["table_calibration_derived"].round(4).astype(object).where(lambda t: t.notna(), "")
        out["fig_calibration_edpvr"] = derived_edpvr_figure(
            d, title=f"EDPVR — {subject} (SYNTHETIC volunteer), posterior of the iid calibration",
            subtitle=f"FE simulator, {d['n_draws']} posterior draws; 90 % band, measured point with its 99 % "
                     "predictive interval, Klotz et al. (2006) curve")
        out["table_calibration_derived"] = table_figure(
            data, title=f"What the data identify — {subject} (SYNTHETIC): medians and equal-tailed 90 % intervals")
    return out
