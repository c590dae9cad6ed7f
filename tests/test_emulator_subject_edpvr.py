"""lvcore.emulator.subject_edpvr: a subject emulator's own EDPVR emulator (FE load paths on its mesh), its accuracy
against fresh FE load paths, and its use by the derived quantities of a calibration through the subject emulator.

CI-sized: a narrow θ box, the ``fast`` mesh, 8 + 3 + 3 subject runs and 12 + 4 + 6 load paths.
"""
import json
import shutil

import numpy as np
import pytest

from lvcore.emulator import edpvr, subject_edpvr
from lvcore.emulator.subject import SubjectDesign, build_subject_emulator
from lvcore.emulator.training import TrainingConfig
from lvcore.exceptions import EmulatorError
from lvcore.inference import derived
from lvcore.resources import volunteer_files

BOUNDS = {"a": (0.5, 1.0), "b": (1.0, 2.0), "af": (0.8, 1.6), "bf": (2.0, 4.0)}
CONFIG = TrainingConfig(architectures=((30, 30),), max_epochs=300, patience=100, decay_epochs=100, batch_size=8,
                        lbfgs_iterations=200, lbfgs_lvv_weight=24.0, seed=0)
PRESSURES = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0)
KW = dict(angles=(-60.0, 60.0), base="sliding", resolution="fast")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("subject_edpvr") / "emu"
    emu = build_subject_emulator(volunteer_files("SYNTHETIC_HV3").geometry, out, design=SubjectDesign(8, 3, 3),
                                 resolution="fast", bounds=BOUNDS, workers=1, seed=3, config=CONFIG, edpvr=True,
                                 edpvr_design=subject_edpvr.EdpvrDesign(12, 4, 6))
    return out, emu, subject_edpvr.load_subject_edpvr(out / subject_edpvr.FOLDER)


def _draw(a=0.7, b=1.4, af=1.1, bf=3.0, **extra):
    return {"a": a, "b": b, "af": af, "bf": bf, **extra}


def test_build_saves_it_in_the_subject_emulators_folder_with_its_held_out_errors(built):
    out, emu, e = built
    rec = emu.metadata["subject"]["edpvr"]
    assert rec["folder"] == "edpvr" and rec["name"] == e.name and emu.metadata["subject"]["seconds"]["edpvr"] > 0
    assert json.loads((out / "metadata.json").read_text())["subject"]["edpvr"]["n_test_paths"] == 6
    assert e.is_subject and e.log1p_pressure and (e.base, e.resolution) == ("sliding", "fast")
    np.testing.assert_allclose(e.lower, [0.5, 1.0, 0.8, 2.0, 0.0])
    np.testing.assert_allclose(e.upper, [1.0, 2.0, 1.6, 4.0, 30.0])
    assert e.metadata["subject"]["geometry_sha256"] == subject_edpvr.geometry_fingerprint(emu.subject_geometry)
    # the stored per-pressure RMSE is the emulator's on the held-out paths (validation.npz)
    t = e.metadata["test"]
    with np.load(out / "edpvr" / "validation.npz") as z:
        pred, lvv, v0 = z["predictions"], z["lvv_ml"], float(e.metadata["subject"]["v0_ml"])
        np.testing.assert_allclose(pred, e.outputs(z["inputs"]), rtol=1e-12)
    np.testing.assert_allclose(t["log_volume_ratio_rmse"],
                               np.sqrt(np.mean((pred[..., 0] - np.log(lvv / v0)) ** 2, axis=0)), rtol=1e-9)
    assert t["n_paths"] == 6 and max(t["pressures_mmhg"]) == 30.0 and 0 < max(t["log_volume_ratio_rmse"]) < 0.05
    # the pressures of the held-out paths lie between the training ones
    with np.load(out / "edpvr" / "load_paths_train.npz") as z:
        assert not set(z["pressures_mmhg"].tolist()) >= set(t["pressures_mmhg"])


