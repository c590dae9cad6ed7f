"""The forward-model interface: named physical inputs -> the 25 outputs.

A *forward model* is anything that satisfies the :class:`Forward` protocol.
It maps named physical inputs (``a, af`` in kPa, ``b, bf`` dimensionless,
``alpha_endo, alpha_epi`` in degrees, ``edp`` in mmHg, PC scores ``h1..hk``)
to the 25 outputs ``[LVV (mL), 24 circumferential strains]`` in the order of
:mod:`lvcore.domain.outputs`. Inputs that are not varied (a geometry, fixed angles,
the EDP) are bound into the forward model when it is built, so its users
(campaigns, optimisers, samplers, studies, the app) see only the inputs in
:attr:`Forward.input_names`.

What a model can do is its type (small protocols, after emukit's
``core/interfaces/models.py``), never a flag checked at run time:

:class:`Forward` (outputs)
    ``forward.evaluate(inputs) -> ForwardBatch``, batched and numeric:
    ``inputs`` maps every name of ``input_names`` to an array of shape
    ``(n,)`` (scalars broadcast). Failures are data: a point that does not
    converge is a NaN row with ``converged`` False and a message; ``evaluate``
    raises only for malformed inputs. ``forward(params) -> (25,)`` is one
    point, raising for a failure.
:class:`JacobianForward` (with Jacobian)
    adds ``forward.jacobian(inputs) -> ForwardBatch`` whose ``jacobian`` is
    ``d outputs / d inputs`` of shape ``(n, 25, len(input_names))``.
:class:`TraceableForward` (batched in JAX)
    ``forward(params)`` is a pure JAX function that ``jax.grad``, ``jax.vmap``
    and numpyro can trace, and ``forward.apply(x)`` is the same function on
    arrays of points ``(..., p) -> (..., 25)``.

This module holds the interface only. Implementations live next to what they
wrap: :class:`lvcore.mechanics.forward.SimulatorForward` and
:class:`~lvcore.mechanics.forward.AdjointSimulatorForward` (the FE simulator;
the latter with the adjoint Jacobian), :class:`lvcore.emulator.forward.EmulatorForward`
(a trained emulator with conditions bound in) and
:class:`lvcore.testing.analytic.AnalyticForward` (a SYNTHETIC closed-form
stand-in for tests and benchmarks only). :class:`JaxForward` is the shared
base of the JAX ones.
"""
from __future__ import annotations

import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Protocol, runtime_checkable

import jax
import jax.numpy as jnp
import numpy as np

from lvcore.exceptions import ForwardError, SolverError
from lvcore.domain.outputs import N_OUTPUTS


# --------------------------------------------------------------------------- the interface
@dataclass(frozen=True, eq=False)
class ForwardBatch:
    """Outputs of one :meth:`Forward.evaluate` call.

    Attributes
    ----------
    outputs : (n, 25) float array
        ``[LVV (mL), 24 strains]`` per point; NaN rows where a point failed.
    converged : (n,) bool array
    messages : tuple of str
        Per point: the solver's message, the failure reason where it failed.
    jacobian : (n, 25, p) float array or None
        ``d outputs / d inputs`` over the forward model's ``input_names``
        (NaN rows where a point failed); only when asked for.
    seconds : (n,) float array or None
        Wall time per point (s), where the forward model measures it.
    """

    outputs: np.ndarray
    converged: np.ndarray
    messages: tuple[str, ...]
    jacobian: np.ndarray | None = None
    seconds: np.ndarray | None = None

    def __post_init__(self):
        y = np.asarray(self.outputs, dtype=float)
        if y.ndim != 2 or y.shape[1] != N_OUTPUTS:
            raise ForwardError(f"forward outputs must have shape (n, {N_OUTPUTS}), got {y.shape}")
        n = y.shape[0]
        conv = np.asarray(self.converged, dtype=bool).reshape(-1)
        if conv.shape != (n,) or len(self.messages) != n:
            raise ForwardError(f"a batch of {n} points needs {n} convergence flags and messages, "
                               f"got {conv.shape[0]} and {len(self.messages)}")
        object.__setattr__(self, "outputs", y)
        object.__setattr__(self, "converged", conv)
        object.__setattr__(self, "messages", tuple(str(m) for m in self.messages))
        if self.jacobian is not None:
            jac = np.asarray(self.jacobian, dtype=float)
            if jac.ndim != 3 or jac.shape[:2] != (n, N_OUTPUTS):
                raise ForwardError(f"a Jacobian must have shape ({n}, {N_OUTPUTS}, p), got {jac.shape}")
            object.__setattr__(self, "jacobian", jac)
        if self.seconds is not None:
            object.__setattr__(self, "seconds", np.asarray(self.seconds, dtype=float).reshape(n))

    @property
    def n(self) -> int:
        """Number of points."""
        return self.outputs.shape[0]

    def raise_on_failure(self) -> "ForwardBatch":
        """Return ``self`` if every point converged, else raise :class:`SolverError` naming the first failure."""
        bad = np.flatnonzero(~self.converged)
        if bad.size:
            raise SolverError(f"{bad.size} of {self.n} forward evaluation(s) failed; point {bad[0]}: "
                              f"{self.messages[bad[0]]}")
        return self


