"""Uploads in the app under AppTest (browser-free): malformed files on every upload widget show an
error and keep the controls; two sessions keep their own data; messages never show server paths."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from streamlit.testing.v1 import AppTest

from lvcore.app import ENTRY, PAGES_DIR

ROOT = Path(__file__).resolve().parents[1]


def _page(fragment: str) -> str:
    """A page script of the app (``pages/``)."""
    hits = sorted(PAGES_DIR.glob(f"*{fragment}*.py"))
    if hits:
        return str(hits[0])
    raise FileNotFoundError(fragment)


HV1 = [151.802823] + [-0.15] * 24
HEADER = "subject,lvv_ml," + ",".join(f"strain_{k:02d}" for k in range(1, 25))


def _csv(subject: str, lvv: float) -> bytes:
    return (HEADER + "\n" + f"{subject},{lvv}," + ",".join(["-0.15"] * 24) + "\n").encode()


BAD_MEASURED = {
    "binary.csv": b"\x00\x01\xff\xfe\x89PNG",
    "wrong_columns.csv": b"a,b,c\n1,2,3\n",
    "huge_number.csv": HEADER.encode() + b"\nS," + b"9" * 500 + b"," + b",".join([b"-0.1"] * 24) + b"\n",
    "duplicate.csv": _csv("A", 150) + _csv("A", 150).split(b"\n", 1)[1],
}
BAD_GEOMETRY = {
    "nested.json": b'{"h": {"h1": {"h2": 3}}}',
    "deep.json": b"[" * 100_000 + b"]" * 100_000,
    "dup.json": b'{"h": [0, 0, 0, 0, 0], "h": [1, 1, 1, 1, 1]}',
    "garbage.csv": b"\x00\xff,,\n\x01",
    "letters.csv": b"h1,h2,h3,h4,h5\na,b,c,d,e\n",
    "bad.vtu": b"<VTKFile>not really</VTKFile>",
}


@pytest.fixture
def calibration_page(tmp_path, monkeypatch):
    from lvcore.emulator.io import save_emulator
    from test_inference_calibrate import _random_emulator

    save_emulator(_random_emulator(), tmp_path / "chapter")
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))

    def start():
        at = AppTest.from_file(_page("Calibration"), default_timeout=120).run()
        assert not at.exception, at.exception
        at.radio[0].set_value("upload").run()
        assert not at.exception, at.exception
        return at

    return start


def _controls_present(at):
    assert at.file_uploader(key="up_measured") is not None and at.file_uploader(key="up_geometry") is not None
    assert any(b.label == "Run calibration" for b in at.button)
    assert len(at.multiselect) == 1  # the model controls did not vanish


def _no_server_paths(at):
    for e in at.error:
        assert "/tmp" not in e.value and "lvcore_upload_" not in e.value, e.value


def test_malformed_measured_uploads_show_an_error_and_keep_the_controls(calibration_page):
    at = calibration_page()
    for name, content in BAD_MEASURED.items():
        at.file_uploader(key="up_measured").upload(name, content, "text/csv")
        at.run()
        assert not at.exception, (name, at.exception)
        assert at.error and name in at.error[0].value, (name, [e.value for e in at.error])
        _controls_present(at)
        _no_server_paths(at)
        assert at.button[0].disabled


def test_malformed_geometry_uploads_show_an_error_and_keep_the_controls(calibration_page):
    at = calibration_page()
    at.file_uploader(key="up_measured").upload("ok.csv", _csv("S1", 150), "text/csv")
    for name, content in BAD_GEOMETRY.items():
        at.file_uploader(key="up_geometry").upload(name, content, "application/octet-stream")
        at.run()
        assert not at.exception, (name, at.exception)
        assert at.error and any(name in e.value for e in at.error), (name, [e.value for e in at.error])
        _controls_present(at)
        _no_server_paths(at)


def test_two_sessions_keep_their_own_uploads(calibration_page):
    a, b = calibration_page(), calibration_page()
    a.file_uploader(key="up_measured").upload("a.csv", _csv("A", 120), "text/csv")
    a.file_uploader(key="up_geometry").upload("h.json", b'{"h": [0, 0, 0, 0, 0]}', "application/json")
    a.run()
    b.file_uploader(key="up_measured").upload("b.csv", _csv("B", 180), "text/csv")
    b.file_uploader(key="up_geometry").upload("h.json", b'{"h": [1, 0, 0, 0, 0]}', "application/json")
    b.run()
    a.run()
    assert not a.exception and not b.exception
    folder_a, folder_b = a.session_state["_lvcore_uploads"].path, b.session_state["_lvcore_uploads"].path
    assert folder_a != folder_b
    assert (folder_a / "measured.csv").read_bytes() == _csv("A", 120)
    assert (folder_b / "measured.csv").read_bytes() == _csv("B", 180)
    assert any("LVV = 120.0" in m.value for m in a.markdown)
    assert any("LVV = 180.0" in m.value for m in b.markdown)


def _stand_in_calibration(monkeypatch, seen: list | None = None, delay_s: float = 0.0) -> None:
    """Replace the sampler by a stand-in whose posterior of ``a`` is the measured LVV (records it in ``seen``)."""
    import arviz as az
    import pandas as pd

    from lvcore.inference import calibrate as cal
    from lvcore.inference.diagnostics import Convergence

    conv = Convergence(converged=True, max_rhat=1.0, min_ess_bulk=4000.0, min_ess_tail=4000.0, n_divergent=0,
                       failing=())  # a clean run, so the page renders its whole results block

    def stand_in(y, forward, model, **kw):
        if seen is not None:
            seen.append(float(y[0]))
        time.sleep(delay_s)
        idata = az.from_dict(posterior={"a": np.full((1, 20), y[0])}, observed_data={"y": np.asarray(y)})
        return cal.CalibrationResult(model, "nuts", idata, conv, pd.DataFrame({"mean": [y[0]]}, index=["a"]), 0.5,
                                     {"min": 1.0})

    monkeypatch.setattr(cal, "calibrate", stand_in)


def test_two_sessions_calibrating_at_once_keep_their_own_data(calibration_page, monkeypatch):
    """Both sessions start a (stand-in) calibration; each result is computed from its own upload."""
    seen = []
    _stand_in_calibration(monkeypatch, seen, delay_s=0.5)  # overlap the two runs
    sessions = {}
    for lvv in (120.0, 180.0):
        at = calibration_page()
        at.file_uploader(key="up_measured").upload("m.csv", _csv(f"S{int(lvv)}", lvv), "text/csv")
        at.file_uploader(key="up_geometry").upload("h.json", b'{"h": [0, 0, 0, 0, 0]}', "application/json")
        at.run()
        at.multiselect[0].set_value(["volume"]).run()
        sessions[lvv] = at
    for at in sessions.values():  # start both before either finishes
        at.button[0].click().run(timeout=60)
    deadline = time.time() + 60
    while time.time() < deadline and not all(at.session_state["calibration_job"]["done"]
                                              for at in sessions.values()):
        time.sleep(0.2)
    assert sorted(seen) == [120.0, 180.0]
    for lvv, at in sessions.items():
        job = at.session_state["calibration_job"]
        assert job["done"] and not job["error"], job["error"]
        assert job["subject"] == f"S{int(lvv)}" and float(job["y"][0]) == lvv
        assert float(job["results"]["volume"].summary["mean"].iloc[0]) == lvv


# --------------------------------------------------------------------------- Geometry & operators page
def test_geometry_page_malformed_uploads_show_errors_and_keep_the_controls():
    at = AppTest.from_file(_page("Geometry"), default_timeout=120).run()
    at.radio[0].set_value("Upload my own").run()
    at.file_uploader(key="c0").upload("deep.json", b"[" * 100_000 + b"]" * 100_000, "application/json")
    at.file_uploader(key="c1").upload("types.json", b'{"units": ["mm"], "slices": []}', "application/json")
    at.file_uploader(key="e2").upload("endo.stl", b"solid x\nfacet garbage\n", "application/octet-stream")
    at.file_uploader(key="p2").upload("epi.stl", b"\x00\x01\x02", "application/octet-stream")
    at.run()
    assert not at.exception, at.exception
    messages = [e.value for e in at.error]
    assert len(messages) == 3, messages
    for name in ("deep.json", "types.json"):
        assert any(name in m for m in messages), (name, messages)
    for m in messages:
        assert "/tmp" not in m and "lvcore_upload_" not in m, m
    for i in range(3):  # every upload widget is still there
        for kind in "cep":
            assert at.file_uploader(key=f"{kind}{i}") is not None


# --------------------------------------------------------------------------- the case box of the entry page
def test_case_box_applies_the_case_file_limits(tmp_path):
    import json

    import hostile_files as hf
    from lvcore.geometry.shape_model import BUNDLED_MODEL

    # a shape model whose .npz declares a 37 GB array (a traceback in the box before issue 28); refused by its header
    (tmp_path / "m.json").write_text(BUNDLED_MODEL.with_suffix(".json").read_text())
    (tmp_path / "m.npz").write_bytes(hf.npz_of({"mean": hf.npy_header(hf.HUGE_SHAPE)}))
    pca_case = json.dumps({"geometry": {"kind": "pca", "scores": [0.0], "model": str(tmp_path / "m.npz")},
                           "material": {"law": "neo-hookean", "mu": 1}, "load": {"pressure": 1, "units": "kPa"}})
    at = AppTest.from_file(str(ENTRY), default_timeout=180).run()  # the entry; its home page has the box
    runner_key = "FormSubmitter:case_runner-Run case"
    for text, fragment in (
        (pca_case, "MAX_ARRAY_BYTES"),
        ('{"geometry": {"kind": "default", "resolution": {"circumferential": 100, "longitudinal": 100, '
         '"transmural": 10}}, "material": {"law": "neo-hookean", "mu": 1}, "load": {"pressure": 1, "units": "kPa"}}',
         "limit"),
        ('{"geometry": {"kind": "mesh", "path": "/dev/zero"}, "material": {"law": "neo-hookean", "mu": 1}, '
         '"load": {"pressure": 1, "units": "kPa"}}', "not a regular file"),
        ('{"geometry": {"kind": "default"}, "geometry": {"kind": "default"}}', "duplicate key"),
    ):
        at.text_area[0].set_value(text)
        t0 = time.perf_counter()
        at.form_submit_button(key=runner_key).click().run()
        assert not at.exception, at.exception
        assert at.error and fragment in at.error[0].value, [e.value for e in at.error]
        assert time.perf_counter() - t0 < 30


def test_pc_scores_outside_the_emulator_box_are_flagged_on_the_page(calibration_page, monkeypatch):
    """The CLI refuses scores outside the training box; the page runs but records and shows the extrapolation."""
    _stand_in_calibration(monkeypatch)
    jobs = {}
    for h1 in (0.0, 2.5):
        at = calibration_page()
        at.file_uploader(key="up_measured").upload("m.csv", _csv("S1", 140.0), "text/csv")
        at.file_uploader(key="up_geometry").upload("h.json", f'{{"h": [{h1}, 0, 0, 0, 0]}}'.encode(),
                                                   "application/json")
        at.run()
        at.multiselect[0].set_value(["volume"]).run()
        at.button[0].click().run(timeout=60)
        jobs[h1] = at.session_state["calibration_job"]
    assert jobs[0.0]["extrapolation"] == []
    assert len(jobs[2.5]["extrapolation"]) == 1 and "h1 = 2.5" in jobs[2.5]["extrapolation"][0]


def test_calibration_page_takes_the_edp_from_the_data_and_shows_it(calibration_page, monkeypatch):
    """edp_mmhg in the upload: used and recorded (8 with the fixed-EDP 'chapter'); a different one is refused."""
    # the stand-in outlasts the click's rerun: this test checks what the job records when it starts, not the results
    # block (a stand-in posterior is too thin for it, and a fast machine could finish first)
    _stand_in_calibration(monkeypatch, delay_s=5.0)
    for edp, ok in ((8.0, True), (11.0, False)):
        at = calibration_page()
        csv = (HEADER + ",edp_mmhg\nS1,140," + ",".join(["-0.15"] * 24) + f",{edp}\n").encode()
        at.file_uploader(key="up_measured").upload("m.csv", csv, "text/csv")
        at.file_uploader(key="up_geometry").upload("h.json", b'{"h": [0, 0, 0, 0, 0]}', "application/json")
        at.run()
        at.multiselect[0].set_value(["volume"]).run()
        at.button[0].click().run(timeout=60)
        assert not at.exception, at.exception
        if ok:
            job = at.session_state["calibration_job"]
            assert job["edp_mmhg"] == 8.0 and job["edp_source"] == "data (edp_mmhg)"
        else:
            assert any("edp_mmhg = 11" in e.value for e in at.error), [e.value for e in at.error]


# --------------------------------------------------------------------------- files that crashed VTK (issue 28)
def test_uploads_that_crashed_the_server_show_an_error_and_the_server_lives():
    """A 169-byte PLY declaring 10^9 vertices (SIGABRT) and a 33-byte OBJ with face index 10^9 (SIGSEGV) killed
    the Streamlit server process for every user. AppTest runs the page in this process: it must survive, show
    st.error naming each file, and keep serving the page."""
    import os

    import hostile_files as hf

    pid = os.getpid()
    at = AppTest.from_file(_page("Geometry"), default_timeout=120).run()
    at.radio[0].set_value("Upload my own").run()
    at.file_uploader(key="e0").upload("crash.ply", hf.huge_ply(), "application/octet-stream")
    at.file_uploader(key="p0").upload("epi.ply", hf.huge_ply(), "application/octet-stream")
    at.file_uploader(key="e1").upload("crash.obj", hf.far_face_obj(), "application/octet-stream")
    at.file_uploader(key="p1").upload("epi.obj", hf.far_face_obj(), "application/octet-stream")
    at.run()
    assert os.getpid() == pid and not at.exception, at.exception
    messages = [e.value for e in at.error]
    assert any("crash.ply" in m and "1,000,000,000 vertices" in m for m in messages), messages
    assert any("crash.obj" in m and "vertex 1,000,000,000" in m for m in messages), messages
    at.run()  # the page still runs
    assert not at.exception and at.file_uploader(key="e2") is not None
