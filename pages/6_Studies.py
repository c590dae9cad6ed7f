"""Studies: the chapter's optimisation and discrepancy studies from saved results, and small background runs.

The tabs are the registry's (:func:`lvcore.studies.registry.tabs`): a study added there gets its place here. Every
study draws through its module (``load``, ``tables``, ``figures``), the same calls as ``lvcore report``; this page
only lays them out (a study without a layout of its own below shows its source and figures).
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import streamlit as st

from lvcore.app.tables import no_missing
from lvcore.exceptions import LVCoreError
from lvcore.studies import bo_fibres, geometry_operators, operators, registry, results
from lvcore.viz.report_figures import wrap_title

#: Characters per title line of a figure on this page (a page-wide figure at a 1400-px window holds ~100).
APP_TITLE_CHARS = 80
#: A table with a text cell longer than this (a verdict's note) and at most WRAP_MAX_ROWS rows is shown as a static
#: table whose cells wrap; a data frame widget would cut the text at its column's width.
WRAP_CHARS, WRAP_MAX_ROWS = 60, 40


def table(frame) -> None:
    """``frame`` with '–' for a missing value; wrapped when a text cell is long (see :data:`WRAP_CHARS`)."""
    frame = no_missing(frame)
    longest = max((len(v) for c in frame.columns for v in frame[c] if isinstance(v, str)), default=0)
    if longest > WRAP_CHARS and len(frame) <= WRAP_MAX_ROWS:
        st.table(frame, hide_index=True)
    else:
        st.dataframe(frame, hide_index=True, width="stretch")

st.title("Studies")
st.caption("The chapter's studies from saved results: the bundled results of a shipped run, and any `--out` folder "
           "of `lvcore study ...`. Everything here is SYNTHETIC (generated volunteers, imitation operators), except "
           "the geometry of the fibre-discrepancy run on the real LV: a REAL patient-derived LV (Dalton et al. 2022, "
           "MIT licence) on which the data are simulated.")

with st.sidebar:
    st.header("Results")
    extra = st.text_input("More result folders (comma-separated)", "",
                          help="--out folders of `lvcore study bo-fibres/operators/fibre-discrepancy`, or their parent")
    try:
        folders = results.parse_folders(extra)
    except LVCoreError as err:
        st.error(str(err))
        folders = []
    if "studies_runs" in st.session_state:
        folders += [r.out for r in st.session_state["studies_runs"].values()]
sources = results.result_sources(folders)


def load(study: registry.Study):
    """The chosen result set of ``study`` loaded by its module, or None (with a message saying why)."""
    opts = sources.get(study.name, [])
    if not opts:
        st.info(f"No saved results of `{study.name}` found (bundled folder: {results.bundled_studies_dir()}). "
                f"Run `lvcore study {study.name} --out DIR` and add DIR in the sidebar.")
        return None
    label = st.selectbox("Result set", [o[0] for o in opts], key=f"{study.module}_src")
    try:
        return study.load(dict(opts)[label])
    except (LVCoreError, KeyError, TypeError, ValueError) as err:
        st.error(f"cannot read the {study.name} results in {dict(opts)[label]}: {err}")
        return None


def show(module, result, figures=None, tables=()) -> None:
    """The module's figures (all, or those named) with their titles, then the named tables as data frames."""
    figs = module.figures(result)
    tabs = module.tables(result)
    for name in figures or figs:
        if name in figs:  # a long title (e.g. "... (REDUCED budget; ...)") wraps instead of running off the figure
            st.plotly_chart(wrap_title(figs[name], width=APP_TITLE_CHARS), width="stretch",
                            key=f"{module.__name__}.{name}")
    for name in tables:
        if name in tabs:
            st.caption(module.TITLES.get(name, name.replace("_", " ")))
            table(tabs[name].round(4))  # "–", never None; a verdict's note in full


def verdict_section(heading: str):
    """A study whose findings are verdicts with CIs: its heading, source, verdict table and figures."""
    def draw(study: registry.Study) -> None:
        st.subheader(heading)
        res = load(study)
        if res is not None:
            module = study.load_module()
            st.caption(module.source_line(res))
            show(module, res, tables=["verdicts"])
    return draw


def draw_bo_fibres(study: registry.Study) -> None:
    res = load(study)
    if res is not None and res["entries"]:
        meta = res["meta"]
        budget = meta.get("budget", {})
        runs = f"{len(meta.get('runs', res['entries']))} of 16 volunteer × mode runs"
        if budget and (not budget.get("chapter_budget") or not meta.get("complete_study", True)):
            st.warning(f"Budget: {budget.get('label')}; {runs}. This is not the chapter's full run.")
        elif budget:
            st.success(f"Budget: {budget.get('label')}")
        st.markdown("**Findings**\n\n" + bo_fibres.format_findings(meta.get("findings", {})).replace("\n", "\n\n"))
        st.subheader("Tables 9.2 (angles fixed at −60°, 90°) and 9.3 (angles optimised)")
        show(bo_fibres, res, figures=["fig_bo_lvv_error", "fig_strain_residuals", "fig_convergence"],
             tables=["table9_2_bo_fixed_angles", "table9_3_bo_free_angles", "angles_vs_hidden"])


