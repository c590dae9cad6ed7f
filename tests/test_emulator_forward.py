"""lvcore.emulator.forward: a trained emulator with conditions bound in, as a traceable forward model."""
import jax
import numpy as np
import pytest

from lvcore.emulator.forward import EmulatorForward, emulator_forward
from lvcore.domain.outputs import THETA_NAMES

THETA = np.array([0.6, 1.3, 1.0, 3.6])


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
