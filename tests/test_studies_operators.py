"""The three-operator SQP study: own-geometry refit, Laplace covariance vs a finite-difference Hessian, outputs."""
import json

import numpy as np
import pytest

from forward_double import JacobianDouble
from lvcore.core.forward import ForwardBatch, as_columns
from lvcore.optimise.sqp import OperatorLoss
from lvcore.domain.outputs import THETA_NAMES
from lvcore.studies import operators as ops

TRUTH = np.array(ops.THETA_TRUE)


M = np.random.default_rng(7).normal(size=(24, 4)) * 0.03


class StandIn(JacobianDouble):
    """A cheap numpy closed-form forward (SYNTHETIC) whose 'geometry' shifts the reference theta."""

    input_names = THETA_NAMES
    label = "numpy stand-in (tests)"

    def __init__(self, shift):
        self.ref = np.array([0.6, 5.0, 1.5, 5.0]) * (1.0 + shift * np.array([1, -1, 2, 1]))

    def _batch(self, inputs, jacobian):
        cols, n = as_columns(inputs, self.input_names)
        th = np.column_stack([cols[k] for k in THETA_NAMES])
        u = np.log(th / self.ref)
        y = np.column_stack([120.0 - 20.0 * np.tanh(u @ [0.5, 0.3, 0.3, 0.2]), -0.15 + u @ M.T + 0.004 * (u**2).sum(1)[:, None]])
        jac = None
        if jacobian:
            t = np.tanh(u @ [0.5, 0.3, 0.3, 0.2])
            du = 1.0 / th                                           # d u_j / d theta_j
            j0 = -20.0 * (1 - t**2)[:, None] * np.array([0.5, 0.3, 0.3, 0.2]) * du
            js = (M[None, :, :] + 0.008 * u[:, None, :]) * du[:, None, :]
            jac = np.concatenate([j0[:, None, :], js], axis=1)
        return ForwardBatch(y, np.ones(n, bool), ("",) * n, jac)


def stand_in(geometry_name: str) -> StandIn:
    shift = {"op1": 0.0, "op2": 0.08, "op3": -0.05}.get(geometry_name.split("/")[0], 0.0)
    shift += {"": 0.0, "pc5": 0.03, "pc10": 0.01}[geometry_name.split("/")[1] if "/" in geometry_name else ""]
    return StandIn(shift)


def loss_value(forward, loss, theta):
    return loss.value_and_output_gradient(forward(dict(zip(THETA_NAMES, theta))))[0]


def test_stand_in_jacobian_is_right():
    f = StandIn(0.02)
    th = TRUTH * 1.2
    b = f.jacobian(dict(zip(THETA_NAMES, th)))
    fd = np.column_stack([(f(dict(zip(THETA_NAMES, th + e))) - f(dict(zip(THETA_NAMES, th - e)))) / 2e-6
                          for e in np.eye(4) * 1e-6])
    np.testing.assert_allclose(b.jacobian[0], fd, rtol=1e-5, atol=1e-8)


def test_laplace_covariance_matches_finite_difference_hessian():
    f = StandIn(0.0)
    y_star = np.asarray(f(dict(zip(THETA_NAMES, TRUTH))))
    loss = OperatorLoss(y_star, 80.0, 80.0)              # own geometry: zero residual at the truth
    b = f.jacobian(dict(zip(THETA_NAMES, TRUTH)))
    r, J = ops.residual_jacobian(loss, b.outputs[0], b.jacobian[0])
    assert np.max(np.abs(r)) < 1e-12
    # the residual Jacobian's J^T r equals the loss gradient / 2 away from the optimum
    th = TRUTH * 1.1
    b2 = f.jacobian(dict(zip(THETA_NAMES, th)))
    r2, J2 = ops.residual_jacobian(loss, b2.outputs[0], b2.jacobian[0])
    g = b2.jacobian[0].T @ loss.value_and_output_gradient(b2.outputs[0])[1]
    np.testing.assert_allclose(2 * J2.T @ r2, g, rtol=1e-10)
    # central-difference Hessian of L / (2 sigma^2) at the optimum
    sigma = ops.SIGMA_RESIDUAL
    h = 1e-4 * TRUTH
    H = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            ei, ej = np.eye(4)[i] * h[i], np.eye(4)[j] * h[j]
            H[i, j] = (loss_value(f, loss, TRUTH + ei + ej) - loss_value(f, loss, TRUTH + ei - ej)
                       - loss_value(f, loss, TRUTH - ei + ej) + loss_value(f, loss, TRUTH - ei - ej)) / (4 * h[i] * h[j])
    cov_fd = np.linalg.inv(H / (2 * sigma**2))
    cov = ops.laplace_covariance(J, sigma)
    np.testing.assert_allclose(cov, cov_fd, rtol=1e-4)
    d = TRUTH * 0.01
    assert ops.mahalanobis(TRUTH + d, TRUTH, cov) == pytest.approx(np.sqrt(d @ np.linalg.inv(cov_fd) @ d), rel=1e-4)


