"""Load-stepping Newton solver with step cutting and a safeguarded line search.

The load factor goes from 0 to 1 in adaptive steps: a step that fails
(too many iterations, inverted elements, no acceptable line-search step, a
non-finite value) is cut in half and retried from the last converged state;
quickly converging steps let the next one grow. Intermediate steps use a
loose tolerance, the final step the tight one.

Newton acts on the mixed (displacement, element pressure) equations with
the pressure condensed per element (see :mod:`lvcore.mechanics.element`).
A tangent (assembly ~20 ms, factorisation ~10 ms at the default LV
resolution) costs about ten residual evaluations, so factorised tangents are
reused while they contract well (chord iterations), and the last tangent of
a converged load step gives the first iteration of the next one.
Line search: backtracking on a scaled norm of the mixed residual; trial
states whose smallest pointwise J is below ``min_jacobian`` are rejected.
"""
from __future__ import annotations

import os
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from lvcore.mechanics.linear import TRIANGLE_BACKENDS, NotPositiveDefinite, default_backend, factorize

_DEBUG = bool(os.environ.get("LVCORE_NEWTON_DEBUG"))


@dataclass
class NewtonOptions:
    """Solver settings (tolerances relative to the norm of the full external load).

    Attributes
    ----------
    rtol, rtol_intermediate : force tolerance of the final / intermediate load steps.
    max_iterations : iterations per load step (chord iterations included).
    first_step, min_step, grow, max_cuts : load stepping (steps that needed at most
        5 tangents grow by ``grow``; failed steps are halved).
    min_jacobian : trial states with a smaller pointwise J are rejected.
    max_line_search : trial states per line search.
    predictor : secant extrapolation of (u, p) from the last two load steps.
    min_first_alpha : a load step whose first Newton step is damped below this is cut.
    reuse_ratio : a factorised tangent is reused (chord iteration) after an
        undamped step that reduced ``‖r_u‖`` by at least this factor, and for as
        long as the chord iterations do; 0 gives a fresh tangent every iteration.
    chord_predictor : start each load step with the last tangent of the previous
        one (a poor chord predictor, damped below ``min_first_alpha``, is dropped
        for a fresh tangent instead of cutting the step unless ``cut_on_predictor``).
        Switched off for the rest of the solve after the first failed load step
        (on hard paths it could lead Newton astray: 2 of 256 sweep points failed).
    cut_on_indefinite : a load step from a loaded state whose first fresh tangent is not positive
        definite (the load stiffness of the larger pressure outweighs the material's) is cut at
        once, before its indefinite factorisation (simplicial LDLᵀ, ~4× the supernodal LLᵀ) and
        line search; CHOLMOD only (SuperLU cannot tell). Once per solve: where the equilibrium
        path itself has indefinite tangents, later steps factorise them as before. Steps from
        the unloaded state are exempt: there an indefinite tangent often still gives a good step
        (the default LV's first step, damped to 0.51), while on Land problem 2 the one from a
        loaded state was cut anyway (damped to 0.05).
    cold_fallback : with a warm start (``solve(initial=...)``) that does not
        converge, restart from zero load (True, the default) or return the
        failure at once (False: the caller has a cheaper way on, e.g. a
        parameter continuation, :func:`lvcore.mechanics.forward.warm_continuation`).
    """

    rtol: float = 1e-9
    rtol_intermediate: float = 1e-2
    max_iterations: int = 25
    first_step: float = 0.25
    min_step: float = 1.0 / 1024
    grow: float = 1.5
    max_cuts: int = 40
    min_jacobian: float = 0.02
    max_line_search: int = 10
    predictor: bool = False
    min_first_alpha: float = 0.3
    reuse_ratio: float = 0.3
    chord_predictor: bool = True
    cut_on_predictor: bool = False
    cut_on_indefinite: bool = True
    cold_fallback: bool = True


class Tangent:
    """A factorised tangent and its condensation matrices ``D`` (n_el, 4, 81) from a converged solve.

    Passed with a warm start (``solve(initial=(u, p, tangent))``), it gives
    the first Newton iterations at a nearby point as chord iterations, so a
    chain of nearby solves needs a fresh tangent only when the reused one
    stops contracting. A factorisation lives in its process: pickling a
    :class:`Tangent` drops it (it unpickles empty, and a solve then takes a
    fresh tangent).
    """

    __slots__ = ("factorization", "D")

    def __init__(self, factorization=None, D=None):
        self.factorization = factorization
        self.D = D

    def __bool__(self) -> bool:
        return self.factorization is not None and self.D is not None

    def __reduce__(self):
        return (Tangent, ())


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
    #: The last factorised tangent used (a :class:`Tangent`; empty if none was taken).
    tangent: Tangent = field(default_factory=Tangent)


