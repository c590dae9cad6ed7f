"""Fibre-angle sweeps (the chapter's Fig 9.5 and a (α_endo, α_epi) map), by simulator or emulator.

The same geometry and material are simulated at several rule-based fibre
angle pairs, to show how differently the volume and the regional strains
respond: in the chapter, moving from (−60°, 90°) to (−30°, 60°) changed the
LVV by about 2 mL but the lateral and inferior strains substantially.

Everything here returns plain data (frozen dataclasses and arrays) that the
app page and reports plot. Solves that fail are kept with their reason. The
sweeps take any :class:`~lvcore.core.forward.Forward` of the two angles;
the default is the FE simulator (:func:`angle_forward`).
:func:`emulator_angle_map` fills the same map from an emulator that takes the
angles as inputs (the bundled ``angles`` emulator): one batched prediction,
fast enough to redraw while sliders move.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore.domain import conditions, units
from lvcore._exports import moved_names
from lvcore.core.forward import Forward, ForwardBatch
from lvcore.emulator.forward import EmulatorForward
from lvcore.mechanics.forward import SimulatorForward
from lvcore.exceptions import ForwardError
from lvcore.geometry.template import N_REGIONS
from lvcore.domain.outputs import ANGLE_NAMES, EDP_NAME, is_pc_name, pc_names

#: Most angle pairs typed into the app's sweep (each is one simulator solve, seconds to a minute).
MAX_TYPED_ANGLE_PAIRS = 20


def parse_angle_pairs(text: str, max_pairs: int = MAX_TYPED_ANGLE_PAIRS) -> list[tuple[float, float]]:
    """Angle pairs typed as ``"-45 75; -90 0"`` (α_endo α_epi in degrees, pairs separated by ``;``).

    Raises
    ------
    ForwardError
        A pair that is not two numbers, an angle outside [-180, 180] degrees, or more than
        ``max_pairs`` pairs; the message repeats at most 60 characters of the text.
    """
    from lvcore.safety.limits import echo

    items = [s.strip() for s in str(text).split(";") if s.strip()]
    if len(items) > max_pairs:
        raise ForwardError(f"{len(items):,} angle pairs typed; at most {max_pairs} can be run at once "
                           "(each is one simulator solve)")
    pairs = []
    for item in items:
        parts = item.split()
        try:
            endo, epi = (float(v) for v in parts)
        except ValueError:
            raise ForwardError(f"could not read '{echo(item, 60)}': write pairs as 'α_endo α_epi' in degrees, "
                               "separated by ';'") from None
        if not all(np.isfinite(v) and -180.0 <= v <= 180.0 for v in (endo, epi)):
            raise ForwardError(f"angle pair '{echo(item, 60)}': angles must be in [-180, 180] degrees")
        pairs.append((endo, epi))
    return pairs


@dataclass(frozen=True)
class AngleRun:
    """One simulation of a sweep.

    Attributes
    ----------
    alpha_endo, alpha_epi : float
        Helix angles (degrees).
    converged : bool
    message : str
        The solver's message (the reason when it failed).
    lvv_ml : float or None
        End-diastolic cavity volume (mL).
    strains : (24,) array or None
        Regional circumferential Green strains.
    """

    alpha_endo: float
    alpha_epi: float
    converged: bool
    message: str
    lvv_ml: float | None
    strains: np.ndarray | None

    @property
    def label(self) -> str:
        lvv = "failed" if self.lvv_ml is None else f"EDV {self.lvv_ml:.1f} mL"
        return f"({self.alpha_endo:g}°, {self.alpha_epi:g}°): {lvv}"


def angle_case(
    alpha_endo: float,
    alpha_epi: float,
    theta: Mapping[str, float] | None = None,
    edp_mmhg: float = conditions.SIMULATOR_DEFAULT_EDP_MMHG,
    geometry: Mapping | None = None,
    resolution: str = "fast",
    base: str = "clamped",
) -> dict:
    """The simulation case dictionary of one sweep point (geometry default: the default LV)."""
    return angle_forward(theta, edp_mmhg, geometry, resolution, base).case(
        {ANGLE_NAMES[0]: alpha_endo, ANGLE_NAMES[1]: alpha_epi})


def angle_forward(
    theta: Mapping[str, float] | None = None,
    edp_mmhg: float = conditions.SIMULATOR_DEFAULT_EDP_MMHG,
    geometry: Mapping | None = None,
    resolution: str = "fast",
    base: str = "clamped",
    workers: int | None = 1,
) -> SimulatorForward:
    """The FE simulator as a forward model of the fibre angles (deg) at fixed material, EDP and geometry.

    Parameters
    ----------
    theta : mapping, optional
        a, b, af, bf (kPa, -, kPa, -); default the reference θ.
    edp_mmhg : float
    geometry : mapping, optional
        The case's geometry section (default: the default LV).
    resolution, base : str
        Mesh preset and basal boundary condition.
    workers : int, optional
        Local processes for batches (see :class:`~lvcore.mechanics.forward.SimulatorForward`).
    """
    theta = dict(conditions.THETA_TILDE if theta is None else theta)
    return SimulatorForward(input_names=ANGLE_NAMES, conditions={**theta, EDP_NAME: float(edp_mmhg)},
                            geometry=dict(geometry or {"kind": "default"}), resolution=resolution, base=base,
                            workers=workers, label="FE simulator (fibre-angle sweep)",
                            warm_start=True)  # the sweep as warm-started continuation chains (issue 25)


def _check_angle_forward(forward) -> None:
    if tuple(forward.input_names) != ANGLE_NAMES:
        raise ForwardError(f"an angle sweep needs a forward model of {list(ANGLE_NAMES)} (deg); "
                           f"this one reads {list(forward.input_names)}")


def _runs(endo, epi, batch) -> list[AngleRun]:
    out = []
    for e, p, y, ok, msg in zip(endo, epi, batch.outputs, batch.converged, batch.messages):
        out.append(AngleRun(float(e), float(p), bool(ok), msg, float(y[0]) if ok else None,
                            y[1:].copy() if ok else None))
    return out


def angle_sweep(
    angle_pairs: Sequence[tuple[float, float]] = conditions.CHAPTER_ANGLE_PAIRS,
    forward: Forward | None = None,
    progress: Callable[[int, int], None] | None = None,
    **case_options,
) -> list[AngleRun]:
    """Evaluate each (α_endo, α_epi) pair (degrees) at otherwise fixed conditions.

    Parameters
    ----------
    angle_pairs : sequence of (float, float)
    forward : Forward, optional
        A forward model reading ``alpha_endo, alpha_epi`` (default
        :func:`angle_forward` with ``case_options``: the FE simulator).
    progress : callable, optional
        Called as ``progress(done, total)`` after each point.
    **case_options
        ``theta``, ``edp_mmhg``, ``geometry``, ``resolution``, ``base`` (see
        :func:`angle_forward`); only without ``forward``.
    """
    if forward is None:
        forward = angle_forward(**case_options)
    elif case_options:
        raise ForwardError(f"case options {sorted(case_options)} apply to the default simulator only; "
                           "bind them into the forward model instead")
    _check_angle_forward(forward)
    runs = []
    for n, (endo, epi) in enumerate(angle_pairs):
        batch = forward.evaluate({ANGLE_NAMES[0]: [float(endo)], ANGLE_NAMES[1]: [float(epi)]})
        runs += _runs([endo], [epi], batch)
        if progress is not None:
            progress(n + 1, len(angle_pairs))
    return runs


@dataclass(frozen=True)
class AngleMap:
    """LVV and mean strain over a grid of fibre angles (NaN where a solve failed).

    Attributes
    ----------
    alpha_endo : (n_endo,) array, degrees; alpha_epi : (n_epi,) array, degrees
    lvv_ml : (n_epi, n_endo) array
    mean_strain : (n_epi, n_endo) array
    runs : list of AngleRun (row-major over alpha_epi, then alpha_endo)
    """

    alpha_endo: np.ndarray
    alpha_epi: np.ndarray
    lvv_ml: np.ndarray
    mean_strain: np.ndarray
    runs: tuple

    @property
    def failures(self) -> list[AngleRun]:
        return [r for r in self.runs if not r.converged]


def angle_map(
    alpha_endo: Sequence[float],
    alpha_epi: Sequence[float],
    forward: Forward | None = None,
    progress: Callable[[int, int], None] | None = None,
    **case_options,
) -> AngleMap:
    """Evaluate every pair of the grid ``alpha_endo × alpha_epi`` (degrees).

    ``forward`` and ``case_options`` as in :func:`angle_sweep`. Failed solves
    are NaN in the maps (so a contour plot shows a hole) and are listed in
    :attr:`AngleMap.failures`.
    """
    ae = np.asarray(alpha_endo, dtype=float)
    ap = np.asarray(alpha_epi, dtype=float)
    pairs = [(e, p) for p in ap for e in ae]
    return _as_map(ae, ap, angle_sweep(pairs, forward=forward, progress=progress, **case_options))


def _as_map(ae: np.ndarray, ap: np.ndarray, runs) -> AngleMap:
    lvv = np.array([np.nan if r.lvv_ml is None else r.lvv_ml for r in runs]).reshape(ap.size, ae.size)
    mean_e = np.array([np.nan if r.strains is None else float(np.mean(r.strains)) for r in runs])
    return AngleMap(ae, ap, lvv, mean_e.reshape(ap.size, ae.size), tuple(runs))


def emulator_angle_map(
    emulator,
    alpha_endo: Sequence[float],
    alpha_epi: Sequence[float],
    theta: Mapping[str, float] | None = None,
    edp_mmhg: float = conditions.SIMULATOR_DEFAULT_EDP_MMHG,
    h: Sequence[float] | None = None,
) -> AngleMap:
    """The map of :func:`angle_map` predicted by an emulator with angle inputs.

    Parameters
    ----------
    emulator : lvcore.emulator.Emulator
        Must take ``alpha_endo`` and ``alpha_epi`` (deg) as inputs, e.g.
        ``load_emulator("angles")``; ``edp`` (mmHg) and PC scores ``h1..hk``
        are filled from ``edp_mmhg`` and ``h`` when it takes them.
    alpha_endo, alpha_epi : sequence of float
        Grid (degrees).
    theta : mapping, optional
        a, b, af, bf (kPa, -, kPa, -); default the reference θ.
    edp_mmhg : float
        End-diastolic pressure (mmHg).
    h : sequence of float, optional
        PC scores of the geometry (default the mean shape, all zero). The
        emulator's geometry is the shape model's, not the analytic default LV.

    Returns
    -------
    AngleMap
        Every run "converged" with the message naming the emulator. Points
        outside the emulator's training box raise the emulator's
        :class:`~lvcore.emulator.model.ExtrapolationWarning` (or an error in
        strict mode); they are never silently extrapolated.

    Raises
    ------
    EmulatorError
        If the emulator does not take the fibre angles, or needs an input
        that cannot be supplied.
    """
    ae = np.asarray(alpha_endo, dtype=float)
    ap = np.asarray(alpha_epi, dtype=float)
    endo, epi = np.meshgrid(ae, ap)  # (n_epi, n_endo), row-major over alpha_epi as in angle_map
    return _as_map(ae, ap, _emulator_runs(emulator, endo.ravel(), epi.ravel(), theta, edp_mmhg, h))


def emulator_angle_sweep(
    emulator,
    angle_pairs: Sequence[tuple[float, float]] = conditions.CHAPTER_ANGLE_PAIRS,
    theta: Mapping[str, float] | None = None,
    edp_mmhg: float = conditions.SIMULATOR_DEFAULT_EDP_MMHG,
    h: Sequence[float] | None = None,
) -> list[AngleRun]:
    """The runs of :func:`angle_sweep` predicted by an emulator with angle inputs.

    Parameters and errors as :func:`emulator_angle_map`, with the angle pairs
    (α_endo, α_epi) in degrees instead of a grid; one batched prediction.
    """
    pairs = np.asarray(angle_pairs, dtype=float).reshape(-1, 2)
    return _emulator_runs(emulator, pairs[:, 0], pairs[:, 1], theta, edp_mmhg, h)


def _emulator_runs(emulator, endo: np.ndarray, epi: np.ndarray, theta, edp_mmhg: float, h) -> list[AngleRun]:
    """One batched emulator prediction at the angle pairs ``(endo[i], epi[i])``, everything else fixed."""
    from lvcore.exceptions import EmulatorError

    names = tuple(emulator.input_names)
    if not set(ANGLE_NAMES) <= set(names):
        raise EmulatorError(f"emulator '{emulator.name}' does not take the fibre angles (inputs {list(names)}); "
                            "use the 'angles' emulator or the simulator")
    pcs = pc_names(sum(1 for n in names if is_pc_name(n)))
    h = np.zeros(len(pcs)) if h is None else np.atleast_1d(np.asarray(h, dtype=float))
    if h.size < len(pcs):
        raise EmulatorError(f"emulator '{emulator.name}' needs {len(pcs)} PC scores, got {h.size}")
    theta = dict(conditions.THETA_TILDE if theta is None else theta)
    fixed = {**theta, EDP_NAME: float(edp_mmhg), **dict(zip(pcs, h[:len(pcs)].tolist()))}
    fwd = EmulatorForward(emulator, fixed, ANGLE_NAMES, f"emulator '{emulator.name}'")
    batch = fwd.evaluate({ANGLE_NAMES[0]: endo, ANGLE_NAMES[1]: epi})
    batch = ForwardBatch(batch.outputs, batch.converged, tuple(m or fwd.label for m in batch.messages))
    return _runs(endo, epi, batch)


def strain_table(runs: Sequence[AngleRun]) -> dict[str, np.ndarray]:
    """Label -> (24,) strains of the converged runs (for grouped strain plots)."""
    return {r.label: r.strains for r in runs if r.converged and r.strains is not None and r.strains.size == N_REGIONS}


# ----------------------------------------------------------------------------- Fig 9.5: data, tables, figures
#: Figures :func:`figures` draws, with their titles.
TITLES = {"fig9_5_angle_sweep": "Fig 9.5: effect of the fibre angles on the strains and LVV",
          "fig9_5_angle_map": "Fig 9.5 (map): EDV over (α_endo, α_epi) by the `angles` emulator"}
#: Why a figure can be absent.
MISSING = {"fig9_5_angle_map": "the `angles` emulator is not installed; build it with "
                               "python scripts/build_emulators.py --emulators angles"}
#: The map's grid (degrees).
MAP_ENDO, MAP_EPI = np.linspace(-90, 0, 31), np.linspace(0, 90, 31)


def compute(sweep: str = "emulator") -> dict:
    """Fig 9.5's data at the reference θ: the chapter's four angle pairs and, with the ``angles`` emulator, the map.

    Parameters
    ----------
    sweep : {"emulator", "simulator"}
        The four pairs by the bundled ``angles`` emulator (milliseconds, the SYNTHETIC
        shape model's mean LV) or the FE simulator (default analytic LV, fast mesh).

    Returns
    -------
    dict
        ``theta``, ``engine`` (text), ``runs`` (:class:`AngleRun` list) and ``map``
        (:class:`AngleMap` or None when the ``angles`` emulator is not installed).
    """
    from lvcore.emulator.io import available_emulators, load_emulator

    theta = dict(conditions.THETA_TILDE)
    emulator = load_emulator("angles") if (sweep != "simulator" or "angles" in available_emulators()) else None
    if sweep == "simulator":
        runs = angle_sweep(conditions.CHAPTER_ANGLE_PAIRS, theta=theta, resolution="fast")
        engine = "FE simulator, default (analytic) LV, fast mesh"
    else:
        runs = emulator_angle_sweep(emulator, conditions.CHAPTER_ANGLE_PAIRS, theta=theta)
        engine = "bundled `angles` emulator, SYNTHETIC shape model's mean LV"
    amap = None if emulator is None else emulator_angle_map(emulator, MAP_ENDO, MAP_EPI, theta=theta)
    return {"theta": theta, "engine": engine, "runs": list(runs), "map": amap}


def tables(result: dict) -> dict:
    """The data of each figure by name (DataFrames)."""
    import pandas as pd

    out = {"fig9_5_angle_sweep": pd.DataFrame([
        {"alpha_endo_deg": r.alpha_endo, "alpha_epi_deg": r.alpha_epi, "converged": r.converged,
         "message": r.message, "lvv_ml": r.lvv_ml,
         **{f"strain_{k + 1:02d}": (None if r.strains is None else float(r.strains[k])) for k in range(N_REGIONS)}}
        for r in result["runs"]])}
    m = result.get("map")
    if m is not None:
        out["fig9_5_angle_map"] = pd.DataFrame({
            "alpha_endo_deg": np.tile(m.alpha_endo, m.alpha_epi.size),
            "alpha_epi_deg": np.repeat(m.alpha_epi, m.alpha_endo.size),
            "lvv_ml": m.lvv_ml.ravel(), "mean_strain": m.mean_strain.ravel()})
    return out


def captions(result: dict) -> dict:
    failed = [r.label for r in result["runs"] if not r.converged]
    return {"fig9_5_angle_sweep": "failed: " + "; ".join(failed)} if failed else {}


def figures(result: dict) -> dict:
    """Fig 9.5 (strain lines at the four pairs) and its map (EDV contour over the angles, when computed)."""
    from lvcore.viz import figures as vf
    from lvcore.viz.report_figures import strain_lines

    th = ", ".join(f"{k} {v:g}" for k, v in result["theta"].items())
    out = {"fig9_5_angle_sweep": strain_lines(
        strain_table(result["runs"]),
        title=f"Fig 9.5 — strains and EDV at four fibre-angle pairs ({result['engine']}; θ: {th}; EDP 8 mmHg)")}
    m = result.get("map")
    if m is not None:
        out["fig9_5_angle_map"] = vf.contour(
            m.alpha_endo, m.alpha_epi, m.lvv_ml,
            title="Fig 9.5 (map) — EDV (mL) over the fibre angles, `angles` emulator, SYNTHETIC mean "
                  f"LV (θ: {th}); markers: the chapter's pairs",
            xaxis_title="α_endo (°)", yaxis_title="α_epi (°)", colorbar_title="mL",
            points={"chapter pairs": tuple(map(list, zip(*conditions.CHAPTER_ANGLE_PAIRS)))})
    return out


def source_line(result: dict) -> str:
    return result["engine"] + ("; map: bundled `angles` emulator" if result.get("map") is not None else "")


#: Moved: the chapter's angle pairs live with the other conditions.
__getattr__ = moved_names(__name__, {"CHAPTER_ANGLE_PAIRS": "lvcore.domain.conditions:CHAPTER_ANGLE_PAIRS"})
