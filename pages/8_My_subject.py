"""My subject: one's own geometry and measurements, from upload to a calibrated, downloadable result."""
from __future__ import annotations

import streamlit as st

from lvcore.units import rms_mm_from_mse_cm2
from lvcore.app import freshness, physiology_panel, subject_flow as flow
from lvcore.app.controls import shared_inputs
from lvcore.emulator.io import available_emulators, load_emulator
from lvcore.exceptions import LVCoreError
from lvcore.inference.models import MODEL_LABELS
from lvcore.inference.samplers import SamplerConfig
from lvcore.viz.inference_figures import display_name
from lvcore.resources import bundled_volunteers, volunteer_files
from lvcore.uploads import session_uploads

st.set_page_config(page_title="My subject", layout="wide")
st.title("My subject")
st.caption("From your subject's geometry and measurements to a calibrated θ = (a, b, a_f, b_f) and a download. "
           "Each step shows what it used; results grey out when an input changes.")


@st.cache_resource(show_spinner=False)
def _emulator(name: str):
    return load_emulator(name)


uploads = session_uploads()
shared = shared_inputs(theta=False)

# ----------------------------------------------------------------------------- 1. geometry
st.header("1 · Geometry")
g1, g2 = st.columns([2, 1])
with g1:
    up_geom = st.file_uploader("Geometry: a volume mesh (.vtu/.vtk/.msh/.inp, fitted to the template), a template "
                               "mesh, or PC scores (.json/.csv)", type=list(flow.GEOMETRY_TYPES), key="my_geometry")
    units = st.radio("Mesh length units", ["mm", "cm", "m"], horizontal=True, key="my_units")
    example = st.selectbox("…or a bundled SYNTHETIC example", ["(none)"] + bundled_volunteers(), key="my_example",
                           help="Generated data, not a real subject; useful to try the flow.")
    ref_volume = st.number_input("Reference (early-diastolic) cavity volume, mL (optional, 0 = not measured)",
                                 min_value=0.0, max_value=500.0, value=0.0, step=1.0, key="my_ref_volume")
geometry, geometry_name, measured_bytes = None, None, None
try:
    if up_geom is not None:
        geometry_name = up_geom.name
        geometry = flow.read_geometry(uploads, up_geom.name, up_geom.getvalue(), units=units)
    elif example != "(none)":
        files = volunteer_files(example)
        geometry_name = files.geometry.name
        geometry = flow.read_geometry(uploads, files.geometry.name, files.geometry.read_bytes())
        measured_bytes = (files.measured.name, files.measured.read_bytes())
except LVCoreError as err:
    st.error(f"Geometry: {err}")
if geometry is not None:
    info, volume_warnings = flow.geometry_measures(geometry, ref_volume or None)
    with g2:
        from lvcore.viz.geometry_views import render_shape

        st.image(render_shape(flow.geometry_nodes(geometry), title="what the emulator sees"),
                 caption=f"{geometry_name}: shape-model reconstruction × scale {geometry.scale:.3f}")
    st.write(f"Read as **{geometry.kind}**; cavity {info['cavity_volume_ml']:.1f} mL, wall "
             f"{info['wall_volume_ml']:.1f} mL, length {info['length_mm']:.1f} mm"
             + (f"; fit residual {geometry.fit_residual_mm:.2f} mm" if geometry.fit_residual_mm is not None else "")
             + (f"; projection error {geometry.projection_mse_cm2:.4f} cm² mean squared node distance "
                f"({rms_mm_from_mse_cm2(geometry.projection_mse_cm2):.2f} mm RMS)"
                if geometry.projection_mse_cm2 is not None else ""))
    for w in list(geometry.warnings) + volume_warnings:
        st.warning(w)

# ----------------------------------------------------------------------------- 2. measurements
st.header("2 · Measurements")
d1, d2 = st.columns([2, 1])
with d1:
    up_data = st.file_uploader("LVV + 24 regional strains (CSV/JSON/.mat; lvcore's 6 × 4 regions or AHA-16)",
                               type=list(flow.DATA_TYPES), key="my_data")
    segments = st.radio("Strain segments", ["as the file says", "lvcore", "aha"], horizontal=True, key="my_segments")
rows = []
try:
    if up_data is not None:
        rows = flow.read_data(uploads, up_data.name, up_data.getvalue(),
                              None if segments == "as the file says" else segments)
    elif measured_bytes is not None:
        rows = flow.read_data(uploads, *measured_bytes)
except LVCoreError as err:
    st.error(f"Measurements: {err}")
