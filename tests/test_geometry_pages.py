"""The Geometry & operators and Shape model pages under Streamlit's AppTest."""
import json
from pathlib import Path

from streamlit.testing.v1 import AppTest

from lvcore.app import PAGES_DIR

ROOT = Path(__file__).resolve().parents[1]
PAGE1 = str(PAGES_DIR / "1_Geometry_and_operators.py")
PAGE2 = str(PAGES_DIR / "2_Shape_model.py")


def test_geometry_page_bundled_patient():
    at = AppTest.from_file(PAGE1, default_timeout=120).run()
    assert not at.exception, at.exception
    assert any("SYNTHETIC" in c.value for c in at.caption)
    assert len(at.get("image")) >= 2  # overlay + distance map
    assert len(at.dataframe) == 2  # volumes/residuals and the MSE matrix
    # the volumes table sits in the narrow right-hand column: one column per operator, so none is clipped
    volumes = at.dataframe[0].value
    assert list(volumes.columns) == ["op1", "op2", "op3"] and "cavity volume (mL)" in volumes.index
    # no None in a table: the base-cut rows of contour stacks (no cut made) are left out, and the caption says why
    assert not volumes.isna().any().any() and "base cut (mm below the base)" not in volumes.index
    assert any(c.value.startswith("Not shown (base cut") and "no base cut was made" in c.value for c in at.caption)
    at.selectbox[0].set_value("SYNTHETIC-P02").run()
    assert not at.exception, at.exception
    assert any("node MSE" in m.label for m in at.metric)
    # MSE in cm² beside distances in mm: the MSE states its RMS distance in mm too (issue 27)
    # one number per metric (the combined "0.0357 cm² = 1.89 mm RMS" was cut off on the page)
    (mse,) = [m for m in at.metric if m.label == "node MSE (cm²)"]
    (rms,) = [m for m in at.metric if m.label == "RMS node distance (mm)"]
    assert float(rms.value) == __import__("pytest").approx(10 * float(mse.value) ** 0.5, abs=0.006)
    assert all(len(m.value) <= 8 for m in at.metric), [m.value for m in at.metric]
    assert any("10·√MSE mm" in c.value for c in at.caption)


def test_geometry_page_upload_messages():
    at = AppTest.from_file(PAGE1, default_timeout=120).run()
    at.radio[0].set_value("Upload my own").run()
    assert not at.exception, at.exception
    assert any("Upload at least one" in i.value for i in at.info)


def test_shape_model_page():
    at = AppTest.from_file(PAGE2, default_timeout=120).run()
    assert not at.exception, at.exception
    assert any("SYNTHETIC" in c.value for c in at.caption)
    assert len(at.get("plotly_chart")) == 2
    assert len(at.get("image")) >= 5  # mean, ±2 SD, original, reconstruction
    at.slider[0].set_value(10).run()
    assert not at.exception, at.exception
    (rec,) = [m for m in at.metric if m.label.startswith("reconstruction error")]
    assert " cm² = " in rec.value and rec.value.endswith(" mm RMS")
    assert any("mm RMS" in c.value for c in at.caption)
    at.radio[0].set_value("op2").run()
    assert not at.exception, at.exception


def test_geometry_page_upload_good_and_bad_contours():
    example = (ROOT / "examples" / "contours" / "SYNTHETIC_example_contours.json").read_bytes()
    d = json.loads(example)
    d["slices"] = d["slices"][:2]
    at = AppTest.from_file(PAGE1, default_timeout=120).run()
    at.radio[0].set_value("Upload my own").run()
    at.file_uploader(key="c0").upload("good.json", example, "application/json")
    at.file_uploader(key="c1").upload("bad.json", json.dumps(d).encode(), "application/json")
    at.run()
    assert not at.exception, at.exception
    assert any("at least 4" in e.value for e in at.error)
    assert any("fitted: residual" in s.value for s in at.success)
    assert len(at.get("image")) >= 1


def test_geometry_page_upload_volume_mesh(tmp_path):
    """A volumetric tetrahedral mesh (ABAQUS .inp) is accepted and fitted like surfaces."""
    from lvcore.geometry.analytic import DEFAULT_LV
    from lvcore.geometry.meshing import ellipsoid_tet_mesh

    path = tmp_path / "lv.inp"
    ellipsoid_tet_mesh(DEFAULT_LV, 6.0, path)
    at = AppTest.from_file(PAGE1, default_timeout=180).run()
    at.radio[0].set_value("Upload my own").run()
    at.file_uploader(key="m0").upload("lv.inp", path.read_bytes(), "application/octet-stream")
    at.run()
    assert not at.exception, at.exception
    assert not at.error, [e.value for e in at.error]
    assert any("fitted: residual" in s.value for s in at.success)


def test_geometry_page_upload_surfaces_whose_walls_meet_at_the_base(tmp_path):
    """SYNTHETIC endo/epi surfaces joined at one base ring: fitted, the cut and the volume removed shown."""
    from lvcore.geometry.synthetic_surfaces import synthetic_surface_pair

    endo, epi = synthetic_surface_pair("joined", seed=2, n_phi=48, n_psi=24).save(tmp_path, "stl")
    at = AppTest.from_file(PAGE1, default_timeout=180).run()
    at.radio[0].set_value("Upload my own").run()
    at.file_uploader(key="e0").upload("endo.stl", endo.read_bytes(), "application/octet-stream")
    at.file_uploader(key="p0").upload("epi.stl", epi.read_bytes(), "application/octet-stream")
    at.run()
    assert not at.exception, at.exception
    assert not at.error, [e.value for e in at.error]
    assert any("meet at the base" in w.value for w in at.warning)
    assert any("cavity removed" in w.value for w in at.warning)
    df = at.dataframe[0].value
    assert df.loc["base cut (mm below the base)"].iloc[0] > 0 and df.loc["cavity removed by the cut (mL)"].iloc[0] > 2
