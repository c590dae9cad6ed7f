"""LV Calibration Lab: the home page, the Simulator.

Started through the app's navigation (``lvcore app`` or ``streamlit run
app.py``; :mod:`lvcore.app.main`); the other pages live in the repository's ``pages/``. This
page only gathers inputs and shows results: the science is in :mod:`lvcore`
(simulation, export) and :mod:`lvcore.viz` (figures, 3-D pictures).
"""
from __future__ import annotations

import json

import numpy as np
import streamlit as st

from lvcore.domain import conditions, physiology, units
from lvcore.app import PAGES
from lvcore.app.controls import THETA_LABELS, THETA_RANGES, log_options, theta_slider  # noqa: F401 (shared log sliders)
from lvcore.exceptions import LVCoreError
from lvcore.mechanics.case import Case, loads_case
from lvcore.mechanics.resolution import RESOLUTION_PRESET_NAMES
from lvcore.resources import example_cases

RESOLUTIONS = RESOLUTION_PRESET_NAMES

st.set_page_config(page_title="LV Calibration Lab", page_icon="🫀", layout="wide")


@st.cache_data(show_spinner=False, max_entries=64)
def run_simulation(case_json: str) -> dict:
    """Simulate a case (given as JSON, the cache key); plain data for the page."""
    from lvcore.mechanics.export import result_vtu_bytes
    from lvcore.mechanics.simulate import simulate

    case = Case.from_dict(json.loads(case_json))
    try:
        result = simulate(case)
    except LVCoreError as err:
        return {"converged": False, "error": f"{type(err).__name__}: {err}"}
    out = {"converged": bool(result.converged), "summary": result.to_dict(),
           "reference_nodes": np.asarray(result.reference_nodes), "elements": np.asarray(result.elements),
           "displacement": None if result.displacement is None else np.asarray(result.displacement)}
    if result.converged:
        out["vtu"] = result_vtu_bytes(result, case)
    return out


@st.cache_data(show_spinner=False, max_entries=64)
def render_picture(case_json: str, view: str) -> bytes:
    """PNG of the reference (wireframe) and deformed (coloured by |u|) LV of a simulated case."""
    from lvcore.viz.mesh3d import render_reference_and_deformed

    sim = run_simulation(case_json)
    ref = sim["reference_nodes"]
    return render_reference_and_deformed(ref, ref + sim["displacement"], sim["elements"], view=view,
                                         reference_label="reference (unloaded)",
                                         window_size=(720, 560))


def page_links() -> None:
    others = PAGES[1:]  # the first is this page
    st.markdown("**Pages**")
    cols = st.columns(min(len(others), 4))
    for k, page in enumerate(others):
        with cols[k % len(cols)]:
            st.page_link(str(page.path), label=page.title, icon=page.icon)


# ----------------------------------------------------------------------------
st.title("LV Calibration Lab")
st.markdown(
    "Estimate the passive stiffness of the left-ventricular (LV) myocardium from cardiac-MRI measurements: "
    "a finite-element simulator of diastolic filling (Holzapfel–Ogden law), a PCA shape model of LV "
    "geometry, neural-network emulators and Bayesian calibration with a model-discrepancy term. "
    "Use the pages in the sidebar; this page is the **simulator**."
)
page_links()

st.header("Simulator")
st.caption(
    "Inflates the default LV (a mildly elliptical, tapered truncated ellipsoid of physiological size; not patient "
    "data) from its "
    "early-diastolic reference geometry to the end-diastolic pressure (EDP). Outputs: the end-diastolic cavity "
    "volume LVV and 24 regional circumferential Green strains (end diastole as reference, negative in filling). "
    "The sliders start at a typical healthy stiffness (see *Explain the numbers*)."
)

