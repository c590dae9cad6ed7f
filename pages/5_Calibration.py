"""Calibration: posterior of theta = (a, b, af, bf) from LVV + 24 strains, with honest uncertainty."""
from __future__ import annotations

import sys
import threading
import time
from functools import partial

import numpy as np
import streamlit as st

import lvcore  # noqa: F401  (float64)
from lvcore.app import cohort_panel, freshness, physiology_panel
from lvcore.app.emulators import cached_emulator
from lvcore.app import warmup as app_warmup
from lvcore.app.subject_prepare import floor_caption
from lvcore.app.tables import summary_view
from lvcore.app.controls import (DEFAULT_SUBJECT, chosen_index, conditions_text, disabled_hint,
                                 discrepancy_kernel_choice, remember_choice, shared_inputs, why_disabled)
from lvcore.domain.conditions import SIMULATOR_DEFAULT_ANGLES, SIMULATOR_DEFAULT_EDP_MMHG
from lvcore.emulator.io import available_emulators, below_spec_emulators
from lvcore.exceptions import LVCoreError
from lvcore.inference import calibrate as cal
from lvcore.inference import guards
from lvcore.inference.data import MeasuredData, read_measured_csv
from lvcore.inference.diagnostics import banner_status, netcdf_bytes
from lvcore.inference.models import MODEL_LABELS, PARAMETER_HELP, parameter_meaning, prior_bounds
from lvcore.inference.request import build_request
from lvcore.inference.samplers import INTERACTIVE, SamplerConfig
from lvcore.viz.inference_figures import display_name
from lvcore.resources import bundled_volunteers, volunteer_files, volunteer_truth
from lvcore.app.uploads import session_uploads

st.set_page_config(page_title="Calibration", layout="wide")
st.title("Bayesian calibration")
st.caption(
    "Infer θ = (a, b, a_f, b_f) from one subject's end-diastolic volume and 24 circumferential strains with an "
    "emulator of the simulator. Three likelihoods: (i) volume only, (ii) iid Gaussian strains, (iii) strains "
    "with a polar Gaussian-process discrepancy b(x) sampled by HMC-within-Gibbs (chapter Algorithm 4)."
)

# ----------------------------------------------------------------------------- emulator
choices = {name: name for name in available_emulators()}
for label_, d in below_spec_emulators(bundled=False).items():  # ones built locally; never loaded by name
    choices.setdefault(label_, str(d))
if not choices:
    st.info(
        "No trained emulator found, so calibration cannot run. Build the bundled ones with "
        "`python scripts/build_emulators.py`, or train one with `lvcore emulator train STORE --out DIR` and set "
        "`LVCORE_EMULATORS` to its parent directory."
    )
    st.stop()


shared_inputs(theta=False, edp=False)  # it reads no θ, no EDP: the sidebar shows no shared inputs here

