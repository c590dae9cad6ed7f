"""Load-stepping Newton solver with step cutting and a safeguarded line search.

The load factor goes from 0 to 1 in adaptive steps: a step that fails
(too many iterations, inverted elements, no acceptable line-search step, a
non-finite value) is cut in half and retried from the last converged state;
quickly converging steps let the next one grow. Intermediate steps use a
loose tolerance, the final step the tight one.

Newton acts on the mixed (displacement, element pressure) equations with
the pressure condensed per element (see :mod:`lvcore.mechanics.element`).
Line search: backtracking on a scaled norm of the mixed residual; trial
states whose smallest pointwise J is below ``min_jacobian`` are rejected.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from lvcore.mechanics.linear import factorize


@dataclass
class NewtonOptions:
    """Solver settings (tolerances relative to the norm of the full external load)."""

    rtol: float = 1e-9
    rtol_intermediate: float = 1e-4
    max_iterations: int = 25
    first_step: float = 1.0
    min_step: float = 1.0 / 1024
    grow: float = 2.0
    max_cuts: int = 12
    min_jacobian: float = 0.02
    max_line_search: int = 10


@dataclass
class NewtonResult:
    converged: bool
    message: str
    u: np.ndarray
    p: np.ndarray
    load_factor: float
    iterations: int
    load_steps: int
    cuts: int
    timings: dict = field(default_factory=dict)


def _newton_at(system, u, p, lam, tol_u, tol_p, opts, stats):
    """Newton iterations at fixed load factor. Returns (ok, u, p, reason)."""
    r_u, r_p, mj, _ = system.residual(u, p, lam)
    stats["residuals"] += 1
    for it in range(opts.max_iterations):
        if not (np.all(np.isfinite(r_u)) and np.all(np.isfinite(r_p))):
            return False, u, p, "non-finite residual"
        if it > 0 and np.linalg.norm(r_u) <= tol_u and np.max(np.abs(r_p)) <= tol_p:
            return True, u, p, ""
        m0 = system.merit(r_u, r_p)
        t0 = time.perf_counter()
        rhs, K, D, r_p = system.tangent(u, p, lam)
        stats["t_tangent"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        try:
            du = -factorize(K, symmetric=system.potential).solve(rhs)
        except RuntimeError as exc:  # singular factor
            return False, u, p, f"linear solve failed: {exc}"
        stats["t_solve"] += time.perf_counter() - t0
        stats["iterations"] += 1
        if not np.all(np.isfinite(du)):
            return False, u, p, "non-finite Newton step"
        dp = system.pressure_increment(du, D, r_p)
        alpha = 1.0
        t0 = time.perf_counter()
        for _ in range(opts.max_line_search):
            ut, pt = u + alpha * du, p + alpha * dp
            rut, rpt, mjt, _ = system.residual(ut, pt, lam)
            stats["residuals"] += 1
            ok = mjt > opts.min_jacobian and np.all(np.isfinite(rut)) and np.all(np.isfinite(rpt))
            if ok:
                mt = system.merit(rut, rpt)
                ok = mt < (1.0 - 1e-4 * alpha) * m0 or (np.linalg.norm(rut) <= tol_u and np.max(np.abs(rpt)) <= tol_p)
            if ok:
                break
            alpha *= 0.5
        else:
            stats["t_line"] += time.perf_counter() - t0
            return False, u, p, "line search found no admissible step (inverted elements or no decrease)"
        stats["t_line"] += time.perf_counter() - t0
        u, p, r_u, r_p = ut, pt, rut, rpt
        if np.linalg.norm(r_u) <= tol_u and np.max(np.abs(r_p)) <= tol_p:
            return True, u, p, ""
    return False, u, p, f"no convergence in {opts.max_iterations} iterations"


def solve(system, opts: NewtonOptions | None = None) -> NewtonResult:
    """Drive ``system`` (a :class:`~lvcore.mechanics.system.DiscreteSystem`) to full load.

    Convergence: ``||r_u|| <= rtol ||f_ext||`` (the external load vector at full
    load) and ``max |r_p| <= rtol_volume * (element volume)`` on every element.
    """
    opts = opts or NewtonOptions()
    t_start = time.perf_counter()
    stats = {"iterations": 0, "residuals": 0, "t_tangent": 0.0, "t_solve": 0.0, "t_line": 0.0}
    u = np.zeros(system.n_free)
    p = system.zero_pressure()
    r1, _, _, _ = system.residual(u, p, 1.0)
    scale = max(np.linalg.norm(r1), 1e-30)
    vol = float(np.max(np.sum(system.wdet, axis=1)))
    lam, step, steps, cuts = 0.0, opts.first_step, 0, 0
    last_reason = ""
    while lam < 1.0:
        target = min(1.0, lam + step)
        final = target >= 1.0
        rtol = opts.rtol if final else opts.rtol_intermediate
        it0 = stats["iterations"]
        ok, u_new, p_new, reason = _newton_at(system, u, p, target, rtol * scale, rtol * 1e-2 * vol, opts, stats)
        if ok:
            u, p, lam = u_new, p_new, target
            steps += 1
            if stats["iterations"] - it0 <= 6:
                step = min(1.0, step * opts.grow)
        else:
            last_reason = reason
            cuts += 1
            step *= 0.5
            if step < opts.min_step or cuts > opts.max_cuts:
                stats["seconds"] = time.perf_counter() - t_start
                return NewtonResult(False, f"stopped at load factor {lam:.4g}: {last_reason}", u, p, lam,
                                    stats["iterations"], steps, cuts, stats)
    stats["seconds"] = time.perf_counter() - t_start
    return NewtonResult(True, "converged", u, p, 1.0, stats["iterations"], steps, cuts, stats)
