"""Simulation-based calibration of the calibration pipeline (`lvcore study sbc`): flag kinds, subjects and routes,
the resumable store, the summary's keys, and one small end-to-end run (slow). The rank statistics:
tests/test_studies_sbc_stats.py."""
from __future__ import annotations

import json

import numpy as np
import pytest

from lvcore.studies import sbc

THETA = ("a", "b", "af", "bf")


# --------------------------------------------------------------------------- the modules
def test_the_statistics_and_the_runs_are_importable_from_the_study_module():
    from lvcore.studies import sbc_runner, sbc_stats

    for module in (sbc_stats, sbc_runner):
        for name in module.__all__:
            assert getattr(sbc, name) is getattr(module, name), (module.__name__, name)


def test_flag_kinds():
    assert sbc.flag_kind("CONSISTENCY: the volume is not reached ...") == "CONSISTENCY"
    assert sbc.flag_kind("SAMPLER: not converged: ...") == "SAMPLER"
    assert sbc.flag_kind("MISFIT: the strain residuals ...") == "MISFIT"
    assert sbc.flag_kind("EXTRAPOLATION: h3 = 2.3 outside ...") == "EXTRAPOLATION"
    assert sbc.flag_kind("IDENTIFIABILITY: a: posterior piled on the prior's lower bound 0.05 ...") == "BOUND"
    assert sbc.flag_kind("something unusual") == "OTHER"


# --------------------------------------------------------------------------- subjects and routes
def test_prior_draws_are_reproducible_and_inside_the_design():
    from lvcore.core.space import THETA_BOUNDS

    draws = [sbc.prior_draw(0, i) for i in range(300)]
    assert sbc.prior_draw(0, 7) == draws[7] and sbc.prior_draw(1, 7) != draws[7]
    assert sbc.prior_draw(0, 7, attempt=1) != draws[7]
    for n in THETA:
        v = [d["theta"][n] for d in draws]
        assert THETA_BOUNDS[n][0] <= min(v) and max(v) <= THETA_BOUNDS[n][1]
    h = np.array([d["h"] for d in draws])
    assert h.shape == (300, 5) and np.abs(h).max() <= 2.0 and 0.8 < h.std() < 1.0   # truncated N(0, 1)
    v = np.log([d["v_ref_ml"] for d in draws])
    assert np.log(40) <= v.min() and v.max() <= np.log(200)
    assert abs(np.mean(v) - np.log(np.sqrt(40 * 200))) < 0.1   # log-uniform: centred on the geometric mean


def test_a_failed_truth_is_redrawn_and_counted_with_the_same_noise():
    calls = []

    def truth(draw):
        calls.append(draw)
        if len(calls) < 3:
            raise sbc.TruthFailure("the data solve did not converge: test")
        return {"h": draw["h"], "scale": 1.0, "v_cav_ml": 100.0, "v_ref_ml": 100.0, "y_clean": [120.0] + [-0.1] * 24,
                "edv_fe_ml": 120.0, "fibre_stretch_ed": 1.1, "truth": {**draw["theta"], "V0": 100.0, "V20": 140.0,
                                                                       "V30": 150.0, "fibre_stress": 3.0},
                "seconds": 0.0}

    s = sbc.make_subject(0, 5, truth_fn=truth)
    assert s["redraws"] == 2 and len(s["redraw_reasons"]) == 2 and calls[2] == sbc.prior_draw(0, 5, 2)
    noise = sbc.noise_draw(0, 5)
    assert s["y"][0] == pytest.approx(120.0 + noise["y"][0])
    assert s["reference_volume_ml"] == pytest.approx(100.0 + noise["reference_volume_ml"])
    assert s["subject"] == "SYNTHETIC-SBC-00005"

    def never(draw):
        raise sbc.TruthFailure("always")

    with pytest.raises(sbc.LVCoreError, match="prior draws in a row failed"):
        sbc.make_subject(0, 5, truth_fn=never, max_redraws=2)