# ----------------------------------------------------------------------------- data
left, right = st.columns(2)
with left:
    st.subheader("Data")
    source = st.radio("Source", ["bundled volunteer", "upload"], horizontal=True)
    data: MeasuredData | None = None
    h = None
    geo = None
    if source == "bundled volunteer":
        names = bundled_volunteers()
        if not names:
            st.warning("No bundled volunteers in assets/volunteers; upload data instead.")
        else:
            name = st.selectbox("Volunteer", names, index=chosen_index("subject", names),
                                help=f"Bundled SYNTHETIC volunteers (default {DEFAULT_SUBJECT}: its PC scores lie "
                                     "inside the default emulator's box).")
            remember_choice("subject", name)
            try:
                vol = volunteer_files(name)
                data = read_measured_csv(vol.measured)[0]
                geo = guards.resolve_geometry(str(vol.geometry))  # size-normalised: scores h and scale s
                h = geo.h
            except LVCoreError as err:
                st.error(str(err))
            if name.startswith("SYNTHETIC"):
                st.caption("⚠ SYNTHETIC volunteer: generated data, not a real subject.")
    else:  # uploads go to this browser session's own folder; errors name the user's file, the controls stay
        uploads = session_uploads()
        up_data = st.file_uploader("Measured CSV (lvv_ml, strain_01..strain_24)", type=["csv"], key="up_measured")
        up_geom = st.file_uploader("Geometry: PC scores (.json/.csv, optional 'scale') or template mesh (.vtu)",
                                   type=["json", "csv", "vtu"], key="up_geometry")
        if up_data is not None:
            try:
                rows = uploads.read(up_data.name, up_data.getvalue(), read_measured_csv, slot="measured")
            except LVCoreError as err:
                st.error(f"Measured data: {err}")
            else:
                subj = st.selectbox("Subject", [r.subject for r in rows])
                data = next(r for r in rows if r.subject == subj)
        if up_geom is not None:
            try:
                geo = uploads.read(up_geom.name, up_geom.getvalue(), lambda p: guards.resolve_geometry(str(p)),
                                   slot="geometry")
                h = geo.h
            except LVCoreError as err:
                st.error(f"Geometry: {err}")
    if data is not None:
        st.write(f"LVV = {data.lvv_ml:.1f} mL; strains from {data.strains.min():.3f} to {data.strains.max():.3f}")
    if h is not None:
        st.write("PC scores h = " + ", ".join(f"{v:.2f}" for v in h)
                 + (f"; scale s = {geo.scale:.3f} (the subject is s × this shape: emulated LVV × s³)"
                    if geo is not None else ""))

with right:
    st.subheader("Model")
    emu_label = st.selectbox("Emulator", list(choices), index=chosen_index("emulator", choices),
                             help="Starts at the emulator last chosen on the Emulator, Calibration or My subject "
                                  "page (first: the one lvcore calibrate uses).")
    remember_choice("emulator", emu_label)
    models = st.multiselect("Likelihood(s)", list(MODEL_LABELS), default=["iid", "discrepancy"],
                            format_func=MODEL_LABELS.get,
                            help="Parameters reported:\n\n" + "\n\n".join(
                                f"- {PARAMETER_HELP[n]}" for n in ("a", "b", "af", "bf", "sigma_s_sq", "v", "lam",
                                                                   "sigma1_sq", "sigma2_sq", "c", "tau")))
    with st.expander("What the parameters mean"):
        st.markdown("\n".join(f"- **{display_name(n)}** — {PARAMETER_HELP[n]}" for n in
                               ("a", "b", "af", "bf", "sigma_s_sq", "v", "lam", "sigma1_sq", "sigma2_sq", "c", "tau")))
    kernel = discrepancy_kernel_choice(models)  # greyed out unless the discrepancy likelihood is chosen
    angles = st.radio("Fibre angles", ["fixed", "infer"], horizontal=True,
                      help="infer: α_endo ~ U(-90, 0), α_epi ~ U(0, 90); needs an emulator with angle inputs")
    c1, c2, c3 = st.columns(3)
    chains = c1.number_input("chains", 1, 8, INTERACTIVE.num_chains)  # defaults chosen by ESS per second
    warmup = c2.number_input("warm-up", 50, 5000, INTERACTIVE.num_warmup, step=50)
    samples = c3.number_input("draws kept", 50, 5000, INTERACTIVE.num_samples, step=100)

# ----------------------------------------------------------------------------- background run
job = st.session_state.get("calibration_job")
cal_inputs = {"subject": None if data is None else data.subject, "emulator": emu_label,
              "likelihoods": [MODEL_LABELS[m] for m in models], "fibre angles": angles, "chains": int(chains),
              "warm-up": int(warmup), "draws": int(samples),
              "discrepancy kernel": kernel if "discrepancy" in models else None}


def _consistency(job: dict):
    """The verdict's consistency check (best fit of volume and strains), stored in the job (an error is kept)."""
    try:
        job["consistency"] = job["request"].consistency()
    except Exception as err:  # noqa: BLE001 - shown beside the results, never hides them
        job["consistency"] = err


