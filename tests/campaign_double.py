"""TEST DOUBLE for the campaign machinery (not a feature, not a simulator).

:class:`DoubleForward` is a cheap, deterministic stand-in for the simulator's
:class:`~lvcore.core.forward.Forward` with the same contract; importing this
module registers it as the forward model ``"campaign-double"``. It exists so
the campaign tests can check the store and runner (crash safety, resume,
failed rows, Dask) in seconds.

* The 25 "outputs" are a smooth closed-form function of the case numbers.
* A case with ``material.a > FAIL_ABOVE_A`` returns ``converged=False``;
  one with ``material.b > RAISE_ABOVE_B`` raises :class:`SolverError`.
* If ``LVCORE_TEST_EXEC_LOG`` is set, every call appends ``start <a>`` and
  ``end <a>`` lines (with the pid) to that file, so a test can count how many
  times each row ran. ``LVCORE_TEST_SLEEP`` (s) slows each call down.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np

from lvcore.core import register_forward
from lvcore.exceptions import SolverError

FAIL_ABOVE_A = float(os.environ.get("LVCORE_TEST_FAIL_ABOVE_A", "inf"))
RAISE_ABOVE_B = float(os.environ.get("LVCORE_TEST_RAISE_ABOVE_B", "inf"))


@dataclass(frozen=True)
class DoubleResult:
    converged: bool
    message: str
    seconds: float
    y: np.ndarray

    def outputs(self) -> np.ndarray:
        return self.y


def closed_form(a, b, af, bf):
    """The double's outputs: volume-like and strain-like smooth functions."""
    lvv = 100.0 + 30.0 / (1.0 + a + 0.1 * b + 0.5 * af + 0.05 * bf)
    r = np.arange(24)
    strains = -0.05 - 0.1 / (1.0 + a * (1 + 0.01 * r) + 0.2 * af)
    return np.concatenate([[lvv], strains])


def _log(event: str, key: str) -> None:
    path = os.environ.get("LVCORE_TEST_EXEC_LOG")
    if path:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, f"{event} {key} {os.getpid()}\n".encode())
        finally:
            os.close(fd)


def forward(case: dict) -> DoubleResult:
    """The double on a case dictionary (material section only)."""
    t0 = time.perf_counter()
    m = case["material"]
    key = repr(float(m["a"]))
    _log("start", key)
    time.sleep(float(os.environ.get("LVCORE_TEST_SLEEP", "0")))
    if m["b"] > RAISE_ABOVE_B:
        _log("end", key)
        raise SolverError(f"test double: b={m['b']:.3g} too stiff")
    y = closed_form(m["a"], m["b"], m["af"], m["bf"])
    _log("end", key)
    if m["a"] > FAIL_ABOVE_A:
        return DoubleResult(False, "test double: line search failed", time.perf_counter() - t0, y)
    return DoubleResult(True, "", time.perf_counter() - t0, y)


@dataclass(frozen=True)
class DoubleForward:
    """The double as a Forward over ``a, b, af, bf`` (one point at a time, as the campaign runner calls it)."""

    input_names: tuple = ("a", "b", "af", "bf")
    label: str = "campaign TEST DOUBLE"
    input_bounds = {}

    def evaluate(self, inputs):
        from lvcore.core.forward import ForwardBatch, as_columns

        cols, n = as_columns(inputs, self.input_names, self.label)
        rows = [forward({"material": {k: float(cols[k][i]) for k in self.input_names}}) for i in range(n)]
        return ForwardBatch(np.stack([np.where(r.converged, r.y, np.nan) for r in rows]),
                            np.array([r.converged for r in rows]), tuple(r.message for r in rows),
                            seconds=np.array([r.seconds for r in rows]))

    def evaluate_warm(self, point, initial=None):
        """As the simulator's: one point "started" from ``initial``; the state is the point itself.

        The outputs never depend on ``initial`` (so results equal the cold ones exactly);
        ``LVCORE_TEST_EXEC_LOG`` gets a ``warm <a> <a of the start>`` line when a state was given.
        """
        if initial is not None:
            _log("warm", f"{float(point['a'])!r}->{float(initial[0])!r}")
        b = self.evaluate({k: [float(point[k])] for k in self.input_names})
        state = np.array([float(point[k]) for k in self.input_names]) if b.converged[0] else None
        return b, state, "cold" if initial is None else "warm", ""

    def __call__(self, params):
        return self.evaluate({k: params[k] for k in self.input_names}).outputs[0]


NAME = "campaign-double"
register_forward(NAME, lambda space, resolution: DoubleForward(tuple(space.names)), overwrite=True)
