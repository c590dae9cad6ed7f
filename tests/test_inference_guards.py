"""Guards of `lvcore calibrate` and the plausibility check: each refusal is exit code 2, each flag a warning."""
import json

import numpy as np
import pytest

from lvcore.cli import main
from lvcore.emulator.io import save_emulator
from lvcore.exceptions import DataError, EmulatorError
from lvcore.inference import guards, plausibility
from lvcore.inference.data import MeasuredData, write_measured_csv

from test_inference_calibrate import _random_emulator  # UNTRAINED test doubles of the real class

FAST = ["--model", "iid", "--chains", "2", "--warmup", "100", "--samples", "100"]


@pytest.fixture()
def emus(tmp_path, monkeypatch):
    save_emulator(_random_emulator(), tmp_path / "emus" / "chapter")
    save_emulator(_random_emulator("angles", angles=True), tmp_path / "emus" / "angles")
    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path / "emus"))
    data = write_measured_csv(tmp_path / "m.csv", [MeasuredData(np.r_[135.0, np.full(24, -0.15)], "S1")])
    return tmp_path, data


def _h(tmp_path, h, name="h.json"):
    p = tmp_path / name
    p.write_text(json.dumps({"h": list(h)}))
    return p


def test_scores_outside_the_box_are_an_error_unless_allowed(emus, capsys):
    tmp_path, data = emus
    for h in ([1e6, 0, 0, 0, 0], [3.1, 0, 0, 0, 0]):
        rc = main(["calibrate", "--data", str(data), "--geometry", str(_h(tmp_path, h)), "--out", str(tmp_path / "o")])
        assert rc == 2
        err = capsys.readouterr().err
        assert "h1" in err and "training box" in err and "--allow-extrapolation" in err
    rc = main(["calibrate", "--data", str(data), "--geometry", str(_h(tmp_path, [3.1, 0, 0, 0, 0])),
               "--allow-extrapolation", *FAST, "--out", str(tmp_path / "o"), "--json"])
    assert rc in (0, 1, 4)  # 4: ran, results flagged (an untrained emulator and few draws)
    assert "EXTRAPOLATION" in capsys.readouterr().err
    (rec,) = json.loads((tmp_path / "o" / "summary.json").read_text())
    g = rec["geometry"]
    assert g["scores"] == [3.1, 0, 0, 0, 0] and g["source"].endswith("h.json") and g["kind"] == "scores"
    assert [b["inside"] for b in g["box"]] == [False, True, True, True, True]
    assert rec["extrapolation_allowed"] is True
    assert any(w.startswith("EXTRAPOLATION") for w in rec["warnings"])
    assert set(rec["plausibility"]["p_values"]) >= {"lvv_ml", "strain_24"}
    assert (tmp_path / "o" / "S1_iid_ppc.csv").is_file()


def test_conditions_the_emulator_cannot_honour_are_errors(emus, capsys):
    tmp_path, data = emus
    h = str(_h(tmp_path, [0.1, 0, 0, 0, 0]))
    base = ["calibrate", "--data", str(data), "--geometry", h, "--out", str(tmp_path / "o")]
    assert main(base + ["--edp", "12"]) == 2  # 'chapter' is trained at 8 mmHg only
    assert "fixed EDP at 8 mmHg" in capsys.readouterr().err
    assert main(base + ["--alpha-endo", "-50"]) == 2
    assert "fixed fibre angles" in capsys.readouterr().err
    for edp in ("-3", "45", "nan"):
        assert main(base + ["--emulator", "angles", "--edp", edp]) == 2
        assert "physiological range" in capsys.readouterr().err
    # an EDP the angles emulator takes, but outside its training box (6-14 mmHg)
    assert main(base + ["--emulator", "angles", "--edp", "20"]) == 2
    assert "edp = 20" in capsys.readouterr().err


def test_mean_geometry_is_explicit_and_warned(emus, capsys):
    tmp_path, data = emus
    rc = main(["calibrate", "--data", str(data), "--geometry", "mean", *FAST, "--out", str(tmp_path / "o"), "--json"])
    assert rc in (0, 1, 4)
    assert "biased" in capsys.readouterr().err
    (rec,) = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert rec["geometry"]["kind"] == "mean" and rec["geometry"]["scores"] == [0.0] * 5
    assert any("biased" in w for w in rec["warnings"])
    assert main(["calibrate", "--data", str(data), "--out", str(tmp_path / "o2")]) == 2  # --geometry is required
    assert "give --data and --geometry" in capsys.readouterr().err


