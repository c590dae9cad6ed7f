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
from lvcore.app.uploads import UploadError, UploadSession

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
    # a mesh gets the CLI's representation-error floor (lvcore calibrate --geometry MESH)
    assert summary["geometry"]["kind"] == "template-mesh"
    assert summary["geometry"]["representation_error"]["mode"] == "floor"
    assert flow.prepare(emulator, "chapter", geo, representation_error="off").representation_error is None
    data = flow.bundle(summary, runs, flow.figures(runs, rows[0].y))
    with zipfile.ZipFile(BytesIO(data)) as z:
        names = set(z.namelist())
        stem = "SYNTHETIC-HV3"
        assert {f"{stem}_iid.nc", "settings.json", "summary.json", "summary.html",
                "figures/posterior_predictive.html", "figures/iid_pair.html"} <= names, names
        assert json.loads(z.read("settings.json")) == settings
        page = z.read("summary.html").decode()
        assert "SYNTHETIC" in page and "EDP 8.00 mmHg" in page
        assert "q05 (90 % equal-tailed interval)" in page and "hdi" not in page
        assert "null" not in page and ">None<" not in page  # settings in words
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
    # the example's mesh is seen through its projection: the floor, scaled to its own projection error
    assert any(c.value.startswith("Representation-error floor: on") and "projection error" in c.value
               for c in at.caption), [c.value for c in at.caption]
    # test_flow_end_to_end_gives_a_complete_bundle's sampler settings (its seed aside): the sampler it compiled
    # for this mesh and emulator is reused, not compiled again for other shapes
    at.number_input(key="my_chains").set_value(1)
    at.number_input(key="my_warmup").set_value(150)
    at.number_input(key="my_draws").set_value(100).run()
    at.button(key="my_run").click().run(timeout=300)
    assert not at.exception and not at.error, [e.value for e in at.error]
    assert "my_subject_run" in at.session_state
    assert at.session_state["my_subject_run"].result["zip"][:2] == b"PK"
    # physiology: the posterior EDV/V0 with its typical range and the assumed EDP (issue 27, item 2)
    assert any("EDP assumed: 8 mmHg" in c.value and "typical EDV/V₀" in c.value for c in at.caption)
    assert any("EDV/V₀ median" in d.value.columns for d in at.dataframe)
    assert any(b.label.startswith("Compute the EDPVR") for b in at.button)
    # the conditions are the emulator's own, with the reason (the Simulator's default angles differ)
    (cond,) = [c.value for c in at.caption if c.value.startswith("Conditions used:")]
    assert "fibre angles -60° / 60°, the 'chapter' emulator's own: it was trained at these angles" in cond
    assert "the Simulator's default is -60° / 90°" in cond
    # the posterior table: the 90 % equal-tailed interval in its headers, help on each ArviZ diagnostic, no None
    (summary,) = [d for d in at.dataframe if "r_hat" in d.value.columns]
    config = json.loads(summary.proto.columns)
    assert config["q05"]["label"] == "q05 (90 % equal-tailed interval)" and "hdi_5%" not in summary.value.columns
    assert all(config[c]["help"] for c in ("mcse_mean", "ess_bulk", "ess_tail", "r_hat"))
    for d in at.dataframe:
        assert not d.value.isna().any().any() and "None" not in d.value.astype(str).to_numpy(), d.value
    # each flag once, in the app's words: the banners name no CLI exit code; "Computed with" has no None
    assert not any("exit code" in a.value or "CLI" in a.value for a in list(at.warning) + list(at.success))
    assert not any("None" in c.value for c in at.caption)
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

    prepared = flow.prepare(load_emulator("chapter"), "chapter", guards.GeometrySource(np.zeros(5), "mean", "mean"))
    rng = np.random.default_rng(0)

    def run(a):
        post = {"a": a * np.exp(0.05 * rng.standard_normal((1, 200))), "b": np.full((1, 200), 1.3) + 0.1 * rng.random((1, 200)),
                "af": np.full((1, 200), 1.0) + 0.1 * rng.random((1, 200)), "bf": np.full((1, 200), 3.6) + 0.1 * rng.random((1, 200))}
        return SimpleNamespace(model="iid", result=SimpleNamespace(idata=az.from_dict(posterior=post)))

    flags = flow.bound_flags(run(0.0507), prepared)
    assert any(f.startswith("a: posterior piled on the prior's lower bound 0.05") for f in flags), flags
    assert not any("bound" in f for f in flow.bound_flags(run(0.6), prepared))


