"""Saving and loading emulators: plain arrays (.npz) plus JSON metadata, never pickle.

An emulator directory holds

``network.npz``
    ``layer{i}_weight`` ``(n_out, n_in)`` and ``layer{i}_bias`` ``(n_out,)``
    for i = 0, 1, 2 (read with ``allow_pickle=False``).
``metadata.json``
    ``format`` (``"lvcore-emulator"``), ``format_version``, ``name``,
    ``input_names``, ``output_names``, ``bounds`` (``lower``, ``upper``),
    ``log_inputs`` (names log-transformed), ``log_outputs`` (outputs the
    network predicts on a log scale), ``fixed_inputs`` (name -> value),
    ``input_scaler`` / ``output_scaler`` (``mean``, ``sd``), ``architecture``
    (``hidden``, ``activation``, ``init_sd``), ``training`` (``set_hash``,
    sizes, seed, optimiser settings, the architecture search), ``validation``
    (metrics, see :func:`lvcore.emulator.training.metrics`), ``test``
    (metrics on a held-out set, if any), ``source`` (store, space,
    resolution, simulator versions), ``strain_layer`` (the wall layer of
    the training strains, :data:`lvcore.domain.outputs.STRAIN_LAYERS`;
    absent in emulators built before it was recorded, which were all
    trained on the inner half), ``created_at``, ``lvcore_version``,
    ``spec_note`` (honest statement of how far the training set is from the
    chapter's size).
``validation.npz`` (optional)
    ``inputs``, ``outputs``, ``predictions`` of the validation (or test)
    set, for parity plots.
``prior/`` (subject emulators with a prior mean only)
    a copy of the emulator the network corrects (same layout), so the
    directory stays self-contained; ``metadata.json``'s ``prior`` names it
    and holds the fixed inputs and scale
    (:class:`lvcore.emulator.model.PriorMean`).
``training_data.npz`` (optional, :func:`save_training_data`)
    the converged campaign rows behind the emulator: ``train_inputs``,
    ``train_outputs``, ``valid_*`` and ``test_*``.

:func:`load_emulator` takes a directory or a bare name: ``"chapter"`` is
looked up in ``$LVCORE_EMULATORS`` (if set) and then in the bundled
``assets/emulators/<name>/`` (package data, see :mod:`lvcore.resources`).
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

import lvcore
from lvcore.emulator.model import Emulator
from lvcore.emulator.network import from_arrays, to_arrays
from lvcore.exceptions import EmulatorError
from lvcore.domain.outputs import OUTPUT_COLUMNS
from lvcore.resources import asset_path

FORMAT = "lvcore-emulator"
FORMAT_VERSION = 1
#: Bundled emulators live here (package data, ``assets/emulators``).
ASSETS_DIR = asset_path("emulators")
#: Demonstration emulators built below the spec, shipped as package data; never loaded by name.
BELOW_SPEC_DIR = asset_path("emulators-below-spec")
#: Where ``scripts/build_emulators.py`` puts below-spec emulators it builds (relative to the working directory).
LOCAL_BELOW_SPEC_DIR = Path("build") / "emulators" / "below-spec"
#: Subfolder of an emulator directory that holds its prior mean's emulator.
PRIOR_DIR = "prior"
REQUIRED_KEYS = ("format", "format_version", "name", "input_names", "bounds", "log_inputs",
                 "input_scaler", "output_scaler", "architecture")


def emulator_search_path() -> list[Path]:
    """Directories searched for named emulators, in order."""
    dirs = []
    if os.environ.get("LVCORE_EMULATORS"):
        dirs += [Path(p) for p in os.environ["LVCORE_EMULATORS"].split(os.pathsep) if p]
    dirs.append(ASSETS_DIR)
    return dirs


def available_emulators() -> list[str]:
    """Names of emulators found on :func:`emulator_search_path`."""
    names = []
    for d in emulator_search_path():
        if d.is_dir():
            names += sorted(p.name for p in d.iterdir() if (p / "metadata.json").is_file() and p.name not in names)
    return names


def below_spec_emulators(*, bundled: bool = True) -> dict[str, Path]:
    """Below-spec (demonstration) emulators, labelled ``"<name> (below spec, demonstration)"``.

    Parameters
    ----------
    bundled : bool
        Include the ones shipped in :data:`BELOW_SPEC_DIR`; the ones in
        :data:`LOCAL_BELOW_SPEC_DIR` (under the working directory) are always
        included, the shipped one winning a name clash.

    Returns
    -------
    dict
        Label -> emulator directory, for loading by path.
    """
    found: dict[str, Path] = {}
    for below in ((BELOW_SPEC_DIR,) if bundled else ()) + (LOCAL_BELOW_SPEC_DIR,):
        if below.is_dir():
            for d in sorted(below.iterdir()):
                label = f"{d.name} (below spec, demonstration)"
                if (d / "metadata.json").is_file() and label not in found:
                    found[label] = d
    return found


def resolve_emulator_dir(name_or_path: str | Path) -> Path:
    p = Path(name_or_path)
    if p.is_dir():
        return p
    if p.name == str(name_or_path):  # a bare name
        for d in emulator_search_path():
            if (d / p.name).is_dir():
                return d / p.name
    found = ", ".join(available_emulators()) or "none"
    raise EmulatorError(
        f"emulator '{name_or_path}' not found (searched {[str(d) for d in emulator_search_path()]}; available: {found}); "
        "build one with `python scripts/build_emulators.py` or `lvcore emulator train`"
    )


def emulator_identity(name_or_path: str | Path) -> tuple[str, int]:
    """Which emulator files ``name_or_path`` means now: its folder (:func:`resolve_emulator_dir`) and the newest
    modification time (ns) of the files in it. A cache of loaded emulators keyed by it (the app's pages) loads
    again when the name resolves elsewhere (another ``LVCORE_EMULATORS``) or the files are rebuilt; ``("", 0)``
    when the name resolves to nothing (the load then says why)."""
    try:
        folder = resolve_emulator_dir(name_or_path)
    except EmulatorError:
        return "", 0
    stamps = [f.stat().st_mtime_ns for f in folder.iterdir() if f.is_file()]
    return str(folder.resolve()), max(stamps, default=0)


def save_emulator(emulator: Emulator, directory: str | Path, *, validation: dict | None = None) -> Path:
    """Write ``emulator`` to ``directory`` (created) as network.npz + metadata.json.

    Parameters
    ----------
    validation : dict, optional
        Arrays ``inputs``, ``outputs``, ``predictions`` to store in
        ``validation.npz`` for parity plots.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    meta = dict(emulator.metadata)
    meta.update({
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "name": emulator.name,
        "input_names": list(emulator.input_names),
        "output_names": list(emulator.output_names),
        "bounds": {"lower": _floats(emulator.lower), "upper": _floats(emulator.upper)},
        "log_inputs": [n for n, flag in zip(emulator.input_names, emulator.log_inputs) if flag],
        "fixed_inputs": {k: float(v) for k, v in emulator.fixed.items()},
        "log_outputs": [n for n, flag in zip(emulator.output_names, emulator.log_outputs) if flag],
        "input_scaler": {"mean": _floats(emulator.x_mean), "sd": _floats(emulator.x_sd)},
        "output_scaler": {"mean": _floats(emulator.y_mean), "sd": _floats(emulator.y_sd)},
        "architecture": {**meta.get("architecture", {}), "hidden": list(emulator.network.hidden), "activation": "tanh"},
        "strain_layer": emulator.strain_layer,
        "lvcore_version": meta.get("lvcore_version", lvcore.__version__),
        "created_at": meta.get("created_at", time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())),
    })
    written = dict(meta)
    sub = meta.get("subject")
    if isinstance(sub, dict) and isinstance(sub.get("geometry"), dict) and sub["geometry"].get("kind") == "mesh":
        path = Path(str(sub["geometry"].get("path", "")))
        if path.is_absolute() and path.parent.resolve() == directory.resolve():  # keep the directory relocatable
            written["subject"] = {**sub, "geometry": {**sub["geometry"], "path": path.name}}
    if emulator.prior is not None:
        prior = emulator.prior
        save_emulator(prior.emulator, directory / PRIOR_DIR)
        meta["prior"] = written["prior"] = {
            "directory": PRIOR_DIR, "name": prior.emulator.name, "inputs": dict(prior.inputs),
            "scale": float(prior.scale),
            "combine": "LVV = network ratio x prior LVV x scale^3; strains = network difference + prior strains",
            "prior_training_set_hash": (prior.emulator.metadata.get("training") or {}).get("set_hash")}
    np.savez(directory / "network.npz", **to_arrays(emulator.network))
    (directory / "metadata.json").write_text(json.dumps(written, indent=2, sort_keys=True))
    emulator.metadata.update(meta)  # the in-memory emulator now shows what was saved
    if validation is not None:
        np.savez(directory / "validation.npz", **{k: np.asarray(v, dtype=float) for k, v in validation.items()})
    return directory


