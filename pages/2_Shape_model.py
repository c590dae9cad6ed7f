"""Shape model: PCA of the SYNTHETIC cohort, its modes, and PCA against operators (Table 9.4)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import streamlit as st

from lvcore.domain import units
from lvcore.exceptions import LVCoreError

st.set_page_config(page_title="Shape model", layout="wide")
st.title("Shape model")
st.caption(
    "A PCA of template node coordinates. The bundled model is built from a **SYNTHETIC** cohort "
    "(scripts/build_cohort.py); the operator-study patients and the volunteers are held out of its training set. "
    "Scores are standardised: ±2 means two standard deviations along a mode."
)


@st.cache_resource(show_spinner=False)
def _model():
    from lvcore.geometry.shape_model import load_shape_model

    return load_shape_model()


@st.cache_data(show_spinner="computing Table 9.4…")
def _table():
    from lvcore.studies.geometry_operators import operator_table

    return operator_table()


@st.cache_data(show_spinner=False)
def _geometries():
    from lvcore.geometry.cohort import ROLE_VOLUNTEER, load_cohort, load_operator_geometries

    og = load_operator_geometries()
    out = {f"{p.replace('SYNTHETIC-', 'SYNTHETIC ')} by {o}": og.nodes[i, j]
           for i, p in enumerate(og.patients) for j, o in enumerate(og.operators)}
    ids, nodes = load_cohort().select(ROLE_VOLUNTEER)
    out.update({f"{i.replace('SYNTHETIC-', 'SYNTHETIC ')} (volunteer)": n for i, n in zip(ids, nodes)})
    return out


@st.cache_data(show_spinner="rendering…")
def _shape_png(nodes: np.ndarray, title: str, color: str = "#c9a27e") -> bytes:
    from lvcore.viz.geometry_views import render_shape

    return render_shape(nodes, title=title, color=color)


try:
    sm = _model()
except LVCoreError as err:
    st.error(f"{err}")
    st.stop()

from lvcore.viz.geometry_views import explained_variance_figure, operator_mse_figure  # noqa: E402

st.markdown(f"**Model:** {sm.label} — {sm.n_modes} modes, {len(sm.train_ids)} training geometries.")
st.plotly_chart(explained_variance_figure(sm.explained_variance_ratio), width="stretch")

st.subheader("Mean shape and modes at ±2 SD")
mode = st.selectbox("Mode", list(range(1, min(10, sm.n_modes) + 1)), index=0)
c1, c2, c3 = st.columns(3)
c1.image(_shape_png(sm.mode_shape(mode - 1, -2.0), f"mode {mode}: -2 SD", "#6baed6"))
c2.image(_shape_png(sm.mean, "mean shape (SYNTHETIC)"))
c3.image(_shape_png(sm.mode_shape(mode - 1, 2.0), f"mode {mode}: +2 SD", "#fd8d3c"))

st.subheader("PCA against operators (the chapter's Table 9.4, on SYNTHETIC data)")
try:
    table = _table()
except LVCoreError as err:
    st.error(f"{err}")
    st.stop()
main = st.radio("Main operator", table["operators"], horizontal=True)
block = next(b for b in table["blocks"] if b["main"] == main)
rows = []
for r in block["rows"]:
    row = {"patient": r["patient"]}
    row.update({f"vs {o}": v for o, v in r["operator_mse"].items()})
    row.update({f"{k}PC": r["pca_mse"][str(k)] for k in table["ks"]})
    row["first k beating both"] = r["first_k_beating_both"] or f">{table['ks'][-1]}"
    rows.append(row)
st.dataframe(pd.DataFrame(rows).set_index("patient").style.format(precision=4), width="stretch")
st.caption("Values: mean squared node distance in cm² (the chapter's unit); the RMS node distance is 10·√MSE mm, "
           "e.g. 0.01 cm² = 1 mm.")
share = pd.DataFrame([table["share_beating_both"], table["chapter_share"]],
                     index=["share of 18 cases where k PCs beat both operators (SYNTHETIC)", "chapter (real data)"])
share.columns = [f"{k}PC" for k in share.columns]
st.dataframe(share.style.format(precision=2), width="stretch")
lo, hi = table["operator_mse_range"]
st.caption(f"Imitation operators differ by {lo:.4f}–{hi:.4f} cm² mean squared node distance, i.e. "
           f"{units.rms_mm_from_mse_cm2(lo):.2f}–{units.rms_mm_from_mse_cm2(hi):.2f} mm RMS (chapter: 0.003–0.03 cm², "
           "0.55–1.73 mm).")
st.plotly_chart(operator_mse_figure(table, main), width="stretch")

st.subheader("Reconstruction with k modes")
geoms = _geometries()
name = st.selectbox("Geometry (held out of the training set)", list(geoms))
k = st.slider("modes k", 1, min(20, sm.n_modes), 5)
g = geoms[name]
rec = sm.reconstruct_nodes(g, k)
rec_mse = sm.reconstruction_mse_cm2(g, k)
st.metric("reconstruction error (mean squared node distance; RMS distance)",
          f"{rec_mse:.4f} cm² = {units.rms_mm_from_mse_cm2(rec_mse):.2f} mm RMS")
d1, d2 = st.columns(2)
d1.image(_shape_png(g, name))
d2.image(_shape_png(rec, f"{k}-mode reconstruction", "#9ecae1"))
