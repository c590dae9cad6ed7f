"""Fibre angles: how LVV and the regional strains move with the rule-based helix angles."""
from __future__ import annotations

import threading
import time
import warnings

import numpy as np
import pandas as pd
import streamlit as st

from lvcore.app import freshness
from lvcore.app.controls import disabled_hint, shared_inputs, why_disabled
from lvcore.app.live_chart import live_plotly_chart
from lvcore.app.emulators import cached_emulator
from lvcore.emulator.io import available_emulators
from lvcore.domain.conditions import CHAPTER_ANGLE_PAIRS, CHAPTER_ANGLES
from lvcore.exceptions import LVCoreError
from lvcore.studies.fibre_angles import (angle_map, angle_sweep, emulator_angle_map, emulator_angle_sweep,
                                         parse_angle_pairs, strain_table)
from lvcore.viz import figures

st.set_page_config(page_title="Fibre angles", layout="wide")
st.title("Fibre angles")
st.caption(
    "The simulator at several rule-based fibre angle pairs (helix angle linear through the wall from "
    "α_endo to α_epi), everything else fixed, on the default LV (an analytic truncated ellipsoid). "
    "In the chapter (Fig 9.5), moving from (−60°, 90°) to (−30°, 60°) changed the LVV by about 2 mL but "
    "some regional strains substantially: a fibre-angle error hides in the strains, not in the volume."
)

shared = shared_inputs()  # θ and EDP from the shared sidebar (log-scaled, with units)
a, b, af, bf = (shared["theta"][n] for n in ("a", "b", "af", "bf"))
edp = shared["edp_mmhg"]
with st.sidebar:
    st.header("Fibre angles")
    resolution = st.selectbox("Mesh", ["fast", "default", "accurate"], index=0,
                              help="fast: a few seconds per angle pair; default: the campaigns' mesh")
options = dict(theta={"a": a, "b": b, "af": af, "bf": bf}, edp_mmhg=edp, resolution=resolution)
conditions = {"a (kPa)": a, "b (–)": b, "a_f (kPa)": af, "b_f (–)": bf, "EDP (mmHg)": edp, "mesh": resolution}

tab_sweep, tab_map = st.tabs(["Angle pairs (Fig 9.5)", "Map over (α_endo, α_epi)"])


def _frozen(opts):
    return tuple(sorted((k, tuple(sorted(v.items())) if isinstance(v, dict) else v) for k, v in opts.items()))


def _thaw(frozen):
    return {k: dict(v) if k == "theta" else v for k, v in frozen}


@st.cache_data(show_spinner=False)
def _sweep(pairs, opts):
    return angle_sweep(list(pairs), **_thaw(opts))


@st.cache_data(show_spinner=False)
def _map(endo, epi, opts):
    return angle_map(list(endo), list(epi), **_thaw(opts))


with tab_sweep:
    labels = [f"({e:g}°, {p:g}°)" for e, p in CHAPTER_ANGLE_PAIRS]
    chosen = st.multiselect("Angle pairs (α_endo, α_epi)", labels, default=labels)
    extra = st.text_input("More pairs, e.g. `-45 75; -90 0`", "")
    pairs = [CHAPTER_ANGLE_PAIRS[labels.index(c)] for c in chosen]
    try:
        pairs += parse_angle_pairs(extra)
    except LVCoreError as err:
        st.error(str(err))
        pairs = []
    sweep_inputs = {**conditions, "pairs (α_endo, α_epi)": [tuple(p) for p in pairs]}
    if pairs and st.button("Run sweep", type="primary"):
        with st.spinner(f"Simulating {len(pairs)} angle pairs..."):
            try:
                freshness.remember("angle_runs", _sweep(tuple(pairs), _frozen(options)), sweep_inputs)
            except LVCoreError as err:
                st.error(str(err))
    stored = freshness.recall("angle_runs")
    if stored is not None and stored.result:
        runs = stored.result
        with freshness.shown(stored, sweep_inputs, "angle_runs"):
            st.plotly_chart(figures.strain_bars(strain_table(runs),
                                                title="Circumferential strain by region and angle pair"),
                            width="stretch")
            st.dataframe(pd.DataFrame([{"α_endo (°)": r.alpha_endo, "α_epi (°)": r.alpha_epi, "LVV (mL)": r.lvv_ml,
                                        "mean E_cc": None if r.strains is None else float(np.mean(r.strains)),
                                        "converged": r.converged, "message": r.message} for r in runs]),
                         hide_index=True, width="stretch")