def _worker(job: dict, models, config):
    """Every likelihood's sampler, then the verdict's best fit, one after the other in this thread.

    The samplers and the best fit are compiled when the app starts (lvcore.app.warmup) and kept in the
    process, so a click samples at once. numpyro's handler stack is global: model traces hold
    ``samplers.TRACE_LOCK``. (Side by side in threads they took no less wall on 2 cores, the 4-chain
    samplers already keep both busy: ``benchmarks/bench_calibration.py --app``.)
    """
    def progress(msg, frac):
        job["message"] = msg
        job["fraction"] = frac

    timings = job.setdefault("timings", {})  # (start, end) of each step, s after the click

    def step(name, fn, *args, **kwargs):
        start = time.perf_counter() - job["t0"]
        try:
            return fn(*args, **kwargs)
        finally:
            timings[name] = (start, time.perf_counter() - job["t0"])

    request = job["request"]
    try:
        for m in models:
            step(m, cal.calibrate_subjects, [(job["subject"], request.y, request.forward)], [m], config=config,
                 sigma_v=request.sigma_v, infer_angles=request.infer_angles, progress=progress,
                 on_result=lambda item: job["results"].__setitem__(item.model, item.result))
        # the verdict's best fit, after the samplers: the results render with it (the banner needs it)
        progress("verdict: best fit of volume and strains", 1.0)
        step("best fit", _consistency, job)
        job["message"] = "done"
        job["fraction"] = 1.0
    except Exception as err:  # noqa: BLE001 - shown to the user
        job["error"] = f"{type(err).__name__}: {err}"
    finally:
        job["done"] = True
        job["elapsed"] = time.perf_counter() - job["t0"]
        print(f"lvcore calibration {job['subject']}: done {job['elapsed']:.1f} s after the click; "
              + ", ".join(f"{k} {a:.1f}-{b:.1f} s" for k, (a, b) in timings.items()), file=sys.stderr, flush=True)


room = app_warmup.calibration_room(models)   # a compile short of memory would abort the server: checked first
blocked = why_disabled(
    (data is None, "no measurements yet: choose a bundled volunteer or upload a measured CSV (LVV + 24 strains)."),
    (h is None, "no geometry yet: upload the subject's PC scores or template mesh too (the emulator needs its shape)."),
    (not models, "no likelihood chosen: pick at least one under Likelihood(s)."),
    (job is not None and not job["done"], "a calibration is running; its results appear below when it is done."),
    (room is not None, room))
run_clicked = st.button("Run calibration", type="primary", disabled=blocked is not None, help=blocked)
disabled_hint(blocked)
if run_clicked:
    try:
        emulator = cached_emulator(choices[emu_label])
        # lvcore calibrate's set-up (lvcore.inference.request): the data's EDP (refused by a fixed-EDP emulator
        # when it differs), the box check, the scaled forward and the representation floor of a mesh. Outside the
        # training box the CLI refuses without --allow-extrapolation; here it runs, flagged.
        request = build_request(emulator, emu_label, geo, row=data, infer_angles=angles == "infer",
                                allow_extrapolation=True)
    except LVCoreError as err:
        st.error(str(err))
        st.stop()
    forward, conditions = request.forward, request.conditions
    try:  # what the derived quantities (EDPVR, stress, ridge) need: the emulator's geometry, resolution and base
        physiology_setup = physiology_panel.Setup.of(
            emulator, forward, edp_mmhg=conditions["edp_mmhg"],
            angles=(conditions["alpha_endo"], conditions["alpha_epi"]), measured_lvv_ml=float(data.y[0]),
            h=request.geometry.h, scale=request.geometry.scale, infer_angles=request.infer_angles)
    except Exception as err:  # noqa: BLE001 - the calibration still runs; the panel says why it is missing
        st.warning(f"The EDPVR and derived quantities will not be available ({type(err).__name__}: {err}).")
        physiology_setup = None
    config = SamplerConfig(num_warmup=int(warmup), num_samples=int(samples), num_chains=int(chains),
                           discrepancy_kernel=kernel)
    job = {"done": False, "message": "compiling the sampler", "fraction": 0.0, "results": {}, "error": None,
           "t0": time.perf_counter(), "y": data.y, "subject": data.subject, "emulator": emu_label,
           "synthetic": data.subject.startswith("SYNTHETIC"), "bounds": prior_bounds(request.infer_angles, forward),
           "inputs": dict(cal_inputs), "extrapolation": request.extrapolation, "verdicts": None, "forward": forward,
           "infer": request.infer_angles, "request": request,
           "edp_mmhg": conditions["edp_mmhg"], "edp_source": request.edp_source,
           "base": request.base, "h": [float(v) for v in request.geometry.h],
           "angles": (conditions["alpha_endo"], conditions["alpha_epi"]),
           "physiology": physiology_setup}
    st.session_state["calibration_job"] = job
    threading.Thread(target=_worker, args=(job, models, config), daemon=True).start()


