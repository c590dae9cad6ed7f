"""Convergence diagnostics (ArviZ R-hat and ESS), InferenceData export.

Policy (chapter: "convergence by PSRF, 1000 draws kept after convergence"):
run warm-up plus ``num_samples`` draws per chain; if the split R-hat of any
monitored parameter exceeds ``rhat_max`` or its bulk ESS is below
``ess_min``, those draws are discarded as burn-in and ``num_samples`` new
draws are taken from where the chains stopped, up to ``max_rounds`` times.
A run that still fails is returned with ``converged=False`` and the failing
parameters listed: non-convergence is reported, never hidden.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import arviz as az
import numpy as np
import pandas as pd

from lvcore.domain.conditions import SIGMA_V_ML
from lvcore.inference import models, samplers
from lvcore.domain.outputs import ANGLE_NAMES, OUTPUT_NAMES, STRAIN_NAMES, THETA_NAMES, is_pc_name

#: Default convergence thresholds.
DEFAULT_RHAT_MAX = 1.05
DEFAULT_ESS_MIN = 100.0


def monitored_names(samples: dict) -> list[str]:
    """Scalar parameters whose convergence is checked (theta, angles, sigma_S^2, v, GP hyperparameters: those the
    run sampled, so the product kernel's, without ``sigma2_sq``, too)."""
    order = THETA_NAMES + ANGLE_NAMES + ("sigma_s2", "v") + models.HYPER_NAMES
    # the geometry of --geometry infer: PC scores h1..hk and the scale (lvcore.inference.geometry_prior)
    pcs = sorted((n for n in samples if is_pc_name(n) and np.ndim(samples[n]) == 2), key=lambda n: int(n[1:]))
    order = order + tuple(pcs) + ("scale",)
    return [n for n in order if n in samples]


@dataclass(frozen=True)
class Convergence:
    """Convergence summary of one run.

    Attributes
    ----------
    converged : bool
        All monitored parameters have R-hat <= rhat_max and bulk ESS >= ess_min.
    max_rhat, min_ess_bulk, min_ess_tail : float
        Worst values over the monitored parameters.
    n_divergent : int
        Divergent transitions among the kept draws.
    failing : tuple of str
        Parameters that missed a threshold.
    rounds : int
        Sampling rounds used (1 = no extension needed).
    rhat_max, ess_min : float
        Thresholds used.
    """

    converged: bool
    max_rhat: float
    min_ess_bulk: float
    min_ess_tail: float
    n_divergent: int
    failing: tuple
    rounds: int = 1
    rhat_max: float = DEFAULT_RHAT_MAX
    ess_min: float = DEFAULT_ESS_MIN

    def message(self) -> str:
        """One line for logs and the app."""
        state = "converged" if self.converged else "NOT CONVERGED"
        msg = (f"{state}: max R-hat {self.max_rhat:.3f} (<= {self.rhat_max}), min bulk ESS "
               f"{self.min_ess_bulk:.0f} (>= {self.ess_min:.0f}), {self.n_divergent} divergent, "
               f"{self.rounds} round(s)")
        if self.failing:
            msg += "; failing: " + ", ".join(self.failing)
        return msg


#: Columns of the posterior summary that give the 90 % equal-tailed interval (the 5 % and 95 % quantiles of the
#: pooled draws): the interval of the verdict, the derived quantities and ``result_record`` (q05, q95), one
#: convention everywhere (not ArviZ's highest-density interval).
INTERVAL_COLUMNS = ("q05", "q95")
#: What the two columns are, in words (table headers, the CLI's printed table).
INTERVAL_TEXT = "90 % equal-tailed interval"


def equal_tailed_summary(data, var_names=None) -> pd.DataFrame:
    """ArviZ's summary of ``data`` (InferenceData) with its HDI columns replaced by the 90 % equal-tailed interval:
    mean, sd, median, q05, q95 (quantiles of the pooled chains and draws), MCSE of mean and sd, bulk and tail ESS,
    R-hat. Unrounded."""
    table = az.summary(data, var_names=var_names, hdi_prob=0.9, round_to="none")
    table = table.drop(columns=[c for c in table.columns if str(c).startswith("hdi_")])
    post = data.posterior
    q = {n: np.quantile(np.asarray(post[n]).reshape(-1), [0.5, 0.05, 0.95]) for n in table.index}
    at = list(table.columns).index("sd") + 1 if "sd" in table.columns else 0
    for k, col in enumerate(("median",) + INTERVAL_COLUMNS):
        table.insert(at + k, col, [float(q[n][k]) for n in table.index])
    table.columns.name = f"{'–'.join(INTERVAL_COLUMNS)} = {INTERVAL_TEXT}"  # the header of a printed table
    return table


def summary_table(samples: dict, var_names=None) -> pd.DataFrame:
    """Posterior summary of scalar parameters: mean, sd, median, the 90 % equal-tailed interval (q05, q95), MCSE,
    ESS bulk/tail, R-hat (:func:`equal_tailed_summary`).

    Unrounded (``round_to="none"``): ArviZ's default of 2 decimals turns a
    strain variance sigma_s2 of order 1e-4 into 0.0.
    """
    var_names = monitored_names(samples) if var_names is None else list(var_names)
    data = az.from_dict(posterior={n: np.asarray(samples[n]) for n in var_names})
    return equal_tailed_summary(data)


def n_chains(run: samplers.SamplerRun) -> int:
    """Number of chains in a run."""
    return int(np.shape(next(iter(run.samples.values())))[0])


def check_convergence(run: samplers.SamplerRun, rhat_max: float = DEFAULT_RHAT_MAX,
                      ess_min: float = DEFAULT_ESS_MIN, rounds: int = 1) -> Convergence:
    """R-hat and ESS of the monitored parameters of ``run`` (ArviZ rank-normalised split R-hat)."""
    table = summary_table(run.samples)
    failing = tuple(table.index[(table["r_hat"] > rhat_max) | (table["ess_bulk"] < ess_min)
                                | ~np.isfinite(table["r_hat"])])
    n_div = int(np.sum(run.sample_stats.get("diverging", 0)))
    rhat = table["r_hat"].to_numpy(dtype=float)
    if n_chains(run) < 2:
        failing = tuple(failing) + ("R-hat needs >= 2 chains",)
    return Convergence(
        converged=not failing,
        max_rhat=float(np.max(rhat)) if np.all(np.isfinite(rhat)) else float("nan"),
        min_ess_bulk=float(np.nanmin(table["ess_bulk"])),
        min_ess_tail=float(np.nanmin(table["ess_tail"])),
        n_divergent=n_div,
        failing=failing,
        rounds=rounds,
        rhat_max=rhat_max,
        ess_min=ess_min,
    )


def sample_until_converged(model_name: str, y, forward, config: samplers.SamplerConfig = samplers.SamplerConfig(),
                           *, sampler: str = "auto", rhat_max: float = DEFAULT_RHAT_MAX,
                           ess_min: float = DEFAULT_ESS_MIN, max_rounds: int = 3, progress=None,
                           **model_kwargs) -> tuple[samplers.SamplerRun, Convergence]:
    """Run a model and extend it until convergence (see module docstring).

    Parameters
    ----------
    progress : callable, optional
        ``progress(message: str, fraction: float)`` called between rounds.
    """
    if progress:
        progress(f"{model_name}: warm-up and sampling (round 1)", 0.0)
    run = samplers.run_model(model_name, y, forward, config, sampler=sampler, **model_kwargs)
    conv = check_convergence(run, rhat_max, ess_min, 1)
    rounds = 1
    # (R-hat needs two chains: a single chain is reported as not assessable, not extended)
    while not conv.converged and rounds < max_rounds and n_chains(run) > 1:
        rounds += 1
        if progress:
            progress(f"{model_name}: {conv.message()}; drawing round {rounds}", (rounds - 1) / max_rounds)
        run = samplers.continue_run(run, forward)
        conv = check_convergence(run, rhat_max, ess_min, rounds)
    if progress:
        progress(f"{model_name}: {conv.message()}", 1.0)
    return run, conv


def ess_per_second(run: samplers.SamplerRun, var_names=THETA_NAMES) -> dict:
    """Bulk ESS per second of wall time (compilation included) for each of ``var_names``, plus the minimum."""
    ess = az.ess(az.from_dict(posterior={n: run.samples[n] for n in var_names if n in run.samples}))
    out = {n: float(ess[n]) / run.wall_s for n in ess.data_vars}
    out["min"] = min(out.values())
    return out


def posterior_predictive(samples: dict, sigma_v: float, rng: np.random.Generator, forward=None,
                         model: str | None = None) -> np.ndarray:
    """Replicated data ``(..., 25)`` under the model's likelihood, one replicate per draw.

    The noise is the likelihood's own (:func:`lvcore.inference.models.lvv_sd`,
    :func:`lvcore.inference.models.strain_noise_covariance`), so a forward model that carries the shape
    model's representation error (a mesh's floor, ``--geometry infer``) widens the replicates as it widened the
    likelihood the sampler used.

    Parameters
    ----------
    samples : dict
        Draws with common leading axes (e.g. (chain, draw)): ``eta`` (..., 25),
        and for models (ii)/(iii) ``sigma_s2`` (...), for (iii) also ``disc``
        (..., 24) and ``v`` (...).
    sigma_v : float
        LVV noise sd (mL).
    rng : numpy Generator
    forward : Forward, optional
        The forward model the posterior was sampled with; its ``representation`` (if any) is the floor.
    model : {"volume", "iid", "discrepancy"}, optional
        The likelihood; default: read from ``samples`` (``disc``: discrepancy, ``sigma_s2``: iid, else volume).

    Returns
    -------
    ndarray
        ``y_rep[..., 0] ~ N(eta_0, lvv_sd^2)`` (``sigma_v``, widened by the floor's ``r_V eta_0``); strains
        ``~ MVN(eta, sigma_S^2 I + Sigma_rep)`` (iid; without a floor ``N(eta, sigma_S^2)``) or
        ``~ N(eta + b + v, sigma_S^2)`` (discrepancy: the drawn b already holds ``Sigma_rep``,
        ``b ~ N(0, K + Sigma_rep)``). The volume-only model does not model the strains: there they are ``eta``
        without noise.
    """
    if model is None:
        model = "discrepancy" if "disc" in samples else "iid" if "sigma_s2" in samples else "volume"
    eta = np.asarray(samples["eta"], dtype=float)
    y_rep = eta.copy()
    lvv_sd = np.asarray(models.lvv_sd(eta[..., 0], float(sigma_v), forward), dtype=float)
    y_rep[..., 0] += lvv_sd * rng.standard_normal(eta.shape[:-1])
    if model != "volume":
        mean = eta[..., 1:]
        if model == "discrepancy":
            mean = mean + np.asarray(samples["disc"]) + np.asarray(samples["v"])[..., None]
        cov = np.asarray(models.strain_noise_covariance(np.asarray(samples["sigma_s2"], dtype=float), forward,
                                                        model), dtype=float)
        y_rep[..., 1:] = mean + _gaussian_noise(cov, rng.standard_normal(mean.shape))
    return y_rep


def _gaussian_noise(cov, z):
    """``L z`` with ``L L^T = cov`` (``(..., n, n)``, ``z`` of shape ``(..., n)``): zero-mean Gaussian draws of
    covariance ``cov``; a diagonal ``cov`` gives ``sqrt(diag) z`` exactly (the iid formula, bit for bit)."""
    diag = np.diagonal(cov, axis1=-2, axis2=-1)
    if not np.any(cov - diag[..., None] * np.eye(cov.shape[-1])):
        return np.sqrt(diag) * z
    return np.einsum("...ij,...j->...i", np.linalg.cholesky(cov), z)


def to_inference_data(run: samplers.SamplerRun, y, *, convergence: Convergence | None = None,
                      sigma_v: float = SIGMA_V_ML, forward_label: str = "",
                      extra_attrs: dict | None = None, forward=None) -> az.InferenceData:
    """ArviZ InferenceData with posterior, posterior_predictive, observed_data and sample_stats.

    ``eta`` (forward-model outputs at every draw) has dimension ``output``
    (LVV, 24 strain names); ``disc`` (the discrepancy b) and ``disc_tilde`` have
    dimension ``region``. ``y_rep`` is :func:`posterior_predictive` under the run's likelihood with
    ``forward``'s representation floor, if any (the forward model that ran); for the volume-only model its
    strain part is the forward model without noise (strains are not modelled).
    """
    posterior = {k: np.asarray(v) for k, v in run.samples.items()}
    coords = {"output": list(OUTPUT_NAMES), "region": list(STRAIN_NAMES)}
    dims = {"eta": ["output"], "disc": ["region"], "disc_tilde": ["region"], "y_rep": ["output"], "y": ["output"]}
    attrs = {
        "model": run.model,
        "sampler": run.method,
        "wall_s": float(run.wall_s),
        "forward_model": forward_label,
        "sigma_v_ml": float(sigma_v),
    }
    block4 = getattr(getattr(run.mcmc, "sampler", None), "block4", None)
    if block4 is not None:  # which HMC-within-Gibbs block 4 drew the discrepancy (samplers.DISCREPANCY_BLOCKS)
        attrs["discrepancy_block"] = block4
        attrs["discrepancy_kernel"] = str(getattr(run.mcmc.sampler, "kernel", "additive"))  # the GP's kernel
    if convergence is not None:
        attrs.update({f"convergence_{k}": (json.dumps(v) if isinstance(v, tuple) else v)
                      for k, v in asdict(convergence).items()})
        attrs["convergence_converged"] = int(convergence.converged)
    attrs.update(extra_attrs or {})
    return az.from_dict(
        posterior=posterior,
        posterior_predictive={"y_rep": posterior_predictive(run.samples, sigma_v, np.random.default_rng(1), forward,
                                                            run.model)},
        observed_data={"y": np.asarray(y, dtype=float)},
        sample_stats={k: np.asarray(v) for k, v in run.sample_stats.items()},
        coords=coords,
        dims=dims,
        attrs=attrs,
    )


def save_netcdf(idata: az.InferenceData, path) -> Path:
    """Write InferenceData to netCDF (``.nc``); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    idata.to_netcdf(str(path))
    return path


def netcdf_bytes(idata: az.InferenceData) -> bytes:
    """InferenceData as the bytes of a netCDF file (for a download; written to a temporary file)."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        return save_netcdf(idata, Path(d) / "posterior.nc").read_bytes()


#: Bulk ESS below which the app's banner is amber even when the run passed its convergence check.
BANNER_ESS_MIN = 400.0


def banner_status(conv: Convergence, ess_min: float = BANNER_ESS_MIN, flags=()) -> tuple[str, str]:
    """The level and text of the app's convergence banner for one run.

    Green (``"success"``) only when the run converged (R-hat and ESS
    thresholds of the check), had no divergent transitions and every monitored
    parameter has bulk ESS >= ``ess_min``; otherwise ``"warning"`` (amber).
    The text always states the divergences, the worst R-hat and the
    smallest bulk and tail ESS, so a user never has to trust a colour.
    ``flags`` are the verdict's (:mod:`lvcore.inference.verdict`, posterior
    mass on a prior bound included): any flag makes the banner amber and is
    listed here, once, in the app's words (the page shows no other copy).

    Returns
    -------
    level : {"success", "warning"}
    text : str
    """
    flags = list(flags)
    # the verdict's SAMPLER flags restate this banner's own convergence and divergence findings: said once, here
    sampler = [f for f in flags if f.startswith("SAMPLER: ")]
    others = [f for f in flags if not f.startswith("SAMPLER: ")]
    problems = []
    if not conv.converged:
        problems.append("not converged" + (f" ({', '.join(conv.failing)})" if conv.failing else ""))
    if conv.n_divergent > 0:
        many = next((f[len("SAMPLER: "):] for f in sampler if "divergent transitions in" in f), None)
        problems.append(many or f"{conv.n_divergent} divergent transition{'s' if conv.n_divergent != 1 else ''}")
    if not conv.min_ess_bulk >= ess_min:
        problems.append(f"bulk ESS {conv.min_ess_bulk:.0f} < {ess_min:.0f}")
    if flags:
        listed = others + (["SAMPLER (the sampler problems above)"] if sampler else [])
        problems.append(f"flagged ({len(flags)}): {'; '.join(listed)}")
    rhat = f"{conv.max_rhat:.3f}" if np.isfinite(conv.max_rhat) else "n/a (needs ≥ 2 chains)"
    numbers = (f"divergences {conv.n_divergent}, max R-hat {rhat}, min bulk ESS "
               f"{conv.min_ess_bulk:.0f}, min tail ESS {conv.min_ess_tail:.0f}, {conv.rounds} round(s)")
    if problems:
        return "warning", "Treat with care: " + "; ".join(problems) + ". " + numbers
    return "success", "Converged: " + numbers


__all__ = ["INTERVAL_COLUMNS", "INTERVAL_TEXT", "equal_tailed_summary", "Convergence", "BANNER_ESS_MIN", "banner_status", "DEFAULT_RHAT_MAX", "DEFAULT_ESS_MIN", "monitored_names", "summary_table", "netcdf_bytes",
           "check_convergence", "sample_until_converged", "ess_per_second", "posterior_predictive", "to_inference_data",
           "save_netcdf"]
