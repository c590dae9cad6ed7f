"""Optimisation studies on a :class:`lvcore.core.Forward`: Bayesian optimisation (chapter §9.3.1) and the
SQP refit of the operator study (§9.3.3)."""
from __future__ import annotations

from lvcore.optimise.bayesopt import BOResult, StandardisedRSS, bayesian_optimise
from lvcore.optimise.sqp import OperatorLoss, SQPResult, refit_theta

__all__ = ["BOResult", "StandardisedRSS", "bayesian_optimise", "OperatorLoss", "SQPResult", "refit_theta"]
