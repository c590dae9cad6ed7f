"""Geometry & operators: segmentations of one LV by up to three operators, fitted to the template."""
from __future__ import annotations

import numpy as np
import pandas as pd
import streamlit as st

from lvcore.exceptions import LVCoreError

st.set_page_config(page_title="Geometry & operators", layout="wide")
st.title("Geometry & operators")
st.caption(
    "Each LV geometry is a fixed-topology mesh fitted to a segmentation (short-axis contour stacks, or endo/epi "
    "surfaces), so geometries compare node by node. The bundled cases are **SYNTHETIC**: synthetic LVs segmented "
    "by three imitation operators (scripts/build_cohort.py), not patient data."
)


@st.cache_data(show_spinner="fitting the template…")
def _fit_upload(kind: str, files: tuple) -> dict:
    """Fit an uploaded segmentation; files are (name, bytes) pairs. Returns nodes + summary or an error."""
    from lvcore.app.uploads import fit_segmentation

    return fit_segmentation(kind, files)


@st.cache_data(show_spinner=False)
def _bundled():
    from lvcore.geometry.cohort import load_operator_geometries

    og = load_operator_geometries()
    return og.patients, og.operators, og.nodes, og.fits


@st.cache_data(show_spinner="rendering…")
def _overlay(names: tuple, nodes: np.ndarray, title: str) -> bytes:
    from lvcore.viz.geometry_views import render_overlay

    return render_overlay(dict(zip(names, nodes)), title=title)


@st.cache_data(show_spinner="rendering…")
def _distance(a: np.ndarray, b: np.ndarray, title: str) -> bytes:
    from lvcore.viz.geometry_views import render_distance_map

    return render_distance_map(a, b, title=title)


source = st.radio("Segmentations", ["Bundled SYNTHETIC operator study", "Upload my own"], horizontal=True)
geoms: dict[str, np.ndarray] = {}
summaries: dict[str, dict] = {}
if source.startswith("Bundled"):
    try:
        patients, operators, nodes, fits = _bundled()
    except LVCoreError as err:
        st.error(f"{err}")
        st.stop()
    patient = st.selectbox("Patient (SYNTHETIC)", patients)
    p = patients.index(patient)
    for o, op in enumerate(operators):
        geoms[op] = nodes[p, o]
        summaries[op] = fits[f"{patient}/{op}"]
    moved = {o: summaries[o]["motion_error_mm"] for o in operators if summaries[o].get("motion_error_mm")}
    if moved:
        which = ", ".join(f"{o} ({mm:g} mm)" for o, mm in moved.items())
        st.info(f"The segmentation by {which} carries an imitated motion-correction error (apical slices shifted "
                "in plane by that distance), like the chapter's operator 1 on its first patient.")
else:
    st.write("For each operator, upload either a contour stack (JSON, schema `lvcore.contours/1`, see "
             "docs/geometry.md), an endocardial and an epicardial surface (VTK/VTP/STL/PLY/OBJ, open at the base), "
             "or a volumetric LV mesh (tetrahedra/hexahedra, mm: ABAQUS .inp, gmsh .msh, VTU, ...; flat base).")
    cols = st.columns(3)
    for i, col in enumerate(cols):
        with col:
            name = st.text_input("Operator name", f"operator {i + 1}", key=f"name{i}")
            cfile = st.file_uploader("Contour stack (.json)", type=["json"], key=f"c{i}")
            efile = st.file_uploader("or endocardial surface", key=f"e{i}")
            pfile = st.file_uploader("and epicardial surface", key=f"p{i}")
            mfile = st.file_uploader("or a volumetric mesh", key=f"m{i}")
            out = None
            if mfile is not None:
                out = _fit_upload("mesh", ((mfile.name, mfile.getvalue()),))
            elif cfile is not None:
                out = _fit_upload("contours", ((cfile.name, cfile.getvalue()),))
            elif efile is not None and pfile is not None:
                out = _fit_upload("surfaces", ((efile.name, efile.getvalue()), (pfile.name, pfile.getvalue())))
            elif efile is not None or pfile is not None:
                st.warning("Upload both the endocardial and the epicardial surface.")
            if out is not None:
                if "error" in out:
                    st.error(f"Cannot use this segmentation: {out['error']}")
                else:
                    geoms[name] = out["nodes"]
                    summaries[name] = out["summary"]
                    st.success(f"fitted: residual {out['summary']['residual_mean_mm']:.2f} mm")
                    for w in out["summary"].get("warnings", []):
                        st.warning(w)
    if not geoms:
        st.info("Upload at least one segmentation to see its fitted geometry.")
        st.stop()

