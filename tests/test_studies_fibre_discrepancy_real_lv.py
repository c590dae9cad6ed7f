"""The fibre-discrepancy study on a subject mesh (the shipped real LV): wiring, regional spread, σ_S inflation."""
from pathlib import Path

import numpy as np
import pytest

from lvcore.core import ForwardBatch
from lvcore.domain.outputs import THETA_NAMES
from lvcore.exceptions import EmulatorError
from lvcore.resources import real_lv_files
from lvcore.studies import fibre_discrepancy as fd
from lvcore.studies import fibre_discrepancy_real_lv as rl


def _random_subject_emulator(directory: Path, mesh: Path):
    """An UNTRAINED subject emulator (random weights) of ``mesh``, saved in ``directory``: plumbing only."""
    from lvcore.emulator.io import save_emulator
    from lvcore.emulator.model import Emulator
    from lvcore.emulator.network import MLP
    from lvcore.emulator.subject import subject_space

    space = subject_space(("theta",))
    emu = Emulator(name="stand-in-subject", input_names=THETA_NAMES, lower=np.asarray(space.lower),
                   upper=np.asarray(space.upper), log_inputs=(True,) * 4, x_mean=np.zeros(4), x_sd=np.ones(4),
                   y_mean=np.r_[100.0, np.full(24, -0.15)], y_sd=np.r_[20.0, np.full(24, 0.03)],
                   network=MLP(4, 25, (8, 8), seed=1), fixed=space.fixed_dict(),
                   metadata={"source": {"space": space.to_dict(), "resolution": ["fast"]},
                             "subject": {"geometry": {"kind": "mesh", "path": str(mesh)}}})
    save_emulator(emu, directory)
    return directory


class _Stop(Exception):
    pass


def test_geometry_option_wires_the_mesh_to_the_data_simulator_and_the_emulator(tmp_path, monkeypatch):
    from lvcore.geometry.io import read_template_mesh
    from lvcore.mechanics import forward as simulator_forward
    from lvcore.mechanics.case import Case

    mesh = real_lv_files().template
    emu_dir = _random_subject_emulator(tmp_path / "emu", mesh)
    section = fd.geometry_section(fd.REAL_LV)
    assert Path(section["path"]) == mesh
    seen = {}

    def fake_sets(forward, h, **kw):
        seen.update(forward=forward, **kw)
        raise _Stop

    monkeypatch.setattr(fd, "make_test_sets", fake_sets)
    with pytest.raises(_Stop):
        fd.run_study(emulator=str(emu_dir), geometry=fd.REAL_LV)
    assert seen["geometry"] == section
    emulator = seen["forward"].emulator
    assert emulator.is_subject and emulator.name == "stand-in-subject" and seen["forward"].base == "sliding"
    monkeypatch.undo()

    cases = []

    class _Result:
        converged, message, seconds, sensitivities = True, "", 0.0, None

        def outputs(self):
            return np.zeros(25)

    monkeypatch.setattr(simulator_forward, "simulate", lambda case, **kw: cases.append(case) or _Result())
    sets = fd.make_test_sets(seen["forward"], set_indices=(2, 9), resolution="fast", geometry=section)
    nodes = read_template_mesh(mesh)
    for raw, s in zip(cases, sets):
        case = Case.from_dict(raw)
        np.testing.assert_allclose(case.geometry.template_nodes, nodes)  # the real LV, not the PCA geometry h
        assert (case.fibres.alpha_endo_deg, case.fibres.alpha_epi_deg) == (s.alpha_endo, s.alpha_epi)
        assert case.boundary.base == "sliding"                             # the emulator's own basal condition
    assert len(cases) == 2


