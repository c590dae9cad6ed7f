"""One calibration request (lvcore.inference.request): ``lvcore calibrate``, the Calibration page and the My subject
flow build the same request for the same inputs, and refuse the same bad input with the same message."""
from __future__ import annotations

import time

import numpy as np
import pytest
from streamlit.testing.v1 import AppTest

from lvcore.app import subject_flow as flow
from lvcore.cli import build_parser, main
from lvcore.emulator.io import load_emulator
from lvcore.exceptions import LVCoreError
from lvcore.inference import cli, guards
from lvcore.inference.request import INFER, CalibrationRequest, build_request
from lvcore.resources import volunteer_files
from lvcore.app.uploads import UploadSession

from test_app_uploads import HEADER, _page, _stand_in_calibration

SUBJECT = "SYNTHETIC_HV3"
THETA = {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}


@pytest.fixture(scope="module")
def uploads():
    with UploadSession() as session:
        yield session


def _cli_request(argv) -> CalibrationRequest:
    (request,) = cli.prepare_run(build_parser().parse_args(["calibrate", *argv])).requests.values()
    return request


def _same(a: CalibrationRequest, b: CalibrationRequest, *, source: bool = True) -> None:
    """Every recorded field equal (the geometry's file name only if ``source``), and the same forward model: the
    same outputs and representation floor at a θ inside the prior (an inferred geometry at the mean shape)."""
    ra, rb = a.record(), b.record()
    if not source:   # an upload is read from the session's copy of the file: another path, the same contents
        ra["geometry"].pop("source"), rb["geometry"].pop("source")
    assert ra == rb
    params = {**THETA, **{n: 0.0 for n in getattr(a.forward, "pc_names", ())}}
    if a.inferred:
        params["scale"] = 1.0
    np.testing.assert_array_equal(np.asarray(a.forward(params)), np.asarray(b.forward(params)))
    assert type(a.forward) is type(b.forward)
    assert a.bounds == b.bounds


def _page_request(monkeypatch, name: str) -> CalibrationRequest:
    """The request the Calibration page makes on "Run calibration" for the bundled volunteer ``name`` ('chapter',
    volume likelihood; the sampler and the verdict's best fit are stand-ins: only the set-up is compared)."""
    from lvcore.inference import verdict

    _stand_in_calibration(monkeypatch)
    monkeypatch.setattr(verdict, "consistency_check", lambda *a, **k: None)
    at = AppTest.from_file(_page("Calibration"), default_timeout=120).run()
    assert not at.exception, at.exception
    next(s for s in at.selectbox if s.label == "Volunteer").select(name)
    next(s for s in at.selectbox if s.label == "Emulator").select("chapter")
    at.multiselect[0].set_value(["volume"]).run()
    at.button[0].click().run(timeout=120)
    assert not at.exception and not at.error, [e.value for e in at.error]
    job = at.session_state["calibration_job"]
    deadline = time.time() + 60   # the page's worker thread ends before the stand-ins are undone
    while not job["done"] and time.time() < deadline:
        time.sleep(0.1)
    assert job["done"] and not job["error"], job["error"]
    return job["request"]


def test_cli_page_and_flow_make_one_request(uploads, monkeypatch):
    """A bundled volunteer's mesh with the 'chapter' emulator: the CLI (its --allow-extrapolation: the pages run
    outside the box, flagged), the Calibration page and the My subject flow (the same files uploaded) give one
    request: conditions, box, warnings, geometry record with its representation floor, verdict inputs, forward."""
    files = volunteer_files(SUBJECT)
    cli_req = _cli_request(["--volunteer", SUBJECT, "--allow-extrapolation"])
    assert cli_req.geometry_record["representation_error"]["mode"] == "floor"   # a mesh: the floor is on
    page_req = _page_request(monkeypatch, SUBJECT)
    _same(cli_req, page_req)
    (row,) = flow.read_data(uploads, "m.csv", files.measured.read_bytes())
    geo = flow.read_geometry(uploads, "g.vtu", files.geometry.read_bytes())
    flow_req = flow.prepare(load_emulator("chapter"), "chapter", geo, row=row)
    _same(cli_req, flow_req, source=False)


def test_cli_and_flow_make_one_inferred_request(uploads):
    """The no-mesh route: --geometry infer --reference-volume and the My subject flow's measures give one request
    (the Calibration page has no no-mesh route)."""
    files = volunteer_files(SUBJECT)
    cli_req = _cli_request(["--data", str(files.measured), "--geometry", "infer", "--reference-volume", "110",
                            "--reference-volume-sd", "4", "--allow-extrapolation"])
    (row,) = flow.read_data(uploads, "m.csv", files.measured.read_bytes())
    measures = flow.inferred_measures({"reference_volume_ml": 110.0}, row.measures)
    sds, sources = flow.inferred_measure_sds({"reference_volume_ml": 4.0}, row.measure_sds, measures)
    flow_req = flow.prepare_inferred(load_emulator("chapter"), "chapter", measures, measure_sd=sds,
                                     measure_sd_source=sources, row=row)
    assert cli_req.inferred and cli_req.geometry_record["likelihood_sd"]["reference_volume_ml"] > 4.0
    # where the sd came from is said in each front end's words: an option, a field
    assert cli_req.geometry_record["measure_sd_source"] == {"reference_volume_ml": "--reference-volume-sd"}
    assert flow_req.geometry_record["measure_sd_source"] == {"reference_volume_ml": "entered"}
    cli_req.geometry_record["measure_sd_source"] = flow_req.geometry_record["measure_sd_source"]
    _same(cli_req, flow_req)