def load_emulator(name_or_path: str | Path, *, strict: bool = False) -> Emulator:
    """Load an emulator by directory or bare name (see the module docstring).

    Raises
    ------
    EmulatorError
        If it cannot be found or its files are malformed.

    Examples
    --------
    >>> from lvcore.emulator.io import load_emulator
    >>> emulator = load_emulator("chapter")      # bundled, SYNTHETIC-trained
    >>> emulator.input_names                     # θ (kPa, -, kPa, -) and five PC scores of the shape model
    ('a', 'b', 'af', 'bf', 'h1', 'h2', 'h3', 'h4', 'h5')
    >>> load_emulator("no-such-emulator")
    Traceback (most recent call last):
    ...
    lvcore.exceptions.EmulatorError: ...
    """
    directory = resolve_emulator_dir(name_or_path)
    from lvcore.emulator.edpvr_states import is_edpvr_folder

    if is_edpvr_folder(directory):   # the EDPVR emulator, composed with its anchor for calibration at any EDP
        from lvcore.emulator.edpvr_states import load_state_emulator

        return load_state_emulator(directory)
    meta_path, net_path = directory / "metadata.json", directory / "network.npz"
    if not meta_path.is_file() or not net_path.is_file():
        raise EmulatorError(f"emulator directory '{directory}' needs metadata.json and network.npz")
    from lvcore.safety import limits

    meta = limits.read_json_file(meta_path, limits.MAX_EMULATOR_BYTES, "emulator metadata", EmulatorError)
    if not isinstance(meta, dict):
        raise EmulatorError(f"'{meta_path}' must hold a JSON object")
    missing = [k for k in REQUIRED_KEYS if k not in meta]
    if missing:
        raise EmulatorError(f"'{meta_path}' lacks key(s) {missing}")
    if meta["format"] != FORMAT or int(meta["format_version"]) > FORMAT_VERSION:
        raise EmulatorError(f"'{meta_path}': unsupported format {meta['format']!r} v{meta['format_version']}")
    from lvcore.safety.headers import load_npz

    # every array header is checked against the limits before numpy allocates (lvcore.safety.headers)
    arrays = load_npz(net_path, limits.MAX_EMULATOR_BYTES, "emulator network", EmulatorError)
    try:
        network = from_arrays(arrays)
    except (ValueError, KeyError, TypeError) as err:
        raise EmulatorError(f"'{net_path}' is not an emulator network: {str(err)[:200]}") from None
    names = tuple(meta["input_names"])
    from lvcore.domain.outputs import strain_layer

    try:  # absent: built before the layer was recorded, on the simulator's default (the inner half)
        if "strain_layer" in meta:
            meta["strain_layer"] = strain_layer(meta["strain_layer"], f"'{meta_path}': strain_layer")
    except ValueError as err:
        raise EmulatorError(str(err)) from None
    _resolve_subject_geometry(meta, directory)
    prior = _load_prior(meta, directory)
    try:
        return Emulator(
            name=str(meta["name"]),
            input_names=names,
            lower=np.asarray(meta["bounds"]["lower"], dtype=float),
            upper=np.asarray(meta["bounds"]["upper"], dtype=float),
            log_inputs=tuple(n in set(meta["log_inputs"]) for n in names),
            x_mean=np.asarray(meta["input_scaler"]["mean"], dtype=float),
            x_sd=np.asarray(meta["input_scaler"]["sd"], dtype=float),
            y_mean=np.asarray(meta["output_scaler"]["mean"], dtype=float),
            y_sd=np.asarray(meta["output_scaler"]["sd"], dtype=float),
            network=network,
            fixed={k: float(v) for k, v in meta.get("fixed_inputs", {}).items()},
            metadata=meta,
            strict=strict,
            log_outputs=tuple(n in set(meta.get("log_outputs", [])) for n in OUTPUT_COLUMNS),
            prior=prior,
        )
    except (KeyError, TypeError, ValueError) as err:
        raise EmulatorError(f"'{meta_path}' is malformed: {err!r}") from err


