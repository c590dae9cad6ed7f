"""Subject-specific emulators (lvcore.emulator.subject): FE runs on one exact geometry, held-out validation.

CI-sized: a narrow θ box, the ``fast`` mesh and 24 + 6 + 6 runs; the held-out
rows are re-simulated cold here and compared with the stored ones and the
emulator.
"""
import json

import numpy as np
import pytest

from lvcore.cli import main
from lvcore.emulator.io import load_emulator, load_validation
from lvcore.emulator.subject import (SubjectDesign, build_subject_emulator, parse_inputs, resolve_subject_geometry,
                                     subject_space)
from lvcore.emulator.training import TrainingConfig
from lvcore.exceptions import EmulatorError, GeometryError
from lvcore.resources import volunteer_files

BOUNDS = {"a": (0.5, 1.0), "b": (1.0, 2.0), "af": (0.8, 1.6), "bf": (2.0, 4.0)}
CONFIG = TrainingConfig(architectures=((50, 50),), max_epochs=600, patience=200, decay_epochs=200, batch_size=8,
                        lbfgs_iterations=400, lbfgs_lvv_weight=24.0, seed=0)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("subject") / "emu"
    geometry = volunteer_files("SYNTHETIC_HV3").geometry
    emu = build_subject_emulator(geometry, out, design=SubjectDesign(24, 6, 6), resolution="fast", bounds=BOUNDS,
                                 workers=1, seed=3, config=CONFIG, edpvr=False)
    return out, emu, geometry


def test_subject_emulator_reproduces_held_out_fe_runs(built):
    out, emu, geometry = built
    meta = emu.metadata
    assert emu.is_subject and not any(n.startswith("h") for n in emu.input_names)
    assert emu.input_names == ("a", "b", "af", "bf")
    assert meta["subject"]["geometry_source"] == str(geometry) and meta["subject"]["geometry_kind"] == "template-mesh"
    assert (out / "geometry.vtu").is_file() and emu.subject_geometry["path"] == str((out / "geometry.vtu").resolve())
    assert json.loads((out / "metadata.json").read_text())["subject"]["geometry"]["path"] == "geometry.vtu"
    runs = meta["subject"]["runs"]
    assert runs["total"] == 36 and runs["converged"] == 36 and runs["n_test"] == 6 and runs["n_train"] == 24
    assert not (out / "fe_runs.npz").exists()
    # the network corrects the bundled chapter emulator at the subject's size-normalised shape (a copy in out/prior)
    prior = meta["subject"]["prior"]
    assert prior["used"] and prior["name"] == "chapter" and set(prior["inputs"]) == {f"h{k}" for k in range(1, 6)}
    assert emu.prior is not None and emu.prior.emulator.name == "chapter" and (out / "prior" / "network.npz").is_file()
    assert emu.prior.scale == pytest.approx(prior["scale"]) and 0.5 < prior["scale"] < 1.8
    # held-out rows: never in the training or validation set
    with np.load(out / "training_data.npz") as z:
        seen = np.concatenate([z["train_inputs"], z["valid_inputs"]])
        test_x, test_y = z["test_inputs"], z["test_outputs"]
    assert not any(np.any(np.all(np.isclose(seen, row, rtol=0, atol=0), axis=1)) for row in test_x)
    # the recorded held-out accuracy is the emulator's on those rows
    val = load_validation(out)
    np.testing.assert_allclose(val["inputs"], test_x)
    pred = np.asarray(emu.apply(val["inputs"]))
    err = pred - val["outputs"]
    assert meta["test"]["n"] == 6
    assert meta["test"]["lvv_rmse_ml"] == pytest.approx(float(np.sqrt(np.mean(err[:, 0] ** 2))), rel=1e-6)
    assert meta["test"]["strain_rmse"] == pytest.approx(float(np.sqrt(np.mean(err[:, 1:] ** 2))), rel=1e-6)
    # ... and small: the emulator reproduces FE runs it never saw (narrow box, 24 training runs)
    lvv = val["outputs"][:, 0]
    assert meta["test"]["lvv_rmse_ml"] < 0.02 * lvv.mean(), (meta["test"]["lvv_rmse_ml"], lvv.mean())
    assert meta["test"]["strain_rmse"] < 0.003
    # the stored held-out outputs are FE runs on the exact geometry: re-simulate two of them cold
    sim = emu.simulator()
    assert sim.geometry == emu.subject_geometry and sim.resolution == "fast" and sim.base == "sliding"
    fresh = sim.evaluate({n: test_x[:2, i] for i, n in enumerate(emu.input_names)}).raise_on_failure()
    np.testing.assert_allclose(fresh.outputs, test_y[:2], rtol=2e-6, atol=2e-7)  # float32 storage
    assert np.all(np.abs(pred[:2, 0] - fresh.outputs[:, 0]) < 0.05 * fresh.outputs[:, 0])


