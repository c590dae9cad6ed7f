"""Optimisation studies on a :class:`lvcore.core.Forward`: Bayesian optimisation (chapter §9.3.1) and the
SQP refit of the operator study (§9.3.3)."""
from __future__ import annotations

from lvcore._exports import lazy_exports

_EXPORTS = {
    "BOResult": "bayesopt", "StandardisedRSS": "bayesopt", "bayesian_optimise": "bayesopt",
    "OperatorLoss": "sqp", "SQPResult": "sqp", "refit_theta": "sqp",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
