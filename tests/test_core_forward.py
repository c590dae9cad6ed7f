"""lvcore.core.forward (the protocols) and the forward registry, on every implementation: the simulator
(lvcore.mechanics.forward), the emulator (lvcore.emulator.forward) and the SYNTHETIC stand-in (lvcore.testing)."""
import jax
import numpy as np
import pytest

import lvcore
from lvcore.core import (Forward, ForwardBatch, JacobianForward, TraceableForward, build_case, forward_names,
                         make_forward, register_forward, registered_name)
from lvcore.emulator.forward import EmulatorForward, emulator_forward
from lvcore.exceptions import CampaignError, ForwardError
from lvcore.mechanics.forward import AdjointSimulatorForward, SimulatorForward
from lvcore.outputs import THETA_NAMES
from lvcore.testing.analytic import AnalyticForward

THETA = np.array([0.6, 1.3, 1.0, 3.6])


@pytest.fixture(scope="module")
def sim():
    return AdjointSimulatorForward(resolution="fast")


def test_every_implementation_satisfies_the_protocol(sim):
    from lvcore.emulator import load_emulator

    emu = emulator_forward(load_emulator("chapter"), np.zeros(5))
    for f in (sim, emu, AnalyticForward()):
        assert isinstance(f, Forward)
        assert f.input_names == THETA_NAMES
    # capabilities are types, not flags
    assert isinstance(sim, JacobianForward) and not isinstance(sim, TraceableForward)
    assert isinstance(emu, TraceableForward) and isinstance(AnalyticForward(), TraceableForward)
    plain = SimulatorForward(input_names=THETA_NAMES + ("alpha_endo",))
    assert isinstance(plain, Forward) and not isinstance(plain, JacobianForward)
    with pytest.raises(ForwardError, match="adjoint Jacobian covers"):
        AdjointSimulatorForward(input_names=THETA_NAMES + ("alpha_endo",))
    x = np.array([[0.6, 1.3, 1.0, 3.6], [1.0, 2.0, 1.5, 4.0]])
    np.testing.assert_allclose(np.asarray(emu.apply(x)), emu.evaluate(dict(zip(THETA_NAMES, x.T))).outputs,
                               rtol=1e-12)


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


def test_emulator_forward_on_the_bundled_chapter_emulator():
    from lvcore.emulator import load_emulator

    emu = load_emulator("chapter")
    h = np.array([0.5, -0.4, 0.3, -0.2, 0.1])
    fwd = emulator_forward(emu, h)
    pts = np.array([THETA, [1.0, 5.0, 2.0, 6.0], [0.3, 10.0, 0.5, 2.0]])
    batch = fwd.jacobian(dict(zip(THETA_NAMES, pts.T)))
    direct = np.asarray(emu.predict(a=pts[:, 0], b=pts[:, 1], af=pts[:, 2], bf=pts[:, 3],
                                    **{f"h{i + 1}": h[i] for i in range(5)}))
    np.testing.assert_allclose(batch.outputs, direct, rtol=1e-12)
    assert batch.converged.all()
    # the Jacobian is JAX's derivative of the same function
    g = jax.grad(lambda a: fwd({"a": a, "b": 5.0, "af": 2.0, "bf": 6.0})[0])(1.0)
    assert float(g) == pytest.approx(batch.jacobian[1, 0, 0], rel=1e-10)
    assert fwd.input_bounds == {n: (float(emu.lower[i]), float(emu.upper[i])) for i, n in enumerate(THETA_NAMES)}


def test_emulator_forward_refuses_objects_that_are_not_emulators():
    from lvcore.exceptions import EmulatorError

    with pytest.raises(EmulatorError, match="not an emulator"):
        EmulatorForward(lambda x: x, {})


def test_analytic_forward_batch_equals_pointwise_calls():
    f = AnalyticForward(input_names=THETA_NAMES + ("alpha_endo", "alpha_epi"))
    pts = {"a": [0.5, 1.0], "b": 4.0, "af": [1.0, 2.0], "bf": 6.0, "alpha_endo": -50.0, "alpha_epi": [70.0, 40.0]}
    b = f.jacobian(pts)
    for i in range(2):
        p = {k: np.broadcast_to(v, (2,))[i] for k, v in pts.items()}
        np.testing.assert_allclose(b.outputs[i], np.asarray(f(p)), rtol=1e-13)
    assert b.jacobian.shape == (2, 25, 6)


def test_registry_allows_names_only():
    assert "simulator" in forward_names()
    assert registered_name("lvcore:simulate") == "simulator"  # stores written before the registry
    for bad in ("builtins:print", "os:system", "lvcore:simulate_extra", "no-such-forward"):
        with pytest.raises(CampaignError, match="unknown forward model"):
            registered_name(bad)
    with pytest.raises(CampaignError, match="no ':'"):
        register_forward("mod:fn", lambda space, resolution: None)
    from lvcore.campaigns.space import get_space

    space = get_space("material")
    f = make_forward("simulator", space, "fast")
    assert type(f) is SimulatorForward and f.input_names == space.names and f.resolution == "fast"
    assert f.conditions == space.fixed_dict()
    register_forward("test-analytic", lambda space, resolution: AnalyticForward(), overwrite=True)
    assert isinstance(make_forward("test-analytic", space), AnalyticForward)
    register_forward("test-wrong-inputs", lambda space, resolution: AnalyticForward(input_names=("a",)),
                     overwrite=True)
    with pytest.raises(CampaignError, match="does not read the space's inputs"):
        make_forward("test-wrong-inputs", space)


@pytest.mark.slow
def test_simulator_batch_on_a_process_pool_equals_serial(sim):
    """workers=2 runs the batch on lvcore.parallel.LocalExecutor: same numbers as in-process."""
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
