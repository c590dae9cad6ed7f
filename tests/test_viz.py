"""Plotly figure builders and off-screen PyVista rendering (no display needed)."""
import io

import numpy as np
import pytest

from lvcore.geometry.analytic import DEFAULT_LV, EllipsoidSurface, TruncatedEllipsoidLV
from lvcore.geometry.template import DEFAULT_TEMPLATE, LVTemplate
from lvcore.domain.outputs import LEVEL_NAMES, STRAIN_NAMES
from lvcore.viz import figures, mesh3d


def _ramp():
    return -0.01 * (np.arange(24) + 1)  # region r has strain -(r+1)/100


def test_strain_heatmap_places_regions():
    fig = figures.strain_heatmap(_ramp())
    hm = fig.data[0]
    z = np.asarray(hm.z)
    assert z.shape == (4, 6)
    # row = level, column = sector: region 6*level + sector
    assert z[2, 4] == pytest.approx(-0.01 * (6 * 2 + 4 + 1))
    assert list(hm.y) == list(LEVEL_NAMES)
    assert np.asarray(hm.customdata)[3, 5] == STRAIN_NAMES[23]
    assert hm.zmin == pytest.approx(-0.24) and hm.zmax == pytest.approx(0.24)
    # a 25-output vector drops LVV
    fig25 = figures.strain_heatmap(np.concatenate([[120.0], _ramp()]))
    np.testing.assert_array_equal(np.asarray(fig25.data[0].z), z)
    with pytest.raises(ValueError, match="24 regional strains"):
        figures.strain_heatmap(np.zeros(23))


def test_strain_bars_and_bullseye():
    fig = figures.strain_bars({"measured": _ramp(), "simulated": _ramp() * 0.5}, errors={"measured": np.full(24, 0.01)})
    assert len(fig.data) == 2 and fig.layout.barmode == "group"
    assert np.asarray(fig.data[1].y)[7] == pytest.approx(-0.04)
    assert np.asarray(fig.data[0].error_y.array)[0] == 0.01
    assert list(fig.data[0].x[0])[6] == LEVEL_NAMES[1] and list(fig.data[0].x[1])[6] == "S1"
    bull = figures.strain_bullseye(_ramp())
    bar = bull.data[0]
    # region 7 = level 1, sector 1: ring base 2 (basal ring outermost), centred at 90 degrees
    assert np.asarray(bar.base)[7] == 2 and np.asarray(bar.theta)[7] == 90
    assert np.asarray(bar.marker.color)[7] == pytest.approx(-0.08)


def test_violin_density_contour():
    rng = np.random.default_rng(0)
    samples = {"a": rng.normal(1.0, 0.1, 500), "b": rng.normal(2.0, 0.2, 500)}
    v = figures.violin(samples, reference={"a": 1.0})
    assert [t.type for t in v.data[:2]] == ["violin", "violin"] and len(v.layout.shapes) == 1
    d = figures.density_overlay(samples, reference={"truth": 1.0}, n_grid=401)
    x, y = np.asarray(d.data[0].x), np.asarray(d.data[0].y)
    assert abs(x[np.argmax(y)] - 1.0) < 0.05  # KDE peaks at the sample mean
    assert np.trapezoid(y, x) == pytest.approx(1.0, abs=0.02)
    assert d.layout.shapes[0].line.dash == "dash"
    xs, ys = np.linspace(0, 1, 5), np.linspace(0, 2, 4)
    c = figures.contour(xs, ys, np.add.outer(ys, xs), points={"opt": ([0.5], [1.0])})
    assert c.data[0].type == "contour" and c.data[1].mode == "markers"
    with pytest.raises(ValueError, match="shape"):
        figures.contour(xs, ys, np.zeros((5, 4)))


# ----------------------------------------------------------------------------
# PyVista (off-screen)
# ----------------------------------------------------------------------------

def _wall_volume(lv: TruncatedEllipsoidLV) -> float:
    outer = TruncatedEllipsoidLV(lv.epi, lv.epi, lv.base_z).cavity_volume_mm3()
    return outer - lv.cavity_volume_mm3()


