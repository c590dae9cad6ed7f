r"""One joint posterior for a cohort: a hierarchical model over the subjects' theta, sampled by NUTS.

Model (non-centred)
    For subject ``i`` of group ``g(i)``, with ``k`` over (a, b, af, bf)::

        mu_g     ~ Uniform(log lower_k, log upper_k)        (Table 9.1's box, on the log scale)
        tau_k    ~ HalfNormal(TAU_SD)                       (population sds of log theta)
        L_Omega  ~ LKJCholesky(4, LKJ_CONCENTRATION)        (their correlations)
        z_i      ~ N(0, I_4)
        log theta_i = mu_g(i) + diag(tau) L_Omega z_i       so  log theta_i ~ N(mu_g(i), Sigma)

    and each subject's data through its own forward model (its geometry bound in, its own floor, loaded states
    or inferred geometry: :func:`lvcore.inference.request.build_request`) with the likelihood of
    :mod:`lvcore.inference.models`: ``volume`` (LVV only) or ``iid`` (LVV plus strains with the subject's own
    ``sigma_S^2 ~ IG(0.001, 0.001)``). The population distribution is not truncated to the box: a subject's
    theta outside it is the emulator's extrapolation (the summary counts the draws outside).

Outputs (:func:`summarise`)
    The population mean and covariance (sds and correlations) of log theta, per group; each subject's 90 %
    interval with its shrinkage against a separate fit (``1 - width_hier / width_separate``); the differences of
    the group means with their 90 % intervals, checked against the same differences of the separate fits
    (:func:`separate_differences`, :func:`group_flags`); R-hat, ESS and divergences at the population and subject
    levels.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
from numpyro.infer import MCMC, NUTS, init_to_value

from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.domain.outputs import THETA_NAMES
from lvcore.inference import models
from lvcore.inference.diagnostics import DEFAULT_ESS_MIN, DEFAULT_RHAT_MAX
from lvcore.inference.sampler_config import SamplerConfig

#: Scale of the half-normal prior of the population sds of log theta (1: a factor e either way is plausible).
TAU_SD = 1.0
#: LKJ concentration of the correlations (2: mild shrinkage towards independence).
LKJ_CONCENTRATION = 2.0
#: The likelihoods a hierarchical calibration takes (the discrepancy model's GP is per subject and not pooled).
LIKELIHOODS = ("volume", "iid")
#: NUTS settings of the joint run: a higher target than a single subject's against the funnel of tau and z.
TARGET_ACCEPT = 0.9
MAX_TREE_DEPTH = 8
#: Resamples of the separate fits' group differences (subjects resampled within each group).
SEPARATE_BOOTSTRAP = 4000
#: Population-level parameters of the joint posterior, and subject-level ones.
POPULATION_SITES = ("mu", "tau", "corr")
SUBJECT_SITES = ("log_theta", "sigma_s2")


@dataclass(frozen=True)
class CohortMember:
    """One subject of the joint model: its id, measured ``[LVV, 24 strains]``, forward model and group index."""

    subject: str
    y: np.ndarray
    forward: object
    group: int = 0


@dataclass(frozen=True)
class HierarchicalRun:
    """Draws of the joint posterior.

    Attributes
    ----------
    subjects : tuple of str
    groups : tuple of str
        Group labels (one, ``"all"``, without groups); ``mu`` is indexed by them.
    group_index : ndarray of int, shape (n,)
    likelihood : str
    samples : dict
        ``mu`` (chain, draw, G, 4) and ``log_theta`` (chain, draw, n, 4) on the log scale of theta, ``tau``
        (chain, draw, 4), ``corr`` (chain, draw, 4, 4), ``sigma_s2`` (chain, draw, n) for ``iid``.
    stats : dict
        ``diverging`` (chain, draw).
    wall_s : float
    """

    subjects: tuple
    groups: tuple
    group_index: np.ndarray
    likelihood: str
    samples: dict = field(repr=False)
    stats: dict = field(repr=False)
    wall_s: float = 0.0


def log_bounds(forward=None) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper log bounds of theta: Table 9.1's box cut to the forward model's
    (:func:`lvcore.inference.models.prior_bounds`)."""
    b = models.prior_bounds(False, forward)
    return np.log([b[k][0] for k in THETA_NAMES]), np.log([b[k][1] for k in THETA_NAMES])


