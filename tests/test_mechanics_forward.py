"""lvcore.mechanics.forward: the FE simulator as a forward model (batches, adjoint Jacobian, pools, warm start)."""
import jax
import numpy as np
import pytest

import lvcore
from lvcore.core import ForwardBatch
from lvcore.mechanics.case_inputs import build_case
from lvcore.exceptions import ForwardError
from lvcore.mechanics.forward import AdjointSimulatorForward
from lvcore.domain.outputs import THETA_NAMES

THETA = np.array([0.6, 1.3, 1.0, 3.6])


@pytest.fixture(scope="module")
def sim():
    return AdjointSimulatorForward(resolution="fast")


def test_simulator_batch_matches_direct_simulate(sim):
    pts = np.array([THETA, THETA * [2.0, 1.0, 2.0, 1.0]])
    batch = sim.evaluate(dict(zip(THETA_NAMES, pts.T)))
    assert isinstance(batch, ForwardBatch) and batch.outputs.shape == (2, 25)
    assert batch.converged.all() and np.all(batch.seconds > 0)
    for i in range(2):
        direct = lvcore.simulate(build_case(dict(zip(THETA_NAMES, pts[i])), resolution="fast")).outputs()
        np.testing.assert_array_equal(batch.outputs[i], direct)
    assert batch.outputs[1, 0] < batch.outputs[0, 0]  # stiffer -> smaller end-diastolic volume
    np.testing.assert_array_equal(sim(dict(zip(THETA_NAMES, pts[0]))), batch.outputs[0])


def test_simulator_adjoint_jacobian_matches_central_differences(sim):
    jac = sim.jacobian(dict(zip(THETA_NAMES, THETA))).jacobian[0]
    assert jac.shape == (25, 4)
    steps = 1e-4 * THETA
    plus, minus = THETA + np.diag(steps), THETA - np.diag(steps)
    b = sim.evaluate(dict(zip(THETA_NAMES, np.vstack([plus, minus]).T)))
    assert b.converged.all()
    fd = ((b.outputs[:4] - b.outputs[4:]) / (2 * steps[:, None])).T
    scale = np.abs(fd).max(axis=0)  # per parameter: relative to the largest sensitivity
    assert np.max(np.abs(jac - fd) / scale) < 1e-3


def test_simulator_failures_are_rows_and_tracing_is_refused(sim):
    # a = 1e-9 kPa: an essentially stress-free matrix at 8 mmHg does not converge (or is rejected): a failed row
    b = sim.evaluate({"a": [0.6, 0.6], "b": 1.3, "af": 1.0, "bf": [3.6, -1.0]})
    assert b.converged[0] and not b.converged[1]
    assert np.all(np.isnan(b.outputs[1])) and "bf" in b.messages[1]
    with pytest.raises(ForwardError, match="not JAX-traceable"):
        jax.grad(lambda a: sim({"a": a, "b": 1.3, "af": 1.0, "bf": 3.6})[0])(0.6)
    with pytest.raises(ForwardError, match="missing"):
        sim.evaluate({"a": 1.0})
    with pytest.raises(ForwardError, match="unexpected"):
        sim.evaluate({**dict(zip(THETA_NAMES, THETA)), "edp": 8.0})


@pytest.mark.slow
def test_simulator_batch_on_a_process_pool_equals_serial(sim):
    """workers=2 runs the batch on lvcore.execution.parallel.LocalExecutor: same numbers as in-process."""
    pts = {"a": [0.6, 1.2], "b": 1.3, "af": 1.0, "bf": 3.6}
    pooled = AdjointSimulatorForward(resolution="fast", workers=2).jacobian(pts)
    serial = sim.jacobian(pts)
    assert pooled.converged.all()
    np.testing.assert_array_equal(pooled.outputs, serial.outputs)
    np.testing.assert_array_equal(pooled.jacobian, serial.jacobian)


