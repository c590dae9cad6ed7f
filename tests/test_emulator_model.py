"""Emulator training, save/load, box checks, gradients and batching, on a known smooth function."""
import json
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lvcore.emulator.io import load_emulator, load_validation, save_emulator
from lvcore.emulator.model import ExtrapolationWarning
from lvcore.emulator.network import MLP, from_arrays, to_arrays
from lvcore.emulator.training import TrainingConfig, metrics, train_emulator
from lvcore.exceptions import EmulatorError

NAMES = ("a", "b", "h1")
LOWER, UPPER = np.array([0.1, 0.5, -2.0]), np.array([10.0, 20.0, 2.0])


def truth(x):
    """A known smooth volume-and-strain-like function of (a, b, h1)."""
    x = np.atleast_2d(x)
    a, b, h = x[:, 0], x[:, 1], x[:, 2]
    lvv = 100 + 30 / (1 + a) + 5 * np.sin(h) + 2 * np.log(b)
    r = np.arange(24)
    s = -0.05 - 0.1 / (1 + a[:, None] * (1 + 0.02 * r)) + 0.01 * np.cos(h)[:, None]
    return np.column_stack([lvv, s])


def draw(rng, n):
    u = rng.random((n, 3))
    return np.column_stack([np.exp(np.log(0.1) + u[:, 0] * np.log(100)), np.exp(np.log(0.5) + u[:, 1] * np.log(40)),
                            -2 + 4 * u[:, 2]])


@pytest.fixture(scope="module")
def trained():
    rng = np.random.default_rng(0)
    xt, xv, xs = draw(rng, 600), draw(rng, 200), draw(rng, 300)
    cfg = TrainingConfig(architectures=((50, 50), (20, 20)), max_epochs=500, patience=80, batch_size=64, decay_epochs=150)
    emu = train_emulator(xt, truth(xt), xv, truth(xv), input_names=NAMES, name="smooth", lower=LOWER, upper=UPPER,
                         fixed={"edp": 8.0}, config=cfg, x_test=xs, y_test=truth(xs))
    return emu, xs


def test_training_recovers_a_known_smooth_function(trained):
    emu, xs = trained
    m = emu.metadata
    assert m["validation"]["mse_standardised"] < 1e-3
    assert m["test"]["lvv_rmse_ml"] < 0.5          # range of LVV here is ~30 mL
    assert m["test"]["strain_rmse"] < 0.002        # range of strains ~0.09
    # architecture chosen by validation MSE among the candidates
    search = m["training"]["search"]
    assert m["architecture"]["hidden"] == min(search, key=lambda s: s["valid_mse"])["hidden"]
    # metrics are what they say: recompute on the test set
    pred = np.asarray(emu.predict(xs))
    np.testing.assert_allclose(np.sqrt(np.mean((pred - truth(xs)) ** 2, axis=0)), m["test"]["rmse"], rtol=1e-10)


def test_save_load_round_trip_identical(tmp_path, trained):
    emu, xs = trained
    save_emulator(emu, tmp_path / "smooth", validation={"inputs": xs, "outputs": truth(xs), "predictions": emu.apply(xs)})
    back = load_emulator(tmp_path / "smooth")
    np.testing.assert_array_equal(np.asarray(back.predict(xs)), np.asarray(emu.predict(xs)))
    assert back.input_names == NAMES and back.fixed == {"edp": 8.0}
    meta = json.loads((tmp_path / "smooth" / "metadata.json").read_text())
    for key in ("input_names", "bounds", "input_scaler", "output_scaler", "architecture", "training", "validation", "test"):
        assert key in meta
    assert len(meta["training"]["set_hash"]) == 64
    with np.load(tmp_path / "smooth" / "network.npz", allow_pickle=False) as npz:  # plain arrays, no pickle
        assert sorted(npz.files) == [f"layer{i}_{k}" for i in range(3) for k in ("bias", "weight")]
    assert load_validation(tmp_path / "smooth")["inputs"].shape == xs.shape
    # a bare name resolves through the search path
    import os
    os.environ["LVCORE_EMULATORS"] = str(tmp_path)
    try:
        assert load_emulator("smooth").name == "smooth"
        with pytest.raises(EmulatorError, match="not found"):
            load_emulator("no-such-emulator")
    finally:
        del os.environ["LVCORE_EMULATORS"]
    (tmp_path / "smooth" / "metadata.json").write_text("{}")
    with pytest.raises(EmulatorError, match="lacks key"):
        load_emulator(tmp_path / "smooth")


