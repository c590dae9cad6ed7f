"""PC scores of a geometry read from a file: JSON, CSV or a template mesh projected on the shape model.

Used wherever a user gives a geometry by its scores: calibration
(:mod:`lvcore.inference.calibrate`, the app's Calibration page) and subject
emulators (:mod:`lvcore.emulator.subject`). Every read goes through the
limits of :mod:`lvcore.safety.limits`; a bad file is a :class:`GeometryError`
naming it.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from lvcore.safety import limits
from lvcore.exceptions import GeometryError
from lvcore.domain.outputs import is_pc_name


def read_pc_scores(path, n_pc: int = 5) -> np.ndarray:
    """PC scores of a geometry from JSON, CSV or a template mesh file.

    * JSON: ``{"h": [h1, h2, ...]}`` or ``{"h1": ..., "h2": ...}`` or a plain list;
    * CSV: columns ``h1..hk`` (first row used) or one row/column of numbers;
    * mesh (``.vtu``, ``.vtk``, ``.xdmf``, ``.npy``, ``.npz``): node positions on
      the template, projected with ``lvcore.geometry.shape_model.load_shape_model().project(nodes)``.

    Returns the first ``n_pc`` scores.
    """
    path = limits.check_regular_file(path, limits.MAX_MESH_BYTES, "geometry file", GeometryError)
    suffix = path.suffix.lower()
    if suffix == ".json":
        obj = limits.read_json_file(path, limits.MAX_SCORES_BYTES, "geometry file", GeometryError)
        if isinstance(obj, dict):
            if "h" in obj:
                h = obj["h"]
            else:
                keys = sorted((k for k in obj if is_pc_name(k)), key=lambda k: int(k[1:]))
                h = [obj[k] for k in keys]
        else:
            h = obj
        h = _score_list(h, path.name)
    elif suffix == ".csv":
        limits.check_regular_file(path, limits.MAX_SCORES_BYTES, "geometry file", GeometryError)
        try:
            df = pd.read_csv(path)
            cols = [c for c in df.columns if is_pc_name(c)]
            if cols:
                cols = sorted(cols, key=lambda c: int(str(c)[1:]))
                h = df.loc[0, cols].to_numpy(dtype=float)
            else:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # "input contained no data": reported below
                    h = np.loadtxt(path, delimiter=",", ndmin=1).reshape(-1)
        except (ValueError, TypeError, KeyError, IndexError, OverflowError, UnicodeDecodeError,
                pd.errors.ParserError, pd.errors.EmptyDataError) as err:
            raise GeometryError(f"{path.name}: cannot read PC scores from this CSV ({type(err).__name__}: "
                                f"{str(err)[:200]}); give columns h1..h5 or one row of numbers") from None
    elif suffix in (".vtu", ".vtk", ".xdmf", ".npy", ".npz"):
        h = project_mesh(path)
    else:
        raise GeometryError(f"{path.name}: unknown geometry format '{suffix}'; give PC scores as .json/.csv "
                            "or a template mesh (.vtu, .vtk, .xdmf, .npy, .npz)")
    try:
        h = np.asarray(h, dtype=float).reshape(-1)
    except (TypeError, ValueError, OverflowError):
        raise GeometryError(f"{path.name}: PC scores must be numbers") from None
    if h.size < n_pc:
        raise GeometryError(f"{path.name}: need {n_pc} PC scores, found {h.size}")
    if not np.all(np.isfinite(h[:n_pc])):
        raise GeometryError(f"{path.name}: PC scores must be finite numbers")
    return h[:n_pc]


def _score_list(h, name: str) -> list:
    """The scores of a JSON geometry file: a flat list of numbers."""
    if not isinstance(h, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in h):
        raise GeometryError(f"{name}: PC scores must be a list of numbers ({{\"h\": [h1, h2, ...]}}, "
                            f"{{\"h1\": ..., \"h2\": ...}} or [h1, h2, ...])")
    return h


def read_scale(path) -> float:
    """The uniform scale ``s`` stored with PC scores (JSON key or CSV column ``scale``); 1 when absent.

    ``s`` is the factor of :mod:`lvcore.geometry.scaling`: the geometry is
    ``s`` times the shape with the stored scores, and the emulated LVV is
    multiplied by ``s^3``.

    Raises
    ------
    GeometryError
        If the scale is not a number in :data:`lvcore.geometry.scaling.SCALE_BOUNDS`.
    """
    from lvcore.geometry.scaling import SCALE_BOUNDS

    path = Path(path)
    value = None
    if path.suffix.lower() == ".json":
        obj = limits.read_json_file(path, limits.MAX_SCORES_BYTES, "geometry file", GeometryError)
        if isinstance(obj, dict):
            value = obj.get("scale")
    elif path.suffix.lower() == ".csv":
        try:
            df = pd.read_csv(path)
        except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
            return 1.0
        if "scale" in df.columns and len(df):
            value = df.loc[0, "scale"]
    if value is None:
        return 1.0
    try:
        s = float(value)
    except (TypeError, ValueError):
        raise GeometryError(f"{path.name}: 'scale' must be a number, got {str(value)[:40]!r}") from None
    if isinstance(value, bool) or not (np.isfinite(s) and SCALE_BOUNDS[0] <= s <= SCALE_BOUNDS[1]):
        raise GeometryError(f"{path.name}: scale = {value} is outside {SCALE_BOUNDS[0]:g}-{SCALE_BOUNDS[1]:g}; it is "
                            "the uniform size factor of the geometry (1 = the shape with these scores as it is)")
    return s


def project_mesh(path: Path, n_pc: int | None = None, with_scale: bool = False):
    """Scores of a template mesh file: the plain projection, or with ``with_scale``
    ``(h, scale, projection MSE (cm²), unscaled h)`` of :func:`lvcore.geometry.scaling.size_normalised_scores`."""
    from lvcore.geometry.io import _check_nodes, read_template_mesh
    from lvcore.geometry.template import DEFAULT_TEMPLATE

    if path.suffix.lower() in (".npy", ".npz"):
        try:
            from lvcore.safety.headers import load_npy, load_npz

            # array headers are checked against the limits before numpy allocates (lvcore.safety.headers)
            if path.suffix.lower() == ".npy":
                nodes = load_npy(path, limits.MAX_MESH_BYTES, "geometry file", GeometryError)
            else:
                arrays = load_npz(path, limits.MAX_MESH_BYTES, "geometry file", GeometryError)
                if not arrays:
                    raise GeometryError(f"{path.name}: the .npz archive holds no arrays; store the template "
                                        "node positions as 'nodes'")
                nodes = arrays["nodes"] if "nodes" in arrays else next(iter(arrays.values()))
            if not (np.issubdtype(nodes.dtype, np.integer) or np.issubdtype(nodes.dtype, np.floating)):
                raise GeometryError(f"{path.name}: node positions must be real numbers, got an array of {nodes.dtype}")
            nodes = np.asarray(nodes, dtype=float)
        except GeometryError:
            raise
        except (ValueError, TypeError, OSError, EOFError, KeyError, OverflowError) as err:
            raise GeometryError(f"{path.name}: cannot read node positions ({type(err).__name__}: {str(err)[:200]}); "
                                "give a numeric (n_nodes, 3) array of the template's nodes in mm") from None
        nodes = _check_nodes(nodes, DEFAULT_TEMPLATE, path.name)
    else:
        nodes = read_template_mesh(path)
    try:
        from lvcore.geometry.shape_model import load_shape_model
    except ImportError as err:
        raise GeometryError(f"cannot project {path.name}: the PCA shape model (lvcore.geometry.shape_model) "
                            f"is not available ({err}); give PC scores as .json/.csv instead") from err
    try:
        model = load_shape_model()
    except (FileNotFoundError, OSError) as err:
        raise GeometryError(f"cannot project {path.name}: no shape model found ({err}); build it with the "
                            "geometry commands or give PC scores as .json/.csv") from err
    if with_scale:
        from lvcore.geometry.scaling import size_normalised_scores

        res = size_normalised_scores(np.asarray(nodes, dtype=float), n_pc or 5, model)
        return res.h, res.scale, res.projection_mse_cm2, res.unscaled_h
    return np.asarray(model.project(np.asarray(nodes, dtype=float)), dtype=float)


__all__ = ["read_pc_scores", "read_scale", "project_mesh"]