def test_loaded_subject_emulator_is_relocatable(built, tmp_path):
    import shutil

    out, emu, _ = built
    moved = tmp_path / "moved"
    shutil.copytree(out, moved)
    again = load_emulator(moved)
    assert again.subject_geometry["path"] == str((moved / "geometry.vtu").resolve())
    x = np.array([0.7, 1.4, 1.1, 3.0])
    np.testing.assert_allclose(np.asarray(again.predict(x)), np.asarray(emu.predict(x)), rtol=1e-12)
    (moved / "geometry.vtu").unlink()
    with pytest.raises(EmulatorError, match="geometry file"):
        load_emulator(moved)


def test_calibrate_cli_with_a_subject_emulator_needs_no_geometry(built, tmp_path, capsys):
    out, emu, _ = built
    y = np.asarray(emu.predict(np.array([0.7, 1.5, 1.2, 3.0])))
    csv = tmp_path / "data.csv"
    csv.write_text("subject,lvv_ml," + ",".join(f"strain_{i:02d}" for i in range(1, 25)) + "\n"
                   + "SYNTHETIC-S1," + ",".join(f"{v:.6g}" for v in y) + "\n")
    rc = main(["calibrate", "--emulator", str(out), "--data", str(csv), "--model", "volume", "--chains", "2",
               "--warmup", "100", "--samples", "100", "--out", str(tmp_path / "cal"), "--json"])
    assert rc in (0, 1, 4)  # 1: not converged, 4: flagged (volume data leave theta unidentified); it ran
    rec = json.loads((tmp_path / "cal" / "summary.json").read_text())[0]
    assert rec["geometry"]["kind"] == "subject-emulator" and rec["geometry"]["scores"] == []
    capsys.readouterr()
    rc = main(["calibrate", "--emulator", str(out), "--data", str(csv), "--geometry", "mean"])
    assert rc == 2 and "subject-specific" in capsys.readouterr().err


def test_prior_mean_choice_matches_the_fe_runs_or_says_why():
    from lvcore.emulator.subject import choose_prior

    section = {"kind": "default"}
    prior, rec = choose_prior(subject_space(("theta",)), section, "auto")
    assert prior.emulator.name == "chapter" and rec["used"] and rec["scale"] > 0
    # another base condition: no bundled emulator matches (the chapter emulator is sliding), and the record says why
    prior, rec = choose_prior(subject_space(("theta",), base="clamped"), section, "auto")
    if prior is None:
        assert not rec["used"] and "base is sliding" in rec["rejected"]["chapter"]
    else:
        assert prior.emulator.base == "clamped"
    # the EDP and the angles varied: the bundled angles emulator (sliding since its rebuild), its scores included
    prior, rec = choose_prior(subject_space(("theta", "edp", "angles")), section, "auto")
    assert prior.emulator.name == "angles" and set(rec["inputs"]) == {f"h{k}" for k in range(1, 6)}
    # the EDP alone over Table 9.1's theta box: the angles emulator's b, bf start at 0.5, so no prior (said why)
    prior, rec = choose_prior(subject_space(("theta", "edp")), section, "auto")
    assert prior is None and "leaves its box" in rec["rejected"]["angles"]
    assert choose_prior(subject_space(("theta",)), section, "none") == (None, {"used": False, "reason":
                                                                             "not asked for (--prior none)"})
    with pytest.raises(EmulatorError, match="cannot be the prior mean.*trained at edp = 8"):
        choose_prior(subject_space(("theta",), edp_mmhg=10.0), section, "chapter")
    with pytest.raises(EmulatorError, match="does not take edp"):
        choose_prior(subject_space(("theta", "edp")), section, "chapter")


