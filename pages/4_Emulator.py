"""Emulator: accuracy on held-out simulations, and a live check against the simulator."""
from __future__ import annotations

import numpy as np
import pandas as pd
import plotly.graph_objects as go
import streamlit as st

from lvcore.app.controls import (chosen_index, conditions_text, disabled_hint, input_label, log_options,
                                   remember_choice, shared_inputs, shared_start, why_disabled)

from lvcore.app.emulators import cached_emulator
from lvcore.emulator.io import available_emulators, below_spec_emulators, load_validation
from lvcore.exceptions import LVCoreError
from lvcore.geometry.scaling import SCALE_BOUNDS, ScaledForward, scale_outputs
from lvcore.domain.outputs import ANGLE_NAMES, EDP_NAME, OUTPUT_NAMES, is_pc_name


st.set_page_config(page_title="Emulator", layout="wide")
st.title("Emulator")
st.caption(
    "A neural-network emulator η(θ, h) replaces the finite-element simulator where thousands of runs are "
    "needed (calibration, live sweeps). Here: how accurate it is on simulations it never saw, and a live "
    "comparison with one simulator run at any point you choose."
)


@st.cache_data(show_spinner=False)
def _validation(path: str):
    return load_validation(path)


choices = {name: name for name in available_emulators()}
for label_, d in below_spec_emulators().items():  # demonstrations, never loaded by name
    choices.setdefault(label_, str(d))
if not choices:
    st.info(
        "No trained emulator found. Build the bundled ones with `python scripts/build_emulators.py` "
        "(see docs/campaigns_and_emulators.md), or train one on a campaign store with "
        "`lvcore emulator train STORE --out DIR` and set `LVCORE_EMULATORS` to its parent directory."
    )
    st.stop()

shared = shared_inputs()
label = st.selectbox("Emulator", list(choices), index=chosen_index("emulator", choices),
                     help="Starts at the emulator last chosen on the Emulator, Calibration or My subject page.")
remember_choice("emulator", label)
try:
    emu = cached_emulator(choices[label])
except LVCoreError as err:
    st.error(str(err))
    st.stop()
meta = emu.metadata
if meta.get("spec_note"):
    st.warning(meta["spec_note"])
source = meta.get("source", {})
if any("campaign_double" in f for f in source.get("forward", [])):
    st.warning("Trained on a TEST DOUBLE forward model (not the simulator): synthetic, for testing only.")

# ----- summary ---------------------------------------------------------------
tr = meta.get("training", {})
held_key = "test" if "test" in meta else "validation"
held = meta.get(held_key, {})
c1, c2, c3, c4 = st.columns(4)
c1.metric("Training runs", tr.get("n_train", "?"))
c2.metric("Architecture", " × ".join(str(h) for h in meta.get("architecture", {}).get("hidden", [])))
if held:
    c3.metric(f"LVV RMSE ({held_key})", f"{held['lvv_rmse_ml']:.2f} mL")
    c4.metric(f"Strain RMSE ({held_key})", f"{held['strain_rmse']:.4f}")

with st.expander("Inputs and training box"):
    st.dataframe(pd.DataFrame({
        "input": emu.input_names, "lower": emu.lower, "upper": emu.upper,
        "scale": ["log" if f else "linear" for f in emu.log_inputs],
    }), hide_index=True)
    if emu.fixed:
        fixed = dict(emu.fixed)
        if {EDP_NAME, *ANGLE_NAMES} <= set(fixed):  # in words, with where the angles come from
            st.write("Fixed during training: " + conditions_text(fixed[EDP_NAME], tuple(fixed[n] for n in ANGLE_NAMES),
                                                                 emu) + ".")
        else:
            st.write("Fixed during training: " + ", ".join(f"{input_label(k)} {float(v):g}" for k, v in fixed.items())
                     + ".")
    st.caption(f"Resolution: {source.get('resolution', '?')} (mesh preset `{emu.resolution}`); base: **{emu.base}**; simulator versions: {source.get('simulator_versions', '?')}; "
               f"training-set hash {str(tr.get('set_hash', ''))[:16]}")

# ----- accuracy ----------------------------------------------------------------
st.subheader("Accuracy on held-out simulations")
if held:
    table = pd.DataFrame({"output": OUTPUT_NAMES, "RMSE": held["rmse"], "99th pct |error| (worst 1%)": held["p99_abs"],
                          "max |error|": held["max_abs"]})
    st.dataframe(table, hide_index=True, height=260)

val = _validation(choices[label])
if val is None:
    st.info("This emulator has no stored validation predictions (validation.npz).")
