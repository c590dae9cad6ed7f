"""The physiology panel of the Calibration and My subject results: EDV/V₀ and the EDPVR on request.

EDV/V₀: the posterior of the emulated end-diastolic volume (``eta[..., 0]``) over the model geometry's
reference cavity V₀, with the measured LVV's ratio and the typical range (:mod:`lvcore.physiology`).
EDPVR: the FE simulator (:func:`lvcore.mechanics.edpvr.simulate_edpvr`, fast mesh, one warm-started solve per
pressure) for :data:`N_EDPVR_DRAWS` posterior draws, run when the user presses the button (the emulators
are trained at 6–14 mmHg at most, so they cannot give 0–30 mmHg).
"""
from __future__ import annotations

import tempfile
from pathlib import Path
from types import SimpleNamespace
from typing import Mapping

import numpy as np

from lvcore import physiology

#: Posterior draws simulated for the EDPVR band.
N_EDPVR_DRAWS = 8
#: Mesh preset of the EDPVR solves.
EDPVR_RESOLUTION = "fast"


def reference_volume_ml(h, scale: float = 1.0) -> float:
    """V₀ (mL): the cavity of the shape model's LV at PC scores ``h`` scaled by ``scale`` (the emulator's geometry)."""
    from lvcore.app.subject_flow import geometry_measures

    info, _ = geometry_measures(SimpleNamespace(h=np.asarray(h, float), scale=float(scale)))
    return float(info["cavity_volume_ml"])


def ratio_table(idatas: Mapping[str, object], v0_ml: float, edp_mmhg: float, measured_lvv_ml: float | None):
    """Rows (one per likelihood) of the posterior EDV/V₀ table."""
    rows = []
    for label, idata in idatas.items():
        post = idata.posterior
        if "eta" not in post:
            continue
        r = physiology.posterior_edv_ratio(np.asarray(post["eta"])[..., 0], v0_ml, edp_mmhg, measured_lvv_ml)
        rows.append({"likelihood": label, "EDV/V₀ median": round(r.median, 3), "EDV/V₀ 90% interval":
                     f"{r.q05:.2f}–{r.q95:.2f}", "measured EDV/V₀": None if r.measured is None else round(r.measured, 3),
                     "typical": f"{r.typical.low:.2f}–{r.typical.high:.2f}"})
    return rows


def posterior_thetas(idata, n: int = N_EDPVR_DRAWS) -> tuple[list[dict], list[tuple[float, float]] | None]:
    """``n`` evenly spaced posterior draws of θ (and of the fibre angles when they were inferred)."""
    post = idata.posterior
    flat = {k: np.asarray(post[k]).reshape(-1) for k in ("a", "b", "af", "bf", "alpha_endo", "alpha_epi") if k in post}
    idx = np.linspace(0, len(flat["a"]) - 1, n).round().astype(int)
    thetas = [{k: float(flat[k][i]) for k in ("a", "b", "af", "bf")} for i in idx]
    angles = ([(float(flat["alpha_endo"][i]), float(flat["alpha_epi"][i])) for i in idx]
              if "alpha_endo" in flat else None)
    return thetas, angles


