r"""One verdict per subject: consistency of the data, identifiability of the posterior, sampler health.

The verdict of a calibration must not depend on which likelihood the user
picked. It has three parts:

1. **Consistency** (:func:`consistency_check`), computed from the data and the
   *best-fitting* forward model, never from the posterior of the model that
   ran: theta (and, with ``--geometry infer``, the PC scores and scale, with
   their priors and the measured geometric measures) are fitted by maximum a
   posteriori to the LVV with its noise ``sigma_V`` and the 24 strains with the
   reference strain noise ``sigma_ref`` (:data:`lvcore.inference.plausibility.DEFAULT_SIGMA_REF`),
   from :data:`N_STARTS` starting points (L-BFGS-B). At the best fit the
   two-sided p-value of every output is ``2 (1 - Phi(|y - eta| / sigma))``.
   The data are inconsistent when the LVV has ``p < ALPHA``, when at least
   :data:`MIN_BAD_STRAINS` strains have ``p < ALPHA``, or when the data-only
   checks of :mod:`lvcore.inference.plausibility` fire (mixed signs, no
   deformation). The same data and forward model give the same answer for
   every model: ``plausible`` is this check.
2. **Bounds** (:func:`identifiability_flags`), from the posterior: mass
   piled on a prior bound *that the data push against* (its q05 or q95
   within :data:`BOUND_FRACTION` of the prior's width from the bound, widths
   in log for a, b, af, bf and the scale, and the likelihood rising towards
   the bound: :func:`_band_push`) is a defect (flag **BOUND**). Weak
   identification is not: with one loaded state the data fix a combination
   of a and b (docs/real_data.md), so a wide interval, or a posterior that
   follows its prior to a bound, is a *note* reported with what is
   identified (:mod:`lvcore.inference.derived`: the EDPVR, stress, the
   ridge and each parameter's contraction).
3. **Sampler health**: divergent transitions above :data:`MAX_DIVERGENT_FRACTION`
   of the kept draws, or a run that did not converge.

Any flag makes the run *flagged*: ``lvcore calibrate`` exits with 4, "ran,
results flagged" (docs/reliability.md), and lists the flags in
``summary.json``. Notes never change the exit code.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lvcore.execution.bounded_cache import BoundedCache
from lvcore.domain.outputs import ANGLE_NAMES, OUTPUT_COLUMNS, THETA_NAMES, is_pc_name

#: p-value below which an output counts as not reached at the best fit.
ALPHA = 0.01
#: Strains with p < ALPHA at the best fit that make the data inconsistent. With 24 strains at
#: the reference noise, 3 or more happen by chance with probability 0.2 % (binomial, p = 0.01).
MIN_BAD_STRAINS = 3
#: Starting points of the best fit.
N_STARTS = 4
#: A posterior quantile this close to a prior bound (fraction of the prior's width) is "piled on the bound".
BOUND_FRACTION = 0.02
#: A 90 % interval at least this fraction of the prior's 90 % interval has learned nothing.
WIDTH_FRACTION = 0.9
#: Each edge band of :func:`_band_push`, as a fraction of the prior's range (log range for log parameters).
EDGE_BAND = 0.05
#: Posterior mass in an edge band below which no bound is flagged.
MIN_EDGE_MASS = 0.05
#: Posterior-to-prior density ratio, edge band over adjacent band, from which the data push against a bound.
PUSH_RATIO = 2.0
#: Divergent transitions above this fraction of the kept draws flag the run (20 of 4 x 1000).
MAX_DIVERGENT_FRACTION = 0.005
#: Parameters whose widths are measured in log space.
LOG_PARAMETERS = THETA_NAMES + ("scale",)
#: Random permutations of the strain residuals behind the p-value of their spatial structure (Moran's I).
N_PERMUTATIONS = 2000


def _grid_adjacency():
    """Neighbours on lvcore's 6 x 4 strain grid (region = level * 6 + sector): the two sectors beside a region
    on its ring (circular) and the regions above and below it in the same sector."""
    from lvcore.domain.outputs import N_LEVELS, N_SECTORS

    n = N_LEVELS * N_SECTORS
    w = np.zeros((n, n))
    for r in range(n):
        level, sector = divmod(r, N_SECTORS)
        for lv, sc in ((level, (sector + 1) % N_SECTORS), (level, (sector - 1) % N_SECTORS),
                       (level + 1, sector), (level - 1, sector)):
            if 0 <= lv < N_LEVELS:
                w[r, lv * N_SECTORS + sc] = 1.0
    return w


def residual_structure(residuals, n_permutations: int = N_PERMUTATIONS, seed: int = 0) -> tuple[float, float]:
    """Moran's I of 24 strain residuals on the 6 x 4 grid and its one-sided permutation p-value.

    Independent residuals (what the iid likelihood assumes) give I near
    ``-1/23`` and a uniform p-value; a smooth pattern (a misfit of the
    model, e.g. a whole level off) gives a large I and a small p.

    Returns
    -------
    moran_i, p_value : float
    """
    r = np.asarray(residuals, float).reshape(-1)
    w = _grid_adjacency()
    if r.size != w.shape[0]:
        raise ValueError(f"need {w.shape[0]} strain residuals, got {r.size}")

    def moran(z):
        z = z - z.mean(axis=-1, keepdims=True)
        return r.size / w.sum() * np.einsum("...i,ij,...j->...", z, w, z) / np.einsum("...i,...i->...", z, z)

    if not np.any(r - r.mean()):
        return 0.0, 1.0
    i0 = float(moran(r))
    rng = np.random.default_rng(seed)
    perm = np.stack([rng.permutation(r) for _ in range(int(n_permutations))])
    p = (1.0 + float(np.sum(moran(perm) >= i0 - 1e-12))) / (1.0 + n_permutations)
    return i0, p


@dataclass(frozen=True)
class Consistency:
    """The best fit and its p-values (see the module docstring).

    Attributes
    ----------
    best_fit : dict
        Parameter values at the best fit (theta, and h/scale when inferred).
    eta : ndarray, shape (25,)
        Forward-model outputs at the best fit.
    p_values : ndarray, shape (25,)
    flags : tuple of str
    sigma_ref : float
    """

    best_fit: dict
    eta: np.ndarray
    p_values: np.ndarray
    flags: tuple = field(default=())
    sigma_ref: float = 0.035
    #: Moran's I of the strain residuals at the best fit, its p-value and the residual RMS (recorded; the
    #: MISFIT flag comes from the posterior of the model that ran, :func:`posterior_misfit`).
    structure: dict = field(default_factory=dict)

    @property
    def plausible(self) -> bool:
        return not self.flags

    def record(self) -> dict:
        return {"plausible": self.plausible, "flags": list(self.flags), "residual_structure": dict(self.structure), "sigma_ref": self.sigma_ref, "alpha": ALPHA,
                "min_bad_strains": MIN_BAD_STRAINS, "best_fit": {k: float(v) for k, v in self.best_fit.items()},
                "best_fit_outputs": {c: float(v) for c, v in zip(OUTPUT_COLUMNS, self.eta)},
                "p_values": {c: float(p) for c, p in zip(OUTPUT_COLUMNS, self.p_values)}}


def _reference_model(y=None, *, forward, sigma_v, sigma_ref, infer_angles):
    """The consistency likelihood: LVV ~ N(eta0, sigma_v^2), strains ~ N(eta, sigma_ref^2), the models' priors
    (with ``--geometry infer``, the shape model's representation error added as in the models:
    :func:`lvcore.inference.models.strain_likelihood`)."""
    import numpyro
    import numpyro.distributions as dist

    from lvcore.inference.models import _sample_params, lvv_sd, strain_likelihood

    params = _sample_params(infer_angles, forward)
    eta = forward(params)
    numpyro.sample("lvv_obs", dist.Normal(eta[0], lvv_sd(eta[0], sigma_v, forward)), obs=y[0])
    numpyro.sample("strain_obs", strain_likelihood(eta[1:], sigma_ref ** 2, forward), obs=y[1:])


#: Compiled best-fit programs kept in this process, per emulator and settings (:func:`_best_fit_programs`),
#: least recently used first out: a long-running app server that meets many emulators keeps a bounded number
#: of compiled programs (each holds executable memory mappings; the kernel allows 65,530 per process).
BEST_FIT_CACHE_SIZE = 8
_BEST_FIT_PROGRAMS: BoundedCache = BoundedCache(BEST_FIT_CACHE_SIZE)


def clear_best_fit_programs() -> None:
    """Forget the compiled best-fit programs kept in this process (:data:`BEST_FIT_CACHE_SIZE`)."""
    _BEST_FIT_PROGRAMS.clear()


def _best_fit_programs(forward, sigma_v: float, sigma_ref: float, infer_angles: bool, n_starts: int):
    """The jitted pieces of :func:`best_fit` and the forward model's run-time conditions.

    An emulator forward model's conditions (PC scores, EDP, angles, scale) are an argument
    (:func:`lvcore.inference.samplers.runtime_conditions`), so the programs are traced and compiled
    once per emulator and settings and kept; any other forward model is compiled in, per call. Every
    step is jitted: numpyro's ``initialize_model`` run eagerly dispatched (and compiled) over a hundred
    small programs, about 2.5 CPU-s the first time in a process (6-10 CPU-s under load).

    Returns
    -------
    programs : dict
        ``starts(keys, y, cond)`` -> (n_starts, d) unconstrained starting points (the first as numpyro
        initialises the model, the others uniform in (-2, 2)); ``value_and_grad(flat, y, cond)`` of the
        negative log posterior; ``final(flat, y, cond)`` -> (scalar sites, eta).
    values : pytree or None
        The run-time conditions to pass as ``cond``.
    """
    import jax
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree
    from numpyro.handlers import substitute, trace
    from numpyro.infer.util import constrain_fn, initialize_model, log_density

    from lvcore.inference import samplers

    template, values = samplers.runtime_conditions(forward)
    tkey = samplers._template_key(template)
    key = None if tkey is None else (tkey, float(sigma_v), float(sigma_ref), bool(infer_angles), int(n_starts))
    kept = None if key is None else _BEST_FIT_PROGRAMS.get(key)
    if kept is not None:
        return kept, values

    def fwd(cond):
        return forward if values is None else template.bind(cond)

    def model(y=None, conditions=None):
        _reference_model(y, forward=fwd(conditions), sigma_v=float(sigma_v), sigma_ref=float(sigma_ref),
                         infer_angles=bool(infer_angles))

    def first(k, y, cond):
        return initialize_model(k, model, model_kwargs={"y": y, "conditions": cond}).param_info.z

    @jax.jit
    def starts(keys, y, cond):
        flat0, _ = ravel_pytree(first(keys[0], y, cond))
        rest = [jax.random.uniform(k, flat0.shape, minval=-2.0, maxval=2.0) for k in keys[1:]]
        return jnp.stack([flat0] + rest)

    def unravel(flat, y, cond):
        return ravel_pytree(jax.eval_shape(lambda: first(jax.random.PRNGKey(0), y, cond)))[1](flat)

    def objective(flat, y, cond):  # data and conditions are arguments: one program serves every data set
        args = {"y": y, "conditions": cond}
        z = constrain_fn(model, (), args, unravel(flat, y, cond))
        return -log_density(model, (), args, z)[0]

    order: list = []  # the sites in the model's order (a jitted dict comes back sorted by name)

    @jax.jit
    def final(flat, y, cond):
        args = {"y": y, "conditions": cond}
        z = constrain_fn(model, (), args, unravel(flat, y, cond))
        tr = trace(substitute(model, data=z)).get_trace(**args)
        params = {k: v["value"] for k, v in tr.items() if v["type"] in ("sample", "deterministic")
                  and not v.get("is_observed", False) and jnp.ndim(v["value"]) == 0}
        order[:] = list(params)
        return params, fwd(cond)(params)

    programs = {"starts": starts, "value_and_grad": jax.jit(jax.value_and_grad(objective)), "final": final,
                "order": order}
    if key is not None:
        _BEST_FIT_PROGRAMS.put(key, programs)
    return programs, values


def best_fit(y, forward, sigma_v: float, sigma_ref: float, infer_angles: bool = False, n_starts: int = N_STARTS,
             seed: int = 0) -> tuple[dict, np.ndarray]:
    """Maximum a posteriori of :func:`_reference_model` from ``n_starts`` prior draws (L-BFGS-B).

    The first start is where numpyro initialises the model (a valid point, uniform in (-2, 2)
    unconstrained), the others are drawn the same way. The programs are compiled once per emulator
    (:func:`_best_fit_programs`); tracing holds :data:`lvcore.inference.samplers.TRACE_LOCK`.

    Returns
    -------
    params : dict
        Constrained values of every sampled site at the best fit.
    eta : ndarray (25,)
    """
    import jax
    import jax.numpy as jnp
    from scipy.optimize import minimize

    from lvcore.inference import samplers

    y = jnp.asarray(y, dtype=jnp.float64)
    keys = jax.random.split(jax.random.PRNGKey(seed), n_starts)
    with samplers.TRACE_LOCK:  # numpyro's handler stack is global: no other trace may run meanwhile
        programs, cond = _best_fit_programs(forward, sigma_v, sigma_ref, infer_angles, n_starts)
        inits = np.asarray(programs["starts"](keys, y, cond), dtype=float)
        vg = programs["value_and_grad"]

        def fun(x):
            v, g = vg(jnp.asarray(x), y, cond)
            v, g = float(v), np.asarray(g, dtype=float)
            if not np.isfinite(v):
                return 1e300, np.zeros_like(g)
            return v, np.nan_to_num(g)

        best = None
        for x0 in inits:
            res = minimize(fun, x0, jac=True, method="L-BFGS-B", options={"maxiter": 300})
            if best is None or res.fun < best.fun:
                best = res
        params, eta = programs["final"](jnp.asarray(best.x), y, cond)
    return {k: float(params[k]) for k in programs["order"]}, np.asarray(eta, dtype=float)


def output_sds(eta, sigma_v: float, sigma_ref: float, forward=None) -> np.ndarray:
    """Marginal sd of each of the 25 outputs in the consistency likelihood: ``sigma_v`` and ``sigma_ref``,
    widened by the shape model's representation error when ``forward`` carries one (a mesh's floor,
    ``--geometry infer``): the iid likelihood's :func:`lvcore.inference.models.lvv_sd` and
    :func:`lvcore.inference.models.strain_noise_covariance` at ``sigma_S = sigma_ref``."""
    from lvcore.inference.models import lvv_sd, strain_noise_covariance

    cov = np.asarray(strain_noise_covariance(float(sigma_ref) ** 2, forward, "iid"), dtype=float)
    return np.r_[float(lvv_sd(float(eta[0]), float(sigma_v), forward)), np.sqrt(np.diag(cov))]


def consistency_check(y, forward, sigma_v: float, sigma_ref: float | None = None, infer_angles: bool = False,
                      n_starts: int = N_STARTS, seed: int = 0) -> Consistency:
    """Best fit, p-values and consistency flags of one subject's data (module docstring, part 1)."""
    from scipy.stats import norm

    from lvcore.inference import plausibility

    sigma_ref = plausibility.DEFAULT_SIGMA_REF if sigma_ref is None else float(sigma_ref)
    y = np.asarray(y, float).reshape(-1)
    params, eta = best_fit(y, forward, sigma_v, sigma_ref, infer_angles, n_starts, seed)
    z = np.abs(y - eta) / output_sds(eta, sigma_v, sigma_ref, forward)
    p = 2.0 * norm.sf(z)
    flags = []
    if p[0] < ALPHA:
        flags.append(f"the volume is not reached: measured LVV {y[0]:.1f} mL, the best fit of volume and strains "
                     f"gives {eta[0]:.1f} mL (p = {p[0]:.2g}); volume and strains imply different stiffness, or the "
                     "geometry (size) is not the subject's")
    bad = np.flatnonzero(p[1:] < ALPHA)
    if bad.size >= MIN_BAD_STRAINS:
        rmse = float(np.sqrt(np.mean((eta[1:] - y[1:]) ** 2)))
        flags.append(f"{bad.size} of 24 strains are not reached at the best fit (p < {ALPHA:g}; strain RMSE {rmse:.3f} "
                     f"against a reference noise of {sigma_ref:g}): volume and strains imply different stiffness, "
                     "the geometry is not the subject's, or the strains use another convention")
    # the data-only checks (signs, no deformation) of the posterior-predictive module, at the best fit
    data_only = plausibility.posterior_predictive_check(y, eta[None, :], sigma_v, sigma_ref, forward=forward)
    flags += [f for f in data_only.flags if "sign opposite" in f or "within" in f]
    i, p_s = residual_structure(y[1:] - eta[1:], seed=seed)
    structure = {"moran_i": i, "p_value": p_s, "residual_rms": float(np.sqrt(np.mean((y[1:] - eta[1:]) ** 2)))}
    return Consistency(best_fit=params, eta=eta, p_values=p, flags=tuple(flags), sigma_ref=sigma_ref,
                       structure=structure)


