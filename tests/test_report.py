"""``lvcore report``: every chapter figure is in the manifest (drawn or explicitly missing), files exist, PNG is PNG."""
from __future__ import annotations

import json

import numpy as np
import pytest

from lvcore.report import build as rb
from lvcore.report import export
from lvcore.studies import results

OPERATORS = ("op1", "op2", "op3")
PATIENTS = ("SYNTHETIC-P01", "SYNTHETIC-P02")


def _write_optimisation_results(d):
    """Small result files in the layout issue 13 specifies (test fixtures, not study output)."""
    rng = np.random.default_rng(0)
    bo = [{"subject": f"SYNTHETIC-HV{i}", "mode": mode, "theta": {"a": 0.5, "b": 2.0, "af": 1.0, "bf": 3.0},
           "alpha_endo": -60.0 if mode == "fixed" else -30.0, "alpha_epi": 90.0 if mode == "fixed" else 60.0,
           "lvv_abs_error_ml": float(rng.uniform(1, 10)), "median_abs_strain_error": float(rng.uniform(0.01, 0.05)),
           "evaluations": 60, "failed_evaluations": 0, "seconds": 10.0}
          for i in (1, 2) for mode in ("fixed", "free")]
    fits = [{"patient": p, "main_operator": m, "test_geometry": g, "converged": True,
             "theta_hat": [0.6, 1.3, 1.0, 3.6], "theta_abs_error": {"a": 0.01, "b": 0.1, "af": 0.02, "bf": 0.2},
             "strain_rmse_forward": float(rng.uniform(0, 0.02)), "output_rmse_refit": float(rng.uniform(0, 0.01)),
             "mahalanobis": 1.0}
            for p in PATIENTS for m in OPERATORS for g in [o for o in OPERATORS if o != m] + ["pc5", "pc10"]]
    x = np.linspace(0.3, 1.2, 5)
    y = np.linspace(0.6, 2.6, 6)
    surf = {"params": ["a", "b"], "x": x.tolist(), "y": y.tolist(),
            "rss": (1 + (x[None, :] - 0.6) ** 2 + (y[:, None] - 1.3) ** 2).tolist(), "truth": [0.6, 1.3]}
    (d / "bo_fibres.json").write_text(json.dumps(bo))
    (d / "operators.json").write_text(json.dumps({"fits": fits, "rss_surfaces": [surf]}))


@pytest.fixture
def no_bundled_studies(tmp_path, monkeypatch):
    empty = tmp_path / "bundled" / "studies"
    empty.mkdir(parents=True)
    monkeypatch.setattr(results, "bundled_studies_dir", lambda: empty)
    return empty


def _section(study):
    return next(s for s in rb.SECTIONS if s.study == study)


def _items(study, results_dir=None):
    return rb.section_items(_section(study), results_dir)


def test_manifest_lists_every_figure_and_says_what_is_missing(tmp_path, no_bundled_studies):
    out = tmp_path / "report"
    m = rb.build_report(out, calibration=False, formats=())
    names = [f["name"] for f in m["figures"]]
    assert names == list(rb.FIGURE_NAMES)
    by = {f["name"]: f for f in m["figures"]}
    for n in _section("fibre_discrepancy").names:
        assert by[n]["status"] == "missing" and "run lvcore study fibre-discrepancy" in by[n]["missing"]
    for n in _section("bo_fibres").names:
        assert by[n]["status"] == "missing" and "run lvcore study bo-fibres" in by[n]["missing"]
    for n in _section("operators").names:
        assert by[n]["status"] == "missing" and "run lvcore study operators" in by[n]["missing"]
        assert by[n]["png"] is None and by[n]["html"] is None
    for n in ("fig9_5_angle_sweep", "fig9_5_angle_map", "table9_4_operators_pca", "fig9_10_geometry_effect"):
        f = by[n]
        assert f["status"] == "ok", f
        assert (out / f["html"]).is_file() and (out / f["data"]).is_file()
        assert f["png"] is None  # HTML-only run
    assert by["fig_calibration_posterior"]["status"] == "missing"
    index = (out / "index.html").read_text()
    assert all(f["name"] in index for f in m["figures"])
    assert json.loads((out / "manifest.json").read_text())["figures"] == m["figures"]


