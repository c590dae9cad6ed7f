"""Shared controls of the app: log-scaled stiffness sliders with units, and input labels with units.

Every page that sets θ = (a, b, a_f, b_f) uses :func:`theta_slider`, so the
stiffness sliders are log-scaled with units everywhere.
"""
from __future__ import annotations

import numpy as np

from lvcore import conditions, units
from lvcore.core.space import THETA_BOUNDS
from lvcore.inference.cli import DEFAULT_EMULATOR

#: The shared sidebar's default subject: a bundled SYNTHETIC volunteer whose PC scores lie inside the
#: default emulator's box both as projected and size-normalised (HV1, the first in the list, has h1 = 2.40
#: unscaled, outside [-2, 2]; tests/test_inference_cli.py checks this one).
DEFAULT_SUBJECT = "SYNTHETIC_HV2"

#: Slider ranges: the chapter's prior box for a, a_f (kPa) and b, b_f (-).
THETA_RANGES = dict(THETA_BOUNDS)
#: θ labels with units.
THETA_LABELS = {"a": "a (kPa)", "b": "b (–)", "af": "a_f (kPa)", "bf": "b_f (–)"}
THETA_HELP = {
    "a": "Isotropic (matrix) stiffness of the Holzapfel–Ogden law; log-scaled slider.",
    "b": "Isotropic exponent: how fast the matrix stiffens; log-scaled slider.",
    "af": "Fibre stiffness; log-scaled slider.",
    "bf": "Fibre exponent: how fast the fibres stiffen; log-scaled slider.",
}


def log_options(lo: float, hi: float, keep: float, n: int = 41) -> list[float]:
    """Log-spaced slider stops (3 significant digits) between ``lo`` and ``hi`` that include ``keep``."""
    values = {float(f"{v:.3g}") for v in np.geomspace(lo, hi, n)} | {float(keep)}
    return sorted(values)


def theta_slider(name: str, value: float | None = None, *, key: str | None = None, container=None) -> float:
    """A log-scaled select slider for θ component ``name`` (a, b, af, bf) with its unit in the label."""
    import streamlit as st

    lo, hi = THETA_RANGES[name]
    where = container if container is not None else st
    if value is None and key is not None and key in st.session_state:
        # the value lives in the widget's state: fixed options and no default, so the widget keeps its identity
        # (a default or options that change between reruns make Streamlit remount it and drop a key press)
        options = log_options(lo, hi, float(conditions.THETA_TILDE[name]))
        return where.select_slider(THETA_LABELS[name], options=options, key=key, help=THETA_HELP[name])
    value = float(conditions.THETA_TILDE[name] if value is None else value)
    return where.select_slider(THETA_LABELS[name], options=log_options(lo, hi, value), value=value, key=key,
                               help=THETA_HELP[name])


def input_label(name: str) -> str:
    """Label with units of an emulator input (θ, fibre angles, EDP, PC scores h1…h5)."""
    if name in THETA_LABELS:
        return THETA_LABELS[name]
    if name.lower() in ("edp", "edp_mmhg"):
        return "EDP (mmHg)"
    if name in ("alpha_endo", "alpha_epi"):
        return f"α_{name.split('_')[1]} (°)"
    if len(name) >= 2 and name[0] == "h" and name[1:].isdigit():
        return f"{name}: PC score {name[1:]} of the shape model (standard deviations)"
    return name




# ----------------------------------------------------------------------------- the shared sidebar
#: session_state key of the values of the shared sidebar (a plain dict, read by every page).
SHARED = "shared_inputs"
_BY_MAIN = "_shared_sidebar_by_main"
#: session_state key of θ as last set in the sidebar (kept while a page hides the θ sliders).
_THETA = "_shared_theta"
#: session_state key of the EDP as last set in the sidebar (kept while a page hides the EDP slider).
_EDP = "_shared_edp"
#: Widget key and range (mmHg) of the sidebar's EDP slider.
EDP_KEY = "shared_edp"
EDP_RANGE = (2.0, 30.0)


def _shared_defaults() -> dict:
    return {"theta": dict(conditions.THETA_TILDE), "edp_mmhg": float(conditions.SIMULATOR_DEFAULT_EDP_MMHG),
            "subject": None, "emulator": None}