def test_calibrate_command_lines_of_both_routes():
    subject = {"index": 3, "reference_volume_ml": 101.25}
    files = {"data": "d.csv", "mesh": "g.vtu"}
    settings = sbc.default_settings(warmup=50, samples=60, derived_draws=7)
    mesh = sbc.calibrate_argv("mesh", files, subject, settings, "out")
    infer = sbc.calibrate_argv("infer", files, subject, settings, "out")
    for argv in (mesh, infer):
        assert argv[0] == "calibrate" and argv[argv.index("--data") + 1] == "d.csv"
        assert [argv[argv.index(o) + 1] for o in ("--model", "--chains", "--warmup", "--samples", "--derived-draws")] \
            == ["iid", "2", "50", "60", "7"]
        assert "--json" in argv and "--allow-extrapolation" not in argv
        assert argv[argv.index("--derived-pressures") + 1] == "20,30"
    assert mesh[mesh.index("--geometry") + 1] == "g.vtu" and "--reference-volume" not in mesh
    assert infer[infer.index("--geometry") + 1] == "infer"
    assert float(infer[infer.index("--reference-volume") + 1]) == pytest.approx(101.25)
    assert mesh[mesh.index("--seed") + 1] != infer[infer.index("--seed") + 1]


def test_calibrate_in_process_exits_as_the_lvcore_command(tmp_path, capsys):
    from lvcore.cli import main

    bad_data = ["calibrate", "--data", str(tmp_path / "missing.csv"), "--geometry", "mean", "--out", str(tmp_path)]
    bad_option = ["calibrate", "--no-such-option"]
    for argv in (bad_data, bad_option):
        code, error = sbc.calibrate_in_process(argv, tmp_path / "log.txt")
        if argv is bad_option:
            with pytest.raises(SystemExit) as info:
                main(argv)
            assert code == info.value.code == 2
        else:
            assert code == main(argv) == 2
        assert error and "error" in error
        assert (tmp_path / "log.txt").read_text()
    capsys.readouterr()


def test_ranks_of_one_run_from_its_posterior_files():
    rng = np.random.default_rng(0)
    truth = {"a": 1.0, "b": 5.0, "af": 2.0, "bf": 8.0, "V0": 100.0, "V20": 150.0, "V30": 160.0}
    truth["fibre_stress"] = float(sbc.fibre_stress(truth))
    theta = {n: rng.lognormal(np.log(truth[n]), 0.1, 1000) for n in THETA}
    p = np.array([0.0, 5, 10, 15, 20, 25, 30])
    vols = np.column_stack([np.full(20, 98.0)] + [rng.normal(150, 5, 20)] * 6)
    vols[3, 2] = np.nan   # one failed solve
    ranks, widths, failed, errors = sbc.route_ranks(truth, theta, {"edpvr_pressures_mmhg": p, "edpvr_ml": vols},
                                                    thin=100, rng=0)
    assert set(ranks) == set(sbc.QUANTITIES)
    assert all(ranks[n][1] == 100 for n in THETA + ("fibre_stress",))
    assert ranks["V0"] == [20, 20]           # every draw of V0 below the truth (a mesh route's fixed V0)
    assert ranks["V20"][1] == 20 and failed == 1
    assert widths["V20"] == pytest.approx((np.quantile(vols[:, 4], 0.95) - np.quantile(vols[:, 4], 0.05)) / 150)
    assert set(widths) == {"V20", "V30"}
    assert errors["V0"] == pytest.approx(-0.02) and set(errors) == set(sbc.DERIVED_QUANTITIES)
    none, _, _, _ = sbc.route_ranks(truth, None, None, thin=100, rng=0)
    assert none == {}


def test_the_study_uses_the_chapter_emulators_conditions():
    assert sbc.check_emulator_conditions() == {"edp": 8.0, "alpha_endo": -60.0, "alpha_epi": 60.0,
                                               "base": "sliding", "resolution": "default"}