data = None
if rows:
    data = rows[0] if len(rows) == 1 else next(
        r for r in rows if r.subject == d2.selectbox("Subject", [r.subject for r in rows], key="my_subject_row"))
    st.write(f"**{data.subject}**: LVV {data.lvv_ml:.1f} mL; strains {data.strains.min():.3f} to "
             f"{data.strains.max():.3f}")
    if data.subject.upper().startswith("SYNTHETIC"):
        st.caption("⚠ SYNTHETIC data: generated, not a real subject.")

# ----------------------------------------------------------------------------- 3. model and box check
st.header("3 · Model")
names = available_emulators()
m1, m2, m3 = st.columns(3)
emu_name = m1.selectbox("Emulator", names, index=names.index(shared["emulator"]) if shared.get("emulator") in names
                        else 0, key="my_emulator")
edp = m2.number_input("EDP (mmHg)", min_value=0.0, max_value=40.0, value=float(shared.get("edp_mmhg", 8.0)),
                      step=0.5, key="my_edp")
models = m3.multiselect("Likelihood(s)", list(MODEL_LABELS), default=["iid"], format_func=MODEL_LABELS.get,
                        key="my_models")
c1, c2, c3 = st.columns(3)
chains = c1.number_input("chains", 1, 8, 2, key="my_chains")
warmup = c2.number_input("warm-up", 50, 5000, 500, step=50, key="my_warmup")
draws = c3.number_input("draws kept", 50, 5000, 500, step=50, key="my_draws")
prepared = None
if geometry is not None:
    try:
        prepared = flow.prepare(_emulator(emu_name), emu_name, geometry, edp_mmhg=edp)
    except LVCoreError as err:
        st.error(f"Model: {err}")
if prepared is not None:
    st.dataframe(prepared.box, width="stretch", hide_index=True)
    if prepared.extrapolating:
        st.warning("EXTRAPOLATION: some inputs lie outside the emulator's training box; the results are flagged.")
    st.caption(f"Conditions used: EDP {prepared.conditions['edp_mmhg']:.2f} mmHg, fibre angles "
               f"{prepared.conditions['alpha_endo']:.0f}° / {prepared.conditions['alpha_epi']:.0f}°.")

# ----------------------------------------------------------------------------- 4. calibrate
st.header("4 · Calibrate")
settings = {"geometry": geometry_name, "units": units, "reference_volume_ml": ref_volume or None,
            "subject": None if data is None else data.subject, "emulator": emu_name, "edp_mmhg": float(edp),
            "models": list(models), "chains": int(chains), "warmup": int(warmup), "draws": int(draws)}
if st.button("Run calibration", type="primary", key="my_run",
             disabled=prepared is None or data is None or not models):
    with st.status("Calibrating…", expanded=True) as status:
        config = SamplerConfig(num_warmup=int(warmup), num_samples=int(draws), num_chains=int(chains))
        try:
            runs = flow.calibrate(data.subject, data.y, prepared, models, config=config,
                                  progress=lambda msg, frac: status.update(label=f"Calibrating: {msg}"))
        except LVCoreError as err:
            st.error(str(err))
            runs = None
        if runs:
            summary = flow.summary_record(data.subject, data.y, geometry, prepared, runs, settings)
            figures = flow.figures(runs, data.y)
            st.session_state["my_subject_run"] = freshness.Stored(
                {"runs": runs, "summary": summary, "figures": figures,
                 "zip": flow.bundle(summary, runs, figures)}, dict(settings))
            status.update(label="Calibration done", state="complete")

stored = st.session_state.get("my_subject_run")
if stored is not None:
    with freshness.shown(stored, settings, "my subject"):
        summary = stored.result["summary"]
        for run in stored.result["runs"]:
            record = summary["models"][run.model]  # the banner of summary_record: convergence and bound flags
            getattr(st, "success" if record["converged_cleanly"] else "warning")(
                f"{MODEL_LABELS[run.model]}: {record['convergence']}")
            for flag in run.check.flags:
                st.warning(f"{MODEL_LABELS[run.model]}: flagged: {flag}")
            st.dataframe(run.result.summary.rename(index=display_name), width="stretch")
        for name, fig in stored.result["figures"].items():
            st.plotly_chart(fig, width="stretch", key=f"my_fig_{name}")
        if geometry is not None and prepared is not None and data is not None:
            physiology_panel.show({MODEL_LABELS[r.model]: r.result.idata for r in stored.result["runs"]},
                                  h=geometry.h, scale=float(geometry.scale), edp_mmhg=prepared.conditions["edp_mmhg"],
                                  angles=(prepared.conditions["alpha_endo"], prepared.conditions["alpha_epi"]),
                                  measured_lvv_ml=float(data.lvv_ml), subject=summary["subject"], key="my_edpvr")
        st.header("5 · Download")
        st.download_button("Download everything (zip: netCDF, figures, settings.json, summary.html)",
                           stored.result["zip"], file_name=f"{summary['subject']}_lvcore.zip",
                           mime="application/zip", key="my_zip")
