"""My subject: one's own geometry and measurements, from upload to a calibrated, downloadable result."""
from __future__ import annotations

from pathlib import Path

import streamlit as st

from lvcore.domain.units import rms_mm_from_mse_cm2
from lvcore.app import freshness, physiology_panel, subject_emulator_panel, subject_flow as flow
from lvcore.app import warmup as app_warmup
from lvcore.app.emulators import cached_emulator
from lvcore.app.tables import number_column, summary_view
from lvcore.app.controls import (chosen_index, conditions_text, disabled_hint, discrepancy_kernel_choice,
                                 remember_choice, shared_inputs, why_disabled)
from lvcore.domain.conditions import SIMULATOR_DEFAULT_EDP_MMHG
from lvcore.emulator.io import available_emulators
from lvcore.exceptions import LVCoreError
from lvcore.inference.diagnostics import banner_status
from lvcore.inference.models import MODEL_LABELS
from lvcore.inference.samplers import SamplerConfig
from lvcore.viz.inference_figures import display_name
from lvcore.resources import bundled_volunteers, volunteer_files
from lvcore.app.uploads import session_uploads

st.set_page_config(page_title="My subject", layout="wide")
st.title("My subject")
st.caption("From your subject's geometry and measurements to a calibrated θ = (a, b, a_f, b_f) and a download. "
           "Each step shows what it used; results grey out when an input changes.")


uploads = session_uploads()
shared_inputs(theta=False, edp=False)  # own EDP (step 3, as lvcore calibrate --edp): no shared inputs in sidebar

# ----------------------------------------------------------------------------- 1. geometry
NO_MESH = "No mesh: infer it from CMR measures"
st.header("1 · Geometry")
mode = st.radio("Geometry", ["A mesh or PC scores", NO_MESH], horizontal=True, key="my_geometry_mode",
                help="No mesh: the PC scores h and the scale s are sampled with θ, informed by the volumes you "
                     "measured (lvcore calibrate --geometry infer).")
inferred = mode == NO_MESH
g1, g2 = st.columns([2, 1])
with g1:
    if not inferred:
        up_geom = st.file_uploader("Geometry: a volume mesh (.vtu/.vtk/.msh/.inp, fitted to the template), a "
                                   "template mesh, or PC scores (.json/.csv)", type=list(flow.GEOMETRY_TYPES),
                                   key="my_geometry")
        units = st.radio("Mesh length units", ["mm", "cm", "m"], horizontal=True, key="my_units")
    else:
        up_geom, units = None, "mm"
    example = st.selectbox("…or a bundled SYNTHETIC example", ["(none)"] + bundled_volunteers(), key="my_example",
                           help="Generated data, not a real subject; useful to try the flow. Without a mesh, only "
                                "its measurements are used.")
    ref_volume = st.number_input("Reference (early-diastolic) cavity volume, mL (optional, 0 = not measured)",
                                 min_value=0.0, max_value=500.0, value=0.0, step=1.0, key="my_ref_volume")
    if inferred:
        wall_volume = st.number_input(flow.MEASURE_LABELS["wall_volume_ml"] + " (optional, 0 = not measured)",
                                      min_value=0.0, max_value=600.0, value=0.0, step=1.0, key="my_wall_volume")
        long_axis = st.number_input(flow.MEASURE_LABELS["long_axis_mm"] + " (optional, 0 = not measured)",
                                    min_value=0.0, max_value=200.0, value=0.0, step=1.0, key="my_long_axis")
        entered = {"reference_volume_ml": ref_volume, "wall_volume_ml": wall_volume, "long_axis_mm": long_axis}
        from lvcore.inference.geometry_prior import MEASURE_SD

        with st.expander("Measurement SDs and the shape model's representation error"):
            sd_cols = st.columns(3)
            entered_sd = {k: sd_cols[i].number_input(
                f"SD of the {k.rsplit('_', 1)[0].replace('_', ' ')}, {'mL' if k.endswith('_ml') else 'mm'} "
                f"(0 = default {MEASURE_SD[k]:g})", min_value=0.0, max_value=50.0, value=0.0, step=0.5,
                key=f"my_{k}_sd", help="lvcore calibrate --reference-volume-sd / --wall-volume-sd / --long-axis-sd "
                                       "(or the data's *_sd column): how well your CMR analysis knows the measure")
                for i, k in enumerate(entered)}
            floor = st.checkbox("Representation-error floor (lvcore calibrate --representation-error floor)",
                                value=True, key="my_rep_floor",
                                help="adds how far a real LV is from the shape model's 5 modes (estimated from the "
                                     "SYNTHETIC cohort) to the likelihood; off only for a subject that is exactly a "
                                     "shape-model shape")
geometry, geometry_name, measured_bytes, geometry_file = None, None, None, None
try:
    if up_geom is not None:
        geometry_name = up_geom.name
        geometry_file = (uploads.save(up_geom.name, up_geom.getvalue(), slot="build_geometry"), up_geom.getvalue())
        geometry = flow.read_geometry(uploads, up_geom.name, up_geom.getvalue(), units=units)
    elif example != "(none)":
        files = volunteer_files(example)
        measured_bytes = (files.measured.name, files.measured.read_bytes())
        if not inferred:
            geometry_name = files.geometry.name
            geometry_file = (files.geometry, files.geometry.read_bytes())
            geometry = flow.read_geometry(uploads, files.geometry.name, geometry_file[1])
