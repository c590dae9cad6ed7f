"""The "My subject" flow (lvcore.app.subject_flow): the same geometry, conditions and checks as the CLI, and a
bundle with every promised file."""
from __future__ import annotations

import json
import zipfile
from io import BytesIO

import numpy as np
import pytest

from lvcore.app import subject_flow as flow
from lvcore.emulator.io import load_emulator
from lvcore.exceptions import LVCoreError
from lvcore.inference import guards
from lvcore.inference.samplers import SamplerConfig
from lvcore.resources import volunteer_files
from lvcore.uploads import UploadError, UploadSession

SUBJECT = "SYNTHETIC_HV3"


@pytest.fixture(scope="module")
def uploads():
    with UploadSession() as session:
        yield session


def test_geometry_upload_reads_like_the_cli(uploads):
    files = volunteer_files(SUBJECT)
    geo = flow.read_geometry(uploads, "my_lv.vtu", files.geometry.read_bytes())
    cli = guards.resolve_geometry(files.geometry, n_pc=5)
    np.testing.assert_allclose(geo.h, cli.h, rtol=0, atol=1e-12)
    assert geo.scale == pytest.approx(cli.scale)
    nodes = flow.geometry_nodes(geo)
    assert nodes.ndim == 2 and nodes.shape[1] == 3 and np.all(np.isfinite(nodes))


def test_a_wrong_upload_names_the_users_file(uploads):
    with pytest.raises(UploadError, match="my_heart.vtu"):
        flow.read_geometry(uploads, "my_heart.vtu", b"this is not a mesh")
    with pytest.raises(UploadError, match="strains.csv"):
        flow.read_data(uploads, "strains.csv", b"lvv_ml,strain_01\n1,2\n")


def test_a_fixed_edp_emulator_refuses_another_edp(uploads):
    files = volunteer_files(SUBJECT)
    geo = flow.read_geometry(uploads, "g.vtu", files.geometry.read_bytes())
    emulator = load_emulator("chapter")
    with pytest.raises(LVCoreError, match="EDP|edp"):
        flow.prepare(emulator, "chapter", geo, edp_mmhg=12.0)


def test_flow_end_to_end_gives_a_complete_bundle(uploads):
    files = volunteer_files(SUBJECT)
    geo = flow.read_geometry(uploads, "g.vtu", files.geometry.read_bytes())
    rows = flow.read_data(uploads, "m.csv", files.measured.read_bytes())
    assert len(rows) == 1
    emulator = load_emulator("chapter")
    prepared = flow.prepare(emulator, "chapter", geo)
    assert prepared.conditions["edp_mmhg"] == pytest.approx(8.0)
    assert not prepared.extrapolating  # HV3 lies inside the box
    config = SamplerConfig(num_warmup=150, num_samples=100, num_chains=1, seed=1)
    runs = flow.calibrate(rows[0].subject, rows[0].y, prepared, ["iid"], config=config)
    assert [r.model for r in runs] == ["iid"]
    settings = {"emulator": "chapter", "edp_mmhg": 8.0, "models": ["iid"], "chains": 1}
    summary = flow.summary_record(rows[0].subject, rows[0].y, geo, prepared, runs, settings)
    assert summary["synthetic"] and summary["conditions"]["edp_mmhg"] == pytest.approx(8.0)
    assert set(summary["models"]["iid"]["posterior"]) >= {"a", "b", "af", "bf"}
    data = flow.bundle(summary, runs, flow.figures(runs, rows[0].y))
    with zipfile.ZipFile(BytesIO(data)) as z:
        names = set(z.namelist())
        stem = "SYNTHETIC-HV3"
        assert {f"{stem}_iid.nc", "settings.json", "summary.json", "summary.html",
                "figures/posterior_predictive.html", "figures/iid_pair.html"} <= names, names
        assert json.loads(z.read("settings.json")) == settings
        page = z.read("summary.html").decode()
        assert "SYNTHETIC" in page and "EDP 8.00 mmHg" in page
        assert json.loads(z.read("summary.json"))["models"]["iid"]["posterior"]["a"]["mean"] > 0


