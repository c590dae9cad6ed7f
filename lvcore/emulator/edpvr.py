r"""An emulator with an EDP input for the derived EDPVR: ``(θ, h, p) -> log V(p)/V₀, log λ_f(p), 24 strains``.

The calibration emulators are trained at one EDP (``chapter``: 8 mmHg), so the derived EDPVR of a posterior
(:mod:`lvcore.inference.derived`) needs the FE simulator at every pressure, hundreds of solves per calibration. This
emulator covers 0-30 mmHg on the ``chapter`` emulator's geometry space (a, b, af, bf on the same box, PC scores
h1..h5 in [-2, 2], fibre angles -60°/60°, sliding base, ``default`` mesh) and is evaluated directly.

Representation. Per (θ, h) the curve is anchored on the ``chapter`` emulator's LVV at its EDP (8 mmHg), V₈, and
the geometry's own reference cavity V₀, computed exactly from the PC scores, no emulator (:func:`reference_volumes_ml`:
the simulator's mesh nodes are linear in h, so the endocardium saved with the emulator gives each draw's cavity by
one vectorised quadrature). With ``L₈ = log V₈/V₀`` the network predicts, at pressure ``p`` (mmHg), the shape of
the load path in units of L₈:

* ``log(V(p)/V₀) / L₈`` (1 at 8 mmHg by construction of the training data);
* ``log λ_f(p) / L₈``, λ_f the volume-weighted mean fibre stretch (:mod:`lvcore.mechanics.fibre_stretch`);
* the 24 regional circumferential strains ``/ L₈`` (for calibration at other EDPs later; not read by the EDPVR).

Normalised so, the outputs depend on the stiffness mostly through the shape of the curve, not its scale, and a
few hundred FE load paths learn them (the plain ``log V/V₀`` from 128 paths missed by 10-15 %). A uniform scale
``s`` multiplies V, V₀ and V₈ by ``s³`` and leaves the ratios, the strains and the fibre stretch as they are
(:mod:`lvcore.geometry.scaling`). The training targets use the FE V₈ of each path; the held-out errors use the
``chapter`` emulator's V₈, as the derived quantities do, so they include its error.

At ``p = 0`` every output is exactly 0; those rows are in the training set. The training data are FE load paths,
one per design row (:mod:`lvcore.campaigns.load_paths`); ``scripts/build_emulators.py --emulators edpvr`` is the
seeded build. The held-out test paths run at pressures between the training ones, and their error per pressure
(RMSE of ``log V/V₀`` and of λ_f) is stored in the metadata: :func:`volume_log_sd` turns it into the emulator's
predictive sd, which the derived quantities add to the data's volume sd.

Files (``assets/emulators/edpvr/``): ``edpvr.json`` (the metadata: format ``lvcore-edpvr-emulator``, inputs, box,
scalers, held-out errors, provenance) and ``network.npz`` (the MLP's arrays, :func:`lvcore.emulator.network.to_arrays`),
``geometry.npz`` (the mesh's endocardium, linear in the PC scores, for V₀), ``validation.npz`` (the held-out rows, predictions and FE values). There is no ``metadata.json``, so the folder is not
listed among the calibration emulators (:func:`lvcore.emulator.io.available_emulators`). Evaluation is NumPy (no
compilation): 100 draws at 8 pressures cost well under a millisecond.

A calibration through a subject emulator (a fixed mesh, no PC scores) is not in this space; a subject emulator
built with its own EDPVR emulator (:mod:`lvcore.emulator.subject_edpvr`, the same class with inputs θ and p) is
found and used by :func:`conditions_covered` and :func:`emulator_for`.
"""
from __future__ import annotations

import dataclasses
import functools
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from lvcore.domain.outputs import EDP_NAME, THETA_NAMES
from lvcore.exceptions import EmulatorError

FORMAT = "lvcore-edpvr-emulator"
FORMAT_VERSION = 1
#: The metadata file of an EDPVR emulator's folder.
METADATA_FILE = "edpvr.json"
#: The bundled EDPVR emulator.
DEFAULT_NAME = "edpvr"
#: Number of PC scores of its geometry.
N_PCS = 5
INPUT_NAMES = THETA_NAMES + tuple(f"h{k + 1}" for k in range(N_PCS)) + (EDP_NAME,)
OUTPUT_NAMES = ("log_volume_ratio", "log_fibre_stretch") + tuple(f"strain_{k:02d}" for k in range(1, 25))
#: The calibration emulator whose LVV at :data:`ANCHOR_EDP_MMHG` anchors the curve (see the module docstring).
ANCHOR_EMULATOR = "chapter"
ANCHOR_EDP_MMHG = 8.0
#: Held-out errors are reported separately for paths with EDV/V₀ at 8 mmHg up to this ratio (-).
PHYSIOLOGICAL_V8_RATIO = 2.5
#: Extra loss weight of the fibre stretch (the EDPVR's volume gets the L-BFGS stage's LVV weight).
STRETCH_WEIGHT = 8.0