except LVCoreError as err:
    st.error(f"Geometry: {err}")
    geometry_file = None
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
if inferred:
    from lvcore.inference.geometry_prior import MEASURE_SD

    st.caption("No mesh: the shape model's PC scores h (prior N(0, 1) within the emulator's box) and a uniform "
               "scale s are sampled with θ, as `lvcore calibrate --geometry infer`; the measures you enter are "
               f"observed with SD {MEASURE_SD['reference_volume_ml']:g} mL (volumes) and "
               f"{MEASURE_SD['long_axis_mm']:g} mm (long axis).")

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
subject_emus = subject_emulator_panel.built_emulators()  # built in this session on a loaded geometry
names = available_emulators() + list(subject_emus)
m1, m2, m3 = st.columns(3)
emu_name = m1.selectbox("Emulator", names, index=chosen_index("emulator", names), key="my_emulator",
                        help="A shared emulator of the shape model's PC scores, or a subject emulator built below "
                             "(its geometry is bound in).")
remember_choice("emulator", emu_name)
edp = m2.number_input("EDP (mmHg)", min_value=0.0, max_value=40.0, value=float(SIMULATOR_DEFAULT_EDP_MMHG),
                      step=0.5, key="my_edp", help="lvcore calibrate --edp; a fixed-EDP emulator takes only its own.")
models = m3.multiselect("Likelihood(s)", list(MODEL_LABELS), default=["iid"], format_func=MODEL_LABELS.get,
                        key="my_models")
kernel = discrepancy_kernel_choice(models, key="my_kernel")  # greyed out unless the discrepancy likelihood is chosen
c1, c2, c3 = st.columns(3)
chains = c1.number_input("chains", 1, 8, 2, key="my_chains")
warmup = c2.number_input("warm-up", 50, 5000, 500, step=50, key="my_warmup")
draws = c3.number_input("draws kept", 50, 5000, 500, step=50, key="my_draws")
emulator = None
try:
    emulator = cached_emulator(subject_emus.get(emu_name, emu_name))
except LVCoreError as err:
    st.error(f"Emulator: {err}")
is_subject_emu = bool(getattr(emulator, "is_subject", False))
prepared, measures, used_geometry = None, None, None
try:
    if emulator is None:
        pass
    elif inferred:
        measures = flow.inferred_measures(entered, None if data is None else data.measures)
        sds, sd_sources = flow.inferred_measure_sds(entered_sd, None if data is None else data.measure_sds, measures)
        prepared = flow.prepare_inferred(emulator, emu_name, measures, edp_mmhg=edp, measure_sd=sds,
                                         measure_sd_source=sd_sources, row=data,
                                         representation_error="floor" if floor else "off")
        used_geometry = flow.InferredGeometry.of(prepared)
    elif is_subject_emu:
        prepared = flow.prepare(emulator, emu_name, geometry, edp_mmhg=edp, row=data)
        used_geometry = flow.subject_emulator_geometry(emulator)
    elif geometry is not None:
        prepared = flow.prepare(emulator, emu_name, geometry, edp_mmhg=edp, row=data)
        used_geometry = geometry
except LVCoreError as err:
    st.error(f"Model: {err}")
if prepared is not None:
    if prepared.box:
        st.dataframe(prepared.box, width="stretch", hide_index=True)
    if prepared.extrapolating:
        st.warning("EXTRAPOLATION: some inputs lie outside the emulator's training box; the results are flagged.")
    if prepared.inferred:
        rec = used_geometry.record()
        st.write("Geometric measures used: " + (", ".join(
            f"{k} {v:g} (SD {rec['measure_sd'][k]:g}, {rec['measure_sd_source'][k]}; in the likelihood "
            f"{rec['likelihood_sd'][k]:.3g})" for k, v in prepared.measures.items()) or "none"))
        st.caption(flow.floor_caption(rec["representation_error"]))
        for w in prepared.warnings:
            st.warning(w)
    elif not is_subject_emu:
        st.caption(flow.floor_caption(prepared.representation_error))
    if is_subject_emu:
        st.info(f"Subject emulator: the geometry it was built on ({Path(used_geometry.source).name}) is bound in, "
                "as it is; no PC scores are used.")
    st.caption("Conditions used: " + conditions_text(
        prepared.conditions["edp_mmhg"], (prepared.conditions["alpha_endo"], prepared.conditions["alpha_epi"]),
        emulator) + ".")
if not inferred and geometry_file is not None:
    with st.expander("Build a subject emulator for this geometry (optional, minutes)",
                     expanded=st.session_state.get("my_build_job") is not None):
        subject_emulator_panel.show(geometry_file[0], geometry_file[1], geometry_name, units=units, key="my_build")