def test_study_sections_draw_saved_results_with_synthetic_titles(tmp_path):
    _write_optimisation_results(tmp_path)
    items = _items("bo_fibres", tmp_path) + _items("operators", tmp_path)
    assert [it.name for it in items] == list(_section("bo_fibres").names) + list(_section("operators").names)
    for it in items:
        assert it.fig is not None and it.missing is None, it
        assert "SYNTHETIC" in it.fig.layout.title.text, it.name
    # the violins hold every fit of their panel: 2 patients per test geometry
    fig11 = next(it.fig for it in items if it.name == "fig9_11_forward_strain_error")
    assert {t.type for t in fig11.data} == {"violin"}
    assert sum(len(t.y) for t in fig11.data) == len(PATIENTS) * len(OPERATORS) * 4


def test_bundled_fibre_discrepancy_results_give_figs_9_6_to_9_9():
    path = results.find_result("fibre_discrepancy.json")
    assert path is not None, "the package must ship assets/studies/fibre_discrepancy.json (scripts/ship_fibre_discrepancy.py)"
    items = {it.name: it for it in _items("fibre_discrepancy")}
    assert list(items) == list(_section("fibre_discrepancy").names)
    for it in items.values():
        assert it.fig is not None, it.missing
        assert "SYNTHETIC" in it.fig.layout.title.text, it.name
    violins = [t for t in items["fig9_9_error_violins"].fig.data if t.type == "violin"]
    assert len(violins) == 3 and all(len(v.y) >= 12 for v in violins)


def test_static_export_failure_is_a_clear_error(monkeypatch):
    import plotly.graph_objects as go
    import plotly.io as pio

    def boom(*a, **k):
        raise RuntimeError("no browser")

    monkeypatch.setattr(pio, "write_images", boom)
    with pytest.raises(export.StaticExportError, match="chromium"):
        export.export_static([go.Figure()], ["x.png"])


def test_a_missing_exporter_is_named_before_chromium_starts(monkeypatch):
    """Issue 49: no kaleido (or no Chromium) is said in words and what to install, not as plotly's RuntimeError."""
    import importlib.metadata

    import plotly.graph_objects as go
    import plotly.io as pio

    def never(*a, **k):
        raise AssertionError("write_images must not be tried")

    monkeypatch.setattr(pio, "write_images", never)
    real_version = importlib.metadata.version

    def version(name):
        if name == "kaleido":
            raise importlib.metadata.PackageNotFoundError(name)
        return real_version(name)

    monkeypatch.setattr(importlib.metadata, "version", version)
    assert export.static_export_problem() == 'kaleido is not installed (pip install "lvcore[report]")'
    with pytest.raises(export.StaticExportError) as err:
        export.export_static([go.Figure()], ["x.png"])
    assert str(err.value) == 'static export (PNG/SVG) not possible: kaleido is not installed (pip install "lvcore[report]")'
    monkeypatch.setattr(export, "_kaleido_problem", lambda: None)
    monkeypatch.setattr(export, "find_chromium", lambda: None)
    assert "apt-get install chromium" in export.static_export_problem()


def test_cli_rejects_a_missing_results_folder(tmp_path, capsys):
    from lvcore.cli import main

    assert main(["report", "--out", str(tmp_path / "r"), "--from", str(tmp_path / "nope"), "--no-calibration"]) == 2
    assert "no such folder" in capsys.readouterr().err