def run_edpvr(idata, h, scale: float, angles: tuple[float, float], progress=None) -> "lvcore.mechanics.edpvr.EDPVR":
    """The FE EDPVR of :data:`N_EDPVR_DRAWS` posterior draws on the emulator's geometry (``h``, ``scale``)."""
    from lvcore.app.subject_flow import geometry_nodes
    from lvcore.mechanics import edpvr

    thetas, draw_angles = posterior_thetas(idata)
    with tempfile.TemporaryDirectory() as d:
        if abs(float(scale) - 1.0) < 1e-12:
            geometry = {"kind": "pca", "scores": [float(v) for v in np.asarray(h, float)]}
        else:  # a scaled shape: the template nodes as a mesh file
            path = Path(d) / "geometry.npy"
            np.save(path, geometry_nodes(SimpleNamespace(h=np.asarray(h, float), scale=float(scale))))
            geometry = {"kind": "mesh", "path": str(path)}
        if draw_angles is None:
            return edpvr.simulate_edpvr(thetas, geometry, angles=angles, resolution=EDPVR_RESOLUTION,
                                             progress=progress)
        curves = [edpvr.simulate_edpvr([t], geometry, angles=a, resolution=EDPVR_RESOLUTION)
                  for t, a in zip(thetas, draw_angles)]
    return edpvr.EDPVR(curves[0].pressures_mmhg, np.vstack([c.volumes_ml for c in curves]), curves[0].v0_ml,
                            sum(c.n_failed for c in curves), EDPVR_RESOLUTION)


def show(idatas: Mapping[str, object], *, h, scale: float = 1.0, edp_mmhg: float, angles: tuple[float, float],
         measured_lvv_ml: float | None, subject: str, key: str) -> None:
    """Render the panel: the EDV/V₀ table and the EDPVR button/figure (state kept under ``key``)."""
    import streamlit as st

    from lvcore.viz.figures import edpvr_figure

    st.subheader("Physiology: EDV/V₀ and the EDPVR")
    v0 = reference_volume_ml(h, scale)
    typical = physiology.typical_edv_ratio(edp_mmhg)
    st.caption(f"EDP assumed: {edp_mmhg:g} mmHg. V₀ = {v0:.1f} mL, the reference (stress-free) cavity of the model "
               f"geometry; EDV from the posterior of the emulated LVV. {typical.text()}.")
    rows = ratio_table(idatas, v0, edp_mmhg, measured_lvv_ml)
    if rows:
        st.dataframe(rows, width="stretch", hide_index=True)
        for row in rows:
            note = physiology.edv_ratio_note(row["EDV/V₀ median"], edp_mmhg)
            if note:
                st.warning(f"{row['likelihood']}: {note}")
    label = st.selectbox("EDPVR from the posterior of", list(idatas), key=f"{key}_model")
    if st.button(f"Simulate the EDPVR (FE, {N_EDPVR_DRAWS} posterior draws, {EDPVR_RESOLUTION} mesh, 0–30 mmHg)",
                 key=f"{key}_run"):
        bar = st.progress(0.0, text="Simulating the EDPVR…")
        try:
            curve = run_edpvr(idatas[label], h, scale, angles,
                              progress=lambda done, total: bar.progress(done / total, text=f"EDPVR: {done}/{total} solves"))
        except ValueError as err:
            st.error(f"EDPVR: {err}")
            curve = None
        bar.empty()
        st.session_state[key] = (label, curve) if curve is not None else None
    stored = st.session_state.get(key)
    if stored:
        label, curve = stored
        if curve.n_failed:
            st.warning(f"EDPVR: {curve.n_failed} solves did not converge; their curves stop early.")
        fig = edpvr_figure(curve.pressures_mmhg, curve.volumes_ml, curve.v0_ml,
                           measured=None if measured_lvv_ml is None else (measured_lvv_ml, edp_mmhg),
                           subtitle=f"{subject}, {label}; FE simulator ({curve.resolution} mesh), "
                                    f"{curve.volumes_ml.shape[0]} posterior draws; V₀ = {curve.v0_ml:.1f} mL")
        st.plotly_chart(fig, width="stretch", key=f"{key}_fig")
        st.caption("The normal curve (Klotz et al. 2006: EDP = 27.78 · EDVn^2.76, EDVn = (V − V₀)/(V₃₀ − V₀)) is "
                   "drawn through the model's V₀ and the measured (EDV, EDP).")


__all__ = ["N_EDPVR_DRAWS", "EDPVR_RESOLUTION", "reference_volume_ml", "ratio_table", "posterior_thetas", "run_edpvr",
           "show"]
