"""The shape model's representation error: statistics, the bundled asset and the infer-mode likelihood."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lvcore.exceptions import DataError
from repo_scripts import load_script

ROOT = Path(__file__).resolve().parents[1]


def _rep(cov=None, lvv=0.02, measures=None):
    from lvcore.inference.representation_error import RepresentationError

    if cov is None:
        a = np.random.default_rng(1).normal(size=(24, 24)) * 0.004
        cov = a @ a.T
    return RepresentationError(5, cov, lvv, measures or {"reference_volume_ml": 0.03})


def test_stats_recover_a_known_covariance_and_count_a_bias():
    """Many draws of a known covariance give it back; a pure bias is an error too (second moment about zero)."""
    from lvcore.inference.representation_error import representation_error_stats

    rng = np.random.default_rng(0)
    a = rng.normal(size=(24, 24)) * 0.003
    true = a @ a.T + np.diag(np.full(24, 1e-5))
    d = rng.multivariate_normal(np.zeros(24), true, size=20000)
    st = representation_error_stats(d, rng.normal(0, 0.02, 20000), {"long_axis_mm": np.full(20000, -0.01)})
    cov = np.asarray(st["strain_cov"])
    assert np.max(np.abs(cov - true)) < 0.05 * np.max(np.abs(true))
    assert st["lvv_rel_sd"] == pytest.approx(0.02, rel=0.03)
    assert st["measure_rel_sd"]["long_axis_mm"] == pytest.approx(0.01)
    # a systematic bias b with no scatter: the floor is b b^T (shrunk), not zero
    b = np.linspace(-0.01, 0.01, 24)
    st = representation_error_stats(np.tile(b, (50, 1)), np.zeros(50))
    cov = np.asarray(st["strain_cov"])
    assert np.trace(cov) == pytest.approx(float(b @ b), rel=1e-6)
    with pytest.raises(DataError, match="strain_deltas"):
        representation_error_stats(np.zeros((5, 23)), np.zeros(5))


def test_the_bundled_asset_is_synthetic_reproducible_and_positive_definite():
    from lvcore.inference.representation_error import FORMAT, asset_file, load_representation_error

    meta = json.loads(asset_file(5).read_text())
    assert meta["format"] == FORMAT and meta["synthetic"] and "SYNTHETIC" in meta["label"]
    assert meta["command"].startswith("python scripts/build_representation_error.py")
    assert (ROOT / "scripts" / "build_representation_error.py").is_file()
    assert asset_file(5).stat().st_size < 200_000
    rep = load_representation_error(5)
    assert rep.n_cases == len(meta["cases"]) >= 30
    assert np.linalg.eigvalsh(rep.strain_cov).min() > 0
    # the stored statistics are those of the stored cases
    from lvcore.inference.representation_error import representation_error_stats

    st = representation_error_stats([c["strain_delta"] for c in meta["cases"]],
                                    [c["lvv_rel_delta"] for c in meta["cases"]])
    np.testing.assert_allclose(st["strain_cov"], rep.strain_cov, rtol=1e-4, atol=1e-10)
    assert st["lvv_rel_sd"] == pytest.approx(rep.lvv_rel_sd, rel=1e-4)
    with pytest.raises(DataError, match="build it with"):
        load_representation_error(7)


def test_strain_likelihood_is_the_multivariate_normal_with_the_floor():
    import jax.numpy as jnp
    from scipy.stats import multivariate_normal, norm

    from lvcore.inference.models import lvv_sd, strain_likelihood

    class Fw:
        representation = _rep()

    rng = np.random.default_rng(3)
    mean, y, s2 = rng.normal(-0.15, 0.03, 24), rng.normal(-0.15, 0.03, 24), 0.02 ** 2
    got = float(strain_likelihood(jnp.asarray(mean), s2, Fw()).log_prob(jnp.asarray(y)))
    want = multivariate_normal(mean, s2 * np.eye(24) + Fw.representation.strain_cov).logpdf(y)
    assert got == pytest.approx(want, rel=1e-10)
    plain = float(strain_likelihood(jnp.asarray(mean), s2, None).log_prob(jnp.asarray(y)))
    assert plain == pytest.approx(norm(mean, 0.02).logpdf(y).sum(), rel=1e-10)
    assert got != pytest.approx(plain, rel=1e-3)   # the floor changes the likelihood
    assert float(lvv_sd(150.0, 5.0, Fw())) == pytest.approx(np.hypot(5.0, 0.02 * 150.0))
    assert lvv_sd(150.0, 5.0, None) == 5.0


def test_infer_mode_models_and_measures_use_the_floor():
    """The iid model's log density with an inferred geometry carrying the floor = the hand-written one."""
    import jax.numpy as jnp
    from numpyro.infer.util import log_density
    from scipy.stats import multivariate_normal, norm

    from lvcore.emulator import load_emulator
    from lvcore.inference.geometry_prior import inferred_geometry_forward
    from lvcore.inference.models import iid_model, prior_bounds

    rep = _rep()
    fw = inferred_geometry_forward(load_emulator("chapter"), measures={"reference_volume_ml": 80.0},
                                   measure_sd={"reference_volume_ml": 4.0}, representation=rep)
    assert fw.measure_sds == {"reference_volume_ml": 4.0}
    assert fw.likelihood_sds["reference_volume_ml"] == pytest.approx(np.hypot(4.0, 0.03 * 80.0))
    h = np.array([0.3, -0.2, 0.1, 0.0, 0.4])
    p = {"a": 0.5, "b": 3.0, "af": 1.5, "bf": 5.0, **{f"h{i + 1}": h[i] for i in range(5)},
         "log_scale": np.log(0.95), "sigma_s2": 0.03 ** 2}
    eta = np.asarray(fw({**p, "scale": 0.95}))
    y = eta + np.r_[6.0, np.full(24, 0.01)]
    got_floor = float(log_density(iid_model, (jnp.asarray(y),), {"forward": fw}, p)[0])
    fw0 = inferred_geometry_forward(load_emulator("chapter"), measures={"reference_volume_ml": 80.0},
                                    measure_sd={"reference_volume_ml": 4.0}, representation=None)
    got_plain = float(log_density(iid_model, (jnp.asarray(y),), {"forward": fw0}, p)[0])
    v0 = float(fw.measures_of(h, 0.95)["reference_volume_ml"])
    diff_want = (norm(eta[0], np.hypot(5.0, rep.lvv_rel_sd * eta[0])).logpdf(y[0]) - norm(eta[0], 5.0).logpdf(y[0])
                 + multivariate_normal(eta[1:], 0.03 ** 2 * np.eye(24) + rep.strain_cov).logpdf(y[1:])
                 - norm(eta[1:], 0.03).logpdf(y[1:]).sum()
                 + norm(v0, fw.likelihood_sds["reference_volume_ml"]).logpdf(80.0) - norm(v0, 4.0).logpdf(80.0))
    assert got_floor - got_plain == pytest.approx(diff_want, rel=1e-8)
    assert set(prior_bounds(False, fw)) == {"a", "b", "af", "bf"}


