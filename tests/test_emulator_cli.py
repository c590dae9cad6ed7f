"""`lvcore emulator train|info` on a campaign store (forward model: the campaign TEST DOUBLE)."""
import json

import numpy as np
import pytest

import campaign_double
from campaign_double import closed_form
from executor_double import InlineExecutor
from lvcore.campaigns.designs import make_design
from lvcore.campaigns.runner import run_campaign
from lvcore.campaigns.space import get_space
from lvcore.cli import main
from lvcore.emulator.cli import parse_architectures
from lvcore.emulator.io import load_emulator
from lvcore.exceptions import EmulatorError


def test_train_from_store_and_info(tmp_path, capsys):
    space = get_space("material")
    for name, n, seed in (("train", 256, 1), ("test", 64, 2)):
        run_campaign(make_design(space, "sobol", n, seed), tmp_path / f"{name}.h5", executor=InlineExecutor(),
                     forward=campaign_double.NAME, progress=False)
    out = tmp_path / "emu"
    rc = main(["emulator", "train", str(tmp_path / "train.h5"), "--out", str(out), "--inputs", "a", "b", "af", "bf",
               "--test", str(tmp_path / "test.h5"), "--architectures", "20x20", "--max-epochs", "300",
               "--batch-size", "64", "--seed", "1"])
    assert rc == 0
    emu = load_emulator(out)
    assert emu.input_names == ("a", "b", "af", "bf") and emu.name == "emu"
    assert emu.fixed == {"alpha_endo": -60.0, "alpha_epi": 60.0, "edp": 8.0}
    np.testing.assert_allclose(emu.lower, space.lower) and np.testing.assert_allclose(emu.upper, space.upper)
    meta = emu.metadata
    assert meta["training"]["n_train"] + meta["training"]["n_valid"] == 256
    assert meta["source"]["forward"] == [campaign_double.NAME]
    # store paths relative to --out: a store outside it by its name; no path of this machine (issue 23)
    assert meta["source"]["stores"] == ["train.h5"] and str(tmp_path) not in json.dumps(meta)
    assert meta["test"]["n"] == 64 and meta["test"]["lvv_rmse_ml"] < 1.0
    x = np.array([0.6, 1.3, 1.0, 3.6])
    assert abs(float(emu.predict(x)[0]) - closed_form(*x)[0]) < 1.5
    capsys.readouterr()
    assert main(["emulator", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "LVV RMSE" in text and "(log scale)" in text
    assert f"base {space.base}" in text and emu.base == space.base   # the training simulations' base condition
    assert main(["emulator", "info", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["name"] == "emu"
    # an input that varies in the data cannot be dropped
    assert main(["emulator", "train", str(tmp_path / "train.h5"), "--out", str(tmp_path / "x"), "--inputs", "a", "b"]) == 2


def test_parse_architectures():
    assert len(parse_architectures("all")) == 16
    assert parse_architectures("50x100,200x200") == ((50, 100), (200, 200))
    with pytest.raises(EmulatorError):
        parse_architectures("50-100")