names = list(geoms)
from lvcore.geometry.measures import geometry_info  # noqa: E402
from lvcore.geometry.measures import node_mse_cm2  # noqa: E402
from lvcore.domain import units  # noqa: E402

rows = []
for n in names:
    info = geometry_info(geoms[n])
    s = summaries[n]
    rows.append({"operator": n, "cavity volume (mL)": round(info["cavity_volume_ml"], 1),
                 "wall volume (mL)": round(info["wall_volume_ml"], 1), "length (mm)": round(info["length_mm"], 1),
                 "fit residual mean (mm)": round(s["residual_mean_mm"], 3),
                 "fit residual max (mm)": round(s["residual_max_mm"], 3),
                 "base cut (mm below the base)": (s.get("base") or {}).get("cut", {}).get("depth_mm"),
                 "cavity removed by the cut (mL)": (s.get("base") or {}).get("cavity_removed_ml")})
left, right = st.columns([3, 2])
with left:
    st.subheader("Fitted geometries, overlaid")
    st.image(_overlay(tuple(names), np.stack([geoms[n] for n in names]),
                      "SYNTHETIC " + patient.replace("SYNTHETIC-", "") if source.startswith("Bundled") else "uploaded"))
with right:
    st.subheader("Volumes and fit residuals")
    # one column per operator: the narrow column holds the table whole, without clipping the right-hand columns
    volumes = pd.DataFrame(rows).set_index("operator").T
    uncut = volumes.isna().all(axis=1)  # e.g. the base-cut rows of contour stacks: no cut was made
    volumes = volumes[~uncut]
    if volumes.isna().any().any():  # a value for some operators only: say "–", never None
        volumes = volumes.astype(object).map(lambda v: "–" if pd.isna(v) else f"{v:g}")
    st.dataframe(volumes, width="stretch")
    if uncut.any():
        st.caption(f"Not shown ({', '.join(uncut.index[uncut])}): no base cut was made for these geometries (a cut "
                   "applies to endo/epi surfaces and volume meshes; contour stacks end at their basal slice).")
    if len(names) > 1:
        mse = pd.DataFrame([[node_mse_cm2(geoms[a], geoms[b]) for b in names] for a in names], index=names,
                           columns=names).round(4)
        st.markdown("**Mean squared node distance (cm², the chapter's unit)**")
        st.dataframe(mse, width="stretch")
        st.caption("MSE in cm², as in the chapter's tables; its root is the RMS node distance: 10·√MSE mm "
                   "(0.01 cm² = 1 mm RMS), comparable with the distances and residuals in mm.")

if len(names) > 1:
    st.subheader("Per-node distance between two geometries")
    c1, c2 = st.columns(2)
    a = c1.selectbox("Geometry", names, index=0)
    b = c2.selectbox("compared with", names, index=1)
    d = np.linalg.norm(geoms[a] - geoms[b], axis=1)
    m0, m1, m2, m3 = st.columns(4)  # one number per metric: "0.0357 cm² = 1.89 mm RMS" was cut off in one
    mse_ab = node_mse_cm2(geoms[a], geoms[b])
    m0.metric("node MSE (cm²)", f"{mse_ab:.4f}", help="Mean squared node distance, the chapter's unit.")
    m1.metric("RMS node distance (mm)", f"{units.rms_mm_from_mse_cm2(mse_ab):.2f}",
              help="The root of the node MSE in mm: 10·√MSE (0.01 cm² = 1 mm RMS).")
    m2.metric("mean distance (mm)", f"{d.mean():.2f}")
    m3.metric("max distance (mm)", f"{d.max():.2f}")
    st.image(_distance(geoms[a], geoms[b], f"{a} coloured by distance to {b}"))

with st.expander("Build a subject emulator for one of these geometries (optional, minutes)",
                 expanded=st.session_state.get("geo_build_job") is not None):
    from lvcore.app import subject_emulator_panel
    from lvcore.app.subject_flow import template_mesh_file
    from lvcore.app.uploads import session_uploads

    which = st.selectbox("Geometry", names, key="geo_build_which")
    label = f"{patient} {which}" if source.startswith("Bundled") else which
    try:
        fitted = template_mesh_file(session_uploads(), geoms[which], label)
    except LVCoreError as err:
        st.error(f"Cannot write the fitted geometry: {err}")
    else:
        subject_emulator_panel.show(fitted, np.asarray(geoms[which], float).tobytes(), fitted.name, key="geo_build")