def _script():
    return load_script("scripts/build_representation_error.py")


@pytest.mark.slow
def test_a_shape_model_shape_has_no_representation_error_and_a_cohort_shape_has(tmp_path):
    """The control: a scaled shape-model shape (the mean shape, 1.2 times its size) is split into
    s = 1.2 and h = 0 and reconstructs exactly, so both FE solves agree; a held-out cohort shape does
    not (the effect the floor accounts for)."""
    from lvcore.geometry.cohort import ROLE_VOLUNTEER, load_cohort
    from lvcore.geometry.scaling import scale_nodes
    from lvcore.geometry.shape_model import load_shape_model

    mod = _script()
    model = load_shape_model()
    theta = {"a": 0.8, "b": 4.0, "af": 1.5, "bf": 6.0}
    inside = scale_nodes(model.mean, 1.2, base_z=0.0)
    rec = mod.one_case(inside, model, 5, theta, tmp_path)
    assert rec["scale"] == pytest.approx(1.2, rel=1e-6)
    assert np.max(np.abs(rec["strain_delta"])) < 1e-6 and abs(rec["lvv_rel_delta"]) < 1e-6
    assert all(abs(v) < 1e-9 for v in rec["measure_rel_delta"].values())
    _, vols = load_cohort().select(ROLE_VOLUNTEER)
    rec = mod.one_case(vols[0], model, 5, theta, tmp_path)
    assert np.sqrt(np.mean(np.square(rec["strain_delta"]))) > 1e-3


