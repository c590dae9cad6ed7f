import os

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import lvcore  # noqa: E402,F401  (turns on float64 before any test makes arrays)
from lvcore.inference.samplers import use_host_devices  # noqa: E402

# As the app and the CLI do: one XLA host device per chain (up to 4), set before JAX starts, so the
# chain method does not depend on which test happens to start JAX first.
use_host_devices(4)


# ----------------------------------------------------------------------------
# Session-scoped fixtures: solved once per test run, shared by the modules that use them.
# Each returns frozen/read-only data; tests must not modify what they get.
# ----------------------------------------------------------------------------
@pytest.fixture(scope="session")
def fast_lv_case():
    """The default LV at the ``fast`` resolution with the population HO parameters (a, b, af, bf) =
    (0.6, 1.3, 1.0, 3.6) kPa / -, EDP 8 mmHg."""
    from lvcore.mechanics.case import Case

    return Case.default_lv({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}, resolution="fast")


@pytest.fixture(scope="session")
def fast_lv_result(fast_lv_case):
    """:func:`simulate` of :func:`fast_lv_case` with adjoint sensitivities (solved once per session)."""
    from lvcore.mechanics.simulate import simulate

    return simulate(fast_lv_case, with_sensitivities=True)