def test_lv_grid_geometry_matches_ellipsoid():
    nodes = DEFAULT_LV.nodes(DEFAULT_TEMPLATE)
    grid = mesh3d.lv_grid(nodes, DEFAULT_TEMPLATE.elements, cell_data={"region": DEFAULT_TEMPLATE.element_regions})
    assert grid.n_cells == DEFAULT_TEMPLATE.n_elements and set(np.unique(grid.celltypes)) == {29}
    vols = grid.compute_cell_sizes(length=False, area=False).cell_data["Volume"]
    assert np.all(vols > 0)  # the permutation keeps every cell right-handed
    # VTK sizes nonlinear cells from a linear subdivision, so only roughly the exact wall volume
    assert vols.sum() == pytest.approx(_wall_volume(DEFAULT_LV), rel=3e-2)
    # VTK's own interpolation inside a cell equals the template's isoparametric map
    r, s, t = 0.25, 0.6, 0.8  # VTK parametric (circumferential, transmural, longitudinal)
    for e in (0, 37, DEFAULT_TEMPLATE.n_elements - 1):
        cell = grid.GetCell(e)
        x, w = [0.0, 0.0, 0.0], [0.0] * 27
        from vtkmodules.vtkCommonCore import reference

        cell.EvaluateLocation(reference(0), [r, s, t], x, w)
        ec, el, et = DEFAULT_TEMPLATE.element_grid[e]
        expected = DEFAULT_TEMPLATE.evaluate(nodes, 2 * np.pi * (ec + r) / DEFAULT_TEMPLATE.n_circ,
                                             (el + t) / DEFAULT_TEMPLATE.n_long, (et + s) / DEFAULT_TEMPLATE.n_trans)
        np.testing.assert_allclose(x, expected, atol=1e-9)
    surf = mesh3d.lv_surface(nodes, DEFAULT_TEMPLATE.elements, point_data={"z": nodes[:, 2]})
    assert surf.n_points > nodes.shape[0]  # subdivided curved faces
    np.testing.assert_allclose(surf.bounds[4:], [-75.0, 10.0], atol=1e-6)
    np.testing.assert_allclose(surf.point_data["z"], surf.points[:, 2], atol=1e-6)  # interpolated field


def test_render_offscreen_png(monkeypatch):
    from PIL import Image

    monkeypatch.delenv("DISPLAY", raising=False)
    tmpl = LVTemplate(6, 4, 1)
    lv = TruncatedEllipsoidLV(EllipsoidSurface(7, 17), EllipsoidSurface(10, 20), 5.0)
    ref = lv.nodes(tmpl)
    cur = ref * np.array([1.2, 1.2, 1.3])
    png = mesh3d.render_reference_and_deformed(ref, cur, tmpl.elements, window_size=(320, 240), title="t")
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and img.shape == (240, 320, 3)
    coloured = np.abs(img.astype(int) - 255).sum(axis=2) > 30  # not the white background
    assert 0.05 < coloured.mean() < 0.9
    # an overlay of two single-colour meshes, tuple form; red must appear
    png2 = mesh3d.render_meshes([(mesh3d.lv_surface(ref, tmpl.elements), "red", 1.0, "a"),
                                 (mesh3d.lv_surface(cur, tmpl.elements), "blue", 0.3, "b")],
                                window_size=(200, 200), view="side")
    img2 = np.asarray(Image.open(io.BytesIO(png2)).convert("RGB")).astype(int)
    assert np.any((img2[..., 0] > 150) & (img2[..., 1] < 80))
    with pytest.raises(ValueError, match="view"):
        mesh3d.render_meshes([mesh3d.lv_surface(ref, tmpl.elements)], view="sideways")


def test_element_edges_follow_the_curved_surfaces():
    tmpl = LVTemplate(6, 4, 1)
    lv = TruncatedEllipsoidLV(EllipsoidSurface(7, 17), EllipsoidSurface(10, 20), 5.0)
    edges = mesh3d.element_edges(lv.nodes(tmpl), tmpl.elements, samples=8)
    p = np.asarray(edges.points)

    def level(surf):
        return np.abs((p[:, 0] ** 2 + p[:, 1] ** 2) / surf.rs**2 + p[:, 2] ** 2 / surf.rl**2 - 1.0)

    off = np.minimum.reduce([level(lv.endo), level(lv.epi), np.abs(p[:, 2] - 5.0)])
    assert off.max() < 0.01  # every sample lies on the endocardium, epicardium or base (boundary only)
    # curved: 60-degree straight chords would sit up to 1 - cos(30 deg) = 13 % inside a circle
    r = np.hypot(p[:, 0], p[:, 1])
    base = np.abs(p[:, 2] - 5.0) < 1e-9
    r_ring = 7.0 * np.sqrt(1 - 25 / 289)  # endocardial base ring, 6.69 mm; chords would dip to 5.79 mm
    assert r[base].min() == pytest.approx(r_ring, rel=5e-3)
    all_edges = mesh3d.element_edges(lv.nodes(tmpl), tmpl.elements, boundary_only=False)
    assert all_edges.n_cells > edges.n_cells


