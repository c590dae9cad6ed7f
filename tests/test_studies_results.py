"""Finding and loading saved study results, background runs, and the Studies page on saved results."""
import json
import time

import pytest
from streamlit.testing.v1 import AppTest

from lvcore.app import PAGES_DIR, ENTRY, PAGES
from lvcore.exceptions import LVCoreError
from lvcore.studies import bo_fibres, operators, results
from lvcore.testing.analytic import AnalyticForward
from tests.test_studies_operators import stand_in

PAGE = str(PAGES_DIR / "6_Studies.py")


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    root = tmp_path_factory.mktemp("studies")
    fac = lambda s, m: AnalyticForward(input_names=bo_fibres.bo_space(m).names)  # noqa: E731
    bo_fibres.run_study(["SYNTHETIC-HV1"], out=root / "bo", n_initial=5, n_iterations=1, forward_factory=fac)
    operators.run_study(["SYNTHETIC-P01"], out=root / "ops", forward_factory=stand_in)
    return root


def test_sources_and_loaders(saved):
    src = results.result_sources([saved])
    assert (f"{saved}: bo", saved / "bo") in src["bo-fibres"]
    assert (f"{saved}: ops", saved / "ops") in src["operators"]
    bo = bo_fibres.load(saved / "bo")
    assert len(bo["entries"]) == 2 and "REDUCED" in bo["meta"]["budget"]["label"]
    data = operators.load(saved / "ops")
    assert len(data["fits"]) == 12 and len(data["surfaces"]) == 12


def test_the_bundled_results_folder_has_one_locator():
    assert results.find_result("operators.json") == results.bundled_studies_dir() / "operators.json"
    assert results.source_label(results.bundled_studies_dir()) == "bundled"


def test_unreadable_results_name_the_file(tmp_path):
    (tmp_path / "bo_fibres.json").write_text("{not json")
    with pytest.raises(LVCoreError, match="bo_fibres.json"):
        bo_fibres.load(tmp_path)


def test_bundled_results_exist_and_are_labelled():
    src = results.result_sources()
    assert src["bo-fibres"] and src["operators"], "ship results in the bundled studies/ folder"
    bo = bo_fibres.load(src["bo-fibres"][0][1])
    assert bo["meta"]["budget"]["label"] and "chapter_budget" in bo["meta"]["budget"]
    assert {e["mode"] for e in bo["entries"]} == {"fixed", "free"}
    ops = operators.load(src["operators"][0][1])
    assert ops["meta"]["budget"] and ops["fits"]


def test_studies_page_renders_saved_results(saved):
    at = AppTest.from_file(PAGE, default_timeout=240).run()
    assert not at.exception
    at.sidebar.text_input[0].set_value(str(saved)).run()
    assert not at.exception
    bo_src = next(s for s in at.selectbox if s.key == "bo_fibres_src")
    bo_src.set_value(next(o for o in bo_src.options if str(saved) in o)).run()  # the saved set, not the bundled one
    assert not at.exception
    assert any("REDUCED" in w.value for w in at.warning)
    assert len(at.dataframe) >= 2


def test_studies_page_is_in_the_navigation_and_shows_the_bundled_results():
    assert "Studies" in [p.title for p in PAGES]
    at = AppTest.from_file(str(ENTRY), default_timeout=240).run()
    at.switch_page(PAGE).run()
    assert not at.exception
    assert at.title[0].value == "Studies"
    # the bundled BO run is the chapter's full budget (300 + 300), and the page says which budget it is
    assert not any("not the chapter's full run" in w.value for w in at.warning)
    assert any("the chapter's full budget" in m.value for m in at.success)
    # the shipped mismatch study: the findings table with a verdict per finding, and the dose-response table
    tables = [d.value for d in [*at.dataframe, *at.table]]  # a table with long notes is a wrapping st.table
    verdicts = next(t for t in tables if {"verdict", "ci", "doses", "unit"} <= set(t.columns))
    assert list(dict.fromkeys(f.split(" ")[0] for f in verdicts["finding"])) == ["F1", "F2", "F3", "F5", "F6"]
    assert set(verdicts["verdict"]) <= {"reproduced", "not shown", "refuted"}
    assert "F1 (direct replication)" in set(verdicts["finding"])
    assert any("iid σ_S/0.03" in t.columns for t in tables)


@pytest.mark.slow
def test_background_run_finishes_with_progress(tmp_path):
    run = results.small_run("bo-fibres", tmp_path, n_initial=3, n_iterations=0)
    assert run.running or run.returncode == 0
    t0 = time.time()
    while run.running and time.time() - t0 < 600:
        time.sleep(2)
    assert run.returncode == 0, run.log_tail()
    assert run.fraction == 1.0
    assert len(json.loads((tmp_path / "bo_fibres.json").read_text())) == 2


def test_study_modules_import_viz_only_to_draw():
    """Layering: studies -> viz only inside figures(); importing a study loads no plotting code."""
    import subprocess
    import sys

    code = ("import sys; import lvcore.studies.bo_fibres, lvcore.studies.operators, lvcore.studies.fibre_discrepancy, "
            "lvcore.studies.geometry_operators, lvcore.studies.fibre_angles, lvcore.studies.volunteer_calibration, "
            "lvcore.studies.results; print(sorted(m for m in sys.modules if m.startswith('lvcore.viz')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out


def test_each_study_draws_its_bundled_results_through_one_interface():
    """load(folder) -> tables(result) -> figures(result): every title names a figure the study can draw."""
    from lvcore.studies import fibre_discrepancy

    folder = results.bundled_studies_dir()
    for mod in (bo_fibres, operators, fibre_discrepancy):
        res = mod.load(folder)
        figs, tabs = mod.figures(res), mod.tables(res)
        assert set(figs) <= set(mod.TITLES) and figs, mod.__name__
        assert "bundled" in mod.source_line(res)
        for name in figs:
            if name in tabs and hasattr(tabs[name], "columns"):
                assert len(tabs[name]) > 0, name


def test_fibre_discrepancy_writes_its_csvs_and_figures_from_one_result(tmp_path):
    from lvcore.studies import fibre_discrepancy

    res = fibre_discrepancy.load(results.bundled_studies_dir())
    res.pop("folder")
    paths = fibre_discrepancy.write_study(res, tmp_path)
    for name in ("strain_predictive.csv", "sigma_s.csv", "errors.csv", "fig_strain_predictive.html",
                 "fig_errors_violin.html"):
        assert (tmp_path / name).is_file(), name
    assert set(paths) >= {"json", "strain_predictive_csv", "sigma_s_csv", "errors_csv"}


def test_typed_result_folders_are_bounded():
    """The Studies page's typed folder list, like the fibre-angle pairs, is bounded (issue 28 finding 2)."""
    from pathlib import Path

    import pytest

    from lvcore.exceptions import LVCoreError
    from lvcore.studies.results import MAX_TYPED_FOLDERS, parse_folders

    assert parse_folders(" a, ~/b ,") == [Path("a"), Path("~/b").expanduser()]
    with pytest.raises(LVCoreError, match=f"at most {MAX_TYPED_FOLDERS}"):
        parse_folders(",".join(["x"] * 10_000))
