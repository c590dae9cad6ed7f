"""Shared study helpers (lvcore.studies._common)."""
import os
import threading
from pathlib import Path

import plotly.graph_objects as go
import pytest

from lvcore.studies import _common


def test_a_study_figure_is_written_as_html_and_png(tmp_path, monkeypatch):
    """The real export (kaleido and Debian's chromium; CI installs both): a valid PNG beside the HTML."""
    from lvcore.report import export

    problem = export.static_export_problem()
    if problem:
        if os.environ.get("CI"):
            pytest.fail(f"static export cannot run in CI: {problem}")
        pytest.skip(problem)
    monkeypatch.delenv("LVCORE_NO_PNG", raising=False)
    paths = _common.save_figure(go.Figure(go.Scatter(x=[0, 1], y=[1, 2])), tmp_path / "fig")
    assert paths == [str(tmp_path / "fig.html"), str(tmp_path / "fig.png")]
    assert Path(paths[1]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_hung_png_export_is_abandoned_and_the_html_kept(tmp_path, monkeypatch):
    release = threading.Event()
    monkeypatch.setattr(_common, "PNG_TIMEOUT_S", 0.5)
    monkeypatch.delenv("LVCORE_NO_PNG", raising=False)
    monkeypatch.setattr(go.Figure, "write_image", lambda self, *a, **k: release.wait(30))  # a Chrome that never answers
    with pytest.warns(RuntimeWarning, match="no answer"):
        paths = _common.save_figure(go.Figure(), tmp_path / "fig")
    release.set()
    assert paths == [str(tmp_path / "fig.html")] and (tmp_path / "fig.html").is_file()


def test_a_failing_png_export_keeps_the_html(tmp_path, monkeypatch):
    monkeypatch.delenv("LVCORE_NO_PNG", raising=False)

    def broken(self, *a, **k):
        raise RuntimeError("no Chrome")

    monkeypatch.setattr(go.Figure, "write_image", broken)
    assert _common.save_figure(go.Figure(), tmp_path / "fig") == [str(tmp_path / "fig.html")]


def test_command_line_helpers(capsys):
    """The simulator options (their defaults and the workers' bound), comma lists and the JSON/text result."""
    import argparse
    import json

    parser = argparse.ArgumentParser()
    _common.add_simulator_options(parser)
    args = parser.parse_args([])
    assert (args.workers, args.scheduler, args.resolution) == (1, None, "default")
    assert parser.parse_args(["--workers", "2", "--resolution", "coarse"]).workers == 2
    with pytest.raises(SystemExit):
        parser.parse_args(["--workers", "0"])
    assert all("default" in a.help for a in parser._actions if a.option_strings and a.dest != "help")
    assert _common.comma_list(" a,,b , ") == ["a", "b"] and _common.comma_list(None) == []
    assert _common.print_result(True, {"x": [1, None]}, lambda: "never") == 0
    assert json.loads(capsys.readouterr().out) == {"x": [1, None]}
    assert _common.print_result(False, {"x": 1}, lambda: "line one\nline two") == 0
    assert capsys.readouterr().out == "line one\nline two\n"


def test_study_executor_is_none_in_process_and_closed_after_use(monkeypatch):
    """No executor for one worker or a local forward model; otherwise make_executor's, closed on leaving (pending
    tasks cancelled only after an error)."""
    import lvcore.execution.parallel

    made = []

    class Fake:
        def __init__(self, workers=None, scheduler=None):
            self.args, self.closed = (workers, scheduler), None
            made.append(self)

        def __enter__(self):
            return self

        def __exit__(self, exc_type, *exc):
            self.closed = "cancel" if exc_type is not None else "done"

    monkeypatch.setattr(lvcore.execution.parallel, "make_executor", Fake)
    for workers, scheduler, local in ((1, None, False), (4, None, True), (2, "tcp://x:1", True)):
        with _common.study_executor(workers, scheduler, local=local) as ex:
            assert ex is None
    assert not made
    with _common.study_executor(2, None) as ex:
        assert ex.args == (2, None)
    with pytest.raises(RuntimeError), _common.study_executor(1, "tcp://x:1") as ex:
        raise RuntimeError("a run failed")
    assert [(m.args, m.closed) for m in made] == [((2, None), "done"), ((1, "tcp://x:1"), "cancel")]
