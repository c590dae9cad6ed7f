"""The emulator's network: an MLP with two hidden tanh layers (equinox).

``y = W3 tanh(W2 tanh(W1 x + b1) + b2) + b3`` acting on *standardised*
inputs and outputs (see :mod:`lvcore.emulator.training`). Weights and biases
are initialised from N(0, ``init_sd``²), with ``init_sd = 0.1`` as in the
chapter.

The network is stored as plain arrays (see :func:`to_arrays` /
:func:`from_arrays`), never pickled.
"""
from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from lvcore.exceptions import EmulatorError

#: The chapter's candidate hidden-layer widths.
WIDTHS = (50, 100, 120, 200)
INIT_SD = 0.1


class MLP(eqx.Module):
    """Two-hidden-layer tanh MLP.

    Parameters
    ----------
    in_size, out_size : int
        Input and output dimensions.
    hidden : tuple of int
        Widths of the hidden layers, e.g. ``(100, 200)``.
    seed : int
        Seed of the N(0, init_sd²) initialisation (numpy Generator; eager
        JAX random ops would compile one kernel per shape).
    init_sd : float
        Standard deviation of the initial weights and biases.
    """

    weights: tuple[jnp.ndarray, ...]
    biases: tuple[jnp.ndarray, ...]

    def __init__(self, in_size: int, out_size: int, hidden: tuple[int, ...], *, seed: int = 0, init_sd: float = INIT_SD):
        sizes = (int(in_size),) + tuple(int(h) for h in hidden) + (int(out_size),)
        rng = np.random.default_rng(seed)
        self.weights = tuple(jnp.asarray(init_sd * rng.standard_normal((n_out, n_in))) for n_in, n_out in zip(sizes[:-1], sizes[1:]))
        self.biases = tuple(jnp.asarray(init_sd * rng.standard_normal(n_out)) for n_out in sizes[1:])

    @property
    def hidden(self) -> tuple[int, ...]:
        return tuple(int(w.shape[0]) for w in self.weights[:-1])

    @property
    def in_size(self) -> int:
        return int(self.weights[0].shape[1])

    @property
    def out_size(self) -> int:
        return int(self.weights[-1].shape[0])

    def __call__(self, x: jnp.ndarray) -> jnp.ndarray:
        """Apply to ``x`` of shape ``(..., in_size)``; returns ``(..., out_size)``."""
        h = x
        for w, b in zip(self.weights[:-1], self.biases[:-1]):
            h = jnp.tanh(h @ w.T + b)
        return h @ self.weights[-1].T + self.biases[-1]


def to_arrays(model: MLP) -> dict[str, np.ndarray]:
    """Weights and biases as named numpy arrays (``layer{i}_weight``, ``layer{i}_bias``)."""
    out = {}
    for i, (w, b) in enumerate(zip(model.weights, model.biases)):
        out[f"layer{i}_weight"] = np.asarray(w)
        out[f"layer{i}_bias"] = np.asarray(b)
    return out


def from_arrays(arrays) -> MLP:
    """Rebuild an :class:`MLP` from :func:`to_arrays` output.

    Raises
    ------
    EmulatorError
        If layers are missing or their shapes do not chain.
    """
    n_layers = sum(1 for k in arrays if str(k).startswith("layer") and str(k).endswith("_weight"))
    if n_layers < 2:
        raise EmulatorError(f"network arrays hold {n_layers} layer(s); expected 3 (two hidden layers and the output)")
    try:
        ws = [np.asarray(arrays[f"layer{i}_weight"], dtype=float) for i in range(n_layers)]
        bs = [np.asarray(arrays[f"layer{i}_bias"], dtype=float) for i in range(n_layers)]
    except KeyError as err:
        raise EmulatorError(f"network arrays lack {err}") from err
    for i in range(n_layers):
        if ws[i].ndim != 2 or bs[i].shape != (ws[i].shape[0],) or (i and ws[i].shape[1] != ws[i - 1].shape[0]):
            raise EmulatorError(f"network layer {i} has inconsistent shapes {ws[i].shape}, {bs[i].shape}")
    model = MLP(ws[0].shape[1], ws[-1].shape[0], tuple(w.shape[0] for w in ws[:-1]), init_sd=0.0)
    return eqx.tree_at(lambda m: (m.weights, m.biases), model,
                       (tuple(jnp.asarray(w) for w in ws), tuple(jnp.asarray(b) for b in bs)))
