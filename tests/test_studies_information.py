"""The information study's presentation (lvcore.studies.information): its result file read, tabled and drawn."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from lvcore.exceptions import LVCoreError
from lvcore.studies import information as inf
from lvcore.studies import registry

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "assets" / "studies" / inf.RESULT_FILE
THETA = ("a", "b", "af", "bf")


def _run(variant, subject, *, a_lo, a_hi, v30=True, exit_code=0, converged=True):
    truth = {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6, "V20": 250.0, "V30": 270.0}
    q05 = {"a": a_lo, "b": 1.0, "af": 0.8, "bf": 3.0}
    med = {"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}
    q95 = {"a": a_hi, "b": 1.8, "af": 1.2, "bf": 4.2}
    if v30:
        q05.update(V20=235.0, V30=240.0)
        med.update(V20=250.0, V30=268.0)
        q95.update(V20=262.0, V30=300.0)
    else:
        truth = {k: v for k, v in truth.items() if k in THETA}
    return {"variant": variant, "subject": subject, "exit": exit_code, "converged": converged, "wall_s": 31.2,
            "truth": truth, "q05": q05, "median": med, "q95": q95}


def _variant(key, part, label, *, states=None, prior="none", method="separate", cohort_size=None, reference,
             narrowing=None, v30=True, hierarchical=False):
    cov = {"a": 1.0, "b": 0.5, "af": 1.0, "bf": 1.0, "all4": 0.5}
    v = {"key": key, "part": part, "label": label, "states_mmhg": states, "prior": prior, "method": method,
         "cohort_size": cohort_size, "reference": reference, "n_runs": 2, "n_calibrated": 2,
         "exit_codes": {"0": 1, "4": 1}, "converged_share": 1.0,
         "a_ratio": {"median": 10.0, "min": 8.0, "max": 12.0}, "narrowing": narrowing,
         "coverage_90": cov, "coverage_90_ci": {k: [0.34, 1.0] for k in cov},
         "v30_width_ml": {"median": 60.0, "min": 55.0, "max": 65.0} if v30 else None,
         "v30_coverage_90": 1.0 if v30 else None,
         "v20_width_ml": {"median": 27.0, "min": 25.0, "max": 29.0} if v30 else None,
         "v20_coverage_90": 1.0 if v30 else None}
    if hierarchical:
        diag = {"max_rhat": 1.01, "min_ess_bulk": 300.0, "n_divergent": 0, "converged": True}
        v.update(mu_covered=dict.fromkeys(THETA, True), diagnostics={"population": diag, "subjects": diag})
    return v


def fake_result() -> dict:
    """A small result in the runner's schema: 2 states variants, 2 cohort variants (one without V30), 8 runs."""
    variants = [
        _variant("states-8", "states", "8 mmHg", states=[8.0], reference="states-8",
                 narrowing={"median": 1.0, "min": 1.0, "max": 1.0}),
        _variant("states-8-20-klotz", "states", "8 + 20 mmHg", states=[8.0, 20.0], prior="klotz",
                 reference="states-8", narrowing={"median": 3.2, "min": 2.5, "max": 4.0}),
        _variant("cohort8-separate", "cohort", "cohort of 8", method="separate", cohort_size=8,
                 reference="cohort8-separate", v30=False),
        _variant("cohort8-hierarchical", "cohort", "cohort of 8", method="hierarchical", cohort_size=8,
                 reference="cohort8-separate", hierarchical=True),
    ]
    runs = []
    for k, (key, width) in enumerate([("states-8", 20.0), ("states-8-20-klotz", 6.0), ("cohort8-separate", 15.0),
                                      ("cohort8-hierarchical", 5.0)]):
        for i in range(2):
            lo = 0.6 / (width ** 0.5) * (1 + 0.1 * i)
            runs.append(_run(key, f"SYNTHETIC-INF-{i:02d}", a_lo=lo, a_hi=lo * width, v30=key != "cohort8-separate",
                             exit_code=4 if i else 0))
    verdicts = [{"claim": "two loaded states (8 + 20 mmHg) narrow a's 90 % interval at least 3x, all four θ covered",
                 "target": ">= 3x", "value": "3.2x (median of 2)", "met": True, "note": "two subjects only"},
                {"claim": "the hierarchical fit narrows a's interval at least 2x per subject", "target": ">= 2x",
                 "value": None, "met": None, "note": None}]
    return {"study": "information", "synthetic": True, "label": inf.SYNTHETIC_LABEL, "complete": False,
            "settings": {"chains": 2, "warmup": 300, "samples": 300, "sigma_v_ml": 5.0, "sigma_s": 0.03, "seed": 0,
                         "n_state_subjects": 2, "state_pressures_mmhg": [8.0, 14.0, 20.0], "cohort_sizes": [8],
                         "state_emulator": {"name": "state", "edp_box_mmhg": [6.0, 30.0],
                                            "heldout_lvv_rmse_ml": 0.7, "heldout_strain_rmse": 0.001},
                         "cohort_emulator": "chapter", "derived_draws": 100},
            "variants": variants, "runs": runs, "verdicts": verdicts,
            "cost": {"wall_s_total": 250.0, "cpu_s_total": 240.0, "wall_s_median_by_variant": {"states-8": 30.0}},
            "notes": ["a note"]}