@dataclass(frozen=True, eq=False)
class EdpvrEmulator:
    """A trained EDPVR emulator (see the module docstring).

    Attributes
    ----------
    name : str
    lower, upper : ndarray (10,)
        Training box of :data:`INPUT_NAMES` (kPa, -, kPa, -, PC scores, mmHg).
    x_mean, x_sd : ndarray (10,)
        Standardisation of the inputs (a, b, af, bf log-transformed first).
    y_mean, y_sd : ndarray (26,)
        Standardisation of :data:`OUTPUT_NAMES`.
    weights, biases : tuple of ndarray
        The tanh MLP's layers.
    fixed : dict
        Inputs held fixed in training: ``alpha_endo``, ``alpha_epi`` (deg).
    base, resolution : str
        The FE runs' base condition and mesh preset.
    geometry : dict
        The mesh's endocardium, linear in the PC scores (:func:`geometry_basis`), for V₀.
    metadata : dict
        Everything else (held-out errors under ``test``, provenance under ``source``; a subject EDPVR emulator's
        V₀ and mesh under ``subject``).
    log1p_pressure : bool
        The pressure enters the network as ``log(1 + p)`` (a subject EDPVR emulator,
        :mod:`lvcore.emulator.subject_edpvr`: inputs a, b, af, bf, edp; outputs ``log V/V₀``, ``log λ_f``), not as p.
    """

    name: str
    lower: np.ndarray
    upper: np.ndarray
    x_mean: np.ndarray
    x_sd: np.ndarray
    y_mean: np.ndarray
    y_sd: np.ndarray
    weights: tuple
    biases: tuple
    fixed: dict
    base: str
    resolution: str
    geometry: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    log1p_pressure: bool = False

    @property
    def is_subject(self) -> bool:
        """True for a subject EDPVR emulator (one fixed mesh, V₀ in ``metadata["subject"]``; no PC scores)."""
        return bool(self.metadata.get("subject"))

    def outputs(self, x) -> np.ndarray:
        """``(..., 10)`` inputs (physical units, :data:`INPUT_NAMES`) -> ``(..., 26)`` :data:`OUTPUT_NAMES` (a subject
        EDPVR emulator: ``(..., 5)`` -> ``(..., 2)``, :mod:`lvcore.emulator.subject_edpvr`).

        No box check (:meth:`in_box`); at ``edp = 0`` the outputs are forced to their exact value 0.
        """
        x = np.asarray(x, float)
        z = x.copy()
        z[..., :4] = np.log(z[..., :4])
        if self.log1p_pressure:
            z[..., -1] = np.log1p(z[..., -1])
        h = (z - self.x_mean) / self.x_sd
        for w, b in zip(self.weights[:-1], self.biases[:-1]):
            h = np.tanh(h @ w.T + b)
        y = (h @ self.weights[-1].T + self.biases[-1]) * self.y_sd + self.y_mean
        return np.where(x[..., -1:] <= 0.0, 0.0, y)

    def physical(self, x, log_v8_ratio) -> np.ndarray:
        """``(..., 26)``: ``log V/V₀``, ``log λ_f`` and the 24 strains at inputs ``x`` ``(..., 10)``, given each row's
        ``L₈ = log V₈/V₀`` (broadcast against ``x[..., 0]``)."""
        return self.outputs(x) * np.asarray(log_v8_ratio, float)[..., None]

    def in_box(self, x) -> np.ndarray:
        """Per row: inside the training box (with a relative slack of 1e-9)."""
        x = np.asarray(x, float)
        tol = 1e-9 * np.maximum(1.0, np.abs(self.upper - self.lower))
        return np.all((x >= self.lower - tol) & (x <= self.upper + tol), axis=-1)

    def volume_log_sd(self, pressure_mmhg) -> np.ndarray:
        """Held-out RMSE of ``log V/V₀`` (-) at ``pressure_mmhg``, interpolated between the test pressures (0 at 0
        mmHg, the largest test value beyond them): the emulator's relative volume error, as a predictive sd."""
        t = self.metadata["test"]
        p = np.r_[0.0, np.asarray(t["pressures_mmhg"], float)]
        s = np.r_[0.0, np.asarray(t["log_volume_ratio_rmse"], float)]
        return np.interp(np.asarray(pressure_mmhg, float), p, s, right=float(s.max()))

    def stretch_sd(self, pressure_mmhg) -> np.ndarray:
        """Held-out RMSE of the mean fibre stretch (-) at ``pressure_mmhg`` (as :meth:`volume_log_sd`)."""
        t = self.metadata["test"]
        p = np.r_[0.0, np.asarray(t["pressures_mmhg"], float)]
        s = np.r_[0.0, np.asarray(t["fibre_stretch_rmse"], float)]
        return np.interp(np.asarray(pressure_mmhg, float), p, s, right=float(s.max()))

    def covers(self, *, base: str, resolution: str, angles: Sequence[float | None]) -> str | None:
        """None when a calibration with these conditions is in this emulator's space, else why not."""
        if base != self.base:
            return f"base '{base}' (the emulator's: '{self.base}')"
        if resolution != self.resolution:
            return f"mesh resolution '{resolution}' (the emulator's: '{self.resolution}')"
        want = (self.fixed["alpha_endo"], self.fixed["alpha_epi"])
        if any(a is None for a in angles) or any(abs(float(a) - w) > 1e-9 for a, w in zip(angles, want)):
            return f"fibre angles {tuple(angles)} (the emulator's: {want})"
        return None