# ----------------------------------------------------------------------------- 4. calibrate
st.header("4 · Calibrate")
settings = {"geometry": "infer" if inferred else geometry_name, "units": units,
            "reference_volume_ml": ref_volume or None, "measures": measures,
            "subject": None if data is None else data.subject, "emulator": emu_name, "edp_mmhg": float(edp),
            "models": list(models), "discrepancy_kernel": kernel if "discrepancy" in models else None,
            "chains": int(chains), "warmup": int(warmup), "draws": int(draws)}
room = app_warmup.calibration_room(models)   # a compile short of memory would abort the server: checked first
blocked = why_disabled(
    (data is None, "no measurements yet: upload LVV + 24 strains in step 2 (or pick a bundled example in step 1)."),
    (prepared is None and (inferred or geometry is not None),
     "the model is not ready: see the message in steps 1–3 (e.g. an EDP the emulator does not take)."),
    (prepared is None, "no geometry yet: upload a mesh or PC scores in step 1, or choose \"No mesh: infer it\"."),
    (not models, "no likelihood chosen: pick at least one in step 3."),
    (room is not None, room))
clicked = st.button("Run calibration", type="primary", key="my_run", disabled=blocked is not None, help=blocked)
disabled_hint(blocked)
if clicked:
    with st.status("Calibrating…", expanded=True) as status:
        config = SamplerConfig(num_warmup=int(warmup), num_samples=int(draws), num_chains=int(chains),
                               discrepancy_kernel=kernel)
        try:
            runs = flow.calibrate(data.subject, data.y, prepared, models, config=config,
                                  progress=lambda msg, frac: status.update(label=f"Calibrating: {msg}"))
        except LVCoreError as err:
            st.error(str(err))
            runs = None
        if runs:
            summary = flow.summary_record(data.subject, data.y, used_geometry, prepared, runs, settings)
            figures = flow.figures(runs, data.y, prepared=prepared)
            try:  # the derived quantities' setup: this emulator's geometry (scores and scale, its own mesh, or
                # the posterior's with an inferred geometry), resolution and base
                physiology_setup = physiology_panel.Setup.of(
                    emulator, prepared.forward, edp_mmhg=prepared.conditions["edp_mmhg"],
                    angles=(prepared.conditions["alpha_endo"], prepared.conditions["alpha_epi"]),
                    measured_lvv_ml=float(data.lvv_ml), h=None if inferred else getattr(geometry, "h", None),
                    scale=1.0 if inferred else float(getattr(geometry, "scale", 1.0)))
            except Exception as err:  # noqa: BLE001 - the results stay; the panel says why it is missing
                st.warning(f"The EDPVR and derived quantities will not be available ({type(err).__name__}: {err}).")
                physiology_setup = None
            st.session_state["my_subject_run"] = freshness.Stored(
                {"runs": runs, "summary": summary, "figures": figures, "physiology": physiology_setup,
                 "zip": flow.bundle(summary, runs, figures)}, dict(settings))
            status.update(label="Calibration done", state="complete")

stored = st.session_state.get("my_subject_run")
if stored is not None:
    with freshness.shown(stored, settings, "my subject"):
        summary = stored.result["summary"]
        for run in stored.result["runs"]:
            record = summary["models"][run.model]
            # one banner per likelihood: its convergence and each of the verdict's flags, once
            level, text = banner_status(run.result.convergence, flags=run.check.flags)
            getattr(st, level)(f"{MODEL_LABELS[run.model]}: {text}")
            shown, config = summary_view(st, run.result.summary.rename(index=display_name))
            st.dataframe(shown, width="stretch", column_config=config)
            if "geometry_posterior" in record:
                st.markdown(f"**Inferred geometry, {MODEL_LABELS[run.model]}**: posterior of the PC scores h, the "
                            "scale s and the implied measures (median and 90 % equal-tailed interval), against what "
                            "was measured")
                # "measured" in words: a value, "not measured" for a measure left out, "–" for h and s (no measure)
                geo_rows = [{**row, "measured": f"{row['measured']:.4g}" if row["measured"] is not None
                             else "not measured" if row["quantity"].startswith("implied") else "–"}
                            for row in flow.geometry_posterior_rows(record["geometry_posterior"])]
                st.dataframe(geo_rows, width="stretch", hide_index=True, column_config={
                    "5 %": number_column(st, "q05"), "95 %": number_column(st, "q95"),
                    "median": number_column(st, "median")})
        for w in summary["warnings"]:
            if summary["geometry"]["kind"] == "inferred":
                st.warning(w)
        for name, fig in stored.result["figures"].items():
            st.plotly_chart(fig, width="stretch", key=f"my_fig_{name}")
        if stored.result.get("physiology") is not None:
            physiology_panel.show({MODEL_LABELS[r.model]: r.result.idata for r in stored.result["runs"]},
                                  stored.result["physiology"], subject=summary["subject"], key="my_edpvr")
        st.header("5 · Download")
        st.download_button("Download everything (zip: netCDF, figures, settings.json, summary.html)",
                           stored.result["zip"], file_name=f"{summary['subject']}_lvcore.zip",
                           mime="application/zip", key="my_zip")
