"""lvcore.app.process: the app's one set-up call keeps what the environment says and fills in the rest."""
from __future__ import annotations

import os

from lvcore.app import process


def test_setup_process_pins_threads_without_overriding_the_environment(monkeypatch):
    calls = []
    monkeypatch.setattr("lvcore.inference.samplers.use_host_devices", lambda n: calls.append(n))
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")  # set by the user: kept
    monkeypatch.delenv("VTK_DEFAULT_OPENGL_WINDOW", raising=False)
    process.setup_process()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "1" and os.environ["OMP_NUM_THREADS"] == "3"
    assert os.environ["VTK_DEFAULT_OPENGL_WINDOW"] == "vtkEGLRenderWindow"
    assert calls == [process.APP_CHAINS]


def test_the_entry_script_calls_it_before_streamlit():
    from lvcore.app import ENTRY

    text = ENTRY.read_text()
    assert text.index("setup_process()") < text.index("import streamlit")
