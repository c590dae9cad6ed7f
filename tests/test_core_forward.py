"""lvcore.core.forward (the protocols: capabilities are types) and the forward registry, on every implementation."""
import numpy as np
import pytest

from lvcore.core import (Forward, JacobianForward, TraceableForward, forward_names, make_forward, register_forward,
                         registered_name)
from lvcore.emulator.forward import emulator_forward
from lvcore.exceptions import CampaignError, ForwardError
from lvcore.mechanics.forward import AdjointSimulatorForward, SimulatorForward
from lvcore.domain.outputs import THETA_NAMES
from lvcore.testing.analytic import AnalyticForward


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