def test_a_mesh_gets_the_floor_and_pc_scores_do_not():
    """--geometry FILE: a template or volume mesh is seen through its 5-mode projection, so its forward model
    carries the floor (same outputs, capabilities and likelihood variances as infer mode); PC scores, the mean
    shape and --representation-error off get none."""
    import jax.numpy as jnp
    from numpyro.infer.util import log_density
    from scipy.stats import multivariate_normal, norm

    from lvcore.emulator import load_emulator
    from lvcore.emulator.forward import emulator_forward
    from lvcore.geometry.scaling import ScaledForward
    from lvcore.inference import verdict
    from lvcore.inference.models import iid_model, representation_error
    from lvcore.inference.representation_error import FlooredForward, MESH_KINDS, given_geometry_floor

    rep = _rep()
    h = np.array([0.3, -0.2, 0.1, 0.0, 0.4])
    base = ScaledForward(emulator_forward(load_emulator("chapter"), h), 1.1)
    for kind in MESH_KINDS:
        fw, rec = given_geometry_floor(base, kind, "floor", 5, representation=rep)
        assert isinstance(fw, FlooredForward) and representation_error(fw) is rep
        assert rec["mode"] == "floor" and rec["n_cases"] == rep.n_cases
    for kind, mode in (("scores", "floor"), ("mean", "floor"), ("template-mesh", "off")):
        fw0, rec0 = given_geometry_floor(base, kind, mode, 5, representation=rep)
        assert fw0 is base and rec0 is None and representation_error(fw0) is None
    with pytest.raises(ValueError, match="floor.*off"):
        given_geometry_floor(base, "template-mesh", "on")
    fw, _ = given_geometry_floor(base, "volume-mesh", "floor", 5, representation=rep)
    theta = {"a": 0.5, "b": 3.0, "af": 1.5, "bf": 5.0}
    np.testing.assert_array_equal(np.asarray(fw(theta)), np.asarray(base(theta)))
    assert fw.input_names == base.input_names and fw.scale == 1.1 and hasattr(fw, "apply") == hasattr(base, "apply")
    # the iid likelihood of a mesh with the floor: MVN(eta, sigma_S^2 I + Sigma_rep), LVV sd with r_V
    eta = np.asarray(base(theta))
    y = eta + np.r_[6.0, np.full(24, 0.01)]
    p = {**theta, "sigma_s2": 0.03 ** 2}
    got = float(log_density(iid_model, (jnp.asarray(y),), {"forward": fw}, p)[0])
    plain = float(log_density(iid_model, (jnp.asarray(y),), {"forward": base}, p)[0])
    want = (norm(eta[0], np.hypot(5.0, rep.lvv_rel_sd * eta[0])).logpdf(y[0]) - norm(eta[0], 5.0).logpdf(y[0])
            + multivariate_normal(eta[1:], 0.03 ** 2 * np.eye(24) + rep.strain_cov).logpdf(y[1:])
            - norm(eta[1:], 0.03).logpdf(y[1:]).sum())
    assert got - plain == pytest.approx(want, rel=1e-8)
    # the samplers pass the mesh's scores and scale at run time (one compiled program for every subject) and
    # keep the floor: the bound forward model gives the same log density
    from lvcore.inference.samplers import runtime_conditions

    template, values = runtime_conditions(fw)
    assert values is not None and template.representation is rep
    bound = template.bind(values)
    assert float(log_density(iid_model, (jnp.asarray(y),), {"forward": bound}, p)[0]) == pytest.approx(got, rel=1e-10)
    # the kept compiled samplers (samplers._template_key) never mix a floored and an unfloored model
    from lvcore.inference.samplers import _template_key

    plain_template, _ = runtime_conditions(base)
    assert _template_key(template) != _template_key(plain_template)
    assert _template_key(template) == _template_key(runtime_conditions(given_geometry_floor(
        ScaledForward(emulator_forward(load_emulator("chapter"), -h), 0.9), "template-mesh", "floor", 5,
        representation=rep)[0])[0])   # another mesh, the same floor: the same program
    # and the verdict's consistency p-values use the same variances
    sd = verdict.output_sds(eta, 5.0, 0.035, fw)
    assert sd[0] == pytest.approx(np.hypot(5.0, rep.lvv_rel_sd * eta[0]))
    np.testing.assert_allclose(sd[1:], np.sqrt(0.035 ** 2 + np.diag(rep.strain_cov)))


