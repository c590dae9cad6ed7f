"""``lvcore simulate``: exit codes, JSON output, VTU export (fast resolution)."""
import json

import numpy as np
import pytest

from lvcore.cli import main

FAST_LV = {
    "geometry": {"kind": "default", "resolution": "fast"},
    "material": {"law": "holzapfel-ogden", "a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6},
    "load": {"pressure": 8, "units": "mmHg"},
}


@pytest.fixture()
def case_file(tmp_path):
    path = tmp_path / "case.json"
    path.write_text(json.dumps(FAST_LV))
    return path


def test_simulate_json_and_vtu(case_file, tmp_path, capsys):
    import meshio

    vtu = tmp_path / "out.vtu"
    assert main(["simulate", str(case_file), "--json", "--vtu", str(vtu), "--sensitivities"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["converged"] is True
    assert out["boundary"] == {"base": "clamped"}  # every result names its base condition (issue 24)
    sens = out["sensitivities"]
    assert set(sens) == {"a", "b", "af", "bf"} and all(len(v) == 25 for v in sens.values())
    assert sens["a"][0] < 0 and sens["af"][0] < 0  # stiffer myocardium, smaller end-diastolic volume
    vol = out["cavity_volume_ml"]
    assert 60 < vol["reference"] < 110 and vol["loaded"] > vol["reference"]  # filling increases the volume
    assert out["lvv_standardised"] == pytest.approx(vol["loaded"] / vol["reference"])
    strains = np.asarray(out["strains"])
    assert strains.shape == (24,) and np.all(strains < 0)  # negative in filling (ED reference)
    mesh = meshio.read(vtu)
    u = mesh.point_data["displacement"]
    assert u.shape == mesh.points.shape and np.abs(u).max() > 0.5
    regions = mesh.cell_data["region"][0]
    assert sorted(set(regions.tolist())) == list(range(24))
    fibre = mesh.cell_data["fibre"][0]
    np.testing.assert_allclose(np.linalg.norm(fibre, axis=1), 1.0, atol=1e-9)
    # the endocardial apex moves down: the deformed apex is below the reference apex
    apex = int(np.argmin(mesh.points[:, 2]))
    assert u[apex, 2] < 0


def test_simulate_summary_text(case_file, capsys):
    assert main(["simulate", str(case_file)]) == 0
    text = capsys.readouterr().out
    assert "converged" in text and "LVV" in text and "mid-basal" in text
    assert "boundary: base clamped (the default; the 'chapter' emulator is sliding)" in text


def test_bad_case_exit_2(tmp_path, capsys):
    bad = dict(FAST_LV, material={"law": "holzapfel-ogden", "a": -1, "b": 1.3, "af": 1.0, "bf": 3.6})
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(bad))
    assert main(["simulate", str(path)]) == 2
    assert "material.a" in capsys.readouterr().err
    assert main(["simulate", str(tmp_path / "missing.json")]) == 2


def test_not_converged_exit_1(case_file, monkeypatch, capsys):
    from lvcore.mechanics import newton, simulate as sim

    real = sim.simulate

    def starved(case, with_sensitivities=False):  # a real solve with too few iterations allowed
        return real(case, with_sensitivities, options=newton.NewtonOptions(max_iterations=1, max_cuts=0))

    monkeypatch.setattr(sim, "simulate", starved)
    assert main(["simulate", str(case_file), "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["converged"] is False