def _load_prior(meta: dict, directory: Path):
    """The :class:`~lvcore.emulator.model.PriorMean` recorded in ``meta`` (its emulator in ``directory/prior``), or None."""
    rec = meta.get("prior")
    if rec is None:
        return None
    from lvcore.emulator.model import PriorMean

    where = f"'{directory}/metadata.json'"
    sub = rec.get("directory", PRIOR_DIR) if isinstance(rec, dict) else None
    if not isinstance(rec, dict) or not isinstance(rec.get("inputs"), dict) or not isinstance(sub, str) \
            or len(sub) > 255 or "\x00" in sub:
        raise EmulatorError(f"{where}: 'prior' must be an object with 'directory' (a subfolder name), 'inputs' "
                            "and 'scale'")
    folder = (directory / sub).resolve()
    if folder == directory.resolve() or directory.resolve() not in folder.parents:
        raise EmulatorError(f"{where}: the prior mean's emulator must lie in a subfolder of the emulator directory, "
                            f"got {rec.get('directory')!r}")
    if not folder.is_dir():
        raise EmulatorError(f"{where}: the prior mean's emulator folder '{folder}' is missing; copy the whole "
                            "emulator directory, or build it again")
    numbers = {**{f"inputs.{k}": v for k, v in rec["inputs"].items()}, "scale": rec.get("scale", 1.0)}
    bad = [k for k, v in numbers.items()
           if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(float(v))]
    if bad:
        raise EmulatorError(f"{where}: the prior's {', '.join(bad[:3])} must be finite numbers")
    return PriorMean(load_emulator(folder), {str(k): float(v) for k, v in rec["inputs"].items()},
                     float(numbers["scale"]))