# ----------------------------------------------------------------------------- the no-mesh route (issue 27)
def test_inferred_measures_take_the_fields_and_the_data_columns():
    from lvcore.exceptions import DataError

    assert flow.inferred_measures({"reference_volume_ml": 0.0, "wall_volume_ml": None, "long_axis_mm": 0.0}) == {}
    assert flow.inferred_measures({"reference_volume_ml": 120.0}) == {"reference_volume_ml": 120.0}
    assert flow.inferred_measures({"reference_volume_ml": 0.0}, {"reference_volume_ml": 110.0}) == \
        {"reference_volume_ml": 110.0}  # the file's column when the field is left at 0
    with pytest.raises(DataError, match=r"'Reference \(early-diastolic\) cavity volume, mL' = 5 is outside .*10-500 "
                                        r"mL; enter it in mL"):
        flow.inferred_measures({"reference_volume_ml": 5.0})
    with pytest.raises(DataError, match="Long axis.* = 900 .*mm"):
        flow.inferred_measures({"long_axis_mm": 900.0})
    with pytest.raises(DataError, match="disagree"):
        flow.inferred_measures({"reference_volume_ml": 120.0}, {"reference_volume_ml": 110.0})


def test_no_mesh_route_is_the_clis_geometry_infer(uploads, tmp_path):
    """prepare_inferred + calibrate give lvcore calibrate --geometry infer --reference-volume's geometry posterior
    (same functions, same seed), the warning without any measure, and a bundle with the inferred geometry."""
    from lvcore.cli import main
    from lvcore.inference.geometry_prior import MEASURE_SD, InferredGeometryForward

    files = volunteer_files(SUBJECT)
    (row,) = flow.read_data(uploads, "m.csv", files.measured.read_bytes())
    geo = flow.read_geometry(uploads, "g.vtu", files.geometry.read_bytes())
    ref = round(flow.geometry_measures(geo)[0]["cavity_volume_ml"], 1)
    emulator = load_emulator("chapter")
    bare = flow.prepare_inferred(emulator, "chapter", {})
    assert bare.inferred and flow.NO_MEASURE_WARNING in bare.warnings
    prepared = flow.prepare_inferred(emulator, "chapter", flow.inferred_measures({"reference_volume_ml": ref}))
    assert isinstance(prepared.forward, InferredGeometryForward)
    assert prepared.forward.measures == {"reference_volume_ml": ref} and flow.NO_MEASURE_WARNING not in prepared.warnings
    assert [b["name"] for b in prepared.box] == []  # chapter fixes EDP and angles: no condition to box-check
    config = SamplerConfig(num_warmup=150, num_samples=100, num_chains=1, seed=0)
    runs = flow.calibrate(row.subject, row.y, prepared, ["iid"], config=config)
    settings = {"geometry": "infer", "measures": {"reference_volume_ml": ref}}
    summary = flow.summary_record(row.subject, row.y, flow.InferredGeometry.of(prepared), prepared, runs, settings)
    post = summary["models"]["iid"]["geometry_posterior"]
    assert {"h1", "h2", "h3", "h4", "h5", "scale", "implied_reference_volume_ml"} <= set(post)
    # the implied reference cavity follows the measured one (observed with SD MEASURE_SD, 5 mL)
    assert abs(post["implied_reference_volume_ml"]["median"] - ref) < 3 * MEASURE_SD["reference_volume_ml"], \
        (post["implied_reference_volume_ml"], ref)
    rc = main(["calibrate", "--data", str(files.measured), "--geometry", "infer", "--reference-volume", str(ref),
               "--model", "iid", "--chains", "1", "--warmup", "150", "--samples", "100", "--seed", "0",
               "--out", str(tmp_path / "cli"), "--json"])
    assert rc in (0, 1, 4)
    cli = json.loads((tmp_path / "cli" / "summary.json").read_text())[0]
    assert cli["geometry"]["kind"] == summary["geometry"]["kind"] == "inferred"
    assert cli["geometry"]["measures"] == summary["geometry"]["measures"]
    # the same sds, the same floor: the app's record is the CLI's
    for k in ("measure_sd", "measure_sd_source", "likelihood_sd", "representation_error"):
        assert summary["geometry"][k] == pytest.approx(cli["geometry"][k]) if k == "likelihood_sd" else \
            summary["geometry"][k] == cli["geometry"][k], k
    assert summary["geometry"]["representation_error"]["mode"] == "floor"
    for name in ("h1", "h5", "scale", "implied_reference_volume_ml"):
        for q in ("median", "q05", "q95"):
            assert post[name][q] == pytest.approx(cli["geometry"]["posterior"][name][q], rel=1e-6, abs=1e-9), name
    assert summary["models"]["iid"]["flags"] == cli["flags"]
    figs = flow.figures(runs, row.y, prepared=prepared)
    assert "iid_geometry" in figs
    rows = flow.geometry_posterior_rows(post)
    assert [r["quantity"] for r in rows][:6] == ["h1", "h2", "h3", "h4", "h5", "scale"]
    assert next(r for r in rows if r["quantity"] == "implied reference_volume_ml")["measured"] == ref
    with zipfile.ZipFile(BytesIO(flow.bundle(summary, runs, figs))) as z:
        assert "figures/iid_geometry.html" in z.namelist()
        assert json.loads(z.read("summary.json"))["models"]["iid"]["geometry_posterior"]["scale"]["median"] > 0
        page = z.read("summary.html").decode()
        assert "inferred (no mesh)" in page and "implied reference_volume_ml" in page


