"""One fit of the operator study: the patient's geometries, the SQP refit of θ on a test geometry with the
simulator's adjoint gradients, the Laplace covariance and Mahalanobis distance of θ̂, and its loss surfaces.

Part of :mod:`lvcore.studies.operators` (the study; its docstring describes the design and each fit's record).
"""
from __future__ import annotations

import time
from itertools import combinations
from pathlib import Path
from typing import Sequence

import numpy as np

from lvcore.domain.conditions import SIGMA_S, THETA_TILDE
from lvcore.core.forward import ForwardBatch, as_columns
from lvcore.exceptions import LVCoreError
from lvcore.mechanics.forward import AdjointSimulatorForward, SimulatorForward
from lvcore.domain.outputs import THETA_NAMES

#: The chapter's ground truth θ̃ (a, af in kPa).
THETA_TRUE = tuple(THETA_TILDE[n] for n in THETA_NAMES)
#: Numbers of PCA modes of the reconstructed test geometries.
PC_TESTS = (5, 10)
#: Standard deviation (strain units) of the residuals of loss (9.11) in the Laplace approximation.
SIGMA_RESIDUAL = SIGMA_S
#: Parameter pairs of the loss surfaces (Fig 9.13).
PAIRS = tuple(combinations(THETA_NAMES, 2))
#: Gauss–Newton surface: grid points per axis and the span (factor around θ̂, log scale).
GN_GRID, SURFACE_SPAN = 9, 2.0
#: The chapter's geometric finding (Table 9.4): 10 PCs beat a new operator in 94 % of cases.
CHAPTER_SHARE_10PC = 0.94
#: SLSQP's ``ftol`` on loss (9.11) (:func:`lvcore.optimise.sqp.refit_theta`'s default).
SQP_TOL = 1e-10
#: θ̂ within this relative distance of a prior bound (Table 9.1) counts as on the bound: there the Laplace
#: approximation behind the Mahalanobis distance is invalid (the mode is not a stationary point).
BOUND_TOL = 1e-3


def theta_dict(v) -> dict:
    """θ as ``{name: value}`` from a dict or a sequence in :data:`THETA_NAMES` order."""
    if isinstance(v, dict):
        return {n: float(v[n]) for n in THETA_NAMES if n in v}
    return dict(zip(THETA_NAMES, (float(x) for x in v)))


# ----------------------------------------------------------------------------- geometry
def early_volume_ml(nodes) -> float:
    """Early-diastolic (reference) cavity volume of a template geometry (mL)."""
    from lvcore.geometry.measures import cavity_volume
    from lvcore.geometry.template import DEFAULT_TEMPLATE

    return float(cavity_volume(np.asarray(nodes, float), DEFAULT_TEMPLATE)) / 1000.0


def patient_geometries(patient: str, out_dir, operator_geometries=None, shape_model=None) -> dict:
    """Write the patient's geometries as VTU under ``out_dir``; name -> {path, v_early_ml}.

    Names: each operator (``op1``...) and ``<main>/pc5``, ``<main>/pc10`` for
    the PC reconstructions of each main operator's geometry.
    """
    from lvcore.geometry.cohort import load_operator_geometries
    from lvcore.geometry.io import write_template_mesh
    from lvcore.geometry.shape_model import load_shape_model

    og = operator_geometries or load_operator_geometries()
    sm = shape_model or load_shape_model()
    if patient not in og.patients:
        raise LVCoreError(f"--patients: unknown patient '{patient}' (operator study: {', '.join(og.patients)})")
    if patient in set(sm.train_ids):
        raise LVCoreError(f"patient '{patient}' is in the shape model's training set; hold it out")
    p = og.patients.index(patient)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    geoms = {}

    def put(name, nodes):
        path = out_dir / f"{patient.replace('-', '_')}_{name.replace('/', '_')}.vtu"
        if not path.is_file():
            write_template_mesh(path, nodes, metadata={"source": f"SYNTHETIC operator study {patient} {name}"})
        geoms[name] = {"path": str(path), "v_early_ml": early_volume_ml(nodes)}

    for o, op in enumerate(og.operators):
        g = og.nodes[p, o]
        put(op, g)
        for k in PC_TESTS:
            put(f"{op}/pc{k}", sm.reconstruct_nodes(g, k))
    return geoms