with st.expander("Explain the numbers"):
    _d = conditions.SIMULATOR_DEFAULT_THETA
    _c = conditions.THETA_TILDE
    st.markdown(
        f"- **Why these starting values: a typical healthy LV.** The sliders start at a = {_d['a']:.2f} kPa, "
        f"b = {_d['b']:.2f}, a_f = {_d['af']:.2f} kPa, b_f = {_d['bf']:.2f}: the healthy-volunteer Holzapfel–Ogden "
        "values of the Glasgow LV models that go with the fixed sheet terms below (Gao et al. 2017, after Gao et al. "
        "2015), as in `assets/cases/default_lv.json`. At 8 mmHg they fill the default LV from V₀ ≈ 86 mL to about "
        "159 mL, **EDV/V₀ ≈ 1.85**, inside the typical 1.66–1.99 of a normal LV (Klotz et al. 2006, shown under the "
        "metrics).\n"
        "- **V₀** is the cavity of the *unloaded, stress-free* reference geometry, not an early-diastolic volume "
        "measured under pressure, so EDV/V₀ is the whole passive filling from zero stress.\n"
        f"- **The chapter's θ̃** (a = {_c['a']:.2f} kPa, b = {_c['b']:.2f}, a_f = {_c['af']:.2f} kPa, "
        f"b_f = {_c['bf']:.2f}), the truth of the SYNTHETIC studies and the starting point of the Emulator and Fibre "
        "angles pages, has a 3× softer fibre term and fills the same LV to about 185 mL, EDV/V₀ ≈ 2.14, above the "
        "typical range: the Holzapfel–Ogden law is soft at small stretch, the wall is thin (9–10 mm for a 24 mm "
        "cavity radius) and the model has no residual stress, pericardium or active tension, so a soft θ roughly "
        "doubles the passive cavity. An EDV/V₀ more than 2 % outside the typical range is flagged under the metrics "
        "(above: the model inflates more than a normal LV, soft or thin-walled; below: less, stiff or thick-walled).\n"
        "- **Sector-to-sector strain differences on the default LV.** The default LV is not axisymmetric: its "
        "cross-section is mildly elliptical (endocardial short radii 24.0 and 21.5 mm, epicardial 33.5 and "
        "31.0 mm) and it tapers to the apex, the base is clamped, and the rule-based fibres wind helically "
        "through the wall. Curvature, wall thickness and fibre direction therefore vary around each ring, and "
        "so does the circumferential strain, even though no patient data are involved."
    )

with st.form("simulator"):
    c1, c2, c3 = st.columns(3)
    theta = {}
    with c1:
        st.markdown("**Material (Holzapfel–Ogden)**")
        for name in ("a", "b"):
            theta[name] = theta_slider(name, key=name, default=conditions.SIMULATOR_DEFAULT_THETA[name])
    with c2:
        st.markdown("**Material, fibre terms**")
        for name in ("af", "bf"):
            theta[name] = theta_slider(name, key=name, default=conditions.SIMULATOR_DEFAULT_THETA[name])
        fixed = conditions.HO_FIXED
        st.caption(f"Fixed: a_s = {fixed['as']:g} kPa, b_s = {fixed['bs']:g}, a_fs = {fixed['afs']:g} kPa, "
                   f"b_fs = {fixed['bfs']:g} (Gao et al. 2017).")
    with c3:
        st.markdown("**Conditions**")
        alpha_endo = st.slider("α_endo (deg)", -90, 90, int(conditions.SIMULATOR_DEFAULT_ANGLES[0]), key="alpha_endo")
        alpha_epi = st.slider("α_epi (deg)", -90, 90, int(conditions.SIMULATOR_DEFAULT_ANGLES[1]), key="alpha_epi")
        edp = st.slider("EDP (mmHg)", 2.0, 30.0, float(conditions.SIMULATOR_DEFAULT_EDP_MMHG), step=0.5, key="edp")
        resolution = st.radio("Resolution", RESOLUTIONS, index=0, horizontal=True, key="resolution",
                              help="fast: seconds, for exploring; coarse (lvcore 0.1's default)/default/accurate: finer meshes (slower; the first "
                                   "solve at a new resolution also compiles the FE kernels).")
    st.form_submit_button("Simulate", type="primary")



def show_failure(sim: dict) -> None:
    """A clear message for a failed solve (no traceback)."""
    reason = sim.get("error") or sim["summary"]["message"]
    st.error(f"The solver did not converge for these inputs: {reason}. Try a lower pressure, stiffer parameters "
             "or another resolution.")
    if "summary" in sim:
        with st.expander("Solver diagnostics"):
            st.json(sim["summary"])


def show_picture(case_json: str, key: str, caption: str) -> None:
    view = st.radio("View", ("iso", "side", "front", "base", "apex"), horizontal=True, key=key)
    try:
        st.image(render_picture(case_json, view), caption=caption)
    except Exception as err:  # rendering is optional: never hide the numbers
        st.warning(f"3-D picture unavailable ({type(err).__name__}: {err})")


