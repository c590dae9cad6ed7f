"""Guards of ``lvcore calibrate``: the geometry is a decision, and the emulator's limits are honoured.

* :func:`resolve_geometry` turns ``--geometry`` into PC scores and records where
  they came from (a scores file, a template mesh projected on the shape model
  with its reconstruction error, a volumetric mesh fitted then projected, or
  the explicit ``mean`` shape, which carries a warning: calibrating a subject
  on the mean shape biases the stiffness when their shape differs).
* :func:`check_inputs_in_box` compares the scores (and any condition the
  emulator takes as an input) with the emulator's training box. Outside it is
  an error unless extrapolation is allowed, in which case it becomes a
  recorded warning.
* :func:`check_conditions` refuses conditions the emulator cannot honour: an
  ``--edp`` or fibre angles given to an emulator trained at fixed values, and
  an EDP outside :data:`EDP_RANGE_MMHG`.

Every refusal is an :class:`~lvcore.exceptions.LVCoreError` (exit code 2 in the CLI).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lvcore.exceptions import DataError, EmulatorError, GeometryError
from lvcore.domain.outputs import ANGLE_NAMES, EDP_NAME, is_pc_name

#: Physiological end-diastolic pressures accepted (mmHg).
EDP_RANGE_MMHG = (2.0, 40.0)
#: Warning attached to ``--geometry mean``.
MEAN_SHAPE_WARNING = ("--geometry mean: calibrating on the population-mean shape (all PC scores 0). When the "
                      "subject's shape differs, the stiffness estimates are biased (4-7x too stiff in a published "
                      "volunteer, with the strains not fitted); give the subject's mesh or PC scores if you have them")
#: Suffixes read as volumetric meshes (fitted with lvcore.geometry.volume_mesh, then projected).
VOLUME_MESH_SUFFIXES = (".inp", ".msh", ".med", ".mesh")


@dataclass(frozen=True)
class GeometrySource:
    """PC scores and where they came from.

    Attributes
    ----------
    h : ndarray
        Standardised PC scores.
    source : str
        ``"mean"`` or the file given.
    kind : str
        ``mean``, ``scores`` (JSON/CSV), ``template-mesh`` (projected) or
        ``volume-mesh`` (fitted, then projected).
    projection_mse_cm2 : float or None
        Reconstruction error of the projection (mean squared node distance, cm²).
    fit_residual_mm : float or None
        Mean surface residual of a volume-mesh fit (mm).
    warnings : tuple of str
    scale : float
        Uniform scale ``s`` of the reference geometry (:mod:`lvcore.geometry.scaling`):
        the subject is ``s`` times the shape with scores ``h``; the emulated LVV
        is multiplied by ``s^3``. 1 for ``mean`` and for scores files without a scale.
    unscaled_scores : ndarray or None
        A mesh's plain projection (``s = 1``), for comparison.
    """

    h: np.ndarray
    source: str
    kind: str
    projection_mse_cm2: float | None = None
    fit_residual_mm: float | None = None
    warnings: tuple = field(default=())
    scale: float = 1.0
    unscaled_scores: np.ndarray | None = None

    def record(self) -> dict:
        """Plain-data record for the summary."""
        return {"scores": [float(v) for v in self.h], "scale": float(self.scale), "source": self.source,
                "kind": self.kind, "projection_mse_cm2": self.projection_mse_cm2,
                "fit_residual_mm": self.fit_residual_mm,
                "unscaled_scores": None if self.unscaled_scores is None else [float(v) for v in self.unscaled_scores]}


def _project(nodes, n_pc: int):
    """Size-normalised scores of template nodes: ``(h, scale, projection MSE (cm²), unscaled h)``."""
    from lvcore.geometry.scaling import size_normalised_scores

    res = size_normalised_scores(np.asarray(nodes, float), n_pc)
    return res.h, res.scale, res.projection_mse_cm2, res.unscaled_h


def resolve_geometry(spec, n_pc: int = 5, units: str = "mm", units_option: str = "--geometry-units") -> GeometrySource:
    """PC scores for ``--geometry SPEC``: ``mean``, a scores file, a template mesh or a volume mesh.

    Raises
    ------
    GeometryError
        If ``spec`` is empty or the file cannot be used.
    """
    from lvcore.geometry.scores import read_pc_scores

    if spec is None or str(spec).strip() == "":
        raise GeometryError("--geometry is required: give the subject's PC scores (.json/.csv), mesh "
                            "(template .vtu, or a volumetric .inp/.msh/.vtu) or, knowingly, 'mean'")
    if str(spec).strip().lower() == "mean":
        return GeometrySource(np.zeros(n_pc), "mean", "mean", warnings=(MEAN_SHAPE_WARNING,))
    path = Path(spec)
    if not path.is_file():
        raise GeometryError(f"--geometry {spec}: no such file (give a file, or 'mean' for the mean shape)")
    suffix = path.suffix.lower()
    if suffix in (".json", ".csv"):
        from lvcore.geometry.scores import read_scale

        return GeometrySource(read_pc_scores(path, n_pc), str(path), "scores", scale=read_scale(path))
    if suffix in VOLUME_MESH_SUFFIXES:
        return _from_volume_mesh(path, n_pc, units, units_option)
    if suffix in (".vtu", ".vtk", ".xdmf"):
        from lvcore.geometry.io import read_template_mesh

        try:
            nodes = read_template_mesh(path)
        except GeometryError as err:
            if "27-node hexahedra" in str(err) or "points, the template has" in str(err):
                return _from_volume_mesh(path, n_pc, units, units_option)
            raise
        h, scale, mse, raw = _project(nodes, n_pc)
        return GeometrySource(h, str(path), "template-mesh", projection_mse_cm2=mse, scale=scale, unscaled_scores=raw)
    if suffix in (".npy", ".npz"):
        from lvcore.geometry.scores import project_mesh

        h, scale, mse, raw = project_mesh(path, n_pc, with_scale=True)
        return GeometrySource(h, str(path), "template-mesh", projection_mse_cm2=mse, scale=scale, unscaled_scores=raw)
    raise GeometryError(f"--geometry {path.name}: unknown format '{suffix}'; give PC scores (.json/.csv), a template "
                        f"mesh (.vtu), a volumetric mesh ({', '.join(VOLUME_MESH_SUFFIXES)}, .vtu) or 'mean'")


def _from_volume_mesh(path: Path, n_pc: int, units: str, units_option: str) -> GeometrySource:
    from lvcore.geometry.fitting import units_warnings
    from lvcore.geometry.volume_mesh import fit_volume_mesh

    res = fit_volume_mesh(path, units=units)
    h, scale, mse, raw = _project(res.fit.nodes, n_pc)
    return GeometrySource(h, str(path), "volume-mesh", projection_mse_cm2=mse, scale=scale, unscaled_scores=raw,
                          fit_residual_mm=float(res.fit.residual_mean_mm),
                          warnings=tuple(res.boundary.warnings) + tuple(res.fit.warnings)
                          + tuple(units_warnings(res.fit, units, units_option)))


def box_report(values: dict, emulator) -> list[dict]:
    """Each named value with the emulator's training range for it and whether it lies inside."""
    names = tuple(emulator.input_names)
    lower, upper = np.asarray(emulator.lower, float), np.asarray(emulator.upper, float)
    out = []
    for n, v in values.items():
        if n not in names:
            continue
        i = names.index(n)
        out.append({"name": n, "value": float(v), "lower": float(lower[i]), "upper": float(upper[i]),
                    "inside": bool(lower[i] <= v <= upper[i])})
    return out