# --------------------------------------------------------------------------- V0 from the PC scores
def geometry_basis(resolution: str = "default", n_pcs: int = N_PCS) -> dict:
    """The simulator mesh's endocardium as a linear function of the PC scores (the nodes are linear in h).

    Returns
    -------
    dict
        ``nodes`` ``(m, 3)`` (mm) of the endocardial nodes at h = 0, ``basis`` ``(k, m, 3)`` (mm per unit score),
        ``faces`` ``(f, 9)`` (indices into ``nodes``), ``base_z`` (mm): saved with the emulator (``geometry.npz``).
    """
    from lvcore.domain.conditions import THETA_TILDE
    from lvcore.mechanics.case import Case
    from lvcore.mechanics.case_inputs import build_case
    from lvcore.mechanics.simulate import build_mesh

    def mesh(h):
        return build_mesh(Case.from_dict(build_case({**THETA_TILDE, **{f"h{k + 1}": float(v) for k, v in enumerate(h)}},
                                                    resolution=resolution)))

    m0 = mesh(np.zeros(n_pcs))
    faces = np.asarray(m0.surfaces["endocardium"])
    used, local = np.unique(faces, return_inverse=True)
    basis = np.stack([np.asarray(mesh(np.eye(n_pcs)[k]).nodes - m0.nodes, float)[used] for k in range(n_pcs)])
    return {"nodes": np.asarray(m0.nodes, float)[used], "basis": basis, "faces": local.reshape(faces.shape),
            "base_z": np.float64(m0.base_z)}


def reference_volumes_ml(h, geometry: Mapping) -> np.ndarray:
    """Reference cavity V₀ (mL) of the shape model's LV at PC scores ``h`` ``(N, k)``, as the simulator meshes it.

    ``geometry`` is :func:`geometry_basis` (the mesh's endocardium, linear in h); each draw's cavity is the
    quadrature of :func:`lvcore.mechanics.loads.cavity_volume` (4 × 4 Gauss points per quad), vectorised: no mesh
    is built.
    """
    return cavity_volume_function(geometry, np)(np.atleast_2d(np.asarray(h, float)))


def cavity_volume_function(geometry: Mapping, xp=np):
    """``h (..., k) -> V₀ (...)`` in mL, the quadrature of :func:`reference_volumes_ml` written once for NumPy
    (``xp=np``) and for JAX (``xp=jax.numpy``: traceable, differentiable in h)."""
    from lvcore.domain import units
    from lvcore.mechanics.quadrature import gauss_quad, quad9_shape

    faces = np.asarray(geometry["faces"])
    nodes = xp.asarray(np.asarray(geometry["nodes"], float)[faces])             # (f, 9, 3)
    basis = xp.asarray(np.asarray(geometry["basis"], float)[:, faces])          # (k, f, 9, 3)
    xi, w = gauss_quad(4)
    N, dA, dB, w = (xp.asarray(np.asarray(a, float)) for a in (*quad9_shape(xi), w))
    base_z = float(geometry["base_z"])

    def volume(h):
        X = nodes + xp.einsum("...k,kfac->...fac", h, basis)
        z = xp.einsum("qa,...fa->...fq", N, X[..., 2]) - base_z
        ta = xp.einsum("qa,...fac->...fqc", dA, X[..., :2])
        tb = xp.einsum("qa,...fac->...fqc", dB, X[..., :2])
        nz = ta[..., 0] * tb[..., 1] - ta[..., 1] * tb[..., 0]
        return -xp.einsum("...fq,q->...", z * nz, w) / units.MM3_PER_ML

    return volume


# --------------------------------------------------------------------------- training
def fe_log_v8_ratio(data) -> np.ndarray:
    """``log V₈/V₀`` of each load path from its own FE solve at :data:`ANCHOR_EDP_MMHG` (NaN where it failed)."""
    j = int(np.flatnonzero(np.isclose(data.pressures_mmhg, ANCHOR_EDP_MMHG))[0])
    return np.log(data.lvv_ml[:, j] / data.v0_ml)


def training_rows(data) -> tuple[np.ndarray, np.ndarray]:
    """Inputs ``(M, 10)`` and outputs ``(M, 26)`` (in units of each path's FE ``L₈``) of every converged (row,
    pressure) of a :class:`~lvcore.campaigns.load_paths.LoadPathData`, and a ``p = 0`` row (outputs 0) per path."""
    L8 = fe_log_v8_ratio(data)
    X, Y = [], []
    for i in range(data.inputs.shape[0]):
        if not (np.isfinite(data.v0_ml[i]) and np.isfinite(L8[i]) and L8[i] > 0):
            continue
        X.append(np.r_[data.inputs[i], 0.0])
        Y.append(np.zeros(len(OUTPUT_NAMES)))
        for j, p in enumerate(data.pressures_mmhg):
            if not np.isfinite(data.lvv_ml[i, j]):
                continue
            X.append(np.r_[data.inputs[i], p])
            Y.append(np.r_[np.log(data.lvv_ml[i, j] / data.v0_ml[i]), np.log(data.fibre_stretch[i, j]),
                           data.strains[i, j]] / L8[i])
    return np.asarray(X), np.asarray(Y)


