import numpy as np

from lvcore.geometry.analytic import DEFAULT_LV
from lvcore.geometry.template import DEFAULT_TEMPLATE
from lvcore.viz.geometry_views import (explained_variance_figure, node_distances, operator_mse_figure,
                                       render_distance_map, template_surface)


def test_template_surface_interpolates_fields_isoparametrically():
    X = DEFAULT_LV.nodes(DEFAULT_TEMPLATE)
    surf = template_surface(X, X[:, 2], name="z")
    assert np.allclose(surf.point_data["z"], surf.points[:, 2], atol=1e-9)
    # the surface reaches the base plane and the epicardial apex
    assert np.isclose(surf.points[:, 2].max(), DEFAULT_LV.base_z)
    assert np.isclose(surf.points[:, 2].min(), -DEFAULT_LV.epi.rl)


def test_renders_and_figures():
    X = DEFAULT_LV.nodes(DEFAULT_TEMPLATE)
    Y = X + np.array([0.0, 0.0, 1.0])
    assert np.allclose(node_distances(X, Y), 1.0)
    png = render_distance_map(X, Y, window_size=(200, 160))
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    fig = explained_variance_figure([0.5, 0.3, 0.2])
    assert np.allclose(fig.data[1].y, [0.5, 0.8, 1.0])
    table = {"ks": [5, 6], "blocks": [{"main": "op1", "others": ["op2"], "rows": [
        {"patient": "SYNTHETIC-P01", "operator_mse": {"op2": 0.01}, "pca_mse": {"5": 0.02, "6": 0.005}}]}]}
    fig = operator_mse_figure(table, "op1")
    assert fig.data[1].y[0] == 0.01
    # one legend entry per patient plus one per line style, not one per line (the 18 entries)
    assert [t.name for t in fig.data if t.showlegend is not False] == ["P01", "solid: k-mode PCA", "dashed: vs op2"]
    assert fig.layout.yaxis.dtick == 1  # log ticks at decades only