def check_inputs_in_box(values: dict, emulator, allow_extrapolation: bool = False,
                        what: str = "input") -> tuple[list[dict], list[str]]:
    """Compare fixed inputs (PC scores, EDP, angles) with the emulator's training box.

    Returns
    -------
    report : list of dict
        ``name, value, lower, upper, inside`` per input.
    warnings : list of str
        Non-empty only when ``allow_extrapolation`` and something is outside.

    Raises
    ------
    EmulatorError
        If a value is outside the box and extrapolation is not allowed.
    """
    report = box_report(values, emulator)
    bad = [r for r in report if not r["inside"]]
    if not bad:
        return report, []
    label = getattr(emulator, "name", "emulator")
    desc = ", ".join(f"{r['name']} = {r['value']:g} (trained on [{r['lower']:g}, {r['upper']:g}])" for r in bad)
    if not allow_extrapolation:
        raise EmulatorError(f"{what} outside the '{label}' emulator's training box: {desc}. The emulator would "
                            "extrapolate; check the geometry/conditions, or pass --allow-extrapolation to run "
                            "anyway (recorded as a warning in the output)")
    return report, [f"EXTRAPOLATION: {desc}; the '{label}' emulator is outside its training box and its "
                    "predictions there are unverified"]


def check_conditions(emulator, edp_mmhg=None, alpha_endo=None, alpha_epi=None, infer_angles: bool = False) -> dict:
    """The conditions to bind into ``emulator``, refusing what it cannot honour.

    Parameters
    ----------
    edp_mmhg, alpha_endo, alpha_epi : float or None
        As given by the user (None: not given).

    Returns
    -------
    dict
        ``edp_mmhg, alpha_endo, alpha_epi`` to use (the emulator's fixed
        values, the given ones, or the defaults), plus ``fixed``: the names the
        emulator holds fixed.

    Raises
    ------
    DataError
        EDP not finite or outside :data:`EDP_RANGE_MMHG`.
    EmulatorError
        EDP or angles given to an emulator trained at fixed values.
    """
    from lvcore.domain.conditions import SIMULATOR_DEFAULT_ANGLES, SIMULATOR_DEFAULT_EDP_MMHG

    names = set(getattr(emulator, "input_names", ()))
    fixed = dict(getattr(emulator, "fixed", None) or {})
    label = getattr(emulator, "name", "emulator")
    if edp_mmhg is not None:
        if not np.isfinite(edp_mmhg) or not EDP_RANGE_MMHG[0] <= edp_mmhg <= EDP_RANGE_MMHG[1]:
            raise DataError(f"--edp {edp_mmhg:g} mmHg is outside the physiological range {EDP_RANGE_MMHG[0]:g}-"
                            f"{EDP_RANGE_MMHG[1]:g} mmHg; give the end-diastolic pressure in mmHg")
        if EDP_NAME not in names:
            at = f" at {fixed[EDP_NAME]:g} mmHg" if EDP_NAME in fixed else ""
            raise EmulatorError(f"--edp {edp_mmhg:g}: the '{label}' emulator was trained at a fixed EDP{at} and "
                                "cannot honour another; drop --edp or use an emulator with an 'edp' input "
                                "(e.g. 'angles')")
    given_angles = {n: v for n, v in zip(ANGLE_NAMES, (alpha_endo, alpha_epi)) if v is not None}
    if given_angles:
        if infer_angles:
            raise EmulatorError(f"--angles infer samples the fibre angles; do not also fix "
                                f"{', '.join('--' + n.replace('_', '-') for n in given_angles)}")
        if not set(ANGLE_NAMES) <= names:
            at = (f" at ({fixed[ANGLE_NAMES[0]]:g}, {fixed[ANGLE_NAMES[1]]:g}) deg"
                  if set(ANGLE_NAMES) <= set(fixed) else "")
            raise EmulatorError(f"{', '.join('--' + n.replace('_', '-') for n in given_angles)}: the '{label}' "
                                f"emulator was trained at fixed fibre angles{at} and cannot honour others; drop "
                                "them or use an emulator with angle inputs (e.g. 'angles')")
    return {
        "edp_mmhg": float(fixed.get(EDP_NAME, SIMULATOR_DEFAULT_EDP_MMHG) if edp_mmhg is None else edp_mmhg),
        "alpha_endo": float(fixed.get(ANGLE_NAMES[0], SIMULATOR_DEFAULT_ANGLES[0]) if alpha_endo is None else alpha_endo),
        "alpha_epi": float(fixed.get(ANGLE_NAMES[1], SIMULATOR_DEFAULT_ANGLES[1]) if alpha_epi is None else alpha_epi),
        "fixed": sorted(fixed),
    }