def test_geometries(main: str, operators: Sequence[str]) -> list[tuple[str, str]]:
    """``(test_geometry label, geometry name)`` for one main operator: the other operators, then pc5, pc10."""
    return [(o, o) for o in operators if o != main] + [(f"pc{k}", f"{main}/pc{k}") for k in PC_TESTS]


def operator_names(geoms: dict) -> list[str]:
    """The operators' own geometries among :func:`patient_geometries` (not their ``<op>/pcK`` reconstructions)."""
    return [k for k in geoms if "/" not in k]


def test_geometry_name(main: str, test: str, geoms: dict) -> str:
    """Name in ``geoms`` of test geometry ``test`` (another operator, ``pc5`` or ``pc10``) for main operator ``main``."""
    return dict(test_geometries(main, operator_names(geoms)))[test]


# ----------------------------------------------------------------------------- forward with a cache
class CachedForward:
    """One-point cache around a :class:`~lvcore.core.forward.JacobianForward` (the SQP asks for the same θ more
    than once; the Jacobian is reused)."""

    def __init__(self, inner):
        self.inner = inner
        self.input_names = tuple(inner.input_names)
        self.label = inner.label
        self.cache: dict = {}
        self.simulations = 0

    @property
    def input_bounds(self):
        return self.inner.input_bounds

    def evaluate(self, inputs) -> ForwardBatch:
        return self._cached(inputs, False)

    def jacobian(self, inputs) -> ForwardBatch:
        return self._cached(inputs, True)

    def _cached(self, inputs, jacobian: bool) -> ForwardBatch:
        cols, n = as_columns(inputs, self.input_names, self.label)
        if n != 1:
            self.simulations += n
            return self.inner.jacobian(cols) if jacobian else self.inner.evaluate(cols)
        key = tuple(float(cols[k][0]) for k in self.input_names)
        hit = self.cache.get(key)
        if hit is None:  # one point: always with its Jacobian, which the SQP asks for next
            hit = self.inner.jacobian(cols)
            self.simulations += 1
            self.cache[key] = hit
        return hit

    def __call__(self, params):
        return self.evaluate({k: params[k] for k in self.input_names}).raise_on_failure().outputs[0]