def tangent_definite(tangent) -> bool | None:
    """Whether a factorised tangent (a :class:`Tangent`, or a factorisation) was positive definite.

    True when PARDISO's or CHOLMOD's Cholesky (LLᵀ) succeeded on it; False when the backend asked for
    one (PARDISO, CHOLMOD supernodal) had to fall back to an indefinite factorisation (PARDISO's
    symmetric indefinite LDLᵀ, CHOLMOD's LDLᵀ, SuperLU), or an LDLᵀ has a pivot ≤ 0 (CHOLMOD's simplicial one; SuperLU's LU where it kept
    to diagonal pivots, a symmetric permutation, is one too); None when it cannot tell (SuperLU that
    pivoted off the diagonal, no tangent). At a converged state (its last tangent is taken within a few Newton iterations of
    it) an indefinite tangent means an unstable equilibrium: under the same pressure a nearby state
    of lower energy exists, and Newton from another start can converge to another equilibrium.
    """
    fac = getattr(tangent, "factorization", tangent)
    if fac is None:
        return None
    kind = getattr(fac, "factorisation", None)
    if kind == "supernodal":
        return True
    requested = getattr(fac, "requested_backend", None)
    if kind == "simplicial":
        chol = getattr(fac, "_chol", None)
        try:
            return bool(np.all(chol.D() > 0))
        except Exception:  # noqa: BLE001 - no D (not an LDLᵀ): cannot tell
            return None
    if requested in ("pardiso", "cholmod"):
        return False
    lu = getattr(fac, "_lu", None)
    try:  # SuperLU that kept to the diagonal (symmetric permutation): LU = LDLᵀ, the signs of diag(U) are the inertia
        if lu is not None and np.array_equal(lu.perm_r, lu.perm_c):
            return bool(np.all(lu.U.diagonal() > 0))
    except Exception:  # noqa: BLE001 - a factorisation without these attributes: cannot tell
        pass
    return None


def _line_search(system, u, p, du, dp, rhs, D, lam, opts, stats):
    """Step length along (du, dp).

    Trial states with min J below ``opts.min_jacobian`` are halved away. Among
    admissible states the step is chosen by the root of the projected residual
    ``g(α) = du · (r_u + κ Dᵀ M⁻¹ r_p)(u + α du, p + α dp)`` (D frozen; the
    directional derivative of the energy for a potential load): the full step is taken unless it overshoots the
    root by much (``g(1) > 0.5 |g(0)|``), in which case secant steps
    towards the root are taken.

    Returns ``(found, alpha, u, p, r_u, r_p, min J, condensed residual with D)`` of the chosen state
    (the last, for a chord iteration on the same D, is its right-hand side).
    """
    g0 = float(du @ rhs)
    alpha, lo, g_lo = 1.0, 0.0, g0
    best = None
    for _ in range(opts.max_line_search):
        ut, pt = u + alpha * du, p + alpha * dp
        rut, rpt, mjt, _ = system.residual(ut, pt, lam, energy=False)
        stats["residuals"] += 1
        if not (mjt > opts.min_jacobian and np.all(np.isfinite(rut)) and np.all(np.isfinite(rpt))):
            alpha = lo + 0.5 * (alpha - lo)
            continue
        condensed = system.condensed(rut, rpt, D)
        best = (alpha, ut, pt, rut, rpt, mjt, condensed)
        g = float(du @ condensed)
        if g0 >= 0 or g <= 0.5 * abs(g0):
            break
        # overshoot: secant root between lo (g_lo < 0) and alpha (g > 0)
        a_new = lo + (alpha - lo) * g_lo / (g_lo - g)
        alpha = float(np.clip(a_new, lo + 0.1 * (alpha - lo), lo + 0.9 * (alpha - lo)))
    if best is None:
        return False, 0.0, u, p, None, None, 0.0, None
    return (True,) + best


