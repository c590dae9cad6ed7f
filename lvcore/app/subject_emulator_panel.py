"""The app's "Build a subject emulator" panel, on every page where a subject geometry is loaded (My subject, and
Geometry & operators for an uploaded segmentation).

It runs ``lvcore emulator build --geometry FILE`` (:class:`lvcore.app.subject_flow.SubjectBuild`, the CLI's
:func:`lvcore.emulator.subject.build_subject_emulator`) in the background with a progress bar and a stop
button, shows the held-out LVV and strain RMSE of its metadata, and keeps the emulator in the session (and on
disk in :data:`lvcore.app.subject_flow.BUILD_CACHE`), where the My subject page offers it for calibration
instead of a shared emulator. The design size is the CLI's by default (:class:`lvcore.emulator.subject.SubjectDesign`);
a smaller one is for trying the flow, a larger one for a tighter emulator. A checkbox (off by default, as the CLI)
also builds the subject's own EDPVR emulator (``--edpvr``, :mod:`lvcore.emulator.subject_edpvr`), after which the
derived EDPVR and stress of a calibration through it need no FE load paths.
"""
from __future__ import annotations

from pathlib import Path

#: session_state key of the subject emulators built in this session: {folder: SubjectBuild}.
SESSION_KEY = "subject_emulators"
#: Label prefix of a built subject emulator in the My subject page's emulator choice.
LABEL_PREFIX = "subject: "
#: The build option's checkbox: its own EDPVR emulator too (``lvcore emulator build --edpvr``, on by default).
EDPVR_LABEL = ("Also build the EDPVR emulator (about +1.5 min on 2 cores; the derived EDPVR and stress then take a "
               "fraction of a second instead of half a minute or more of FE solves)")


def built_emulators() -> dict:
    """The subject emulators built (or found in the cache) in this browser session, by their choice label."""
    import streamlit as st

    from lvcore.app.subject_flow import SubjectBuild

    builds = dict(st.session_state.get(SESSION_KEY) or {})
    for value in list(st.session_state.values()):  # a panel's build that finished since the page last ran
        if isinstance(value, SubjectBuild) and value.ok:
            builds.setdefault(str(value.out), value)
    return {f"{LABEL_PREFIX}{b.label}{' + EDPVR' if _has_edpvr(b.metadata) else ''} ({Path(folder).name[-16:]})":
            folder for folder, b in builds.items() if b.ok}


def _has_edpvr(metadata) -> bool:
    """Whether a subject emulator's metadata records its own EDPVR emulator."""
    return bool(dict(dict(metadata or {}).get("subject") or {}).get("edpvr"))


def _design_controls(key: str):
    import streamlit as st

    from lvcore.emulator.subject import SubjectDesign

    default = SubjectDesign()  # the CLI's --n-train/--n-valid/--n-test defaults
    c1, c2, c3 = st.columns(3)
    n_train = c1.number_input("training FE runs", 2, 20_000, default.n_train, step=50, key=f"{key}_train",
                              help=f"lvcore emulator build --n-train (default {default.n_train})")
    n_valid = c2.number_input("validation FE runs", 2, 5_000, default.n_valid, step=10, key=f"{key}_valid",
                              help=f"early stopping; --n-valid (default {default.n_valid})")
    n_test = c3.number_input("held-out test FE runs", 2, 5_000, default.n_test, step=10, key=f"{key}_test",
                             help=f"never used in training; their RMSE is recorded; --n-test (default {default.n_test})")
    return SubjectDesign(int(n_train), int(n_valid), int(n_test), default.method)


def _edpvr_control(key: str) -> bool:
    import streamlit as st

    from lvcore.emulator.subject import DEFAULT_EDPVR

    return bool(st.checkbox(EDPVR_LABEL, value=DEFAULT_EDPVR, key=f"{key}_edpvr",
                            help="lvcore emulator build --edpvr (on by default for a mesh; --no-edpvr skips it): FE "
                                 "load paths of 0-30 mmHg on the same mesh train the subject's own EDPVR emulator. "
                                 "Without it the derived EDPVR and stress of a calibration run FE load paths."))


def _progress(key: str) -> None:
    import streamlit as st

    job = st.session_state.get(f"{key}_job")
    if job is None:
        return
    if job.running:
        st.progress(job.fraction, text=f"Building the subject emulator: {job.status()}")
        if job.lines:
            st.caption(job.lines[-1])
    elif not st.session_state.get(f"{key}_shown") is job:
        st.session_state[f"{key}_shown"] = job
        st.rerun()  # once, to show the outcome in the page