def test_build_cli_refuses_bad_options(tmp_path, capsys):
    geometry = str(volunteer_files("SYNTHETIC_HV3").geometry)
    for extra, needle in ((["--inputs", "theta,pressure"], "--inputs"), (["--bound", "a=3"], "--bound"),
                          (["--bound", "h1=0,1"], "unknown input"), (["--n-test", "1"], "n-test"),
                          (["--resolution", "huge"], "--resolution"), (["--edp", "90"], "--edp")):
        rc = main(["emulator", "build", "--geometry", geometry, "--out", str(tmp_path / "x"), *extra])
        assert rc == 2 and needle in capsys.readouterr().err, extra
    rc = main(["emulator", "build", "--geometry", str(tmp_path / "nope.vtu"), "--out", str(tmp_path / "x")])
    assert rc == 2 and "no such file" in capsys.readouterr().err


def test_geometry_kinds(tmp_path):
    assert resolve_subject_geometry("default").section == {"kind": "default"}
    scores = tmp_path / "h.json"
    scores.write_text(json.dumps({"h": [0.5, -0.2, 0.1]}))
    g = resolve_subject_geometry(scores)
    assert g.section == {"kind": "pca", "scores": [0.5, -0.2, 0.1]} and g.kind == "scores"
    mesh = volunteer_files("SYNTHETIC_HV3").geometry
    case = tmp_path / "case.json"
    case.write_text(json.dumps({"geometry": {"kind": "mesh", "path": str(mesh), "resolution": "fast"}}))
    g = resolve_subject_geometry(case)
    assert g.kind == "case" and g.nodes is not None and g.record["cavity_volume_ml"] > 0
    bad = tmp_path / "x.stl"
    bad.write_text("solid x\nendsolid x\n")
    with pytest.raises(GeometryError, match="unknown format"):
        resolve_subject_geometry(bad)


def test_design_space():
    space = subject_space(parse_inputs("angles,theta,edp"))
    assert space.names == ("a", "b", "af", "bf", "edp", "alpha_endo", "alpha_epi") and space.fixed == ()
    assert space.parameters[1].lower == 0.5  # the angles emulator's b >= 0.5 with free angles
    space = subject_space(("theta",), edp_mmhg=10.0)
    assert dict(space.fixed) == {"edp": 10.0, "alpha_endo": -60.0, "alpha_epi": 60.0} and space.base == "sliding"
    with pytest.warns(DeprecationWarning, match=r"subject_space\(edp=\.\.\.\) is deprecated; use edp_mmhg="):
        assert subject_space(("theta",), edp=10.0) == space  # the old keyword still works
    with pytest.raises(EmulatorError):
        parse_inputs("edp")