EMULATOR_ENGINE = "`angles` emulator (live)"


def _draw_map(amap, live: bool = False):
    # one figure with two heat maps: far cheaper for the browser to redraw than two labelled contour plots
    fig = figures.map_pair(amap.alpha_endo, amap.alpha_epi, amap.lvv_ml, amap.mean_strain,
                           titles=("LVV (mL)", "Mean E_cc"), colorbar_titles=("mL", "–"),
                           xaxis_title="α_endo (°)", yaxis_title="α_epi (°)", colorscales=("Viridis", "RdBu"))
    if live:  # stays mounted and is updated in place (Plotly.react) as the sliders move
        live_plotly_chart(fig, key="fibre_angle_live_map")
    else:
        st.plotly_chart(fig, width="stretch")


def _verify_worker(job: dict, point, theta, edp_mmhg, resolution) -> None:
    try:
        job["runs"] = angle_sweep([point], theta=theta, edp_mmhg=edp_mmhg, resolution=resolution)
    except Exception as err:  # noqa: BLE001 - shown to the user
        job["error"] = f"{type(err).__name__}: {err}"
    finally:
        job["elapsed"] = time.perf_counter() - job["t0"]
        job["done"] = True


def _verify_status() -> None:
    job = st.session_state.get("angle_verify")
    if job is not None and not job["done"]:
        st.progress(0.5, text=f"FE simulator running at {job['point']}: "
                              f"{time.perf_counter() - job['t0']:.0f} s elapsed")
    elif job is not None and not job.get("shown"):
        job["shown"] = True
        st.rerun()  # once, to show the result in the map fragment


def _grid_controls(n_min: int, n_max: int, n_default: int):
    """Grid size and α ranges of an angle map: ``(n, endo angles, epi angles)`` in degrees."""
    c1, c2, c3 = st.columns(3)
    n = c1.slider("Grid points per angle", n_min, n_max, n_default)
    endo_range = c2.slider("α_endo range (°)", -90, 0, (-90, 0))
    epi_range = c3.slider("α_epi range (°)", 0, 90, (0, 90))
    return n, tuple(np.linspace(*endo_range, n)), tuple(np.linspace(*epi_range, n))