else:
    k = st.selectbox("Output", list(range(len(OUTPUT_NAMES))), format_func=lambda i: OUTPUT_NAMES[i])
    y, p = val["outputs"][:, k], val["predictions"][:, k]
    unit = " (mL)" if k == 0 else ""
    left, right = st.columns(2)
    lo, hi = float(min(y.min(), p.min())), float(max(y.max(), p.max()))
    fig = go.Figure([
        go.Scatter(x=y, y=p, mode="markers", marker=dict(size=4, opacity=0.6), name="held-out runs"),
        go.Scatter(x=[lo, hi], y=[lo, hi], mode="lines", line=dict(dash="dash", color="black"), name="y = x"),
    ])
    fig.update_layout(title=f"Parity: {OUTPUT_NAMES[k]}", xaxis_title=f"simulator{unit}", yaxis_title=f"emulator{unit}",
                      height=420, margin=dict(l=10, r=10, t=40, b=10))
    left.plotly_chart(fig, width="stretch")
    hist = go.Figure(go.Histogram(x=p - y, nbinsx=40))
    hist.update_layout(title=f"Residuals: {OUTPUT_NAMES[k]}", xaxis_title=f"emulator − simulator{unit}",
                       yaxis_title="count", height=420, margin=dict(l=10, r=10, t=40, b=10))
    right.plotly_chart(hist, width="stretch")

# ----- live check ----------------------------------------------------------------
st.subheader("Live check: emulator vs one simulator run")
st.caption("Starts at the shared sidebar's θ and EDP (clipped to the emulator's training box); move the sliders "
           "to explore around it. The sliders follow the sidebar when it changes.")
values = {}
cols = st.columns(3)
for i, (name, lo, hi, log) in enumerate(zip(emu.input_names, emu.lower, emu.upper, emu.log_inputs)):
    start = shared_start(name, shared)
    mid = float(np.sqrt(lo * hi)) if log else float(0.5 * (lo + hi))
    start = mid if start is None else float(np.clip(start, lo, hi))
    key = f"in_{name}_{start:.6g}"  # a new sidebar value restarts the slider there
    if log:  # log-scaled stops over a log-scaled input (the stiffnesses)
        values[name] = cols[i % 3].select_slider(input_label(name), options=log_options(float(lo), float(hi), start),
                                                 value=start, key=key)
    else:
        values[name] = cols[i % 3].slider(input_label(name), float(lo), float(hi), start, key=key)
pcs = [n for n in emu.input_names if is_pc_name(n)]
scale = 1.0
if pcs:  # exact uniform scaling (lvcore.geometry.scaling): the geometry s * reconstruct(h), strains unchanged, LVV x s^3
    from lvcore.app.physiology_panel import reference_volume_ml

    scale = cols[len(emu.input_names) % 3].slider(
        "scale s of the geometry", float(SCALE_BOUNDS[0]), float(SCALE_BOUNDS[1]), 1.0, 0.01, key="in_scale",
        help="the reference geometry is s times the shape with these PC scores: every strain is unchanged and "
             "the LVV is s³ times the emulated one (exact scaling, docs/real_data.md); a heart of any size")
    st.caption(f"Reference cavity V₀ of this geometry: {reference_volume_ml([values[n] for n in pcs], scale):.1f} mL "
               f"(scale {scale:.2f}).")
x = np.array([values[n] for n in emu.input_names])
y_emu = np.asarray(scale_outputs(np.asarray(emu.predict(x, strict=True), dtype=float), scale))
x = np.r_[x, scale]
st.write(f"Emulator: LVV **{y_emu[0]:.1f} mL**, mean strain **{y_emu[1:].mean():.4f}** (instant).")

space_dict = source.get("space")
blocked = why_disabled((space_dict is None, "this emulator's metadata does not record the campaign space it was "
                                            "trained on, so its inputs cannot be turned into a simulation."))
run = st.button("Run the simulator at this point", disabled=blocked is not None,
                help=blocked or "one finite-element solve at the resolution and base condition the emulator was "
                                "trained on")
disabled_hint(blocked)
if run:
    res = None
    try:
        # the simulator at s * reconstruct(h) is the simulator at reconstruct(h) with its LVV x s^3, to the Newton
        # tolerance (tests/test_geometry_scaling.py checks the identity at s = 0.6 and 1.5)
        sim = ScaledForward(emu.simulator(), scale)
        with st.spinner("Simulating..."):
            res = sim.evaluate({n: [values.get(n, emu.fixed.get(n))] for n in sim.input_names})
    except LVCoreError as err:
        st.error(f"Simulator failed: {err}")
    if res is not None and not res.converged[0]:
        st.error(f"Simulator did not converge: {res.messages[0]}")
    elif res is not None:
        st.session_state["live"] = (x.tolist(), res.outputs[0].tolist(), float(res.seconds[0]))
live = st.session_state.get("live")
if live and np.allclose(live[0], x):
    y_sim = np.asarray(live[1])
    st.write(f"Simulator ({live[2]:.2f} s): LVV **{y_sim[0]:.1f} mL**; emulator error "
             f"{y_emu[0] - y_sim[0]:+.2f} mL, strain RMSE {np.sqrt(np.mean((y_emu[1:] - y_sim[1:]) ** 2)):.4f}.")
    fig = go.Figure([go.Bar(x=list(OUTPUT_NAMES[1:]), y=y_sim[1:], name="simulator"),
                     go.Bar(x=list(OUTPUT_NAMES[1:]), y=y_emu[1:], name="emulator")])
    fig.update_layout(barmode="group", yaxis_title="circumferential strain", height=380, margin=dict(l=10, r=10, t=20, b=10))
    st.plotly_chart(fig, width="stretch")