def posterior_misfit(result, forward=None, seed: int = 0) -> tuple[dict, list[str]]:
    """Posterior-predictive check of the strain likelihood's noise model: are the residuals independent?

    The residual is the data minus the posterior mean of the model's strain
    mean (``eta``, plus the discrepancy ``disc`` and offset ``v`` of model
    (iii)), whitened by the likelihood's own strain covariance at the
    posterior median ``sigma_S^2`` (``sigma_S^2 I``, plus the shape model's
    representation error ``Sigma_rep`` with ``--geometry infer`` or a mesh; symmetric
    square root, so each value stays at its region). The likelihood says
    these are independent; a significant spatial structure (Moran's I on the
    6 x 4 grid, permutation p < :data:`ALPHA`, :func:`residual_structure`)
    says the model misses a pattern the data have (a shape further from the
    shape model than the floor allows, a geometry that is not the
    subject's, a mismatch of the mechanics) and the intervals may be too
    narrow and biased. Noise-free data of an imperfect model show it;
    measurement noise larger than the misfit hides it (and then the
    intervals are wide enough). The volume model does not model the strains:
    not checked.

    Returns
    -------
    structure : dict
        ``moran_i``, ``p_value``, ``residual_rms`` (unwhitened), or empty when not checked.
    flags : list of str
    """
    from lvcore.inference.models import strain_floor, strain_noise_covariance

    idata = result.idata
    post = idata.posterior
    if result.model == "volume" or "eta" not in post or getattr(idata, "observed_data", None) is None \
            or "y" not in idata.observed_data or "sigma_s2" not in post:
        return {}, []
    y = np.asarray(idata.observed_data["y"], float).reshape(-1)
    mean = np.asarray(post["eta"], float).reshape(-1, y.size)[:, 1:]
    if "disc" in post:
        mean = mean + np.asarray(post["disc"], float).reshape(mean.shape)
    if "v" in post:
        mean = mean + np.asarray(post["v"], float).reshape(-1, 1)
    r = y[1:] - mean.mean(axis=0)
    # the likelihood's own strain covariance: sigma_S^2 I, plus Sigma_rep in the iid model with a floor (the
    # discrepancy model's b already holds it: models.strain_floor)
    model = "discrepancy" if "disc" in post else "iid"
    cov = np.asarray(strain_noise_covariance(float(np.median(np.asarray(post["sigma_s2"], float))), forward, model),
                     dtype=float)
    rep = strain_floor(forward, model)
    lam, u = np.linalg.eigh(cov)
    w = u @ ((u.T @ r) / np.sqrt(np.maximum(lam, 1e-300)))
    moran_i, p = residual_structure(w, seed=seed)
    out = {"moran_i": moran_i, "p_value": p, "residual_rms": float(np.sqrt(np.mean(r ** 2))),
           "whitened_by": "sigma_S^2 I" + (" + representation error" if rep is not None else "")}
    flags = []
    if p < ALPHA:
        flags.append(f"the strain residuals (data minus the posterior mean, whitened by the likelihood's "
                     f"{out['whitened_by']}) are spatially structured (Moran's I {moran_i:.2f}, p = {p:.2g}): the model "
                     "misses a pattern in the data that its noise model treats as independent, so the intervals may "
                     "be too narrow and biased (a shape the shape model does not reach, a geometry that is not the "
                     "subject's, other mechanics)" + ("; give the subject's mesh (--geometry FILE)"
                                                      if getattr(forward, "latent_names", None) else ""))
    return out, flags


