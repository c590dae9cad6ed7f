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