def test_calibrate_with_a_mesh_records_the_floor(tmp_path, monkeypatch):
    """lvcore calibrate --geometry MESH: summary.json's geometry.representation_error is the floor's record;
    --representation-error off records None. The floored forward model reaches the posterior predictive of the
    .nc file and the posterior-predictive check (their noise: tests/test_inference_floor_consumers.py)."""
    from lvcore.cli import main
    from lvcore.inference import diagnostics, plausibility
    from lvcore.inference.models import representation_error
    from lvcore.resources import asset_path

    seen = {"y_rep": [], "ppc": []}
    real_idata, real_check = diagnostics.to_inference_data, plausibility.check_result
    monkeypatch.setattr(diagnostics, "to_inference_data",
                        lambda *a, **k: seen["y_rep"].append(k.get("forward")) or real_idata(*a, **k))
    monkeypatch.setattr(plausibility, "check_result",
                        lambda *a, **k: seen["ppc"].append(k.get("forward")) or real_check(*a, **k))
    mesh = asset_path("volunteers", "SYNTHETIC_HV1_geometry.vtu")
    data = asset_path("volunteers", "SYNTHETIC_HV1_measured.csv")
    for mode in ("floor", "off"):
        out = tmp_path / mode
        rc = main(["calibrate", "--data", str(data), "--geometry", str(mesh), "--representation-error", mode,
                   "--model", "iid", "--chains", "1", "--warmup", "60", "--samples", "40", "--out", str(out), "--json"])
        assert rc in (0, 1, 4)
        rec = json.loads((out / "summary.json").read_text())[0]["geometry"]
        assert rec["kind"] == "template-mesh"
        if mode == "floor":
            rep = rec["representation_error"]
            assert rep["mode"] == "floor" and rep["n_cases"] >= 30
            # scaled to this mesh's own projection error (at the mean size), with the fit behind it
            assert rep["projection_mse_cm2"] == pytest.approx(rec["projection_mse_cm2"] / rec["scale"] ** 2)
            fit = rep["projection_fit"]
            assert rep["strain_scale"] == pytest.approx(
                (fit["intercept"] + fit["slope"] * rep["projection_mse_cm2"]) / fit["mean"])
            for k in seen:
                assert representation_error(seen[k][-1]).strain_scale == pytest.approx(rep["strain_scale"])
        else:
            assert rec["representation_error"] is None
            assert all(representation_error(seen[k][-1]) is None for k in seen)


@pytest.mark.slow
def test_calibrate_discrepancy_with_a_mesh_uses_and_records_the_floor(tmp_path):
    """lvcore calibrate --model discrepancy --geometry MESH: summary.json records the floor it used (None with
    --representation-error off), and the blocked sampler uses it: with one seed the two posteriors differ (the
    sampler that ignored the floor drew the same samples for both)."""
    from lvcore.cli import main
    from lvcore.resources import asset_path

    mesh = asset_path("volunteers", "SYNTHETIC_HV1_geometry.vtu")
    data = asset_path("volunteers", "SYNTHETIC_HV1_measured.csv")
    recs = {}
    for mode in ("floor", "off"):
        out = tmp_path / mode
        rc = main(["calibrate", "--data", str(data), "--geometry", str(mesh), "--representation-error", mode,
                   "--model", "discrepancy", "--chains", "1", "--warmup", "30", "--samples", "20", "--out", str(out),
                   "--json"])
        assert rc in (0, 1, 4)
        recs[mode] = json.loads((out / "summary.json").read_text())[0]
        assert recs[mode]["model"] == "discrepancy" and recs[mode]["sampler"] == "hmc_gibbs"
    floor = recs["floor"]["geometry"]["representation_error"]
    assert floor["mode"] == "floor" and floor["strain_scale"] > 0
    assert recs["off"]["geometry"]["representation_error"] is None
    assert any(recs["floor"][k]["median"] != recs["off"][k]["median"] for k in ("a", "b", "af", "bf", "sigma_s2"))