def anchor_log_v8_ratio(theta_h, v0_ml, name: str = ANCHOR_EMULATOR) -> np.ndarray:
    """``log V₈/V₀`` with V₈ the anchor emulator's LVV (mL) at rows ``theta_h`` ``(N, 9)`` (a, b, af, bf, h1..h5;
    unscaled geometry) and V₀ ``(N,)`` (mL), evaluated in NumPy (no compilation)."""
    w, b, emu = _anchor(name)
    x = np.asarray(theta_h, float)
    mask = np.asarray(emu.log_inputs, bool)
    z = np.where(mask, np.log(np.where(mask, x, 1.0)), x)
    h = (z - emu.x_mean) / emu.x_sd
    for wk, bk in zip(w[:-1], b[:-1]):
        h = np.tanh(h @ wk.T + bk)
    y0 = (h @ w[-1][:1].T + b[-1][:1])[:, 0] * emu.y_sd[0] + emu.y_mean[0]
    lvv = np.exp(y0) if emu.log_outputs[0] else y0
    return np.log(lvv / np.asarray(v0_ml, float))


@functools.lru_cache(maxsize=2)
def _anchor_cached(name: str, identity) -> tuple:
    from lvcore.emulator.io import load_emulator
    from lvcore.emulator.network import to_arrays

    emu = load_emulator(name)
    if emu.prior is not None:
        raise EmulatorError(f"the anchor emulator '{name}' has a prior mean; an EDPVR emulator needs a plain one")
    arrays = to_arrays(emu.network)
    n = len(arrays) // 2
    return (tuple(np.asarray(arrays[f"layer{i}_weight"], float) for i in range(n)),
            tuple(np.asarray(arrays[f"layer{i}_bias"], float) for i in range(n)), emu)


def _anchor(name: str) -> tuple:
    from lvcore.emulator.io import emulator_identity, resolve_emulator_dir

    return _anchor_cached(name, emulator_identity(resolve_emulator_dir(name)))


def _heldout(emu: EdpvrEmulator, data) -> tuple[dict, dict]:
    """Held-out errors per test pressure (``test`` metadata) and the validation arrays; V₈ from the anchor emulator,
    as in use."""
    L8 = anchor_log_v8_ratio(data.inputs, data.v0_ml)
    ok = np.isfinite(data.lvv_ml) & np.isfinite(data.v0_ml)[:, None]
    P = data.pressures_mmhg.size
    X = np.concatenate([np.repeat(data.inputs[:, None, :], P, axis=1), np.broadcast_to(
        data.pressures_mmhg[None, :, None], (data.inputs.shape[0], P, 1))], axis=2)
    pred = emu.physical(X, L8[:, None])
    v_pred = data.v0_ml[:, None] * np.exp(pred[..., 0])
    err_v = np.where(ok, v_pred - data.lvv_ml, np.nan)
    err_log = np.where(ok, pred[..., 0] - np.log(data.lvv_ml / data.v0_ml[:, None]), np.nan)
    err_lam = np.where(ok, np.exp(pred[..., 1]) - data.fibre_stretch, np.nan)
    err_s = np.where(ok[..., None], pred[..., 2:] - data.strains, np.nan)

    def rmse(e, axis=0):
        return np.sqrt(np.nanmean(e ** 2, axis=axis))

    test = {"n_paths": int(data.inputs.shape[0]), "n_failed_solves": int((~ok).sum()),
            "pressures_mmhg": [float(p) for p in data.pressures_mmhg],
            "volume_rmse_ml": rmse(err_v).tolist(), "volume_p99_abs_ml": np.nanquantile(np.abs(err_v), 0.99, axis=0).tolist(),
            "volume_max_abs_ml": np.nanmax(np.abs(err_v), axis=0).tolist(),
            "log_volume_ratio_rmse": rmse(err_log).tolist(),
            "fibre_stretch_rmse": rmse(err_lam).tolist(), "fibre_stretch_max_abs": np.nanmax(np.abs(err_lam), axis=0).tolist(),
            "strain_rmse": rmse(err_s.reshape(-1, err_s.shape[-1])).tolist(),
            "strain_rmse_all": float(rmse(err_s.ravel())), "volume_rmse_ml_all": float(rmse(err_v.ravel())),
            "fibre_stretch_rmse_all": float(rmse(err_lam.ravel()))}
    # the physiological part of the box: EDV/V₀ at 8 mmHg up to PHYSIOLOGICAL_V8_RATIO (the soft corners of the
    # log-uniform box reach several times V₀, far outside any heart)
    phys = np.exp(L8) <= PHYSIOLOGICAL_V8_RATIO
    test.update({"physiological_v8_ratio_max": PHYSIOLOGICAL_V8_RATIO, "n_physiological": int(phys.sum()),
                 "volume_rmse_ml_physiological": rmse(err_v[phys]).tolist(),
                 "log_volume_ratio_rmse_physiological": rmse(err_log[phys]).tolist(),
                 "fibre_stretch_rmse_physiological": rmse(err_lam[phys]).tolist()})
    arrays = {"inputs": X, "pressures_mmhg": data.pressures_mmhg, "v0_ml": data.v0_ml, "lvv_ml": data.lvv_ml,
              "fibre_stretch": data.fibre_stretch, "strains": data.strains, "predictions": pred}
    return test, arrays