def hierarchical_model(y=None, *, members, n_groups: int = 1, likelihood: str = "iid",
                       sigma_v: float = SIGMA_V_ML, bounds=None, batch=None):
    """The joint model of a cohort (module docstring).

    Parameters
    ----------
    y : array (n, 25), optional
        Measured ``[LVV (mL), 24 strains]`` per subject (None: prior predictive).
    members : sequence of CohortMember
        Their forward models (JAX-traceable) and group indices (``y`` is taken from the argument).
    n_groups : int
    likelihood : {"volume", "iid"}
    sigma_v : float
        LVV noise sd (mL).
    bounds : (lower, upper), optional
        Log bounds of mu's uniform prior (default :func:`log_bounds`).
    batch : (template, values), optional
        :func:`batched`'s stacked conditions: every subject through one batched emulator call.
    """
    lo, hi = log_bounds() if bounds is None else bounds
    n = len(members)
    mu = numpyro.sample("mu", dist.Uniform(jnp.asarray(lo), jnp.asarray(hi)).expand([n_groups, 4]).to_event(2))
    tau = numpyro.sample("tau", dist.HalfNormal(TAU_SD).expand([4]).to_event(1))
    chol = numpyro.sample("L_omega", dist.LKJCholesky(4, LKJ_CONCENTRATION))
    z = numpyro.sample("z", dist.Normal(0.0, 1.0).expand([n, 4]).to_event(2))
    gi = np.asarray([m.group for m in members])
    log_theta = numpyro.deterministic("log_theta", mu[gi] + z @ (tau[:, None] * chol).T)
    sigma_s2 = None
    if likelihood == "iid":
        sigma_s2 = numpyro.sample("sigma_s2", models.sigma_s2_prior().expand([n]).to_event(1))
    if batch is not None:   # one emulator, conditions per subject: one batched evaluation (:func:`batched`)
        template, values = batch
        eta = jax.vmap(lambda v, th: template.bind(v)({k: th[j] for j, k in enumerate(THETA_NAMES)}))(
            values, jnp.exp(log_theta))
        numpyro.sample("lvv_obs", dist.Normal(eta[:, 0], sigma_v).to_event(1), obs=None if y is None else y[:, 0])
        if sigma_s2 is not None:
            numpyro.sample("strain_obs", dist.Normal(eta[:, 1:], jnp.sqrt(sigma_s2)[:, None]).to_event(2),
                           obs=None if y is None else y[:, 1:])
        return
    for i, m in enumerate(members):
        with numpyro.handlers.scope(prefix=f"s{i}", divider="/"):
            _subject_terms(m.forward, jnp.exp(log_theta[i]), None if y is None else y[i],
                           None if sigma_s2 is None else sigma_s2[i], sigma_v)


def batched(members):
    """``(template, values)`` with the subjects' run-time conditions stacked, when every forward model is one
    emulator with its conditions (PC scores, scale) as run-time values
    (:func:`lvcore.inference.compiled_samplers.runtime_conditions`) and nothing else (no representation floor,
    loaded states or inferred geometry); else None (the model then loops over the subjects)."""
    from lvcore.inference.compiled_samplers import _template_key, runtime_conditions

    pairs = [runtime_conditions(m.forward) for m in members]
    keys = {_template_key(t) for t, _ in pairs}
    if len(keys) != 1 or None in keys or any(v is None or "floor_scale" in v for _, v in pairs):
        return None
    if any(t.representation is not None for t, _ in pairs):
        return None
    return pairs[0][0], jax.tree.map(lambda *xs: jnp.stack(xs), *[v for _, v in pairs])