def show_summary(job) -> None:
    """The held-out accuracy of a finished build (metadata ``test``) and its run counts."""
    import streamlit as st

    from lvcore.app import subject_flow as flow
    from lvcore.emulator.subject import SubjectDesign

    info = flow.held_out_summary(job.metadata)
    st.success(f"Subject emulator for {job.label} {job.status()}: held-out test ({info['n_test']} FE runs never "
               f"used in training) LVV RMSE {info['lvv_rmse_ml']:.3f} mL, strain RMSE {info['strain_rmse']:.4f}; "
               f"{info['runs_converged']} of {info['runs_total']} FE runs converged. {info['prior']}")
    if not info["within_targets"]:
        t = flow.HELD_OUT_TARGETS
        st.warning(f"The held-out accuracy misses the targets (LVV RMSE ≤ {t['lvv_rmse_ml']:g} mL, strain RMSE ≤ "
                   f"{t['strain_rmse']:g}): calibrations with it carry that emulator error; build with more "
                   f"training runs (the default is {SubjectDesign().n_train}).")
    e = info["edpvr"]
    if e:
        st.success(f"Its own EDPVR emulator: held-out test ({e['n_test_paths']} FE load paths) log-volume-ratio "
                   f"RMSE ≤ {e['log_volume_ratio_rmse_max']:.4f}, fibre-stretch RMSE ≤ "
                   f"{e['fibre_stretch_rmse_max']:.4f}; "
                   f"built in {e['seconds']:.0f} s. The derived EDPVR and stress of a calibration through this "
                   "emulator use it, with no FE solve, where the posterior draws lie in its box (else FE load "
                   "paths; the results say which).")
    else:
        st.caption("Built without its own EDPVR emulator: the derived EDPVR and stress of a calibration through it "
                   "run FE load paths (minutes).")


def show(geometry_file, geometry_bytes: bytes, label: str, *, units: str = "mm", key: str = "build"):
    """Render the panel for one loaded geometry; returns the finished :class:`SubjectBuild` or None.

    Parameters
    ----------
    geometry_file : path
        The geometry as ``lvcore emulator build --geometry`` takes it.
    geometry_bytes : bytes
        Its contents (they name the cache folder).
    label : str
        The user's name of the geometry.
    units : str
        Units of a volume mesh.
    key : str
        Widget-key prefix of this panel.
    """
    import streamlit as st

    from lvcore.app import subject_flow as flow
    from lvcore.emulator.subject import SubjectDesign
    from lvcore.exceptions import LVCoreError

    st.markdown("**Build a subject emulator** (optional): the FE simulator on this geometry as it is, with no "
                "PC projection and no ±2 score box, emulated and validated on held-out FE runs. The default design "
                f"is `lvcore emulator build`'s: {SubjectDesign().total:,} FE runs, minutes on two cores.")
    try:
        design = _design_controls(key)
    except LVCoreError as err:
        st.error(f"Design: {err}")
        return None
    edpvr = _edpvr_control(key)
    out = flow.build_dir(geometry_bytes, label, units=units, design=design, root=flow.BUILD_CACHE, edpvr=edpvr)
    job = st.session_state.get(f"{key}_job")
    busy = job is not None and job.running
    from lvcore.app.controls import disabled_hint, why_disabled

    blocked = why_disabled((busy, "a build is running: wait for it, or stop it below."))
    what = f"{design.total:,} FE runs" + (" + its EDPVR emulator" if edpvr else "")
    clicked = st.button(f"Build a subject emulator ({what})", disabled=blocked is not None,
                        key=f"{key}_start", help=blocked)
    disabled_hint(blocked)
    if clicked:
        job = flow.SubjectBuild(geometry_file, out, design=design, units=units, label=label, edpvr=edpvr).start()
        st.session_state[f"{key}_job"] = job
        busy = job.running
    if busy:
        st.button("Stop the build (the FE runs done are kept)", key=f"{key}_stop", on_click=job.stop)
        st.fragment(run_every=1.0)(_progress)(key)  # a 1 s timer only while it runs: no idle reruns
        return None
    if job is None:
        return None
    if job.error:
        st.error(job.error)
        return None
    if job.ok:
        st.session_state.setdefault(SESSION_KEY, {})[str(job.out)] = job
        show_summary(job)
        st.caption("Choose it as the emulator on the My subject page: its geometry is bound in (no PC scores).")
        return job
    return None


__all__ = ["SESSION_KEY", "LABEL_PREFIX", "EDPVR_LABEL", "built_emulators", "show", "show_summary"]
