"""The mismatch study on the real LV: a mesh volunteer beside the SYNTHETIC ones, its subject-emulator check, its
FE-simulated sources, and fit files and per-volunteer values that name it."""
import json
from pathlib import Path

import numpy as np
import pytest

from lvcore.domain.outputs import THETA_NAMES
from lvcore.exceptions import EmulatorError
from lvcore.mechanics.case import Case
from lvcore.resources import real_lv_files
from lvcore.studies import mismatch as mm


def _stand_in_subject_emulator(directory: Path, mesh: Path, *, base: str = "sliding", layer: str | None = None,
                               alpha_epi: float = 60.0):
    """An UNTRAINED subject emulator (random weights) of ``mesh``, saved in ``directory``: plumbing only."""
    from lvcore.emulator.io import save_emulator
    from lvcore.emulator.model import Emulator
    from lvcore.emulator.network import MLP
    from lvcore.emulator.subject import subject_space

    space = subject_space(("theta",), base=base, alpha_epi=alpha_epi)
    emu = Emulator(name="stand-in-subject", input_names=THETA_NAMES, lower=np.asarray(space.lower),
                   upper=np.asarray(space.upper), log_inputs=(True,) * 4, x_mean=np.zeros(4), x_sd=np.ones(4),
                   y_mean=np.r_[100.0, np.full(24, -0.15)], y_sd=np.r_[20.0, np.full(24, 0.03)],
                   network=MLP(4, 25, (8, 8), seed=1), fixed=space.fixed_dict(),
                   metadata={"source": {"space": space.to_dict(), "resolution": ["fast"]},
                             "subject": {"geometry": {"kind": "mesh", "path": str(mesh)}},
                             **({"strain_layer": layer} if layer else {})})
    save_emulator(emu, directory)
    return str(directory)


def test_the_real_lv_is_a_mesh_volunteer_at_a_theta_inside_the_box():
    vols = mm.study_volunteers(["HV1", mm.REAL_LV])
    assert [v.name for v in vols] == ["HV1", mm.REAL_LV]
    real = vols[1]
    assert real.h == () and real.geometry == {"kind": "mesh", "path": str(real_lv_files().template)}
    assert real.theta == mm.REAL_LV_THETA and vols[0].geometry is None
    med = {n: np.median([v.theta[n] for v in mm.bundled_volunteers()]) for n in THETA_NAMES}
    assert all(real.theta[n] == pytest.approx(med[n], rel=0.01) for n in THETA_NAMES)  # the population median
    assert [v.name for v in mm.study_volunteers([mm.REAL_LV])] == [mm.REAL_LV]
    assert len(mm.study_volunteers(None)) == 8  # the bundled ones only, as before
    with pytest.raises(ValueError, match="REAL-LV"):
        mm.study_volunteers(["HV9"])


@pytest.mark.parametrize("source,dose", [(None, 0.0), ("angles", 15.0), ("base", 1.0), ("sheet", 4.0),
                                         ("dispersion", 0.1), ("heterogeneity", 0.4), ("pericardium", 0.1)])
def test_every_source_applies_to_the_mesh(source, dose):
    real = mm.real_lv_volunteer()
    case = mm.mismatch_case(real.theta, real.h, source, dose, geometry=real.geometry)
    c = Case.from_dict(case)
    assert c.geometry.kind == "mesh" and case["geometry"]["path"] == real.geometry["path"]
    assert c.boundary.base == ("clamped" if source == "base" else "sliding")
    with pytest.raises(ValueError, match="not both"):
        mm.mismatch_case(real.theta, (0.1,), source, dose, geometry=real.geometry)


def test_the_subject_emulator_must_be_of_the_mesh_at_the_models_conditions(tmp_path):
    from lvcore.resources import volunteer_files

    real, mesh = mm.real_lv_volunteer(), real_lv_files().template
    with pytest.raises(EmulatorError, match="takes PC scores.*lvcore emulator build --geometry .*--base sliding"):
        mm.subject_forward("chapter", real)
    other = _stand_in_subject_emulator(tmp_path / "other", volunteer_files("SYNTHETIC_HV1").geometry)
    with pytest.raises(EmulatorError, match="another geometry than volunteer REAL-LV's mesh"):
        mm.subject_forward(other, real)
    clamped = _stand_in_subject_emulator(tmp_path / "clamped", mesh, base="clamped")
    with pytest.raises(EmulatorError, match="'base': 'clamped'.*--base sliding --strain-layer inner_half"):
        mm.subject_forward(clamped, real)
    whole = _stand_in_subject_emulator(tmp_path / "whole", mesh, layer="whole_wall")
    with pytest.raises(EmulatorError, match="'strain_layer': 'whole_wall'"):
        mm.subject_forward(whole, real)
    angles = _stand_in_subject_emulator(tmp_path / "angles", mesh, alpha_epi=90.0)
    with pytest.raises(EmulatorError, match="'alpha_epi': 90.0"):
        mm.subject_forward(angles, real)
    fwd = mm.subject_forward(_stand_in_subject_emulator(tmp_path / "ok", mesh), real)
    assert fwd.input_names == THETA_NAMES and fwd.base == "sliding" and fwd.label == "stand-in-subject"
    with pytest.raises(ValueError, match="needs? a subject emulator.*--subject-emulator REAL-LV=DIR"):
        mm.run_study(sources=("base",), volunteers=[mm.REAL_LV], out=tmp_path / "none")
    with pytest.raises(ValueError, match="not mesh volunteers"):
        mm.run_study(sources=("base",), volunteers=["HV1"], subject_emulators={"HV1": "x"}, out=tmp_path / "x")


