"""The wall layer of measured strains: what a data file declares, and the refusal of a layer the emulator was not
trained on.

The 24 regional strains are averaged over one layer of the wall
(:data:`lvcore.domain.outputs.STRAIN_LAYERS`: ``inner_half``, ``mid_wall``,
``whole_wall``, ``outer_half``); the chapter does not say which. An emulator
records the layer of its training strains (``metadata["strain_layer"]``,
:attr:`lvcore.emulator.model.Emulator.strain_layer`), and a data file may
declare the layer of its strains:

CSV
    a ``strain_layer`` column (every row the same layer, or blank);
JSON
    a ``strain_layer`` key at the top level (``{"strain_layer": ..., "subjects": [...]}``) or in each subject;
MATLAB ``.mat``
    a ``strain_layer`` char variable.

One file holds one layer. ``lvcore calibrate --strain-layer`` says the same for
a file that does not; a contradiction between the two, or a layer other than the
emulator's, is refused (exit 2) with what to do. Undeclared strains are taken to
be of the emulator's layer.
"""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, STRAIN_LAYER_LABELS, strain_layer
from lvcore.exceptions import DataError
from lvcore.safety import limits

#: The column (CSV), key (JSON) and variable (.mat) that declares the layer of a file's strains.
LAYER_FIELD = "strain_layer"


def _canonical(value, where: str) -> str:
    try:
        return strain_layer(value, where)
    except ValueError as err:
        raise DataError(str(err)) from None


def _one(values, where: str) -> str | None:
    """The single layer of ``values`` (blank ones ignored); None when none is given."""
    found = {}
    for v in values:
        if v is None or (isinstance(v, str) and not v.strip()) or (isinstance(v, float) and np.isnan(v)):
            continue
        found.setdefault(_canonical(v, f"{where}: {LAYER_FIELD}"), v)
    if len(found) > 1:
        raise DataError(f"{where}: {LAYER_FIELD} names {len(found)} layers ({', '.join(found)}); one file holds "
                        "strains of one wall layer, so split it")
    return next(iter(found), None)


def declared_strain_layer(path) -> str | None:
    """The layer a measured-data file declares for its strains (module docstring), or None.

    Raises
    ------
    DataError
        An unknown layer name, or several layers in one file.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".json":
        obj = limits.read_json_file(path, limits.MAX_MEASURED_BYTES, "measured-data file", DataError)
        top = obj.get(LAYER_FIELD) if isinstance(obj, dict) else None
        items = obj.get("subjects", []) if isinstance(obj, dict) and "subjects" in obj else obj
        items = items if isinstance(items, list) else [items]
        return _one([top] + [it.get(LAYER_FIELD) for it in items if isinstance(it, dict)], path.name)
    if suffix == ".mat":
        import scipy.io

        mat = scipy.io.loadmat(path, squeeze_me=True, chars_as_strings=True, variable_names=[LAYER_FIELD])
        value = mat.get(LAYER_FIELD)
        return None if value is None else _one([str(v) for v in np.atleast_1d(value).ravel()], path.name)
    text = limits.read_text_file(path, limits.MAX_MEASURED_BYTES, "measured-data file", DataError)
    rows = csv.reader(ln for ln in io.StringIO(text) if ln.strip() and not ln.lstrip().startswith("#"))
    header = [c.strip() for c in next(rows, [])]
    if LAYER_FIELD not in header:
        return None
    col = header.index(LAYER_FIELD)
    return _one([r[col] if col < len(r) else "" for r in rows], path.name)


def check_strain_layer(emulator, name: str, declared: str | None = None, asked: str | None = None,
                       where: str = "the data") -> str:
    """The layer of the measured strains, refused unless it is the emulator's.

    Parameters
    ----------
    emulator : lvcore.emulator.Emulator
    name : str
        The emulator as the user chose it (messages).
    declared : str, optional
        The layer the data file declares (:func:`declared_strain_layer`).
    asked : str, optional
        The layer the user gave (``--strain-layer``); default: the file's, else the emulator's own.
    where : str
        The data as the message names them.

    Returns
    -------
    str
        The layer (the emulator's).

    Raises
    ------
    DataError
        The file and the option disagree, or the strains are of another layer than the emulator's.
    """
    own = getattr(emulator, "strain_layer", DEFAULT_STRAIN_LAYER)  # a stand-in without one: the default
    declared = None if declared is None else _canonical(declared, f"{where}: {LAYER_FIELD}")
    asked = None if asked is None else _canonical(asked, "--strain-layer")
    if declared and asked and declared != asked:
        raise DataError(f"{where}: the file declares its strains as {declared} but --strain-layer says {asked}; "
                        "drop one or make them agree")
    layer = declared or asked or own
    if layer != own:
        raise DataError(
            f"{where}: the strains are {STRAIN_LAYER_LABELS[layer]} strains ({layer}), but emulator '{name}' was "
            f"trained on strains of the {STRAIN_LAYER_LABELS[own]} ({own}); strains of different wall layers differ "
            f"systematically, so give strains averaged over the {STRAIN_LAYER_LABELS[own]}, or use an emulator "
            f"trained on {layer} strains (`lvcore campaign run --strain-layer {layer}`, then `lvcore emulator "
            "train`); if the strains are in fact of the emulator's layer, correct the declaration")
    return layer


__all__ = ["LAYER_FIELD", "declared_strain_layer", "check_strain_layer"]
