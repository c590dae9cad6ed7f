"""Shared controls of the app: log-scaled stiffness sliders with units, and input labels with units.

Every page that sets θ = (a, b, a_f, b_f) uses :func:`theta_slider`, so the
stiffness sliders are log-scaled with units everywhere.
"""
from __future__ import annotations

import numpy as np

from lvcore.domain import conditions
from lvcore.core.space import THETA_BOUNDS
from lvcore.inference.cli import DEFAULT_EMULATOR
from lvcore.domain.outputs import EDP_NAME

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


def log_options(lo: float, hi: float, keep, n: int = 41) -> list[float]:
    """Log-spaced slider stops (3 significant digits) between ``lo`` and ``hi`` that include ``keep`` (a value or
    several)."""
    kept = {float(k) for k in (keep if np.ndim(keep) else [keep])}
    values = {float(f"{v:.3g}") for v in np.geomspace(lo, hi, n)} | kept
    return sorted(values)


def theta_slider(name: str, value: float | None = None, *, key: str | None = None, container=None,
                 default: float | None = None) -> float:
    """A log-scaled select slider for θ component ``name`` (a, b, af, bf) with its unit in the label.

    ``default`` is the starting value and a stop of the slider (default the chapter's θ̃; the Simulator page passes
    :data:`lvcore.domain.conditions.SIMULATOR_DEFAULT_THETA`); θ̃ is always a stop too. The stops depend only on these, so
    they are the same on every rerun."""
    import streamlit as st

    lo, hi = THETA_RANGES[name]
    where = container if container is not None else st
    start = float(conditions.THETA_TILDE[name] if default is None else default)
    stops = (start, float(conditions.THETA_TILDE[name]))  # θ̃ is a stop on every θ slider
    if value is None and key is not None and key in st.session_state:
        # the value lives in the widget's state: fixed options and no default, so the widget keeps its identity
        # (a default or options that change between reruns make Streamlit remount it and drop a key press)
        options = log_options(lo, hi, stops)
        return where.select_slider(THETA_LABELS[name], options=options, key=key, help=THETA_HELP[name])
    value = start if value is None else float(value)
    return where.select_slider(THETA_LABELS[name], options=log_options(lo, hi, (value, stops[1])), value=value,
                               key=key, help=THETA_HELP[name])


def input_label(name: str) -> str:
    """Label with units of an emulator input (θ, fibre angles, EDP, PC scores h1…h5)."""
    if name in THETA_LABELS:
        return THETA_LABELS[name]
    if name == EDP_NAME:
        return "EDP (mmHg)"
    if name in ("alpha_endo", "alpha_epi"):
        return f"α_{name.split('_')[1]} (°)"
    if len(name) >= 2 and name[0] == "h" and name[1:].isdigit():
        return f"{name}: PC score {name[1:]} of the shape model (standard deviations)"
    return name




def conditions_text(edp_mmhg: float, angles, emulator, *, infer_angles: bool = False) -> str:
    """The conditions a calibration or an emulator uses, with where each comes from, in one sentence.

    The emulator's own fixed training conditions win, and are said to be its own: the ``chapter`` emulator was
    trained at fibre angles −60° / 60° (:data:`lvcore.domain.conditions.CHAPTER_ANGLES`), while the simulator's default
    (Simulator page, case files) is −60° / 90° (:data:`lvcore.domain.conditions.SIMULATOR_DEFAULT_ANGLES`); an emulator with
    angle inputs gets the simulator's default unless the angles are inferred.
    """
    fixed = dict(getattr(emulator, "fixed", None) or {})
    name = getattr(emulator, "name", None)
    who = f"the '{name}' emulator" if name else "the emulator"
    sim = conditions.SIMULATOR_DEFAULT_ANGLES
    sim_text = f"{sim[0]:.0f}° / {sim[1]:.0f}°"
    if infer_angles:
        angle_text = "fibre angles inferred (α_endo in −90°…0°, α_epi in 0°…90°)"
    elif "alpha_endo" in fixed and "alpha_epi" in fixed:
        a = (float(fixed["alpha_endo"]), float(fixed["alpha_epi"]))
        chapter = " (the chapter's conditions)" if a == tuple(conditions.CHAPTER_ANGLES) else ""
        angle_text = (f"fibre angles {a[0]:.0f}° / {a[1]:.0f}°, {who}'s own: it was trained at these angles{chapter} "
                      f"and takes no others (the Simulator's default is {sim_text})")
    else:
        a = tuple(float(v) for v in angles)
        angle_text = (f"fibre angles {a[0]:.0f}° / {a[1]:.0f}°"
                      + (f", the simulator's default ({who} takes the angles as inputs)" if a == tuple(sim) else ""))
    edp_text = f"EDP {float(edp_mmhg):g} mmHg" + (f", {who}'s training EDP" if EDP_NAME in fixed else "")
    return f"{edp_text}; {angle_text}"


def why_disabled(*checks: tuple[bool, str]) -> str | None:
    """The reason a button is greyed out: the text of the first ``(blocked, text)`` pair whose ``blocked`` is true,
    else ``None`` (the button is enabled). Pages pass it as the button's ``help`` and show it under the button
    (:func:`disabled_hint`), so a greyed-out button always says why."""
    return next((text for blocked, text in checks if blocked), None)


def disabled_hint(reason: str | None, container=None) -> None:
    """Under a greyed-out button: why it is disabled (nothing when ``reason`` is ``None``)."""
    import streamlit as st

    if reason:
        (container if container is not None else st).caption(f"Disabled: {reason}")