def residual_jacobian(loss, y: np.ndarray, jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Residuals ``r`` (25,) of loss (9.11) (``L = |r|²``) and ``dr/dθ`` (25, 4) from outputs and their Jacobian."""
    y0s = loss.measured[0]
    r = np.empty(len(y))
    r[0] = (loss.v_early_main - y0s) / y0s - (loss.v_early_test - y[0]) / y[0]
    r[1:] = loss.measured[1:] - y[1:]
    J = np.empty_like(jac)
    J[0] = loss.v_early_test / y[0] ** 2 * jac[0]
    J[1:] = -jac[1:]
    return r, J


def laplace_covariance(J: np.ndarray, sigma: float = SIGMA_RESIDUAL) -> np.ndarray:
    """Gauss–Newton/Laplace covariance ``σ² (JᵀJ)⁻¹`` of θ (pseudo-inverse where JᵀJ is singular)."""
    return sigma**2 * np.linalg.pinv(J.T @ J)


def mahalanobis(theta_hat, theta_true, cov) -> float:
    d = np.asarray(theta_hat, float) - np.asarray(theta_true, float)
    return float(np.sqrt(max(d @ np.linalg.pinv(cov) @ d, 0.0)))


def on_bound(theta_hat, bounds=None, tol: float = BOUND_TOL) -> list[str]:
    """Names of the parameters of ``theta_hat`` (a, b, af, bf) that sit on a prior bound (within ``tol`` relative).

    ``bounds``: default the prior box of Table 9.1 (:data:`lvcore.core.space.THETA_BOUNDS`), the SQP's box.
    """
    from lvcore.core.space import THETA_BOUNDS

    bounds = THETA_BOUNDS if bounds is None else bounds
    th = theta_dict(theta_hat)
    return [n for n in THETA_NAMES if n in th and (abs(th[n] - bounds[n][0]) <= tol * abs(bounds[n][0])
                                                   or abs(th[n] - bounds[n][1]) <= tol * abs(bounds[n][1]))]


def gauss_newton_surfaces(theta_hat, r, J, n: int = GN_GRID, span: float = SURFACE_SPAN) -> list[dict]:
    """Gauss–Newton model of the loss over each parameter pair around θ̂ (others held at θ̂)."""
    th = np.asarray(theta_hat, float)
    out = []
    for a, b in PAIRS:
        i, j = THETA_NAMES.index(a), THETA_NAMES.index(b)
        xs = th[i] * np.geomspace(1 / span, span, n)
        ys = th[j] * np.geomspace(1 / span, span, n)
        rss = np.empty((n, n))
        for q, yv in enumerate(ys):
            for p_, xv in enumerate(xs):
                d = np.zeros(4)
                d[i], d[j] = xv - th[i], yv - th[j]
                rss[q, p_] = float(np.sum((r + J @ d) ** 2))
        out.append({"x": a, "y": b, "x_values": xs.tolist(), "y_values": ys.tolist(),
                    "rss": np.round(rss, 8).tolist()})
    return out


def surface_axes(theta_hat, theta_true, n: int, margin: float = 1.5) -> list[np.ndarray]:
    """Log-spaced axes per parameter spanning θ̂ and θ̃ (widened by ``margin`` on each side)."""
    th, tt = np.asarray(theta_hat, float), np.asarray(theta_true, float)
    return [np.geomspace(min(a, b) / margin, max(a, b) * margin, n) for a, b in zip(th, tt)]


def simulator_surfaces(forward, loss, theta_hat, n: int, theta_true=THETA_TRUE) -> list[dict]:
    """The simulator's loss (9.11) over each parameter pair on an ``n × n`` log grid spanning θ̂ and θ̃.

    The other two parameters are held at θ̂; 6 n² simulations in batches
    (``forward.evaluate``; a :class:`SimulatorForward` with workers runs them in parallel).
    """
    th = np.asarray(theta_hat, float)
    axes = surface_axes(th, theta_true, n)
    out = []
    for a, b in PAIRS:
        i, j = THETA_NAMES.index(a), THETA_NAMES.index(b)
        xs, ys = axes[i], axes[j]
        X, Y = np.meshgrid(xs, ys)
        pts = np.tile(th, (n * n, 1))
        pts[:, i], pts[:, j] = X.ravel(), Y.ravel()
        b_ = forward.evaluate(dict(zip(THETA_NAMES, pts.T)))
        rss = np.array([loss.value_and_output_gradient(y)[0] if ok else np.nan
                        for y, ok in zip(b_.outputs, b_.converged)]).reshape(n, n)
        out.append({"x": a, "y": b, "x_values": xs.tolist(), "y_values": ys.tolist(), "rss": rss.tolist(),
                    "failed": int(np.sum(~b_.converged))})
    return out


def surface_for_fit(fit: dict, geoms: dict, y_star, n: int, *, resolution: str = "default", workers: int = 1) -> dict:
    """A simulator loss surface (Fig 9.13) for one finished fit: a ``rss_surfaces.json`` record."""
    from lvcore.optimise.sqp import OperatorLoss

    name = test_geometry_name(fit["main_operator"], fit["test_geometry"], geoms)
    fwd = SimulatorForward(geometry={"kind": "mesh", "path": geoms[name]["path"]}, resolution=resolution,
                           workers=workers)
    loss = OperatorLoss(np.asarray(y_star, float), geoms[fit["main_operator"]]["v_early_ml"], geoms[name]["v_early_ml"])
    return {"patient": fit["patient"], "main_operator": fit["main_operator"], "test_geometry": fit["test_geometry"],
            "method": f"simulator, {n} x {n} log grid per pair spanning theta_hat and theta_true (others at theta_hat)",
            "theta_hat": fit["theta_hat"], "pairs": simulator_surfaces(fwd, loss, fit["theta_hat"], n)}


# ----------------------------------------------------------------------------- one fit
def fit_one(patient: str, main: str, test: str, y_star, geoms: dict, resolution: str = "default",
            forward_factory=None, surface_grid: int = 0, sqp_tol: float = SQP_TOL) -> dict:
    """One SQP refit of θ on test geometry ``test`` against data ``y_star`` from ``main`` (a fit record).

    ``geoms``: :func:`patient_geometries`. ``forward_factory(geometry_name)``
    replaces the simulator (tests). Runs in worker processes; failures are
    recorded, not raised.
    """
    from lvcore.optimise.sqp import OperatorLoss, refit_theta

    t0 = time.perf_counter()
    name = test_geometry_name(main, test, geoms)

    def make(geom_name):
        if forward_factory is not None:
            return CachedForward(forward_factory(geom_name))
        # warm start: each SQP step starts Newton from the previous converged state (same mesh, nearby θ)
        return CachedForward(AdjointSimulatorForward(geometry={"kind": "mesh", "path": geoms[geom_name]["path"]},
                                                     resolution=resolution,
                                                     label=f"FE simulator on {patient} {geom_name}", warm_start=True))

    y_star = np.asarray(y_star, float)
    truth = np.array(THETA_TRUE)
    rec = {"patient": patient, "main_operator": main, "test_geometry": test, "converged": False,
           "theta_true": list(THETA_TRUE), "y_star": y_star.tolist()}
    try:
        fwd = make(name)
        loss = OperatorLoss(y_star, geoms[main]["v_early_ml"], geoms[name]["v_early_ml"])
        y_fwd = fwd.jacobian(dict(zip(THETA_NAMES, truth))).raise_on_failure().outputs[0]
        err_fwd = y_fwd[1:] - y_star[1:]
        res = refit_theta(fwd, loss, truth, tol=sqp_tol)
        b_hat = fwd.jacobian(dict(zip(THETA_NAMES, res.theta))).raise_on_failure()
        r, J = residual_jacobian(loss, b_hat.outputs[0], b_hat.jacobian[0])
        cov = laplace_covariance(J)
        main_fwd = fwd if name == main else make(main)
        y_main_hat = main_fwd.evaluate(dict(zip(THETA_NAMES, res.theta))).raise_on_failure().outputs[0]
        err_out = y_main_hat[1:] - y_star[1:]
        surfaces = {"method": "gauss-newton model at theta_hat (adjoint Jacobian), x1/2..x2 around theta_hat",
                    "pairs": gauss_newton_surfaces(res.theta, r, J)}
        if surface_grid:
            surfaces = {"method": f"simulator, {surface_grid} x {surface_grid} log grid per pair spanning theta_hat "
                                  "and theta_true (others at theta_hat)",
                        "pairs": simulator_surfaces(fwd, loss, res.theta, surface_grid)}
        surfaces["theta_hat"] = res.theta.tolist()
        rec.update({
            "converged": bool(res.success),
            "message": res.message,
            "theta_hat": res.theta.tolist(),
            "theta_abs_error": np.abs(res.theta - truth).tolist(),
            "loss": float(res.loss),
            "strain_rmse_forward": float(np.sqrt(np.mean(err_fwd**2))),
            "strain_errors_forward": err_fwd.tolist(),
            "lvv_forward_ml": float(y_fwd[0]),
            "output_rmse_refit": float(np.sqrt(np.mean(err_out**2))),
            "output_distance_refit": float(np.linalg.norm(err_out)),
            "covariance": cov.tolist(),
            "sigma_residual": SIGMA_RESIDUAL,
            "mahalanobis": mahalanobis(res.theta, truth, cov),
            "on_bound": on_bound(res.theta),
            "sqp_evaluations": int(res.n_evaluations),
            "simulations": fwd.simulations + (0 if main_fwd is fwd else main_fwd.simulations),
            "rss_surface": surfaces,
        })
    except Exception as err:  # noqa: BLE001 - a failed fit is data (the study goes on), with its reason
        from lvcore.core.forward import failure_reason

        rec["message"] = failure_reason(err)
    rec["seconds"] = round(time.perf_counter() - t0, 2)
    return rec


def data_task(patient, main, geoms, resolution, forward_factory):
    """``y* = ζ(θ̃, g_main)`` (worker task)."""
    if forward_factory is not None:
        f = forward_factory(main)
    else:
        f = SimulatorForward(geometry={"kind": "mesh", "path": geoms[main]["path"]}, resolution=resolution)
    return f.evaluate(dict(zip(THETA_NAMES, THETA_TRUE))).raise_on_failure().outputs[0].tolist()


__all__ = ["THETA_TRUE", "PC_TESTS", "SIGMA_RESIDUAL", "PAIRS", "GN_GRID", "SURFACE_SPAN", "CHAPTER_SHARE_10PC",
           "SQP_TOL", "BOUND_TOL", "early_volume_ml", "patient_geometries", "test_geometries", "operator_names",
           "test_geometry_name", "CachedForward", "residual_jacobian", "laplace_covariance", "mahalanobis",
           "on_bound", "gauss_newton_surfaces", "surface_axes", "simulator_surfaces", "surface_for_fit", "fit_one",
           "data_task"]
