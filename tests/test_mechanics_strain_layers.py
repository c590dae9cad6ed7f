"""The strain layers (inner half, mid-wall, whole wall, outer half): one home for the names, the old names as
aliases with the same numbers, each layer's strains on the default LV, whole wall = volume-weighted halves, and an
analytic inflation whose strains are ordered through the wall and converge under transmural refinement."""
import numpy as np
import pytest

from lvcore.domain import outputs
from lvcore.exceptions import CaseError
from lvcore.mechanics import case as case_mod
from lvcore.mechanics import observables as ob
from lvcore.mechanics.case import Case
from lvcore.mechanics.resolution import LVResolution
from lvcore.mechanics.simulate import build_mesh

LAYERS = ("inner_half", "mid_wall", "whole_wall", "outer_half")


def _strains(x, mesh, layer):
    return np.asarray(ob.regional_strains(x, ob.strain_operator(mesh, layer)))


def test_the_layer_names_have_one_home():
    assert tuple(outputs.STRAIN_LAYERS) == LAYERS
    assert ob.STRAIN_LAYERS is outputs.STRAIN_LAYERS
    assert not hasattr(case_mod, "STRAIN_LAYERS") or case_mod.STRAIN_LAYERS is outputs.STRAIN_LAYERS
    assert outputs.STRAIN_LAYERS["mid_wall"] == (0.25, 0.75)
    assert outputs.strain_layer("endocardial") == "inner_half" and outputs.strain_layer("wall") == "whole_wall"
    with pytest.raises(ValueError, match="inner_half, mid_wall, whole_wall, outer_half"):
        outputs.strain_layer("epicardial")