def test_overlay_and_scalar_map():
    from PIL import Image

    tmpl = LVTemplate(6, 4, 1)
    a = TruncatedEllipsoidLV(EllipsoidSurface(7, 17), EllipsoidSurface(10, 20), 5.0).nodes(tmpl)
    b = a * np.array([1.3, 1.3, 1.0])
    png = mesh3d.render_overlay({"A": a, "B": b}, tmpl.elements, window_size=(240, 200), opacity=1.0)
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    blue = (img[..., 2] > 150) & (img[..., 0] < 120)  # royalblue: B (wider) shows around A
    assert blue.mean() > 0.01
    png = mesh3d.render_scalar_map(a, tmpl.elements, tmpl.element_regions, label="region", window_size=(200, 200))
    assert png[:4] == b"\x89PNG"
    with pytest.raises(ValueError, match="one entry per node"):
        mesh3d.render_scalar_map(a, tmpl.elements, np.zeros(5))


def test_map_pair_draws_both_maps_in_one_figure():
    xs, ys = np.linspace(-90, 0, 4), np.linspace(0, 90, 3)
    left, right = np.add.outer(ys, xs), np.multiply.outer(ys, xs)
    fig = figures.map_pair(xs, ys, left, right, titles=("LVV (mL)", "Mean E_cc"), xaxis_title="α_endo (°)")
    assert [t.type for t in fig.data] == ["heatmap", "heatmap"]
    np.testing.assert_array_equal(fig.data[0].z, left)
    np.testing.assert_array_equal(fig.data[1].z, right)
    assert fig.data[0].xaxis == "x" and fig.data[1].xaxis == "x2"  # side by side, own axes and colour bars
    assert fig.data[0].colorbar.x != fig.data[1].colorbar.x
    with pytest.raises(ValueError, match="shape"):
        figures.map_pair(xs, ys, left, right.T)


# ----------------------------------------------------------------------------- content checks (issue 27)
def _decade_labels(axis):
    lo, hi = axis.range
    return [10.0 ** k for k in range(int(np.ceil(lo)), int(np.floor(hi)) + 1)]


def test_shape_model_error_axis_has_a_label_at_every_decade():
    """Data within one decade used to get a single tick label on the log axis (dtick=1 without a range)."""
    from lvcore.studies.geometry_operators import operator_table
    from lvcore.viz.geometry_views import operator_mse_figure

    table = operator_table()
    fig = operator_mse_figure(table, table["operators"][0])
    ax = fig.layout.yaxis
    assert ax.type == "log" and ax.dtick == 1 and ax.range is not None
    labels = _decade_labels(ax)
    assert len(labels) >= 3
    ys = [v for t in fig.data if t.y is not None for v in t.y if v is not None]
    assert 10 ** ax.range[0] <= min(ys) and max(ys) <= 10 ** ax.range[1]


def test_decade_log_axis_widens_a_narrow_range():
    ax = figures.decade_log_axis([0.002, 0.008])
    assert ax["range"][1] - ax["range"][0] >= 2 and ax["dtick"] == 1


def _bo_entries(n=8):
    rng = np.random.default_rng(0)
    return [{"subject": f"SYNTHETIC-HV{i}", "mode": m, "n_initial": 30,
             "convergence": np.minimum.accumulate(rng.uniform(0.1, 10, 60)).tolist(),
             "strain_residuals": rng.normal(0, 0.02, 24).tolist()}
            for i in range(1, n + 1) for m in ("fixed", "free")]


def test_bo_convergence_legend_holds_every_subject_and_the_title_fits():
    from lvcore.viz import study_figures

    fig = study_figures.convergence_figure(_bo_entries())
    shown = [t.name for t in fig.data if t.showlegend is not False]
    assert {f"HV{i}" for i in range(1, 9)} <= set(shown)
    # a vertical legend of ~20 px per entry must fit the plot area, or the legend is laid out horizontally
    plot_h = (fig.layout.height or 450) - (fig.layout.margin.t or 100) - (fig.layout.margin.b or 80)
    assert fig.layout.legend.orientation == "h" or 20 * len(shown) <= plot_h
    # the Studies page shows it in half the width: no title line longer than ~60 characters
    assert max(len(line) for line in fig.layout.title.text.split("<br>")) <= 60
    assert fig.layout.yaxis.type == "log" and fig.layout.yaxis.dtick == 1


def test_violin_of_a_nonnegative_quantity_ends_at_the_data():
    fig = figures.violin({"|error|": [0.0, 0.001, 0.002, 0.01]}, nonnegative=True)
    assert fig.data[0].spanmode == "hard" and fig.layout.yaxis.rangemode == "nonnegative"