def _width(lo, hi, log: bool) -> float:
    return math.log(hi / lo) if log else hi - lo


def _band_push(v: np.ndarray, lo: float, hi: float, log: bool, upper: bool) -> tuple[float, float]:
    """Posterior mass in the edge band at a bound and the posterior-to-prior density ratio there against the
    adjacent band (each band :data:`EDGE_BAND` of the range, on the log scale for log parameters).

    The prior is uniform on the linear scale, so its mass in each band is exact. A ratio near 1 means the
    posterior follows the prior towards the bound (nothing learned there); a ratio well above 1 means the
    likelihood rises towards the bound: the data push against it.
    """
    f = np.log if log else (lambda x: x)
    inv = np.exp if log else (lambda x: x)
    a, b = f(lo), f(hi)
    w = EDGE_BAND * (b - a)
    if upper:
        edge, adj = (inv(b - w), hi), (inv(b - 2 * w), inv(b - w))
    else:
        edge, adj = (lo, inv(a + w)), (inv(a + w), inv(a + 2 * w))
    post = lambda band: float(np.mean((v >= band[0]) & (v <= band[1])))  # noqa: E731
    prior = lambda band: (band[1] - band[0]) / (hi - lo)  # noqa: E731
    m_edge, m_adj = post(edge), post(adj)
    ratio = (m_edge / prior(edge)) / max(m_adj / prior(adj), 1e-12) if m_edge > 0 else 0.0
    return m_edge, ratio


