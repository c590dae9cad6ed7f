"""Training emulators: the chapter's recipe.

* Inputs: the material parameters (a, b, af, bf) on a log scale, the others
  as they are; then standardised with the training set's mean and sd.
* Outputs: the 25 simulator outputs, standardised per output; the LVV is
  first put on a log scale (``TrainingConfig.log_lvv``, default on; not in
  the chapter, see there).
* Network: MLP with two hidden tanh layers; the widths are chosen from
  ``{50, 100, 120, 200}²`` by the validation MSE (on standardised outputs).
* Weights initialised from N(0, 0.1²).
* Adam (optax) on the mean squared error with an exponentially decaying
  learning rate starting at 0.01; minibatches reshuffled every epoch.
* Early stopping on the validation MSE: the best epoch's weights are kept
  and training stops after ``patience`` epochs without improvement.
* Optional, not in the chapter: the selected network is then refined by
  full-batch L-BFGS (``TrainingConfig.lbfgs_iterations``), again keeping the
  iterate with the best validation loss. The bundled emulators use it.

Only converged rows of a campaign are used; failed rows are counted in the
metadata, never filled in.
"""
from __future__ import annotations

import hashlib
import itertools
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

import lvcore
from lvcore.emulator.model import LOG_INPUTS, Emulator, correction_targets, prior_outputs
from lvcore.emulator.network import INIT_SD, MLP, WIDTHS, from_arrays, to_arrays
from lvcore.exceptions import EmulatorError
from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, N_OUTPUTS, strain_layer

#: The chapter's architecture grid: every pair of widths.
ARCHITECTURES = tuple(itertools.product(WIDTHS, WIDTHS))


@dataclass(frozen=True)
class TrainingConfig:
    """Optimiser and search settings.

    Parameters
    ----------
    architectures : tuple of (int, int)
        Hidden widths to try; the best by validation MSE is kept.
    learning_rate : float
        Initial Adam learning rate (0.01 in the chapter).
    decay_rate, decay_epochs : float, int
        The learning rate is multiplied by ``decay_rate`` every
        ``decay_epochs`` epochs (smoothly), down to ``learning_rate * 1e-3``.
    max_epochs, patience : int
        Epoch budget and early-stopping patience (epochs).
    batch_size : int
        Minibatch size (capped at the training-set size).
    init_sd : float
        Standard deviation of the N(0, init_sd²) weight initialisation.
    seed : int
        Seed of initialisation and shuffling.
    log_lvv : bool
        Fit the LVV on a log scale (then standardised). Not in the chapter:
        over the prior box the LVV spans ~100 to ~1000 mL, and the log makes
        it far easier to fit; strains are always fitted as they are.
    lbfgs_iterations : int
        After the Adam search, the selected network is refined by full-batch
        L-BFGS (optax, zoom line search) for up to this many iterations,
        keeping the iterate with the lowest validation loss (checked every
        ``lbfgs_check_every`` iterations). 0 (the default) is the chapter's
        recipe alone. Not in the chapter: on the first 1,237 rows of the
        ``chapter`` campaign it cut the validation strain RMSE from 0.0030
        to 0.0017 and the LVV RMSE from 8.0 to 5.5 mL (100 x 100 network).
    lbfgs_check_every : int
        Validation check interval of the L-BFGS stage (iterations).
    lvv_weight : float
        Weight of the (standardised) LVV in the mean squared error, the 24
        strains having weight 1 each; used for training, early stopping and
        the architecture choice. 1 is the chapter's plain MSE, in which the
        volume is 1/25 of the loss although calibration leans on it as much
        as on all the strains together; ``N_OUTPUTS - 1`` gives the volume
        the weight of the 24 strains.
    lbfgs_lvv_weight : float or None
        LVV weight of the L-BFGS stage (loss and best-iterate choice); None
        uses ``lvv_weight``. Not in the chapter: the search keeps the plain
        MSE, the refinement then concentrates on the volume, which the
        calibration weighs as much as all 24 strains. On the ``chapter``
        campaign, 2,000 L-BFGS iterations from the plain-MSE network gave a
        test LVV RMSE of 1.35 mL with weight 1, 0.91 mL with weight 10 and
        0.88 mL with weight 25, the strain RMSE staying at 0.0006-0.0008;
        the bundled build uses 24 (the volume weighs as much as the strains).
    """

    architectures: tuple[tuple[int, int], ...] = ARCHITECTURES
    learning_rate: float = 0.01
    decay_rate: float = 0.5
    decay_epochs: int = 150
    max_epochs: int = 2000
    patience: int = 150
    batch_size: int = 256
    init_sd: float = INIT_SD
    seed: int = 0
    log_lvv: bool = True
    lvv_weight: float = 1.0
    lbfgs_iterations: int = 0
    lbfgs_check_every: int = 50
    lbfgs_lvv_weight: float | None = None