def _subject_terms(forward, theta, y, sigma_s2, sigma_v) -> None:
    """One subject's likelihood at its theta: LVV (and iid strains), plus its forward model's further terms
    (loaded states) and latent geometry (``--geometry infer``), as in :mod:`lvcore.inference.models`."""
    params = {k: theta[j] for j, k in enumerate(THETA_NAMES)}
    latents = getattr(forward, "sample_latents", None)
    if latents is not None:
        params.update(latents())
    eta = forward(params)
    numpyro.sample("lvv_obs", dist.Normal(eta[0], models.lvv_sd(eta[0], sigma_v, forward)),
                   obs=None if y is None else y[0])
    if sigma_s2 is not None:
        numpyro.sample("strain_obs", models.strain_likelihood(eta[1:], sigma_s2, forward),
                       obs=None if y is None else y[1:])
    models.extra_terms(forward, params, eta, sigma_v, sigma_s2)


def _init_values(n: int, n_groups: int, likelihood: str, bounds) -> dict:
    lo, hi = bounds
    start = {"mu": jnp.broadcast_to(jnp.asarray((lo + hi) / 2), (n_groups, 4)),
             "tau": jnp.full(4, 0.3), "z": jnp.zeros((n, 4)), "L_omega": jnp.eye(4)}
    if likelihood == "iid":
        start["sigma_s2"] = jnp.full(n, 1e-3)
    return start


def run_hierarchical(members, *, groups=("all",), likelihood: str = "iid", config: SamplerConfig = SamplerConfig(),
                     sigma_v: float = SIGMA_V_ML, progress_bar: bool = False,
                     vectorize: bool = True) -> HierarchicalRun:
    """Sample the joint posterior of a cohort with NUTS (``config``'s warm-up, draws, chains and seed).

    Parameters
    ----------
    members : sequence of CohortMember
        At least two; every forward model JAX-traceable and reading theta only.
    groups : sequence of str
        Group labels; ``members[i].group`` indexes them.
    likelihood : {"volume", "iid"}
    progress_bar : bool
        numpyro's progress bar (stderr).
    vectorize : bool
        Evaluate the subjects in one batched emulator call when they allow it (:func:`batched`); False: one
        call per subject (the same posterior; a test compares the two).

    Examples
    --------
    Four SYNTHETIC subjects of the analytic stand-in forward model (tests only), short chains:

    >>> import numpy as np
    >>> from lvcore.testing.analytic import AnalyticForward
    >>> fw = AnalyticForward()
    >>> ms = [CohortMember(f"S{i}", np.asarray(fw({"a": 0.6 * (1 + 0.1 * i), "b": 5.0, "af": 1.5, "bf": 5.0})), fw)
    ...       for i in range(4)]
    >>> run = run_hierarchical(ms, config=SamplerConfig(num_warmup=100, num_samples=100, num_chains=2))
    >>> run.samples["log_theta"].shape, run.samples["mu"].shape
    ((2, 100, 4, 4), (2, 100, 1, 4))
    """
    members = list(members)
    if len(members) < 2:
        raise ValueError("a hierarchical calibration needs at least 2 subjects")
    if likelihood not in LIKELIHOODS:
        raise ValueError(f"likelihood {likelihood!r}: a hierarchical calibration takes {', '.join(LIKELIHOODS)}")
    for m in members:
        models.check_traceable(m.forward)
    bounds = log_bounds(members[0].forward)
    kernel = NUTS(hierarchical_model, target_accept_prob=max(config.target_accept_prob, TARGET_ACCEPT),
                  max_tree_depth=min(config.max_tree_depth, MAX_TREE_DEPTH), dense_mass=config.dense_mass,
                  init_strategy=init_to_value(values=_init_values(len(members), len(groups), likelihood, bounds)))
    n_dev = jax.local_device_count()
    method = "parallel" if config.num_chains > 1 and n_dev >= config.num_chains else "vectorized"
    mcmc = MCMC(kernel, num_warmup=config.num_warmup, num_samples=config.num_samples, num_chains=config.num_chains,
                chain_method=method, progress_bar=progress_bar)
    y = jnp.asarray(np.stack([np.asarray(m.y, float) for m in members]))
    t0 = time.perf_counter()
    mcmc.run(jax.random.PRNGKey(config.seed), y, members=tuple(members), n_groups=len(groups),
             likelihood=likelihood, sigma_v=sigma_v, bounds=bounds, batch=batched(members) if vectorize else None,
             extra_fields=("diverging",))
    raw = mcmc.get_samples(group_by_chain=True)
    samples = {k: np.asarray(raw[k]) for k in ("mu", "tau", "log_theta", "sigma_s2") if k in raw}
    chol = np.asarray(raw["L_omega"])
    samples["corr"] = np.einsum("...ij,...kj->...ik", chol, chol)
    stats = {"diverging": np.asarray(mcmc.get_extra_fields(group_by_chain=True)["diverging"])}
    return HierarchicalRun(tuple(m.subject for m in members), tuple(groups),
                           np.asarray([m.group for m in members]), likelihood, samples, stats,
                           time.perf_counter() - t0)