@runtime_checkable
class Forward(Protocol):
    """A forward model: named physical inputs -> the 25 outputs (see the module docstring).

    The base capability: outputs, one point (``__call__``) or a batch (``evaluate``). What a model can do
    beyond that is its type, not a flag: :class:`JacobianForward` (derivatives of the outputs) and
    :class:`TraceableForward` (a pure JAX function), as in emukit's ``IModel`` / ``IDifferentiable``.

    Attributes
    ----------
    input_names : tuple of str
        Inputs read at call time, in Jacobian-column order.
    label : str
        Human-readable description (summaries, stores); says SYNTHETIC for stand-ins.
    input_bounds : mapping
        Box in which the forward model is valid (an emulator's training box),
        name -> (lower, upper); empty where unrestricted.

    Examples
    --------
    Any object with these members is a forward model; the SYNTHETIC analytic stand-in (tests only) is one, and a
    traceable one:

    >>> from lvcore.core.forward import Forward, TraceableForward
    >>> from lvcore.testing.analytic import AnalyticForward
    >>> model = AnalyticForward()
    >>> isinstance(model, Forward), isinstance(model, TraceableForward)
    (True, True)
    >>> y = model({"a": 0.6, "b": 5.0, "af": 1.5, "bf": 5.0})     # its reference θ
    >>> y.shape, round(float(y[0]), 6)                            # 25 outputs; LVV 140 mL
    ((25,), 140.0)
    >>> model.evaluate({"a": [0.6, 1.2], "b": 5.0, "af": 1.5, "bf": 5.0}).outputs.shape
    (2, 25)
    """

    input_names: tuple[str, ...]
    label: str

    @property
    def input_bounds(self) -> Mapping[str, tuple[float, float]]:  # pragma: no cover - protocol
        ...

    def evaluate(self, inputs: Mapping[str, Any]) -> ForwardBatch:  # pragma: no cover - protocol
        """Outputs of a batch: ``inputs`` maps every input name to a number or an ``(n,)`` array."""
        ...

    def __call__(self, params: Mapping[str, Any]) -> Any:  # pragma: no cover - protocol
        """Outputs ``(25,)`` of one point; raises :class:`SolverError` if it fails."""
        ...


@runtime_checkable
class JacobianForward(Forward, Protocol):
    """A :class:`Forward` that also gives ``d outputs / d inputs``."""

    def jacobian(self, inputs: Mapping[str, Any]) -> ForwardBatch:  # pragma: no cover - protocol
        """Like :meth:`Forward.evaluate`, with the batch's ``jacobian`` (n, 25, len(input_names)) filled."""
        ...


@runtime_checkable
class TraceableForward(JacobianForward, Protocol):
    """A :class:`Forward` whose outputs are a pure JAX function (usable inside ``jax.grad``, ``jax.vmap``, numpyro).

    ``__call__(params)`` traces; :meth:`apply` is the same function on arrays of points.
    """

    def apply(self, x: Any) -> Any:  # pragma: no cover - protocol
        """Outputs ``(..., 25)`` of points ``x`` of shape ``(..., len(input_names))`` (input_names order)."""
        ...


