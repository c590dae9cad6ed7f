"""Base of the numpy forward-model test doubles that have a Jacobian (a :class:`lvcore.core.JacobianForward`).

A subclass sets ``input_names`` and ``label`` and writes one ``_batch(inputs, jacobian)`` returning a
:class:`lvcore.core.ForwardBatch`; ``evaluate``, ``jacobian`` and the one-point call come from here.
"""
from __future__ import annotations


class JacobianDouble:
    input_bounds: dict = {}

    def _batch(self, inputs, jacobian: bool):  # pragma: no cover - subclasses
        raise NotImplementedError

    def evaluate(self, inputs):
        return self._batch(inputs, False)

    def jacobian(self, inputs):
        return self._batch(inputs, True)

    def __call__(self, params):
        return self.evaluate({k: params[k] for k in self.input_names}).outputs[0]
