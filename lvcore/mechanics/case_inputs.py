"""Named physical inputs -> the simulator's case dictionary: the one writer of cases from named inputs.

Campaigns, the emulators' training spaces, the simulator as a forward model
(:class:`lvcore.mechanics.forward.SimulatorForward`), derived quantities and
the studies write a case through :func:`build_case` (one point) or
:func:`space_case` (one row of a :class:`lvcore.core.space.ParameterSpace`
design); :mod:`lvcore.mechanics.case` reads and validates what they write.
Units: ``a``, ``af`` in kPa; ``b``, ``bf`` dimensionless; ``alpha_endo``,
``alpha_epi`` in degrees; ``edp`` in mmHg; PC scores ``h1..hk`` in the shape
model's standardised score units.
"""
from __future__ import annotations

from typing import Mapping, Sequence

from lvcore.domain.conditions import CHAPTER_ANGLES, CHAPTER_EDP
from lvcore.core.space import ParameterSpace
from lvcore.exceptions import CampaignError, CaseError
from lvcore.domain.outputs import (ANGLE_NAMES, DEFAULT_STRAIN_LAYER, EDP_NAME, THETA_NAMES, is_pc_name, pc_names,
                                   strain_layer as _layer)

#: The material law of the cases :func:`build_case` writes.
CASE_LAW = "holzapfel-ogden"


def build_case(inputs: Mapping[str, float], *, geometry: Mapping | None = None, resolution: str = "default",
               base: str = "clamped", strain_layer: str = DEFAULT_STRAIN_LAYER) -> dict:
    """The simulator case dictionary for named physical inputs.

    Parameters
    ----------
    inputs : mapping
        ``a, b, af, bf`` (kPa, -, kPa, -; required), and optionally
        ``alpha_endo, alpha_epi`` (deg; default :data:`lvcore.domain.conditions.CHAPTER_ANGLES`),
        ``edp`` (mmHg; default :data:`lvcore.domain.conditions.CHAPTER_EDP`) and PC scores
        ``h1..hk`` (consecutive from h1). Other names are an error.
    geometry : mapping, optional
        The case's ``geometry`` section (e.g. ``{"kind": "default"}`` or
        ``{"kind": "mesh", "path": ...}``). Default: a ``pca`` geometry with
        the scores ``h1..hk`` when ``inputs`` has them, else the default LV.
        Giving both a geometry and PC scores is an error.
    resolution : str
        Mesh resolution preset, used unless ``geometry`` sets its own.
    base : {"clamped", "sliding"}
        Basal boundary condition.
    strain_layer : str
        The wall layer of the regional strains (:data:`lvcore.domain.outputs.STRAIN_LAYERS`; default the inner
        half); written as ``outputs.strain_layer`` unless it is the default.

    Returns
    -------
    dict
        ``geometry``, ``material``, ``fibres``, ``load`` (mmHg) and
        ``boundary`` sections (and ``outputs`` for another strain layer); validated later by
        :meth:`lvcore.mechanics.case.Case.from_dict`.

    Raises
    ------
    CaseError
        Missing material parameters, unknown or non-consecutive input names,
        or PC scores together with an explicit geometry.

    Examples
    --------
    >>> from lvcore.domain.conditions import THETA_TILDE
    >>> case = build_case({**THETA_TILDE, "edp": 10.0}, resolution="fast")
    >>> case["load"], case["fibres"], case["geometry"]
    ({'pressure': 10.0, 'units': 'mmHg'}, {'alpha_endo': -60.0, 'alpha_epi': 60.0}, {'kind': 'default', 'resolution': 'fast'})
    """
    v = {str(k): val for k, val in inputs.items()}
    try:
        layer = _layer(strain_layer)
    except ValueError as err:
        raise CaseError("outputs.strain_layer", str(err).split(": ", 1)[1]) from None
    known = set(THETA_NAMES) | set(ANGLE_NAMES) | {EDP_NAME}
    unknown = sorted(n for n in v if n not in known and not is_pc_name(n))
    if unknown:
        raise CaseError("inputs", f"unknown input name(s) {unknown}; known: {sorted(known)} and h1..hk")
    missing = [n for n in THETA_NAMES if n not in v]
    if missing:
        raise CaseError("material", f"missing material parameter(s) {missing} (a, af in kPa; b, bf dimensionless)")
    pcs = sorted((n for n in v if is_pc_name(n)), key=lambda n: int(n[1:]))
    if pcs and tuple(pcs) != pc_names(len(pcs)):
        raise CaseError("geometry.scores", f"PC scores must be h1..hk without gaps, got {pcs}")
    if pcs and geometry is not None:
        raise CaseError("geometry", f"give either PC scores {pcs} or a geometry section, not both")
    if geometry is not None:
        geom = dict(geometry)
        geom.setdefault("resolution", resolution)
    elif pcs:
        geom = {"kind": "pca", "scores": [float(v[n]) for n in pcs], "resolution": resolution}
    else:
        geom = {"kind": "default", "resolution": resolution}
    case = {
        "geometry": geom,
        "material": {"law": CASE_LAW, **{n: float(v[n]) for n in THETA_NAMES}},
        "fibres": {"alpha_endo": float(v.get(ANGLE_NAMES[0], CHAPTER_ANGLES[0])),
                   "alpha_epi": float(v.get(ANGLE_NAMES[1], CHAPTER_ANGLES[1]))},
        "load": {"pressure": float(v.get(EDP_NAME, CHAPTER_EDP)), "units": "mmHg"},
        "boundary": {"base": base},
    }
    if layer != DEFAULT_STRAIN_LAYER:  # the default is left out, so the cases of every earlier store are unchanged
        case["outputs"] = {"strain_layer": layer}
    return case


def space_case(space: ParameterSpace, row: Sequence[float], resolution: str = "default",
               strain_layer: str = DEFAULT_STRAIN_LAYER, geometry: Mapping | None = None) -> dict:
    """The simulator case dictionary for one design row of ``space`` (see :func:`build_case`).

    Parameters
    ----------
    space : ParameterSpace
        The design's space: its varied inputs, fixed inputs and basal boundary condition.
    row : sequence of float
        Values of ``space.names``, physical units.
    resolution : {"fast", "default", ...}
        Mesh resolution passed to the simulator's geometry section.
    strain_layer : str
        The wall layer of the strains (:func:`build_case`).
    geometry : mapping, optional
        A fixed case ``geometry`` section (e.g. a subject emulator's mesh); default: PC scores of the row, else the
        default LV (:func:`build_case`).

    Raises
    ------
    CampaignError
        The space defines no value for some of ``a, b, af, bf``.
    """
    v = space.full_inputs(row)
    missing = [n for n in THETA_NAMES if n not in v]
    if missing:
        raise CampaignError(f"space '{space.name}' does not define material parameter(s) {missing}")
    return build_case(v, geometry=geometry, resolution=resolution, base=space.base, strain_layer=strain_layer)


__all__ = ["CASE_LAW", "build_case", "space_case"]