def identifiability_flags(samples: dict, bounds: dict) -> tuple[list[str], dict, list[str]]:
    """Bound flags (a defect) and identification notes (information) (module docstring, part 2).

    A posterior is *piled on a bound the data push against* when its q05 (q95) lies within
    :data:`BOUND_FRACTION` of the range from the lower (upper) bound, at least :data:`MIN_EDGE_MASS` of the draws
    lie in the edge band, and the posterior-to-prior density ratio in the edge band is at least
    :data:`PUSH_RATIO` times that of the adjacent band (:func:`_band_push`): the likelihood rises towards the
    bound, so the bound, not the data, sets the estimate. A posterior that merely follows its prior to a
    bound (an unidentified direction meeting the box) is not a defect: it is a note, as is a 90 % interval
    at least :data:`WIDTH_FRACTION` of the prior's.

    Parameters
    ----------
    samples : dict
        Posterior draws by name (any shape).
    bounds : dict
        Prior bounds ``name -> (lower, upper)`` of the parameters to check.

    Returns
    -------
    flags : list of str
        Defects: posterior mass piled on a bound the data push against.
    table : dict
        Per parameter: q05, q95, prior bounds, distances to the bounds, the width ratio and the edge-band numbers.
    notes : list of str
        Weak identification (information, no flag).
    """
    flags, table, notes = [], {}, []
    for n, (lo, hi) in bounds.items():
        if n not in samples:
            continue
        v = np.asarray(samples[n], float).reshape(-1)
        log = n in LOG_PARAMETERS and lo > 0
        q05, q95 = float(np.quantile(v, 0.05)), float(np.quantile(v, 0.95))
        w = _width(lo, hi, log)
        d_lo = _width(lo, max(q05, lo), log) / w
        d_hi = _width(min(q95, hi), hi, log) / w
        # widths on the prior's own (uniform, linear) scale: its 90 % interval is 0.9 (hi - lo)
        ratio = (q95 - q05) / (0.9 * (hi - lo))
        m_lo, r_lo = _band_push(v, lo, hi, log, upper=False)
        m_hi, r_hi = _band_push(v, lo, hi, log, upper=True)
        row = {"q05": q05, "q95": q95, "lower": float(lo), "upper": float(hi), "scale": "log" if log else "linear",
               "q05_from_lower": d_lo, "q95_from_upper": d_hi, "width_vs_prior": ratio,
               "edge_mass_lower": m_lo, "push_ratio_lower": r_lo, "edge_mass_upper": m_hi, "push_ratio_upper": r_hi}
        table[n] = row
        for side, d, m, r, bound, q in (("lower", d_lo, m_lo, r_lo, lo, q05), ("upper", d_hi, m_hi, r_hi, hi, q95)):
            if d >= BOUND_FRACTION:
                continue
            if m >= MIN_EDGE_MASS and r >= PUSH_RATIO:
                flags.append(f"{n}: posterior piled on the prior's {side} bound {bound:g} ({'q05' if side == 'lower' else 'q95'} = "
                             f"{q:.4g}; {100 * m:.0f} % of the draws in the edge band, the likelihood {r:.1f}x higher "
                             f"there than next to it): the data push {n} {'below' if side == 'lower' else 'above'} "
                             "what the prior allows")
            else:
                notes.append(f"{n}: the posterior follows its prior to the {side} bound {bound:g}: the data do not "
                             f"bound {n} on that side")
        if n in THETA_NAMES + ANGLE_NAMES and ratio >= WIDTH_FRACTION:
            notes.append(f"{n}: the 90 % interval [{q05:.3g}, {q95:.3g}] is {100 * ratio:.0f} % of the prior's; the "
                         "data do not identify it on its own")
    return flags, table, notes