def train_edpvr_emulator(train, valid, test, *, name: str = DEFAULT_NAME, base: str, resolution: str, config,
                         workers: int = 1, log=None, source: Mapping | None = None) -> tuple[EdpvrEmulator, dict]:
    """Train on load paths (:class:`~lvcore.campaigns.load_paths.LoadPathData`): the architecture search of
    :func:`lvcore.emulator.training.search_architectures` (Adam, early stopping on ``valid``), then the L-BFGS
    refinement, with the volume ratio weighted by the config's L-BFGS LVV weight and the fibre stretch by
    :data:`STRETCH_WEIGHT`; held-out errors on ``test``. Returns the emulator and its validation arrays."""
    from lvcore.domain.conditions import CHAPTER_ANGLES
    from lvcore.emulator.network import to_arrays
    from lvcore.emulator.training import refine_lbfgs, search_architectures

    t0 = time.perf_counter()
    x, y = training_rows(train)
    xv, yv = training_rows(valid)
    tx, txv = x.copy(), xv.copy()
    tx[:, :4], txv[:, :4] = np.log(x[:, :4]), np.log(xv[:, :4])
    x_mean, x_sd = tx.mean(0), tx.std(0)
    y_mean, y_sd = y.mean(0), y.std(0)
    # a loss weight w on output k is its sd divided by sqrt(w) in the standardisation
    w_sd = y_sd.copy()
    w_sd[1] /= np.sqrt(STRETCH_WEIGHT)
    zx, zxv = (tx - x_mean) / x_sd, (txv - x_mean) / x_sd
    zy, zyv = (y - y_mean) / w_sd, (yv - y_mean) / w_sd
    if log:
        log(f"[{name}] {x.shape[0]} training rows ({train.inputs.shape[0]} paths), {xv.shape[0]} validation rows")
    fits = search_architectures(zx, zy, zxv, zyv, config, workers=workers, log=log)
    best = min(fits, key=lambda f: f.valid_mse)
    net, refinement = best.network, None
    if config.lbfgs_iterations:
        net, refinement = refine_lbfgs(net, zx, zy, zxv, zyv, config)
        if log:
            log(f"[{name}] L-BFGS: validation {refinement['valid_before']:.3e} -> {refinement['valid_after']:.3e}")
    arrays = to_arrays(net)
    n = len(arrays) // 2
    lower = np.r_[_space_bounds(source, 0, train), 0.0]
    upper = np.r_[_space_bounds(source, 1, train), 30.0]
    emu = EdpvrEmulator(name, lower, upper, x_mean, x_sd, y_mean, w_sd,
                        tuple(arrays[f"layer{i}_weight"] for i in range(n)),
                        tuple(arrays[f"layer{i}_bias"] for i in range(n)),
                        {"alpha_endo": float(CHAPTER_ANGLES[0]), "alpha_epi": float(CHAPTER_ANGLES[1])}, base,
                        resolution, geometry_basis(resolution))
    held, val = _heldout(emu, test)
    meta = {"architecture": {"hidden": list(best.hidden), "activation": "tanh"},
            "training": {"config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(config).items()},
                         "valid_mse": [{"hidden": list(f.hidden), "valid_mse": f.valid_mse, "best_epoch": f.best_epoch}
                                       for f in fits],
                         "lbfgs": None if refinement is None else {k: refinement[k] for k in
                                                                   ("iterations", "valid_before", "valid_after")},
                         "n_train_rows": int(x.shape[0]), "n_valid_rows": int(xv.shape[0]),
                         "n_failed_paths": int((~np.isfinite(train.v0_ml)).sum()),
                         "n_failed_solves": int((~np.isfinite(train.lvv_ml)).sum()),
                         "seconds": round(time.perf_counter() - t0, 1)},
            "test": held, "source": dict(source or {}),
            "anchor": {"emulator": ANCHOR_EMULATOR, "edp_mmhg": ANCHOR_EDP_MMHG}}
    return dataclasses.replace(emu, metadata=meta), val


def _space_bounds(source, k: int, data) -> np.ndarray:
    """The space's lower (k = 0) or upper (k = 1) bounds of the design's inputs (from the source record)."""
    params = {p["name"]: p for p in (source or {}).get("space", {}).get("parameters", [])}
    if not params:
        return data.inputs.min(0) if k == 0 else data.inputs.max(0)
    return np.array([params[n]["lower" if k == 0 else "upper"] for n in data.input_names], float)


def format_heldout(test: Mapping) -> str:
    """The held-out errors (``metadata["test"]``) as a markdown table, one row per test pressure."""
    lines = [f"held-out: {test['n_paths']} FE load paths, {test['n_failed_solves']} failed solves; volume RMSE "
             f"{test['volume_rmse_ml_all']:.2f} mL, fibre stretch RMSE {test['fibre_stretch_rmse_all']:.4f}, strain RMSE "
             f"{test['strain_rmse_all']:.4f} over all pressures",
             "| p (mmHg) | volume RMSE (mL) | p99 abs (mL) | max abs (mL) | log V/V0 RMSE | fibre stretch RMSE | max abs |",
             "|---|---|---|---|---|---|---|"]
    lines[1] += " volume RMSE, EDV/V0 <= 2.5 at 8 mmHg (mL) | fibre stretch RMSE there |"
    lines[2] += "---|---|"
    phys = "volume_rmse_ml_physiological" in test
    for k, p in enumerate(test["pressures_mmhg"]):
        lines.append(f"| {p:g} | {test['volume_rmse_ml'][k]:.2f} | {test['volume_p99_abs_ml'][k]:.2f} | "
                     f"{test['volume_max_abs_ml'][k]:.2f} | {test['log_volume_ratio_rmse'][k]:.4f} | "
                     f"{test['fibre_stretch_rmse'][k]:.4f} | {test['fibre_stretch_max_abs'][k]:.4f} | " +
                     (f"{test['volume_rmse_ml_physiological'][k]:.2f} | "
                      f"{test['fibre_stretch_rmse_physiological'][k]:.4f} |" if phys else "- | - |"))
    if phys:
        lines.append(f"({test['n_physiological']} of {test['n_paths']} test paths have EDV/V0 <= "
                     f"{test['physiological_v8_ratio_max']:g} at 8 mmHg)")
    return "\n".join(lines)


