"""Bayesian optimisation and the SQP refit, on closed-form forward models
whose optimum is known."""
import numpy as np
import pytest

from lvcore.campaigns.space import get_space
from forward_double import JacobianDouble
from lvcore.core.forward import ForwardBatch, as_columns
from lvcore.optimise.bayesopt import StandardisedRSS, bayesian_optimise
from lvcore.optimise.sqp import OperatorLoss, refit_theta
from lvcore.domain.outputs import THETA_NAMES

W = np.random.default_rng(3).normal(size=(25, 4)) * 0.2


def smooth_forward(theta):
    """A smooth, monotone closed-form map from (a, b, af, bf) to 25 outputs."""
    t = np.log(np.atleast_2d(theta))
    y = np.tanh(t @ W.T * 0.5)
    y[:, 0] = 120.0 - 20.0 * t[:, 0] - 5.0 * t[:, 2]
    y[:, 1:] = -0.15 + 0.03 * y[:, 1:]
    return y


class SmoothForward(JacobianDouble):
    """``smooth_forward`` as a JacobianForward over (a, b, af, bf), with a central-difference Jacobian."""

    input_names = THETA_NAMES
    label = "closed-form test function"

    def _batch(self, inputs, jacobian):
        cols, n = as_columns(inputs, self.input_names)
        theta = np.column_stack([cols[k] for k in self.input_names])
        jac = None
        if jacobian:
            eps = 1e-6
            jac = np.stack([(smooth_forward(theta + eps * e) - smooth_forward(theta - eps * e)) / (2 * eps)
                            for e in np.eye(4)], axis=2)
        return ForwardBatch(smooth_forward(theta), np.ones(n, bool), ("",) * n, jac)


def test_standardised_rss_weights_lvv():
    obj = StandardisedRSS(np.zeros(25), np.ones(25), lvv_weight=2.0)
    y = np.zeros(25)
    y[0] = 1.0
    y[5] = 1.0
    assert obj(y)[0] == pytest.approx(3.0)


def test_bo_gets_close_to_known_optimum():
    space = get_space("bo4")
    truth = np.array([1.0, 2.0, 3.0, 4.0])
    measured = smooth_forward(truth)[0]
    res = bayesian_optimise(SmoothForward(), measured, space, n_initial=40, n_iterations=40, seed=1)
    design_best = res.f[: res.n_initial].min()
    assert res.f_best <= design_best
    assert res.f_best < 0.05 * design_best
    assert np.allclose(res.x_best, truth, rtol=0.25)
    assert np.all(np.diff(res.best_so_far()) <= 0)


def test_sqp_recovers_truth_with_exact_gradients():
    truth = np.array([0.6, 1.3, 1.0, 3.6])

    forward = SmoothForward()
    y_star = forward(dict(zip(THETA_NAMES, truth)))
    loss = OperatorLoss(y_star, v_early_main=80.0, v_early_test=80.0)
    res = refit_theta(forward, loss, truth * np.array([1.3, 0.8, 1.2, 0.9]))
    assert res.loss < 1e-10
    assert np.allclose(res.theta[[0, 2]], truth[[0, 2]], rtol=1e-3)


def test_operator_loss_gradient_matches_finite_differences():
    rng = np.random.default_rng(0)
    loss = OperatorLoss(np.r_[110.0, rng.normal(-0.15, 0.03, 24)], 82.0, 79.0)
    y = np.r_[105.0, rng.normal(-0.15, 0.03, 24)]
    _, g = loss.value_and_output_gradient(y)
    for i in [0, 3, 24]:
        e = np.zeros(25)
        e[i] = 1e-6
        fd = (loss.value_and_output_gradient(y + e)[0] - loss.value_and_output_gradient(y - e)[0]) / 2e-6
        assert g[i] == pytest.approx(fd, rel=1e-5, abs=1e-9)


