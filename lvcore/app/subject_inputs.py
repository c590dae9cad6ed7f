"""The My subject flow's inputs: the user's geometry and measurements read as ``lvcore calibrate`` reads them, and
the geometric measures of the no-mesh route checked as its options (:mod:`lvcore.app.subject_flow`)."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from lvcore.exceptions import DataError

#: File types the geometry step takes (volume meshes are fitted, template meshes projected).
GEOMETRY_TYPES = ("vtu", "vtk", "msh", "inp", "npy", "npz", "json", "csv")
#: File types the data step takes.
DATA_TYPES = ("csv", "json", "mat", "txt")


#: The My-subject page's control for a volume mesh's length units, named by the wrong-units warning.
UNITS_CONTROL = "the 'Mesh length units' choice"


def read_geometry(session, name: str, data: bytes, *, n_pc: int = 5, units: str = "mm"):
    """The PC scores and scale of an uploaded geometry, as ``lvcore calibrate --geometry FILE`` reads it.

    Parameters
    ----------
    session : lvcore.app.uploads.UploadSession
        The browser session's upload folder.
    name : str
        The user's file name (its suffix picks the reader).
    data : bytes
        The file's contents.
    n_pc : int
        PC scores the emulator uses.
    units : {"mm", "cm", "m"}
        Length units of a volume mesh.

    Returns
    -------
    lvcore.inference.guards.GeometrySource

    Raises
    ------
    lvcore.app.uploads.UploadError
        With a message naming the user's file.
    """
    from lvcore.inference import guards

    return session.read(name, data, lambda path: guards.resolve_geometry(path, n_pc=n_pc, units=units,
                                                                          units_option=UNITS_CONTROL),
                        slot="geometry")


def geometry_nodes(geometry) -> np.ndarray:
    """Template nodes (mm) of the geometry the emulator sees: the shape model at ``h``, scaled by ``s``."""
    from lvcore.geometry.scaling import scale_nodes
    from lvcore.geometry.shape_model import load_shape_model

    model = load_shape_model()
    h = np.asarray(geometry.h, float)[:model.n_modes]
    return scale_nodes(model.reconstruct(h), float(geometry.scale))


#: Relative difference between the entered reference volume and the model geometry's cavity that is flagged.
REFERENCE_VOLUME_TOLERANCE = 0.10


def geometry_measures(geometry, reference_volume_ml: float | None = None) -> tuple[dict, list]:
    """Cavity and wall volume (mL) and length (mm) of the geometry the emulator sees, and warnings.

    When the user entered the subject's early-diastolic cavity volume (``reference_volume_ml``),
    a difference above :data:`REFERENCE_VOLUME_TOLERANCE` is a warning: the emulated volumes, and so the
    stiffness, would be biased by the geometry.
    """
    from lvcore.geometry.measures import geometry_info

    info = geometry_info(geometry_nodes(geometry))
    warnings = []
    if reference_volume_ml is not None and reference_volume_ml > 0:
        rel = info["cavity_volume_ml"] / float(reference_volume_ml) - 1.0
        info["reference_volume_ml"] = float(reference_volume_ml)
        info["reference_volume_difference"] = rel
        if abs(rel) > REFERENCE_VOLUME_TOLERANCE:
            warnings.append(f"the model geometry's cavity is {info['cavity_volume_ml']:.1f} mL, {100 * rel:+.0f} % "
                            f"from the {reference_volume_ml:.1f} mL you entered: check the mesh's units and that "
                            "it is the early-diastolic (reference) frame; the stiffness would be biased")
    return info, warnings


def read_data(session, name: str, data: bytes, segments: str | None = None) -> list:
    """Measured rows of an uploaded CSV/JSON/``.mat`` (24 lvcore regions or AHA-16), as ``lvcore calibrate --data``.

    Raises
    ------
    lvcore.app.uploads.UploadError
        With a message naming the user's file.
    """
    from lvcore.inference.data import read_measurements

    return session.read(name, data, lambda path: read_measurements(path, segments=segments), slot="measured")


#: The no-mesh route's geometric measures, as the page labels them (units in the name).
MEASURE_LABELS = {"reference_volume_ml": "Reference (early-diastolic) cavity volume, mL",
                  "wall_volume_ml": "Wall (myocardial) volume, mL (LV mass in g / 1.05)",
                  "long_axis_mm": "Long axis, base plane to epicardial apex, mm"}
#: The warning of a no-mesh run without any geometric measure (the CLI's, in the page's terms).
NO_MEASURE_WARNING = ("no geometric measure given: the subject's size is inferred from the LVV and strains alone, and "
                      "size and stiffness trade off (a larger reference cavity inflated less fits the same LVV as a "
                      "smaller one inflated more); measure the early-diastolic cavity volume and enter it as the "
                      "reference volume")



def _entered_fields(entered: Mapping[str, float | None], ranges: Mapping[str, tuple], *, unknown, outside) -> dict:
    """Fields the user entered (0 or None: not given), each checked against its ``(lo, hi)`` range.

    ``unknown(name)`` and ``outside(name, value, lo, hi, unit)`` make the :class:`DataError` messages; the unit (mL
    or mm) is read from the field name's suffix.
    """
    import math

    given = {k: (None if v is None or float(v) == 0.0 else float(v)) for k, v in dict(entered).items()}
    for name, value in given.items():
        if name not in ranges:
            raise DataError(unknown(name))
        lo, hi = ranges[name]
        unit = {"ml": "mL", "mm": "mm"}[name.rsplit("_", 1)[-1]]
        if value is not None and not (math.isfinite(value) and lo <= value <= hi):
            raise DataError(outside(name, value, lo, hi, unit))
    return given


def _merge(out: dict, given: Mapping[str, float | None], disagree) -> list:
    """Put the entered values of ``given`` (None: not entered) into ``out`` (the data file's); a value that differs
    from the file's raises :class:`DataError` with ``disagree(name, value, file_value)``. Returns the names put."""
    put = []
    for name, value in given.items():
        if value is None:
            continue
        if name in out and abs(out[name] - value) > 1e-9:
            raise DataError(disagree(name, value, out[name]))
        out[name] = value
        put.append(name)
    return put


def inferred_measures(entered: Mapping[str, float | None], data_measures: Mapping[str, float] | None = None) -> dict:
    """The geometric measures of the no-mesh route: those entered (0 or None: not measured) and the data's columns.

    Validated as ``lvcore calibrate --reference-volume/--wall-volume/--long-axis``
    (:func:`lvcore.inference.geometry_prior.check_measures`).

    Raises
    ------
    lvcore.exceptions.DataError
        A measure outside its plausible range, or an entered measure that disagrees with the data's column,
        naming the field.
    """
    from lvcore.inference.geometry_prior import MEASURE_NAMES, MEASURE_RANGES, check_measures

    given = _entered_fields(
        entered, MEASURE_RANGES,
        unknown=lambda name: f"unknown geometric measure '{name}'; use {', '.join(MEASURE_NAMES)}",
        outside=lambda name, value, lo, hi, unit: (f"'{MEASURE_LABELS[name]}' = {value:g} is outside the plausible "
                                                   f"range {lo:g}-{hi:g} {unit}; enter it in {unit}, or 0 if not "
                                                   "measured"))
    out = check_measures(data_measures or {}, "the measurements file's geometric columns")
    _merge(out, given, lambda name, value, old: (f"'{MEASURE_LABELS.get(name, name)}' {value:g} and the measurements "
                                                 f"file's {name} {old:g} disagree; enter 0 to use the file's value, "
                                                 "or correct one of them"))
    return out


def inferred_measure_sds(entered: Mapping[str, float | None], data_sds: Mapping[str, float] | None = None,
                         measures: Mapping[str, float] | None = None) -> tuple[dict, dict]:
    """The measures' standard deviations of the no-mesh route, as ``--reference-volume-sd`` etc. and the data's
    ``*_sd`` columns: those entered (0 or None: the default) and the data's, which must agree.

    Returns
    -------
    sds : dict
        Measure name -> sd (mL, mm), only those given (the rest take
        :data:`lvcore.inference.geometry_prior.MEASURE_SD`).
    sources : dict
        Measure name -> ``"entered"`` or ``"data column <name>_sd"``.

    Raises
    ------
    lvcore.exceptions.DataError
        An sd outside its range (naming the field and the range), an entered sd that disagrees with the data's
        column, or an sd for a measure that is not given.
    """
    from lvcore.inference.geometry_prior import MEASURE_SD_COLUMNS, MEASURE_SD_RANGES, check_measure_sds

    given = _entered_fields(
        entered, MEASURE_SD_RANGES, unknown=lambda name: f"unknown geometric measure '{name}'",
        outside=lambda name, value, lo, hi, unit: (f"SD of '{MEASURE_LABELS[name]}' = {value:g} is outside "
                                                   f"{lo:g}-{hi:g} {unit}; enter the measurement's standard "
                                                   f"deviation in {unit}, or 0 for the default"))
    out = check_measure_sds(data_sds or {}, "the measurements file's geometric columns", by="column")
    sources = {k: f"data column {MEASURE_SD_COLUMNS[k]}" for k in out}
    for name in _merge(out, given, lambda name, value, old: (f"SD of '{MEASURE_LABELS[name]}' {value:g} and the "
                                                             f"measurements file's {MEASURE_SD_COLUMNS[name]} {old:g} "
                                                             "disagree; enter 0 to use the file's value")):
        sources[name] = "entered"
    have = set(measures or {})
    for name in out:
        if name not in have:
            raise DataError(f"an SD is given for '{MEASURE_LABELS[name]}' ({sources[name]}) but not the measure "
                            "itself; enter the measure too, or drop the SD")
    return out, sources



def template_mesh_file(session, nodes, label: str) -> Path:
    """Write fitted template nodes (mm) as a template mesh in the session's upload folder, the file
    ``lvcore emulator build --geometry`` takes (the Geometry page's fitted segmentations)."""
    from lvcore.geometry.io import write_template_mesh
    from lvcore.app.uploads import safe_name

    path = Path(session.path) / f"fitted_{safe_name(label, 'geometry')}.vtu"
    write_template_mesh(path, np.asarray(nodes, float), metadata={"label": f"fitted geometry {label}"})
    return path