def sampler_flags(convergence, n_draws: int) -> list[str]:
    """Divergences above :data:`MAX_DIVERGENT_FRACTION` and non-convergence (module docstring, part 3)."""
    flags = []
    if not convergence.converged:
        flags.append(f"not converged: {convergence.message()}")
    if n_draws and convergence.n_divergent > MAX_DIVERGENT_FRACTION * n_draws:
        flags.append(f"{convergence.n_divergent} divergent transitions in {n_draws} draws (more than "
                     f"{100 * MAX_DIVERGENT_FRACTION:g} %): the sampler may have missed part of the posterior")
    return flags


@dataclass(frozen=True)
class Verdict:
    """All flags of one (subject, model) run.

    Attributes
    ----------
    consistency : Consistency
        Shared by every model of a subject.
    identifiability : tuple of str
        Defects: posterior mass piled on a bound the data push against (flag kind BOUND).
    sampler : tuple of str
    table : dict
        Per-parameter numbers behind the identifiability flags.
    """

    consistency: Consistency
    identifiability: tuple = ()
    sampler: tuple = ()
    table: dict = field(default_factory=dict)
    misfit: tuple = ()
    structure: dict = field(default_factory=dict)
    #: Information that is not a defect (weak identification), shown with the identified quantities.
    notes: tuple = ()
    #: Flags found outside this module (the EDPVR's consistency, extrapolation), by kind: ((kind, text), ...).
    extra: tuple = ()

    @property
    def flags(self) -> list[str]:
        checked = self.consistency.flags if self.consistency is not None else []   # None: no check was made
        return ([f"CONSISTENCY: {f}" for f in checked]
                + [f"MISFIT: {f}" for f in self.misfit]
                + [f"BOUND: {f}" for f in self.identifiability] + [f"SAMPLER: {f}" for f in self.sampler]
                + [f"{kind}: {f}" for kind, f in self.extra])

    def with_extra(self, kind: str, flags) -> "Verdict":
        """This verdict with more flags of ``kind`` (e.g. ``CONSISTENCY`` from the EDPVR, ``EXTRAPOLATION``)."""
        from dataclasses import replace

        return replace(self, extra=tuple(self.extra) + tuple((kind, f) for f in flags))

    @property
    def plausible(self) -> bool:
        """The model-independent part: the data are consistent with the best-fitting forward model."""
        return self.consistency.plausible

    @property
    def flagged(self) -> bool:
        return bool(self.flags)

    def record(self) -> dict:
        return {"flagged": self.flagged, "plausible": self.plausible, "flags": self.flags, "notes": list(self.notes),
                "consistency": self.consistency.record(), "identifiability": self.table,
                "residual_structure": dict(self.structure),
                "thresholds": {"alpha": ALPHA, "min_bad_strains": MIN_BAD_STRAINS, "bound_fraction": BOUND_FRACTION,
                               "width_fraction": WIDTH_FRACTION, "edge_band": EDGE_BAND,
                               "min_edge_mass": MIN_EDGE_MASS, "push_ratio": PUSH_RATIO,
                               "max_divergent_fraction": MAX_DIVERGENT_FRACTION}}