@pytest.mark.slow
def test_sqp_on_the_simulator_uses_its_adjoint_jacobian():
    """The refit on the FE simulator itself (same geometry): the adjoint Jacobian drives SLSQP back to the truth."""
    from lvcore.mechanics.forward import AdjointSimulatorForward

    sim = AdjointSimulatorForward(resolution="fast")
    truth = np.array([0.6, 1.3, 1.0, 3.6])
    y_star = sim(dict(zip(THETA_NAMES, truth)))
    loss = OperatorLoss(y_star, v_early_main=80.0, v_early_test=80.0)
    start = truth * np.array([1.2, 0.9, 1.1, 0.9])
    res = refit_theta(sim, loss, start, max_iterations=30)
    start_loss = loss.value_and_output_gradient(sim(dict(zip(THETA_NAMES, start))))[0]
    assert res.success and res.loss < 1e-4 * start_loss
    # theta is weakly identified from noise-free outputs (a flat valley): every parameter moves toward the truth
    assert np.all(np.abs(res.theta / truth - 1) < 0.25 * np.abs(start / truth - 1))


def ridge_forward(theta):
    """Outputs that depend on a and b through a·b only (the a–b ridge of one loaded state), and on af, bf."""
    t = np.log(np.atleast_2d(theta))
    ridge = np.column_stack([t[:, 0] + t[:, 1], t[:, 2], t[:, 3]])
    y = np.tanh(ridge @ W[:, :3].T * 0.5)
    y[:, 0] = 120.0 - 20.0 * ridge[:, 0] - 5.0 * ridge[:, 1]
    y[:, 1:] = -0.15 + 0.03 * y[:, 1:]
    return y


class RidgeForward(SmoothForward):
    def _batch(self, inputs, jacobian):
        cols, n = as_columns(inputs, self.input_names)
        theta = np.column_stack([cols[k] for k in self.input_names])
        return ForwardBatch(ridge_forward(theta), np.ones(n, bool), ("",) * n, None)


def test_posterior_objective_is_chi2_plus_the_prior_terms():
    from lvcore.optimise.bayesopt import PosteriorObjective

    measured = np.r_[120.0, np.full(24, -0.15)]
    obj = PosteriorObjective(measured, 5.0, 0.03, {"a": (1.0, 0.5)}, {"alpha_endo": (-60.0, 20.0)})
    y = measured + np.r_[10.0, np.full(24, 0.03)]
    x = np.array([[np.e, 5.0, -20.0]])
    # chi2: (10/5)² + 24·1² = 28; prior: (ln e / 0.5)² = 4 on a, ((−20 + 60)/20)² = 4 on alpha_endo; b has none
    assert obj.misfit(y)[0] == pytest.approx(28.0)
    assert obj.penalty(("a", "b", "alpha_endo"), x)[0] == pytest.approx(8.0)
    assert obj(y, ("a", "b", "alpha_endo"), x)[0] == pytest.approx(36.0)


def test_the_posterior_objective_keeps_a_ridge_fit_off_the_box_edge():
    """Data that fix a·b only, from a truth near two box edges (a = 0.12, b = 8; the box is [0.1, 10]): the
    regularised BO's best point lies on the ridge (a·b as the truth's), clearly better than the truth on its
    objective (the prior pulls it along the ridge), and away from every edge; its recorded best value is the
    objective at the recorded best point."""
    from lvcore.optimise.bayesopt import PosteriorObjective

    space = get_space("bo4")
    truth = np.array([0.12, 8.0, 1.0, 3.0])
    measured = ridge_forward(truth)[0]
    obj = PosteriorObjective(measured, 5.0, 0.03, {n: (1.0, float(np.log(10) / 2)) for n in THETA_NAMES}, {})
    res = bayesian_optimise(RidgeForward(), measured, space, n_initial=30, n_iterations=40, seed=2, objective=obj)
    a, b = res.x_best[:2]
    assert a * b == pytest.approx(truth[0] * truth[1], rel=0.15)
    f_truth = obj(ridge_forward(truth), space.names, truth[None, :])[0]   # its prior term alone is 6.6
    assert res.f_best < f_truth - 2.0
    assert np.min(np.abs(np.log(res.x_best / np.array([[0.1], [10.0]])))) > 0.3   # no parameter near an edge
    assert res.f_best == pytest.approx(obj(res.y_best, space.names, res.x_best)[0])
    with pytest.raises(ValueError, match="measured data differ"):
        bayesian_optimise(RidgeForward(), measured + 1.0, space, n_initial=5, n_iterations=1, objective=obj)