def test_stand_in_study_writes_the_issue_format(tmp_path):
    res = ops.run_study(["SYNTHETIC-P01"], out=tmp_path, forward_factory=stand_in)
    data = json.loads((tmp_path / "operators.json").read_text())
    fits = data["fits"]
    assert len(fits) == 12 and data["meta"]["complete_study"] is False and "PARTIAL" in data["meta"]["budget"]
    assert {f["test_geometry"] for f in fits} == {"op1", "op2", "op3", "pc5", "pc10"}
    for f in fits:
        assert {"patient", "main_operator", "test_geometry", "converged", "theta_hat", "theta_abs_error",
                "strain_rmse_forward", "output_rmse_refit", "mahalanobis"} <= set(f), f.get("message")
        assert f["converged"] and f["test_geometry"] != f["main_operator"]
    # a different "geometry" moves theta_hat; the refit lowers the strain error on the test geometry
    assert max(max(f["theta_abs_error"]) for f in fits) > 1e-3
    assert (tmp_path / "operators_fits.csv").is_file() and (tmp_path / "fig_9_14_output_errors.html").is_file()
    assert len(json.loads((tmp_path / "rss_surfaces.json").read_text())) == 12
    assert res["findings"]["n_fits"] == 12 and "pc10" in res["findings"]["output_rmse_refit"]
    # a second run resumes from the saved fits without refitting
    again = ops.run_study(["SYNTHETIC-P01"], out=tmp_path, forward_factory=lambda g: pytest.fail("refitted"))
    assert again["fits"] == res["fits"]


@pytest.mark.slow
def test_fit_on_the_main_operators_own_geometry_returns_the_truth_with_the_simulator(tmp_path):
    geoms = ops.patient_geometries("SYNTHETIC-P02", tmp_path)
    y_star = ops._data_task("SYNTHETIC-P02", "op1", geoms, "fast", None)
    # test geometry = the main operator's own: call fit_one with op1 as the geometry of "test" op1
    rec = ops.fit_one("SYNTHETIC-P02", "op2", "op1", y_star, {**geoms, "op2": geoms["op1"]}, resolution="fast")
    assert rec["converged"], rec.get("message")
    np.testing.assert_allclose(rec["theta_hat"], TRUTH, atol=1e-6)
    assert rec["strain_rmse_forward"] < 1e-12 and rec["mahalanobis"] < 1e-3
    assert np.all(np.isfinite(rec["covariance"]))


def test_unknown_patient_names_the_study_patients(tmp_path):
    with pytest.raises(ops.LVCoreError, match="SYNTHETIC-P01"):
        ops.patient_geometries("SYNTHETIC-P99", tmp_path)


def test_cli_names_a_bad_patient(tmp_path, capsys):
    from lvcore.cli import main

    assert main(["study", "operators", "--patients", "SYNTHETIC-P99", "--out", str(tmp_path)]) == 2
    assert "SYNTHETIC-P01" in capsys.readouterr().err


def test_docs_quote_the_bound_aware_laplace_medians_of_the_shipped_fits():
    from pathlib import Path

    from lvcore.studies.results import bundled_studies_dir

    f = ops.load(bundled_studies_dir())["findings"]
    text = " ".join((Path(__file__).resolve().parents[1] / "docs" / "studies.md").read_text().split())
    n = sum(f["n_on_bound"].values())
    inner = f["median_mahalanobis_interior"]
    assert (f"{n} of {f['n_fits']} fits on a bound" in text
            and f"interior medians are {inner['operator']:.2f} (operators), {inner['pc5']:.2f} (pc5) and "
                f"{inner['pc10']:.2f} (pc10)" in text)