# --------------------------------------------------------------------------- the resumable store and the summary
def _fake_record(i: int, seed: int = 0) -> dict:
    """A SYNTHETIC subject record as run_subject writes it (calibrated ranks; test data, not study output)."""
    rng = np.random.default_rng([seed, i])
    routes = {}
    for k, route in enumerate(sbc.ROUTES):
        code = int(rng.choice([0, 0, 4, 1]))
        ranks = {q: [int(rng.integers(0, 101)), 100] for q in THETA + ("fibre_stress",)}
        ranks.update({q: [int(rng.integers(0, 21)), 20] for q in sbc.DERIVED_QUANTITIES})
        routes[route] = {"exit_code": code, "error": "lvcore: did not converge" if code == 1 else None,
                         "converged": code != 1, "flag_kinds": ["CONSISTENCY", "BOUND"] if code == 4 else [],
                         "flags": [], "ranks": ranks, "width_rel": {"V20": 0.2 + 0.01 * k, "V30": 0.3},
                         "median_rel_error": {"V0": -0.01 * (k + 1), "V20": 0.05, "V30": 0.05},
                         "derived_failed": 0, "geometry_scale": None, "seed": i, "seconds": 60.0 + k}
    return {"version": sbc.RECORD_VERSION, "index": i, "subject": sbc.subject_name(i),
            "settings_key": sbc.settings_key(sbc.default_settings()), "h": [0.0] * 5, "scale": 1.0, "v_ref_ml": 90.0,
            "reference_volume_ml": 91.0, "truth": {q: 1.0 for q in sbc.QUANTITIES}, "y": [100.0] + [-0.1] * 24,
            "y_clean": [100.0] + [-0.1] * 24, "redraws": int(i == 2), "redraw_reasons": ["x: y"] * int(i == 2),
            "truth_seconds": 2.0, "routes": routes, "seconds": 125.0, "finished": "now"}


def test_pieces_split_the_subjects_without_gaps():
    assert sbc.piece_range(200, "1/2") == (0, 100) and sbc.piece_range(200, "2/2") == (100, 200)
    parts = [sbc.piece_range(10, f"{k}/3") for k in (1, 2, 3)]
    assert [i for a, b in parts for i in range(a, b)] == list(range(10))
    assert sbc.piece_range(10, start=4, stop=6) == (4, 6) and sbc.piece_range(10) == (0, 10)
    for bad in ("0/2", "3/2", "x"):
        with pytest.raises(sbc.LVCoreError, match="--piece"):
            sbc.piece_range(10, bad)


def test_a_killed_piece_resumes_skipping_the_finished_subjects(tmp_path):
    settings = sbc.default_settings()
    ran = []

    def killed_at_3(i):
        if i == 3:
            raise KeyboardInterrupt
        ran.append(i)
        return _fake_record(i)

    with pytest.raises(KeyboardInterrupt):
        sbc.run_piece(0, 6, settings, tmp_path, n_subjects=10, subject_fn=killed_at_3)
    store = sbc.Store(tmp_path)
    path = store.piece_path(0, 6)
    assert store.done() == {0, 1, 2} and len(path.read_text().splitlines()) == 3
    with open(path, "a") as f:                       # a kill in the middle of writing a line
        f.write('{"index": 3, "routes": {"mesh": ')
    assert store.done() == {0, 1, 2}
    # the other piece, in its own file, at the same time
    sbc.run_piece(6, 10, settings, tmp_path, n_subjects=10, subject_fn=_fake_record)
    ran.clear()
    sbc.run_piece(0, 6, settings, tmp_path, n_subjects=10, subject_fn=lambda i: ran.append(i) or _fake_record(i))
    assert ran == [3, 4, 5]
    assert [json.loads(line)["index"] for line in path.read_text().splitlines()] == [0, 1, 2, 3, 4, 5]
    assert [r["index"] for r in store.records()] == list(range(10))
    assert store.settings()["n_subjects"] == 10
    ran.clear()
    sbc.run_piece(0, 10, settings, tmp_path, subject_fn=lambda i: ran.append(i) or _fake_record(i))
    assert ran == []
    with pytest.raises(sbc.LVCoreError, match="other settings"):
        sbc.run_piece(0, 10, sbc.default_settings(warmup=10), tmp_path, subject_fn=_fake_record)


