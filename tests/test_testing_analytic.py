"""lvcore.testing.analytic: the SYNTHETIC closed-form stand-in (tests and benchmarks only)."""
import numpy as np

from lvcore.domain.outputs import THETA_NAMES
from lvcore.testing.analytic import AnalyticForward


def test_analytic_forward_batch_equals_pointwise_calls():
    f = AnalyticForward(input_names=THETA_NAMES + ("alpha_endo", "alpha_epi"))
    pts = {"a": [0.5, 1.0], "b": 4.0, "af": [1.0, 2.0], "bf": 6.0, "alpha_endo": -50.0, "alpha_epi": [70.0, 40.0]}
    b = f.jacobian(pts)
    for i in range(2):
        p = {k: np.broadcast_to(v, (2,))[i] for k, v in pts.items()}
        np.testing.assert_allclose(b.outputs[i], np.asarray(f(p)), rtol=1e-13)
    assert b.jacobian.shape == (2, 25, 6)
