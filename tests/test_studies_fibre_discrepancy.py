"""Fibre-discrepancy study: the pipeline on explicit stand-ins, and the clear error without the emulator."""
import json

import numpy as np
import pytest

from lvcore.core import ForwardBatch
from lvcore.exceptions import EmulatorError
from lvcore.inference import samplers
from lvcore.domain.outputs import THETA_NAMES
from lvcore.studies import fibre_discrepancy as fd
from lvcore.testing.analytic import AnalyticForward


class _NeverCalled:
    input_names = ("a", "b", "af", "bf", "alpha_endo", "alpha_epi")

    def evaluate(self, inputs):
        pytest.fail("must not simulate without an emulator")


def test_missing_chapter_emulator_is_a_clear_error(tmp_path, monkeypatch):
    import lvcore.emulator.io as eio

    monkeypatch.setenv("LVCORE_EMULATORS", str(tmp_path))
    monkeypatch.setattr(eio, "ASSETS_DIR", tmp_path / "none")
    with pytest.raises(EmulatorError, match="emulator 'chapter' not found.*build_emulators.py"):
        fd.run_study(simulator=_NeverCalled())


# The chapter's design (DESIGN.md, fibre-discrepancy study): simulator angles x true theta, noise sigma_V, sigma_S.
CHAPTER_ANGLES = ((-60.0, 90.0), (-30.0, 60.0), (0.0, 90.0))
CHAPTER_THETAS = ((0.1, 5.0, 1.0, 6.0), (0.5, 8.0, 1.5, 6.0), (1.0, 1.0, 1.0, 1.0), (1.0, 5.0, 1.0, 5.0))
SIGMA_V_ML, SIGMA_S = 5.0, 0.03  # the chapter's values, independent of lvcore.domain.conditions
#: SYNTHETIC stand-ins: the "simulator" shifts the strains with the fibre angles; the "emulator" has none.
TRUTH = AnalyticForward(input_names=("a", "b", "af", "bf", "alpha_endo", "alpha_epi"))
EMULATOR = AnalyticForward()


def _simulate(theta, alpha_endo, alpha_epi):
    return np.asarray(TRUTH({**theta, "alpha_endo": alpha_endo, "alpha_epi": alpha_epi}))


def _simulate_at_emulator_angles(theta, alpha_endo, alpha_epi):
    """The control: a simulator that ignores the set's angles and uses the emulator's (-60, 60)."""
    return _simulate(theta, -60.0, 60.0)


class _FunctionSimulator:
    """A forward model over theta and the fibre angles that calls ``fn(theta, alpha_endo, alpha_epi)`` per point."""

    input_names = ("a", "b", "af", "bf", "alpha_endo", "alpha_epi")

    def __init__(self, fn):
        self.fn = fn

    def evaluate(self, inputs):
        n = len(np.atleast_1d(inputs["a"]))
        col = {k: np.atleast_1d(np.asarray(inputs[k], dtype=float)) for k in self.input_names}
        ys = [self.fn({k: float(col[k][i]) for k in THETA_NAMES}, float(col["alpha_endo"][i]),
                      float(col["alpha_epi"][i])) for i in range(n)]
        return ForwardBatch(np.asarray(ys, dtype=float), np.ones(n, dtype=bool), ("",) * n)