def test_inferred_measure_sds_and_the_record_follow_the_cli():
    """The page's SD fields: 0 is the default, the data's *_sd column is used and must agree, an SD without its
    measure or outside its range is refused; the record carries the sds, their sources and the floor."""
    from lvcore.exceptions import DataError
    from lvcore.inference.geometry_prior import MEASURE_SD

    m = {"reference_volume_ml": 60.0}
    assert flow.inferred_measure_sds({"reference_volume_ml": 0.0}, None, m) == ({}, {})
    assert flow.inferred_measure_sds({"reference_volume_ml": 2.0}, None, m) == (
        {"reference_volume_ml": 2.0}, {"reference_volume_ml": "entered"})
    assert flow.inferred_measure_sds({"reference_volume_ml": 0.0}, {"reference_volume_ml": 3.0}, m) == (
        {"reference_volume_ml": 3.0}, {"reference_volume_ml": "data column reference_volume_ml_sd"})
    with pytest.raises(DataError, match="disagree"):
        flow.inferred_measure_sds({"reference_volume_ml": 2.0}, {"reference_volume_ml": 3.0}, m)
    with pytest.raises(DataError, match=r"SD of 'Reference .* = 0.1 is outside 0.5-50 mL"):
        flow.inferred_measure_sds({"reference_volume_ml": 0.1}, None, m)
    with pytest.raises(DataError, match="not the measure itself"):
        flow.inferred_measure_sds({"long_axis_mm": 2.0}, None, m)
    emulator = load_emulator("chapter")
    p = flow.prepare_inferred(emulator, "chapter", m, measure_sd={"reference_volume_ml": 2.0},
                              measure_sd_source={"reference_volume_ml": "entered"})
    rec = flow.InferredGeometry.of(p).record()
    assert rec["measure_sd"] == {"reference_volume_ml": 2.0} and rec["measure_sd_source"] == {
        "reference_volume_ml": "entered"}
    assert rec["likelihood_sd"]["reference_volume_ml"] > 2.0   # widened by the floor's relative sd
    assert rec["representation_error"]["mode"] == "floor" and rec["representation_error"]["n_cases"] > 0
    off = flow.InferredGeometry.of(flow.prepare_inferred(emulator, "chapter", m, representation_error="off")).record()
    assert off["representation_error"] is None and off["measure_sd"] == {
        "reference_volume_ml": MEASURE_SD["reference_volume_ml"]}
    assert off["likelihood_sd"] == off["measure_sd"] and off["measure_sd_source"] == {"reference_volume_ml": "default"}


