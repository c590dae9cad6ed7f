import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

import lvcore  # noqa: E402,F401  (turns on float64 before any test makes arrays)
from lvcore.inference.samplers import use_host_devices  # noqa: E402

# As the app and the CLI do: one XLA host device per chain (up to 4), set before JAX starts, so the
# chain method does not depend on which test happens to start JAX first.
use_host_devices(4)