# --------------------------------------------------------------------------- files
def save_edpvr_emulator(emu: EdpvrEmulator, folder, validation: Mapping | None = None) -> Path:
    """Write ``edpvr.json``, ``network.npz`` and (given) ``validation.npz`` into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    meta = {"format": FORMAT, "format_version": FORMAT_VERSION, "name": emu.name, "input_names": list(INPUT_NAMES),
            "output_names": list(OUTPUT_NAMES), "log_inputs": list(THETA_NAMES), "lower": emu.lower.tolist(),
            "upper": emu.upper.tolist(), "input_scaler": {"mean": emu.x_mean.tolist(), "sd": emu.x_sd.tolist()},
            "output_scaler": {"mean": emu.y_mean.tolist(), "sd": emu.y_sd.tolist()}, "fixed_inputs": emu.fixed,
            "base": emu.base, "resolution": emu.resolution,
            "created_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), **emu.metadata}
    (folder / METADATA_FILE).write_text(json.dumps(meta, indent=1))
    arrays = {}
    for i, (w, b) in enumerate(zip(emu.weights, emu.biases)):
        arrays[f"layer{i}_weight"], arrays[f"layer{i}_bias"] = np.asarray(w, float), np.asarray(b, float)
    np.savez_compressed(folder / "network.npz", **arrays)
    np.savez_compressed(folder / "geometry.npz", **{k: np.asarray(v) for k, v in emu.geometry.items()})
    if validation is not None:
        np.savez_compressed(folder / "validation.npz", **{k: np.asarray(v) for k, v in validation.items()})
    return folder


def find_edpvr_emulator(name: str = DEFAULT_NAME) -> Path | None:
    """The folder of the EDPVR emulator ``name`` on the emulator search path (``LVCORE_EMULATORS``, then the
    bundled ones), or None."""
    from lvcore.emulator.io import emulator_search_path

    for d in emulator_search_path():
        if (d / name / METADATA_FILE).is_file():
            return d / name
    return None


def read_layers(npz_path) -> tuple[tuple, tuple]:
    """The tanh MLP's weights and biases (``layer{i}_weight``, ``layer{i}_bias``) saved in ``npz_path``."""
    with np.load(npz_path) as z:
        n = sum(1 for k in z.files if k.endswith("_weight"))
        return (tuple(np.asarray(z[f"layer{i}_weight"], float) for i in range(n)),
                tuple(np.asarray(z[f"layer{i}_bias"], float) for i in range(n)))