def test_summary_has_the_designed_keys_and_draws(tmp_path):
    settings = sbc.default_settings()
    sbc.run_piece(0, 30, settings, tmp_path, n_subjects=40, subject_fn=_fake_record)
    out = tmp_path / "ship" / "sbc.json"
    res = sbc.summarise(tmp_path, out)
    saved = json.loads(out.read_text())
    assert saved["n_subjects"] == 30 and saved["synthetic"] is True
    assert saved["n_subjects_planned"] == 40 and saved["complete"] is False
    assert {"seed", "warmup", "samples", "chains", "derived_draws", "L_theta", "noise", "edp_mmhg", "edp_note",
            "volume_range_ml", "routes"} <= set(saved["settings"])
    assert "4-20" in saved["settings"]["edp_note"]
    assert set(saved["routes"]) == {"mesh", "infer"}
    for route in ("mesh", "infer"):
        r = saved["routes"][route]
        for q in sbc.QUANTITIES:
            keys = {"coverage_90", "coverage_50", "coverage_90_ci", "rank_chi2_p", "rank_histogram", "n"}
            assert keys <= set(r[q]), (route, q)
            assert ("median_width_rel" in r[q]) == (q in ("V20", "V30"))
            assert len(r[q]["rank_histogram"]) == 10
            assert r[q]["n"] == sum(1 for i in range(30) if _fake_record(i)["routes"][route]["exit_code"] in (0, 4))
            assert r[q]["all_runs"]["n"] == 30
        codes = [_fake_record(i)["routes"][route]["exit_code"] for i in range(30)]
        assert r["exit4_share"] == pytest.approx(codes.count(4) / 30, rel=1e-5)   # 6 significant digits
        assert r["exit4_reasons"] == ({"CONSISTENCY": codes.count(4), "BOUND": codes.count(4)} if 4 in codes else {})
        assert r["cost"]["seconds_per_subject"]["median"] == pytest.approx(60.0 + sbc.ROUTES.index(route))
        assert saved["exit4_share"][route] == r["exit4_share"]
    assert saved["routes"]["infer"]["V20"]["median_width_rel"] == pytest.approx(0.21)
    assert saved["routes"]["infer"]["V0"]["median_abs_rel_error"] == pytest.approx(0.02)
    assert "median_abs_rel_error" not in saved["routes"]["infer"]["a"]
    assert saved["cost"]["machine"]["cpu_count"] and saved["cost"]["total_s"] == pytest.approx(30 * 125.0)
    assert saved["truth_generation"]["redrawn"] == 1
    assert len(saved["subjects"]) == 30 and saved["subjects"][0]["routes"]["mesh"]["ranks"]["a"][1] == 100
    import pandas as pd

    table = pd.read_csv(out.parent / sbc.SUBJECTS_FILE)
    assert len(table) == 60 and {"rank_a", "L_a", "exit_code", "route", "truth_V30"} <= set(table.columns)
    # drawn through one interface, SYNTHETIC in every title
    loaded = sbc.load(out.parent)
    figs = sbc.figures(loaded)
    assert set(figs) == set(sbc.TITLES)
    for name, fig in figs.items():
        assert "SYNTHETIC" in fig.layout.title.text, name
    hist = figs["fig_sbc_rank_histograms"]
    assert sum(1 for t in hist.data if t.type == "bar") == 2 * len(sbc.QUANTITIES)
    assert "30 of 40 SYNTHETIC subjects (incomplete)" in sbc.source_line(loaded)
    assert res["n_subjects"] == 30