def test_a_subject_emulator_has_no_geometry_to_infer():
    from types import SimpleNamespace

    fake = SimpleNamespace(is_subject=True)
    with pytest.raises(LVCoreError, match="subject-specific.*no-mesh"):
        flow.prepare_inferred(fake, "subject-x", {})


def test_my_subject_page_no_mesh_route():
    """AppTest: the no-mesh route needs no geometry file, warns without a measure, and calibrates with the
    reference volume; the results show the inferred geometry's posterior."""
    from streamlit.testing.v1 import AppTest

    from lvcore.app import PAGES_DIR
    from lvcore.inference.geometry_prior import MEASURE_SD

    at = AppTest.from_file(str(PAGES_DIR / "8_My_subject.py"), default_timeout=180).run()
    at.radio(key="my_geometry_mode").set_value("No mesh: infer it from CMR measures").run()
    assert not at.exception and not [u for u in at.get("file_uploader") if u.proto.label.startswith("Geometry")]
    at.selectbox(key="my_example").select(SUBJECT).run()
    assert not at.exception and not at.error, [e.value for e in at.error]
    assert any(w.value == flow.NO_MEASURE_WARNING for w in at.warning)
    at.number_input(key="my_ref_volume").set_value(110.0)
    at.number_input(key="my_chains").set_value(1)
    at.number_input(key="my_warmup").set_value(100)
    at.number_input(key="my_draws").set_value(100).run()
    assert not any(w.value == flow.NO_MEASURE_WARNING for w in at.warning)
    at.button(key="my_run").click().run(timeout=300)
    assert not at.exception and not at.error, [e.value for e in at.error]
    summary = at.session_state["my_subject_run"].result["summary"]
    geo = summary["geometry"]
    assert {k: geo[k] for k in ("kind", "source", "measures", "measure_sd", "measure_sd_source")} == {
        "kind": "inferred", "source": "infer", "measures": {"reference_volume_ml": 110.0},
        "measure_sd": {"reference_volume_ml": MEASURE_SD["reference_volume_ml"]},
        "measure_sd_source": {"reference_volume_ml": "default"}}
    assert geo["representation_error"]["mode"] == "floor"   # the CLI's default, shown on the page
    assert geo["likelihood_sd"]["reference_volume_ml"] > MEASURE_SD["reference_volume_ml"]
    assert any("Inferred geometry" in m.value for m in at.markdown)
    assert any("quantity" in d.value.columns for d in at.dataframe)
    assert "iid_geometry" in at.session_state["my_subject_run"].result["figures"]


# ----------------------------------------------------------------------------- a subject emulator (issue 25 item 2)
def test_subject_build_design_defaults_are_the_clis():
    """The app's build (and its design controls) default to `lvcore emulator build`'s options."""
    from lvcore.cli import build_parser
    from lvcore.emulator.subject import resolve_edpvr

    args = build_parser().parse_args(["emulator", "build", "--geometry", "g.vtu", "--out", "o"])
    build = flow.SubjectBuild("g.vtu", "out")
    assert (build.design.n_train, build.design.n_valid, build.design.n_test, build.design.method) == \
        (args.n_train, args.n_valid, args.n_test, args.design)
    assert (build.workers, build.seed, build.resolution, build.units) == \
        (args.workers, args.seed, args.resolution, args.units)
    assert args.edpvr is None and build.edpvr is resolve_edpvr(args.edpvr, {"kind": "mesh"}) is True  # a mesh: on