#: Help of the discrepancy kernel choice (Calibration and My subject pages).
KERNEL_HELP = ("The polar GP of the discrepancy likelihood: additive (the chapter's: a sector profile plus a level "
               "profile, rank 9 on the 24 regions) or product (sector × level, full rank: it can represent a regional "
               "interaction). Used only by the discrepancy likelihood (`lvcore calibrate --discrepancy-kernel`).")


def discrepancy_kernel_choice(models, *, key: str | None = None, container=None) -> str:
    """The discrepancy likelihood's GP kernel (:data:`lvcore.inference.kernels.KERNEL_KINDS`; additive, the chapter's
    and the CLI's default, first), greyed out unless ``"discrepancy"`` is in ``models``. Pages pass it on as
    :class:`lvcore.inference.samplers.SamplerConfig` ``discrepancy_kernel``."""
    import streamlit as st

    from lvcore.inference.kernels import KERNEL_KINDS

    where = container if container is not None else st
    return where.radio("Discrepancy kernel", list(KERNEL_KINDS), horizontal=True, key=key,
                       disabled="discrepancy" not in models, help=KERNEL_HELP)


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


#: session_state keys of the subject and the emulator last chosen on any page (each page has its own selector; the
#: next page's selector starts at the same choice).
_CHOSEN = {"subject": "_chosen_subject", "emulator": "_chosen_emulator"}


def _shared_defaults() -> dict:
    return {"theta": dict(conditions.THETA_TILDE), "edp_mmhg": float(conditions.SIMULATOR_DEFAULT_EDP_MMHG),
            "subject": DEFAULT_SUBJECT, "emulator": DEFAULT_EMULATOR}


def chosen_index(kind: str, options, fallback: str | None = None) -> int:
    """Index in ``options`` of the ``kind`` ("subject" or "emulator") last chosen on any page, else of ``fallback``
    (default :data:`DEFAULT_SUBJECT` / the CLI's default emulator), else 0: the start of a page's own selector."""
    import streamlit as st

    options = list(options)
    for name in (st.session_state.get(_CHOSEN[kind]), fallback, _shared_defaults()[kind]):
        if name in options:
            return options.index(name)
    return 0


def remember_choice(kind: str, name) -> None:
    """Remember the ``kind`` ("subject" or "emulator") chosen on a page, so the next page's selector starts there."""
    import streamlit as st

    if name is not None:
        st.session_state[_CHOSEN[kind]] = name
        if SHARED in st.session_state:
            st.session_state[SHARED][kind] = name


def shared_sidebar(theta: bool = True, edp: bool = True) -> dict:
    """Render the sidebar's shared inputs and return the shared values (also in ``st.session_state[SHARED]``).

    θ (log-scaled, with units) and the EDP, shown only on a page that reads them (``theta`` / ``edp``; the Emulator
    and Fibre angles pages): elsewhere the sidebar shows no shared inputs at all, and the values are kept and come
    back with the sliders. The subject and the emulator are chosen on the pages that use them (one selector each,
    on the page); the values hold the last choice (:func:`remember_choice`). The entry script
    (:mod:`lvcore.app.main`) renders it before the page runs, so the values and the widgets' state are the same on
    every page. Each slider has fixed options and no default once its value is in the widget state (a default or
    options that change between reruns make Streamlit remount the widget and drop a key press).
    """
    import streamlit as st

    values = _shared_defaults()
    for kind, key in _CHOSEN.items():
        if st.session_state.get(key) is not None:
            values[kind] = st.session_state[key]
    saved = dict(st.session_state.get(_THETA) or values["theta"])
    saved_edp = float(st.session_state.get(_EDP, values["edp_mmhg"]))
    values["theta"], values["edp_mmhg"] = saved, saved_edp
    if theta or edp:
        with st.sidebar:
            st.header("Shared inputs")
            st.caption("Shared by the Emulator and Fibre angles pages.")
            if theta:
                values["theta"] = {}
                for name in ("a", "b", "af", "bf"):
                    key = f"shared_{name}"
                    if key not in st.session_state:  # first shown, or shown again after a page that hid it
                        lo, hi = THETA_RANGES[name]
                        grid = np.asarray(log_options(lo, hi, float(conditions.THETA_TILDE[name])))
                        st.session_state[key] = float(grid[np.argmin(np.abs(np.log(grid / float(saved[name]))))])
                    values["theta"][name] = theta_slider(name, key=key)
                st.session_state[_THETA] = dict(values["theta"])
            if edp:
                if EDP_KEY not in st.session_state:  # first shown, or shown again after a page that hid it
                    st.session_state[EDP_KEY] = saved_edp
                values["edp_mmhg"] = float(st.slider("EDP (mmHg)", EDP_RANGE[0], EDP_RANGE[1], step=0.5, key=EDP_KEY,
                                                     help="End-diastolic pressure of the Emulator and Fibre angles "
                                                          "pages."))
                st.session_state[_EDP] = values["edp_mmhg"]
    st.session_state[SHARED] = values
    return values


def shared_start(name: str, shared: dict) -> float | None:
    """The shared sidebar's value of emulator input ``name`` (θ component or EDP), or ``None`` if it sets none."""
    if name in shared.get("theta", {}):
        return float(shared["theta"][name])
    if name == EDP_NAME and shared.get("edp_mmhg") is not None:
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
           "EDP_KEY", "EDP_RANGE", "DEFAULT_SUBJECT", "chosen_index", "remember_choice", "why_disabled", "disabled_hint", "conditions_text",
           "KERNEL_HELP", "discrepancy_kernel_choice",
           "shared_sidebar", "render_shared_sidebar", "shared_inputs", "shared_start"]