def _progress():
    """Progress bar and elapsed time, visible; reruns itself once a second only while a run is in flight."""
    j = st.session_state.get("calibration_job")
    if j is None or j.get("shown"):
        return
    if not j["done"]:
        st.progress(min(1.0, j["fraction"]),
                    text=f"Sampling: {j['message']} — {time.perf_counter() - j['t0']:.0f} s elapsed")
    else:
        j["shown"] = True
        st.rerun()


_job = st.session_state.get("calibration_job")
if _job is not None and not _job["done"]:  # the 1 Hz timer exists only while sampling: no idle reruns
    st.fragment(run_every=1.0)(_progress)()

# ----------------------------------------------------------------------------- results
def _verdicts(job: dict, results: dict) -> dict:
    """One verdict per subject (lvcore.inference.verdict), computed once per job; {} if it cannot be computed."""
    if job.get("verdicts") is None:
        from lvcore.inference import verdict

        out = {}
        try:
            with st.spinner("Verdict: best fit of volume and strains"):
                request = job["request"]
                consistency = job.get("consistency")  # computed by the worker after the sampler (_consistency)
                if isinstance(consistency, Exception):
                    raise consistency
                if consistency is None:
                    consistency = request.consistency()
                for m, res in results.items():
                    out[m] = verdict.run_verdict(res, consistency, request.bounds, request.forward)
        except Exception as err:  # noqa: BLE001 - shown, never hides the results
            st.warning(f"The verdict could not be computed ({type(err).__name__}: {err}); judge the results "
                       "by the convergence numbers below.")
        job["verdicts"] = out
    return job["verdicts"]