def test_my_subject_page_runs_the_flow_and_offers_the_zip():
    """AppTest: pick the bundled SYNTHETIC example, calibrate (small sampler), get the download."""
    from streamlit.testing.v1 import AppTest

    from lvcore.app import PAGES_DIR

    at = AppTest.from_file(str(PAGES_DIR / "8_My_subject.py"), default_timeout=180).run()
    assert not at.exception
    at.selectbox(key="my_example").select(SUBJECT)
    at.selectbox(key="my_emulator").select("chapter").run()
    assert not at.exception and not at.error, [e.value for e in at.error]
    assert any("cavity" in m.value for m in at.markdown)
    at.number_input(key="my_chains").set_value(1)
    at.number_input(key="my_warmup").set_value(100)
    at.number_input(key="my_draws").set_value(100).run()
    at.button(key="my_run").click().run(timeout=300)
    assert not at.exception and not at.error, [e.value for e in at.error]
    assert "my_subject_run" in at.session_state
    assert at.session_state["my_subject_run"].result["zip"][:2] == b"PK"
    # physiology: the posterior EDV/V0 with its typical range and the assumed EDP (issue 27, item 2)
    assert any("EDP assumed: 8 mmHg" in c.value and "typical EDV/V₀" in c.value for c in at.caption)
    assert any("EDV/V₀ median" in d.value.columns for d in at.dataframe)
    assert any(b.label.startswith("Simulate the EDPVR") for b in at.button)
    # a wrong EDP for the fixed-EDP chapter emulator is refused with a message naming the EDP
    at.selectbox(key="my_emulator").select("chapter")
    at.number_input(key="my_edp").set_value(12.0).run()
    assert any("EDP" in e.value or "edp" in e.value for e in at.error)


def test_a_mm_mesh_uploaded_as_cm_warns_naming_the_units_control(uploads, tmp_path):
    """The app's geometry upload gets the wrong-units warning of the CLI, naming the page's own control."""
    import meshio

    from lvcore.geometry.analytic import DEFAULT_LV
    from lvcore.geometry.meshing import ellipsoid_tet_mesh

    path = tmp_path / "lv.inp"
    ellipsoid_tet_mesh(DEFAULT_LV, 6.0, path)
    mesh = meshio.read(path)
    mesh.points = mesh.points * 0.3  # a 25 mm LV in mm: read as cm it is 255 mm long
    meshio.write(path, mesh)
    assert not any("units" in w for w in flow.read_geometry(uploads, "lv.inp", path.read_bytes()).warnings)
    geo = flow.read_geometry(uploads, "lv.inp", path.read_bytes(), units="cm")
    (w,) = [w for w in geo.warnings if "units" in w]
    assert "check the 'Mesh length units' choice (read as cm" in w and "--geometry-units" not in w


def test_bound_flags_name_a_posterior_piled_on_the_prior_bound():
    """My subject's banner (and summary) carries the verdict's bound flags: a, af at 0.05 were green (issue 27)."""
    from types import SimpleNamespace

    import arviz as az

    prepared = flow.prepare(load_emulator("chapter"), "chapter",
                            SimpleNamespace(h=np.zeros(5), scale=1.0, warnings=[]))
    rng = np.random.default_rng(0)

    def run(a):
        post = {"a": a * np.exp(0.05 * rng.standard_normal((1, 200))), "b": np.full((1, 200), 1.3) + 0.1 * rng.random((1, 200)),
                "af": np.full((1, 200), 1.0) + 0.1 * rng.random((1, 200)), "bf": np.full((1, 200), 3.6) + 0.1 * rng.random((1, 200))}
        return SimpleNamespace(model="iid", result=SimpleNamespace(idata=az.from_dict(posterior=post)))

    flags = flow.bound_flags(run(0.0507), prepared)
    assert any(f.startswith("a: posterior piled on the prior's lower bound 0.05") for f in flags), flags
    assert not any("bound" in f for f in flow.bound_flags(run(0.6), prepared))