@dataclass(frozen=True)
class FitResult:
    """One architecture's training run."""

    hidden: tuple[int, int]
    network: MLP = field(repr=False)
    valid_mse: float
    best_epoch: int
    epochs: int
    seconds: float
    history: tuple[tuple[int, float, float], ...] = field(repr=False, default=())  # (epoch, train, valid)


def training_set_hash(x: np.ndarray, y: np.ndarray, names: Sequence[str]) -> str:
    """SHA-256 of the training inputs, outputs and input names (float64, C order)."""
    h = hashlib.sha256()
    h.update(",".join(names).encode())
    h.update(np.ascontiguousarray(x, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(y, dtype="<f8").tobytes())
    return h.hexdigest()


def metrics(y_true: np.ndarray, y_pred: np.ndarray, y_sd: np.ndarray | None = None) -> dict:
    """Accuracy in physical units, per output and pooled.

    Returns a dict with ``n``; per output (lists of 25): ``rmse``, ``mae``,
    ``p99_abs`` (99th percentile of the absolute error: the worst 1 %),
    ``max_abs``; pooled: ``lvv_rmse_ml``, ``lvv_p99_abs_ml``,
    ``strain_rmse``, ``strain_p99_abs``; and ``mse_standardised`` (mean over
    outputs of the MSE divided by ``y_sd²``) when ``y_sd`` is given.
    """
    y_true, y_pred = np.asarray(y_true, float), np.asarray(y_pred, float)
    err = y_pred - y_true
    abs_err = np.abs(err)
    out = {
        "n": int(y_true.shape[0]),
        "rmse": np.sqrt(np.mean(err**2, axis=0)).tolist(),
        "mae": np.mean(abs_err, axis=0).tolist(),
        "p99_abs": np.percentile(abs_err, 99, axis=0).tolist(),
        "max_abs": np.max(abs_err, axis=0).tolist(),
        "lvv_rmse_ml": float(np.sqrt(np.mean(err[:, 0] ** 2))),
        "lvv_p99_abs_ml": float(np.percentile(abs_err[:, 0], 99)),
        "strain_rmse": float(np.sqrt(np.mean(err[:, 1:] ** 2))),
        "strain_p99_abs": float(np.percentile(abs_err[:, 1:], 99)),
    }
    if y_sd is not None:
        out["mse_standardised"] = float(np.mean((err / np.asarray(y_sd)) ** 2))
    return out


def transform_inputs(x: np.ndarray, log_inputs: Sequence[bool]) -> np.ndarray:
    x = np.asarray(x, dtype=float).copy()
    mask = np.asarray(log_inputs, dtype=bool)
    if np.any(x[:, mask] <= 0):
        raise EmulatorError("log-scaled inputs (a, b, af, bf) must be positive")
    x[:, mask] = np.log(x[:, mask])
    return x


def _transform_outputs(y: np.ndarray, log_outputs) -> np.ndarray:
    y = np.asarray(y, dtype=float).copy()
    mask = np.asarray(log_outputs, dtype=bool)
    y[:, mask] = np.log(y[:, mask])
    return y


def output_weights(config: TrainingConfig, n_outputs: int = N_OUTPUTS, stage: str = "adam") -> np.ndarray:
    """Per-output loss weights, normalised to mean 1 (LVV first).

    ``stage="adam"`` uses ``TrainingConfig.lvv_weight``; ``stage="lbfgs"`` uses
    ``lbfgs_lvv_weight`` (falling back to ``lvv_weight``).
    """
    lvv = config.lvv_weight
    if stage == "lbfgs" and config.lbfgs_lvv_weight is not None:
        lvv = config.lbfgs_lvv_weight
    w = np.ones(n_outputs)
    w[0] = float(lvv)
    if not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise EmulatorError(f"the LVV loss weight must be a positive number, got {lvv}")
    return w / w.mean()


def weighted_mse(network, x, y, weights) -> jnp.ndarray:
    """Mean over rows and outputs of ``weights * (network(x) - y)²`` (standardised units)."""
    return jnp.mean(weights * (network(x) - y) ** 2)


def fit_network(zx: np.ndarray, zy: np.ndarray, zx_valid: np.ndarray, zy_valid: np.ndarray,
                hidden: tuple[int, int], config: TrainingConfig, key: int) -> FitResult:
    """Train one architecture on standardised data with early stopping."""
    t0 = time.perf_counter()
    n, d = zx.shape
    bs = int(min(config.batch_size, n))
    n_batches = max(1, n // bs)
    init_seed, shuffle_seed = np.random.default_rng(key).integers(0, 2**31, size=2)
    model = MLP(d, zy.shape[1], tuple(hidden), seed=int(init_seed), init_sd=config.init_sd)
    rng = np.random.default_rng(shuffle_seed)
    schedule = optax.exponential_decay(
        init_value=config.learning_rate,
        transition_steps=config.decay_epochs * n_batches,
        decay_rate=config.decay_rate,
        end_value=config.learning_rate * 1e-3,
    )
    opt = optax.adam(schedule)
    opt_state = opt.init(model)
    zx_j, zy_j = jnp.asarray(zx), jnp.asarray(zy)
    zxv, zyv = jnp.asarray(zx_valid), jnp.asarray(zy_valid)

    weights = jnp.asarray(output_weights(config, zy.shape[1]))

    def loss_fn(m, xb, yb):
        return weighted_mse(m, xb, yb, weights)

    @eqx.filter_jit
    def epoch(m, state, perm):
        def step(carry, idx):
            m, state = carry
            loss, grads = eqx.filter_value_and_grad(loss_fn)(m, zx_j[idx], zy_j[idx])
            updates, state = opt.update(grads, state, m)
            return (eqx.apply_updates(m, updates), state), loss

        (m, state), losses = jax.lax.scan(step, (m, state), perm)
        return m, state, jnp.mean(losses), loss_fn(m, zxv, zyv)

    best, best_mse, best_epoch, history = model, np.inf, 0, []
    for ep in range(1, config.max_epochs + 1):
        perm = rng.permutation(n)[: n_batches * bs].reshape(n_batches, bs)
        model, opt_state, train_loss, valid_mse = epoch(model, opt_state, perm)
        valid_mse = float(valid_mse)
        if ep % 10 == 0 or ep == 1:
            history.append((ep, float(train_loss), valid_mse))
        if not np.isfinite(valid_mse):
            break
        if valid_mse < best_mse:
            best, best_mse, best_epoch = model, valid_mse, ep
        elif ep - best_epoch >= config.patience:
            break
    return FitResult(tuple(hidden), best, float(best_mse), best_epoch, ep, time.perf_counter() - t0, tuple(history))


def refine_lbfgs(network: MLP, zx: np.ndarray, zy: np.ndarray, zx_valid: np.ndarray, zy_valid: np.ndarray,
                 config: TrainingConfig) -> tuple[MLP, dict]:
    """Full-batch L-BFGS refinement of a trained network (see ``TrainingConfig.lbfgs_iterations``).

    Returns
    -------
    network : MLP
        The iterate with the lowest validation loss, weighted as the L-BFGS
        loss (the input network if none improves on it).
    report : dict
        ``iterations`` run, ``valid_before`` / ``valid_after`` (weighted MSE
        on standardised outputs), ``seconds`` and ``history`` ((iteration,
        train, valid) triples).
    """
    t0 = time.perf_counter()
    weights = jnp.asarray(output_weights(config, zy.shape[1], stage="lbfgs"))
    params, static = eqx.partition(network, eqx.is_array)
    x, y, xv, yv = (jnp.asarray(a) for a in (zx, zy, zx_valid, zy_valid))

    def loss(p, xb, yb):
        return weighted_mse(eqx.combine(p, static), xb, yb, weights)

    def train_loss(p):
        return loss(p, x, y)

    opt = optax.lbfgs()
    value_and_grad = optax.value_and_grad_from_state(train_loss)

    @jax.jit
    def block(p, state):
        def one(carry, _):
            p, state = carry
            value, grad = value_and_grad(p, state=state)
            updates, state = opt.update(grad, state, p, value=value, grad=grad, value_fn=train_loss)
            return (optax.apply_updates(p, updates), state), value

        (p, state), values = jax.lax.scan(one, (p, state), None, length=int(config.lbfgs_check_every))
        return p, state, values[-1], loss(p, xv, yv)

    state = opt.init(params)
    best_params, best_valid = params, float(loss(params, xv, yv))
    before, history, it = best_valid, [], 0
    while it < int(config.lbfgs_iterations):
        params, state, train_value, valid_value = block(params, state)
        it += int(config.lbfgs_check_every)
        train_value, valid_value = float(train_value), float(valid_value)
        history.append((it, train_value, valid_value))
        if not (np.isfinite(train_value) and np.isfinite(valid_value)):
            break
        if valid_value < best_valid:
            best_params, best_valid = params, valid_value
    report = {"iterations": it, "valid_before": before, "valid_after": best_valid,
              "seconds": round(time.perf_counter() - t0, 2), "history": history}
    return eqx.combine(best_params, static), report


def _fit_in_worker(zx, zy, zxv, zyv, hidden, config, key) -> dict:
    """:func:`fit_network` in a worker process; the network comes back as plain arrays."""
    fit = fit_network(zx, zy, zxv, zyv, hidden, config, key)
    return {"hidden": fit.hidden, "arrays": to_arrays(fit.network), "valid_mse": fit.valid_mse,
            "best_epoch": fit.best_epoch, "epochs": fit.epochs, "seconds": fit.seconds, "history": fit.history}


def search_architectures(zx: np.ndarray, zy: np.ndarray, zx_valid: np.ndarray, zy_valid: np.ndarray,
                         config: TrainingConfig, workers: int = 1, log: callable = None) -> list[FitResult]:
    """Train every architecture of ``config.architectures`` (the chapter's grid).

    Each architecture gets its own seed drawn from ``config.seed``, so the
    fits, and therefore the selected network, are the same whether they run
    in this process (``workers=1``) or in ``workers`` spawned processes
    (:class:`lvcore.execution.parallel.LocalExecutor`, one thread each).

    Returns
    -------
    list of FitResult
        In the order of ``config.architectures``.
    """
    seeds = np.random.default_rng(config.seed).integers(0, 2**31, size=len(config.architectures))
    jobs = [(tuple(int(w) for w in hidden), int(sub)) for hidden, sub in zip(config.architectures, seeds)]

    def report(fit: FitResult) -> None:
        if log:
            log(f"  hidden {fit.hidden}: validation MSE {fit.valid_mse:.3e} (standardised) at epoch "
                f"{fit.best_epoch}/{fit.epochs}, {fit.seconds:.1f} s")

    if int(workers) <= 1 or len(jobs) == 1:
        fits = []
        for hidden, key in jobs:
            fits.append(fit_network(zx, zy, zx_valid, zy_valid, hidden, config, key))
            report(fits[-1])
        return fits

    from lvcore.execution.parallel import LocalExecutor

    fits: dict[int, FitResult] = {}
    with LocalExecutor(min(int(workers), len(jobs))) as pool:
        futures = {pool.submit(_fit_in_worker, zx, zy, zx_valid, zy_valid, hidden, config, key): i
                   for i, (hidden, key) in enumerate(jobs)}
        for fut in pool.as_completed(futures):
            r = fut.result()
            fit = FitResult(tuple(r["hidden"]), from_arrays(r["arrays"]), float(r["valid_mse"]), int(r["best_epoch"]),
                            int(r["epochs"]), float(r["seconds"]), tuple(r["history"]))
            fits[futures[fut]] = fit
            report(fit)
    return [fits[i] for i in range(len(jobs))]


def train_emulator(
    x_train: np.ndarray,
    y_train: np.ndarray,
    x_valid: np.ndarray,
    y_valid: np.ndarray,
    *,
    input_names: Sequence[str],
    name: str,
    lower: Sequence[float] | None = None,
    upper: Sequence[float] | None = None,
    fixed: dict | None = None,
    config: TrainingConfig = TrainingConfig(),
    x_test: np.ndarray | None = None,
    y_test: np.ndarray | None = None,
    source: dict | None = None,
    log: callable = None,
    workers: int = 1,
    prior=None,
) -> Emulator:
    """Train an emulator and pick its architecture by validation MSE.

    Parameters
    ----------
    x_train, y_train : np.ndarray
        ``(n, d)`` inputs (physical units, columns ``input_names``) and
        ``(n, 25)`` outputs [LVV mL, 24 strains].
    x_valid, y_valid : np.ndarray
        Validation set: early stopping and architecture selection.
    input_names : sequence of str
        Column names; ``a, b, af, bf`` are log-transformed.
    name : str
        Emulator name.
    lower, upper : sequence of float, optional
        Training box; default the design space's bounds should be passed,
        otherwise the training data's min/max are used.
    fixed : dict, optional
        Inputs held fixed in the training set (recorded, checked by predict).
    config : TrainingConfig
    x_test, y_test : np.ndarray, optional
        A held-out test set never used in training or selection; its
        metrics are stored under ``metadata["test"]``.
    source : dict, optional
        Provenance recorded under ``metadata["source"]``.
    log : callable, optional
        Called with progress lines (e.g. ``print``).
    workers : int
        Processes for the architecture search (see
        :func:`search_architectures`); the result does not depend on it.
    prior : lvcore.emulator.model.PriorMean, optional
        A baseline the network learns to correct: it is trained on the LVV
        ratio and the strain differences to the prior's outputs
        (:func:`~lvcore.emulator.model.correction_targets`); the emulator
        returned adds them back, and its metrics are of the full outputs.

    Returns
    -------
    Emulator
        With ``metadata`` holding ``training``, ``validation`` (and ``test``).
    """
    names = tuple(input_names)
    x_train, y_train = np.asarray(x_train, float), np.asarray(y_train, float)
    x_valid, y_valid = np.asarray(x_valid, float), np.asarray(y_valid, float)
    _check_sets(len(names), {"training": (x_train, y_train), "validation": (x_valid, y_valid)})
    targets, targets_valid = y_train, y_valid
    if prior is not None:
        targets = correction_targets(y_train, prior_outputs(prior, names, x_train))
        targets_valid = correction_targets(y_valid, prior_outputs(prior, names, x_valid))
    z = _standardise(names, x_train, targets, x_valid, targets_valid, config)
    fits = search_architectures(z.zx, z.zy, z.zx_valid, z.zy_valid, config, workers=workers, log=log)
    best = min(fits, key=lambda f: f.valid_mse)
    network, refinement = best.network, None
    if config.lbfgs_iterations > 0:
        network, refinement = refine_lbfgs(best.network, z.zx, z.zy, z.zx_valid, z.zy_valid, config)
        if log:
            log(f"  L-BFGS refinement of {best.hidden}: validation MSE {refinement['valid_before']:.3e} -> "
                f"{refinement['valid_after']:.3e} in {refinement['iterations']} iterations, {refinement['seconds']:.1f} s")

    lower = np.asarray(lower if lower is not None else np.minimum(x_train.min(0), x_valid.min(0)), float)
    upper = np.asarray(upper if upper is not None else np.maximum(x_train.max(0), x_valid.max(0)), float)
    meta = _training_metadata(fits, best, refinement, config, training_set_hash(x_train, y_train, names),
                              n_train=int(x_train.shape[0]), n_valid=int(x_valid.shape[0]), source=source)
    emu = Emulator(name=name, input_names=names, lower=lower, upper=upper, log_inputs=z.log_inputs,
                   x_mean=z.x_mean, x_sd=z.x_sd, y_mean=z.y_mean, y_sd=z.y_sd, network=network,
                   fixed=dict(fixed or {}), metadata=meta, log_outputs=z.log_outputs, prior=prior)
    y_sd_phys = y_valid.std(axis=0)  # physical-unit scale for the standardised MSE in the report
    meta["validation"] = metrics(y_valid, np.asarray(emu.apply(x_valid)), y_sd_phys)
    if x_test is not None and y_test is not None and len(x_test):
        meta["test"] = metrics(y_test, np.asarray(emu.apply(np.asarray(x_test, float))), y_sd_phys)
    return emu


def _check_sets(d: int, sets: dict) -> None:
    """Refuse a ``{label: (inputs, outputs)}`` set of the wrong shape, with NaN/inf, or of fewer than 2 rows."""
    for label, (x, y) in sets.items():
        if x.ndim != 2 or x.shape[1] != d or y.shape != (x.shape[0], N_OUTPUTS):
            raise EmulatorError(f"{label} set must be inputs (n, {d}) and outputs (n, {N_OUTPUTS}); got {x.shape}, {y.shape}")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise EmulatorError(f"{label} set contains NaN/inf (use only converged rows)")
        if x.shape[0] < 2:
            raise EmulatorError(f"{label} set needs at least 2 rows, got {x.shape[0]}")


@dataclass(frozen=True)
class _Standardised:
    """The training and validation sets transformed (log inputs/LVV) and standardised, with the scaling used."""

    log_inputs: tuple[bool, ...]
    log_outputs: tuple[bool, ...]
    x_mean: np.ndarray
    x_sd: np.ndarray
    y_mean: np.ndarray
    y_sd: np.ndarray
    zx: np.ndarray
    zy: np.ndarray
    zx_valid: np.ndarray
    zy_valid: np.ndarray


def _standardise(names: tuple[str, ...], x_train: np.ndarray, y_train: np.ndarray, x_valid: np.ndarray,
                 y_valid: np.ndarray, config: TrainingConfig) -> _Standardised:
    """Transform and standardise the network's inputs and targets by the training set's mean and SD.

    Raises
    ------
    EmulatorError
        An input constant over the training set; ``log_lvv`` with a non-positive volume target.
    """
    log_inputs = tuple(n in LOG_INPUTS for n in names)
    tx = transform_inputs(x_train, log_inputs)
    x_mean, x_sd = tx.mean(axis=0), tx.std(axis=0)
    if np.any(x_sd == 0):
        raise EmulatorError(f"input(s) {[n for n, s in zip(names, x_sd) if s == 0]} are constant in the training set; pass them as fixed")
    log_outputs = (bool(config.log_lvv),) + (False,) * (N_OUTPUTS - 1)
    if config.log_lvv and (np.any(y_train[:, 0] <= 0) or np.any(y_valid[:, 0] <= 0)):
        raise EmulatorError("log_lvv needs positive volumes")
    ty, tyv = _transform_outputs(y_train, log_outputs), _transform_outputs(y_valid, log_outputs)
    y_mean, y_sd = ty.mean(axis=0), ty.std(axis=0)
    y_sd = np.where(y_sd > 0, y_sd, 1.0)
    return _Standardised(log_inputs, log_outputs, x_mean, x_sd, y_mean, y_sd, (tx - x_mean) / x_sd,
                         (ty - y_mean) / y_sd, (transform_inputs(x_valid, log_inputs) - x_mean) / x_sd,
                         (tyv - y_mean) / y_sd)


def _training_metadata(fits, best: FitResult, refinement, config: TrainingConfig, set_hash: str, *, n_train: int,
                       n_valid: int, source) -> dict:
    """The emulator's ``metadata`` before validation: architecture, training record, provenance."""
    return {
        "architecture": {"hidden": list(best.hidden), "activation": "tanh", "init_sd": config.init_sd},
        "training": {
            "set_hash": set_hash,
            "n_train": n_train,
            "n_valid": n_valid,
            "config": {**asdict(config), "architectures": [list(a) for a in config.architectures]},
            "best_epoch": best.best_epoch,
            "epochs_run": best.epochs,
            "search": [{"hidden": list(f.hidden), "valid_mse": f.valid_mse, "best_epoch": f.best_epoch,
                        "epochs": f.epochs, "seconds": round(f.seconds, 2)} for f in fits],
            "history": [list(h) for h in best.history],
            "lbfgs": None if refinement is None else {**refinement, "history": [list(h) for h in refinement["history"]]},
        },
        "source": dict(source or {}),
        # the wall layer of the training strains (the stores' layer, which load_store_data puts in the source)
        "strain_layer": strain_layer((source or {}).get("strain_layer", DEFAULT_STRAIN_LAYER), "source.strain_layer"),
        "lvcore_version": lvcore.__version__,
    }


# ----- from campaign stores ---------------------------------------------------

@dataclass(frozen=True)
class StoreData:
    """Converged rows of one or more campaign stores, restricted to chosen inputs."""

    inputs: np.ndarray
    outputs: np.ndarray
    input_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    fixed: dict
    n_failed: int
    n_pending: int
    info: dict
    n_inconsistent: int = 0
    problems: tuple = ()


def load_store_data(stores: Sequence[str | Path], inputs: Sequence[str] | None = None) -> StoreData:
    """Read the converged rows of campaign stores (same space) for training.

    Rows that fail the store check (:meth:`~lvcore.campaigns.store.StoreContents.check`:
    a tampered state, record count, NaN outputs or inputs outside the space)
    are excluded and counted in ``n_inconsistent``.

    Parameters
    ----------
    stores : sequence of path
        HDF5 stores from ``lvcore campaign run``.
    inputs : sequence of str, optional
        Which varied inputs the emulator takes (default: all of the space's).
        A varied input left out must then be constant in the data.
    """
    from lvcore.campaigns.store import read_store

    contents = [read_store(p) for p in stores]
    if not contents:
        raise EmulatorError("no campaign stores given")
    space = contents[0].space
    for p, c in zip(stores, contents):
        if c.space != space:
            raise EmulatorError(f"store '{p}' uses space '{c.space.name}' with different inputs/bounds than '{stores[0]}'")
    names = tuple(inputs) if inputs else space.names
    unknown = [n for n in names if n not in space.names]
    if unknown:
        raise EmulatorError(f"input(s) {unknown} are not varied in space '{space.name}' (varied: {list(space.names)})")
    cols = [space.names.index(n) for n in names]
    x = np.concatenate([c.inputs[c.converged][:, cols] for c in contents])
    y = np.concatenate([c.outputs[c.converged] for c in contents])
    fixed = space.fixed_dict()
    dropped = [n for n in space.names if n not in names]
    for n in dropped:
        vals = np.concatenate([c.inputs[c.converged][:, space.names.index(n)] for c in contents])
        if not np.allclose(vals, vals[0]):
            raise EmulatorError(f"input '{n}' varies in the data but is not an emulator input; add it to --inputs")
        fixed[n] = float(vals[0])
    layers = {c.strain_layer for c in contents}
    if len(layers) > 1:
        raise EmulatorError(f"the stores hold strains of different wall layers ({', '.join(sorted(layers))}); train "
                            "an emulator on stores of one layer")
    versions = sorted({v for c in contents for v, ok in zip(c.versions, c.converged) if ok})
    return StoreData(
        inputs=x, outputs=y, input_names=names,
        lower=space.lower[cols], upper=space.upper[cols], fixed=fixed,
        n_failed=int(sum(c.failed.sum() for c in contents)),
        n_pending=int(sum(c.pending.sum() for c in contents)),
        # the store check (lvcore campaign status --check): inconsistent rows are never training data
        n_inconsistent=int(sum(c.inconsistent.sum() for c in contents)),
        problems=tuple(f"{p}: {msg}" for p, c in zip(stores, contents) for msg in c.check(limit=10)),
        info={"stores": [str(p) for p in stores], "space": space.to_dict(),
              "resolution": sorted({str(c.attrs.get("resolution")) for c in contents}),
              "forward": sorted({str(c.attrs.get("forward")) for c in contents}),
              "simulator_versions": versions, "strain_layer": layers.pop()},
    )