def test_emulator_agrees_with_fe_load_paths_at_held_out_theta(built):
    """Two θ off every design: the emulated volumes (0-30 mmHg and the EDP) are within 4 times the stated held-out
    error (+ 0.5 %) of fresh FE load paths on the subject's mesh, V₀ is the mesh's, the fibre stretch close."""
    out, emu, e = built
    draws = [_draw(), _draw(a=0.55, b=1.9, af=1.5, bf=2.2)]
    fe = derived.fe_load_path(draws, edp_mmhg=11.0, geometry=emu.subject_geometry, pressures_mmhg=PRESSURES,
                              angles=(-60.0, 60.0), base="sliding", resolution="fast")
    assert fe.n_failed == 0
    em = edpvr.emulated_load_path(e, draws, edp_mmhg=11.0, pressures_mmhg=PRESSURES)
    np.testing.assert_allclose(em.volumes_ml[:, 0], fe.volumes_ml[:, 0], rtol=1e-9)
    rel = np.abs(np.log(em.volumes_ml[:, 1:] / fe.volumes_ml[:, 1:]))
    sd = e.volume_log_sd(np.asarray(PRESSURES))
    assert np.all(rel <= 4 * sd + 5e-3), (rel, sd)
    assert np.all(np.abs(np.log(em.volume_at_edp_ml / fe.volume_at_edp_ml)) <= 4 * e.volume_log_sd(11.0) + 5e-3)
    np.testing.assert_allclose(em.fibre_stretch_at_edp, fe.fibre_stretch_at_edp, atol=4 * e.stretch_sd(11.0) + 0.005)


def test_derive_takes_the_subject_edpvr_emulator_for_a_subject_calibration(built):
    """derive() on a SYNTHETIC posterior through the subject emulator (its geometry section, no PC scores): the
    subject EDPVR emulator, no FE solve; the record names it and the source says so."""
    import arviz as az

    out, emu, e = built
    rng = np.random.default_rng(0)
    post = {k: rng.uniform(lo + 0.05 * (hi - lo), hi - 0.05 * (hi - lo), (2, 100)) for k, (lo, hi) in BOUNDS.items()}
    rec, dd = derived.derive(az.from_dict(posterior=post), bounds=BOUNDS, edp_mmhg=8.0, measured_edv_ml=None,
                             lvv_sd_ml=1.0, geometry=emu.subject_geometry, n_draws=100, **KW)
    assert (rec["path"], rec["emulator"], rec["path_reason"]) == ("emulator", e.name, "")
    assert rec["seconds"]["fe"] == 0.0 and rec["edpvr_check"]["n_failed_solves"] == 0
    assert f"subject EDPVR emulator '{e.name}'" in rec["edpvr_check"]["source"]
    v0 = float(e.metadata["subject"]["v0_ml"])
    assert rec["edpvr"][0]["median"] == pytest.approx(v0, rel=1e-12)
    assert all(r["median"] > v0 for r in rec["edpvr"][1:]) and "end_diastolic" in rec["stress"]


def test_fe_fallback_says_why(built, tmp_path):
    """No subject EDPVR folder, another mesh, draws or pressures outside the box, inferred angles, other conditions,
    or the FE path asked for: no emulator, and the reason names it."""
    out, emu, e = built
    geo = emu.subject_geometry
    kw = dict(geometry=geo, edp_mmhg=8.0, pressures_mmhg=PRESSURES, **KW)
    got, why = edpvr.emulator_for([_draw()], **kw)
    assert got is not None and got.name == e.name and why == ""
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(geo["path"], bare / "geometry.vtu")
    other = tmp_path / "other"
    shutil.copytree(out, other)
    with open(other / "geometry.vtu", "ab") as f:
        f.write(b"\n")
    cases = [(dict(geometry={"kind": "mesh", "path": str(bare / "geometry.vtu")}), [_draw()], "missing"),
             (dict(geometry={"kind": "mesh", "path": str(other / "geometry.vtu")}), [_draw()], "another mesh"),
             (dict(geometry={"kind": "default"}), [_draw()], "kind 'default'"),
             (dict(), [_draw(a=2.0)], "box"), (dict(edp_mmhg=31.0), [_draw()], "box"),
             (dict(), [_draw(alpha_endo=-50.0, alpha_epi=55.0)], "angles"),
             (dict(base="clamped"), [_draw()], "base"), (dict(resolution="default"), [_draw()], "resolution"),
             (dict(angles=(None, None)), [_draw()], "angles"), (dict(name=None), [_draw()], "asked")]
    for change, draws, word in cases:
        got, why = edpvr.emulator_for(draws, **{**kw, **change})
        assert got is None and word in why, (change, why)
    # derive() falls back to the FE load path with the reason recorded (one draw, one pressure)
    import arviz as az

    rng = np.random.default_rng(1)
    post = {k: v * np.exp(0.02 * rng.standard_normal((1, 6))) for k, v in _draw(a=2.0).items()}
    rec, _ = derived.derive(az.from_dict(posterior=post), bounds=BOUNDS, edp_mmhg=5.0, measured_edv_ml=None,
                            lvv_sd_ml=1.0, geometry=geo, n_draws=2, pressures_mmhg=(5.0,), **KW)
    assert rec["path"] == "fe" and "outside the subject EDPVR emulator's box" in rec["path_reason"]