def test_build_dir_names_the_geometry_and_design(tmp_path):
    from lvcore.emulator.subject import SubjectDesign

    a = flow.build_dir(b"mesh", "my lv.vtu", root=tmp_path)
    assert a.parent == tmp_path and a.name.startswith("my_lv-")
    assert flow.build_dir(b"mesh", "my lv.vtu", root=tmp_path) == a
    assert flow.build_dir(b"mesh2", "my lv.vtu", root=tmp_path) != a
    assert flow.build_dir(b"mesh", "my lv.vtu", root=tmp_path, design=SubjectDesign(10, 5, 5)) != a
    assert flow.build_dir(b"mesh", "my lv.vtu", root=tmp_path, units="cm") != a
    assert flow.build_dir(b"mesh", "my lv.vtu", root=tmp_path, edpvr=False) == a   # the folders built before
    assert flow.build_dir(b"mesh", "my lv.vtu", root=tmp_path, edpvr=True) != a    # with its EDPVR emulator


def test_held_out_summary_and_the_derived_path_say_whether_a_subject_edpvr_emulator_was_built():
    """A build with --edpvr: its EDPVR emulator's summary in the build's summary (None without); a derived record
    from FE load paths says why, and where the subject emulator lacks one, how to build it from the app."""
    from lvcore.app.physiology_panel import path_reason_text

    edpvr = {"folder": "edpvr", "name": "subject-x-edpvr", "n_test_paths": 32, "log_volume_ratio_rmse_max": 0.004,
             "fibre_stretch_rmse_max": 0.002, "seconds": 150.0}
    assert flow.held_out_summary({"subject": {"edpvr": edpvr}})["edpvr"] == edpvr
    assert flow.held_out_summary({"subject": {}})["edpvr"] is None
    text = path_reason_text({"path": "fe", "path_reason": "a subject emulator's mesh without a subject EDPVR "
                                                          "emulator (x missing; build the subject emulator with --edpvr)"})
    assert text.startswith("The EDPVR and stress here are from FE load paths") and "Also build the EDPVR" in text
    assert "Also build" not in path_reason_text({"path": "fe", "path_reason": "inferred fibre angles"})


@pytest.fixture(scope="module")
def build_cache(tmp_path_factory):
    """The module's folder of subject-emulator builds (the page's ``flow.BUILD_CACHE`` in its test)."""
    return tmp_path_factory.mktemp("subject_builds")


def test_subject_build_runs_stops_keeps_and_resumes(build_cache):
    """SubjectBuild: a stopped build says what to do and keeps the FE runs; the next build resumes from them and
    gives the held-out accuracy; a third finds it in the folder."""
    from lvcore.emulator.subject import RUNS_FILE, SubjectDesign

    geometry = volunteer_files(SUBJECT).geometry
    design = SubjectDesign(8, 3, 3)
    # the folder the My subject page names for this example and design (the page's test below, whose build is this
    # one on the fast mesh, then finds it there instead of running the same 14 FE runs and training again)
    out = flow.build_dir(geometry.read_bytes(), geometry.name, design=design, root=build_cache)
    job = flow.SubjectBuild(geometry, out, design=design, resolution="fast", workers=1, label="hv3.vtu", edpvr=False)
    job.stop()  # before the first batch: nothing done
    job.start(background=False)
    assert job.finished and not job.ok and "No FE run was finished" in job.error
    assert "lvcore emulator build --geometry hv3.vtu" in job.error and "--n-train 8" in job.error
    job = flow.SubjectBuild(geometry, out, design=design, resolution="fast", workers=1, label="hv3.vtu",
                            edpvr=False).start()
    job.join(1500)  # about a minute on a quiet machine
    assert job.finished, f"the build is still running after 1500 s: {job.status()}"
    assert job.ok, job.error
    info = flow.held_out_summary(job.metadata)
    assert info["n_test"] == 3 and info["runs_total"] == 14 and info["lvv_rmse_ml"] > 0
    assert info["geometry_source"] == str(geometry)
    assert not (out / RUNS_FILE).exists()  # the converged rows are in training_data.npz
    again = flow.SubjectBuild(geometry, out, design=design, resolution="fast", workers=1, edpvr=False).start()
    assert again.ok and again.cached and again.metadata["test"] == job.metadata["test"]