def run_verdict(result, consistency: Consistency, bounds: dict, forward=None) -> Verdict:
    """The :class:`Verdict` of a :class:`~lvcore.inference.calibrate.CalibrationResult`
    (``forward``: the forward model that ran, for the representation error of :func:`posterior_misfit`)."""
    post = result.idata.posterior
    samples = {n: np.asarray(post[n]) for n in bounds if n in post}
    ident, table, notes = identifiability_flags(samples, bounds)
    n_draws = int(np.prod(np.asarray(post[next(iter(THETA_NAMES))]).shape[:2]))
    structure, misfit = posterior_misfit(result, forward)
    return Verdict(consistency, tuple(ident), tuple(sampler_flags(result.convergence, n_draws)), table,
                   tuple(misfit), structure, tuple(notes))


def checked_bounds(forward, infer_angles: bool = False) -> dict:
    """Prior bounds of the parameters whose identifiability is checked (theta, angles, inferred geometry)."""
    from lvcore.inference.models import prior_bounds

    bounds = dict(prior_bounds(infer_angles, forward))
    bounds.update(getattr(forward, "latent_bounds", {}) or {})
    return {n: b for n, b in bounds.items() if n in THETA_NAMES + ANGLE_NAMES or is_pc_name(n) or n == "scale"}


__all__ = ["ALPHA", "MIN_BAD_STRAINS", "N_STARTS", "BOUND_FRACTION", "WIDTH_FRACTION", "EDGE_BAND", "MIN_EDGE_MASS", "PUSH_RATIO",
           "MAX_DIVERGENT_FRACTION",
           "N_PERMUTATIONS", "Consistency", "best_fit", "output_sds", "consistency_check", "posterior_misfit",
           "residual_structure", "identifiability_flags", "sampler_flags", "Verdict",
           "run_verdict", "checked_bounds"]