@pytest.fixture()
def result(tmp_path):
    (tmp_path / inf.RESULT_FILE).write_text(json.dumps(fake_result()))
    return inf.load(tmp_path)


def _no_missing_text(frame) -> list:
    return [(c, v) for c in frame.columns for v in frame[c]
            if v is None or (isinstance(v, float) and v != v) or str(v) in ("None", "nan", "NaN", "null")]


# --------------------------------------------------------------------------- load
def test_load_reads_the_result_and_adds_its_folder(result, tmp_path):
    assert result["folder"] == str(tmp_path) and result["synthetic"] is True and len(result["variants"]) == 4


def test_a_missing_file_is_a_clear_error_naming_it(tmp_path):
    with pytest.raises(LVCoreError, match=inf.RESULT_FILE):
        inf.load(tmp_path)


@pytest.mark.parametrize("text", ["{not json", "[1, 2]", '{"study": "information"}',
                                  '{"study": "sbc", "variants": []}'])
def test_a_malformed_file_is_a_clear_error_naming_it(tmp_path, text):
    (tmp_path / inf.RESULT_FILE).write_text(text)
    with pytest.raises(LVCoreError, match=inf.RESULT_FILE):
        inf.load(tmp_path)


# --------------------------------------------------------------------------- tables
def test_tables_have_their_columns_and_no_missing_value_shown_as_none(result):
    tabs = inf.tables(result)
    assert set(tabs) == set(inf.TITLES)
    variants = tabs["table_information_variants"]
    assert len(variants) == 4
    for col in ("part", "variant", "states (mmHg)", "prior", "method", "subjects", "a q95/q05: median [min–max]",
                "narrowing vs reference: median [min–max]", "coverage a", "coverage b", "coverage af", "coverage bf",
                "coverage all four", "V30 90 % width (mL): median [min–max]", "V30 coverage", "exit codes",
                "converged"):
        assert col in variants.columns, col
    assert list(tabs["verdicts"].columns) == ["claim", "target", "value", "met", "note"]
    assert len(tabs["runs"]) == 8
    for name, frame in tabs.items():
        assert not _no_missing_text(frame), (name, _no_missing_text(frame)[:3])


