"""lvcore.app.process: the app's one set-up call keeps what the environment says and fills in the rest."""
from __future__ import annotations

import os

import pytest

from lvcore.app import process
from lvcore.execution.parallel import THREAD_VARIABLES


def test_setup_process_pins_threads_without_overriding_the_environment(monkeypatch):
    calls = []
    monkeypatch.setattr("lvcore.inference.samplers.use_host_devices", lambda n: calls.append(n))
    omp, blas = THREAD_VARIABLES[:2]
    monkeypatch.delenv(blas, raising=False)
    monkeypatch.setenv(omp, "3")  # set by the user: kept
    monkeypatch.delenv("VTK_DEFAULT_OPENGL_WINDOW", raising=False)
    process.setup_process()
    assert os.environ[blas] == "1" and os.environ[omp] == "3"
    assert os.environ["VTK_DEFAULT_OPENGL_WINDOW"] == "vtkEGLRenderWindow"
    assert calls == [process.APP_CHAINS]


def test_the_entry_script_calls_it_before_streamlit():
    from lvcore.app import ENTRY

    text = ENTRY.read_text()
    assert text.index("setup_process()") < text.index("import streamlit")


def test_ast_parse_is_serialised_across_threads(monkeypatch):
    """The app serialises ast.parse (CPython 3.11's AST converter keeps its recursion depth per interpreter: two
    threads parsing at once raised 'AST constructor recursion depth mismatch' and stopped the server); idempotent,
    and many threads parsing deep sources at once all succeed."""
    import ast
    import threading

    monkeypatch.setattr(ast, "parse", ast.parse)   # restored after the test
    process.serialise_ast_parse()
    wrapped = ast.parse
    process.serialise_ast_parse()
    assert ast.parse is wrapped and wrapped._lvcore_serialised
    source = "x = " + "(" * 200 + "1" + ")" * 200 + "\n" + "def f():\n    return [i for i in range(3)]\n" * 50
    errors = []

    def work():
        try:
            for _ in range(30):
                ast.parse(source)
        except Exception as err:  # noqa: BLE001 - collected for the assertion
            errors.append(repr(err))

    threads = [threading.Thread(target=work) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors[:2]
    assert isinstance(ast.parse("a = 1"), ast.Module)


def test_the_thread_variables_moved_to_lvcore_parallel():
    with pytest.warns(DeprecationWarning, match="lvcore.execution.parallel.THREAD_VARIABLES"):
        assert process.THREAD_VARIABLES == THREAD_VARIABLES
