"""Exact uniform scaling: strains unchanged and volumes x s^3 in the FE simulator (lvcore.geometry.scaling)."""
from __future__ import annotations

import numpy as np
import pytest

from lvcore.geometry.analytic import DEFAULT_LV
from lvcore.geometry.scaling import (ScaledForward, scale_ellipsoid, scale_nodes, scale_outputs,
                                     size_normalised_scores)


def _case(lv, base="sliding", resolution="coarse"):
    surf = lambda e: {"rs": e.rs, "rl": e.rl, **({"ry": e.ry} if e.ry is not None else {})}  # noqa: E731
    return {"geometry": {"kind": "ellipsoid", "endo": surf(lv.endo), "epi": surf(lv.epi), "base_z": lv.base_z,
                         "resolution": resolution},
            "material": {"law": "holzapfel-ogden", "a": 0.5, "b": 3.0, "af": 1.5, "bf": 5.0},
            "fibres": {"alpha_endo": -60.0, "alpha_epi": 60.0},
            "load": {"pressure": 8.0, "units": "mmHg"}, "boundary": {"base": base}}


@pytest.fixture(scope="module")
def unit_result():
    from lvcore.mechanics.simulate import simulate

    return simulate(_case(DEFAULT_LV), raise_on_failure=True)


@pytest.mark.parametrize("s", [0.6, 1.5])
def test_fe_scaling_is_exact(unit_result, s):
    """The FE simulator on the geometry scaled by s: strains equal, reference and deformed cavities x s^3."""
    from lvcore.mechanics.simulate import simulate

    r = simulate(_case(scale_ellipsoid(DEFAULT_LV, s)), raise_on_failure=True)
    y1, ys = unit_result.outputs(), r.outputs()
    np.testing.assert_allclose(ys[1:], y1[1:], rtol=1e-6, atol=1e-9)          # issue: <= 0.1 %; measured ~1e-11
    np.testing.assert_allclose(ys[0], y1[0] * s**3, rtol=1e-6)                 # LVV x s^3
    np.testing.assert_allclose(r.cavity_volume_mm3[0], unit_result.cavity_volume_mm3[0] * s**3, rtol=1e-9)
    # and the prediction of the identity, as scale_outputs writes it
    np.testing.assert_allclose(scale_outputs(y1, s), ys, rtol=1e-3, atol=1e-6)


def test_fe_scaling_fails_for_non_uniform_stretch(unit_result):
    """A check that can fail: stretching only the long axis is not a similarity and changes the strains."""
    from lvcore.geometry.analytic import EllipsoidSurface, TruncatedEllipsoidLV
    from lvcore.mechanics.simulate import simulate

    lv = DEFAULT_LV
    longer = TruncatedEllipsoidLV(EllipsoidSurface(lv.endo.rs, lv.endo.rl * 1.5, lv.endo.ry),
                                  EllipsoidSurface(lv.epi.rs, lv.epi.rl * 1.5, lv.epi.ry), lv.base_z * 1.5)
    r = simulate(_case(longer), raise_on_failure=True)
    assert np.max(np.abs(r.outputs()[1:] - unit_result.outputs()[1:])) > 1e-2


def test_scale_outputs_numpy_and_jax():
    import jax
    import jax.numpy as jnp

    y = np.r_[100.0, -0.1 * np.ones(24)]
    np.testing.assert_allclose(scale_outputs(y, 2.0), np.r_[800.0, y[1:]])
    assert y[0] == 100.0  # not modified in place
    g = jax.grad(lambda s: scale_outputs(jnp.asarray(y), s)[0])(1.5)
    np.testing.assert_allclose(g, 3 * 1.5**2 * 100.0)


def test_size_normalised_scores_are_size_free():
    """One shape at three sizes gets the same scores, and scales in the ratio of the sizes."""
    from lvcore.geometry.measures import cavity_volume
    from lvcore.geometry.shape_model import load_shape_model
    from lvcore.geometry.template import DEFAULT_TEMPLATE

    model = load_shape_model()
    x = model.reconstruct(np.array([0.5, -1.0, 0.3, 0.2, -0.4]))
    ref = size_normalised_scores(x, 5, model)
    v_mean, v_x = float(cavity_volume(model.mean, DEFAULT_TEMPLATE)), float(cavity_volume(x, DEFAULT_TEMPLATE))
    assert ref.scale == pytest.approx((v_x / v_mean) ** (1 / 3), rel=1e-9)
    for s in (0.6, 1.5):
        res = size_normalised_scores(scale_nodes(x, s), 5, model)
        assert res.scale == pytest.approx(s * ref.scale, rel=1e-9)
        np.testing.assert_allclose(res.h, ref.h, atol=1e-8)
        # the reconstruction error is measured at the subject's size: x s^2
        assert res.projection_mse_cm2 == pytest.approx(ref.projection_mse_cm2 * s**2, rel=1e-6, abs=1e-12)
        # the plain projection of a scaled shape is far outside the emulator's box, the normalised one is not
        assert np.max(np.abs(res.unscaled_h)) > 2.0 > np.max(np.abs(res.h))
    # the mean shape is its own size
    assert size_normalised_scores(model.mean, 5, model).scale == pytest.approx(1.0, rel=1e-12)


def test_scaled_forward_wraps_any_forward():
    from lvcore.testing.analytic import AnalyticForward

    f = AnalyticForward()
    p = {"a": 0.6, "b": 5.0, "af": 1.5, "bf": 5.0}
    sf = ScaledForward(f, 0.8)
    np.testing.assert_allclose(np.asarray(sf(p)), scale_outputs(np.asarray(f(p)), 0.8))
    batch = sf.jacobian({k: [v] for k, v in p.items()})
    ref = f.jacobian({k: [v] for k, v in p.items()})
    np.testing.assert_allclose(batch.outputs[0, 0], ref.outputs[0, 0] * 0.512)
    np.testing.assert_allclose(batch.jacobian[0, 0], ref.jacobian[0, 0] * 0.512)
    np.testing.assert_allclose(batch.jacobian[0, 1:], ref.jacobian[0, 1:])
    from lvcore.core import JacobianForward, TraceableForward
    from lvcore.mechanics.forward import SimulatorForward

    assert sf.input_names == f.input_names and isinstance(sf, TraceableForward)  # the wrapped model's capabilities
    np.testing.assert_allclose(np.asarray(sf.apply(np.array([list(p.values())]))), batch.outputs, rtol=1e-12)
    plain = ScaledForward(SimulatorForward(resolution="fast"), 0.8)
    assert not isinstance(plain, JacobianForward) and not hasattr(plain, "apply")
    with pytest.raises(ValueError, match="scale"):
        ScaledForward(f, 0.0)
