"""Bayesian optimisation (GP surrogate + lower confidence bound), as in the chapter §9.3.1.

The objective is the residual sum of squares between a forward model's 25
outputs and measured data, each output standardised by the standard deviation
of the initial design's outputs, with the LVV term weighted (×2 in the
chapter)::

    f(x) = w_V ((y_0(x) - y*_0) / s_0)² + Σ_i ((y_i(x) - y*_i) / s_i)²

The initial design is the chapter's 300-point "exp design" (a Latin hypercube
whose material dimensions are exp-warped and rescaled to [0.1, 10]; see
:func:`lvcore.campaigns.designs.make_design`). Each iteration fits a Gaussian
process (scikit-learn, Matérn 5/2 with automatic relevance determination plus
white noise) to the objective values in the unit cube and evaluates the
forward model where the acquisition ``A = μ − κ σ`` (κ = 2, the MATLAB
default used in the chapter) is smallest. Unlike the chapter, the GP models
``log f`` rather than ``f``: the RSS spans several orders of magnitude over
the box and a GP on the raw values fits the many poor points at the expense
of the basin (with raw values our test problem made no progress at all).

A regularised alternative, not the chapter's (:class:`PosteriorObjective`): minus twice the log posterior of
the calibration's Gaussian noise model (σ_V on the LVV, σ_S on each strain) under a weakly informative prior,
log-normal on the stiffnesses and normal on free fibre angles. The chapter's objective has no term that keeps a
fit off the box's edge: along the a–b ridge, and for angles whose strain signal is a fraction of σ_S, the data
do not decide, so where its optimum lands, a bound included, is set by the noise
(``benchmarks/bo_fit_vs_truth.py``); the prior picks the point of that valley nearest its centre.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import minimize
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

from lvcore.campaigns.designs import make_design
from lvcore.core.forward import Forward
from lvcore.core.space import ParameterSpace
from lvcore.exceptions import ForwardError, SolverError
from lvcore.domain.outputs import N_OUTPUTS

#: The GP models log(f + floor): the RSS spans orders of magnitude over the box.
_LOG_FLOOR = 1e-6


@dataclass(frozen=True)
class StandardisedRSS:
    """The chapter's BO objective (see module docstring).

    Parameters
    ----------
    measured : (25,) array
        Measured LVV (mL) and 24 strains.
    scale : (25,) array
        Standard deviation of each output over the initial design.
    lvv_weight : float
        Weight of the LVV term (2 in the chapter).
    """

    measured: np.ndarray
    scale: np.ndarray
    lvv_weight: float = 2.0

    def __call__(self, outputs: np.ndarray) -> np.ndarray:
        r = (np.atleast_2d(outputs) - self.measured) / self.scale
        w = np.ones(N_OUTPUTS)
        w[0] = self.lvv_weight
        return np.sum(w * r**2, axis=1)


@dataclass(frozen=True)
class PosteriorObjective:
    """Minus twice the log posterior (up to a constant) of outputs and parameters: the regularised BO objective.

    ``f(x) = ((y_0 − y*_0)/σ_V)² + Σ_i ((y_i − y*_i)/σ_S)² + Σ_θ ((ln θ − ln m_θ)/s_θ)² + Σ_α ((α − c_α)/s_α)²``

    Parameters
    ----------
    measured : (25,) array
        Measured LVV (mL) and 24 strains.
    sigma_v_ml, sigma_s : float
        Noise SDs of the LVV (mL) and of each strain (the calibration's σ_V and σ_S).
    log_prior : dict
        Parameter name -> ``(median, log_sd)`` of a log-normal prior (stiffnesses, kPa).
    normal_prior : dict
        Parameter name -> ``(mean, sd)`` of a normal prior (fibre angles, degrees).
    """

    measured: np.ndarray
    sigma_v_ml: float
    sigma_s: float
    log_prior: dict
    normal_prior: dict

    def misfit(self, outputs: np.ndarray) -> np.ndarray:
        """The data term alone, ``χ²`` per row of ``outputs`` (n, 25)."""
        sd = np.r_[self.sigma_v_ml, np.full(N_OUTPUTS - 1, self.sigma_s)]
        return np.sum(((np.atleast_2d(outputs) - self.measured) / sd) ** 2, axis=1)

    def penalty(self, names, X: np.ndarray) -> np.ndarray:
        """The prior term per row of ``X`` (n, len(names)); parameters without a prior add nothing."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        out = np.zeros(X.shape[0])
        for j, n in enumerate(names):
            if n in self.log_prior:
                med, sd = self.log_prior[n]
                out += ((np.log(X[:, j]) - np.log(med)) / sd) ** 2
            elif n in self.normal_prior:
                mu, sd = self.normal_prior[n]
                out += ((X[:, j] - mu) / sd) ** 2
        return out

    def __call__(self, outputs: np.ndarray, names, X: np.ndarray) -> np.ndarray:
        return self.misfit(outputs) + self.penalty(names, X)


@dataclass(frozen=True)
class BOResult:
    """Outcome of :func:`bayesian_optimise`.

    Attributes
    ----------
    x_best : (dim,) array
        Best evaluated point in physical units (names in ``names``).
    f_best : float
        Objective at ``x_best``.
    y_best : (25,) array
        Forward-model outputs at ``x_best``.
    X, f : arrays
        Every evaluated point (physical units) and its objective, in order
        (initial design first).
    n_initial : int
        Size of the initial design.
    names : tuple of str
    """

    x_best: np.ndarray
    f_best: float
    y_best: np.ndarray
    X: np.ndarray
    f: np.ndarray
    n_initial: int
    names: tuple

    def best_so_far(self) -> np.ndarray:
        """Running minimum of the objective (for convergence plots)."""
        return np.minimum.accumulate(self.f)


def _fit_gp(U: np.ndarray, f: np.ndarray, kernel=None, seed: int = 0, optimise: bool = True
            ) -> GaussianProcessRegressor:
    """GP on ``(U, f)``.

    ``kernel=None``: hyperparameters estimated from the default start plus one
    random restart. With a fitted ``kernel``: ``optimise=True`` re-estimates
    them from that kernel's values (a warm start, no restart);
    ``optimise=False`` keeps them and only conditions on the data.
    """
    if kernel is None:
        kernel = ConstantKernel(1.0, (1e-3, 1e3)) * Matern(
            length_scale=np.full(U.shape[1], 0.3), length_scale_bounds=(1e-2, 1e1), nu=2.5
        ) + WhiteKernel(1e-4, (1e-8, 1e-1))
        gp = GaussianProcessRegressor(kernel, normalize_y=True, n_restarts_optimizer=1, random_state=seed)
    elif optimise:
        gp = GaussianProcessRegressor(kernel, normalize_y=True, n_restarts_optimizer=0, random_state=seed)
    else:
        gp = GaussianProcessRegressor(kernel, normalize_y=True, optimizer=None)
    return gp.fit(U, f)


#: Step of the forward differences of the acquisition (unit-cube coordinates).
_FD_STEP = 1e-6


def _next_point(gp, dim: int, rng: np.random.Generator, U_best: np.ndarray, kappa: float) -> np.ndarray:
    """Minimiser of the LCB: best of 2,200 candidates, the three best polished by L-BFGS-B in the unit cube.

    The polish gets its gradient by forward differences evaluated in ONE
    GP prediction of ``dim + 1`` points (stepping inwards at the upper
    bound), instead of ``dim + 1`` separate predictions: the per-call cost
    of the GP's predict dominates at these sizes.
    """
    def lcb(u):
        mu, sd = gp.predict(np.atleast_2d(u), return_std=True)
        return mu - kappa * sd

    steps = np.eye(dim) * _FD_STEP

    def lcb_and_gradient(u):
        h = np.where(u + _FD_STEP <= 1.0, 1.0, -1.0)
        v = lcb(np.vstack([u, u + steps * h[:, None]]))
        return float(v[0]), (v[1:] - v[0]) / (_FD_STEP * h)

    cand = np.vstack([rng.random((2000, dim)), np.clip(U_best + 0.05 * rng.standard_normal((200, dim)), 0, 1)])
    vals = lcb(cand)
    best = cand[np.argsort(vals)[:3]]
    results = [minimize(lcb_and_gradient, u0, jac=True, method="L-BFGS-B", bounds=[(0.0, 1.0)] * dim)
               for u0 in best]
    return min(results, key=lambda r: r.fun).x


def _outputs(forward: Forward, space: ParameterSpace, X: np.ndarray, chain: bool = False) -> np.ndarray:
    """``(n, 25)`` outputs at the rows of ``X`` (columns ``space.names``); NaN rows where a point failed.

    ``chain``: evaluate the rows in continuation order (near neighbours in the
    space's unit cube one after another, :func:`lvcore.execution.chains.continuation_order`)
    and return them in the order of ``X``. A warm-starting forward model
    (``SimulatorForward(warm_start=True)``) then starts each solve from a
    neighbour's solution, also when a caller splits the batch into chunks; for
    any other forward model only the order of the calls changes.
    """
    X = np.atleast_2d(X)
    if not chain or X.shape[0] < 3:
        return forward.evaluate(dict(zip(space.names, X.T))).outputs
    from lvcore.execution.chains import continuation_order

    order = continuation_order(space.to_unit(X))
    Y = np.empty((X.shape[0], N_OUTPUTS))
    Y[order] = forward.evaluate(dict(zip(space.names, X[order].T))).outputs
    return Y


def _objective(objective, Y: np.ndarray, X: np.ndarray, f_seen: np.ndarray) -> np.ndarray:
    """Objective per row of outputs ``Y`` at points ``X``; a failed point (NaN outputs) gets the worst value seen
    so far."""
    f = objective(Y, X)
    ok = np.isfinite(f)
    if not ok.all():
        finite = np.concatenate([f_seen[np.isfinite(f_seen)], f[ok]])
        if finite.size == 0:
            raise SolverError("every forward evaluation of the initial design failed")
        f = np.where(ok, f, finite.max())
    return f


def bayesian_optimise(
    forward: Forward,
    measured: np.ndarray,
    space: ParameterSpace,
    n_initial: int = 300,
    n_iterations: int = 300,
    seed: int = 0,
    lvv_weight: float = 2.0,
    kappa: float = 2.0,
    refit_every: int = 20,
    callback: Callable[[int, float], None] | None = None,
    objective: PosteriorObjective | None = None,
) -> BOResult:
    """Minimise the standardised RSS of ``forward`` against ``measured`` by BO.

    Parameters
    ----------
    forward : Forward
        Reads ``space.names`` (its ``input_names``, in any order); evaluated in
        batches (the initial design in one batch, in continuation order: a
        :class:`~lvcore.mechanics.SimulatorForward` with ``workers`` runs it on a
        process pool, and with ``warm_start=True`` as warm-started chains, each
        solve starting from a neighbour's solution; BO iterations then start
        from the nearest earlier point). A point that fails gets the worst
        objective seen so far.
    measured : (25,) array
        Measured LVV (mL) and 24 strains.
    space : ParameterSpace
        The optimisation box, e.g. ``get_space("bo4")`` or ``"bo6"``.
    n_initial, n_iterations : int
        Size of the exp design and number of BO iterations (300 and 300 in
        the chapter).
    seed : int
        Seeds the design and the acquisition search.
    lvv_weight, kappa : float
        LVV weight in the objective and LCB exploration weight.
    refit_every : int
        Re-estimate the GP hyperparameters every this many iterations, warm
        started from the previous estimate (the first estimate starts from the
        default kernel plus one random restart). In between, the GP is
        conditioned on all data with fixed hyperparameters. The
        hyperparameter fit is the cost that grows with the data (O(n³) per
        likelihood evaluation, about a hundred evaluations per fit); see
        ``benchmarks/bench_studies.py gp``.
    callback : callable, optional
        Called as ``callback(iteration, best_objective)``.
    objective : PosteriorObjective, optional
        The regularised objective instead of the chapter's standardised RSS (None; ``lvv_weight`` is then
        unused). Its ``measured`` must be ``measured``.

    Returns
    -------
    BOResult
    """
    measured = np.asarray(measured, dtype=float)
    if measured.shape != (N_OUTPUTS,) or not np.all(np.isfinite(measured)):
        raise ValueError(f"measured data must be {N_OUTPUTS} finite numbers (LVV mL and 24 strains)")
    if refit_every < 1:
        raise ValueError("refit_every must be at least 1")
    if set(forward.input_names) != set(space.names):
        raise ForwardError(f"the optimisation box varies {list(space.names)}; the forward model reads "
                           f"{list(forward.input_names)}")
    design = make_design(space, "exp", n_initial, seed)
    X = np.array(design.points)
    Y = _outputs(forward, space, X, chain=True)
    if objective is None:
        scale = np.nanstd(Y, axis=0)
        scale[~(scale > 0)] = 1.0
        rss = StandardisedRSS(measured, scale, lvv_weight)
        objective = lambda y, x: rss(y)  # noqa: E731 - the chapter's objective reads the outputs only
    elif not np.array_equal(np.asarray(objective.measured, dtype=float), measured):
        raise ValueError("the posterior objective's measured data differ from the data being fitted")
    else:
        posterior = objective
        objective = lambda y, x: posterior(y, space.names, x)  # noqa: E731
    f = _objective(objective, Y, X, np.empty(0))
    U = space.to_unit(X)
    rng = np.random.default_rng(seed + 1)
    kernel = None
    for it in range(n_iterations):
        gp = _fit_gp(U, np.log(f + _LOG_FLOOR), kernel, seed, optimise=it % refit_every == 0)
        kernel = gp.kernel_
        u_new = _next_point(gp, space.dim, rng, U[np.argmin(f)], kappa)
        x_new = space.from_unit(u_new[None, :])
        y_new = _outputs(forward, space, x_new)
        X = np.vstack([X, x_new])
        Y = np.vstack([Y, y_new])
        U = np.vstack([U, u_new[None, :]])
        f = np.append(f, _objective(objective, y_new, x_new, f))
        if callback is not None:
            callback(it, float(f.min()))
    i = int(np.argmin(f))
    return BOResult(X[i], float(f[i]), Y[i], X, f, n_initial, space.names)