def test_out_of_box_warns_and_strict_raises(trained):
    emu, _ = trained
    inside = dict(a=1.0, b=2.0, h1=0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        emu.predict(**inside)                       # no warning inside
        emu.predict(**inside, edp=8.0)              # fixed input at its training value: fine
    with pytest.warns(ExtrapolationWarning, match=r"a=20 not in \[0.1, 10\]"):
        y = emu.predict(a=20.0, b=2.0, h1=0.5)
    assert y.shape == (25,)                          # still predicts, but not silently
    with pytest.raises(EmulatorError, match="strict"):
        emu.predict(a=20.0, b=2.0, h1=0.5, strict=True)
    with pytest.warns(ExtrapolationWarning, match="edp was fixed at 8"):
        emu.predict(**inside, edp=12.0)
    with pytest.raises(EmulatorError, match="no input"):
        emu.predict(**inside, alpha_endo=-60.0)
    with pytest.raises(EmulatorError, match="needs input"):
        emu.predict(a=1.0, b=2.0)
    with pytest.raises(EmulatorError, match="shape"):
        emu.predict(np.ones((4, 2)))


def test_gradient_through_predict_matches_finite_differences(trained):
    emu, _ = trained
    x0 = np.array([0.8, 3.0, 0.3])

    def f(x):
        return emu.predict(a=x[0], b=x[1], h1=x[2])

    jac = np.asarray(jax.jacfwd(f)(jnp.asarray(x0)))
    assert jac.shape == (25, 3)
    eps = 1e-6 * np.maximum(1.0, np.abs(x0))
    fd = np.column_stack([(np.asarray(f(x0 + e)) - np.asarray(f(x0 - e))) / (2 * e[i])
                          for i, e in enumerate(np.diag(eps))])
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-9)
    # apply is pure and usable under grad / vmap (as inside numpyro)
    g = jax.grad(lambda x: emu.apply(x)[0])(jnp.asarray(x0))
    np.testing.assert_allclose(g, jac[0], rtol=1e-10)


def test_prediction_is_batched(trained):
    emu, xs = trained
    batch = np.asarray(emu.predict(xs))
    assert batch.shape == (xs.shape[0], 25)
    rows = np.stack([np.asarray(emu.predict(x)) for x in xs[:5]])
    np.testing.assert_allclose(rows, batch[:5], rtol=1e-12, atol=1e-12)
    grid = np.asarray(emu.predict(a=np.linspace(0.2, 5, 7)[:, None], b=np.full((1, 4), 2.0), h1=0.0))
    assert grid.shape == (7, 4, 25)
    assert np.asarray(emu.predict(xs.reshape(3, 100, 3))).shape == (3, 100, 25)


def test_batches_are_padded_to_few_compiled_shapes(trained):
    """predict pads a batch to a few row counts (one compilation each) and returns exactly the unpadded rows."""
    from lvcore.emulator.model import PAD_ROWS, padded_rows

    emu, xs = trained
    assert [padded_rows(n) for n in (0, 1, 2, 3, 441, 484, 529)] == [1, 1, 2, 4, 512, 512, 1024]
    assert padded_rows(PAD_ROWS) == PAD_ROWS and padded_rows(PAD_ROWS + 1) == 2 * PAD_ROWS
    assert padded_rows(100_000) == 25 * PAD_ROWS  # at most one PAD_ROWS block extra
    for n in (3, 37, 300):
        np.testing.assert_array_equal(np.asarray(emu.predict(xs[:n])), np.asarray(emu.apply(xs[:n])))
    # grid sizes 17..22 squared share one compiled shape (512 rows): no new compilation as a grid slider moves
    sizes = {emu._apply._cache_size()}
    for n in range(17, 23):
        emu.predict(np.repeat(xs[:1], n * n, axis=0))
        sizes.add(emu._apply._cache_size())
    assert max(sizes) - min(sizes) <= 1


def test_network_arrays_round_trip_and_init_scale():
    net = MLP(9, 25, (100, 200), seed=3)
    assert net.hidden == (100, 200)
    w = np.concatenate([np.ravel(a) for a in to_arrays(net).values()])
    assert abs(w.std() - 0.1) < 0.005 and abs(w.mean()) < 0.005      # N(0, 0.1^2) init
    back = from_arrays(to_arrays(net))
    x = np.random.default_rng(0).standard_normal((4, 9))
    np.testing.assert_array_equal(np.asarray(back(x)), np.asarray(net(x)))
    with pytest.raises(EmulatorError):
        from_arrays({"layer0_weight": np.ones((3, 2)), "layer0_bias": np.ones(3)})