def test_old_names_load_as_aliases_and_unknown_names_are_refused(fast_lv_case):
    base = {"geometry": {"kind": "default", "resolution": "fast"},
            "material": {"law": "holzapfel-ogden", "a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6},
            "load": {"pressure": 8, "units": "mmHg"}}
    assert Case.from_dict(base).outputs.strain_layer == "inner_half"
    for old, new in outputs.STRAIN_LAYER_ALIASES.items():
        c = Case.from_dict({**base, "outputs": {"strain_layer": old}})
        assert c.outputs.strain_layer == new
        assert c.to_dict()["outputs"] == {"strain_layer": new}
    with pytest.raises(CaseError, match="outputs.strain_layer.*did you mean 'outer_half'"):
        Case.from_dict({**base, "outputs": {"strain_layer": "outer-half"}})
    mesh = build_mesh(fast_lv_case)
    a, b = ob.strain_operator(mesh, "endocardial"), ob.strain_operator(mesh, "inner_half")
    for name in ("connectivity", "dNdX", "e_c", "weights"):
        assert np.array_equal(getattr(a, name), getattr(b, name))


def test_band_pieces():
    assert ob.layer_pieces("inner_half", 1) == [(0, 0.0, 0.5)]  # as before: the inner half of the element
    assert ob.layer_pieces("inner_half", 2) == [(0, 0.0, 0.5)]  # the inner element layer
    assert ob.layer_pieces("whole_wall", 1) == [(0, 0.0, 0.5), (0, 0.5, 1.0)]
    assert ob.layer_pieces("mid_wall", 1) == [(0, 0.25, 0.5), (0, 0.5, 0.75)]
    assert ob.layer_pieces("mid_wall", 2) == [(0, 0.25, 0.5), (1, 0.5, 0.75)]
    assert ob.layer_pieces("outer_half", 4) == [(2, 0.5, 0.75), (3, 0.75, 1.0)]


def test_each_layer_on_the_default_lv_at_a_fixed_theta(fast_lv_case, fast_lv_result):
    """θ = (0.6, 1.3, 1.0, 3.6), 8 mmHg, fast mesh: region mean, region 1 and region 24 of each layer."""
    mesh = build_mesh(fast_lv_case)
    x = fast_lv_result.reference_nodes + fast_lv_result.displacement
    expected = {"inner_half": (-0.179226, -0.163939, -0.154003), "mid_wall": (-0.144852, -0.13891, -0.107087),
                "whole_wall": (-0.144956, -0.137519, -0.112256), "outer_half": (-0.11891, -0.116788, -0.081827)}
    got = {L: _strains(x, mesh, L) for L in LAYERS}
    for L, (mean, first, last) in expected.items():
        assert (got[L].mean(), got[L][0], got[L][-1]) == pytest.approx((mean, first, last), abs=2e-6), L
    # the simulator's own strains are the default layer's
    np.testing.assert_allclose(fast_lv_result.strains, got["inner_half"], rtol=0, atol=1e-12)
    # filling stretches the inner wall most: every region's inner-half strain is the most negative
    assert np.all(got["inner_half"] < got["whole_wall"]) and np.all(got["whole_wall"] < got["outer_half"])


@pytest.mark.parametrize("resolution", ["fast", LVResolution(6, 4, 2)])
def test_whole_wall_is_the_volume_weighted_mean_of_the_halves(fast_lv_result, resolution):
    c = Case.default_lv({"a": 0.6, "b": 1.3, "af": 1.0, "bf": 3.6}, resolution="fast")
    if not isinstance(resolution, str):
        c = Case.from_dict({**c.to_dict(), "geometry": {"kind": "default", "resolution": resolution.case_dict()}})
    mesh = build_mesh(c)
    rng = np.random.default_rng(0)  # any deformation: the identity is one of the quadrature
    x = mesh.nodes * (1.0 + 0.05 * rng.random((1, 3))) + 0.2 * rng.standard_normal(mesh.nodes.shape)
    ops = {L: ob.strain_operator(mesh, L) for L in ("inner_half", "outer_half", "whole_wall")}
    e = {L: np.asarray(ob.regional_strains(x, op)) for L, op in ops.items()}
    v = {L: op.volumes for L, op in ops.items()}
    np.testing.assert_allclose(v["whole_wall"], v["inner_half"] + v["outer_half"], rtol=1e-13)
    mean = (v["inner_half"] * e["inner_half"] + v["outer_half"] * e["outer_half"]) / v["whole_wall"]
    np.testing.assert_allclose(e["whole_wall"], mean, rtol=0, atol=1e-13)


def _inflated(nt: int, k_mm2: float = 300.0):
    """A circular truncated ellipsoid (nt elements through the wall) under the incompressible plane inflation of a
    thick cylinder, r² = R² + k: the circumferential stretch r/R falls through the wall."""
    c = Case.from_dict({
        "geometry": {"kind": "ellipsoid", "endo": {"rs": 25, "rl": 45}, "epi": {"rs": 35, "rl": 55}, "base_z": 5,
                     "resolution": LVResolution(8, 4, nt).case_dict()},
        "material": {"law": "neo-hookean", "mu": 10}, "load": {"pressure": 1, "units": "kPa"}})
    mesh = build_mesh(c)
    X = mesh.nodes
    R = np.hypot(X[:, 0], X[:, 1])
    f = np.sqrt(1.0 + k_mm2 / np.maximum(R, 1e-9) ** 2)
    f[R < 1e-9] = 1.0
    x = X.copy()
    x[:, :2] *= f[:, None]
    return mesh, x


def test_thick_cylinder_inflation_orders_the_layers_and_converges():
    got = {}
    for nt in (1, 2, 4):
        mesh, x = _inflated(nt)
        got[nt] = {L: _strains(x, mesh, L) for L in LAYERS}
    g = got[4]
    # analytic ordering: E_c = -k / (2 (R² + k)) is most negative at the endocardium
    assert np.all(g["inner_half"] < g["mid_wall"]) and np.all(g["mid_wall"] < g["outer_half"])
    assert np.all(g["inner_half"] < g["whole_wall"]) and np.all(g["whole_wall"] < g["outer_half"])
    for L in LAYERS:  # transmural refinement converges for every layer
        d12 = np.abs(got[1][L] - got[2][L]).max()
        d24 = np.abs(got[2][L] - got[4][L]).max()
        assert d24 < 0.5 * d12 + 1e-9, (L, d12, d24)
        assert d24 < 2e-3, (L, d24)