def test_the_variant_table_says_what_each_number_is(result):
    rows = {r["variant"]: r for r in inf.tables(result)["table_information_variants"].to_dict("records")}
    assert set(rows) == {"8 mmHg", "8 + 20 mmHg, Klotz prior", "cohort of 8, separate", "cohort of 8, hierarchical"}
    klotz = rows["8 + 20 mmHg, Klotz prior"]
    assert klotz["states (mmHg)"] == "8 + 20" and klotz["prior"] == "klotz" and klotz["reference"] == "8 mmHg"
    assert klotz["narrowing vs reference: median [min–max]"] == "3.2× [2.5–4]"
    assert klotz["a q95/q05: median [min–max]"] == "10 [8–12]"
    assert klotz["coverage b"] == "50 % [34, 100]" and klotz["exit codes"] == "0: 1, 4: 1"
    assert rows["8 mmHg"]["narrowing vs reference: median [min–max]"] == "reference"
    separate = rows["cohort of 8, separate"]
    assert separate["V30 90 % width (mL): median [min–max]"] == "–" and separate["V30 coverage"] == "–"
    assert separate["states (mmHg)"] == "–" and separate["population (hierarchical)"] == "–"
    assert "μ covered: a yes" in rows["cohort of 8, hierarchical"]["population (hierarchical)"]


def test_verdicts_say_yes_no_or_not_shown(result):
    rows = inf.tables(result)["verdicts"].to_dict("records")
    assert [r["met"] for r in rows] == ["yes", "not shown"]
    assert rows[1]["value"] == "–" and rows[1]["note"] == "–"


def test_runs_give_a_width_and_coverage_per_subject(result):
    runs = inf.tables(result)["runs"]
    first = runs.iloc[0]
    assert first["a q95/q05"] == pytest.approx(20.0) and first["a covered"] == "yes" and first["b covered"] == "yes"
    assert set(runs.loc[runs["variant"] == "cohort of 8, separate", "V30 90 % width (mL)"]) == {"–"}
    assert inf.width(fake_result()["runs"][0]) == pytest.approx(60.0)
    assert inf.a_ratio({"q05": {}, "q95": {}}) is None


# --------------------------------------------------------------------------- figures
def test_titles_say_synthetic():
    assert all("SYNTHETIC" in t for t in inf.TITLES.values())
    assert "SYNTHETIC" in inf.SYNTHETIC_LABEL


def test_figures_draw_every_subject_on_a_log_axis(result):
    figs = inf.figures(result)
    assert set(figs) == set(inf.TITLES)
    fig = figs["fig_information_a_ratio"]
    assert "SYNTHETIC" in fig.layout.title.text
    assert fig.layout.yaxis.type == "log" and fig.layout.yaxis2.type == "log"  # two panels: states and cohort
    subjects = [t for t in fig.data if t.name != "median over subjects"]
    assert sum(len(t.y) for t in subjects) == 8
    medians = [t for t in fig.data if t.name == "median over subjects"]
    assert len(medians) == 2 and sorted(round(y, 6) for t in medians for y in t.y) == pytest.approx(
        sorted([20.0, 6.0, 15.0, 5.0]))
    assert list(fig.layout.xaxis.ticktext) == ["8 mmHg", "8 + 20 mmHg, Klotz prior"]
    v30 = figs["fig_information_v30_width"]
    assert v30.layout.yaxis.type != "log" and "SYNTHETIC" in v30.layout.title.text
    # the variant without V30 is left out: 3 variants, 6 subjects
    assert sum(len(t.y) for t in v30.data if t.name != "median over subjects") == 6
    assert "cohort of 8, separate" not in list(v30.layout.xaxis2.ticktext)
    for name in ("table_information_variants", "verdicts", "runs"):
        assert figs[name].data[0].type == "table" and "SYNTHETIC" in figs[name].layout.title.text


def test_a_result_without_any_v30_has_no_v30_figure(tmp_path):
    res = fake_result()
    for r in res["runs"]:
        for c in ("q05", "median", "q95"):
            r[c] = {k: v for k, v in r[c].items() if k in THETA}
    (tmp_path / inf.RESULT_FILE).write_text(json.dumps(res))
    figs = inf.figures(inf.load(tmp_path))
    assert "fig_information_v30_width" not in figs and "fig_information_v30_width" in inf.MISSING