def test_metrics_known_values():
    y = np.zeros((100, 25))
    p = y.copy()
    p[:, 0] = 2.0
    p[:, 1:] = -0.01
    m = metrics(y, p)
    assert m["lvv_rmse_ml"] == pytest.approx(2.0) and m["strain_rmse"] == pytest.approx(0.01)
    assert m["p99_abs"][0] == pytest.approx(2.0)


@pytest.mark.slow
def test_parallel_architecture_search_equals_serial():
    """Two worker processes train the same networks (same seeds) as one process."""
    from lvcore.emulator.training import search_architectures

    rng = np.random.default_rng(3)
    x, xv = rng.standard_normal((120, 3)), rng.standard_normal((40, 3))
    y, yv = truth(np.abs(x) + 0.2)[:, :4], truth(np.abs(xv) + 0.2)[:, :4]
    y, yv = (y - y.mean(0)) / y.std(0), (yv - y.mean(0)) / y.std(0)
    cfg = TrainingConfig(architectures=((8, 8), (12, 6)), max_epochs=30, patience=30, batch_size=32)
    serial = search_architectures(x, y, xv, yv, cfg, workers=1)
    parallel = search_architectures(x, y, xv, yv, cfg, workers=2)
    assert [f.hidden for f in parallel] == [(8, 8), (12, 6)]
    for s, p in zip(serial, parallel):
        assert p.best_epoch == s.best_epoch
        np.testing.assert_allclose(p.valid_mse, s.valid_mse, rtol=1e-10)
        for a, b in zip(to_arrays(s.network).values(), to_arrays(p.network).values()):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


def test_lbfgs_refinement_lowers_validation_loss_and_is_recorded():
    rng = np.random.default_rng(5)
    xt, xv = draw(rng, 300), draw(rng, 100)
    base = dict(architectures=((20, 20),), max_epochs=60, patience=60, batch_size=64)
    plain = train_emulator(xt, truth(xt), xv, truth(xv), input_names=NAMES, name="p", config=TrainingConfig(**base))
    refined = train_emulator(xt, truth(xt), xv, truth(xv), input_names=NAMES, name="r",
                             config=TrainingConfig(**base, lbfgs_iterations=200, lbfgs_check_every=50))
    rep = refined.metadata["training"]["lbfgs"]
    assert plain.metadata["training"]["lbfgs"] is None
    assert rep["iterations"] == 200 and len(rep["history"]) == 4
    assert rep["valid_after"] < 0.5 * rep["valid_before"]
    # the same Adam result went in: the refined emulator is better in physical units too
    assert refined.metadata["validation"]["strain_rmse"] < plain.metadata["validation"]["strain_rmse"]


def test_lvv_weight_enters_the_loss_and_is_validated():
    from lvcore.emulator.training import output_weights

    w = output_weights(TrainingConfig(lvv_weight=24.0))
    assert w.shape == (25,) and np.isclose(w.mean(), 1.0) and np.isclose(w[0] / w[1], 24.0)
    np.testing.assert_array_equal(output_weights(TrainingConfig()), np.ones(25))
    with pytest.raises(EmulatorError, match="LVV loss weight"):
        output_weights(TrainingConfig(lvv_weight=0.0))
    # the L-BFGS stage has its own weight, falling back to lvv_weight
    cfg = TrainingConfig(lvv_weight=2.0, lbfgs_lvv_weight=10.0)
    assert np.isclose(output_weights(cfg)[0] / output_weights(cfg)[1], 2.0)
    assert np.isclose(output_weights(cfg, stage="lbfgs")[0] / output_weights(cfg, stage="lbfgs")[1], 10.0)
    assert np.isclose(output_weights(TrainingConfig(lvv_weight=3.0), stage="lbfgs")[0], 3.0 * 25 / 27)


# ----- a prior mean the network corrects (subject emulators) -------------------------------------------------------
def subject_truth(x, h1=0.7, scale=1.2):
    """A 'subject' at h1 = 0.7 and size 1.2: the smooth function's shape, slightly different physics."""
    x = np.atleast_2d(x)
    y = truth(np.column_stack([x, np.full(len(x), h1)]))
    y[:, 0] *= scale ** 3 * (1 + 0.03 * x[:, 0] / (1 + x[:, 0]))
    y[:, 1:] += 0.002 * np.log(x[:, 1])[:, None]
    return y