def show_simulator_result(case: Case, case_json: str, sim: dict) -> None:
    from lvcore.viz import figures

    summary = sim["summary"]
    vol = summary["cavity_volume_ml"]
    for warning in summary.get("warnings") or []:  # implausible results are shown, and flagged
        st.warning(warning)
    m1, m2, m3, m4 = st.columns(4)
    m1.metric("LVV (end diastole)", f"{vol['loaded']:.1f} mL")
    m2.metric("V₀ (reference cavity)", f"{vol['reference']:.1f} mL")
    typical = physiology.typical_edv_ratio(units.kpa_to_mmhg(case.load.pressure_kpa))
    m3.metric("EDV/V₀", f"{summary['lvv_standardised']:.3f}",
              help="End-diastolic over reference (stress-free) cavity volume; " + typical.text() + ".")
    m4.metric("Mean E_cc", f"{np.mean(summary['strains']):.3f}")
    st.caption(f"EDV/V₀ = {summary['lvv_standardised']:.2f}; {typical.text()}.")

    left, right = st.columns([1.1, 1])
    with left:
        tab_map, tab_bull, tab_bars = st.tabs(["Strain map", "Bull's eye", "Bars"])
        strains = np.asarray(summary["strains"])
        with tab_map:
            st.plotly_chart(figures.strain_heatmap(strains), width="stretch")
        with tab_bull:
            st.plotly_chart(figures.strain_bullseye(strains), width="stretch")
        with tab_bars:
            st.plotly_chart(figures.strain_bars({"simulated": strains}), width="stretch")
    with right:
        show_picture(case_json, "view", "Reference (black element edges) and end-diastolic LV coloured by "
                                        "displacement (mm)")

    with st.expander("Solver diagnostics"):
        st.write(f"{summary['newton_iterations']} Newton iterations over {summary['load_steps']} load steps, "
                 f"{summary['dofs']} degrees of freedom, {summary['seconds']:.2f} s "
                 "(cached results are not re-timed).")
        st.json({k: summary[k] for k in ("message", "apex", "newton_iterations", "load_steps", "dofs", "seconds")})

    d1, d2, d3 = st.columns(3)
    d1.download_button("Download mesh + displacement (VTU)", sim["vtu"], file_name="lv_simulation.vtu",
                       mime="application/octet-stream", key="dl_vtu")
    d2.download_button("Download result (JSON)", json.dumps(summary, indent=2), file_name="lv_simulation_result.json",
                       mime="application/json", key="dl_json")
    d3.download_button("Download case (JSON)", case.to_json(), file_name="lv_case.json", mime="application/json",
                       key="dl_case", help="Run it again with `lvcore simulate lv_case.json`.")


case = Case.default_lv(theta, alpha_endo, alpha_epi, edp, resolution)
case_json = case.to_json(indent=None)
with st.spinner("Solving…"):
    sim = run_simulation(case_json)
if sim["converged"]:
    show_simulator_result(case, case_json, sim)
else:
    show_failure(sim)

# ----------------------------------------------------------------------------
st.header("Run a case file")
st.caption("Any geometry, law and load of the case schema (docs/case_schema.md), e.g. the Land et al. (2015) "
           "benchmarks. The same as `lvcore simulate CASE.json` on the command line.")
EXAMPLES = example_cases()
example = st.selectbox("Start from an example", list(EXAMPLES), key="example") if EXAMPLES else None
with st.form("case_runner"):
    text = st.text_area("Case JSON", EXAMPLES[example].read_text() if example else "", height=220,
                        key=f"case_text_{example}")
    run_case = st.form_submit_button("Run case")
if run_case:
    st.session_state["case_runner_input"] = (text, example)

if "case_runner_input" in st.session_state:
    from lvcore.mechanics.summary import format_summary

    text, example = st.session_state["case_runner_input"]
    base_dir = EXAMPLES[example].parent if example else None
    try:
        user_case = loads_case(text, base_dir=base_dir)  # strict JSON and the limits of a case file
    except LVCoreError as err:
        field = getattr(err, "field", None)
        st.error(f"Bad case: field `{field}`: {err.problem}" if field else f"Bad case: {err}")
    else:
        user_json = user_case.to_json(indent=None)
        with st.spinner("Solving the case…"):
            user_sim = run_simulation(user_json)
        if user_sim["converged"]:
            c1, c2 = st.columns([1, 1])
            c1.code(format_summary(user_sim["summary"]), language=None)
            with c2:
                show_picture(user_json, "case_view", f"Reference edges and deformed {user_case.geometry.source}, "
                                                     "coloured by displacement (mm)")
            st.download_button("Download mesh + displacement (VTU)", user_sim["vtu"], file_name="case_result.vtu",
                               mime="application/octet-stream", key="dl_case_vtu")
        else:
            show_failure(user_sim)