def test_simulate_rows_keeps_the_runs_done_and_resumes(tmp_path):
    """A stopped simulation keeps its finished chunks in the checkpoint; the next call with the same inputs
    resumes from them, and its results equal one uninterrupted run (within solver tolerance)."""
    from lvcore.campaigns.designs import make_design
    from lvcore.emulator.subject import simulate_rows

    space = subject_space(("theta",), bounds=BOUNDS)
    x = make_design(space, "sobol", 6, 1).points
    geometry = resolve_subject_geometry("default").section
    ckpt = tmp_path / "fe_runs.npz"
    seen = []
    with pytest.raises(EmulatorError, match=f"stopped after 3 of 6 FE runs; they are kept in {ckpt}"):
        simulate_rows(space, x, geometry, resolution="fast", workers=1, checkpoint=ckpt, chunk=3,
                      progress=lambda done, total: seen.append(done), stop=lambda: len(seen) >= 1)
    assert seen == [3]
    with np.load(ckpt) as z:
        assert z["inputs"].shape == (3, 4) and z["converged"].all()
        kept_x, kept = z["inputs"].copy(), z["outputs"].copy()
    calls = []
    res = simulate_rows(space, x, geometry, resolution="fast", workers=1, checkpoint=ckpt, chunk=3,
                        progress=lambda done, total: calls.append(done))
    assert calls == [3, 6]  # the 3 kept rows were not simulated again
    assert res.converged.all()
    from lvcore.execution.chains import continuation_order, scaled_coordinates

    first = continuation_order(scaled_coordinates(space.names, x))[:3]  # solved in the walk's order
    np.testing.assert_array_equal(x[first], kept_x)
    np.testing.assert_array_equal(res.outputs[first], kept)
    other_x = make_design(space, "sobol", 6, 2).points
    other = simulate_rows(space, other_x, geometry, resolution="fast", workers=1, checkpoint=ckpt, chunk=6,
                          progress=lambda done, total: calls.append(("other", done)))
    assert calls[2:] == [("other", 6)]  # other inputs: nothing taken from the checkpoint
    cold = simulate_rows(space, x[::-1], geometry, resolution="fast", workers=1, chunk=1)  # another walk, no file
    np.testing.assert_allclose(cold.outputs[::-1], res.outputs, rtol=1e-5, atol=1e-7)
    assert other.converged.all()


def test_simulate_rows_on_two_workers_streams_chunks_and_resumes(tmp_path):
    """With a pool, chain chunks are recorded as they return (no barrier per batch): a stop keeps every chunk
    returned so far (any subset of the walk), the resumed run simulates only the rest, and the results equal
    those of the in-process walk within solver tolerance. Both pooled calls share one pool of two processes, as
    the stages of a build do (each new worker process imports JAX and compiles the simulator again)."""
    from lvcore.campaigns.designs import make_design
    from lvcore.emulator.subject import simulate_rows
    from lvcore.execution.parallel import make_executor

    space = subject_space(("theta",), bounds=BOUNDS)
    x = make_design(space, "sobol", 10, 4).points
    geometry = resolve_subject_geometry("default").section
    ckpt = tmp_path / "fe_runs.npz"
    seen, calls = [], []
    with make_executor(workers=2) as pool:
        with pytest.raises(EmulatorError, match="stopped after [0-9]+ of 10 FE runs"):
            simulate_rows(space, x, geometry, resolution="fast", workers=2, checkpoint=ckpt, chunk=2,
                          progress=lambda done, total: seen.append(done), stop=lambda: len(seen) >= 1,
                          executor=pool)
        with np.load(ckpt) as z:
            n_kept = z["inputs"].shape[0]
            assert 2 <= n_kept < 10 and z["converged"].all()
        res = simulate_rows(space, x, geometry, resolution="fast", workers=2, checkpoint=ckpt, chunk=2,
                            progress=lambda done, total: calls.append(done), executor=pool)
    assert calls[0] == n_kept and calls[-1] == 10 and calls == sorted(calls)
    assert res.converged.all() and res.workers == 2
    ref = simulate_rows(space, x, geometry, resolution="fast", workers=1)
    np.testing.assert_allclose(res.outputs, ref.outputs, rtol=1e-5, atol=1e-7)


def test_design_rows_fill_the_box_and_hold_out_other_points():
    from lvcore.campaigns.designs import make_design
    from lvcore.emulator.subject import design_rows

    space = subject_space(("theta",))
    design = SubjectDesign(16, 5, 7)
    x, parts = design_rows(space, design, seed=3)
    assert x.shape == (28, 4) and [len(parts[k]) for k in ("train", "valid", "test")] == [16, 5, 7]
    assert sorted(np.concatenate(list(parts.values()))) == list(range(28))
    # the training rows are one 16-point Sobol design: every 1/16 slab of every axis holds one point
    np.testing.assert_array_equal(x[parts["train"]], make_design(space, "sobol", 16, 3).points)
    u = space.to_unit(x[parts["train"]])
    assert all(len(set(np.floor(u[:, j] * 16).astype(int))) == 16 for j in range(4))
    held = x[np.concatenate([parts["valid"], parts["test"]])]
    assert not any(np.any(np.all(held == row, axis=1)) for row in x[parts["train"]])