def _newton_at(system, u, p, lam, tol_u, tol_p, opts, stats, can_cut=False, reuse=None, lam_from=0.0):
    """Newton iterations at fixed load factor. Returns (ok, u, p, reason, last).

    ``lam_from``: the load factor of the converged state the step starts from (0: unloaded).

    ``reuse``: optional ``(factorisation, D)`` of an earlier tangent (the last
    one of the previous load step) for the first iteration, a chord
    predictor; ``last`` is the ``(factorisation, D)`` of the last tangent used.

    Once a full Newton step has reduced ``‖r_u‖`` by ``opts.reuse_ratio`` or
    more, the factorised tangent (and its condensation matrices D) is reused
    for the next iterations (chord / modified Newton: one residual and one
    back-substitution each) for as long as every such iteration keeps
    reducing ``‖r_u‖`` by that ratio; otherwise the next iteration takes a
    fresh tangent. The convergence test is on the true residuals either way.
    Without ``reuse`` the first iteration's tangent kernel gives the starting residuals (one residual
    evaluation fewer per load step and per warm start: 5.64 → 4.83 per warm solve of a 1,000-point design).
    """
    r_u = r_p = None
    if reuse is not None:  # else the first iteration's tangent kernel gives the residuals
        r_u, r_p, mj, _ = system.residual(u, p, lam, energy=False)
        stats["residuals"] += 1
    # a symmetric tangent goes to PARDISO or CHOLMOD as its upper triangle (half the entries to assemble)
    backend = default_backend()
    triangle = system.potential and backend in TRIANGLE_BACKENDS
    last = reuse
    cond = None  # (D, r_u + κ Dᵀ M⁻¹ r_p) of the current state, from the line search that accepted it
    first = True  # the first accepted iteration of this load step decides a cut
    for it in range(opts.max_iterations):
        if r_u is not None and not (np.all(np.isfinite(r_u)) and np.all(np.isfinite(r_p))):
            return False, u, p, "non-finite residual", last
        if it > 0 and np.linalg.norm(r_u) <= tol_u and np.max(np.abs(r_p)) <= tol_p:
            return True, u, p, "", last
        chord = reuse is not None
        t0 = time.perf_counter()
        if chord:
            fac, D = reuse
            # the line search that accepted (u, p) condensed its residual with this D already
            rhs = cond[1] if cond is not None and cond[0] is D else system.condensed(r_u, r_p, D)
        else:
            rhs, K, D, r_p = system.tangent(u, p, lam, triangle=triangle)
            stats["tangents"] += 1
            if r_u is None:  # r_u = rhs − κ Dᵀ M⁻¹ r_p (the condensed part taken off again)
                r_u = rhs - system.condensed(np.zeros_like(rhs), r_p, D)
                if not (np.all(np.isfinite(r_u)) and np.all(np.isfinite(r_p))):
                    return False, u, p, "non-finite residual", last
        stats["t_tangent"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        try:
            if not chord:
                # the first tangent of a load step that can be cut, from a loaded state, must be positive
                # definite (see NewtonOptions.cut_on_indefinite): else the step is cut before the slower
                # indefinite factorisation and its line search
                fac = factorize(K, symmetric=system.potential, cache=system.tangent_pattern(triangle).cache,
                                triangle=triangle,
                                require_definite=first and can_cut and opts.cut_on_indefinite and lam_from > 0
                                and not stats.get("indefinite_cuts"))
                fac.requested_backend = backend  # a fallback to SuperLU rewrites fac.backend (tangent_definite)
                last = (fac, D)
                t1 = time.perf_counter()
                stats["t_factor"] += t1 - t0
                t0 = t1
            du = -fac.solve(rhs)
        except NotPositiveDefinite:
            stats["t_factor"] += time.perf_counter() - t0
            stats["indefinite_cuts"] = stats.get("indefinite_cuts", 0) + 1
            return False, u, p, "load step too large (tangent not positive definite)", last
        except RuntimeError as exc:  # singular factor
            return False, u, p, f"linear solve failed: {exc}", last
        stats["t_solve"] += time.perf_counter() - t0
        stats["iterations"] += 1
        if not np.all(np.isfinite(du)):
            return False, u, p, "non-finite Newton step", last
        dp = system.pressure_increment(du, D, r_p)
        t0 = time.perf_counter()
        found, alpha, ut, pt, rut, rpt, mjt, cvec = _line_search(system, u, p, du, dp, rhs, D, lam, opts, stats)
        stats["t_line"] += time.perf_counter() - t0
        if not found:
            if chord:  # retry from the same state with a fresh tangent
                reuse = None
                continue
            return False, u, p, "line search found no admissible step (inverted elements)", last
        if chord and not np.linalg.norm(rut) < np.linalg.norm(r_u):
            reuse = None  # a chord step must reduce the residual; else a fresh tangent from the same state
            continue
        if first and chord and alpha < opts.min_first_alpha and not opts.cut_on_predictor:
            reuse = None  # poor chord predictor: judge the step on a fresh tangent
            continue
        if first and can_cut and alpha < opts.min_first_alpha:
            # the linearisation at the start of the step is poor: a smaller load step is cheaper
            return False, u, p, f"load step too large (first Newton step damped to {alpha:.2g})", last
        if _DEBUG:
            print(f"  it {it} lam {lam:.4f} |r_u| {np.linalg.norm(r_u):.3e} -> {np.linalg.norm(rut):.3e} alpha {alpha:g} "
                  f"|r_p| {np.abs(rpt).max():.2e} minJ {mjt:.3f}{' chord' if chord else ''}")
        first = False
        if alpha < 1.0:
            stats["damped"] = stats.get("damped", 0) + 1
        contracted = alpha == 1.0 and np.linalg.norm(rut) <= opts.reuse_ratio * np.linalg.norm(r_u)
        reuse = (fac, D) if contracted and opts.reuse_ratio > 0 else None
        u, p, r_u, r_p = ut, pt, rut, rpt
        cond = (D, cvec)
        if np.linalg.norm(r_u) <= tol_u and np.max(np.abs(r_p)) <= tol_p:
            return True, u, p, "", last
    return False, u, p, f"no convergence in {opts.max_iterations} iterations", last


@dataclass(frozen=True)
class SolveRecord:
    """What one :func:`solve` call did, as :func:`recorded_solves` collects it.

    Attributes
    ----------
    warm : bool
        A warm start was tried (``initial`` of the right shapes).
    warm_converged : bool
        ... and converged at full load (the result is the warm start's, not the load stepping's).
    converged : bool
    iterations, tangents, load_steps, cuts, damped : int
        Newton iterations, fresh tangents, load steps, step cuts, and accepted Newton steps the line
        search damped (α < 1).
    definite : bool or None
        :func:`tangent_definite` of the last tangent (None: cannot tell, or none).
    jump : float
        ‖u − u₀‖ / ‖u‖ from the warm start's state to the converged one (NaN unless ``warm_converged``).
    """

    warm: bool
    warm_converged: bool
    converged: bool
    iterations: int
    tangents: int
    load_steps: int
    cuts: int
    damped: int
    definite: bool | None
    jump: float


_RECORDS = threading.local()


@contextmanager
def recorded_solves():
    """Collect a :class:`SolveRecord` of every :func:`solve` in this thread inside the block (a list).

    For a caller that reaches Newton through other layers (a forward model's warm start, its
    continuation and cold fallback) and wants to judge the path its result took.
    """
    log: list[SolveRecord] = []
    stack = getattr(_RECORDS, "stack", None)
    if stack is None:
        stack = _RECORDS.stack = []
    stack.append(log)
    try:
        yield log
    finally:  # by identity: an enclosing block's log may hold the same records (lists compare by value)
        del stack[next(i for i in range(len(stack) - 1, -1, -1) if stack[i] is log)]


def solve(system, opts: NewtonOptions | None = None, initial: tuple | None = None) -> NewtonResult:
    """Drive ``system`` to full load (see :func:`_solve`); recorded by :func:`recorded_solves`."""
    res = _solve(system, opts, initial)
    stack = getattr(_RECORDS, "stack", None)
    if stack:
        t = res.timings
        rec = SolveRecord("warm_start" in t, bool(t.get("warm_start")), bool(res.converged), int(res.iterations),
                          int(t.get("tangents", 0)), int(res.load_steps), int(res.cuts), int(t.get("damped", 0)),
                          tangent_definite(res.tangent) if res.converged else None,
                          float(t.get("warm_jump", float("nan"))))
        for log in stack:
            log.append(rec)
    return res


def _solve(system, opts: NewtonOptions | None = None, initial: tuple | None = None) -> NewtonResult:
    """Drive ``system`` (a :class:`~lvcore.mechanics.system.DiscreteSystem`) to full load.

    Convergence: ``||r_u|| <= rtol ||f_ext||`` (the external load vector at full
    load) and ``max |r_p| <= rtol_volume * (element volume)`` on every element.

    ``initial``: optional ``(u, p)`` or ``(u, p, tangent)`` (free
    displacements and element pressures of a converged solve of the same mesh
    and boundary conditions, e.g. at nearby material parameters, and
    optionally its last factorised :class:`Tangent`). Newton then starts at
    full load from that state (a warm start), with chord iterations on the
    given tangent for as long as they contract; if it does not converge there,
    the solve restarts from zero with the usual load stepping, so a poor guess
    costs time, never the result. The converged state satisfies the same
    tolerances either way.
    """
    opts = opts or NewtonOptions()
    t_start = time.perf_counter()
    stats = {"iterations": 0, "tangents": 0, "residuals": 0, "t_tangent": 0.0, "t_factor": 0.0, "t_solve": 0.0,
             "t_line": 0.0}
    u = np.zeros(system.n_free)
    p = system.zero_pressure()
    scale = max(system.load_norm(), 1e-30)
    vol = float(np.max(np.sum(system.wdet, axis=1)))

    def tolerances(rtol):  # (force, volume) tolerances of a load step solved to relative tolerance rtol
        return rtol * scale, rtol * 1e-2 * vol

    if initial is not None:
        u0, p0 = (np.asarray(v, dtype=float) for v in tuple(initial)[:2])
        given = initial[2] if len(initial) > 2 else None
        if u0.shape == u.shape and p0.shape == np.shape(p) and np.all(np.isfinite(u0)) and np.all(np.isfinite(p0)):
            reuse = None
            if given and given.factorization.shape == (u.size, u.size) and given.D.shape[0] == p.shape[0]:
                reuse = (given.factorization, given.D)
            stats["reused_tangent"] = reuse is not None
            ok, u_w, p_w, _, last = _newton_at(system, u0, p0, 1.0, *tolerances(opts.rtol), opts, stats, reuse=reuse)
            stats["warm_start"] = bool(ok)
            if ok:  # how far Newton went from the given state (relative displacement)
                stats["warm_jump"] = float(np.linalg.norm(u_w - u0) / max(np.linalg.norm(u_w), 1e-300))
            if ok:
                stats["seconds"] = time.perf_counter() - t_start
                return NewtonResult(True, "converged (warm start)", u_w, p_w, 1.0, stats["iterations"], 1, 0, stats,
                                    Tangent(*last) if last else Tangent())
            if not opts.cold_fallback:
                stats["seconds"] = time.perf_counter() - t_start
                return NewtonResult(False, "warm start did not converge", u, p, 0.0, stats["iterations"], 0, 0, stats)
    lam, step, steps, cuts = 0.0, opts.first_step, 0, 0
    carry = None  # (factorisation, D) of the last tangent of the last converged step
    predict = opts.chord_predictor
    prev = None  # (load factor, u, p) of the previous converged step, for the secant predictor
    last_reason = ""
    while lam < 1.0:
        target = min(1.0, lam + step)
        final = target >= 1.0
        rtol = opts.rtol if final else opts.rtol_intermediate
        it0 = stats["tangents"]
        u_start, p_start = u, p
        if prev is not None and opts.predictor:
            c = (target - lam) / (lam - prev[0])
            u_try, p_try = u + c * (u - prev[1]), p + c * (p - prev[2])
            if system.residual(u_try, p_try, target, energy=False)[2] > opts.min_jacobian:
                u_start, p_start = u_try, p_try
            stats["residuals"] += 1
        ok, u_new, p_new, reason, last = _newton_at(system, u_start, p_start, target, *tolerances(rtol),
                                                    opts, stats, can_cut=step > 4 * opts.min_step,
                                                    reuse=carry if predict else None, lam_from=lam)
        if ok:
            prev = (lam, u, p)
            u, p, lam = u_new, p_new, target
            carry = last
            steps += 1
            if stats["tangents"] - it0 <= 5:
                step = min(1.0, step * opts.grow)
        else:
            last_reason = reason
            if _DEBUG:
                print(f"  cut at lam {target:.4f}: {reason}")
            predict = False  # a hard path: no chord predictor from here on (it can lead Newton astray)
            cuts += 1
            step *= 0.5
            if step < opts.min_step or cuts > opts.max_cuts:
                stats["seconds"] = time.perf_counter() - t_start
                return NewtonResult(False, f"stopped at load factor {lam:.4g}: {last_reason}", u, p, lam,
                                    stats["iterations"], steps, cuts, stats)
    stats["seconds"] = time.perf_counter() - t_start
    return NewtonResult(True, "converged", u, p, 1.0, stats["iterations"], steps, cuts, stats,
                        Tangent(*carry) if carry else Tangent())


solve.__doc__ = _solve.__doc__ + """
    Every call is recorded (a :class:`SolveRecord`) by the enclosing :func:`recorded_solves` blocks of its thread.
    """
