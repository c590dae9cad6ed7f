"""SQP refit of the material parameters for the operator study (chapter §9.3.3).

Given data ``y*`` simulated at the truth θ̃ on the main operator's geometry g
(early-diastolic volume ``V_early``), θ is refitted on a test geometry ĝ
(another operator, or a k-PC reconstruction of g; early volume ``V̂_early``)
by minimising the chapter's loss (9.11)::

    L(θ) = ((V_early − y*_0)/y*_0 − (V̂_early − ζ_0(θ, ĝ))/ζ_0(θ, ĝ))²
           + Σ_{i=1}^{24} (y*_i − ζ_i(θ, ĝ))²

starting at θ̃, with scipy's SLSQP inside the prior box. The volume term
compares the relative volume change, so the early volume of a reconstruction
does not dominate. Gradients come from the forward model's Jacobian (the
simulator's adjoint, :class:`lvcore.mechanics.AdjointSimulatorForward`) when it provides
one (a :class:`~lvcore.core.forward.JacobianForward`), else from scipy's finite differences.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from lvcore.core.forward import Forward, JacobianForward
from lvcore.core.space import THETA_BOUNDS
from lvcore.exceptions import ForwardError
from lvcore.domain.outputs import N_OUTPUTS, THETA_NAMES


@dataclass(frozen=True)
class OperatorLoss:
    """Loss (9.11) and its gradient with respect to the outputs.

    Parameters
    ----------
    measured : (25,) array
        ``y*`` on the main geometry: LVV (mL) and 24 strains.
    v_early_main, v_early_test : float
        Early-diastolic cavity volumes (mL) of the main and the test geometry.
    """

    measured: np.ndarray
    v_early_main: float
    v_early_test: float

    def value_and_output_gradient(self, y: np.ndarray) -> tuple[float, np.ndarray]:
        y0s = self.measured[0]
        rel_main = (self.v_early_main - y0s) / y0s
        rel_test = (self.v_early_test - y[0]) / y[0]
        r0 = rel_main - rel_test
        rs = self.measured[1:] - y[1:]
        grad = np.empty(N_OUTPUTS)
        # d rel_test / d y0 = -V̂_early / y0²
        grad[0] = 2.0 * r0 * (self.v_early_test / y[0] ** 2)
        grad[1:] = -2.0 * rs
        return float(r0**2 + rs @ rs), grad


@dataclass(frozen=True)
class SQPResult:
    theta: np.ndarray
    loss: float
    outputs: np.ndarray
    success: bool
    message: str
    n_evaluations: int


def refit_theta(
    forward: Forward,
    loss: OperatorLoss,
    theta_start: np.ndarray,
    bounds: dict | None = None,
    tol: float = 1e-10,
    max_iterations: int = 100,
) -> SQPResult:
    """Refit θ = (a, b, af, bf) on a test geometry by SLSQP from ``theta_start``.

    Parameters
    ----------
    forward : Forward
        Reads ``a, b, af, bf`` (``input_names`` in that order), e.g.
        ``SimulatorForward(geometry=..., resolution=...)`` on the test
        geometry. As a :class:`~lvcore.core.forward.JacobianForward` its Jacobian gives the gradient,
        else scipy's finite differences do. A point that fails to converge
        raises :class:`~lvcore.exceptions.SolverError`.
    loss : OperatorLoss
    theta_start : (4,) array
        Start (the truth θ̃ in the chapter), kPa for a and af.
    bounds : dict, optional
        Parameter bounds; default the prior box of Table 9.1.
    """
    if tuple(forward.input_names) != THETA_NAMES:
        raise ForwardError(f"the SQP refit varies {list(THETA_NAMES)}; the forward model reads "
                           f"{list(forward.input_names)} (bind the other inputs into it)")
    bounds = THETA_BOUNDS if bounds is None else bounds
    box = [bounds[n] for n in THETA_NAMES]
    has_jac = isinstance(forward, JacobianForward)
    cache: dict = {}
    n_eval = [0]

    def evaluate(theta):
        key = tuple(np.round(theta, 14))
        if key not in cache:
            point = dict(zip(THETA_NAMES, np.asarray(theta, dtype=float)))
            batch = (forward.jacobian(point) if has_jac else forward.evaluate(point)).raise_on_failure()
            n_eval[0] += 1
            y = batch.outputs[0]
            value, g_y = loss.value_and_output_gradient(y)
            grad = batch.jacobian[0].T @ g_y if has_jac else None
            cache[key] = (value, grad, y)
        return cache[key]

    res = minimize(
        lambda t: evaluate(t)[0],
        np.asarray(theta_start, dtype=float),
        jac=(lambda t: evaluate(t)[1]) if has_jac else None,
        method="SLSQP",
        bounds=box,
        options={"ftol": tol, "maxiter": max_iterations},
    )
    value, _, y = evaluate(res.x)
    return SQPResult(np.asarray(res.x), value, y, bool(res.success), str(res.message), n_eval[0])