def fixed_inputs(h, conditions: dict, emulator, infer_angles: bool = False) -> dict:
    """Named fixed inputs (PC scores and the conditions the emulator takes) for :func:`check_inputs_in_box`."""
    names = tuple(emulator.input_names)
    n_pc = sum(1 for n in names if is_pc_name(n))
    out = {f"h{i + 1}": float(v) for i, v in enumerate(np.asarray(h, float)[:n_pc])}
    if EDP_NAME in names:
        out[EDP_NAME] = conditions["edp_mmhg"]
    if not infer_angles:
        for n in ANGLE_NAMES:
            if n in names:
                out[n] = conditions[n]
    return out


def subject_edp(row, cond: dict, emulator, name: str, cli_edp) -> float:
    """The EDP (mmHg) of one subject: the data's ``edp_mmhg``, else ``--edp``, else the emulator's.

    Raises
    ------
    DataError
        The data and ``--edp`` disagree.
    EmulatorError
        The data's EDP differs from a fixed-EDP emulator's.
    """
    edp = row.edp_mmhg
    if edp is None:
        return float(cond["edp_mmhg"])
    if cli_edp is not None and abs(float(cli_edp) - edp) > 1e-9:
        raise DataError(f"subject {row.subject}: the data's edp_mmhg {edp:g} and --edp {cli_edp:g} disagree; drop "
                        "one of them")
    if EDP_NAME not in emulator.input_names:
        fixed = dict(getattr(emulator, "fixed", None) or {}).get(EDP_NAME, cond["edp_mmhg"])
        if abs(float(fixed) - edp) > 1e-6:
            raise EmulatorError(f"subject {row.subject}: edp_mmhg = {edp:g} in the data, but the '{name}' emulator "
                                f"was trained at a fixed EDP of {float(fixed):g} mmHg and cannot honour another; use "
                                "an emulator with an 'edp' input (--emulator angles) or drop the column")
    return float(edp)


def edp_source(row, cli_edp, emulator) -> str:
    """Where :func:`subject_edp` took the EDP from (recorded in the summary)."""
    if row.edp_mmhg is not None:
        return "data (edp_mmhg)"
    if cli_edp is not None:
        return "--edp"
    return "emulator default" if EDP_NAME in emulator.input_names else "fixed by the emulator"



__all__ = ["EDP_RANGE_MMHG", "MEAN_SHAPE_WARNING", "GeometrySource", "resolve_geometry", "box_report",
           "check_inputs_in_box", "check_conditions", "fixed_inputs", "subject_edp", "edp_source"]
