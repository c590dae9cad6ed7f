r"""A subject EDPVR emulator: ``(θ, p) -> log V(p)/V₀, log λ_f(p)`` on one subject emulator's fixed mesh.

The derived EDPVR of a calibration (:mod:`lvcore.inference.derived`) needs the cavity volume at 0-30 mmHg and the
mean fibre stretch at the EDP for 100 or more posterior draws. The bundled EDPVR emulator
(:mod:`lvcore.emulator.edpvr`) covers the shape model's PC-score geometries; a calibration through a subject
emulator (:mod:`lvcore.emulator.subject`, the geometry fixed and bound in) fell back to FE load paths, 700
warm-chained solves. This module trains a small EDPVR emulator on the subject emulator's own mesh, saved in its
folder (``<emulator>/edpvr/``), which :func:`lvcore.emulator.edpvr.emulator_for` finds and ``derive()`` evaluates
directly (NumPy, microseconds per draw).

Training data. FE load paths (:func:`lvcore.campaigns.load_paths.run_load_paths`, each row solved at increasing
pressures, warm-continued; :data:`TRAINING_PRESSURES_MMHG`) on the subject's geometry section, at the subject emulator's base condition, fibre
angles, mesh resolution and strain layer, over the θ box of its design space (log-uniform): a scrambled Sobol
design for training (seed ``S``), another for validation (``S + 1``: early stopping and the L-BFGS iterate) and a
uniform random one for the held-out test (``S + 2``) whose paths run at pressures *between* the training ones
(:data:`~lvcore.campaigns.load_paths.TEST_PRESSURES_MMHG`), so the test measures the interpolation in pressure
too (:func:`lvcore.campaigns.designs.make_design`, ``scipy.stats.qmc``).

Representation. The mesh is fixed, so V₀ is one number (the simulator's reference cavity, from the first solve
of every path; stored in the metadata) and the network maps ``(log a, log b, log af, log bf, log(1 + p))``
directly to ``log V(p)/V₀`` and ``log λ_f(p)`` (a 5 -> 64 -> 64 -> 2 tanh MLP, the training code of
:mod:`lvcore.emulator.training`; λ_f weighted by :data:`~lvcore.emulator.edpvr.STRETCH_WEIGHT` as in the bundled
one). No anchor is needed. On SYNTHETIC_HV3 (default mesh, 32 held-out paths; 256 training paths at all 14
pressures of the bundled design) the held-out RMSE of ``log V/V₀`` over the whole θ box was 0.6-2.1 % for this
direct fit (0.4-0.7 % where EDV/V₀ <= 2.5 at 8 mmHg), 0.7-4 % for the bundled emulator's anchored form even with
the FE V₈ as anchor (0.35-0.8 %, 2.6 % at 0.5 mmHg), 0.9-3.3 % for a direct fit in ``p`` rather than
``log(1 + p)``, and 2-5 % from 128 training paths; with the 8 pressures used here (:data:`TRAINING_PRESSURES_MMHG`)
0.3-1.9 % (0.3-0.7 %; BENCHMARKS.md row 51). At ``p = 0`` both outputs are exactly 0 (rows in the training set,
and forced on evaluation).

The held-out RMSE per test pressure (``log V/V₀`` and λ_f) is stored under ``test`` in the metadata, as the
bundled emulator's, so :func:`lvcore.emulator.edpvr.emulator_error_draws` draws it into the derived band the
same way. The emulator is an :class:`~lvcore.emulator.edpvr.EdpvrEmulator` with inputs :data:`INPUT_NAMES` and
outputs :data:`OUTPUT_NAMES` (``log1p_pressure`` set).

Files (``<subject emulator>/edpvr/``): ``edpvr.json`` (format :data:`FORMAT`: inputs, box, scalers, V₀, the
geometry's fingerprint, held-out errors, provenance), ``network.npz``, ``validation.npz`` (the held-out paths,
predictions and FE values) and ``load_paths_{train,valid,test}.npz`` (the FE load paths; a build into the same
folder with the same design reuses them).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from lvcore.domain.outputs import ANGLE_NAMES, EDP_NAME, THETA_NAMES
from lvcore.emulator.edpvr import METADATA_FILE, STRETCH_WEIGHT, EdpvrEmulator, EmulatedPath, read_layers
from lvcore.exceptions import EmulatorError

FORMAT = "lvcore-subject-edpvr-emulator"
FORMAT_VERSION = 1
#: The subfolder of a subject emulator's folder that holds its EDPVR emulator.
FOLDER = "edpvr"
INPUT_NAMES = THETA_NAMES + (EDP_NAME,)
OUTPUT_NAMES = ("log_volume_ratio", "log_fibre_stretch")
#: Highest pressure of the EDPVR (mmHg): the top of the emulator's pressure box.
MAX_PRESSURE_MMHG = 30.0
#: Held-out errors are also reported for paths with EDV/V₀ at 8 mmHg up to this ratio (-), as the bundled one's.
PHYSIOLOGICAL_V8_RATIO = 2.5
#: Files of the FE load paths kept in the folder (one per part of the design).
PATHS_FILE = "load_paths_{}.npz"
#: Pressures (mmHg) of the training and validation load paths: 8 of the bundled emulator's 14
#: (:data:`~lvcore.campaigns.load_paths.LOAD_PATH_PRESSURES_MMHG`). On SYNTHETIC_HV3 (256 paths, ``log(1 + p)``
#: input) they gave the same held-out error as all 14 (0.4-0.8 % at 5-30 mmHg) at 57 % of the solve time.
TRAINING_PRESSURES_MMHG = (1.0, 2.0, 4.0, 6.5, 10.0, 14.0, 20.0, 30.0)


@dataclass(frozen=True)
class EdpvrDesign:
    """Load paths of a subject EDPVR emulator's design.

    Attributes
    ----------
    n_train, n_valid, n_test : int
        Training paths (Sobol), validation paths (Sobol, another seed) and held-out test paths (uniform random, at
        pressures between the training ones). A training or validation path is 8 FE solves of 1-30 mmHg
        (:data:`TRAINING_PRESSURES_MMHG`), a test path 14.
    method : str
        Design method of the training and validation paths (:func:`lvcore.campaigns.designs.make_design`).

    The default (256 + 16 + 32 paths) reached a held-out RMSE of ``log V/V₀`` of 0.4-2 % on SYNTHETIC_HV3 over
    the whole θ box (the most at 2.5-3.5 mmHg); 128 training paths gave 2-5 % (BENCHMARKS.md row 51).
    """

    n_train: int = 256
    n_valid: int = 16
    n_test: int = 32
    method: str = "sobol"

    def __post_init__(self):
        for k in ("n_train", "n_valid", "n_test"):
            if int(getattr(self, k)) < 2:
                raise EmulatorError(f"the EDPVR design's {k.replace('_', '-')} must be >= 2 paths, got "
                                    f"{getattr(self, k)}")
        if self.n_train + self.n_valid + self.n_test > 4096:
            raise EmulatorError("a subject EDPVR design is capped at 4,096 load paths")


def default_edpvr_config(seed: int = 0):
    """The :class:`~lvcore.emulator.training.TrainingConfig` of subject EDPVR emulators.

    One 64 x 64 network, 1,500 Adam epochs (batch 64, learning rate halved every 250 epochs, patience 375), then
    4,000 L-BFGS iterations, both outputs weighted alike (λ_f's extra weight is in the standardisation). About
    30-40 s on one core for 256 paths (≈ 2,300 rows).
    """
    from lvcore.emulator.training import TrainingConfig

    return TrainingConfig(architectures=((64, 64),), max_epochs=1500, decay_epochs=250, patience=375,
                          batch_size=64, lbfgs_iterations=4000, lvv_weight=1.0, lbfgs_lvv_weight=1.0, seed=seed)


def edpvr_space(space, *, alpha_endo: float, alpha_epi: float):
    """The load paths' space: θ as in a subject emulator's design ``space`` (its bounds and scales), the fibre
    angles fixed (the space's fixed ones, else ``alpha_endo``/``alpha_epi``, deg), the EDP a placeholder (each
    pressure replaces it), the space's base condition."""
    from lvcore.core.space import ParameterSpace

    params = tuple(p for p in space.parameters if p.name in THETA_NAMES)
    if tuple(p.name for p in params) != THETA_NAMES:
        raise EmulatorError(f"the subject emulator's space must vary {THETA_NAMES}, got {space.names}")
    fixed = space.fixed_dict()
    angles = {ANGLE_NAMES[0]: float(fixed.get(ANGLE_NAMES[0], alpha_endo)),
              ANGLE_NAMES[1]: float(fixed.get(ANGLE_NAMES[1], alpha_epi))}
    return ParameterSpace(f"{space.name}-edpvr", params, tuple(angles.items()) + ((EDP_NAME, 8.0),), space.base)


def transform_inputs(x) -> np.ndarray:
    """``(..., 5)`` :data:`INPUT_NAMES` (kPa, -, kPa, -, mmHg) -> ``(log a, log b, log af, log bf, log(1 + p))``."""
    z = np.array(x, dtype=float)
    z[..., :4] = np.log(z[..., :4])
    z[..., 4] = np.log1p(z[..., 4])
    return z


def training_rows(data) -> tuple[np.ndarray, np.ndarray]:
    """Inputs ``(M, 5)`` and outputs ``(M, 2)`` (``log V/V₀``, ``log λ_f``) of every converged (path, pressure) of
    a :class:`~lvcore.campaigns.load_paths.LoadPathData`, with a ``p = 0`` row (outputs 0) per path."""
    X, Y = [], []
    for i in range(data.inputs.shape[0]):
        if not np.isfinite(data.v0_ml[i]):
            continue
        X.append(np.r_[data.inputs[i], 0.0])
        Y.append(np.zeros(2))
        for j, p in enumerate(data.pressures_mmhg):
            if np.isfinite(data.lvv_ml[i, j]) and np.isfinite(data.fibre_stretch[i, j]):
                X.append(np.r_[data.inputs[i], p])
                Y.append([np.log(data.lvv_ml[i, j] / data.v0_ml[i]), np.log(data.fibre_stretch[i, j])])
    if not X:
        raise EmulatorError("no converged load path to train a subject EDPVR emulator on")
    return np.asarray(X), np.asarray(Y)


def geometry_fingerprint(section: Mapping) -> str:
    """SHA-256 of a geometry: the mesh file's bytes for a ``mesh`` section, else the section's JSON (sorted)."""
    if section.get("kind") == "mesh":
        path = Path(str(section.get("path", "")))
        if not path.is_file():
            raise EmulatorError(f"the subject geometry's mesh file '{path}' is missing")
        return hashlib.sha256(path.read_bytes()).hexdigest()
    return hashlib.sha256(json.dumps(dict(section), sort_keys=True).encode()).hexdigest()


# --------------------------------------------------------------------------- held-out errors and training
def heldout(emu: EdpvrEmulator, data) -> tuple[dict, dict]:
    """Held-out errors per test pressure (the ``test`` metadata, keys as the bundled emulator's) and the
    validation arrays of the test paths ``data``."""
    P, n = data.pressures_mmhg.size, data.inputs.shape[0]
    X = np.concatenate([np.repeat(data.inputs[:, None, :], P, axis=1),
                        np.broadcast_to(data.pressures_mmhg[None, :, None], (n, P, 1))], axis=2)
    pred = emu.outputs(X)
    v0 = float(emu.metadata["subject"]["v0_ml"])
    ok = np.isfinite(data.lvv_ml) & np.isfinite(data.fibre_stretch)
    err_v = np.where(ok, v0 * np.exp(pred[..., 0]) - data.lvv_ml, np.nan)
    err_log = np.where(ok, pred[..., 0] - np.log(data.lvv_ml / v0), np.nan)
    err_lam = np.where(ok, np.exp(pred[..., 1]) - data.fibre_stretch, np.nan)

    def rmse(e):
        return np.sqrt(np.nanmean(e ** 2, axis=0))

    with np.errstate(all="ignore"):
        v8 = np.array([np.interp(8.0, np.r_[0.0, data.pressures_mmhg[r]], np.r_[v0, data.lvv_ml[i, r]])
                       for i, r in enumerate(ok)])
    phys = v8 / v0 <= PHYSIOLOGICAL_V8_RATIO
    test = {"n_paths": int(n), "n_failed_solves": int((~ok).sum()),
            "pressures_mmhg": [float(p) for p in data.pressures_mmhg],
            "volume_rmse_ml": rmse(err_v).tolist(),
            "volume_p99_abs_ml": np.nanquantile(np.abs(err_v), 0.99, axis=0).tolist(),
            "volume_max_abs_ml": np.nanmax(np.abs(err_v), axis=0).tolist(),
            "log_volume_ratio_rmse": rmse(err_log).tolist(),
            "log_volume_ratio_max_abs": np.nanmax(np.abs(err_log), axis=0).tolist(),
            "fibre_stretch_rmse": rmse(err_lam).tolist(),
            "fibre_stretch_max_abs": np.nanmax(np.abs(err_lam), axis=0).tolist(),
            "volume_rmse_ml_all": float(rmse(err_v.ravel())),
            "fibre_stretch_rmse_all": float(rmse(err_lam.ravel())),
            "physiological_v8_ratio_max": PHYSIOLOGICAL_V8_RATIO, "n_physiological": int(phys.sum())}
    if phys.any():
        test.update({"volume_rmse_ml_physiological": rmse(err_v[phys]).tolist(),
                     "log_volume_ratio_rmse_physiological": rmse(err_log[phys]).tolist(),
                     "fibre_stretch_rmse_physiological": rmse(err_lam[phys]).tolist()})
    arrays = {"inputs": X, "pressures_mmhg": data.pressures_mmhg, "v0_ml": data.v0_ml, "lvv_ml": data.lvv_ml,
              "fibre_stretch": data.fibre_stretch, "predictions": pred}
    return test, arrays


def train_subject_edpvr(train, valid, test, *, name: str, base: str, resolution: str, angles: Sequence[float],
                        lower: Sequence[float], upper: Sequence[float], config=None, log=None,
                        metadata: Mapping | None = None) -> tuple[EdpvrEmulator, dict]:
    """Train on load paths (:class:`~lvcore.campaigns.load_paths.LoadPathData`): Adam with early stopping on
    ``valid`` (:func:`lvcore.emulator.training.search_architectures`), then L-BFGS; held-out errors on ``test``.

    Parameters
    ----------
    train, valid, test : LoadPathData
    name : str
    base, resolution : str
        The FE runs' base condition and mesh preset.
    angles : (float, float)
        The fibre angles of the runs (deg).
    lower, upper : sequence of float
        The θ box (kPa, -, kPa, -); the pressure box is [0, :data:`MAX_PRESSURE_MMHG`].
    config : TrainingConfig, optional
        Default :func:`default_edpvr_config`.
    log : callable, optional
    metadata : mapping, optional
        Merged into the emulator's ``subject`` metadata (geometry fingerprint, design, seconds).

    Returns
    -------
    EdpvrEmulator, dict
        The emulator (``metadata["test"]``: held-out errors) and the validation arrays.
    """
    from lvcore.emulator.network import to_arrays
    from lvcore.emulator.training import refine_lbfgs, search_architectures

    t0 = time.perf_counter()
    config = config or default_edpvr_config()
    v0 = np.asarray(train.v0_ml, float)
    v0 = float(np.median(v0[np.isfinite(v0)]))
    x, y = training_rows(train)
    xv, yv = training_rows(valid)
    tx, txv = transform_inputs(x), transform_inputs(xv)
    x_mean, x_sd = tx.mean(0), tx.std(0)
    y_mean, y_sd = y.mean(0), y.std(0)
    w_sd = y_sd.copy()
    w_sd[1] /= np.sqrt(STRETCH_WEIGHT)   # a loss weight w on an output is its sd over sqrt(w)
    zx, zxv = (tx - x_mean) / x_sd, (txv - x_mean) / x_sd
    zy, zyv = (y - y_mean) / w_sd, (yv - y_mean) / w_sd
    if log:
        log(f"[{name}] {x.shape[0]} training rows ({train.inputs.shape[0]} paths), {xv.shape[0]} validation rows")
    fits = search_architectures(zx, zy, zxv, zyv, config, log=log)
    best = min(fits, key=lambda f: f.valid_mse)
    net, refinement = best.network, None
    if config.lbfgs_iterations:
        net, refinement = refine_lbfgs(net, zx, zy, zxv, zyv, config)
    arrays = to_arrays(net)
    n = len(arrays) // 2
    meta = {"subject": {"v0_ml": v0, **dict(metadata or {})},
            "architecture": {"hidden": list(best.hidden), "activation": "tanh",
                             "inputs": "log a, log b, log af, log bf, log(1 + p)"},
            "training": {"config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(config).items()},
                         "valid_mse": best.valid_mse, "best_epoch": best.best_epoch,
                         "lbfgs": None if refinement is None else {k: refinement[k] for k in
                                                                   ("iterations", "valid_before", "valid_after")},
                         "n_train_rows": int(x.shape[0]), "n_valid_rows": int(xv.shape[0]),
                         "n_failed_solves": int((~np.isfinite(train.lvv_ml)).sum()),
                         "seconds": round(time.perf_counter() - t0, 1)}}
    emu = EdpvrEmulator(name, np.r_[np.asarray(lower, float), 0.0], np.r_[np.asarray(upper, float), MAX_PRESSURE_MMHG],
                        x_mean, x_sd, y_mean, w_sd, tuple(np.asarray(arrays[f"layer{i}_weight"], float) for i in range(n)),
                        tuple(np.asarray(arrays[f"layer{i}_bias"], float) for i in range(n)),
                        {"alpha_endo": float(angles[0]), "alpha_epi": float(angles[1])}, base, resolution, {}, meta,
                        log1p_pressure=True)
    test_rec, validation = heldout(emu, test)
    return dataclasses.replace(emu, metadata={**meta, "test": test_rec}), validation


# --------------------------------------------------------------------------- the build
def _load_paths(part: str, space, rows: np.ndarray, pressures, folder: Path, *, geometry: Mapping, resolution: str,
                workers: int, strain_layer: str, log):
    """The FE load paths of one part of the design, reused from ``folder`` when it holds the same rows."""
    from lvcore.campaigns.load_paths import LoadPathData, run_load_paths

    path = folder / PATHS_FILE.format(part)
    if path.is_file():
        try:
            old = LoadPathData.load(path)
            if old.inputs.shape == rows.shape and np.array_equal(old.inputs, rows) and \
                    np.array_equal(old.pressures_mmhg, np.asarray(pressures, float)):
                return old
        except (OSError, KeyError, ValueError):
            pass   # damaged: run again
    t0 = time.perf_counter()
    data = run_load_paths(space, rows, resolution=resolution, workers=workers, chunk=4, pressures_mmhg=pressures,
                          geometry=geometry, strain_layer=strain_layer)
    data.save(path)
    if log:
        log(f"  EDPVR {part} load paths: {rows.shape[0]} x {len(pressures)} pressures in "
            f"{time.perf_counter() - t0:.1f} s ({int(np.isnan(data.lvv_ml).sum())} failed solves)")
    return data


def build_subject_edpvr(geometry: Mapping, space, out, *, resolution: str, strain_layer: str,
                        alpha_endo: float, alpha_epi: float, design: EdpvrDesign = EdpvrDesign(), workers: int = 2,
                        seed: int = 0, config=None, name: str = "subject-edpvr",
                        log: Callable[[str], None] | None = None) -> EdpvrEmulator:
    """Build, validate and save the EDPVR emulator of a subject emulator's mesh (see the module docstring).

    Parameters
    ----------
    geometry : mapping
        The subject emulator's case ``geometry`` section (a ``mesh`` path is fingerprinted, :func:`geometry_fingerprint`).
    space : ParameterSpace
        The subject emulator's design space (its θ box, fixed angles, base condition).
    out : str or Path
        The folder (``<subject emulator>/edpvr``; created).
    resolution, strain_layer : str
        The subject emulator's mesh preset and strain layer.
    alpha_endo, alpha_epi : float
        Fibre angles (deg) where the space varies them (else its fixed ones are used).
    design : EdpvrDesign
    workers : int
        FE worker processes.
    seed : int
        Seeds of the designs (training ``seed``, validation ``seed + 1``, test ``seed + 2``) and the training.
    config : TrainingConfig, optional
        Default :func:`default_edpvr_config`.
    name : str
    log : callable, optional

    Returns
    -------
    EdpvrEmulator
        As saved and loaded back.
    """
    from lvcore.campaigns.designs import make_design
    from lvcore.campaigns.load_paths import TEST_PRESSURES_MMHG

    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sp = edpvr_space(space, alpha_endo=alpha_endo, alpha_epi=alpha_epi)
    fixed = sp.fixed_dict()
    parts = {"valid": (design.method, design.n_valid, seed + 1, TRAINING_PRESSURES_MMHG),
             "test": ("random", design.n_test, seed + 2, TEST_PRESSURES_MMHG),
             "train": (design.method, design.n_train, seed, TRAINING_PRESSURES_MMHG)}
    data = {}
    for part, (method, n, s, pressures) in parts.items():
        rows = make_design(sp, method, n, int(s) % 2 ** 32).points
        data[part] = _load_paths(part, sp, rows, pressures, out, geometry=geometry, resolution=resolution,
                                 workers=workers, strain_layer=strain_layer, log=log)
    t_runs = time.perf_counter() - t0
    record = {"geometry_sha256": geometry_fingerprint(geometry), "geometry_kind": str(geometry.get("kind")),
              "strain_layer": strain_layer, "space": sp.to_dict(),
              "design": {**dataclasses.asdict(design), "seeds": {k: int(v[2]) for k, v in parts.items()}},
              "seconds": {"load_paths": round(t_runs, 1)}}
    emu, validation = train_subject_edpvr(data["train"], data["valid"], data["test"], name=name, base=sp.base,
                                          resolution=resolution,
                                          angles=(fixed[ANGLE_NAMES[0]], fixed[ANGLE_NAMES[1]]), lower=sp.lower,
                                          upper=sp.upper, config=config or default_edpvr_config(seed), log=log,
                                          metadata=record)
    emu.metadata["subject"]["seconds"]["total"] = round(time.perf_counter() - t0, 1)
    save_subject_edpvr(emu, out, validation)
    if log:
        t = emu.metadata["test"]
        log(f"  EDPVR emulator: held-out ({t['n_paths']} paths) log V/V0 RMSE "
            f"{min(t['log_volume_ratio_rmse']):.4f}-{max(t['log_volume_ratio_rmse']):.4f} at "
            f"{min(t['pressures_mmhg']):g}-{max(t['pressures_mmhg']):g} mmHg, fibre stretch RMSE up to "
            f"{max(t['fibre_stretch_rmse']):.4f}; {emu.metadata['subject']['seconds']['total']:.0f} s")
    return load_subject_edpvr(out)


# --------------------------------------------------------------------------- files
def save_subject_edpvr(emu: EdpvrEmulator, folder, validation: Mapping | None = None) -> Path:
    """Write ``edpvr.json``, ``network.npz`` and (given) ``validation.npz`` into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    meta = {"format": FORMAT, "format_version": FORMAT_VERSION, "name": emu.name, "input_names": list(INPUT_NAMES),
            "output_names": list(OUTPUT_NAMES), "input_transform": "log theta, log(1 + p)",
            "lower": emu.lower.tolist(), "upper": emu.upper.tolist(),
            "input_scaler": {"mean": emu.x_mean.tolist(), "sd": emu.x_sd.tolist()},
            "output_scaler": {"mean": emu.y_mean.tolist(), "sd": emu.y_sd.tolist()}, "fixed_inputs": emu.fixed,
            "base": emu.base, "resolution": emu.resolution,
            "created_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), **emu.metadata}
    arrays = {}
    for i, (w, b) in enumerate(zip(emu.weights, emu.biases)):
        arrays[f"layer{i}_weight"], arrays[f"layer{i}_bias"] = np.asarray(w, float), np.asarray(b, float)
    np.savez_compressed(folder / "network.npz", **arrays)
    if validation is not None:
        np.savez_compressed(folder / "validation.npz", **{k: np.asarray(v) for k, v in validation.items()})
    (folder / METADATA_FILE).write_text(json.dumps(meta, indent=1))   # last: a folder without it is not an emulator
    return folder


def load_subject_edpvr(folder) -> EdpvrEmulator:
    """Load the subject EDPVR emulator in ``folder``.

    Raises
    ------
    EmulatorError
        Missing files, another format, or metadata that is not a subject EDPVR emulator's (naming the file).
    """
    folder = Path(folder)
    meta_path = folder / METADATA_FILE
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise EmulatorError(f"{meta_path}: cannot read a subject EDPVR emulator ({type(err).__name__}: "
                            f"{str(err)[:200]})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT or \
            not isinstance(meta.get("format_version"), int) or meta["format_version"] > FORMAT_VERSION:
        raise EmulatorError(f"{meta_path}: not an {FORMAT} file of version <= {FORMAT_VERSION}")
    try:
        if tuple(meta["input_names"]) != INPUT_NAMES or tuple(meta["output_names"]) != OUTPUT_NAMES:
            raise EmulatorError(f"{meta_path}: inputs/outputs differ from {INPUT_NAMES} -> {OUTPUT_NAMES}")
        ws, bs = read_layers(folder / "network.npz")
        vec = {k: np.asarray(v, float) for k, v in (("lower", meta["lower"]), ("upper", meta["upper"]),
                                                    ("x_mean", meta["input_scaler"]["mean"]),
                                                    ("x_sd", meta["input_scaler"]["sd"]),
                                                    ("y_mean", meta["output_scaler"]["mean"]),
                                                    ("y_sd", meta["output_scaler"]["sd"]))}
        shapes_ok = all(vec[k].shape == (len(INPUT_NAMES),) for k in ("lower", "upper", "x_mean", "x_sd")) and \
            all(vec[k].shape == (len(OUTPUT_NAMES),) for k in ("y_mean", "y_sd")) and len(ws) >= 1 and \
            ws[0].shape[1] == len(INPUT_NAMES) and ws[-1].shape[0] == len(OUTPUT_NAMES)
        v0 = float(meta["subject"]["v0_ml"])
        test = meta["test"]
        per_p = [np.asarray(test[k], float) for k in ("pressures_mmhg", "log_volume_ratio_rmse", "fibre_stretch_rmse")]
        if not shapes_ok or not (np.isfinite(v0) and v0 > 0) or len({a.shape for a in per_p}) != 1 or \
                not all(np.all(np.isfinite(a)) for a in per_p) or not np.all(vec["x_sd"] > 0) or \
                not np.all(vec["lower"][:4] > 0):
            raise ValueError("array shapes, V0, scalers or held-out errors are invalid")
        extra = {k: v for k, v in meta.items() if k in ("architecture", "training", "test", "subject", "created_at")}
        return EdpvrEmulator(str(meta["name"]), vec["lower"], vec["upper"], vec["x_mean"], vec["x_sd"],
                             vec["y_mean"], vec["y_sd"], ws, bs, {k: float(v) for k, v in meta["fixed_inputs"].items()},
                             str(meta["base"]), str(meta["resolution"]), {}, extra, log1p_pressure=True)
    except EmulatorError:
        raise
    except (OSError, KeyError, TypeError, ValueError, IndexError) as err:
        raise EmulatorError(f"subject EDPVR emulator '{folder}' is malformed ({type(err).__name__}: "
                            f"{str(err)[:200]})") from None


# --------------------------------------------------------------------------- use in the derived quantities
def find_subject_edpvr(geometry: Mapping) -> tuple[Path | None, str]:
    """The folder of the EDPVR emulator of the subject emulator whose geometry section is ``geometry``, or None and
    why not. A subject emulator's mesh is its folder's ``geometry.vtu``; its EDPVR emulator is :data:`FOLDER` next
    to it."""
    if geometry.get("kind") != "mesh" or not geometry.get("path"):
        return None, (f"a subject emulator's geometry of kind '{geometry.get('kind')}' (no mesh file in an emulator "
                      "folder to find a subject EDPVR emulator next to)")
    folder = Path(str(geometry["path"])).parent / FOLDER
    if not (folder / METADATA_FILE).is_file():
        return None, (f"a subject emulator's mesh without a subject EDPVR emulator ({folder} missing; build the "
                      "subject emulator with --edpvr)")
    return folder, ""


def conditions_covered(geometry: Mapping, *, angles: Sequence[float | None], base: str,
                       resolution: str) -> tuple[EdpvrEmulator | None, str]:
    """The subject EDPVR emulator of ``geometry`` when it exists, was trained on this very mesh (fingerprint) and
    matches the calibration's angles, base and mesh resolution; else None and why not."""
    folder, why = find_subject_edpvr(geometry)
    if folder is None:
        return None, why
    try:
        emu = load_subject_edpvr(folder)
        same = geometry_fingerprint(geometry) == emu.metadata["subject"].get("geometry_sha256")
    except EmulatorError as err:
        return None, f"the subject EDPVR emulator cannot be used ({err})"
    if not same:
        return None, f"the subject EDPVR emulator in {folder} was trained on another mesh (fingerprint differs)"
    why = emu.covers(base=base, resolution=resolution, angles=angles)
    return (emu, "") if why is None else (None, f"the subject EDPVR emulator's conditions: {why}")


def emulator_for(draws: Sequence[Mapping], *, geometry: Mapping, angles: Sequence[float | None], base: str,
                 resolution: str, edp_mmhg: float,
                 pressures_mmhg: Sequence[float]) -> tuple[EdpvrEmulator | None, str]:
    """The subject EDPVR emulator that covers a subject calibration's derived quantities (its conditions,
    :func:`conditions_covered`, and every draw's θ and every pressure in its box), or None and why not."""
    emu, why = conditions_covered(geometry, angles=angles, base=base, resolution=resolution)
    if emu is None:
        return None, why
    if not draws:
        return None, "no posterior draws"
    if any(k in d for d in draws for k in ANGLE_NAMES):
        return None, "inferred fibre angles"
    p = np.r_[np.asarray(pressures_mmhg, float), float(edp_mmhg)]
    x = np.array([[float(d[k]) for k in THETA_NAMES] + [float(q)] for d in draws for q in p])
    if not emu.in_box(x).all():
        return None, "posterior draws or pressures outside the subject EDPVR emulator's box"
    return emu, ""


def emulated_load_path(emu: EdpvrEmulator, draws: Sequence[Mapping], *, edp_mmhg: float,
                       pressures_mmhg: Sequence[float]) -> EmulatedPath:
    """The EDPVR (V₀ first, then each pressure, mL) and the volume and mean fibre stretch at the EDP of draws
    ``{"a", "b", "af", "bf"}`` on the subject's fixed mesh (V₀ the mesh's, the same for every draw)."""
    t0 = time.perf_counter()
    theta = np.array([[float(d[k]) for k in THETA_NAMES] for d in draws])
    levels = np.r_[np.asarray(pressures_mmhg, float), float(edp_mmhg)]
    X = np.concatenate([np.repeat(theta[:, None, :], levels.size, axis=1),
                        np.broadcast_to(levels[None, :, None], (len(draws), levels.size, 1))], axis=2)
    out = emu.outputs(X)
    v0 = float(emu.metadata["subject"]["v0_ml"])
    vols = v0 * np.exp(out[..., 0])
    return EmulatedPath(np.r_[0.0, levels[:-1]], np.column_stack([np.full(len(draws), v0), vols[:, :-1]]),
                        vols[:, -1], np.exp(out[:, -1, 1]), float(emu.volume_log_sd(edp_mmhg)),
                        time.perf_counter() - t0)


__all__ = ["FORMAT", "FOLDER", "INPUT_NAMES", "OUTPUT_NAMES", "EdpvrDesign", "default_edpvr_config", "edpvr_space",
           "transform_inputs", "training_rows", "geometry_fingerprint", "heldout", "train_subject_edpvr",
           "build_subject_edpvr", "save_subject_edpvr", "load_subject_edpvr", "find_subject_edpvr",
           "conditions_covered", "emulator_for", "emulated_load_path"]