def test_source_line_names_the_file_and_says_synthetic(result, tmp_path):
    line = inf.source_line(result)
    assert line.startswith(f"{inf.RESULT_FILE} ({tmp_path})") and "SYNTHETIC" in line
    assert "incomplete" in line and "2 chains × (300 + 300), noise σ_V 5 mL, σ_S 0.03" in line


def test_the_runners_settings_names_and_run_counts_are_read_too(tmp_path):
    res = fake_result()
    res["settings"] = {"chains": 2, "warmup": 10, "samples": 10, "n_subjects": 12}
    res.update(n_records=6, n_planned=16)
    (tmp_path / inf.RESULT_FILE).write_text(json.dumps(res))
    line = inf.source_line(inf.load(tmp_path))
    assert "12 SYNTHETIC state subjects (incomplete: 6 of 16 planned runs done)" in line and "cohorts of" not in line
    assert "noise" not in line


# --------------------------------------------------------------------------- registry and report
def test_the_registry_entry_round_trips():
    s = registry.study("information")
    assert s is registry.study("information") and s.module_name == "lvcore.studies.information"
    assert s.load_module() is inf and inf.RESULT_FILE == s.result_file == registry.result_file("information")
    assert isinstance(inf, registry.StudyModule) and set(s.report_items) <= set(inf.TITLES)
    assert s.tab and s.report and "SYNTHETIC" in s.report and "information_runner" in s.parts
    assert "information" in inf.COMMAND and inf.RESULT_FILE in inf.COMMAND


def test_the_report_section_draws_a_saved_result(tmp_path):
    from lvcore.report import build as rb

    (tmp_path / inf.RESULT_FILE).write_text(json.dumps(fake_result()))
    section = next(x for x in rb.SECTIONS if x.study == "information")
    items = rb.section_items(section, tmp_path)
    assert [it.name for it in items] == list(section.names)
    for it in items:
        assert it.missing is None and it.fig is not None and "SYNTHETIC" in it.fig.layout.title.text


def test_the_studies_page_has_an_information_tab_drawing_a_result_folder(tmp_path):
    from streamlit.testing.v1 import AppTest

    from lvcore.app import PAGES_DIR

    (tmp_path / inf.RESULT_FILE).write_text(json.dumps(fake_result()))
    at = AppTest.from_file(str(PAGES_DIR / "6_Studies.py"), default_timeout=240).run()
    assert registry.study("information").tab in [t.label for t in at.tabs]
    at.sidebar.text_input[0].input(str(tmp_path)).run()
    src = next(s for s in at.selectbox if s.key == "information_src")
    src.set_value(next(o for o in src.options if str(tmp_path) in o)).run()   # the saved set, not the bundled one
    assert not at.exception
    assert any(c.value.startswith(f"{inf.RESULT_FILE} ({tmp_path})") and "SYNTHETIC" in c.value for c in at.caption)
    assert any(w.value.startswith("Incomplete: not every planned run done") for w in at.warning)
    shown = [list(t.value.columns) for t in [*at.table, *at.dataframe]]
    assert ["claim", "target", "value", "met", "note"] in shown
    assert any("narrowing vs reference: median [min–max]" in cols for cols in shown)


@pytest.mark.skipif(not SHIPPED.is_file(), reason="the shipped result is not there yet")
def test_the_shipped_result_loads_and_draws():
    from lvcore.studies.results import bundled_studies_dir

    res = inf.load(bundled_studies_dir())
    assert res["synthetic"] is True and "SYNTHETIC" in inf.source_line(res)
    tabs, figs = inf.tables(res), inf.figures(res)
    assert {"table_information_variants", "verdicts", "runs"} <= set(tabs)
    assert set(registry.study("information").report_items) <= set(figs)
    for name, frame in tabs.items():
        assert not _no_missing_text(frame), name