def test_a_subject_mesh_needs_a_subject_emulator_of_that_mesh(tmp_path):
    from lvcore.resources import volunteer_files

    section = fd.geometry_section(fd.REAL_LV)
    with pytest.raises(EmulatorError, match="takes PC scores; a subject mesh needs a subject emulator"):
        fd.subject_forward("chapter", section)
    other = _random_subject_emulator(tmp_path / "other", volunteer_files("SYNTHETIC_HV1").geometry)
    with pytest.raises(EmulatorError, match="trained on another geometry"):
        fd.subject_forward(str(other), section)
    assert fd.subject_forward(str(_random_subject_emulator(tmp_path / "ok", real_lv_files().template)),
                              section).input_names == THETA_NAMES


class _AngleSimulator:
    """SYNTHETIC: strains shift with alpha_epi by region-dependent amounts, LVV by a constant."""

    input_names = THETA_NAMES + ("alpha_endo", "alpha_epi")

    def evaluate(self, inputs):
        a = np.atleast_1d(np.asarray(inputs["alpha_epi"], dtype=float))
        base = np.r_[100.0, np.linspace(-0.2, -0.1, 24)]
        ys = np.stack([base + (v - 60.0) / 30.0 * np.r_[2.0, np.linspace(-0.03, 0.03, 24)] for v in a])
        return ForwardBatch(ys, np.ones(a.size, bool), ("",) * a.size)


def test_regional_change_is_the_strain_change_and_its_spread_over_the_regions():
    r = rl.regional_change(_AngleSimulator(), dict(zip(THETA_NAMES, (1.0, 5.0, 1.0, 5.0))))
    d = np.linspace(-0.03, 0.03, 24)
    np.testing.assert_allclose(r["delta_strain"], d, atol=1e-12)
    assert r["delta_lvv_ml"] == pytest.approx(2.0) and r["mean"] == pytest.approx(0.0, abs=1e-12)
    assert r["spread"] == pytest.approx(d.std())
    known = np.r_[105.0, np.full(24, -0.1)]
    r2 = rl.regional_change(_AngleSimulator(), dict(zip(THETA_NAMES, (1.0, 5.0, 1.0, 5.0))), to_outputs=known)
    assert r2["delta_lvv_ml"] == pytest.approx(5.0) and r2["lvv_from_ml"] == pytest.approx(100.0)


def test_bootstrap_median_resamples_the_units():
    v = np.array([0.03, 0.033, 0.036, 0.06, 0.09, 0.03, 0.031, 0.045, 0.05, 0.07, 0.04, 0.032])
    b = rl.bootstrap_median(v, scale=0.03, n_boot=2000, seed=1)
    assert b["estimate"] == pytest.approx(np.median(v) / 0.03) and b["n"] == 12
    assert b["lo"] < b["estimate"] < b["hi"] and b["lo"] >= v.min() / 0.03 and b["hi"] <= v.max() / 0.03
    assert rl.bootstrap_median(np.full(12, 0.03), scale=0.03)["hi"] == pytest.approx(1.0)


def _fake_study(inflate: float) -> dict:
    sets = []
    for i, ((ae, ap), th) in enumerate((a, t) for a in ((-60.0, 90.0), (-30.0, 60.0), (0.0, 90.0))
                                       for t in fd.THETA_SETS):
        models = {m: {"rhat_max": 1.01, "abs_error_median": 0.01, "theta_median": {}} for m in fd.MODELS}
        for m, sig in (("iid", 0.03 * inflate * (1 + 0.01 * i)), ("discrepancy", 0.03)):
            models[m]["sigma_s"] = {"median": sig, "q05": sig * 0.9, "q95": sig * 1.1}
        sets.append({"set": i, "alpha_endo": ae, "alpha_epi": ap, "theta": dict(zip(THETA_NAMES, th)),
                     "z": [0.0] * 25, "y": [0.0] * 25, "benchmark": [0.0] * 25, "models": models})
    return {"sets": sets, "findings": {"median_abs_error": {"volume": 0.01, "iid": 0.02, "discrepancy": 0.01}},
            "error_draws": {m: [0.01] * (12 * 10) for m in fd.MODELS}, "sampler": {"num_chains": 2}}