# --------------------------------------------------------------------------- summaries
def _q(x) -> dict:
    x = np.asarray(x, float).reshape(-1)
    q05, med, q95 = np.quantile(x, [0.05, 0.5, 0.95])
    return {"q05": float(q05), "median": float(med), "q95": float(q95)}


def _level(samples: dict, names, diverging) -> dict:
    """Worst R-hat and ESS over the elements of the named draws (chain, draw, ...), with the joint sampler's
    divergences; a correlation matrix contributes its upper triangle only (its diagonal is 1)."""
    import arviz as az

    post = {}
    for k in names:
        if k not in samples:
            continue
        v = np.asarray(samples[k])
        if k == "corr":
            iu = np.triu_indices(v.shape[-1], 1)
            v = v[..., iu[0], iu[1]]
        post[k] = v.reshape(v.shape[:2] + (-1,))
    data = az.from_dict(posterior=post)
    rhat, bulk, tail = az.rhat(data), az.ess(data, method="bulk"), az.ess(data, method="tail")
    per = {k: {"max_rhat": float(np.max(rhat[k].values)), "min_ess_bulk": float(np.min(bulk[k].values)),
               "min_ess_tail": float(np.min(tail[k].values))} for k in post}
    failing = [k for k, r in per.items() if not (r["max_rhat"] <= DEFAULT_RHAT_MAX and r["min_ess_bulk"] >= DEFAULT_ESS_MIN)]
    return {"max_rhat": max(r["max_rhat"] for r in per.values()),
            "min_ess_bulk": min(r["min_ess_bulk"] for r in per.values()),
            "min_ess_tail": min(r["min_ess_tail"] for r in per.values()),
            "n_divergent": int(np.sum(diverging)), "failing": failing, "by_parameter": per,
            "converged": not failing, "rhat_max": DEFAULT_RHAT_MAX, "ess_min": DEFAULT_ESS_MIN}


def diagnostics(run: HierarchicalRun) -> dict:
    """R-hat, ESS and divergences per level: ``population`` (mu, tau, correlations) and ``subject`` (log theta,
    sigma_S^2). Divergences are the joint sampler's (one count, shown at both levels)."""
    div = run.stats["diverging"]
    if np.shape(div)[0] < 2:
        raise ValueError("R-hat needs >= 2 chains")
    return {"population": _level(run.samples, POPULATION_SITES, div),
            "subject": _level(run.samples, SUBJECT_SITES, div)}


