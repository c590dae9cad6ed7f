"""The physiology panel of the Calibration and My subject results: EDV/V₀ and the derived quantities on request.

EDV/V₀: the posterior of the emulated end-diastolic volume (``eta[..., 0]``) over the reference cavity V₀, with
the measured LVV's ratio and the typical range (:mod:`lvcore.domain.physiology`).
EDPVR and the derived quantities: :func:`lvcore.inference.derived.derive`, exactly what ``lvcore calibrate``
writes to summary.json (``derived``): on the calibration's own geometry (PC scores and scale, the posterior's own
scores and scale when the geometry was inferred, or a subject emulator's mesh), base condition, fibre angles and
the emulator's training resolution, for :func:`edpvr_draws` posterior draws, run when the user presses the
button: the EDPVR emulator (an EDP input of 0–30 mmHg, :mod:`lvcore.emulator.edpvr`; through a subject emulator
its own, where it was built with one, :mod:`lvcore.emulator.subject_edpvr`) where it covers the calibration, else
the FE simulator (the calibration emulators are trained at 6–14 mmHg at most); the panel says which, and why FE.
Once computed, V₀ is the derived one (the FE reference cavity) everywhere in the panel.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, Callable, Mapping

import numpy as np

from lvcore.domain import physiology

#: Posterior draws behind the EDPVR band and the derived quantities (a 90 % band from fewer is mostly noise).
N_EDPVR_DRAWS = 100
#: Environment variable that overrides :data:`N_EDPVR_DRAWS` (an integer 1-2000; tests use a handful).
DRAWS_ENV = "LVCORE_EDPVR_DRAWS"
#: Wall time to expect per 100 draws (s), said on the button.
SECONDS_PER_100_DRAWS = 60


def edpvr_draws() -> int:
    """Posterior draws of the EDPVR: ``LVCORE_EDPVR_DRAWS`` when set (1-2000), else :data:`N_EDPVR_DRAWS`."""
    raw = os.environ.get(DRAWS_ENV, "").strip()
    if raw:
        try:
            n = int(raw)
        except ValueError:
            n = 0
        if 1 <= n <= 2000:
            return n
    return int(N_EDPVR_DRAWS)


@dataclass(frozen=True)
class Setup:
    """What a calibration was run on, as :func:`lvcore.inference.derived.derive` needs it.

    Attributes
    ----------
    edp_mmhg : float
    angles : (float, float)
        Fixed fibre angles (deg); inferred ones come from the posterior.
    base, resolution : str
        The emulator's base condition and training mesh resolution.
    bounds : mapping
        θ's prior bounds (for the contraction).
    lvv_sd_ml : float or callable
        The volume likelihood's sd (mL), or a function of the model's LVV.
    measured_lvv_ml : float, optional
    h : sequence of float, optional
        PC scores of a given geometry (None with a subject emulator or an inferred geometry).
    scale : float
        The given geometry's scale (the subject is ``scale`` times the shape with scores ``h``).
    geometry : mapping, optional
        A subject emulator's geometry section (its mesh).
    """

    edp_mmhg: float
    angles: tuple
    base: str
    resolution: str
    bounds: Mapping
    lvv_sd_ml: Any
    measured_lvv_ml: float | None
    h: Any = None
    scale: float = 1.0
    geometry: Mapping | None = None

    @classmethod
    def of(cls, emulator, forward, *, edp_mmhg: float, angles, measured_lvv_ml, h=None, scale: float = 1.0,
           infer_angles: bool = False, sigma_v: float | None = None) -> "Setup":
        """The setup of a calibration with ``emulator`` through ``forward`` (its bounds and volume sd)."""
        from lvcore.domain.conditions import SIGMA_V_ML
        from lvcore.inference import verdict
        from lvcore.inference.models import lvv_sd
        from lvcore.domain.outputs import THETA_NAMES

        sv = SIGMA_V_ML if sigma_v is None else float(sigma_v)
        subject = bool(getattr(emulator, "is_subject", False))
        bounds = {k: b for k, b in verdict.checked_bounds(forward, infer_angles).items() if k in THETA_NAMES}
        return cls(edp_mmhg=float(edp_mmhg), angles=tuple(float(a) for a in angles),
                   base=str(getattr(emulator, "base", "clamped")), resolution=str(emulator.resolution),
                   bounds=bounds, lvv_sd_ml=lambda v, fw=forward: np.asarray(lvv_sd(v, sv, fw), float),
                   measured_lvv_ml=None if measured_lvv_ml is None else float(measured_lvv_ml),
                   h=None if (subject or h is None) else [float(v) for v in np.asarray(h, float)],
                   scale=1.0 if subject else float(scale),
                   geometry=emulator.subject_geometry if subject else None)


def reference_volume_ml(h, scale: float = 1.0) -> float:
    """V₀ (mL): the cavity of the shape model's LV at PC scores ``h`` scaled by ``scale`` (the emulator's geometry)."""
    from lvcore.app.subject_flow import geometry_measures

    info, _ = geometry_measures(SimpleNamespace(h=np.asarray(h, float), scale=float(scale)))
    return float(info["cavity_volume_ml"])


def derived_v0_ml(record: Mapping) -> float:
    """The derived V₀ (mL): the median FE cavity at 0 mmHg."""
    return float(record["edpvr"][0]["median"])


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


def run_edpvr(idata, setup: Setup, *, n_draws: int | None = None,
              progress: Callable[[int, int], None] | None = None) -> dict:
    """The derived record (:func:`lvcore.inference.derived.derive`) of one posterior: EDPVR, its check against the
    measured point, stress, ridge, contraction. ``n_draws`` defaults to :func:`edpvr_draws`."""
    from lvcore.inference import derived

    record, _ = derived.derive(idata, bounds=setup.bounds, edp_mmhg=setup.edp_mmhg, angles=setup.angles,
                               base=setup.base, resolution=setup.resolution, measured_edv_ml=setup.measured_lvv_ml,
                               lvv_sd_ml=setup.lvv_sd_ml, h=setup.h, scale=setup.scale, geometry=setup.geometry,
                               n_draws=edpvr_draws() if n_draws is None else int(n_draws), progress=progress)
    return record


def _q(q: Mapping, unit: str = "", digits: int = 1) -> str:
    from lvcore.inference.derived import format_interval

    return format_interval(q, digits, unit)


def edpvr_rows(record: Mapping) -> list[dict]:
    """The EDPVR as table rows: pressure, median and 90 % interval of the cavity volume."""
    return [{"pressure (mmHg)": f"{r['pressure_mmhg']:g}" + (" (V₀)" if r["pressure_mmhg"] == 0 else ""),
             "cavity volume median (mL)": None if r["median"] is None else round(r["median"], 1),
             "90% interval (mL)": "n/a" if r["median"] is None else f"{r['q05']:.1f}–{r['q95']:.1f}"}
            for r in record["edpvr"]]


def contraction_rows(record: Mapping) -> list[dict]:
    """Per parameter: the contraction and what it means in words."""
    from lvcore.inference.derived import WEAK_CONTRACTION
    from lvcore.viz.inference_figures import display_name

    return [{"parameter": display_name(n), "contraction": round(c, 2),
             "meaning": (f"weakly identified (< {WEAK_CONTRACTION:g}): the data say little about it on its own"
                         if c < WEAK_CONTRACTION else "identified by the data")}
            for n, c in record["contraction"].items()]


def check_text(record: Mapping) -> tuple[str, str]:
    """``(level, text)`` of the measured point against the EDPVR: ``success`` inside the 99 % predictive interval,
    ``error`` with the CONSISTENCY flag text outside it, ``info`` without a measurement."""
    from lvcore.inference.derived import check_flags

    c = record["edpvr_check"]
    if "measured_edv_ml" not in c:
        return "info", "No measured EDV: the EDPVR is not checked against a measurement."
    flags = check_flags(record)
    if flags:
        return "error", "CONSISTENCY: " + "; ".join(flags)
    lo, hi = c["predictive_99"]
    return "success", (f"The measured point lies inside the band: EDV {c['measured_edv_ml']:.1f} mL at "
                       f"{c['edp_mmhg']:g} mmHg is inside the EDPVR's 99 % predictive interval [{lo:.1f}, {hi:.1f}] mL.")


def summary_lines(record: Mapping) -> list[str]:
    """The derived quantities in words (markdown bullets, each "median [equal-tailed 90 % interval]"): the identified
    combination, the stress, the emulator-to-FE offset."""
    from lvcore.inference.derived import stress_phrases

    rg, st_, c = record["ridge"], record["stress"], record["edpvr_check"]
    ab, best = rg["a_b"], rg["best"]
    lines = [f"**Identified combination** (matrix pair): {ab['text']} = {ab['median']:.2f} (90 % width a factor "
             f"{ab['width90_factor']:.2f}); best-determined over all four: {best['text']} = {best['median']:.2f} "
             f"(90 % width a factor {best['width90_factor']:.2f}). corr(log a, log b) "
             f"{rg['correlation_log_a_log_b']:+.2f}."]
    lines += [f"{phrase}." for phrase in stress_phrases(st_, lambda heading: f"**{heading}**")]
    what = ("EDPVR emulator's volume − calibration emulator's, same draws" if record.get("path") == "emulator" else
            "FE volume − emulated volume, same draws")
    lines.append(f"**Emulator-to-FE offset** at {c['edp_mmhg']:g} mmHg ({what}): "
                 f"{_q(c['emulator_to_fe_offset_ml'], ' mL')}; {c['source']}.")
    return lines


def path_reason_text(record: Mapping) -> str:
    """Why a derived record's EDPVR came from FE load paths rather than an EDPVR emulator (``path_reason``)."""
    why = str(record.get("path_reason", ""))
    hint = (" A subject emulator built with “Also build the EDPVR emulator” ticked needs no FE solve here."
            if "--edpvr" in why else "")
    return f"The EDPVR and stress here are from FE load paths, not an EDPVR emulator: {why}.{hint}"