def test_assembled_result_reports_spread_and_inflation_per_layer():
    sim = _AngleSimulator()
    real = rl.regional_changes(sim, fd.THETA_SETS)
    res = rl.assemble({"inner_half": {"study": _fake_study(2.0), "regional": real, "emulator": {"name": "x"}}},
                      {"inner_half": {"SYNTHETIC h": real[:2]}})
    res["folder"] = "somewhere"
    s = res["layers"]["inner_half"]["summary"]
    assert s["iid_sigma_s_inflation"]["estimate"] == pytest.approx(2.0 * (1 + 0.01 * 5.5), rel=1e-9)
    assert s["discrepancy_sigma_s"]["estimate"] == pytest.approx(0.03)
    tab = rl.tables(res)["table_real_lv_findings"]
    assert tab.loc[0, "regional spread real LV"] == pytest.approx(np.linspace(-0.03, 0.03, 24).std())
    assert set(rl.figures(res)) == set(rl.TITLES) - {"regional"}
    assert "REAL patient-derived" in rl.source_line(res)
    # a layer with the FE sweeps only (its MCMC not run) is reported as such
    res = rl.assemble({"inner_half": {"study": _fake_study(2.0), "regional": real},
                       "whole_wall": {"study": None, "regional": real, "resolution": "6,2+1+1+2,2,5"}},
                      {"whole_wall": {"SYNTHETIC h": real}}) | {"folder": "somewhere"}
    tab = rl.tables(res)["table_real_lv_findings"]
    assert list(tab["layer"]) == ["inner half", "whole wall"] and tab.loc[1, "iid σ_S inflation [CI]"] == "not run"
    assert "FE sweeps only" in rl.source_line(res) and "whole wall" not in rl.docs_markdown(res).split("\n\n")[2]


def test_the_shipped_result_holds_the_inner_half():
    from lvcore.studies.results import bundled_studies_dir

    res = rl.load(bundled_studies_dir())
    assert "inner_half" in res["layers"] and res["geometry"]["synthetic"] is False
    inner = res["layers"]["inner_half"]
    assert len(inner["regional"]) == 4 and inner["summary"]["n_sets"] == 12
    assert inner["summary"]["iid_sigma_s_inflation"]["lo"] <= inner["summary"]["iid_sigma_s_inflation"]["estimate"]
    assert inner["study"]["sampler"]["num_chains"] >= 2


def test_no_shipped_layer_rests_on_an_unconverged_fit():
    """Every fit of every shipped layer (3 likelihoods x 12 sets) has >= 2 chains and split R-hat <= 1.05, and the
    layers share one sampler budget (comparable); the script's defaults are that budget."""
    from lvcore.studies.results import bundled_studies_dir

    res = rl.load(bundled_studies_dir())
    budgets = set()
    for name, layer in res["layers"].items():
        smp = layer["study"]["sampler"]
        budgets.add((smp["num_chains"], smp["num_warmup"], smp["num_samples"]))
        assert smp["num_chains"] >= 2, name
        rhats = [r["rhat_max"] for s in layer["study"]["sets"] for r in s["models"].values()]
        assert len(rhats) == 36 and max(rhats) <= 1.05 and layer["summary"]["rhat_max"] == max(rhats), name
    assert len(budgets) == 1
    text = (Path(__file__).resolve().parent.parent / "scripts" / "ship_fibre_discrepancy_real_lv.py").read_text()
    chains, warmup, samples = budgets.pop()
    for opt, value in (("warmup", warmup), ("samples", samples), ("chains", chains)):
        assert f'"--{opt}", type=int, default={value},' in text, opt


def test_docs_quote_the_shipped_result():
    from lvcore.studies.results import bundled_studies_dir

    text = (Path(__file__).resolve().parent.parent / "docs" / "studies.md").read_text()
    block = text.split(rl.DOCS_BEGIN)[1].split(rl.DOCS_END)[0].strip()
    assert block == rl.docs_markdown(rl.load(bundled_studies_dir())).strip(), (
        "docs/studies.md's real-LV block is stale: python scripts/ship_fibre_discrepancy_real_lv.py --steps docs")