def population(run: HierarchicalRun) -> dict:
    """The population per group: ``mu`` (log theta and theta = exp(mu), the population median), ``sd`` (of log
    theta) and ``corr`` (posterior medians, and 90 % intervals of each pair), plus the differences of the group
    means from the first group (log scale and ratio, with whether the 90 % interval excludes 0)."""
    s = run.samples
    out = {"groups": {}, "sd": {k: _q(s["tau"][..., j]) for j, k in enumerate(THETA_NAMES)},
           "corr": {"median": np.median(s["corr"].reshape((-1, 4, 4)), axis=0).round(6).tolist(),
                    "pairs": {f"{THETA_NAMES[i]}-{THETA_NAMES[j]}": _q(s["corr"][..., i, j])
                              for i in range(4) for j in range(i + 1, 4)}}}
    for gi, g in enumerate(run.groups):
        mu = s["mu"][..., gi, :]
        out["groups"][g] = {"n_subjects": int(np.sum(run.group_index == gi)),
                            "mu_log": {k: _q(mu[..., j]) for j, k in enumerate(THETA_NAMES)},
                            "median_theta": {k: _q(np.exp(mu[..., j])) for j, k in enumerate(THETA_NAMES)}}
    diffs = {}
    for gi, g in enumerate(run.groups[1:], start=1):
        d = s["mu"][..., gi, :] - s["mu"][..., 0, :]
        rec = {}
        for j, k in enumerate(THETA_NAMES):
            q = _q(d[..., j])
            rec[k] = {"log": q, "ratio": {n: float(np.exp(v)) for n, v in q.items()},
                      "excludes_zero": bool(q["q05"] > 0 or q["q95"] < 0)}
        diffs[f"{g} - {run.groups[0]}"] = rec
    out["differences"] = diffs
    return out


def subject_intervals(run: HierarchicalRun, bounds=None) -> dict:
    """Subject -> theta's q05/median/q95 in the joint posterior, and the fraction of its draws outside the
    prior box (extrapolated by the emulator)."""
    lo, hi = log_bounds() if bounds is None else bounds
    lt = run.samples["log_theta"]
    out = {}
    for i, s in enumerate(run.subjects):
        x = lt[..., i, :].reshape((-1, 4))
        out[s] = {k: _q(np.exp(x[:, j])) for j, k in enumerate(THETA_NAMES)}
        out[s]["outside_box"] = float(np.mean(np.any((x < lo) | (x > hi), axis=1)))
        if "sigma_s2" in run.samples:
            out[s]["sigma_s2"] = _q(run.samples["sigma_s2"][..., i])
    return out


def shrinkage(hier: dict, separate: dict) -> dict:
    """Per subject and parameter, ``1 - width_hier / width_separate`` of the 90 % intervals, with both widths;
    and the median ratio ``width_separate / width_hier`` (narrowing) over the subjects per parameter."""
    per, ratios = {}, {k: [] for k in THETA_NAMES}
    for s, h in hier.items():
        if s not in separate:
            continue
        per[s] = {}
        for k in THETA_NAMES:
            wh = h[k]["q95"] - h[k]["q05"]
            ws = separate[s][k]["q95"] - separate[s][k]["q05"]
            per[s][k] = {"width_hier": wh, "width_separate": ws, "shrinkage": 1.0 - wh / ws if ws > 0 else None}
            if wh > 0:
                ratios[k].append(ws / wh)
    return {"per_subject": per,
            "median_narrowing": {k: float(np.median(v)) if v else None for k, v in ratios.items()}}


def separate_differences(separate: dict, subjects, groups, group_index, seed: int = 0) -> dict:
    """The group differences as the separate fits give them: per pair (each group against the first) and theta,
    the ratio ``exp(mean_B log m - mean_A log m)`` of the subjects' separate posterior medians ``m``, with its 90 %
    percentile interval from resampling the subjects within each group (the independent unit;
    ``scipy.stats.bootstrap``, :data:`SEPARATE_BOOTSTRAP` resamples) and whether it excludes 1; a pair with a group
    of one subject is left out."""
    from scipy.stats import bootstrap

    gi = np.asarray(group_index)
    logm = {k: np.log([float(separate[s][k]["median"]) for s in subjects]) for k in THETA_NAMES}
    out = {}
    for g in range(1, len(groups)):
        if min(np.sum(gi == 0), np.sum(gi == g)) < 2:   # nothing to resample (the cohort reader refuses such groups)
            continue
        rec = {}
        for j, k in enumerate(THETA_NAMES):
            a, b = logm[k][gi == 0], logm[k][gi == g]
            ci = bootstrap((a, b), lambda x, y, axis: np.mean(y, axis=axis) - np.mean(x, axis=axis),
                           n_resamples=SEPARATE_BOOTSTRAP, confidence_level=0.9, method="percentile",
                           vectorized=True, rng=np.random.default_rng(seed + 1000 * g + j)).confidence_interval
            lo, hi = float(ci.low), float(ci.high)
            d = float(np.mean(b) - np.mean(a))
            rec[k] = {"ratio": {"q05": float(np.exp(lo)), "median": float(np.exp(d)), "q95": float(np.exp(hi))},
                      "excludes_zero": bool(lo > 0 or hi < 0)}
        out[f"{groups[g]} - {groups[0]}"] = rec
    return out