def test_a_lost_work_folder_resumes_from_its_summary(tmp_path):
    """--import-summary: a summary's subjects seed a new work folder, give the same statistics and are not rerun."""
    settings = sbc.default_settings()
    sbc.run_piece(0, 12, settings, tmp_path / "old", n_subjects=20, subject_fn=_fake_record)
    first = sbc.summarise(tmp_path / "old", tmp_path / "first" / "sbc.json")
    store = sbc.Store(tmp_path / "new")
    assert store.import_summary(first, settings, "first/sbc.json") == 12
    assert store.import_summary(first, settings, "first/sbc.json") == 0          # already there: kept as is
    assert store.settings()["n_subjects"] == 20
    ran = []
    sbc.run_piece(0, 20, settings, tmp_path / "new", subject_fn=lambda i: ran.append(i) or _fake_record(i))
    assert ran == list(range(12, 20))
    again = sbc.summarise(tmp_path / "new", tmp_path / "again" / "sbc.json")
    sbc.run_piece(12, 20, settings, tmp_path / "old", subject_fn=_fake_record)      # the folder never lost
    whole = sbc.summarise(tmp_path / "old", tmp_path / "whole" / "sbc.json")
    for route in sbc.ROUTES:
        for q in sbc.QUANTITIES:
            for key in ("coverage_90", "coverage_50", "rank_chi2_p", "n"):
                assert again["routes"][route][q][key] == whole["routes"][route][q][key], (route, q, key)
        assert again["routes"][route]["exit4_reasons"] == whole["routes"][route]["exit4_reasons"]
        assert again["routes"][route]["errors"] == whole["routes"][route]["errors"]
    assert {r.get("imported_from") for r in store.records()} == {"first/sbc.json", None}
    with pytest.raises(sbc.LVCoreError, match="other settings.*warmup"):
        sbc.Store(tmp_path / "third").import_summary(first, sbc.default_settings(warmup=10), "first/sbc.json")
    with pytest.raises(sbc.LVCoreError, match="no per-subject records"):
        sbc.Store(tmp_path / "third").import_summary({**first, "subjects": []}, settings, "x.json")


def test_summarise_refuses_an_empty_work_folder(tmp_path):
    with pytest.raises(sbc.LVCoreError, match="no such folder"):
        sbc.summarise(tmp_path / "none")
    (tmp_path / "w").mkdir()
    with pytest.raises(sbc.LVCoreError, match="no finished SBC subjects"):
        sbc.summarise(tmp_path / "w")


def test_the_shipped_result_is_synthetic_and_drawn_by_the_report():
    from lvcore.report import build as rb
    from lvcore.studies.results import bundled_studies_dir

    res = sbc.load(bundled_studies_dir())
    assert res["synthetic"] is True and res["n_subjects"] >= 1
    section = next(s for s in rb.SECTIONS if s.study == "sbc")
    items = rb.section_items(section)
    assert [it.name for it in items] == list(section.names)
    for it in items:
        assert it.missing is None and it.fig is not None and "SYNTHETIC" in it.fig.layout.title.text


def test_the_studies_page_has_an_sbc_tab_on_the_shipped_result():
    from streamlit.testing.v1 import AppTest

    from lvcore.app import PAGES_DIR
    from lvcore.studies.results import bundled_studies_dir

    at = AppTest.from_file(str(PAGES_DIR / "6_Studies.py"), default_timeout=240).run()
    assert not at.exception
    assert "SBC" in [t.label for t in at.tabs]
    assert any(c.value.startswith(sbc.RESULT_FILE) and "SYNTHETIC" in c.value for c in at.caption)
    res = sbc.load(bundled_studies_dir())
    if not res["complete"]:
        assert any("Incomplete run" in w.value for w in at.warning)
    assert any({"coverage 90 %", "χ² p"} <= set(d.value.columns) for d in at.dataframe)