def test_table_figure_is_as_wide_as_its_columns():
    import pandas as pd

    from lvcore.viz.report_figures import TABLE_CHAR_PX, table_figure

    df = pd.DataFrame({"meaning": ["a very long explanation of what this parameter means in the model"],
                       **{f"column {k}": [1.23456] for k in range(12)}})
    fig = table_figure(df, title="t")
    w = fig.data[0].columnwidth
    lines = fig.data[0].cells.values[0][0].split("<br>")
    assert " ".join(lines) == df["meaning"][0]  # wrapped (13 columns would not fit), every word kept
    assert w[0] >= TABLE_CHAR_PX * max(len(x) for x in lines) and fig.layout.width >= sum(w)
    assert fig.data[0].cells.fill.color == "white" and fig.data[0].cells.font.color  # explicit: no theme leak


def test_a_wide_table_wraps_its_long_cells_instead_of_growing_wider():
    """Issue 49: the findings table was 2,986 px wide (one 187-character cell on one line), its text tiny."""
    import pandas as pd

    from lvcore.viz.report_figures import TABLE_MAX_WIDTH_PX, table_figure

    long = "pc5 no worse in 33 % [19, 47] of comparisons (18 cases; refuted); " * 3
    df = pd.DataFrame({"finding": ["F1", "F5"], "ci": ["1.70× [1.66, 1.74]", long.strip()],
                       "dose": ["heterogeneity 1.2 (strain RMS 0.048; sampler 2 × (300 + 300))", "n/a"]})
    fig = table_figure(df, title="t")
    assert fig.layout.width <= TABLE_MAX_WIDTH_PX
    cell = fig.data[0].cells.values[1][1]
    assert cell.count("<br>") >= 2 and cell.replace("<br>", " ") == long.strip()
    assert list(fig.data[0].cells.values[0]) == ["F1", "F5"]  # short cells untouched
    assert fig.layout.height > table_figure(df.iloc[:, :1], title="t").layout.height  # rows grow with the lines
    narrow = pd.DataFrame({"a": [1.0], "b": ["short text"]})
    assert list(table_figure(narrow, title="t").data[0].cells.values[1]) == ["short text"]  # fits: never wrapped


def test_strain_map_labels_fit_their_columns_and_the_colour_bar_title_clears_its_ticks():
    """The sector labels ran together at a half-page width ("60–120°120–180°…"): each line of a tick is short now;
    the colour bar's title sits beside the bar (above it, it overlapped the top tick label)."""
    import re

    for fig in (figures.strain_heatmap(_ramp()), ):
        ticks = list(fig.data[0].x)
        assert len(ticks) == 6 and ticks[2].startswith("S3")
        assert max(len(line) for t in ticks for line in re.split("<br>", t)) <= 5, ticks
        assert "degrees" in fig.layout.xaxis.title.text  # the unit of the angular ranges
    for colorbar in (figures.strain_heatmap(_ramp()).data[0].colorbar, figures.strain_bullseye(_ramp()).data[0].marker.colorbar):
        assert colorbar.title.text == "E_cc (-)" and colorbar.title.side == "right"


def test_no_markdown_backticks_in_figure_titles():
    from lvcore.viz.report_figures import posterior_prior_figure, wrap_title

    assert figures.plain_text("iid model, `chapter` emulator<br><sup>x</sup>") == "iid model, chapter emulator<br><sup>x</sup>"
    fig = posterior_prior_figure({"a": np.ones(10)}, {"a": (0.05, 10.0)}, title="`chapter` emulator")
    assert fig.layout.title.text == "chapter emulator"
    fig = figures.contour([0, 1], [0, 1], np.zeros((2, 2)), title="EDV, `angles` emulator")
    assert "`" not in fig.layout.title.text
    fig.update_layout(title="a long title with a `chapter` emulator")
    assert "`" not in wrap_title(fig).layout.title.text