def test_test_sets_are_simulated_at_the_chapters_angles_and_theta_with_the_stated_noise():
    calls = []

    def sim(theta, alpha_endo, alpha_epi):
        calls.append((alpha_endo, alpha_epi, tuple(theta[n] for n in THETA_NAMES)))
        return _simulate(theta, alpha_endo, alpha_epi)

    sets = fd.make_test_sets(EMULATOR, simulator=_FunctionSimulator(sim), seed=3)
    design = [(ae, ap, th) for ae, ap in CHAPTER_ANGLES for th in CHAPTER_THETAS]
    assert sorted(calls) == sorted(design) and len(sets) == 12
    for s, call in zip(sets, calls):
        assert (s.alpha_endo, s.alpha_epi, tuple(s.theta[n] for n in THETA_NAMES)) == call
        # the data come from the simulator at the set's own angles ...
        np.testing.assert_allclose(s.z, _simulate(s.theta, s.alpha_endo, s.alpha_epi), rtol=1e-12)
        # ... the benchmark is the emulator (fixed angles) at the true theta
        np.testing.assert_allclose(s.benchmark, np.asarray(EMULATOR(s.theta)), rtol=1e-12)
    # the same theta at other angles: other strain data, the same benchmark
    assert np.abs(sets[0].z[1:] - sets[8].z[1:]).max() > 0.01 and sets[0].z[0] == pytest.approx(sets[8].z[0])
    np.testing.assert_array_equal(sets[0].benchmark, sets[8].benchmark)
    # noise: sigma_V on the volume, sigma_S on each strain, independent across sets
    noise = np.stack([s.y - s.z for s in sets])
    strain, volume = noise[:, 1:].ravel() / SIGMA_S, noise[:, 0] / SIGMA_V_ML
    assert 0.85 < strain.std() < 1.15 and abs(strain.mean()) < 0.2
    assert 0.5 < volume.std() < 1.6
    assert abs(np.corrcoef(noise[:-1, 1:].ravel(), noise[1:, 1:].ravel())[0, 1]) < 0.2
    # a subset of the sets sees exactly the same data as in the full study
    subset = fd.make_test_sets(EMULATOR, simulator=_FunctionSimulator(sim), seed=3, set_indices=(4, 11))
    assert [s.index for s in subset] == [4, 11]
    np.testing.assert_array_equal(subset[1].y, sets[11].y)


def test_default_test_data_come_from_the_fe_simulator_at_the_set_angles(monkeypatch):
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.mechanics import forward as simulator_forward
    from lvcore.mechanics.case import Case

    cases = []

    class _Result:
        converged, message, seconds, sensitivities = True, "", 0.0, None

        def outputs(self):
            return np.zeros(25)

    def fake_simulate(case, **kwargs):
        cases.append(case)
        return _Result()

    monkeypatch.setattr(simulator_forward, "simulate", fake_simulate)  # what SimulatorForward runs per point
    h = (0.3, -0.2, 0.1, 0.0, 0.4)
    sets = fd.make_test_sets(EMULATOR, h, set_indices=(2, 9), resolution="fast")
    assert len(cases) == 2
    nodes = load_shape_model().reconstruct(np.asarray(h))
    for raw, s in zip(cases, sets):
        case = Case.from_dict(raw)
        assert (case.fibres.alpha_endo_deg, case.fibres.alpha_epi_deg) == (s.alpha_endo, s.alpha_epi)
        assert case.material.law == "holzapfel-ogden"
        assert {n: case.material.params[n] for n in THETA_NAMES} == pytest.approx(s.theta)
        assert case.load.pressure_kpa == pytest.approx(8.0 * 0.133322, rel=1e-5)  # EDP 8 mmHg
        np.testing.assert_allclose(case.geometry.template_nodes, nodes)         # the geometry at h
    assert (sets[0].alpha_endo, sets[1].alpha_endo) == (-60.0, 0.0)


@pytest.fixture(scope="module")
def study_mismatched(tmp_path_factory):
    """The study on sets 0 and 11, SYNTHETIC stand-ins: simulator angles differ from the emulator's."""
    cfg = samplers.SamplerConfig(num_warmup=100, num_samples=100, num_chains=2)
    out = tmp_path_factory.mktemp("fibre_discrepancy")
    return out, fd.run_study(EMULATOR, config=cfg, simulator=_FunctionSimulator(_simulate), out=out, set_indices=(0, 11))


@pytest.fixture(scope="module")
def study_matched():
    """The control: the same sets with the simulator at the emulator's angles (no discrepancy)."""
    cfg = samplers.SamplerConfig(num_warmup=100, num_samples=100, num_chains=2)
    return fd.run_study(EMULATOR, config=cfg, simulator=_FunctionSimulator(_simulate_at_emulator_angles), set_indices=(0, 11))