# --------------------------------------------------------------------------- end to end
@pytest.mark.slow
def test_one_subject_end_to_end_through_lvcore_calibrate(tmp_path, monkeypatch):
    """One SYNTHETIC subject, truth by the FE simulator, both routes through `lvcore calibrate`, tiny budget.

    One sampling round per route: at this budget the chains never converge, and the two further rounds
    `lvcore calibrate` would draw (a samples-only program traced and compiled per route, about a quarter of
    this test's CPU) are the CLI's sampler loop, not the study's: the records and ranks come out the same way."""
    from lvcore.cli import main
    from lvcore.inference import diagnostics

    until_converged = diagnostics.sample_until_converged
    monkeypatch.setattr(diagnostics, "sample_until_converged",
                        lambda *a, **k: until_converged(*a, **{**k, "max_rounds": 1}))

    work = tmp_path / "work"
    assert main(["study", "sbc", "--n-subjects", "1", "--workdir", str(work), "--warmup", "30", "--samples", "30",
                 "--derived-draws", "3", "--json"]) == 0
    rec = sbc.Store(work).records()[0]
    assert rec["subject"] == "SYNTHETIC-SBC-00000" and not (work / "runs" / "00000").exists()
    t = rec["truth"]
    assert t["V0"] == pytest.approx(rec["v_ref_ml"]) and t["V0"] < t["V20"] < t["V30"]
    assert 40 <= rec["v_ref_ml"] <= 200 and rec["y"][0] > 0
    for route in sbc.ROUTES:
        rr = rec["routes"][route]
        assert rr["exit_code"] in (0, 1, 4), rr
        assert set(rr["ranks"]) == set(sbc.QUANTITIES), rr
        assert all(rr["ranks"][q][1] == 3 for q in sbc.DERIVED_QUANTITIES)
        assert all(0 <= rr["ranks"][q][0] <= rr["ranks"][q][1] for q in sbc.QUANTITIES)
        assert rr["seconds"] > 0
    assert main(["study", "sbc", "--summarise", "--workdir", str(work), "--out", str(tmp_path / "sbc.json")]) == 0
    res = json.loads((tmp_path / "sbc.json").read_text())
    assert res["n_subjects"] == 1 and res["synthetic"] is True and set(res["routes"]) == set(sbc.ROUTES)


def test_the_docs_sbc_table_is_the_shipped_results():
    """docs/real_data.md's SBC table is :func:`sbc.docs_markdown` of the shipped result (regenerate it with
    ``lvcore study sbc --summarise ... --docs docs/real_data.md``), without the mesh route's unranked V0."""
    from pathlib import Path

    from lvcore.studies.results import bundled_studies_dir

    text = (Path(__file__).resolve().parents[1] / "docs" / "real_data.md").read_text(encoding="utf-8")
    block = text.split(sbc.DOCS_BEGIN)[1].split(sbc.DOCS_END)[0].strip()
    res = sbc.load(bundled_studies_dir())
    assert block == sbc.docs_markdown(res).strip(), "regenerate: lvcore study sbc --summarise --docs docs/real_data.md"
    assert "| mesh | V0 |" not in block and "| infer | V0 |" in block and f"{res['n_subjects']} SYNTHETIC" in block


def test_rewrite_docs_needs_its_markers(tmp_path):
    from lvcore.studies.results import bundled_studies_dir

    res = sbc.load(bundled_studies_dir())
    p = tmp_path / "doc.md"
    p.write_text("before\n" + sbc.DOCS_BEGIN + "\nold\n" + sbc.DOCS_END + "\nafter\n")
    assert sbc.rewrite_docs(res, p)
    text = p.read_text()
    assert text.startswith("before\n") and text.endswith("after\n") and "old" not in text and "| infer | a |" in text
    q = tmp_path / "plain.md"
    q.write_text("no markers\n")
    assert not sbc.rewrite_docs(res, q) and q.read_text() == "no markers\n"


def test_a_routes_error_names_workdir_not_the_machines_path(tmp_path):
    """A refused run's error line is shipped in sbc.json: the subject folder is written WORKDIR/runs/<index>."""
    from lvcore.studies import sbc_runner

    folder = tmp_path / "w" / "runs" / "00007"
    folder.mkdir(parents=True)

    def refused(argv, log_path=None):
        return 2, f"lvcore: error: --geometry {folder.resolve()}/geometry.vtu: outside the box"

    subject = {"subject": "SYNTHETIC-SBC-00007", "index": 7, "truth": {}, "reference_volume_ml": 100.0}
    settings = sbc.default_settings(seed=0, warmup=10, samples=10, chains=2, derived_draws=2, thin=10,
                                    routes=["mesh"], allow_extrapolation=False)
    files = {"data": str(folder / "data.csv"), "mesh": str(folder / "geometry.vtu")}
    rec = sbc_runner.run_route("mesh", subject, files, settings, folder, calibrate=refused)
    assert rec["exit_code"] == 2 and str(tmp_path) not in rec["error"]
    assert "WORKDIR/runs/00007/geometry.vtu" in rec["error"]