@pytest.mark.slow
def test_png_and_svg_are_written(tmp_path, no_bundled_studies):
    """Kaleido + Chromium: valid PNG and SVG for every drawn figure (CI installs Debian's chromium)."""
    results = tmp_path / "results"
    results.mkdir()
    _write_optimisation_results(results)
    out = tmp_path / "report"
    m = rb.build_report(out, results, calibration=False)
    drawn = [f for f in m["figures"] if f["status"] == "ok"]
    assert len(drawn) >= 10
    for f in drawn:
        assert (out / f["png"]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", f["png"]
        assert b"<svg" in (out / f["svg"]).read_bytes()[:2000], f["svg"]
        assert (out / f["data"]).stat().st_size > 0
    assert (out / "figures" / "plotly.min.js").is_file()


@pytest.mark.slow
def test_calibration_posterior_shows_prior_and_truth():
    from lvcore.studies import volunteer_calibration as vc

    res = vc.compute(num_warmup=150, num_samples=150, num_chains=2)
    fig = vc.figures(res)["fig_calibration_posterior"]
    assert "SYNTHETIC" in fig.layout.title.text
    names = {t.name for t in fig.data}
    assert {"posterior", "prior (uniform)", "truth (SYNTHETIC)"} <= names
    assert len([s for s in fig.layout.shapes if s.line.color == "red"]) == 4  # one truth line per parameter
    summary = vc.tables(res)["table_calibration_summary"]
    theta_rows = summary[summary["parameter"].isin(["a", "b", "af", "bf"])]
    assert len(theta_rows) == 4 and theta_rows["truth"].notna().all()


# ----------------------------------------------------------------------------- figure content (issues 23 and 27)
def _fake_calibration():
    """A calibration result as plain data (what volunteer_calibration.compute returns), without running NUTS."""
    import pandas as pd

    rng = np.random.default_rng(1)
    bounds = {"a": (0.05, 5.0), "b": (0.5, 10.0), "af": (0.05, 5.0), "bf": (0.5, 10.0)}
    draws = {n: rng.uniform(lo, hi, 400) for n, (lo, hi) in bounds.items()}
    summary = pd.DataFrame({"parameter": list(bounds), "mean": [d.mean() for d in draws.values()],
                            "truth": [0.6, 1.3, 1.0, 3.6]})
    return {"subject": "SYNTHETIC-HV3", "draws": draws, "bounds": bounds, "truth": dict(zip(bounds, [0.6, 1.3, 1, 3.6])),
            "summary": summary, "wall_s": 0.0,
            "status": "converged: max R-hat 1.007 (<= 1.05), min bulk ESS 826 (>= 100), 0 divergent, 1 round(s); "
                      "0 divergent transitions (fake run for a figure test)",
            "config": {"num_warmup": 5, "num_samples": 100, "num_chains": 4}, "derived": _fake_derived()}


def _fake_derived():
    """A derived record (lvcore.inference.derived.derive) as plain data: the shapes and keys, made-up numbers."""
    q = lambda lo, m, hi: {"q05": lo, "median": m, "q95": hi}  # noqa: E731
    edpvr = [{"pressure_mmhg": p, **q(v - 2 * k, v, v + 3 * k)}
             for k, (p, v) in enumerate(zip((0, 5, 10, 15, 20, 25, 30), (84.0, 133, 146, 153, 158, 162, 165)))]
    comb = {"coefficients": {"log_a": 1.0, "log_b": 0.97}, "text": "log_a + 0.97 log_b", "median": 0.63,
            "q05": -1.14, "q95": 1.79, "width90_log": 2.93, "width90_factor": 18.7, "sd_log": 0.9}
    return {"edpvr": edpvr, "n_draws": 100,
            "edpvr_check": {"edp_mmhg": 8.0, "measured_edv_ml": 145.8, "predictive_99": [125.2, 160.2], "inside": True,
                            "emulator_to_fe_offset_ml": q(-0.26, -0.03, 0.16),
                            "klotz": {"v0_ml": 84.0, "v30_ml": 181.1,
                                      "volumes_ml": [84.0, 136.1, 151.0, 161.6, 170.2, 177.5, 183.9]}},
            "stress": {"fixed_stretch": {"stretch": 1.1, "fibre_kpa": q(0.8, 1.7, 2.9),
                                         "cross_fibre_kpa": q(0.02, 0.1, 0.47)},
                       "end_diastolic": {"stretch": q(1.128, 1.138, 1.152), "fibre_kpa": q(3.0, 5.1, 6.6),
                                         "cross_fibre_kpa": q(0.03, 0.16, 0.64), "n_draws": 100}},
            "ridge": {"a_b": comb, "best": comb, "least": comb, "correlation_log_a_log_b": -0.6},
            "contraction": {"a": -0.2, "b": -0.2, "af": 0.39, "bf": 0.67}, "weakly_identified": []}


@pytest.fixture(scope="module")
def report_items():
    """Every report item as the report draws it: bundled results, and a calibration result given as plain data."""
    from lvcore.report.export import plotly_template
    from lvcore.studies import volunteer_calibration as vc

    items = []
    with plotly_template():
        for s in rb.SECTIONS:
            if s.study == "volunteer_calibration":
                res = _fake_calibration()
                figs = vc.figures(res)
                items += [rb.ReportItem(n, vc.TITLES[n], figs[n], vc.tables(res)[n], vc.source_line(res))
                          for n in s.names]
            else:
                items += rb.section_items(s)
    return {it.name: it for it in items}


def test_every_report_item_renders(report_items):
    assert list(report_items) == list(rb.FIGURE_NAMES)
    for name, it in report_items.items():
        assert it.fig is not None and it.missing is None, (name, it.missing)
        it.fig.to_json()  # a valid plotly figure
        assert it.fig.layout.title.text, name


def _axes_used(fig):
    xs, ys = set(), set()
    for t in fig.data:
        if t.type in ("table", "splom", "barpolar"):
            continue
        xs.add("xaxis" + (t.xaxis or "x")[1:])
        ys.add("yaxis" + (t.yaxis or "y")[1:])
    return xs, ys


def test_axis_titles_present(report_items):
    """Every axis that carries data is titled, or shares its column (x) or row (y) with a titled one."""
    for name, it in report_items.items():
        fig = it.fig
        xs, ys = _axes_used(fig)
        for used, other in ((xs, "domain"), (ys, "domain")):
            for ax in used:
                a = fig.layout[ax]
                titled = [fig.layout[b] for b in used if fig.layout[b].title.text]
                same_line = [b for b in titled if tuple(b[other] or (0, 1)) == tuple(a[other] or (0, 1))]
                assert a.title.text or same_line, f"{name}: {ax} has no title"


def test_violins_of_nonnegative_quantities_stay_above_zero(report_items):
    """|errors|, RMSEs and distances: the violin ends at the data (hard span), never below 0."""
    violins = [(n, t) for n, it in report_items.items() for t in it.fig.data if t.type == "violin"]
    assert {n for n, _ in violins} >= {"fig9_9_error_violins", "fig9_11_forward_strain_error", "fig9_14_output_error"}
    for name, t in violins:
        assert np.min(t.y) >= 0, name
        assert t.spanmode == "hard", f"{name}: a soft span draws the density below 0"


def test_panel_and_model_labels_read_properly(report_items):
    texts = [a.text for it in report_items.values() for a in it.fig.layout.annotations if a.text]
    names = [t.name for it in report_items.values() for t in it.fig.data if t.name]
    assert not [t for t in texts if "main main" in t]
    assert any(t == "main operator: op1" for t in texts)
    assert not [n for n in names if "None" in n]
    from lvcore.inference.models import MODEL_LABELS

    fig99 = report_items["fig9_9_error_violins"].fig
    assert [t.name for t in fig99.data if t.type == "violin"] == [MODEL_LABELS[m] for m in ("volume", "iid",
                                                                                            "discrepancy")]


def test_fig_9_13_names_the_fit_and_marks_theta_hat_and_the_truth(report_items):
    from lvcore.studies import operators

    res = operators.load(results.bundled_studies_dir())
    s = res["surfaces"][0]
    fig = report_items["fig9_13_rss_surface"].fig
    title = fig.layout.title.text
    assert s["patient"] in title and f"test geometry {s['test_geometry']}" in title.replace("<br>", " ")
    hats = [t for t in fig.data if t.name == "refit θ̂"]
    truths = [t for t in fig.data if t.name == "truth θ̃"]
    assert len(hats) == len(truths) == len(s["pairs"]) == 6
    first = s["pairs"][0]
    i, j = ("a", "b", "af", "bf").index(first["x"]), ("a", "b", "af", "bf").index(first["y"])
    assert (hats[0].x[0], hats[0].y[0]) == (s["theta_hat"][i], s["theta_hat"][j])
    assert (truths[0].x[0], truths[0].y[0]) == (operators.THETA_TRUE[i], operators.THETA_TRUE[j])


def _lines(text):
    return (text or "").split("<br>")


def test_exported_titles_never_overlap_subplot_titles(report_items):
    """After the report's wrap_title: the title's last line ends above the row of subplot titles."""
    from lvcore.viz.report_figures import SUBPLOT_TITLE_PX, TITLE_CHAR_PX, TITLE_LINE_PX, _visible_len, wrap_title

    for name, it in report_items.items():
        fig = wrap_title(it.fig)
        t = fig.layout.title
        top_margin = fig.layout.margin.t
        n = len(_lines(t.text))
        if t.yanchor == "top" and t.yref == "container":
            bottom = (1 - t.y) * fig.layout.height if fig.layout.height else 0
            bottom += (t.pad.t or 0) + TITLE_LINE_PX * n
        else:  # plotly's "auto": the title is centred in the top margin
            bottom = top_margin / 2 + TITLE_LINE_PX * n / 2
        has_subplot_titles = any(a.yref == "paper" and (a.y or 0) >= 0.99 for a in fig.layout.annotations)
        assert bottom <= top_margin - (SUBPLOT_TITLE_PX if has_subplot_titles else 0), name
        # and no line runs past the right edge of the exported image
        assert max(_visible_len(x) for x in _lines(t.text)) * TITLE_CHAR_PX <= (fig.layout.width or 1100), name


def test_tables_fit_their_columns(report_items):
    """Each column is as wide as its longest line, and the figure as wide as its columns: nothing clipped."""
    from lvcore.viz.report_figures import TABLE_CHAR_PX, TABLE_MAX_WIDTH_PX

    tables = {n: it.fig for n, it in report_items.items() if it.fig.data and it.fig.data[0].type == "table"}
    assert {"table9_2_bo_fixed_angles", "table_calibration_summary", "table9_4_operators_pca"} <= set(tables)
    for name, fig in tables.items():
        t = fig.data[0]
        widths = t.columnwidth
        assert widths is not None and len(widths) == len(t.header.values), name
        for k, w in enumerate(widths):
            import re

            texts = [re.sub(r"<[^>]+>", "", line) for v in [t.header.values[k], *t.cells.values[k]]
                     for line in str(v).split("<br>")]
            assert w >= TABLE_CHAR_PX * max(len(x) for x in texts), (name, texts[0])
        assert fig.layout.width >= sum(widths), name
    assert tables["table_findings"].layout.width <= TABLE_MAX_WIDTH_PX  # wrapped, not 2,986 px (issue 49)


def test_source_lines_are_readable_text(tmp_path):
    m = rb.build_report(tmp_path / "r", calibration=False, formats=())
    for f in m["figures"]:
        assert "{'" not in f["source"] and "':" not in f["source"], f["source"]
    fd = next(f for f in m["figures"] if f["name"] == "fig9_6_strain_predictive")
    assert "4 chains × (500 warm-up + 1000 draws)" in fd["source"]


def test_without_a_static_exporter_the_html_report_is_written_and_says_so(tmp_path, monkeypatch, capsys):
    import plotly.io as pio

    from lvcore.cli import main

    def no_kaleido(*a, **k):
        raise ValueError("Image export using the \"kaleido\" engine requires the kaleido package")

    monkeypatch.setattr(pio, "write_images", no_kaleido)
    out = tmp_path / "r"
    assert main(["report", "--out", str(out), "--no-calibration"]) == 0
    err = capsys.readouterr().err
    assert "static formats skipped: png, svg" in err and "kaleido" in err
    m = json.loads((out / "manifest.json").read_text())
    assert m["skipped_formats"] == ["png", "svg"]
    assert all(f["png"] is None and f["svg"] is None for f in m["figures"])
    assert all((out / f["html"]).is_file() for f in m["figures"] if f["status"] == "ok")
    assert "Static formats skipped" in (out / "index.html").read_text()


def test_importing_the_report_loads_no_plotting_code():
    """`lvcore --help` imports lvcore.report.cli: plotly and pandas load only when a report is built."""
    import subprocess
    import sys

    code = "import sys, lvcore.report; print(sorted(m for m in sys.modules if m.startswith(('plotly', 'pandas'))))"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "[]"