def _fake_fit(calls):
    """A stand-in for the batched NUTS fits: per data set, σ_S and errors from the data (plumbing only)."""
    def fit(forward, ys, conditions, truths, eta_trues, *, config, keys):
        calls.append({"label": forward.label, "conditions": conditions, "n": len(ys)})
        n = len(ys)
        spread = np.std(ys[:, 1:] - eta_trues[:, 1:], axis=1)
        out = {m: {"coverage": np.full(n, 0.75), "output_error": spread * (k + 1), "min_ess": np.full(n, 200.0),
                   "max_rhat": np.full(n, 1.01)} for k, m in enumerate(mm.MODELS)}
        out["iid"]["sigma_s"], out["discrepancy"]["sigma_s"] = spread, spread / 2
        return out
    return fit


def test_the_real_lv_is_simulated_fitted_and_summarised_beside_a_volunteer(tmp_path, monkeypatch):
    """FE simulations of HV1 and the real LV (nominal, fibre angles +15°); the fits through a stand-in for the
    sampler (the real LV's on its subject emulator, in a batch of its own; HV1's on the chapter emulator with its
    PC scores as conditions); then a recorded-only run over the folder picks up both."""
    from lvcore.inference import samplers

    emu = _stand_in_subject_emulator(tmp_path / "emu", real_lv_files().template)
    calls = []
    monkeypatch.setattr(mm, "fit_datasets", _fake_fit(calls))
    cfg = samplers.SamplerConfig(num_warmup=5, num_samples=5, num_chains=1)
    kw = dict(sources=("angles",), doses={"angles": (15.0,)}, volunteers=["HV1", mm.REAL_LV], seeds=3, config=cfg,
              out=tmp_path / "work", batch=3)
    res = mm.run_study(**kw, subject_emulators={mm.REAL_LV: emu})
    assert res["complete"] and res["volunteers"] == ["HV1", mm.REAL_LV]
    assert [c["label"] for c in calls] == ["chapter", "stand-in-subject"]
    assert calls[0]["conditions"].shape == (3, 5) and calls[1]["conditions"] is None
    sims = json.loads((tmp_path / "work" / "sims" / "REAL-LV__angles__15.json").read_text())
    assert sims["converged"] and len(sims["outputs"]) == 25
    fits = sorted(p.name for p in (tmp_path / "work" / "fits").glob("*.json"))
    assert fits == ["HV1__angles__15__s3_w5_n5_c1.json", "REAL-LV__angles__15__s3_w5_n5_c1.json"]
    assert res["subject_emulators"] == {mm.REAL_LV: "stand-in-subject"}
    assert res["mesh_volunteers"][mm.REAL_LV]["theta"] == mm.REAL_LV_THETA
    assert "REAL" in res["mesh_volunteers"][mm.REAL_LV]["geometry"]
    assert str(real_lv_files().template.parent) not in json.dumps(res)  # no machine path
    line = mm.source_line({**res, "folder": str(tmp_path / "work")})
    assert "1 SYNTHETIC volunteer(s) (HV1) and REAL-LV (the REAL LV's mesh" in line
    assert "chapter emulator (REAL-LV: through its subject emulator stand-in-subject)" in line
    assert mm.docs_markdown(res).startswith("Shipped run: 1 SYNTHETIC volunteer(s) (HV1) and REAL-LV")
    (row,) = res["rows"]
    assert set(row["per_volunteer"]) == {"HV1", mm.REAL_LV} and row["n_datasets"] == 6
    assert row["per_volunteer"][mm.REAL_LV]["strain_rms"] == pytest.approx(
        mm.strain_rms(sims["outputs"], json.loads((tmp_path / "work" / "sims" / "REAL-LV__none__0.json")
                                                  .read_text())["outputs"]))
    assert len(row["per_volunteer"][mm.REAL_LV]["iid_sigma_s"]) == 3
    calls.clear()
    again = mm.run_study(**kw, recorded_only=True, result_file="recorded.json")  # no subject emulator needed
    assert not calls and again["complete"] and set(again["rows"][0]["per_volunteer"]) == {"HV1", mm.REAL_LV}
    assert again["rows"][0]["per_volunteer"] == row["per_volunteer"]
    assert again["mesh_volunteers"] == res["mesh_volunteers"] and again["subject_emulators"] == {}


def test_cli_takes_the_real_lv_and_its_subject_emulator(capsys):
    from lvcore.cli import main

    assert main(["study", "mismatch", "--volunteers", "HV1,REAL-LV", "--out", "/nonexistent/never"]) == 2
    assert "--subject-emulator REAL-LV=DIR" in capsys.readouterr().err
    assert main(["study", "mismatch", "--volunteers", "REAL-LV", "--subject-emulator", "REAL-LV",
                 "--out", "/nonexistent/never"]) == 2
    assert "expected VOLUNTEER=DIR" in capsys.readouterr().err
