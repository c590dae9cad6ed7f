"""Studies: the chapter's optimisation and discrepancy studies from saved results, and small background runs."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np
import pandas as pd
import streamlit as st

from lvcore.exceptions import LVCoreError
from lvcore.studies import results
from lvcore.studies.bo_fibres import format_findings as bo_findings_text
from lvcore.studies.bo_fibres import tables as bo_tables
from lvcore.studies.operators import fits_frame
from lvcore.studies.operators import format_findings as op_findings_text
from lvcore.viz import figures, study_figures

st.title("Studies")
st.caption("The chapter's studies from saved results: the bundled results of a shipped run, and any `--out` folder "
           "of `lvcore study ...`. Everything here is SYNTHETIC (generated volunteers, imitation operators).")

with st.sidebar:
    st.header("Results")
    extra = st.text_input("More result folders (comma-separated)", "",
                          help="--out folders of `lvcore study bo-fibres/operators/fibre-discrepancy`, or their parent")
    folders = [Path(p.strip()).expanduser() for p in extra.split(",") if p.strip()]
    if "studies_runs" in st.session_state:
        folders += [r.out for r in st.session_state["studies_runs"].values()]
sources = results.result_sources(folders)


def pick(study: str, key: str):
    opts = sources[study]
    if not opts:
        st.info(f"No saved results of `{study}` found (bundled folder: {results.bundled_studies_dir()}). "
                f"Run `lvcore study {study} --out DIR` and add DIR in the sidebar.")
        return None
    label = st.selectbox("Result set", [o[0] for o in opts], key=key)
    return dict(opts)[label]


tab_bo, tab_ops, tab_fd, tab_geo, tab_run = st.tabs(
    ["Fibre-angle BO (Tables 9.2/9.3)", "Operators (Figs 9.11–9.14)", "Fibre discrepancy (Figs 9.6–9.9)",
     "Operators, geometry (Table 9.4)", "Run a small study"])

# ----------------------------------------------------------------------------- BO
with tab_bo:
    folder = pick("bo-fibres", "bo_src")
    if folder is not None:
        try:
            entries, meta = results.load_bo(folder)
        except LVCoreError as err:
            st.error(str(err))
            entries = []
        if entries:
            budget = meta.get("budget", {})
            runs = f"{len(meta.get('runs', entries))} of 16 volunteer × mode runs"
            if budget and (not budget.get("chapter_budget") or not meta.get("complete_study", True)):
                st.warning(f"Budget: {budget.get('label')}; {runs}. This is not the chapter's full run.")
            elif budget:
                st.success(f"Budget: {budget.get('label')}")
            st.markdown("**Findings**\n\n" + bo_findings_text(meta.get("findings", {})).replace("\n", "\n\n"))
            st.subheader("Tables 9.2 (angles fixed at −60°, 90°) and 9.3 (angles optimised), side by side")
            st.dataframe(bo_tables(entries).round(4), hide_index=True, width="stretch")
            c1, c2 = st.columns(2)
            c1.plotly_chart(study_figures.residual_figure(entries), width="stretch")
            c2.plotly_chart(study_figures.convergence_figure(entries), width="stretch")
            lvv = {m: [e["lvv_abs_error_ml"] for e in entries if e["mode"] == m] for m in ("fixed", "free")}
            st.plotly_chart(figures.violin({f"LVV |error| (mL), {m}": v for m, v in lvv.items() if v},
                                           title="LVV error at the optimum, fixed vs free angles"),
                            width="stretch")
            hidden = meta.get("findings", {}).get("angles_vs_hidden")
            if hidden:
                st.caption("Found angles against the volunteers' hidden ones (used for this report only, never the fit)")
                st.dataframe(pd.DataFrame(hidden).round(1), hide_index=True)

# ----------------------------------------------------------------------------- operators
with tab_ops:
    folder = pick("operators", "ops_src")
    if folder is not None:
        try:
            data = results.load_operators(folder)
        except LVCoreError as err:
            st.error(str(err))
            data = {"fits": []}
        fits = [f for f in data["fits"] if "strain_rmse_forward" in f]
        if data.get("meta"):
            m = data["meta"]
            (st.warning if not m.get("complete_study") else st.info)(
                f"{m.get('budget')}; {m.get('n_fits')} fits, settings {m.get('settings')}")
        if data.get("findings"):
            st.markdown("**Findings**\n\n" + op_findings_text(data["findings"]).replace("\n", "\n\n"))
        if fits:
            st.plotly_chart(study_figures.violin_figure(fits, "strain_errors_forward",
                                                        "Fig 9.11: |forward strain error| at θ̃ (test vs main geometry)",
                                                        "|ζ(θ̃, ĝ) − y*| per region", per_region=True),
                            width="stretch")
            st.plotly_chart(study_figures.violin_figure(fits, "output_rmse_refit",
                                                        "Fig 9.14: output-space error of θ̂ on the main geometry",
                                                        "RMS strain error"), width="stretch")
            st.plotly_chart(study_figures.violin_figure(fits, "mahalanobis",
                                                        "Beyond the chapter: Mahalanobis distance of θ̂ from θ̃ "
                                                        "(Laplace covariance from the adjoint Jacobian)",
                                                        "Mahalanobis distance"), width="stretch")
            st.subheader("Fig 9.12: absolute parameter errors per fit")
            st.dataframe(fits_frame(fits).round(4), hide_index=True, width="stretch")
            if data.get("surfaces"):
                labels = [f"{s['patient']} main {s['main_operator']} test {s['test_geometry']}" for s in data["surfaces"]]
                i = st.selectbox("Loss surface (Fig 9.13) of fit", range(len(labels)), format_func=labels.__getitem__)
                st.plotly_chart(study_figures.surface_figure({**data["surfaces"][i], "rss_surface": data["surfaces"][i]}),
                                width="stretch")

# ----------------------------------------------------------------------------- fibre discrepancy
with tab_fd:
    folder = pick("fibre-discrepancy", "fd_src")
    if folder is not None:
        from lvcore.viz import inference_figures

        try:
            fd = results.load_fibre_discrepancy(folder)
        except LVCoreError as err:
            st.error(str(err))
            fd = {}
        if fd:
            st.json(fd.get("findings", {}), expanded=False)
            draws = {m: np.asarray(v) for m, v in fd.get("error_draws", {}).items()}
            if draws:
                st.plotly_chart(inference_figures.error_violin_figure(draws), width="stretch")
                st.plotly_chart(figures.density_overlay(draws, title="Density of the mean |strain error| per draw"),
                                width="stretch")
            sets = fd.get("sets", [])
            if sets:
                rows = [{"set": s["set"], "alpha_endo": s["alpha_endo"], "alpha_epi": s["alpha_epi"], "model": m,
                         "median |error|": r["abs_error_median"],
                         "sigma_S median": r.get("sigma_s", {}).get("median")}
                        for s in sets for m, r in s["models"].items()]
                st.dataframe(pd.DataFrame(rows).round(4), hide_index=True, width="stretch")

# ----------------------------------------------------------------------------- Table 9.4
with tab_geo:
    from lvcore.studies.geometry_operators import format_table, operator_table

    @st.cache_data(show_spinner=False)
    def _table94():
        return operator_table()

    try:
        st.code(format_table(_table94()))
    except LVCoreError as err:
        st.error(str(err))

# ----------------------------------------------------------------------------- background runs
with tab_run:
    st.write("Start a small run (fast mesh) in the background; the page stays usable while it runs and its "
             "results appear in the tabs above when it is done.")
    runs = st.session_state.setdefault("studies_runs", {})
    c1, c2, c3 = st.columns(3)
    study = c1.selectbox("Study", ["bo-fibres", "operators"])
    if study == "bo-fibres":
        subject = c2.selectbox("Volunteer", [f"SYNTHETIC-HV{i}" for i in range(1, 9)])
        n0 = c3.number_input("initial design", 3, 300, 6)
        n1 = c3.number_input("iterations", 0, 300, 4)
    else:
        subject = c2.selectbox("Patient", [f"SYNTHETIC-P0{i}" for i in range(1, 7)])
    if st.button("Start", type="primary"):
        out = Path(tempfile.mkdtemp(prefix=f"lvcore_{study}_"))
        try:
            if study == "bo-fibres":
                run = results.small_run(study, out, subject=subject, n_initial=int(n0), n_iterations=int(n1))
            else:
                run = results.small_run(study, out, patient=subject)
            runs[str(out)] = run
        except LVCoreError as err:
            st.error(str(err))

    @st.fragment(run_every=2.0)
    def _progress():
        for key, run in list(runs.items()):
            state = "running" if run.running else ("done" if run.returncode == 0 else f"failed ({run.returncode})")
            st.progress(run.fraction, text=f"{run.study} → {run.out} — {state}")
            if not run.running and run.returncode not in (0, None):
                st.code(run.log_tail())

    _progress()
