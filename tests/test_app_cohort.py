"""The Calibration page's Cohort section (lvcore.app.cohort_panel) and the cohort figure."""
from __future__ import annotations

import pytest
from streamlit.testing.v1 import AppTest

from lvcore.app import PAGES_DIR, cohort_panel
from lvcore.inference import hierarchical as hi
from lvcore.viz.inference_figures import cohort_figure
from test_inference_hierarchical import two_group_run


def _record():
    """summary.json's hierarchical section from made-up draws (3 subjects, two groups; not a calibration)."""
    run = two_group_run(400)
    sep = {s: {k: {"q05": 0.3, "median": 1.0, "q95": 3.0} for k in ("a", "b", "af", "bf")} for s in run.subjects}
    return hi.summarise(run, sep)


def test_tables_and_figure_show_the_population_subjects_and_differences():
    rec = _record()
    pop = cohort_panel.population_table(rec)
    assert list(pop["group"].unique()) == ["A", "B"] and len(pop) == 8
    sub = cohort_panel.subject_table(rec)
    assert len(sub) == 12 and sub["shrinkage"].notna().all()
    diff = cohort_panel.difference_table(rec)
    row = diff[diff["parameter"] == "a"].iloc[0]
    assert row["interval excludes 1"] and row["ratio median"] == pytest.approx(2.0, rel=0.05)
    fig = cohort_figure(rec, "a", truth={"S1": 1.0})
    names = [t.name for t in fig.data]
    assert names == ["joint (hierarchical)", "separate fit", "truth (SYNTHETIC)"]
    assert list(fig.data[0].y) == ["S1", "S2", "S3"] and fig.layout.xaxis.type == "log"


def test_the_calibration_page_has_a_cohort_section_that_runs_the_demo(monkeypatch):
    """The page's wiring: the demo button writes a SYNTHETIC cohort and shows what the run returns (the run itself,
    lvcore.inference.hierarchical_cli.calibrate_cohort, is tested with the CLI in test_inference_hierarchical)."""
    calls = []

    def fake_run(csv, out, geometry=None):
        from lvcore.inference.cohort import read_cohort

        calls.append(read_cohort(csv).subjects)
        return {**_record(), "warnings": ["3 of 6 subjects have several loaded states (stand-in warning)"]}

    monkeypatch.setattr(cohort_panel, "run_cohort", fake_run)
    at = AppTest.from_file(str(PAGES_DIR / "5_Calibration.py"), default_timeout=180).run()
    assert not at.exception, at.exception
    assert "Cohort" in [h.value for h in at.header]
    at.button(key="cohort_demo").click().run()
    assert not at.exception, at.exception
    assert not at.error, [e.value for e in at.error]
    assert len(calls) == 1 and len(calls[0]) == cohort_panel.DEMO_SUBJECTS
    assert all(s.startswith("SYNTHETIC") for s in calls[0])
    tables = [d.value for d in at.dataframe]
    subjects = next(t for t in tables if "shrinkage" in t.columns)
    assert list(subjects["subject"].unique()) == ["S1", "S2", "S3"]
    assert any("interval excludes 1" in t.columns for t in tables)
    assert any("several loaded states" in w.value for w in at.warning)   # the run's warnings are shown