def draw_operators(study: registry.Study) -> None:
    res = load(study)
    if res is not None:
        m = res.get("meta")
        if m:
            (st.warning if not m.get("complete_study") else st.info)(
                f"{m.get('budget')}; {m.get('n_fits')} fits, resolution {m.get('settings', {}).get('resolution')}")
        if res.get("findings"):
            st.markdown("**Findings**\n\n" + operators.format_findings(res["findings"]).replace("\n", "\n\n"))
        show(operators, res, figures=["fig9_11_forward_strain_error", "fig9_14_output_error", "fig_mahalanobis",
                                      "fig9_12_parameter_error"], tables=["fits"])
        if res.get("surfaces"):
            labels = [f"{s['patient']} main {s['main_operator']} test {s['test_geometry']}" for s in res["surfaces"]]
            i = st.selectbox("Loss surface (Fig 9.13) of fit", range(len(labels)), format_func=labels.__getitem__)
            st.plotly_chart(wrap_title(operators.surface_figure(res, i), width=APP_TITLE_CHARS), width="stretch")


def draw_geometry_operators(study: registry.Study) -> None:
    @st.cache_data(show_spinner=False)
    def _table94():
        return {"table": geometry_operators.operator_table(), "geometry_effect": None}

    try:
        show(geometry_operators, _table94())
    except LVCoreError as err:
        st.error(str(err))


def draw_findings(study: registry.Study) -> None:
    """The verdicts, from the result set chosen for the first input study (the mismatch dose-response)."""
    first = registry.STUDIES[study.inputs[0]]
    opts = dict(sources[first.name])
    folder = opts.get(st.session_state.get(f"{first.module}_src")) or next(iter(opts.values()), None)
    module = study.load_module()
    try:
        res = study.load(folder)
    except (LVCoreError, KeyError, TypeError, ValueError, FileNotFoundError) as err:
        st.error(f"cannot compute the findings table: {err}")
        return
    st.subheader("The chapter's findings: verdicts")
    table(module.tables(res)["table_findings"])
    st.caption(module.source_line(res))


def draw_mismatch(study: registry.Study) -> None:
    res = load(study)
    if res is not None:
        module = study.load_module()
        st.caption(module.source_line(res))
        st.subheader("Dose–response")
        show(module, res, figures=["fig_mismatch_sigma_s_inflation", "fig_mismatch_discrepancy_sigma_s",
                                   "fig_mismatch_output_error"], tables=["table_mismatch_doses"])


def draw_sbc(study: registry.Study) -> None:
    st.write("Simulation-based calibration of `lvcore calibrate` (mesh and `--geometry infer`) on SYNTHETIC "
             "subjects drawn from the prior, with the truth by the FE simulator: if the pipeline is calibrated, the "
             "truth's rank among the posterior draws is uniform (`lvcore study sbc --help`).")
    res = load(study)
    if res is not None:
        module = study.load_module()
        st.caption(module.source_line(res))
        if not res.get("complete", True):
            st.warning(f"Incomplete run: {res['n_subjects']} of {res.get('n_subjects_planned')} subjects; the "
                       "coverage CIs say how little so few subjects can show.")
        show(module, res, figures=["fig_sbc_coverage", "fig_sbc_rank_histograms"],
             tables=["table_sbc_summary", "runs"])


def draw_information(study: registry.Study) -> None:
    st.write("What pins the stiffness: with one pressure, 24 strains and one volume, a and b are fixed only as a "
             "combination. How much do a second and third loaded state, the Klotz EDPVR prior and a hierarchical "
             "fit of a cohort narrow a's 90 % interval, and is the truth still covered? SYNTHETIC subjects "
             "(`lvcore study information --help`).")
    res = load(study)
    if res is not None:
        module = study.load_module()
        st.caption(module.source_line(res))
        if not res.get("complete", True):
            st.warning(f"{module.incomplete_text(res).capitalize()}; the numbers are those of the finished runs.")
        show(module, res, figures=["fig_information_a_ratio", "fig_information_v30_width"],
             tables=["verdicts", "table_information_variants"])
        if res.get("notes"):
            with st.expander("Notes"):
                st.markdown("\n".join(f"* {n}" for n in res["notes"]))


def draw_default(study: registry.Study, tables=()) -> None:
    """Any study without a layout of its own: its source, its figures, and the named tables."""
    res = load(study)
    if res is not None:
        module = study.load_module()
        st.caption(module.source_line(res))
        show(module, res, tables=tables)


#: The studies with a layout of their own (by registry name); every other study is drawn by :func:`draw_default`.
DRAW = {"bo-fibres": draw_bo_fibres, "operators": draw_operators, "geometry-operators": draw_geometry_operators,
        "mismatch": draw_mismatch, "findings": draw_findings, "sbc": draw_sbc, "information": draw_information,
        "fibre-discrepancy": lambda study: draw_default(study, tables=["sets"]),
        "bo-mismatch": verdict_section("F6 as a real test: data with a known mismatch"),
        "operators-realistic": verdict_section("F4/F5 with realistic operators (whole slices, trabeculae, "
                                               "breath-hold shifts)")}

study_tabs = registry.tabs()
*tabs, tab_run = st.tabs([*study_tabs, "Run a small study"])
for tab, studies in zip(tabs, study_tabs.values()):
    with tab:
        for s in studies:
            DRAW.get(s.name, draw_default)(s)

with tab_run:
    st.write("Start a small run (fast mesh) in the background; the page stays usable while it runs and its "
             "results appear in the tabs above when it is done.")
    runs = st.session_state.setdefault("studies_runs", {})
    c1, c2, c3 = st.columns(3)
    study = c1.selectbox("Study", ["bo-fibres", "operators"])
    if study == "bo-fibres":
        subject = c2.selectbox("Volunteer", bo_fibres.available_subjects())
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