def test_simulator_warm_start_reproduces_cold_solves(sim):
    """warm_start=True (SQP refits): Newton starts from the last converged state; same outputs and Jacobian."""
    warm = AdjointSimulatorForward(resolution="fast", warm_start=True)
    near = THETA * np.array([1.05, 0.97, 1.02, 1.04])
    first = warm.evaluate(dict(zip(THETA_NAMES, THETA)))
    assert first.messages[0] == "converged"  # nothing to start from yet
    b = warm.jacobian(dict(zip(THETA_NAMES, near)))
    assert b.messages[0] == "converged (warm start)"
    cold = sim.jacobian(dict(zip(THETA_NAMES, near)))
    np.testing.assert_allclose(b.outputs, cold.outputs, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(b.jacobian, cold.jacobian, rtol=1e-5, atol=1e-8)


def test_warm_continuation_reaches_a_point_a_plain_warm_start_cannot_and_equals_the_cold_solve():
    """A failed warm start continues through the parameter midpoint (issue 25): bf 1 -> 10 at soft a, af is out
    of a plain warm start's reach on the fast mesh, the midpoint path converges, and to the cold solve's outputs."""
    from lvcore.execution.chains import light_state
    from lvcore.mechanics.case_inputs import build_case
    from lvcore.mechanics import forward as F
    from lvcore.mechanics.simulate import simulate

    def case(theta):
        return build_case(dict(zip(("a", "b", "af", "bf"), theta)), resolution="fast", base="sliding")

    start, target = case((0.3, 0.5, 0.2, 1.0)), case((0.3, 0.5, 0.2, 10.0))
    state = F._as_warm(simulate(start), F.case_values(start))
    assert state.values == (0.3, 0.5, 0.2, 1.0, -60.0, 60.0, 8.0)
    light = light_state(state)
    assert light.tangent is None and light.values == state.values  # chains drop the factor, keep the parameters
    plain = simulate(target, options=F._warm_only_options(), initial=light)
    assert not plain.converged and plain.message == "warm start did not converge"
    via = F.warm_continuation(target, light)
    assert via.converged and via.message == "converged (warm start)"
    cold = simulate(target)
    np.testing.assert_allclose(via.outputs(), cold.outputs(), rtol=1e-7, atol=1e-9)
    assert F.warm_continuation(target, light, depth=0).converged is False  # without the midpoint: as plain


def test_a_suspect_warm_result_is_re_solved_cold_in_a_warm_batch(sim, monkeypatch):
    """A warm-started batch (sweeps, BO, the subject emulators' runs) guards its rows as a campaign does: a point
    whose warm Newton path is suspect (here every one: the rule forced) is solved again cold, so its outputs are
    the cold solve's to round-off, and each re-solve is recorded with its reason. Unforced, the warm batch agrees
    with the cold solves within the solver's tolerance and records nothing it did not re-solve."""
    from lvcore.execution import chains
    from lvcore.mechanics.forward import SimulatorForward

    points = {n: THETA[i] * np.array([1.0, 1.04, 0.97, 1.06]) for i, n in enumerate(THETA_NAMES)}
    cold = SimulatorForward(resolution="fast").evaluate(points)
    free = SimulatorForward(resolution="fast", warm_start=True)
    got = free.evaluate(points)
    np.testing.assert_allclose(got.outputs, cold.outputs, rtol=1e-6, atol=1e-8)
    assert all(why for why in free.resolved_cold)   # each one recorded with its reason
    monkeypatch.setattr(chains, "warm_path_problem", lambda log: "forced by the test")
    guarded = SimulatorForward(resolution="fast", warm_start=True)
    got = guarded.evaluate(points)
    assert got.converged.all()
    np.testing.assert_allclose(got.outputs, cold.outputs, rtol=1e-12, atol=1e-12)
    # the first point is solved cold (nothing to start from); the other three started warm and were re-solved
    assert guarded.resolved_cold == ("forced by the test",) * 3


def test_the_soft_corner_is_a_box_in_a_and_af_that_grows_with_the_pressure():
    """Pure: the points solved cold whatever their start (a, af both below the bounds, scaled above 8 mmHg)."""
    from lvcore.mechanics.forward import SOFT_CORNER_KPA, soft_corner

    a0, af0 = SOFT_CORNER_KPA["a"], SOFT_CORNER_KPA["af"]

    def case(a, af, edp=8.0, b=1.0):
        return build_case({"a": a, "b": b, "af": af, "bf": 1.0, "edp": edp}, resolution="fast")

    assert soft_corner(case(0.9 * a0, 0.9 * af0)) and soft_corner(case(0.05, 0.05, b=30.0))
    assert not soft_corner(case(1.1 * a0, 0.9 * af0)) and not soft_corner(case(0.9 * a0, 1.1 * af0))
    assert not soft_corner(case(0.9 * a0, 1.1 * af0, edp=4.0))   # never smaller than at 8 mmHg
    assert soft_corner(case(1.5 * a0, 1.5 * af0, edp=16.0))      # twice the pressure: twice the bounds
    assert not soft_corner(case(2.1 * a0, 1.5 * af0, edp=16.0))
    box = case(0.05, 0.05)
    box["material"] = {"law": "neo_hookean", "mu": 1.0}
    assert soft_corner(box) == ""   # another law: never in it


def test_the_simulators_warm_solve_reports_how_each_point_was_solved(monkeypatch):
    """evaluate_warm is the one guarded warm solve (campaign rows, subject runs, warm batches): a point in the
    soft corner is solved cold at once; a suspect warm path is re-solved cold and its state marked suspect, so
    a point started from that state is re-solved too (and passes nothing on); every result equals the cold one."""
    from lvcore.execution import chains
    from lvcore.mechanics import forward as F

    fwd = F.SimulatorForward(resolution="fast")
    near = dict(zip(THETA_NAMES, THETA * 1.05))
    cold = fwd.evaluate_warm(dict(zip(THETA_NAMES, THETA)))
    assert cold.start == F.COLD and cold.why == "" and not cold.state.suspect
    ref = fwd.evaluate({k: [v] for k, v in near.items()}).outputs[0]
    warm = fwd.evaluate_warm(near, cold.state)
    assert (warm.start, warm.why) == (F.WARM, "") and warm.batch.messages == ("converged (warm start)",)
    np.testing.assert_allclose(warm.batch.outputs[0], ref, rtol=1e-7, atol=1e-9)
    monkeypatch.setattr(chains, "warm_path_problem", lambda log: "forced by the test")
    flagged = fwd.evaluate_warm(near, cold.state)
    assert (flagged.start, flagged.why, flagged.state.suspect) == (F.RESOLVED, "forced by the test", True)
    np.testing.assert_allclose(flagged.batch.outputs[0], ref, rtol=1e-12, atol=1e-12)
    monkeypatch.setattr(chains, "warm_path_problem", lambda log: "")
    seeded = fwd.evaluate_warm(near, flagged.state._replace(tangent=None))
    assert (seeded.start, seeded.why, seeded.state.suspect) == (F.RESOLVED, chains.SEED_RESOLVED, False)
    monkeypatch.setattr(F, "SOFT_CORNER_KPA", {"a": 10.0, "af": 10.0})   # every point in the corner
    corner = fwd.evaluate_warm(near, cold.state)
    assert corner.start == F.COLD and corner.why.startswith("in the soft corner")
    assert corner.batch.messages == ("converged",)
    np.testing.assert_allclose(corner.batch.outputs[0], ref, rtol=1e-12, atol=1e-12)