def shared_sidebar(theta: bool = True, edp: bool = True) -> dict:
    """Render the sidebar shared by every page and return its values (also in ``st.session_state[SHARED]``).

    Subject (a bundled SYNTHETIC volunteer), emulator, θ (log-scaled, with units) and EDP. The entry script
    (:mod:`lvcore.app.main`) renders it before the page runs, so the values and the widgets' state are the
    same on every page. ``theta=False`` (a page that does not read θ) hides the θ sliders, ``edp=False`` (a page
    that does not read the sidebar's EDP) the EDP slider; their values are kept and come back with the sliders.
    Each slider has fixed options and no default once its value is in the widget state (a default or options that
    change between reruns make Streamlit remount the widget and drop a key press).
    """
    import streamlit as st

    from lvcore.emulator.io import available_emulators
    from lvcore.resources import bundled_volunteers

    values = _shared_defaults()
    with st.sidebar:
        st.header("Shared inputs")
        subjects = bundled_volunteers()
        if subjects:
            values["subject"] = st.selectbox("Subject (SYNTHETIC volunteer)", subjects, key="shared_subject",
                                             index=subjects.index(DEFAULT_SUBJECT) if DEFAULT_SUBJECT in subjects
                                             else 0,
                                             help="Used by Calibration; bundled SYNTHETIC volunteers "
                                                  f"(default {DEFAULT_SUBJECT}, inside the emulator's box).")
        emulators = available_emulators()
        if emulators:
            values["emulator"] = st.selectbox("Emulator", emulators, key="shared_emulator",
                                              index=emulators.index(DEFAULT_EMULATOR) if DEFAULT_EMULATOR in emulators
                                              else 0,
                                              help="Default emulator of the Emulator and Calibration pages "
                                                   f"(default {DEFAULT_EMULATOR}, as for lvcore calibrate).")
        saved = dict(st.session_state.get(_THETA) or values["theta"])
        if theta:
            for name in ("a", "b", "af", "bf"):
                key = f"shared_{name}"
                if key not in st.session_state:  # first shown, or shown again after a page that hid it
                    lo, hi = THETA_RANGES[name]
                    grid = np.asarray(log_options(lo, hi, float(conditions.THETA_TILDE[name])))
                    st.session_state[key] = float(grid[np.argmin(np.abs(np.log(grid / float(saved[name]))))])
                values["theta"][name] = theta_slider(name, key=key)
            st.session_state[_THETA] = dict(values["theta"])
        else:
            values["theta"] = saved
        saved_edp = float(st.session_state.get(_EDP, values["edp_mmhg"]))
        if edp:
            if EDP_KEY not in st.session_state:  # first shown, or shown again after a page that hid it
                st.session_state[EDP_KEY] = saved_edp
            values["edp_mmhg"] = float(st.slider("EDP (mmHg)", EDP_RANGE[0], EDP_RANGE[1], step=0.5, key=EDP_KEY,
                                                 help="End-diastolic pressure of the Emulator and Fibre angles pages."))
            st.session_state[_EDP] = values["edp_mmhg"]
        else:
            values["edp_mmhg"] = saved_edp
        hidden = [what for what, shown in (("θ (a, b, a_f, b_f)", theta), ("EDP", edp)) if not shown]
        if hidden:
            st.caption(f"{' and '.join(hidden)}: not used on this page; set {'them' if len(hidden) > 1 else 'it'} "
                       "on the Emulator or Fibre angles page.")
    st.session_state[SHARED] = values
    return values


def shared_start(name: str, shared: dict) -> float | None:
    """The shared sidebar's value of emulator input ``name`` (θ component or EDP), or ``None`` if it sets none."""
    if name in shared.get("theta", {}):
        return float(shared["theta"][name])
    if name.lower() in ("edp", "edp_mmhg") and shared.get("edp_mmhg") is not None:
        return float(shared["edp_mmhg"])
    return None


def render_shared_sidebar(theta: bool = True, edp: bool = True) -> dict:
    """The entry script's call: render the shared sidebar (θ sliders only if ``theta``, the EDP slider only if
    ``edp``) and mark that the pages need not."""
    import streamlit as st

    st.session_state[_BY_MAIN] = True
    return shared_sidebar(theta, edp)


def shared_inputs(theta: bool = True, edp: bool = True) -> dict:
    """For a page: the shared sidebar's values; renders the sidebar itself when the page runs on its own
    (``streamlit run`` of one page, AppTest), so every page works with and without the navigation."""
    import streamlit as st

    if st.session_state.get(_BY_MAIN) and SHARED in st.session_state:
        return st.session_state[SHARED]
    return shared_sidebar(theta, edp)


__all__ = ["THETA_RANGES", "THETA_LABELS", "THETA_HELP", "log_options", "theta_slider", "input_label", "SHARED",
           "EDP_KEY", "EDP_RANGE",
           "shared_sidebar", "render_shared_sidebar", "shared_inputs", "shared_start"]