job = st.session_state.get("calibration_job")
if job is not None and job["done"]:
    from lvcore.viz import inference_figures as figs
    from lvcore.viz import report_figures as rfigs

    if job["error"]:
        st.error(job["error"])
    results = job["results"]
    if results:
        with freshness.shown(freshness.Stored(results, job.get("inputs", cal_inputs)), cal_inputs,
                             "calibration"):
            st.subheader(f"Results for {job['subject']} ({job['elapsed']:.0f} s, emulator {job['emulator']})")
            for message in job.get("extrapolation", ()):
                st.warning(message)
            truth = volunteer_truth(job["subject"]) if job["synthetic"] else None
            if job["synthetic"]:
                st.caption("⚠ SYNTHETIC data." + (" The hidden generating value (display only; it never enters the "
                                                  "fit): red dashed lines in the histograms, red crosses in the pair "
                                                  "plot, and the truth column of the table." if truth else ""))
            st.caption("Conditions used: " + conditions_text(
                job.get("edp_mmhg", SIMULATOR_DEFAULT_EDP_MMHG), job.get("angles", SIMULATOR_DEFAULT_ANGLES),
                cached_emulator(choices[job["emulator"]]) if job["emulator"] in choices else None,
                infer_angles=job.get("infer", False))
                + f" (EDP: {job.get('edp_source', 'default')}); {job.get('base', 'clamped')} base (the emulator's "
                  "simulations)")
            st.caption(floor_caption(job["request"].representation_error))  # a mesh's, as lvcore calibrate's
            verdicts = _verdicts(job, results)
            for m, res in results.items():
                v = verdicts.get(m)
                level, text = banner_status(res.convergence, flags=v.flags if v is not None else ())
                getattr(st, level)(f"{MODEL_LABELS[m]}: {text}")
            idatas = {MODEL_LABELS[m]: r.idata for m, r in results.items()}
            fig_pred = figs.predictive_density_figure(idatas, job["y"])
            st.plotly_chart(fig_pred, width="stretch", key="cal_predictive")
            downloads = {"posterior_predictive.html": fig_pred}
            tabs = st.tabs([MODEL_LABELS[m] for m in results])
            for tab, (m, res) in zip(tabs, results.items()):
                with tab:
                    table = res.summary.copy()
                    # a short meaning fits its column (the full text is in the list above the run button)
                    table.insert(0, "meaning", [parameter_meaning(n) for n in table.index])
                    if truth:
                        table.insert(1, "truth (SYNTHETIC)", [f"{truth[str(n)]:.4g}" if truth.get(str(n)) is not None
                                                              else "–" for n in table.index])
                    table.index = [display_name(n) for n in table.index]  # a_f, b_f as on the sliders
                    table, config = summary_view(st, table)  # headers in words, help, no None/NaN
                    st.dataframe(table, width="stretch",
                                 column_config={"meaning": st.column_config.TextColumn(width="large"),
                                                "truth (SYNTHETIC)": st.column_config.TextColumn(
                                                    help="The hidden truth of the SYNTHETIC volunteer; – where it "
                                                         "has none (noise and discrepancy parameters)."),
                                                **config})
                    bounds = job.get("bounds") or {}
                    post = {n: np.asarray(res.idata.posterior[n]).reshape(-1) for n in bounds if n in res.idata.posterior}
                    if post:
                        st.plotly_chart(rfigs.posterior_prior_figure(
                            post, bounds, truth=truth, units=figs.UNITS,
                            title="Posterior (histogram) with the uniform prior (dotted)"
                                  + (" and the hidden truth (red)" if truth else "")),
                            width="stretch", key=f"cal_post_{m}")
                    st.caption(f"sampler {res.sampler}; {res.wall_s:.1f} s incl. compilation; "
                               f"min bulk ESS/s over θ {res.ess_per_s['min']:.1f}")
                    fig_pair = figs.pair_figure(res.idata, truth=truth)
                    st.plotly_chart(fig_pair, width="stretch", key=f"cal_pair_{m}")
                    names = [n for n in ("a", "b", "af", "bf", "alpha_endo", "alpha_epi", "sigma_s2")
                             if n in res.idata.posterior]
                    fig_trace = figs.trace_figure(res.idata, names)
                    fig_rank = figs.rank_figure(res.idata, names)
                    t1, t2 = st.columns(2)
                    # keyed per likelihood: two likelihoods' figures can be identical (one chain: the same
                    # empty rank plot), and Streamlit refuses two elements with one auto-generated id
                    t1.plotly_chart(fig_trace, width="stretch", key=f"cal_trace_{m}")
                    t2.plotly_chart(fig_rank, width="stretch", key=f"cal_rank_{m}")
                    downloads.update({f"{m}_pair.html": fig_pair, f"{m}_trace.html": fig_trace,
                                      f"{m}_rank.html": fig_rank})
                    if m == "discrepancy":
                        fig_disc = figs.discrepancy_figure(res.idata)
                        st.plotly_chart(fig_disc, width="stretch", key=f"cal_disc_{m}")
                        downloads[f"{m}_discrepancy.html"] = fig_disc
                    st.download_button(f"InferenceData ({m}, netCDF)", partial(netcdf_bytes, res.idata),
                                       file_name=f"{cal.file_stem(job['subject'])}_{m}.nc", key=f"nc_{m}")
            if job.get("physiology") is not None:
                physiology_panel.show(idatas, job["physiology"], subject=job["subject"], key="cal_edpvr")
            st.subheader("Export figures")
            for name, fig in downloads.items():
                # written on the click (each HTML carries plotly.js, ~4 MB): not on every rerun
                st.download_button(name, partial(fig.to_html, include_plotlyjs=True),
                                   file_name=f"{cal.file_stem(job['subject'])}_{name}", mime="text/html",
                                   key=f"html_{name}")

# --------------------------------------------------------------------------- a cohort: one joint posterior
cohort_panel.show(st)