def _button_label(n: int, setup: "Setup | None" = None) -> str:
    if setup is not None and _emulated(setup):
        return f"Compute the EDPVR and derived quantities (EDPVR emulator, {n} posterior draws, 0–30 mmHg; under a minute)"
    minutes = max(1, round(n * SECONDS_PER_100_DRAWS / 100 / 60))
    return (f"Compute the EDPVR and derived quantities (FE, {n} posterior draws, 0–30 mmHg; about "
            f"{minutes} minute{'s' if minutes > 1 else ''})")


def _emulated(setup: "Setup") -> bool:
    """Whether the EDPVR emulator covers the calibration's conditions (its posterior draws are checked on the run)."""
    from lvcore.emulator.edpvr import conditions_covered

    emu, _ = conditions_covered(geometry=setup.geometry, angles=setup.angles, base=setup.base,
                                resolution=setup.resolution)
    return emu is not None


def show(idatas: Mapping[str, object], setup: Setup, *, subject: str, key: str) -> None:
    """Render the panel: the EDV/V₀ table, the button, and the stored derived record (kept under ``key``)."""
    import streamlit as st

    from lvcore.viz.figures import derived_edpvr_figure

    st.subheader("Physiology: EDV/V₀, the EDPVR and what the data identify")
    label = st.selectbox("From the posterior of", list(idatas), key=f"{key}_model")
    stored = st.session_state.get(key)
    if stored and (stored.get("label") not in idatas or stored.get("idata") is not idatas[stored["label"]]):
        stored = None  # another calibration since: not this posterior's record
    record = stored["record"] if stored else None
    typical = physiology.typical_edv_ratio(setup.edp_mmhg)
    if record is not None:
        v0, v0_text = derived_v0_ml(record), "the FE reference (stress-free) cavity of the EDPVR below"
    elif setup.h is not None:
        try:
            v0 = reference_volume_ml(setup.h, setup.scale)
        except Exception as err:  # noqa: BLE001 - shown in words
            st.warning(f"The reference cavity V₀ could not be computed ({type(err).__name__}: {err}).")
            v0 = None
        v0_text = "the reference cavity of the model geometry (the EDPVR below replaces it by its FE V₀)"
    else:
        v0, v0_text = None, ""
    if v0 is not None:
        st.caption(f"EDP assumed: {setup.edp_mmhg:g} mmHg. V₀ = {v0:.1f} mL, {v0_text}; EDV from the posterior of "
                   f"the emulated LVV. {typical.text()}.")
        rows = ratio_table(idatas, v0, setup.edp_mmhg, setup.measured_lvv_ml)
        if rows:
            st.dataframe(rows, width="stretch", hide_index=True)
            for row in rows:
                note = physiology.edv_ratio_note(row["EDV/V₀ median"], setup.edp_mmhg)
                if note:
                    st.warning(f"{row['likelihood']}: {note}")
    else:
        st.caption(f"EDP assumed: {setup.edp_mmhg:g} mmHg. The geometry is not a fixed set of PC scores: V₀ and "
                   f"EDV/V₀ come with the EDPVR below. {typical.text()}.")
    n = edpvr_draws()
    if st.button(_button_label(n, setup), key=f"{key}_run"):
        bar = st.progress(0.0, text=f"EDPVR of {n} posterior draws…")
        try:
            record = run_edpvr(idatas[label], setup, n_draws=n,
                               progress=lambda done, total: bar.progress(
                                   min(1.0, done / total), text=f"EDPVR: {done} of {total} done"))
        except Exception as err:  # noqa: BLE001 - a page shows errors in words, never a traceback
            st.error(f"The EDPVR could not be computed: {type(err).__name__}: {err}")
            record = None
        bar.empty()
        st.session_state[key] = None if record is None else {"label": label, "idata": idatas[label],
                                                              "record": record}
        if record is not None:
            st.rerun()  # the EDV/V₀ table above switches to the derived V₀
    if record is None:
        return
    shown = st.session_state[key]["label"]
    v0 = derived_v0_ml(record)
    c = record["edpvr_check"]
    failed = int(c.get("n_failed_solves", 0))
    if failed:
        st.warning(f"EDPVR: {failed} FE solves did not converge; their points are left out of the band.")
    fig = derived_edpvr_figure(record, subtitle=f"{subject}, {shown}; {record['n_draws']} posterior draws, "
                                                f"{setup.resolution} mesh, {setup.base} base; V₀ = {v0:.1f} mL")
    st.plotly_chart(fig, width="stretch", key=f"{key}_fig")
    st.caption("Band: equal-tailed 90 % posterior interval of the cavity volume (0 mmHg is V₀; "
               f"{record['edpvr_check']['source']}). The normal "
               "curve (Klotz et al. 2006: EDP = 27.78 · EDVn^2.76, EDVn = (V − V₀)/(V₃₀ − V₀)) is drawn through "
               "the derived V₀ and the measured (EDV, EDP); the red bar is the 99 % posterior predictive interval "
               "of the volume at the EDP.")
    if record.get("path") == "fe" and record.get("path_reason"):
        st.caption(path_reason_text(record))
    level, text = check_text(record)
    getattr(st, level)(text)
    st.dataframe(edpvr_rows(record), width="stretch", hide_index=True)
    st.markdown("\n".join(f"- {line}" for line in summary_lines(record)))
    st.markdown("**Contraction** (1 − posterior/prior variance of log θ: 1 pinned by the data, 0 nothing learned)")
    st.dataframe(contraction_rows(record), width="stretch", hide_index=True)
    import re

    from lvcore.viz.inference_figures import display_name

    for note in record["weakly_identified"]:  # a_f, b_f as on the sliders
        st.info("Note: " + re.sub(r"\b(af|bf)\b", lambda m: display_name(m.group(1)), note))


__all__ = ["N_EDPVR_DRAWS", "DRAWS_ENV", "edpvr_draws", "Setup", "reference_volume_ml", "derived_v0_ml",
           "ratio_table", "run_edpvr", "edpvr_rows", "contraction_rows", "check_text", "summary_lines",
           "path_reason_text", "show"]
