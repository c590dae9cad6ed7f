"""The fibre-angle BO study end to end on tiny budgets (closed-form stand-in forward; one simulator run)."""
import json

import numpy as np
import pytest

from lvcore.mechanics.forward import SimulatorForward
from lvcore.studies import bo_fibres as bf
from lvcore.testing.analytic import AnalyticForward


class CountingForward(AnalyticForward):
    """The analytic stand-in, counting points and optionally stopping (a killed run) after ``stop_after`` points."""

    def __init__(self, names, stop_after=None):
        super().__init__(input_names=names)
        object.__setattr__(self, "_count", [0])
        object.__setattr__(self, "_stop", stop_after)

    def evaluate(self, inputs):
        n = np.size(next(iter(inputs.values())))
        if self._stop is not None and self._count[0] + n > self._stop:
            raise KeyboardInterrupt("killed")
        self._count[0] += n
        return super().evaluate(inputs)


@pytest.fixture(scope="module")
def subject():
    return bf.load_subject("SYNTHETIC-HV2")


def test_resume_after_kill_gives_the_uninterrupted_result(subject, tmp_path):
    names = bf.bo_space("free").names
    kw = dict(n_initial=8, n_iterations=6, seed=3)
    ref = bf.run_one(subject, "free", state_dir=tmp_path / "a", forward=CountingForward(names), **kw)
    killed = CountingForward(names, stop_after=11)   # dies during the 4th BO iteration
    with pytest.raises(KeyboardInterrupt):
        bf.run_one(subject, "free", state_dir=tmp_path / "b", forward=killed, **kw)
    state = json.loads((tmp_path / "b" / f"{subject.stem}_free.json").read_text())
    assert len(state["X"]) == 11
    again = CountingForward(names)
    res = bf.run_one(subject, "free", state_dir=tmp_path / "b", forward=again, **kw)
    assert again._count[0] == 14 - 11              # no evaluation repeated
    assert res["fresh_evaluations"] == 3 and res["evaluations"] == 14
    for k in ("theta", "alpha_endo", "alpha_epi", "lvv_abs_error_ml", "median_abs_strain_error", "convergence"):
        assert res[k] == ref[k], k


def test_state_of_other_settings_is_refused(subject, tmp_path):
    names = bf.bo_space("fixed").names
    bf.run_one(subject, "fixed", state_dir=tmp_path, forward=CountingForward(names), n_initial=5, n_iterations=0)
    with pytest.raises(bf.StudyStateError, match="other settings"):
        bf.run_one(subject, "fixed", state_dir=tmp_path, forward=CountingForward(names), n_initial=6, n_iterations=0)


def test_study_writes_the_issue_format(tmp_path):
    fac = lambda s, m: AnalyticForward(input_names=bf.bo_space(m).names)  # noqa: E731
    entries = bf.run_study(["SYNTHETIC-HV1"], out=tmp_path, n_initial=6, n_iterations=2, forward_factory=fac)
    data = json.loads((tmp_path / "bo_fibres.json").read_text())
    assert [e["mode"] for e in data] == ["fixed", "free"] and data == entries
    for e in data:
        assert {"subject", "mode", "theta", "alpha_endo", "alpha_epi", "lvv_abs_error_ml", "median_abs_strain_error",
                "evaluations", "failed_evaluations", "seconds"} <= set(e)
        assert set(e["theta"]) == {"a", "b", "af", "bf"} and e["evaluations"] == 8
        assert set(e["failed_evaluations"]) == {"count", "reasons"}
    assert (data[0]["alpha_endo"], data[0]["alpha_epi"]) == bf.FIXED_ANGLES
    meta = json.loads((tmp_path / "bo_fibres_meta.json").read_text())
    assert "REDUCED" in meta["budget"]["label"] and not meta["budget"]["chapter_budget"]
    assert meta["findings"]["n_subjects_both_modes"] == 1
    assert (tmp_path / "tables.csv").read_text().startswith("subject,fixed_a")
    assert (tmp_path / "fig_convergence.html").is_file() and (tmp_path / "fig_strain_residuals.html").is_file()


def test_simulator_forward_reads_the_mode_inputs(subject):
    f = bf.simulator_forward(subject, "free", resolution="fast")
    assert isinstance(f, SimulatorForward) and f.input_names == ("a", "b", "af", "bf", "alpha_endo", "alpha_epi")
    g = bf.simulator_forward(subject, "fixed", resolution="fast")
    assert g.conditions == {"alpha_endo": -60.0, "alpha_epi": 90.0}


def test_unknown_subject_names_the_bundled_ones():
    with pytest.raises(bf.LVCoreError, match="SYNTHETIC-HV1"):
        bf.load_subject("SYNTHETIC-HV99")


@pytest.mark.slow
def test_tiny_simulator_run_records_failures_and_best(subject, tmp_path):
    e = bf.run_one(subject, "fixed", n_initial=3, n_iterations=1, resolution="fast", state_dir=tmp_path)
    assert e["evaluations"] == 4 and e["failed_evaluations"]["count"] <= 4
    assert np.isfinite(e["lvv_abs_error_ml"])


def test_cli_names_a_bad_subject(tmp_path, capsys):
    from lvcore.cli import main

    assert main(["study", "bo-fibres", "--subjects", "SYNTHETIC-HV99", "--out", str(tmp_path)]) == 2
    assert "SYNTHETIC-HV1" in capsys.readouterr().err


def test_the_regularised_objective_is_recorded_and_a_chapter_state_is_not_resumed_with_it(subject, tmp_path):
    names = bf.bo_space("free").names
    kw = dict(n_initial=6, n_iterations=2, seed=1, state_dir=tmp_path)
    chapter = bf.run_one(subject, "free", forward=CountingForward(names), **kw)
    assert chapter["objective"] == "chapter" and "chi2_best" not in chapter
    with pytest.raises(bf.StudyStateError, match="other settings"):
        bf.run_one(subject, "free", forward=CountingForward(names), objective="posterior", **kw)
    post = bf.run_one(subject, "free", forward=CountingForward(names), objective="posterior",
                      **{**kw, "state_dir": tmp_path / "post"})
    obj = bf.posterior_objective(subject.measured, "free")
    assert set(obj.normal_prior) == {"alpha_endo", "alpha_epi"} and set(obj.log_prior) == {"a", "b", "af", "bf"}
    assert not bf.posterior_objective(subject.measured, "fixed").normal_prior   # fixed angles carry no prior
    x = np.array([[post["theta"][n] for n in names[:4]] + [post["alpha_endo"], post["alpha_epi"]]])
    assert post["prior_penalty_best"] == pytest.approx(obj.penalty(names, x)[0])
    assert post["objective_best"] == pytest.approx(post["chi2_best"] + post["prior_penalty_best"])
    with pytest.raises(bf.LVCoreError, match="objective must be one of"):
        bf.run_one(subject, "free", forward=CountingForward(names), objective="map", **kw)