def test_common_objective_panels_show_different_quantities():
    """The F6 comparison: left, the common-scale objective at each mode's optimum (and, only where a run reached a
    lower common-scale value elsewhere, that value as a diamond); right, 100 (1 − free / fixed). Two panels of the
    optimum's value and of the lowest reached drew the same bars twice when, as in every bundled run, they agree."""
    import pandas as pd

    from lvcore.viz.study_figures import common_objective_bars

    rows = pd.DataFrame([
        {"subject": "HV1 angles", "mode": "fixed", "objective_common_at_best": 20.0, "objective_common_min": 20.0},
        {"subject": "HV1 angles", "mode": "free", "objective_common_at_best": 15.0, "objective_common_min": 15.0},
        {"subject": "HV2 base", "mode": "fixed", "objective_common_at_best": 10.0, "objective_common_min": 10.0},
        {"subject": "HV2 base", "mode": "free", "objective_common_at_best": 12.0, "objective_common_min": 12.0}])
    fig = common_objective_bars(rows)
    bars = {t.name: list(t.y) for t in fig.data if t.type == "bar" and t.xaxis == "x"}
    assert bars == {"fixed angles": [20.0, 10.0], "free angles": [15.0, 12.0]}
    (change,) = [t for t in fig.data if t.xaxis == "x2"]
    assert list(change.x) == ["HV1 angles", "HV2 base"] and list(change.y) == pytest.approx([25.0, -20.0])
    assert not [t for t in fig.data if t.type == "scatter"]  # nothing lower elsewhere: no diamonds ...
    assert "no run reached a lower" in fig.layout.annotations[0].text  # ... and the panel says so
    rows.loc[1, "objective_common_min"] = 14.0  # HV1 free reached 14 elsewhere on the common scale
    fig = common_objective_bars(rows)
    (diamond,) = [t for t in fig.data if t.type == "scatter"]
    assert list(diamond.x) == ["HV1 angles"] and list(diamond.y) == [14.0] and "free" in diamond.name
    assert "no run reached" not in fig.layout.annotations[0].text


def test_truth_marks_are_drawn_as_the_calibration_caption_says():
    """The Calibration page's caption promises the hidden truth of a SYNTHETIC volunteer as "red dashed lines in the
    histograms, red crosses in the pair plot": the posterior histograms mark it with red dashed vertical lines and
    the pair plot with red x markers (it once promised dashed lines where crosses were drawn)."""
    from pathlib import Path

    import arviz as az

    from lvcore.app import PAGES_DIR
    from lvcore.viz.inference_figures import pair_figure
    from lvcore.viz.report_figures import posterior_prior_figure

    page = " ".join((Path(PAGES_DIR) / "5_Calibration.py").read_text(encoding="utf-8").split())
    assert 'red dashed lines in the histograms, red crosses in the pair " "plot' in page
    truth = {"a": 0.5, "b": 5.0}
    rng = np.random.default_rng(0)
    draws = {n: rng.normal(v, 0.1 * v, 200) for n, v in truth.items()}
    hist = posterior_prior_figure(draws, {"a": (0.1, 1.0), "b": (1.0, 10.0)}, truth=truth, title="posterior")
    lines = [s for s in hist.layout.shapes if s.type == "line" and s.x0 == s.x1]
    assert sorted(s.x0 for s in lines) == [0.5, 5.0]
    assert all(s.line.color == "red" and s.line.dash == "dash" for s in lines)
    idata = az.from_dict(posterior={n: v.reshape(1, -1) for n, v in draws.items()})
    (mark,) = [t for t in pair_figure(idata, var_names=("a", "b"), truth=truth).data if t.name == "truth"]
    assert mark.marker.color == "red" and mark.marker.symbol == "x"


def test_panelled_error_figures_have_one_panel_per_value_and_every_case():
    """grouped_violins and error_strips (chapter Figs 9.11, 9.12, 9.14): one subplot per value of the panel
    column, titled "<label>: <value>", every case drawn once, the height 300 px a panel (at least 360)."""
    import pandas as pd

    from lvcore.viz.report_figures import error_strips, grouped_violins

    rng = np.random.default_rng(0)
    df = pd.DataFrame({"main_operator": np.repeat(["op2", "op3", "pc5"], 8), "geo": np.tile(["pc5", "pc10"], 12),
                       "param": np.tile(["a", "a", "b", "b"], 6), "err": rng.random(24)})
    v = grouped_violins(df, panel="main_operator", x="geo", y="err", title="t", yaxis_title="e", nonnegative=True)
    s = error_strips(df, panel="main_operator", param="param", x="geo", y="err", title="t", yaxis_title="e",
                     panel_label="operator")
    assert [a.text for a in v.layout.annotations] == ["main operator: op2", "main operator: op3", "main operator: pc5"]
    assert [a.text for a in s.layout.annotations] == ["operator: op2", "operator: op3", "operator: pc5"]
    assert v.layout.height == s.layout.height == 900
    assert sum(len(t.y) for t in v.data) == len(df)
    cases = [t for t in s.data if t.marker.size == 10]
    assert sum(len(t.y) for t in cases) == len(df)
    assert all(t.spanmode == "hard" for t in v.data)