def group_flags(joint: dict, separate: dict) -> list[str]:
    """CONSISTENCY flags where the joint posterior and the separate fits disagree on a group difference: one
    interval excludes no difference and the other does not, or both exclude it with opposite signs (a symmetric
    rule: a difference the joint model adds and one it removes are both flagged). On a SYNTHETIC two-group cohort
    the joint model called a difference in a_f that was not there while the separate fits did not
    (BENCHMARKS.md row 64)."""
    flags = []
    for pair, d in joint.items():
        for k, v in d.items():
            w = separate.get(pair, {}).get(k)
            if w is None:
                continue
            jr, sr = v["ratio"], w["ratio"]
            same = v["excludes_zero"] == w["excludes_zero"] and (
                not v["excludes_zero"] or (jr["median"] > 1) == (sr["median"] > 1))
            if not same:
                flags.append(f"CONSISTENCY: group difference {pair} in {k}: the joint posterior's ratio "
                             f"{jr['median']:.2f} [{jr['q05']:.2f}, {jr['q95']:.2f}] and the separate fits' "
                             f"{sr['median']:.2f} [{sr['q05']:.2f}, {sr['q95']:.2f}] (subjects resampled) disagree on "
                             "whether there is one; trust neither without more data")
    return flags


def summarise(run: HierarchicalRun, separate: dict | None = None) -> dict:
    """summary.json's ``hierarchical`` section: population, subjects (with shrinkage against ``separate``, subject
    -> theta's q05/median/q95 of separate fits, when given), group differences and diagnostics per level."""
    subj = subject_intervals(run)
    rec = {"likelihood": run.likelihood, "n_subjects": len(run.subjects), "groups": list(run.groups),
           "wall_s": float(run.wall_s), "scale": "mu and sd are of log theta (theta in kPa for a, af)",
           "population": population(run), "subjects": subj, "diagnostics": diagnostics(run),
           "priors": {"mu": "Uniform over Table 9.1's box (log scale)", "tau": f"HalfNormal({TAU_SD:g})",
                      "corr": f"LKJCholesky(4, {LKJ_CONCENTRATION:g})"}}
    rec["flags"] = []
    rec["converged"] = all(v["converged"] for v in rec["diagnostics"].values())
    return with_separate(rec, run, separate) if separate else rec


def with_separate(rec: dict, run: HierarchicalRun, separate: dict) -> dict:
    """:func:`summarise`'s record ``rec`` with the separate fits added (in place, and returned): ``separate``, the
    ``shrinkage`` against them and, with groups and every subject fitted, ``population.differences_separate`` and
    the CONSISTENCY ``flags`` of :func:`group_flags`."""
    rec["separate"] = separate
    rec["shrinkage"] = shrinkage(rec["subjects"], separate)
    if len(run.groups) > 1 and all(s in separate for s in run.subjects):
        sep = separate_differences(separate, run.subjects, run.groups, run.group_index)
        rec["population"]["differences_separate"] = sep
        rec["flags"] = group_flags(rec["population"]["differences"], sep)
    return rec


__all__ = ["CohortMember", "HierarchicalRun", "hierarchical_model", "run_hierarchical", "log_bounds", "diagnostics",
           "population", "subject_intervals", "shrinkage", "summarise", "LIKELIHOODS", "TAU_SD", "LKJ_CONCENTRATION",
           "separate_differences", "group_flags", "SEPARATE_BOOTSTRAP", "with_separate"]