@pytest.mark.slow
def test_the_three_likelihoods_respond_to_the_angle_discrepancy_as_described(study_mismatched, study_matched):
    _, wrong = study_mismatched
    for w, m in zip(wrong["sets"], study_matched["sets"]):
        assert w["set"] == m["set"] and w["y"][0] == m["y"][0] and w["y"][1:] != m["y"][1:]
        # (i) volume only: the strains are not used, so the wrong strains change nothing
        assert w["models"]["volume"]["theta_median"] == pytest.approx(m["models"]["volume"]["theta_median"],
                                                                      rel=1e-9)
        # (ii) iid: recovers sigma_S without a discrepancy, and absorbs the discrepancy into an inflated sigma_S
        assert m["models"]["iid"]["sigma_s"]["median"] == pytest.approx(SIGMA_S, abs=0.006)
        assert w["models"]["iid"]["sigma_s"]["median"] > 1.3 * m["models"]["iid"]["sigma_s"]["median"]
        # (iii) the polar-GP discrepancy keeps sigma_S near the truth either way
        for run in (w, m):
            assert run["models"]["discrepancy"]["sigma_s"]["median"] == pytest.approx(SIGMA_S, abs=0.01)
    assert wrong["findings"]["iid_inflates_sigma_s_about_2x"]
    assert not study_matched["findings"]["iid_inflates_sigma_s_about_2x"]
    assert wrong["findings"]["discrepancy_sigma_s_near_truth"] and study_matched["findings"]["discrepancy_sigma_s_near_truth"]


@pytest.mark.slow
def test_study_pipeline_on_stand_ins(study_mismatched):
    """SYNTHETIC stand-ins passed explicitly: the 'simulator' shifts strains with the fibre angles."""
    tmp_path, res = study_mismatched
    assert [s["set"] for s in res["sets"]] == [0, 11]
    assert res["sets"][1]["alpha_endo"] == 0.0 and res["sets"][1]["theta"]["bf"] == 5.0
    for s in res["sets"]:
        assert set(s["models"]) == {"volume", "iid", "discrepancy"}
        assert len(s["models"]["discrepancy"]["strain_predictive"]["q50"]) == 24
        assert "sigma_s" not in s["models"]["volume"]
        for m in ("volume", "iid", "discrepancy"):  # Fig 9.8: eta(theta_post, h) bands of all 25 outputs
            q = s["models"][m]["eta_quantiles"]
            assert len(q["q50"]) == 25 and np.all(np.asarray(q["q05"]) <= np.asarray(q["q95"]))
        assert 0 < len(s["models"]["iid"]["sigma_s"]["draws"]) <= 200  # Fig 9.7 density
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


def test_docs_quote_the_shipped_json():
    """docs/calibration.md's shipped-run block is exactly fd.docs_markdown of the shipped JSON, so every
    number it quotes comes from assets/studies/fibre_discrepancy.json; and the shipped run is the current
    chapter emulator (default mesh, sliding base), reproducible by the documented script."""
    from pathlib import Path

    from lvcore.studies.results import bundled_studies_dir

    shipped = fd.load(bundled_studies_dir())
    doc = (Path(__file__).resolve().parents[1] / "docs" / "calibration.md").read_text()
    assert doc.count(fd.DOCS_BEGIN) == 1 and doc.count(fd.DOCS_END) == 1
    block = doc.split(fd.DOCS_BEGIN)[1].split(fd.DOCS_END)[0].strip()
    assert block == fd.docs_markdown(shipped).strip(), "re-run fd.docs_markdown on the shipped JSON into the docs"
    build = shipped["forward_build"]
    assert (build["name"], build["resolution"], build["base"]) == ("chapter", "default", "sliding")
    assert shipped["shipped"]["script"] == "scripts/ship_fibre_discrepancy.py"
