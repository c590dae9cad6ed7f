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
    # (a load step cut for an indefinite first tangent took a tangent but no iteration)
    assert full.timings["tangents"] == full.newton_iterations + full.timings.get("indefinite_cuts", 0)
    assert fast.timings["tangents"] < full.timings["tangents"]
    np.testing.assert_allclose(fast.outputs(), full.outputs(), rtol=1e-6)


def test_warm_start_from_nearby_parameters_gives_the_cold_result_with_fewer_iterations(fast_lv_case):
    base = simulate(fast_lv_case)
    stiffer = Case.default_lv({"a": 0.66, "b": 1.3, "af": 1.0, "bf": 3.42}, resolution="fast")
    cold = simulate(stiffer)
    warm = simulate(stiffer, initial=base.solver_state)
    assert cold.converged and warm.converged and warm.message == "converged (warm start)"
    assert warm.load_steps == 1 < cold.load_steps
    assert warm.timings["tangents"] < cold.timings["tangents"]
    np.testing.assert_allclose(warm.outputs(), cold.outputs(), rtol=1e-7, atol=1e-9)
    assert warm.outputs()[0] < base.outputs()[0]  # the state was not just copied: stiffer -> smaller volume


def test_a_poor_warm_start_falls_back_to_load_stepping(fast_lv_case):
    cold = simulate(fast_lv_case)
    u, p = cold.solver_state
    bad = simulate(fast_lv_case, initial=(50.0 * u, p))  # inverts elements: Newton at full load fails
    assert bad.converged and bad.message == "converged" and bad.timings["warm_start"] is False
    np.testing.assert_allclose(bad.outputs(), cold.outputs(), rtol=1e-7, atol=1e-9)
    wrong = simulate(fast_lv_case, initial=(u[:10], p))  # another mesh's state is ignored
    assert wrong.converged and "warm_start" not in wrong.timings
