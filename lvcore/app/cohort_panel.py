"""The Calibration page's Cohort section: a cohort CSV in, the hierarchical calibration's population and
per-subject estimates out.

Thin: the upload is saved in the session's folder (:mod:`lvcore.app.uploads`), the run is
:func:`lvcore.inference.hierarchical_cli.calibrate_cohort` with the command line's defaults
(:func:`~lvcore.inference.hierarchical_cli.cohort_args`) and shorter chains, and the figure is
:func:`lvcore.viz.inference_figures.cohort_figure`. A SYNTHETIC demo cohort
(:func:`lvcore.inference.cohort.synthetic_cohort`) runs without an upload.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

#: The app's chains: 2 x (300 + 300) (the command line's default is 4 x (1000 + 1000)).
APP_SAMPLER = {"chains": 2, "warmup": 300, "samples": 300}
#: Subjects of the SYNTHETIC demo cohort (two groups, group B's population a twice group A's).
DEMO_SUBJECTS = 6


def population_table(rec: dict) -> pd.DataFrame:
    """One row per group and parameter: the population median theta (exp mu) with its 90 % interval and the
    population sd of log theta."""
    rows = []
    for g, grp in rec["population"]["groups"].items():
        for k, q in grp["median_theta"].items():
            sd = rec["population"]["sd"][k]
            rows.append({"group": g, "parameter": k, "median": q["median"], "q05": q["q05"], "q95": q["q95"],
                         "sd of log θ": sd["median"]})
    return pd.DataFrame(rows)


def subject_table(rec: dict) -> pd.DataFrame:
    """One row per subject and parameter: the joint and separate 90 % intervals and the shrinkage."""
    rows = []
    shr = rec.get("shrinkage", {}).get("per_subject", {})
    for s, q in rec["subjects"].items():
        for k in ("a", "b", "af", "bf"):
            sep = rec.get("separate", {}).get(s, {}).get(k, {})
            rows.append({"subject": s, "parameter": k, "joint median": q[k]["median"], "joint q05": q[k]["q05"],
                         "joint q95": q[k]["q95"], "separate q05": sep.get("q05"), "separate q95": sep.get("q95"),
                         "shrinkage": shr.get(s, {}).get(k, {}).get("shrinkage")})
    return pd.DataFrame(rows)


def difference_table(rec: dict) -> pd.DataFrame:
    """One row per pair of groups and parameter: the ratio of the population medians with its 90 % interval, and
    the same ratio from the separate fits (subjects resampled) where they were made."""
    sep = rec["population"].get("differences_separate", {})
    rows = []
    for pair, d in rec["population"]["differences"].items():
        for k, v in d.items():
            row = {"groups": pair, "parameter": k, "ratio median": v["ratio"]["median"], "ratio q05": v["ratio"]["q05"],
                   "ratio q95": v["ratio"]["q95"], "interval excludes 1": v["excludes_zero"]}
            w = sep.get(pair, {}).get(k)
            if w is not None:
                row.update({"separate fits: ratio q05": w["ratio"]["q05"], "separate fits: ratio q95": w["ratio"]["q95"],
                            "separate fits: excludes 1": w["excludes_zero"]})
            rows.append(row)
    return pd.DataFrame(rows)


def demo_cohort(folder) -> Path:
    """Write the SYNTHETIC demo cohort into ``folder`` and return its CSV."""
    from lvcore.emulator.io import load_emulator
    from lvcore.inference.cohort import synthetic_cohort, write_cohort

    return write_cohort(synthetic_cohort(DEMO_SUBJECTS, load_emulator("chapter"), seed=0, n_groups=2), folder)


def run_cohort(csv, out, geometry: str | None = None) -> dict:
    """The hierarchical calibration of the cohort ``csv`` at the app's sampler settings (summary.json's
    ``hierarchical`` section)."""
    from lvcore.inference.hierarchical_cli import calibrate_cohort, cohort_args

    args = cohort_args(csv, out, geometry=geometry, **APP_SAMPLER)
    return calibrate_cohort(args, say=lambda msg: None, progress_bar=False)


def show(st) -> None:
    """Render the Cohort section (upload or demo, run, population, differences, subjects, figure)."""
    from lvcore.app.uploads import UploadError, session_uploads
    from lvcore.exceptions import LVCoreError
    from lvcore.viz.inference_figures import cohort_figure

    st.header("Cohort")
    st.caption("One joint posterior for several subjects: log θ of each subject drawn from one population "
               "N(μ, Σ), every subject through its own geometry and noise (lvcore calibrate --hierarchical; "
               f"here {APP_SAMPLER['chains']} chains x ({APP_SAMPLER['warmup']} + {APP_SAMPLER['samples']})). "
               "The CSV: subject, optional group and geometry (PC-scores file, mean or infer), lvv_ml, "
               "strain_01 .. strain_24; geometry files named in it are uploaded beside it.")
    files = st.file_uploader("Cohort CSV (and its geometry files)", type=["csv", "json"], accept_multiple_files=True,
                             key="cohort_upload")
    geometry = st.selectbox("Geometry of subjects without a geometry column", ["mean", "infer"], key="cohort_geometry")
    c1, c2 = st.columns(2)
    run_upload = c1.button("Calibrate the uploaded cohort", disabled=not files, key="cohort_run")
    run_demo = c2.button(f"SYNTHETIC demo cohort ({DEMO_SUBJECTS} subjects, two groups)", key="cohort_demo")
    if run_upload or run_demo:
        uploads = session_uploads()
        try:
            if run_demo:
                csv = demo_cohort(uploads.path / "cohort_demo")
            else:   # the CSV and the geometry files it names side by side in the session's folder
                csvs = [uploads.save(f.name, f.getvalue()) for f in files if f.name.lower().endswith(".csv")]
                for f in files:
                    if not f.name.lower().endswith(".csv"):
                        uploads.save(f.name, f.getvalue())
                if len(csvs) != 1:
                    raise UploadError("upload exactly one cohort CSV (and the geometry files it names)")
                csv = csvs[0]
            with st.spinner("Sampling the joint posterior and the separate fits (a few minutes)..."):
                st.session_state["cohort_result"] = run_cohort(csv, uploads.path / "cohort_out", geometry)
        except (LVCoreError, UploadError) as err:
            st.error(uploads.message(str(err)))
            return
    rec = st.session_state.get("cohort_result")
    if rec is None:
        return
    level = "success" if rec["converged"] else "warning"
    getattr(st, level)(" ".join(f"{lv}: {'converged' if d['converged'] else 'NOT CONVERGED'} (max R-hat "
                                f"{d['max_rhat']:.3f}, min ESS {d['min_ess_bulk']:.0f});" for lv, d in
                                rec["diagnostics"].items())
                       + f" {rec['diagnostics']['population']['n_divergent']} divergent")
    for w in rec.get("warnings") or ():
        st.warning(w)
    for f in rec.get("flags") or ():
        st.error(f)
    st.subheader("Population")
    st.dataframe(population_table(rec), width="stretch", hide_index=True)
    if rec["population"]["differences"]:
        st.dataframe(difference_table(rec), width="stretch", hide_index=True)
    st.subheader("Subjects")
    st.plotly_chart(cohort_figure(rec, "a"), width="stretch", key="cohort_fig")
    st.dataframe(subject_table(rec), width="stretch", hide_index=True)


__all__ = ["show", "population_table", "subject_table", "difference_table", "run_cohort", "demo_cohort",
           "APP_SAMPLER"]