def _measured_csv(tmp_path, states) -> bytes:
    """One subject S1 (SYNTHETIC_HV2's data) with one row per EDP in ``states``."""
    from lvcore.inference.data import read_measured_csv

    y = read_measured_csv(volunteer_files("SYNTHETIC_HV2").measured)[0].y
    lines = [HEADER + ",edp_mmhg"] + [f"S1,{y[0] * (1 + 0.02 * k)}," + ",".join(map(str, y[1:])) + f",{edp}"
                                      for k, edp in enumerate(states)]
    data = ("\n".join(lines) + "\n").encode()
    (tmp_path / "measured.csv").write_bytes(data)   # the name the page's upload slot gives it
    return data


SCORES = b'{"h": [0, 0, 0, 0, 0]}'


@pytest.mark.parametrize("states, fragment", [
    ((11.0,), "edp_mmhg = 11 in the data, but the 'chapter' emulator was trained at a fixed EDP of 8 mmHg"),
    ((8.0, 14.0), "measured.csv: subject 'S1' has 2 loaded states, which needs an emulator with an EDP input"),
], ids=["data-edp", "loaded-states"])
def test_bad_input_gets_one_message_in_all_three(uploads, tmp_path, capsys, monkeypatch, states, fragment):
    """An EDP in the data that the fixed-EDP 'chapter' emulator cannot honour, and loaded states it cannot take:
    the CLI exits 2, the Calibration page shows an error and the My subject flow raises, each with one message."""
    data = _measured_csv(tmp_path, states)
    (tmp_path / "h.json").write_bytes(SCORES)
    code = main(["calibrate", "--data", str(tmp_path / "measured.csv"), "--geometry", str(tmp_path / "h.json"),
                 "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and fragment in err, err
    (message,) = [ln.removeprefix("lvcore: error: ") for ln in err.splitlines() if ln.startswith("lvcore: error: ")]

    (row,) = flow.read_data(uploads, "measured.csv", data)
    with pytest.raises(LVCoreError) as caught:
        flow.prepare(load_emulator("chapter"), "chapter", flow.read_geometry(uploads, "h.json", SCORES), row=row)
    assert str(caught.value) == message

    _stand_in_calibration(monkeypatch)
    at = AppTest.from_file(_page("Calibration"), default_timeout=120).run()
    at.radio[0].set_value("upload").run()
    at.file_uploader(key="up_measured").upload("measured.csv", data, "text/csv")
    at.file_uploader(key="up_geometry").upload("h.json", SCORES, "application/json")
    next(s for s in at.selectbox if s.label == "Emulator").select("chapter")
    at.multiselect[0].set_value(["volume"]).run()
    at.button[0].click().run(timeout=60)
    assert not at.exception, at.exception
    assert message in [e.value for e in at.error], [e.value for e in at.error]
    assert "calibration_job" not in at.session_state   # nothing started


def test_the_builder_refuses_what_it_cannot_build():
    """No geometry for a shape-model emulator, an inferred geometry for a subject emulator, an unknown prior or
    floor mode: each refused naming what to give."""
    from types import SimpleNamespace

    from lvcore.exceptions import DataError, EmulatorError

    emulator = load_emulator("chapter")
    with pytest.raises(DataError, match="no geometry: give the subject's mesh or PC scores"):
        build_request(emulator, "chapter", None)
    with pytest.raises(EmulatorError, match="subject-specific: its geometry is bound in"):
        build_request(SimpleNamespace(is_subject=True), "subject-x", INFER)
    with pytest.raises(DataError, match="prior 'flat': choose from none, klotz"):
        build_request(emulator, "chapter", guards.GeometrySource(np.zeros(5), "mean", "mean"), prior="flat")
    with pytest.raises(ValueError, match="'floor' or 'off'"):
        build_request(emulator, "chapter", INFER, representation_error="on")


def test_a_request_without_data_has_no_fit_check():
    """The My subject page prepares before the data are read: the request has no y, and its fit check says so."""
    from lvcore.exceptions import DataError

    request = build_request(load_emulator("chapter"), "chapter", guards.GeometrySource(np.zeros(5), "mean", "mean"))
    assert request.subject is None and request.y is None and request.edp_source == "fixed by the emulator"
    assert request.representation_error is None   # PC scores and the mean shape never get a floor
    with pytest.raises(DataError, match="no measurements"):
        request.consistency()


def test_the_pages_load_an_emulator_again_when_its_files_change(tmp_path, monkeypatch):
    """The app's emulator cache is keyed by the files behind a name: another LVCORE_EMULATORS folder (as a test
    with a stand-in emulator of the same name leaves behind) or a rebuilt emulator is loaded again, not served
    from the cache (a stale 'chapter' once gave a later request the wrong base condition)."""
    from test_inference_calibrate import _random_emulator

    from lvcore.app.emulators import cached_emulator
    from lvcore.emulator.io import emulator_identity, save_emulator

    real = cached_emulator("chapter")
    assert cached_emulator("chapter") is real   # cached
    save_emulator(_random_emulator(), tmp_path / "chapter")
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))
    stand_in = cached_emulator("chapter")
    assert stand_in is not real and emulator_identity("chapter")[0] == str((tmp_path / "chapter").resolve())
    monkeypatch.delenv("LVCORE_EMULATORS")
    assert cached_emulator("chapter") is real
    assert emulator_identity("no-such-emulator") == ("", 0)
