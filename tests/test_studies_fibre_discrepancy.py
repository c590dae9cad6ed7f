"""Fibre-discrepancy study: the pipeline on explicit stand-ins, and the clear error without the emulator."""
import json

import numpy as np
import pytest

from lvcore.exceptions import EmulatorError
from lvcore.inference import samplers
from lvcore.core import AnalyticForward
from lvcore.studies import fibre_discrepancy as fd


class _NeverCalled:
    input_names = ("a", "b", "af", "bf", "alpha_endo", "alpha_epi")

    def evaluate(self, inputs, jacobian=False):
        pytest.fail("must not simulate without an emulator")


def test_missing_chapter_emulator_is_a_clear_error(tmp_path, monkeypatch):
    import lvcore.emulator.io as eio

    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))
    monkeypatch.setattr(eio, "ASSETS_DIR", tmp_path / "none")
    with pytest.raises(EmulatorError, match="emulator 'chapter' not found.*build_emulators.py"):
        fd.run_study(simulator=_NeverCalled())


def test_design_is_the_chapters():
    assert len(fd.ANGLE_SETS) * len(fd.THETA_SETS) == 12
    assert (0.0, 90.0) in fd.ANGLE_SETS and (0.5, 8.0, 1.5, 6.0) in fd.THETA_SETS


def test_study_pipeline_on_stand_ins(tmp_path):
    """SYNTHETIC stand-ins passed explicitly: the 'simulator' shifts strains with the fibre angles."""
    truth = AnalyticForward(input_names=("a", "b", "af", "bf", "alpha_endo", "alpha_epi"))
    cfg = samplers.SamplerConfig(num_warmup=100, num_samples=100, num_chains=2)
    res = fd.run_study(AnalyticForward(), config=cfg, simulator=truth, out=tmp_path, set_indices=(0, 11))
    assert [s["set"] for s in res["sets"]] == [0, 11]
    assert res["sets"][1]["alpha_endo"] == 0.0 and res["sets"][1]["theta"]["bf"] == 5.0
    for s in res["sets"]:
        assert set(s["models"]) == {"volume", "iid", "discrepancy"}
        assert len(s["models"]["discrepancy"]["strain_predictive"]["q50"]) == 24
        assert "sigma_s" not in s["models"]["volume"]
    # set 11 has angles (0, 90): a strain discrepancy the iid model can only absorb into noise
    s11 = res["sets"][1]["models"]
    assert s11["iid"]["sigma_s"]["median"] > s11["discrepancy"]["sigma_s"]["median"]
    f = res["findings"]
    assert set(f["median_abs_error"]) == {"volume", "iid", "discrepancy"}
    saved = json.loads((tmp_path / "fibre_discrepancy.json").read_text())
    assert saved["synthetic"] is True
    for name in ("strain_predictive.csv", "sigma_s.csv", "errors.csv", "fig_strain_predictive.html",
                 "fig_errors_violin.html"):
        assert (tmp_path / name).is_file()