def test_flipped_sign_strains_raise_a_plausibility_warning(emus, capsys):
    tmp_path, _ = emus
    y = np.r_[135.0, np.where(np.arange(24) % 2 == 0, 0.15, -0.15)]  # half the strains with a flipped sign
    data = write_measured_csv(tmp_path / "flip.csv", [MeasuredData(y, "F1")])
    rc = main(["calibrate", "--data", str(data), "--geometry", str(_h(tmp_path, [0, 0, 0, 0, 0])), *FAST,
               "--out", str(tmp_path / "o"), "--json"])
    assert rc in (1, 4)  # flagged (exit 4) unless the short run did not converge (1 takes precedence)
    err = capsys.readouterr().err
    assert "FLAGGED: CONSISTENCY" in err and "sign opposite" in err
    (rec,) = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert rec["plausibility"]["plausible"] is False and rec["plausible"] is False
    assert any("sign opposite" in f for f in rec["flags"])
    assert any("sign opposite" in f for f in rec["plausibility"]["flags"])


# --------------------------------------------------------------------------- the check itself, on known draws
def _draws(y, n=2000, seed=0):
    rng = np.random.default_rng(seed)
    return np.asarray(y)[None, :] + rng.normal(0, 1, (n, 25)) * np.r_[2.0, np.full(24, 0.005)]


def test_check_passes_data_the_model_reaches():
    rng = np.random.default_rng(3)
    eta = np.r_[140.0, -0.15 + 0.02 * np.sin(np.arange(24))]
    y = eta + np.r_[rng.normal(0, 5), rng.normal(0, 0.02, 24)]
    c = plausibility.posterior_predictive_check(y, _draws(eta), sigma_v=5.0)
    assert c.plausible, c.flags
    assert c.p_values.shape == (25,) and np.all((c.p_values > 0) & (c.p_values <= 1))


def test_check_flags_zero_strains_and_volume_strain_conflict():
    eta = np.r_[140.0, np.full(24, -0.15)]
    zero = plausibility.posterior_predictive_check(np.r_[140.0, np.zeros(24)], _draws(eta), 5.0)
    assert any("within" in f and "zero" in f for f in zero.flags)
    assert any("24 of 24 strains" in f for f in zero.flags)
    vol = plausibility.posterior_predictive_check(np.r_[180.0, np.full(24, -0.15)], _draws(eta), 5.0)
    assert len(vol.flags) == 1 and "volume is not reached" in vol.flags[0]
    assert vol.p_values[0] < 0.01 and np.all(vol.p_values[1:] > 0.01)


def test_check_conditions_unit():
    chapter, angles = _random_emulator(), _random_emulator("angles", angles=True)
    assert guards.check_conditions(chapter)["edp_mmhg"] == 8.0
    assert guards.check_conditions(angles, 10.0)["edp_mmhg"] == 10.0
    with pytest.raises(EmulatorError):
        guards.check_conditions(chapter, 8.0)  # even the trained value: the emulator takes no EDP
    with pytest.raises(DataError):
        guards.check_conditions(angles, 1.0)
    with pytest.raises(EmulatorError, match="do not also fix"):
        guards.check_conditions(angles, alpha_endo=-60.0, infer_angles=True)


def test_resolve_geometry_from_a_volume_mesh(tmp_path):
    """--geometry LV.inp: the volume mesh is fitted, projected, and the source recorded."""
    from lvcore.exceptions import GeometryError
    from lvcore.geometry.analytic import DEFAULT_LV
    from lvcore.geometry.meshing import ellipsoid_tet_mesh

    path = tmp_path / "lv.inp"
    ellipsoid_tet_mesh(DEFAULT_LV, 6.0, path)
    g = guards.resolve_geometry(str(path))
    assert g.kind == "volume-mesh" and g.source == str(path) and g.h.shape == (5,)
    assert g.fit_residual_mm < 0.5 and g.projection_mse_cm2 < 1.0
    assert np.all(np.abs(g.h) < 2.0)
    with pytest.raises(GeometryError, match="required"):
        guards.resolve_geometry("")
    with pytest.raises(GeometryError, match="no such file"):
        guards.resolve_geometry(str(tmp_path / "nope.json"))


def test_a_mm_volume_mesh_read_as_cm_warns_naming_geometry_units(tmp_path):
    """calibrate --geometry LV.inp --geometry-units cm on a mm mesh: a 1,000x cavity, flagged (issue 28, finding 5)."""
    from lvcore.geometry.analytic import DEFAULT_LV
    from lvcore.geometry.meshing import ellipsoid_tet_mesh

    import meshio

    # a small LV in mm (25 mm long, an extent the readers accept as mm or as cm): read as cm it is 255 mm long
    path = tmp_path / "lv.inp"
    ellipsoid_tet_mesh(DEFAULT_LV, 6.0, path)
    mesh = meshio.read(path)
    mesh.points = mesh.points * 0.3
    meshio.write(path, mesh)
    assert not any("units" in w for w in guards.resolve_geometry(str(path), units="mm").warnings)
    (w,) = [w for w in guards.resolve_geometry(str(path), units="cm").warnings if "units" in w]
    assert "check --geometry-units (read as cm" in w and "mL cavity" in w
