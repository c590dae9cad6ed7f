"""lvcore.app.uploads: per-session upload folders, size limit, messages without server paths."""
from __future__ import annotations

import gc
import tomllib
from pathlib import Path

import pytest

from lvcore.app import uploads
from lvcore.exceptions import LVCoreError
from lvcore.app.uploads import UploadError, UploadSession, fit_segmentation, safe_name, session_uploads

ROOT = Path(__file__).resolve().parents[1]


def test_sessions_have_their_own_folders_and_clean_up():
    a, b = UploadSession(), UploadSession()
    pa = a.save("measured.csv", b"A", slot="measured")
    pb = b.save("measured.csv", b"B", slot="measured")
    assert pa.parent != pb.parent and pa.read_bytes() == b"A" and pb.read_bytes() == b"B"
    folder = a.path
    del a
    gc.collect()
    assert not folder.exists()  # removed with the session
    b.cleanup()
    assert not pb.exists()


def test_session_uploads_lives_in_the_session_state():
    state1, state2 = {}, {}
    s1 = session_uploads(state1)
    assert session_uploads(state1) is s1
    assert session_uploads(state2).path != s1.path


@pytest.mark.parametrize("name, expected", [
    ("../../etc/passwd", "passwd"), ("/abs/path/x.csv", "x.csv"), ("..", "upload"), (".hidden.json", "hidden.json"),
    ("a b\x00c.vtu", "a_b_c.vtu"), ("C:\\Users\\me\\geo.json", "geo.json"),
])
def test_safe_names_stay_in_the_folder(name, expected):
    assert safe_name(name) == expected
    with UploadSession() as s:
        p = s.save(name, b"x")
        assert p.parent == s.path


def test_oversize_uploads_are_refused(monkeypatch):
    monkeypatch.setattr(uploads, "MAX_UPLOAD_MB", 0.001)
    with UploadSession() as s, pytest.raises(UploadError, match="big.csv.*MB"):
        s.save("big.csv", b"x" * 5000)


def test_read_errors_name_the_users_file_not_the_server_path():
    from lvcore.inference.calibrate import read_pc_scores

    with UploadSession() as s:
        with pytest.raises(UploadError) as info:
            s.read("my scores.json", b'{"h": {"h1": {"deep": 1}}}', read_pc_scores, slot="geometry")
        msg = str(info.value)
        assert "my scores.json" in msg and str(s.path) not in msg and "/tmp" not in msg
        assert isinstance(info.value, LVCoreError)


def test_unexpected_reader_errors_become_upload_errors():
    def broken(path):
        raise KeyError(f"internal trouble at {path}")

    with UploadSession() as s, pytest.raises(UploadError, match=r"cannot read 'x.json' \(KeyError") as info:
        s.read("x.json", b"{}", broken)
    assert "/tmp" not in str(info.value)


def test_fit_segmentation_reports_bad_uploads_by_name():
    out = fit_segmentation("contours", (("op1 contours.json", b"[1, 2"),))
    assert "op1 contours.json" in out["error"] and "/tmp" not in out["error"]
    out = fit_segmentation("surfaces", (("endo.stl", b"solid x\nendsolid x\n"), ("epi.stl", b"garbage")))
    assert "error" in out and "/tmp" not in out["error"]


def test_streamlit_config_limits_uploads():
    cfg = tomllib.loads((ROOT / ".streamlit" / "config.toml").read_text())
    assert cfg["server"]["maxUploadSize"] == uploads.MAX_UPLOAD_MB <= 16


def test_lvcore_app_passes_the_upload_limit_to_streamlit():
    from lvcore.app.cli import streamlit_command

    cmd = streamlit_command()
    i = cmd.index("--server.maxUploadSize")
    assert cmd[i + 1] == str(uploads.MAX_UPLOAD_MB)


def test_no_usage_statistics_in_config_and_lvcore_app():
    """Issue 27 item 6: Streamlit's usage statistics are off, so no page reaches an external metrics endpoint."""
    from lvcore.app.cli import streamlit_command

    cfg = tomllib.loads((ROOT / ".streamlit" / "config.toml").read_text())
    assert cfg["browser"]["gatherUsageStats"] is False
    cmd = streamlit_command()
    assert cmd[cmd.index("--browser.gatherUsageStats") + 1] == "false"


# --------------------------------------------------------------------------- messages (issue 27 item 6)
def test_upload_errors_name_the_file_and_say_what_to_do():
    """Garbage .vtu said '(SystemExit: 1)'; garbage .stl was told to use '.stl'; binary text gave codec jargon."""
    out = fit_segmentation("mesh", (("my_lv.vtu", bytes(range(256)) * 3),))["error"]
    assert "my_lv.vtu" in out and "SystemExit" not in out and "not a valid .vtu file" in out
    out = fit_segmentation("surfaces", (("endo.stl", b"solid x\nfacet garbage\n"), ("epi.stl", b"solid x\n")))["error"]
    assert "endo.stl" in out and "not a valid STL file" in out and "export" in out
    assert ".stl," not in out  # not told to use the format it already has
    out = fit_segmentation("surfaces", (("endo.vtk", bytes(range(256)) * 3), ("epi.vtk", b"x")))["error"]
    assert "endo.vtk" in out and "SystemExit" not in out and ": 1)" not in out and "not a valid VTK file" in out
    with uploads.UploadSession() as s:
        with pytest.raises(uploads.UploadError) as info:
            s.read("notes.csv", b"\xff\xfe\x00x", lambda p: p.read_text())
        text = str(info.value)
        assert "notes.csv" in text and "codec" not in text and "UTF-8" in text
        from lvcore.inference.calibrate import read_pc_scores

        with pytest.raises(uploads.UploadError) as info:  # the Calibration page's geometry upload
            s.read("subject.vtu", bytes(range(256)) * 3, read_pc_scores, slot="geometry")
        assert "subject.vtu" in str(info.value) and "SystemExit" not in str(info.value)
        with pytest.raises(uploads.UploadError, match="gave up") as info:
            s.read("x.vtu", b"x", lambda p: (_ for _ in ()).throw(SystemExit(1)))
        assert "x.vtu" in str(info.value)


def test_surface_uploads_that_crashed_vtk_are_errors_naming_the_file():
    import hostile_files as hf

    for name, data, words in (("big.ply", hf.huge_ply(), "1,000,000,000 vertices"),
                              ("face.obj", hf.far_face_obj(), "vertex 1,000,000,000")):
        out = fit_segmentation("surfaces", ((name, data), ("epi" + name[-4:], data)))
        assert name in out["error"] and words in out["error"] and "/tmp" not in out["error"]


def test_an_upload_ten_times_too_large_gets_the_units_warning(tmp_path):
    """A volume mesh in 0.4 mm units (read as mm, the LV is 2.5x too long): the fitted LV is flagged (issue 28)."""
    import meshio

    from lvcore.geometry.analytic import DEFAULT_LV
    from lvcore.geometry.meshing import ellipsoid_tet_mesh

    mm, big = tmp_path / "lv.inp", tmp_path / "lv_big.inp"
    ellipsoid_tet_mesh(DEFAULT_LV, 6.0, mm)
    mesh = meshio.read(mm)
    mesh.points = mesh.points * 2.5
    meshio.write(big, mesh)
    ok = fit_segmentation("mesh", (("lv.inp", mm.read_bytes()),))
    assert not any("units" in w for w in ok["summary"]["warnings"])
    out = fit_segmentation("mesh", (("lv_big.inp", big.read_bytes()),))
    (w,) = [w for w in out["summary"]["warnings"] if "units" in w]
    assert "check the file's units (uploads here are read as mm" in w