def test_bad_metadata_is_a_clear_emulator_error(built, tmp_path):
    out, emu, e = built
    folder = tmp_path / "edpvr"
    shutil.copytree(out / "edpvr", folder)
    meta_path = folder / "edpvr.json"
    good = json.loads(meta_path.read_text())
    for bad, word in (("{not json", "cannot read"), (json.dumps({**good, "format": "other"}), "not an"),
                      (json.dumps({**good, "input_names": ["a", "b"]}), "inputs/outputs"),
                      (json.dumps({k: v for k, v in good.items() if k != "test"}), "malformed"),
                      (json.dumps({**good, "lower": [0.5, 1.0]}), "malformed"),
                      (json.dumps({**good, "subject": {**good["subject"], "v0_ml": -1.0}}), "malformed")):
        meta_path.write_text(bad)
        with pytest.raises(EmulatorError, match=word):
            subject_edpvr.load_subject_edpvr(folder)
    meta_path.write_text(json.dumps(good))
    (folder / "network.npz").unlink()
    with pytest.raises(EmulatorError, match="malformed"):
        subject_edpvr.load_subject_edpvr(folder)
    # in use: a damaged subject EDPVR emulator is a reason for the FE path, not a crash
    geo = tmp_path / "geometry.vtu"
    shutil.copy(emu.subject_geometry["path"], geo)
    got, why = edpvr.conditions_covered(geometry={"kind": "mesh", "path": str(geo)}, **KW)
    assert got is None and "cannot be used" in why and "malformed" in why


def test_design_parts_are_seeded_and_refused_when_too_small(built):
    with pytest.raises(EmulatorError, match="n-valid"):
        subject_edpvr.EdpvrDesign(12, 1, 6)
    out, _, e = built
    seeds = e.metadata["subject"]["design"]["seeds"]
    assert seeds == {"train": 3, "valid": 4, "test": 5}
    from lvcore.campaigns.designs import make_design
    from lvcore.core.space import ParameterSpace

    sp = ParameterSpace.from_dict(e.metadata["subject"]["space"])
    with np.load(out / "edpvr" / "load_paths_train.npz") as z:
        np.testing.assert_array_equal(z["inputs"], make_design(sp, "sobol", 12, 3).points)


def test_build_cli_states_its_default_and_info_names_it(built, capsys):
    from lvcore.cli import main
    from lvcore.emulator.cli import format_info

    with pytest.raises(SystemExit):
        main(["emulator", "build", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--edpvr, --no-edpvr" in text and "(default on for a mesh geometry, off for default or PC scores" in text
    _, emu, e = built
    assert f"EDPVR emulator: '{e.name}' in edpvr/" in format_info(emu.metadata)
    assert "EDPVR emulator: none" in format_info({k: v for k, v in emu.metadata.items() if k != "subject"} |
                                                 {"subject": {k: v for k, v in emu.metadata["subject"].items()
                                                              if k != "edpvr"}})


def test_build_refuses_edpvr_for_a_geometry_without_a_mesh_file(tmp_path):
    """With no mesh file in the emulator folder, nothing would find the EDPVR emulator: refused before any run."""
    with pytest.raises(EmulatorError, match="--edpvr needs a mesh geometry"):
        build_subject_emulator("default", tmp_path / "emu", design=SubjectDesign(8, 3, 3), resolution="fast",
                               bounds=BOUNDS, workers=1, config=CONFIG, edpvr=True)
    assert not (tmp_path / "emu" / "fe_runs.npz").exists()


def test_the_default_builds_the_edpvr_emulator_for_a_mesh_only():
    """``edpvr=None`` (the CLI's and the app's default): on for a mesh geometry, off for one without a mesh file
    (``default``, PC scores), which cannot have one; an explicit choice wins."""
    from lvcore.emulator.subject import DEFAULT_EDPVR, resolve_edpvr

    assert DEFAULT_EDPVR is True
    assert resolve_edpvr(None, {"kind": "mesh", "path": "x/geometry.vtu"}) is True
    assert resolve_edpvr(None, {"kind": "default"}) is False and resolve_edpvr(None, {"kind": "scores"}) is False
    assert resolve_edpvr(False, {"kind": "mesh"}) is False and resolve_edpvr(True, {"kind": "mesh"}) is True