@functools.lru_cache(maxsize=4)
def _load(folder: str, stamp: int) -> EdpvrEmulator:
    path = Path(folder)
    try:
        meta = json.loads((path / METADATA_FILE).read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise EmulatorError(f"{path / METADATA_FILE}: cannot read an EDPVR emulator ({type(err).__name__}: "
                            f"{str(err)[:200]})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT or not isinstance(meta.get("format_version"), int) \
            or meta["format_version"] > FORMAT_VERSION:
        raise EmulatorError(f"{path / METADATA_FILE}: not an {FORMAT} file of version <= {FORMAT_VERSION}")
    try:
        return _parse(path, meta)
    except EmulatorError:
        raise
    except (OSError, KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
        raise EmulatorError(f"EDPVR emulator '{path}' is malformed ({type(err).__name__}: {str(err)[:200]})") from None


def _parse(path: Path, meta: dict) -> EdpvrEmulator:
    """The emulator from its checked metadata and arrays (any malformed part raises; :func:`_load` says which)."""
    if tuple(meta["input_names"]) != INPUT_NAMES or tuple(meta["output_names"]) != OUTPUT_NAMES:
        raise EmulatorError(f"{path / METADATA_FILE}: inputs/outputs differ from {INPUT_NAMES} -> {OUTPUT_NAMES}")
    ws, bs = read_layers(path / "network.npz")
    with np.load(path / "geometry.npz") as z:
        geometry = {k: np.asarray(z[k]) for k in z.files}
    extra = {k: v for k, v in meta.items() if k in ("architecture", "training", "test", "source", "created_at",
                                                   "anchor")}
    vec = {k: np.asarray(v, float) for k, v in (("lower", meta["lower"]), ("upper", meta["upper"]),
                                                ("x_mean", meta["input_scaler"]["mean"]),
                                                ("x_sd", meta["input_scaler"]["sd"]),
                                                ("y_mean", meta["output_scaler"]["mean"]),
                                                ("y_sd", meta["output_scaler"]["sd"]))}
    test = meta["test"]
    per_p = [np.asarray(test[k], float) for k in ("pressures_mmhg", "log_volume_ratio_rmse", "fibre_stretch_rmse")]
    ok = (all(vec[k].shape == (len(INPUT_NAMES),) for k in ("lower", "upper", "x_mean", "x_sd"))
          and all(vec[k].shape == (len(OUTPUT_NAMES),) for k in ("y_mean", "y_sd"))
          and all(np.all(np.isfinite(v)) for v in vec.values()) and np.all(vec["x_sd"] > 0)
          and np.all(vec["lower"][:len(THETA_NAMES)] > 0) and np.all(vec["lower"] < vec["upper"])
          and len(ws) >= 1 and len(ws) == len(bs) and ws[0].shape[1] == len(INPUT_NAMES)
          and ws[-1].shape[0] == len(OUTPUT_NAMES)
          and per_p[0].ndim == 1 and per_p[0].size >= 1 and len({a.shape for a in per_p}) == 1
          and all(np.all(np.isfinite(a)) for a in per_p)
          and {"faces", "nodes", "basis", "base_z"} <= set(geometry))
    if not ok:
        raise ValueError("array shapes, bounds, scalers, held-out errors or the geometry are invalid")
    fixed = {str(k): float(v) for k, v in dict(meta["fixed_inputs"]).items()}
    return EdpvrEmulator(str(meta["name"]), vec["lower"], vec["upper"], vec["x_mean"], vec["x_sd"], vec["y_mean"],
                         vec["y_sd"], ws, bs, fixed, str(meta["base"]), str(meta["resolution"]), geometry, extra)


def load_edpvr_emulator(name_or_folder: str | Path = DEFAULT_NAME) -> EdpvrEmulator:
    """Load an EDPVR emulator by name (search path) or folder (cached per process while its files are unchanged)."""
    path = Path(name_or_folder)
    folder = path if (path / METADATA_FILE).is_file() else find_edpvr_emulator(str(name_or_folder))
    if folder is None:
        raise EmulatorError(f"no EDPVR emulator '{name_or_folder}' ({METADATA_FILE}) on the emulator search path")
    stamp = max(f.stat().st_mtime_ns for f in folder.iterdir() if f.is_file())
    return _load(str(folder.resolve()), stamp)


# --------------------------------------------------------------------------- the EDPVR of posterior draws
@dataclass(frozen=True)
class EmulatedPath:
    """EDPVR of draws from an :class:`EdpvrEmulator` (volumes mL; see :func:`emulated_load_path`)."""

    pressures_mmhg: np.ndarray
    volumes_ml: np.ndarray
    volume_at_edp_ml: np.ndarray
    fibre_stretch_at_edp: np.ndarray
    volume_log_sd_at_edp: float
    seconds: float


def emulated_load_path(emu: EdpvrEmulator, draws: Sequence[Mapping], *, edp_mmhg: float,
                       pressures_mmhg: Sequence[float]) -> EmulatedPath:
    """The EDPVR (V₀ first, then each pressure) and the volume and mean fibre stretch at the EDP of draws
    ``{"a", "b", "af", "bf", "h", "scale"}`` (volumes times ``scale³``); a subject EDPVR emulator's draws need only
    θ (:func:`lvcore.emulator.subject_edpvr.emulated_load_path`)."""
    if emu.is_subject:
        from lvcore.emulator import subject_edpvr

        return subject_edpvr.emulated_load_path(emu, draws, edp_mmhg=edp_mmhg, pressures_mmhg=pressures_mmhg)
    t0 = time.perf_counter()
    theta = np.array([[float(d[k]) for k in THETA_NAMES] for d in draws])
    h = np.array([[float(v) for v in d["h"]] for d in draws])
    s3 = np.array([float(d.get("scale", 1.0)) ** 3 for d in draws])
    uniq, inv = np.unique(h, axis=0, return_inverse=True)
    v0 = reference_volumes_ml(uniq, emu.geometry)[np.ravel(inv)] * s3
    L8 = anchor_log_v8_ratio(np.c_[theta, h], v0 / s3, emu.metadata.get("anchor", {}).get("emulator", ANCHOR_EMULATOR))
    levels = np.r_[np.asarray(pressures_mmhg, float), float(edp_mmhg)]
    X = np.concatenate([np.repeat(np.c_[theta, h][:, None, :], levels.size, axis=1),
                        np.broadcast_to(levels[None, :, None], (len(draws), levels.size, 1))], axis=2)
    out = emu.physical(X, L8[:, None])
    vols = v0[:, None] * np.exp(out[..., 0])
    return EmulatedPath(np.r_[0.0, levels[:-1]], np.column_stack([v0, vols[:, :-1]]), vols[:, -1],
                        np.exp(out[:, -1, 1]), float(emu.volume_log_sd(edp_mmhg)), time.perf_counter() - t0)


#: Seed of the emulator-error draws of :func:`emulator_error_draws` (fixed: a rerun gives the same band).
EMULATOR_ERROR_SEED = 20261202


def emulator_error_draws(emu: EdpvrEmulator, path: EmulatedPath, edp_mmhg: float) -> tuple[np.ndarray, np.ndarray]:
    """The emulated EDPVR volumes and ED fibre stretch with the emulator's own held-out error drawn in.

    The emulator predicts the FE mean; the quantity is the FE value. Each draw's volume at pressure p is
    multiplied by exp(z s(p)), s(p) the held-out RMSE of log V/V₀ there (:meth:`EdpvrEmulator.volume_log_sd`;
    0 at V₀, which is exact) and z ~ N(0, 1) one number per draw, the same at every pressure: the emulator's
    error along one curve is smooth, and a new z at every pressure made single draws' curves, and the medians
    of a few draws, fall with pressure where the error is larger than a step's rise (25 to 30 mmHg). Each
    pressure's spread is s(p) either way. Its fibre stretch
    gets N(0, s_λ²) at the EDP (:meth:`EdpvrEmulator.stretch_sd`), so the quantiles are
    those of the FE quantity, not only of the emulator's mean. The volume at the EDP is left as the mean: the
    check adds its error as a variance.

    Parameters
    ----------
    emu : EdpvrEmulator
    path : EmulatedPath
        The emulated means (volumes in mL, V₀ first).
    edp_mmhg : float
        The data's EDP (mmHg), where the fibre stretch is taken.

    Returns
    -------
    volumes_ml : ndarray (N, P)
    fibre_stretch : ndarray (N,)
    """
    rng = np.random.default_rng(EMULATOR_ERROR_SEED)
    vols = np.asarray(path.volumes_ml, float)
    log_sd = np.asarray(emu.volume_log_sd(path.pressures_mmhg), float)
    vols = vols * np.exp(rng.standard_normal((vols.shape[0], 1)) * log_sd[None, :])
    lam = np.asarray(path.fibre_stretch_at_edp, float)
    lam = lam + rng.standard_normal(lam.shape) * float(emu.stretch_sd(edp_mmhg))
    return vols, lam


def conditions_covered(*, geometry: Mapping | None, angles: Sequence[float | None], base: str, resolution: str,
                       name: str | None = DEFAULT_NAME) -> tuple[EdpvrEmulator | None, str]:
    """The EDPVR emulator ``name`` when a calibration's conditions are in its space (the draws not yet known:
    :func:`emulator_for` checks them), else None and why not."""
    if name is None:
        return None, "the FE load path was asked for"
    if geometry is not None:   # a subject emulator's mesh: its own EDPVR emulator, if it was built with one
        from lvcore.emulator import subject_edpvr

        return subject_edpvr.conditions_covered(geometry, angles=angles, base=base, resolution=resolution)
    folder = find_edpvr_emulator(name)
    if folder is None:
        return None, f"no EDPVR emulator '{name}' installed"
    emu = load_edpvr_emulator(folder)
    why = emu.covers(base=base, resolution=resolution, angles=angles)
    if why is not None:
        return None, why
    anchor = emu.metadata.get("anchor", {}).get("emulator", ANCHOR_EMULATOR)
    try:
        _anchor(anchor)
    except EmulatorError as err:
        return None, f"its anchor emulator '{anchor}' is not available ({err})"
    return emu, ""


def emulator_for(draws: Sequence[Mapping], *, geometry: Mapping | None, angles: Sequence[float | None], base: str,
                 resolution: str, edp_mmhg: float, pressures_mmhg: Sequence[float],
                 name: str | None = DEFAULT_NAME) -> tuple[EdpvrEmulator | None, str]:
    """The EDPVR emulator that covers a calibration's derived quantities, or None and why the FE path is needed.

    It covers them when the geometry is the shape model's (every draw has PC scores ``h``, given or inferred, with a
    ``scale``), the fibre angles, base condition and mesh resolution are the emulator's, and every draw's θ, h and
    every pressure lie in its box. With a subject emulator's mesh (``geometry``) it is that subject emulator's own
    EDPVR emulator where one was built (:func:`lvcore.emulator.subject_edpvr.emulator_for`). ``name`` None asks for
    the FE path.
    """
    if geometry is not None and name is not None:
        from lvcore.emulator import subject_edpvr

        return subject_edpvr.emulator_for(draws, geometry=geometry, angles=angles, base=base, resolution=resolution,
                                          edp_mmhg=edp_mmhg, pressures_mmhg=pressures_mmhg)
    emu, why = conditions_covered(geometry=geometry, angles=angles, base=base, resolution=resolution, name=name)
    if emu is None:
        return None, why
    if not draws or any("h" not in d or len(d["h"]) != N_PCS for d in draws):
        return None, f"draws without {N_PCS} PC scores"
    if any(k in d for d in draws for k in ("alpha_endo", "alpha_epi")):
        return None, "inferred fibre angles"
    p = np.r_[np.asarray(pressures_mmhg, float), float(edp_mmhg)]
    x = np.array([[float(d[k]) for k in THETA_NAMES] + [float(v) for v in d["h"]] + [float(q)] for d in draws
                  for q in p])
    if not emu.in_box(x).all():
        return None, "posterior draws or pressures outside the EDPVR emulator's box"
    return emu, ""


__all__ = ["FORMAT", "METADATA_FILE", "DEFAULT_NAME", "INPUT_NAMES", "OUTPUT_NAMES", "EdpvrEmulator", "emulator_error_draws", "EMULATOR_ERROR_SEED",
           "geometry_basis", "reference_volumes_ml", "cavity_volume_function", "fe_log_v8_ratio", "training_rows",
           "anchor_log_v8_ratio", "train_edpvr_emulator", "format_heldout", "save_edpvr_emulator",
           "find_edpvr_emulator", "load_edpvr_emulator", "EmulatedPath", "emulated_load_path", "conditions_covered", "emulator_for"]