def test_prior_mean_targets_invert_the_combination():
    from lvcore.emulator.model import combine_with_prior, correction_targets

    rng = np.random.default_rng(1)
    y = np.column_stack([50 + 100 * rng.random(7), -0.2 * rng.random((7, 24))])
    p = np.column_stack([50 + 100 * rng.random(7), -0.2 * rng.random((7, 24))])
    np.testing.assert_allclose(combine_with_prior(correction_targets(y, p), p), y, rtol=1e-13)
    np.testing.assert_allclose(np.asarray(combine_with_prior(jnp.asarray(correction_targets(y, p)), jnp.asarray(p))),
                               y, rtol=1e-13)


def test_a_prior_mean_lets_few_rows_learn_a_subject(tmp_path, trained):
    import shutil

    from lvcore.emulator.model import PriorMean, prior_outputs

    prior_emu, _ = trained
    prior = PriorMean(prior_emu, {"h1": 0.7}, 1.2)
    rng = np.random.default_rng(5)
    xt, xv, xs = draw(rng, 40)[:, :2], draw(rng, 40)[:, :2], draw(rng, 200)[:, :2]
    cfg = TrainingConfig(architectures=((20, 20),), max_epochs=300, patience=100, batch_size=16, decay_epochs=100,
                         lbfgs_iterations=200)
    kw = dict(input_names=("a", "b"), name="subject", lower=LOWER[:2], upper=UPPER[:2], config=cfg, x_test=xs,
              y_test=subject_truth(xs))
    direct = train_emulator(xt, subject_truth(xt), xv, subject_truth(xv), **kw)
    corrected = train_emulator(xt, subject_truth(xt), xv, subject_truth(xv), prior=prior, **kw)
    # the prior is the smooth function at h1 = 0.7 with LVV x 1.2^3, as a PriorMean says
    p = prior_outputs(prior, ("a", "b"), xs)
    np.testing.assert_allclose(p[:, 0], np.asarray(prior_emu.apply(np.column_stack([xs, np.full(200, 0.7)])))[:, 0]
                               * 1.2 ** 3, rtol=1e-12)
    # metrics are of the full outputs, and the prior makes 40 rows enough
    pred = np.asarray(corrected.predict(xs))
    assert corrected.metadata["test"]["lvv_rmse_ml"] == pytest.approx(
        float(np.sqrt(np.mean((pred[:, 0] - subject_truth(xs)[:, 0]) ** 2))), rel=1e-9)
    assert corrected.metadata["test"]["lvv_rmse_ml"] < 0.3 * direct.metadata["test"]["lvv_rmse_ml"], \
        (corrected.metadata["test"], direct.metadata["test"])
    assert corrected.metadata["test"]["lvv_rmse_ml"] < 1.0  # LVV ~ 170-260 mL here
    # gradients flow through the prior
    g = jax.grad(lambda x: corrected.apply(x)[0])(jnp.array([1.0, 3.0]))
    eps = 1e-6
    fd = (np.asarray(corrected.apply(np.array([1.0 + eps, 3.0])))[0]
          - np.asarray(corrected.apply(np.array([1.0 - eps, 3.0])))[0]) / (2 * eps)
    assert float(g[0]) == pytest.approx(fd, rel=1e-5)
    # saved with a copy of the prior: self-contained and relocatable
    save_emulator(corrected, tmp_path / "emu")
    assert (tmp_path / "emu" / "prior" / "network.npz").is_file()
    shutil.copytree(tmp_path / "emu", tmp_path / "moved")
    again = load_emulator(tmp_path / "moved")
    assert again.prior is not None and again.prior.inputs == {"h1": 0.7} and again.prior.scale == 1.2
    np.testing.assert_allclose(np.asarray(again.apply(xs)), np.asarray(corrected.apply(xs)), rtol=1e-12)
    # a missing or escaping prior folder is a clear error
    meta = json.loads((tmp_path / "moved" / "metadata.json").read_text())
    meta["prior"]["directory"] = "../emu/prior"
    (tmp_path / "moved" / "metadata.json").write_text(json.dumps(meta))
    with pytest.raises(EmulatorError, match="subfolder"):
        load_emulator(tmp_path / "moved")
    shutil.rmtree(tmp_path / "emu" / "prior")
    with pytest.raises(EmulatorError, match="prior mean's emulator folder"):
        load_emulator(tmp_path / "emu")
    # a prior that needs an input nobody gives is refused
    with pytest.raises(EmulatorError, match="needs input 'h1'"):
        train_emulator(xt, subject_truth(xt), xv, subject_truth(xv), prior=PriorMean(prior_emu, {}, 1.0), **kw)