def _resolve_subject_geometry(meta: dict, directory: Path) -> None:
    """A subject emulator's geometry file, named relative to its directory, as an absolute path (in memory)."""
    sub = meta.get("subject")
    if not isinstance(sub, dict) or not isinstance(sub.get("geometry"), dict):
        return
    geo = dict(sub["geometry"])
    if geo.get("kind") == "mesh":
        path = Path(str(geo.get("path", "")))
        if not path.is_absolute():
            path = (directory / path).resolve()
            if directory.resolve() not in path.parents:
                raise EmulatorError(f"'{directory}/metadata.json': the subject geometry must lie in the emulator "
                                    f"directory, got {geo.get('path')!r}")
        if not path.is_file():
            raise EmulatorError(f"subject emulator '{directory}': its geometry file '{path}' is missing")
        geo["path"] = str(path)
    meta["subject"] = {**sub, "geometry": geo}


def provenance_path(path: str | Path, folder: str | Path) -> str:
    """``path`` as metadata records it: relative to ``folder`` (POSIX separators), or by its file name alone when
    it lies outside ``folder``, so an emulator's metadata never records a path of the machine that built it.

    ``scripts/build_emulators.py`` records its stores relative to the build folder, ``lvcore emulator train``
    relative to the emulator's folder (``--out``).
    """
    try:
        return Path(path).resolve().relative_to(Path(folder).resolve()).as_posix()
    except ValueError:
        return Path(path).name


def save_training_data(out_dir: str | Path, sets: dict) -> Path:
    """Ship the converged campaign rows an emulator was trained on: ``training_data.npz``.

    Parameters
    ----------
    out_dir : path
        The emulator's directory.
    sets : dict
        ``{"train": (inputs, outputs), "valid": ..., "test": ...}``; inputs
        ``(n, d)`` in the emulator's input order (stored as float64, exact),
        outputs ``(n, 25)`` (stored as float32, ~7 significant digits, far
        below the simulator's discretisation error).

    Returns
    -------
    Path
        The file, with arrays ``<set>_inputs`` and ``<set>_outputs``.
    """
    arrays = {}
    for key, (x, y) in sets.items():
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float32)
        if x.ndim != 2 or y.shape != (x.shape[0], len(OUTPUT_COLUMNS)):
            raise EmulatorError(f"training data '{key}': inputs (n, d) and outputs (n, 25) expected, got {x.shape}, {y.shape}")
        arrays[f"{key}_inputs"], arrays[f"{key}_outputs"] = x, y
    path = Path(out_dir) / "training_data.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)
    return path


def load_validation(name_or_path: str | Path) -> dict | None:
    """The stored validation arrays (``inputs``, ``outputs``, ``predictions``), or None."""
    path = resolve_emulator_dir(name_or_path) / "validation.npz"
    if not path.is_file():
        return None
    from lvcore.safety import limits
    from lvcore.safety.headers import load_npz

    return load_npz(path, limits.MAX_EMULATOR_BYTES, "emulator validation arrays", EmulatorError)


def _floats(a) -> list[float]:
    return [float(v) for v in np.asarray(a, dtype=float).reshape(-1)]
