"""--geometry infer: geometric measures of (h, s) in JAX and the forward model with sampled geometry."""
from __future__ import annotations

import numpy as np
import pytest

from lvcore.exceptions import DataError


@pytest.fixture(scope="module")
def shape():
    from lvcore.inference.geometry_prior import shape_measures

    return shape_measures(5)


def test_measures_equal_the_mesh_measures_and_scale_exactly(shape):
    """Cavity/wall volume and long axis of s * reconstruct(h) = geometry_info of the scaled mesh."""
    from lvcore.geometry.measures import geometry_info
    from lvcore.geometry.scaling import scale_nodes
    from lvcore.geometry.shape_model import load_shape_model

    model = load_shape_model()
    h, s = np.array([1.2, -0.7, 0.4, 1.5, -1.0]), 0.8
    ref = geometry_info(scale_nodes(model.reconstruct(h), s, base_z=0.0))
    got = {k: float(v) for k, v in shape(h, s).items()}
    assert got["reference_volume_ml"] == pytest.approx(ref["cavity_volume_ml"], rel=1e-9)
    assert got["wall_volume_ml"] == pytest.approx(ref["wall_volume_ml"], rel=1e-9)
    assert got["long_axis_mm"] == pytest.approx(ref["length_mm"], rel=1e-9)
    # the shape model's span of reference cavities at s = 1 (the 62-110 mL) vs any size with s
    assert 50 < float(shape(np.array([2.0, -2, 0, 0, 0]), 1.0)["reference_volume_ml"]) < 60


def test_measures_are_differentiable(shape):
    """jax.grad of the reference volume agrees with central differences in h and s."""
    import jax
    import jax.numpy as jnp

    f = lambda h, s: shape(h, s)["reference_volume_ml"]  # noqa: E731
    h, s = jnp.array([0.3, -0.2, 0.5, 0.1, -0.4]), 1.1
    gh, gs = jax.grad(f, argnums=(0, 1))(h, s)
    eps = 1e-5
    for i in range(5):
        e = jnp.zeros(5).at[i].set(eps)
        assert float(gh[i]) == pytest.approx(float(f(h + e, s) - f(h - e, s)) / (2 * eps), rel=1e-6, abs=1e-8)
    assert float(gs) == pytest.approx(3 * float(f(h, s)) / s, rel=1e-9)


def test_forward_with_sampled_geometry_is_the_scaled_emulator():
    from lvcore.emulator.forward import emulator_forward
    from lvcore.emulator import load_emulator
    from lvcore.geometry.scaling import ScaledForward
    from lvcore.inference.geometry_prior import inferred_geometry_forward

    emu = load_emulator("chapter")
    fw = inferred_geometry_forward(emu, name="chapter", measures={"reference_volume_ml": 50.0})
    h, s = np.array([0.5, -0.3, 0.2, 0.0, 1.0]), 0.85
    theta = {"a": 0.5, "b": 3.0, "af": 1.5, "bf": 5.0}
    got = np.asarray(fw({**theta, **{f"h{i + 1}": h[i] for i in range(5)}, "scale": s}))
    ref = np.asarray(ScaledForward(emulator_forward(emu, h, name="chapter"), s)(theta))
    np.testing.assert_allclose(got, ref, rtol=1e-12)
    assert fw.input_names == ("a", "b", "af", "bf")
    assert fw.latent_names == ("h1", "h2", "h3", "h4", "h5", "scale")
    assert fw.latent_bounds["h1"] == (-2.0, 2.0)
    assert set(fw.input_bounds) == {"a", "b", "af", "bf"}


def test_sample_latents_observes_the_measures():
    """The model's trace holds h, the scale and one observed site per measure."""
    import jax
    from numpyro.handlers import seed, trace

    from lvcore.emulator import load_emulator
    from lvcore.inference.geometry_prior import inferred_geometry_forward

    fw = inferred_geometry_forward(load_emulator("chapter"), measures={"reference_volume_ml": 50.0,
                                                                      "long_axis_mm": 70.0})
    tr = trace(seed(fw.sample_latents, jax.random.PRNGKey(0))).get_trace()
    assert tr["reference_volume_ml_obs"]["is_observed"] and tr["long_axis_mm_obs"]["is_observed"]
    assert "wall_volume_ml_obs" not in tr
    lo, hi = fw.latent_bounds["scale"]
    assert lo <= float(tr["scale"]["value"]) <= hi and -2 <= float(tr["h3"]["value"]) <= 2


@pytest.mark.parametrize("measures,match", [({"reference_volume_ml": 2.0}, "--reference-volume"),
                                            ({"wall_volume_ml": "x"}, "must be a number"),
                                            ({"height": 3.0}, "unknown geometric measure")])
def test_bad_measures_are_refused(measures, match):
    from lvcore.inference.geometry_prior import check_measures

    with pytest.raises(DataError, match=match):
        check_measures(measures)