@st.fragment
def _live_map(theta, edp_mmhg, resolution) -> None:
    """The emulator's map and its grid/range sliders: moving them reruns only this fragment, not the page."""
    n, endo, epi = _grid_controls(5, 41, 21)
    emu = cached_emulator("angles")  # cached resource: the emulator and its compiled prediction live across reruns
    st.caption(f"{n * n} emulator predictions on the shape model's mean LV (PC scores 0) with the {emu.base} base "
               "of its training simulations, not the analytic default LV with the simulator's clamped base; the "
               "mesh choice does not apply.")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            _draw_map(emulator_angle_map(emu, endo, epi, theta=theta, edp_mmhg=edp_mmhg), live=True)
        except LVCoreError as err:
            st.error(str(err))
        try:  # the chapter's angle pairs (Fig 9.5), live: how the regional strains move with θ and EDP
            runs = emulator_angle_sweep(emu, CHAPTER_ANGLE_PAIRS, theta=theta, edp_mmhg=edp_mmhg)
            live_plotly_chart(figures.strain_bars(strain_table(runs), title="Circumferential strain by region at the "
                                                  "chapter's angle pairs (α_endo, α_epi), emulator"),
                              key="fibre_angle_live_strains")
        except LVCoreError as err:
            st.error(str(err))
    for w in {str(w.message): w for w in caught}.values():  # each warning once (both views may raise it)
        st.warning(str(w.message))

    st.markdown("**Verify a point with the FE simulator** (runs in the background; the map stays live)")
    v1, v2, v3 = st.columns([1, 1, 1])
    pe = v1.number_input("α_endo (°)", -90.0, 0.0, CHAPTER_ANGLES[0], 5.0, key="verify_endo")
    pp = v2.number_input("α_epi (°)", 0.0, 90.0, CHAPTER_ANGLES[1], 5.0, key="verify_epi")
    job = st.session_state.get("angle_verify")
    busy = job is not None and not job["done"]
    inputs = {"a (kPa)": theta["a"], "b (–)": theta["b"], "a_f (kPa)": theta["af"], "b_f (–)": theta["bf"],
              "EDP (mmHg)": edp_mmhg, "mesh": resolution, "point (α_endo, α_epi)": (pe, pp)}
    blocked = why_disabled((busy, "a verification is running; its result appears below when it is done."))
    clicked = v3.button("Verify with the FE simulator", disabled=blocked is not None,
                        help=blocked or "One finite-element solve at this point, in the background.")
    disabled_hint(blocked, v3)
    if clicked:
        job = {"done": False, "t0": time.perf_counter(), "point": (pe, pp), "inputs": inputs, "error": None}
        st.session_state["angle_verify"] = job
        threading.Thread(target=_verify_worker, args=(job, (pe, pp), dict(theta), edp_mmhg, resolution),
                         daemon=True).start()
        busy = True
    if busy:  # a 1 s timer only while the simulator runs: no idle reruns
        st.fragment(run_every=1.0)(_verify_status)()
    elif job is not None:
        with freshness.shown(freshness.Stored(job, job["inputs"]), inputs, "angle_verify"):
            if job["error"]:
                st.error(job["error"])
            else:
                r = job["runs"][0]
                if not r.converged:
                    st.error(f"The simulator did not converge at {job['point']}: {r.message}")
                else:
                    e_map = emulator_angle_map(emu, (job["point"][0],), (job["point"][1],), theta=theta,
                                               edp_mmhg=edp_mmhg)
                    st.write(f"FE simulator ({job['elapsed']:.0f} s, analytic default LV, {resolution} mesh): "
                             f"LVV **{r.lvv_ml:.1f} mL**, mean E_cc **{float(np.mean(r.strains)):.4f}**; emulator "
                             f"(shape model's mean LV): LVV **{float(np.ravel(e_map.lvv_ml)[0]):.1f} mL**, mean E_cc "
                             f"**{float(np.ravel(e_map.mean_strain)[0]):.4f}**. The two geometries differ, so "
                             "expect an offset; the check is whether the trends agree.")


with tab_map:
    engines = ["FE simulator"] + ([EMULATOR_ENGINE] if "angles" in available_emulators() else [])
    engine = st.radio("Computed by", engines, horizontal=True,
                      help="The emulator answers in milliseconds, so its map follows the sliders live; build it with "
                           "`python scripts/build_emulators.py --emulators angles` if it is missing.")
    live = engine == EMULATOR_ENGINE
    if not live:
        n, endo, epi = _grid_controls(2, 6, 3)
    if live:
        _live_map(options["theta"], edp, resolution)
    else:
        st.caption(f"{n * n} simulations.")
        map_inputs = {**conditions, "grid": n, "α_endo range (°)": (float(endo[0]), float(endo[-1])),
                      "α_epi range (°)": (float(epi[0]), float(epi[-1]))}
        if st.button("Run map"):
            with st.spinner(f"Simulating {n * n} angle pairs..."):
                freshness.remember("angle_map", _map(endo, epi, _frozen(options)), map_inputs)
        stored_map = freshness.recall("angle_map")
        if stored_map is not None:
            with freshness.shown(stored_map, map_inputs, "angle_map"):
                _draw_map(stored_map.result)
                for r in stored_map.result.failures:
                    st.warning(f"({r.alpha_endo:g}°, {r.alpha_epi:g}°) did not converge: {r.message}")
