"""Fibre-angle sweeps (the chapter's Fig 9.5 and a (α_endo, α_epi) map), by simulator or emulator.

The same geometry and material are simulated at several rule-based fibre
angle pairs, to show how differently the volume and the regional strains
respond: in the chapter, moving from (−60°, 90°) to (−30°, 60°) changed the
LVV by about 2 mL but the lateral and inferior strains substantially.

Everything here returns plain data (frozen dataclasses and arrays) that the
app page and reports plot. Solves that fail are kept with their reason.
:func:`emulator_angle_map` fills the same map from an emulator that takes the
angles as inputs (the bundled ``angles`` emulator): one batched prediction,
fast enough to redraw while sliders move.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore import units
from lvcore.geometry.template import N_REGIONS
from lvcore.outputs import ANGLE_NAMES, EDP_NAME, is_pc_name

#: Angle pairs (α_endo, α_epi) in degrees used by the chapter (§9.3.2, Fig 9.5).
CHAPTER_ANGLE_PAIRS = ((-60.0, 90.0), (-60.0, 60.0), (-30.0, 60.0), (0.0, 90.0))


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
    edp_mmhg: float = units.DEFAULT_EDP_MMHG,
    geometry: Mapping | None = None,
    resolution: str = "fast",
    base: str = "clamped",
) -> dict:
    """The simulation case dictionary of one sweep point (geometry default: the default LV)."""
    theta = dict(units.HO_REFERENCE_THETA if theta is None else theta)
    geom = dict(geometry or {"kind": "default"})
    geom.setdefault("resolution", resolution)
    return {
        "geometry": geom,
        "material": {"law": "holzapfel-ogden", **theta},
        "fibres": {"alpha_endo": float(alpha_endo), "alpha_epi": float(alpha_epi)},
        "load": {"pressure": float(edp_mmhg), "units": "mmHg"},
        "boundary": {"base": base},
    }


def _run(case: dict, simulate_fn: Callable) -> AngleRun:
    r = simulate_fn(case)
    alpha = case["fibres"]
    if not r.converged:
        return AngleRun(alpha["alpha_endo"], alpha["alpha_epi"], False, r.message, None, None)
    y = np.asarray(r.outputs())
    return AngleRun(alpha["alpha_endo"], alpha["alpha_epi"], True, r.message, float(y[0]), y[1:])


def angle_sweep(
    angle_pairs: Sequence[tuple[float, float]] = CHAPTER_ANGLE_PAIRS,
    simulate_fn: Callable | None = None,
    progress: Callable[[int, int], None] | None = None,
    **case_options,
) -> list[AngleRun]:
    """Simulate each (α_endo, α_epi) pair (degrees) at otherwise fixed conditions.

    Parameters
    ----------
    angle_pairs : sequence of (float, float)
    simulate_fn : callable, optional
        The forward simulator (default :func:`lvcore.simulate`).
    progress : callable, optional
        Called as ``progress(done, total)`` after each run.
    **case_options
        ``theta``, ``edp_mmhg``, ``geometry``, ``resolution``, ``base`` (see
        :func:`angle_case`).
    """
    if simulate_fn is None:
        from lvcore import simulate as simulate_fn
    runs = []
    for n, (endo, epi) in enumerate(angle_pairs):
        runs.append(_run(angle_case(endo, epi, **case_options), simulate_fn))
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
    simulate_fn: Callable | None = None,
    progress: Callable[[int, int], None] | None = None,
    **case_options,
) -> AngleMap:
    """Simulate every pair of the grid ``alpha_endo × alpha_epi`` (degrees).

    Failed solves are NaN in the maps (so a contour plot shows a hole) and are
    listed in :attr:`AngleMap.failures`.
    """
    ae = np.asarray(alpha_endo, dtype=float)
    ap = np.asarray(alpha_epi, dtype=float)
    pairs = [(e, p) for p in ap for e in ae]
    runs = angle_sweep(pairs, simulate_fn=simulate_fn, progress=progress, **case_options)
    lvv = np.array([np.nan if r.lvv_ml is None else r.lvv_ml for r in runs]).reshape(ap.size, ae.size)
    mean_e = np.array([np.nan if r.strains is None else float(np.mean(r.strains)) for r in runs])
    return AngleMap(ae, ap, lvv, mean_e.reshape(ap.size, ae.size), tuple(runs))


def emulator_angle_map(
    emulator,
    alpha_endo: Sequence[float],
    alpha_epi: Sequence[float],
    theta: Mapping[str, float] | None = None,
    edp_mmhg: float = units.DEFAULT_EDP_MMHG,
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
    from lvcore.exceptions import EmulatorError

    names = tuple(emulator.input_names)
    if not set(ANGLE_NAMES) <= set(names):
        raise EmulatorError(f"emulator '{emulator.name}' does not take the fibre angles (inputs {list(names)}); "
                            "use the 'angles' emulator or the simulator")
    ae = np.asarray(alpha_endo, dtype=float)
    ap = np.asarray(alpha_epi, dtype=float)
    endo, epi = np.meshgrid(ae, ap)  # (n_epi, n_endo), row-major over alpha_epi as in angle_map
    theta = dict(units.HO_REFERENCE_THETA if theta is None else theta)
    pcs = [n for n in names if is_pc_name(n)]
    h = np.zeros(len(pcs)) if h is None else np.atleast_1d(np.asarray(h, dtype=float))
    if h.size < len(pcs):
        raise EmulatorError(f"emulator '{emulator.name}' needs {len(pcs)} PC scores, got {h.size}")
    values = {**theta, ANGLE_NAMES[0]: endo, ANGLE_NAMES[1]: epi, EDP_NAME: float(edp_mmhg)}
    values.update({n: float(h[int(n[1:]) - 1]) for n in pcs})
    missing = [n for n in names if n not in values]
    if missing:
        raise EmulatorError(f"emulator '{emulator.name}' needs input(s) {missing}")
    y = np.asarray(emulator.predict(**{n: values[n] for n in names}))  # (n_epi, n_endo, 25)
    message = f"emulator '{emulator.name}'"
    runs = tuple(AngleRun(float(e), float(p), True, message, float(yy[0]), yy[1:].copy())
                 for e, p, yy in zip(endo.ravel(), epi.ravel(), y.reshape(-1, y.shape[-1])))
    return AngleMap(ae, ap, y[..., 0], y[..., 1:].mean(axis=-1), runs)


def strain_table(runs: Sequence[AngleRun]) -> dict[str, np.ndarray]:
    """Label -> (24,) strains of the converged runs (for grouped strain plots)."""
    return {r.label: r.strains for r in runs if r.converged and r.strains is not None and r.strains.size == N_REGIONS}
