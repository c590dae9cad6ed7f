"""Load-stepping Newton (lvcore.mechanics.newton): the chord/predictor shortcuts do not change results."""
import numpy as np

from lvcore.mechanics.case import Case
from lvcore.mechanics.newton import NewtonOptions
from lvcore.mechanics.simulate import simulate


def test_chord_iterations_match_full_newton(fast_lv_case):
    case = fast_lv_case
    assert case == Case.default_lv(resolution="fast")
    full = simulate(case, options=NewtonOptions(reuse_ratio=0.0, chord_predictor=False))
    fast = simulate(case)
    assert full.converged and fast.converged
    # every full-Newton iteration takes a tangent; the default reuses factorised tangents
    assert full.timings["tangents"] == full.newton_iterations
    assert fast.timings["tangents"] < full.timings["tangents"]
    np.testing.assert_allclose(fast.outputs(), full.outputs(), rtol=1e-6)