def as_columns(inputs: Mapping[str, Any], names: tuple[str, ...], who: str = "forward model") -> tuple[dict, int]:
    """Check ``inputs`` against ``names`` and broadcast them to float columns of one length.

    Returns ``(columns, n)``; raises :class:`ForwardError` for missing or
    unknown names, mismatched lengths, more than one dimension or non-finite values.
    """
    if not isinstance(inputs, Mapping):
        raise ForwardError(f"{who}: inputs must be a mapping name -> values, got {type(inputs).__name__}")
    missing = [n for n in names if n not in inputs]
    unknown = [k for k in inputs if k not in names]
    if missing or unknown:
        raise ForwardError(f"{who} reads inputs {list(names)}; "
                           + (f"missing {missing}" if missing else "") + ("; " if missing and unknown else "")
                           + (f"unexpected {unknown}" if unknown else ""))
    try:
        cols = [np.asarray(inputs[n], dtype=float) for n in names]
    except (TypeError, ValueError) as err:
        raise ForwardError(f"{who}: inputs must be numbers ({err})") from None
    if any(c.ndim > 1 for c in cols):
        raise ForwardError(f"{who}: each input must be a number or a 1-d array of points")
    try:
        cols = np.broadcast_arrays(*[np.atleast_1d(c) for c in cols]) if cols else []
    except ValueError:
        raise ForwardError(f"{who}: inputs have different numbers of points "
                           f"{ {n: np.size(inputs[n]) for n in names} }") from None
    n = cols[0].shape[0] if cols else 1
    out = {name: np.array(c, dtype=float) for name, c in zip(names, cols)}
    bad = [name for name, c in out.items() if not np.all(np.isfinite(c))]
    if bad:
        raise ForwardError(f"{who}: input(s) {bad} contain NaN or inf")
    return out, n


def is_traced(params: Mapping[str, Any]) -> bool:
    """True when any value of ``params`` is a JAX tracer (the caller is inside jit, grad or vmap)."""
    return any(isinstance(v, jax.core.Tracer) for v in params.values())


def failure_reason(err: BaseException) -> str:
    """``"Type: message (file.py:line)"`` for a recorded failure."""
    if isinstance(err, SolverError):
        return f"SolverError: {err}"
    last = traceback.extract_tb(err.__traceback__)[-1] if err.__traceback__ else None
    where = f" ({Path(last.filename).name}:{last.lineno})" if last else ""
    return f"{type(err).__name__}: {err}{where}"


class JaxForward:
    """Base of the forward models whose ``__call__`` is a pure JAX function of one point.

    Gives them :meth:`evaluate`, :meth:`jacobian` (``jax.jacfwd``) and :meth:`apply` (``jax.vmap``), so every
    subclass is a :class:`TraceableForward`. A subclass defines ``input_names``, ``label``, ``input_bounds``
    and ``__call__(params)``.
    """

    def _point(self, x):
        return self(dict(zip(self.input_names, x)))

    def apply(self, x):
        x = jnp.asarray(x)
        flat = jnp.reshape(x, (-1, len(self.input_names)))
        return jnp.reshape(jax.vmap(self._point)(flat), x.shape[:-1] + (N_OUTPUTS,))

    def evaluate(self, inputs: Mapping[str, Any]) -> ForwardBatch:
        return self._batch(inputs, False)

    def jacobian(self, inputs: Mapping[str, Any]) -> ForwardBatch:
        return self._batch(inputs, True)

    def _batch(self, inputs: Mapping[str, Any], jacobian: bool) -> ForwardBatch:
        cols, n = as_columns(inputs, self.input_names, self.label)
        x = jnp.stack([jnp.asarray(cols[k]) for k in self.input_names], axis=-1) if self.input_names \
            else jnp.zeros((n, 0))
        self._check_box(np.asarray(x))
        y = np.array(jax.vmap(self._point)(x), dtype=float)
        ok = np.all(np.isfinite(y), axis=1)
        jac = np.array(jax.vmap(jax.jacfwd(self._point))(x), dtype=float) if jacobian else None
        if jac is not None:
            jac[~ok] = np.nan
        y[~ok] = np.nan
        msgs = tuple("" if o else "non-finite outputs" for o in ok)
        return ForwardBatch(y, ok, msgs, jac)

    def _check_box(self, x: np.ndarray) -> None:
        """Hook: warn or raise for points outside the valid box (the emulator does)."""


__all__ = ["Forward", "JacobianForward", "TraceableForward", "ForwardBatch", "JaxForward", "as_columns",
           "failure_reason", "is_traced"]