def test_my_subject_page_builds_and_uses_a_subject_emulator(build_cache, monkeypatch):
    """AppTest: the build panel (CLI defaults; a small design here, on the fast mesh), its held-out RMSE, the
    emulator offered for calibration, and a calibration with the geometry bound in. After
    test_subject_build_runs_stops_keeps_and_resumes the page's build is found in the module's build folder (that
    test's build, the same design and mesh); run alone, the page builds it."""
    from streamlit.testing.v1 import AppTest

    from lvcore.app import PAGES_DIR

    class SmallBuild(flow.SubjectBuild):  # the page's build on the fast mesh in this process (CI-sized)
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **{**kwargs, "resolution": "fast", "workers": 1})

    monkeypatch.setattr(flow, "SubjectBuild", SmallBuild)
    monkeypatch.setattr(flow, "BUILD_CACHE", build_cache)
    at = AppTest.from_file(str(PAGES_DIR / "8_My_subject.py"), default_timeout=180).run()
    at.selectbox(key="my_example").select(SUBJECT).run()
    assert not at.exception and not at.error, [e.value for e in at.error]
    from lvcore.emulator.subject import SubjectDesign

    d = SubjectDesign()  # the page's defaults are the CLI's
    assert [at.number_input(key=f"my_build_{k}").value for k in ("train", "valid", "test")] == [d.n_train, d.n_valid,
                                                                                                 d.n_test]
    at.number_input(key="my_build_train").set_value(8)
    at.number_input(key="my_build_valid").set_value(3)
    at.number_input(key="my_build_test").set_value(3)
    assert at.checkbox(key="my_build_edpvr").value is True   # on by default; off here: the CI-sized build above
    at.checkbox(key="my_build_edpvr").set_value(False).run()
    at.button(key="my_build_start").click().run()
    assert not at.exception, at.exception
    job = at.session_state["my_build_job"]
    job.join(1500)
    assert job.finished, f"the build is still running after 1500 s: {job.status()}"
    assert job.ok, job.error
    at.run()
    assert any("held-out test (3 FE runs never used in training) LVV RMSE" in s.value
               and "corrects the bundled `chapter` emulator" in s.value for s in at.success)
    label = next(o for o in at.selectbox(key="my_emulator").options if o.startswith("subject: "))
    at.selectbox(key="my_emulator").select(label)
    at.number_input(key="my_chains").set_value(1)
    at.number_input(key="my_warmup").set_value(100)
    at.number_input(key="my_draws").set_value(100).run()
    assert not at.exception and not at.error, [e.value for e in at.error]
    assert any("bound in" in i.value for i in at.info)
    at.button(key="my_run").click().run(timeout=300)
    assert not at.exception and not at.error, [e.value for e in at.error]
    summary = at.session_state["my_subject_run"].result["summary"]
    assert summary["geometry"]["kind"] == "subject-emulator" and summary["geometry"]["scores"] == []
    assert summary["emulator"] == label


def test_floor_caption_says_off_the_cohort_floor_or_the_meshs_own():
    assert flow.floor_caption(None) == "Representation-error floor: off"
    rec = {"mode": "floor", "n_cases": 80, "strain_sd_rms": 0.0061, "strain_scale": 1.0, "projection_mse_cm2": None}
    assert flow.floor_caption(rec) == "Representation-error floor: on (80 SYNTHETIC cohort cases; strain sd RMS 0.0061)"
    mesh = {**rec, "strain_scale": 1.47, "projection_mse_cm2": 0.0137, "beyond_cohort": False}
    assert "×1.47 of the cohort's mean strain covariance" in flow.floor_caption(mesh)
    assert "0.0137 cm²" in flow.floor_caption(mesh) and "extrapolated" not in flow.floor_caption(mesh)
    assert "extrapolated" in flow.floor_caption({**mesh, "beyond_cohort": True})