def test_the_mesh_floor_scales_with_its_own_projection_error():
    """projection_scaling_fit recovers a known linear growth of the strain error with the projection error;
    for_projection gives 1 at the cohort's mean, grows with the error, and measures it at the mean size."""
    from lvcore.inference.representation_error import load_representation_error, projection_scaling_fit

    rng = np.random.default_rng(3)
    p = rng.uniform(0.001, 0.02, 4000)
    c0, c1 = 1e-5, 2e-3
    d = rng.normal(size=(4000, 24)) * np.sqrt(c0 + c1 * p)[:, None]
    fit = projection_scaling_fit(p, d)
    assert fit["intercept"] == pytest.approx(c0, rel=0.1) and fit["slope"] == pytest.approx(c1, rel=0.05)
    assert fit["spearman_rho"] > 0.3 and fit["spearman_p"] < 1e-6 and fit["n"] == 4000
    # no relation: the slope is (near) 0 and the fit says so
    flat = projection_scaling_fit(p, rng.normal(size=(4000, 24)) * 0.005)
    assert flat["slope"] * 0.02 < 0.1 * flat["intercept"] and flat["spearman_p"] > 1e-3
    with pytest.raises(DataError, match="3 cases"):
        projection_scaling_fit([0.1, 0.2], np.zeros((2, 24)))

    rep = _rep()
    rep = type(rep)(rep.n_pc, rep.strain_cov, rep.lvv_rel_sd, projection_fit={**fit, "mse_max": 0.02})
    mean_p = (fit["mean"] - fit["intercept"]) / fit["slope"]
    assert rep.for_projection(mean_p).strain_scale == pytest.approx(1.0)
    lo, hi = rep.for_projection(0.002), rep.for_projection(0.02)
    assert lo.strain_scale < 1 < hi.strain_scale
    np.testing.assert_allclose(hi.effective_strain_cov, hi.strain_scale * rep.strain_cov)
    assert hi.strain_rms == pytest.approx(np.sqrt(hi.strain_scale) * rep.strain_rms)
    assert not hi.record()["beyond_cohort"] and rep.for_projection(0.05).record()["beyond_cohort"]
    # a mesh 1.3x the mean size with the same shape error: the same factor (strains do not see size)
    assert rep.for_projection(0.01 * 1.3 ** 2, 1.3).strain_scale == pytest.approx(rep.for_projection(0.01).strain_scale)
    with pytest.raises(DataError, match="projection_mse_cm2"):
        rep.for_projection(-1.0)
    # an asset without per-case projection errors: the mean floor, unchanged
    assert _rep().for_projection(0.01).strain_scale == 1.0
    # the bundled asset carries the fit
    assert load_representation_error(5).projection_fit["n"] >= 30


def test_two_meshes_share_one_program_with_their_own_floors():
    """The per-mesh factor is a run-time value: two meshes' floored forward models have the same template
    key (one compiled sampler) and each bound model's likelihood uses its own strain_scale * Sigma_rep."""
    import jax.numpy as jnp
    from numpyro.infer.util import log_density
    from scipy.stats import multivariate_normal, norm

    from lvcore.emulator import load_emulator
    from lvcore.emulator.forward import emulator_forward
    from lvcore.geometry.scaling import ScaledForward
    from lvcore.inference import verdict
    from lvcore.inference.models import iid_model
    from lvcore.inference.representation_error import given_geometry_floor, projection_scaling_fit
    from lvcore.inference.samplers import _template_key, runtime_conditions

    rng = np.random.default_rng(4)
    p = rng.uniform(0.001, 0.02, 200)
    fit = projection_scaling_fit(p, rng.normal(size=(200, 24)) * np.sqrt(1e-5 + 2e-3 * p)[:, None])
    base_rep = _rep()
    base_rep = type(base_rep)(5, base_rep.strain_cov, base_rep.lvv_rel_sd, projection_fit=fit)
    h = np.array([0.3, -0.2, 0.1, 0.0, 0.4])
    emu = load_emulator("chapter")
    theta = {"a": 0.5, "b": 3.0, "af": 1.5, "bf": 5.0, "sigma_s2": 0.03 ** 2}
    keys, dens = [], []
    for mse in (0.002, 0.02):
        base = ScaledForward(emulator_forward(emu, h), 1.0)
        fw, rec = given_geometry_floor(base, "template-mesh", "floor", 5, representation=base_rep,
                                       projection_mse_cm2=mse)
        assert rec["strain_scale"] == pytest.approx(fw.representation.strain_scale)
        template, values = runtime_conditions(fw)
        keys.append(_template_key(template))
        eta = np.asarray(base(theta))
        y = eta + np.r_[6.0, np.full(24, 0.01)]
        got = float(log_density(iid_model, (jnp.asarray(y),), {"forward": template.bind(values)}, theta)[0])
        k = fw.representation.strain_scale
        plain = float(log_density(iid_model, (jnp.asarray(y),), {"forward": base}, theta)[0])
        want = (norm(eta[0], np.hypot(5.0, base_rep.lvv_rel_sd * eta[0])).logpdf(y[0]) - norm(eta[0], 5.0).logpdf(y[0])
                + multivariate_normal(eta[1:], 0.03 ** 2 * np.eye(24) + k * base_rep.strain_cov).logpdf(y[1:])
                - norm(eta[1:], 0.03).logpdf(y[1:]).sum())
        assert got - plain == pytest.approx(want, rel=1e-8)
        np.testing.assert_allclose(verdict.output_sds(eta, 5.0, 0.035, fw)[1:],
                                   np.sqrt(0.035 ** 2 + k * np.diag(base_rep.strain_cov)))
        dens.append(got)
    assert keys[0] == keys[1] and dens[0] != dens[1]
