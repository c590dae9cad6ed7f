"""The strain layer recorded everywhere a result is written (case, forward, store, emulator, calibration) and data
declared in another layer than the emulator's refused (lvcore.inference.strain_layers)."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from lvcore.cli import main
from lvcore.domain.outputs import OUTPUT_COLUMNS
from lvcore.emulator.io import load_emulator
from lvcore.exceptions import CampaignError, CaseError, DataError, EmulatorError, ForwardError
from lvcore.inference import guards
from lvcore.inference.data import read_measurements
from lvcore.inference.request import build_request
from lvcore.inference.strain_layers import check_strain_layer, declared_strain_layer
from lvcore.mechanics.case_inputs import build_case
from lvcore.mechanics.forward import SimulatorForward

THETA = {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}
Y = [150.0] + [-0.12] * 24


def _csv(tmp_path, layers=("whole_wall",), name="m.csv"):
    p = tmp_path / name
    rows = [f"S{i},{','.join(map(str, Y))},{layer}" for i, layer in enumerate(layers)]
    p.write_text("subject," + ",".join(OUTPUT_COLUMNS) + ",strain_layer\n" + "\n".join(rows) + "\n")
    return p


def test_a_file_declares_its_layer_in_each_format(tmp_path):
    import scipy.io

    (row,) = read_measurements(_csv(tmp_path))
    assert row.strain_layer == "whole_wall" and np.allclose(row.y, Y)   # the column is not a data column
    assert [r.strain_layer for r in read_measurements(_csv(tmp_path, ("wall", "", "whole-wall")))] == ["whole_wall"] * 3
    with pytest.raises(DataError, match="names 2 layers.*split it"):
        declared_strain_layer(_csv(tmp_path, ("inner_half", "outer_half")))
    with pytest.raises(DataError, match="strain layer must be one of"):
        declared_strain_layer(_csv(tmp_path, ("epicardium",)))
    j = tmp_path / "m.json"
    j.write_text(json.dumps({"strain_layer": "mid_wall", "subjects": [{"subject": "S", "lvv_ml": 150,
                                                                     "strains": Y[1:]}]}))
    assert read_measurements(j)[0].strain_layer == "mid_wall"
    m = tmp_path / "m.mat"
    scipy.io.savemat(m, {"lvv_ml": 150.0, "strains": np.array(Y[1:]), "strain_layer": "outer_half"})
    assert read_measurements(m)[0].strain_layer == "outer_half"
    plain = tmp_path / "plain.json"
    plain.write_text(json.dumps({"lvv_ml": 150, "strains": Y[1:]}))
    assert read_measurements(plain)[0].strain_layer is None


def test_the_request_refuses_strains_of_another_layer(tmp_path):
    emulator = load_emulator("chapter")
    assert emulator.strain_layer == "inner_half" == emulator.metadata["strain_layer"]
    mean = guards.GeometrySource(np.zeros(5), "mean", "mean")
    (row,) = read_measurements(_csv(tmp_path))
    with pytest.raises(DataError, match=r"subject S0: the strains are whole wall .* emulator 'chapter' was trained "
                                        r"on strains of the inner half .*--strain-layer whole_wall"):
        build_request(emulator, "chapter", mean, row=row)
    (ok,) = read_measurements(_csv(tmp_path, ("endocardial",)))   # the old name of the inner half
    request = build_request(emulator, "chapter", mean, row=ok)
    assert request.strain_layer == "inner_half" and request.record()["strain_layer"] == "inner_half"
    with pytest.raises(DataError, match="declares its strains as inner_half but --strain-layer says outer_half"):
        build_request(emulator, "chapter", mean, row=ok, strain_layer="outer_half")
    with pytest.raises(DataError, match="outer half"):
        build_request(emulator, "chapter", mean, strain_layer="outer_half")   # undeclared data, the option
    assert check_strain_layer(emulator, "chapter") == "inner_half"   # nothing declared: the emulator's own


def test_calibrate_exits_2_on_another_layer(tmp_path, capsys):
    code = main(["calibrate", "--data", str(_csv(tmp_path)), "--geometry", "mean", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "whole wall" in err and "inner half" in err and "lvcore emulator train" in err
    code = main(["calibrate", "--data", str(_csv(tmp_path, ("",))), "--geometry", "mean", "--strain-layer",
                 "mid_wall", "--out", str(tmp_path / "o")])
    assert code == 2 and "mid-wall" in capsys.readouterr().err


def test_emulator_metadata_keeps_its_layer(tmp_path):
    for name in ("chapter", "angles"):
        assert load_emulator(name).metadata["strain_layer"] == "inner_half"
    from lvcore.emulator.io import resolve_emulator_dir

    d = tmp_path / "e"
    d.mkdir()
    for f in ("metadata.json", "network.npz"):
        shutil.copy(resolve_emulator_dir("chapter") / f, d / f)
    meta = json.loads((d / "metadata.json").read_text())
    del meta["strain_layer"]   # built before the layer was recorded: the simulator's default
    (d / "metadata.json").write_text(json.dumps(meta))
    emu = load_emulator(d)
    assert emu.strain_layer == "inner_half" and emu.simulator().strain_layer == "inner_half"
    meta["strain_layer"] = "wall"
    (d / "metadata.json").write_text(json.dumps(meta))
    assert load_emulator(d).strain_layer == "whole_wall"
    meta["strain_layer"] = "subendocardium"
    (d / "metadata.json").write_text(json.dumps(meta))
    with pytest.raises(EmulatorError, match="strain_layer"):
        load_emulator(d)


def test_cases_and_simulator_forwards_carry_the_layer():
    assert "outputs" not in build_case(THETA)   # the default: every earlier store's cases unchanged
    assert build_case(THETA, strain_layer="wall")["outputs"] == {"strain_layer": "whole_wall"}
    with pytest.raises(CaseError, match="outputs.strain_layer"):
        build_case(THETA, strain_layer="inner")
    fwd = SimulatorForward(strain_layer="outer_half", resolution="fast")
    assert fwd.case(THETA)["outputs"] == {"strain_layer": "outer_half"}
    with pytest.raises(ForwardError, match="strain layer"):
        SimulatorForward(strain_layer="inner")


def test_stores_record_the_layer_and_training_refuses_a_mix(tmp_path):
    import h5py

    from executor_double import InlineExecutor
    import campaign_double
    from lvcore.campaigns.designs import make_design
    from lvcore.campaigns.runner import campaign_status, run_campaign, with_strain_layer
    from lvcore.campaigns.space import get_space
    from lvcore.campaigns.store import read_store
    from lvcore.emulator.training import load_store_data

    design = make_design(get_space("material"), "sobol", 4, seed=0)
    for name in ("a.h5", "b.h5"):
        run_campaign(design, tmp_path / name, executor=InlineExecutor(), forward=campaign_double.NAME,
                     progress=False)
    assert read_store(tmp_path / "a.h5").strain_layer == "inner_half"
    assert "strains over the inner half" in campaign_status(tmp_path / "a.h5").format()
    assert load_store_data([tmp_path / "a.h5"]).info["strain_layer"] == "inner_half"
    with pytest.raises(CampaignError, match="has no strain layer"):
        run_campaign(design, tmp_path / "c.h5", executor=InlineExecutor(), forward=campaign_double.NAME,
                     progress=False, strain_layer="whole_wall")
    assert with_strain_layer(SimulatorForward(), "whole_wall").strain_layer == "whole_wall"
    with h5py.File(tmp_path / "b.h5", "r+") as f:
        f.attrs["strain_layer"] = "whole_wall"
    with pytest.raises(EmulatorError, match="different wall layers"):
        load_store_data([tmp_path / "a.h5", tmp_path / "b.h5"])
    with h5py.File(tmp_path / "b.h5", "r+") as f:
        del f.attrs["strain_layer"]   # a store written before the layer was recorded: the inner half
    assert read_store(tmp_path / "b.h5").strain_layer == "inner_half"


def test_subject_emulator_builds_take_the_layer():
    """``lvcore emulator build --strain-layer``: the FE runs use the layer, their checkpoint knows it, and a prior
    mean of another layer is refused (named) or passed over (auto)."""
    from lvcore.emulator.subject import subject_space
    from lvcore.emulator.subject_prior import choose_prior
    from lvcore.emulator.subject_runs import _runs_signature, simulate_rows
    from lvcore.mechanics.case import Case
    from lvcore.mechanics.simulate import simulate

    space = subject_space(("theta",))
    section = {"kind": "default"}
    assert _runs_signature(space, section, "fast") == _runs_signature(space, section, "fast", "inner_half")
    assert _runs_signature(space, section, "fast", "whole_wall") != _runs_signature(space, section, "fast")
    with pytest.raises(EmulatorError, match="its strains are inner_half, the FE runs' whole_wall"):
        choose_prior(space, section, "chapter", strain_layer="whole_wall")
    prior, record = choose_prior(space, section, "auto", strain_layer="whole_wall")
    assert prior is None and "its strains are inner_half" in record["rejected"]["chapter"]
    runs = simulate_rows(space, np.array([[THETA[n] for n in space.names]]), section, resolution="fast", workers=1,
                         strain_layer="whole_wall")
    case = Case.from_dict(SimulatorForward(input_names=space.names, conditions=space.fixed_dict(),
                                           geometry=section, resolution="fast", base=space.base,
                                           strain_layer="whole_wall").case(THETA))
    np.testing.assert_allclose(runs.outputs[0], simulate(case).outputs(), rtol=1e-9, atol=1e-12)
